"""Rig files as a new user writes them: a vision-only rig needs no hull, stills need no
frame rate, ``gtrig rig check`` lists every problem of a file at once, and the beam timing of a
scanner is the device's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.errors import ConfigError
from gtrig.rig import dump_rig, load_rig
from gtrig.rig.load import rig_to_dict
from gtrig.rig.models import BeamTiming, StampAt
from gtrig.sim.gtroom import make_scene

runner = CliRunner()


def _vision_only(tmp_path: Path) -> Path:
    doc = rig_to_dict(make_scene(0).rig_nominal)
    doc.pop("laser_scanners")
    doc["robot"].pop("hull")
    doc["robot"].pop("onboard_scanners")
    for c in doc["cameras"]:
        c.pop("rate_hz")  # stills
    p = tmp_path / "rig.yaml"
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    return p


def test_vision_only_rig_of_stills_needs_no_hull_nor_rate(tmp_path: Path) -> None:
    p = _vision_only(tmp_path)
    rig = load_rig(p)
    assert rig.robot.hull is None and all(c.rate_hz is None for c in rig.cameras)
    r = runner.invoke(app, ["rig", "check", str(p)])
    assert r.exit_code == 0, r.output
    assert "no hull" in r.output and "stills" in r.output


def test_gtlaser_without_hull_is_one_clear_line(tmp_path: Path) -> None:
    from gtrig.laser.recording import track_sequence

    rig = make_scene(0).rig_nominal
    rig = rig.model_copy(update={"robot": rig.robot.model_copy(update={"hull": None})})
    with pytest.raises(ConfigError) as e:
        track_sequence(rig, tmp_path, [])
    assert "robot.hull" in str(e.value) and "\n" not in str(e.value)


def test_rig_check_lists_every_problem(tmp_path: Path) -> None:
    p = tmp_path / "rig.yaml"
    dump_rig(make_scene(0).rig_nominal, p)
    text = p.read_text().replace("side_m: 0.156", "side_m: 156.0", 1).replace("beams: 180", "beams: 1", 1)
    text = text.replace("range_sigma_m:", "range_sigma:", 1)
    p.write_text(text)
    r = runner.invoke(app, ["rig", "check", str(p)])
    assert r.exit_code == 2
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 3 and all(x.startswith("error:") for x in lines), r.output
    joined = " ".join(lines)
    assert "side_m" in joined and "beams" in joined and "range_sigma" in joined
    # each names the line of the file at fault
    assert all(f"{p}:" in x for x in lines)
    # the library still raises one line, saying how many more there are
    with pytest.raises(ConfigError) as e:
        load_rig(p)
    assert "(and 2 more)" in str(e.value) and "\n" not in str(e.value)


def test_beam_delays_follow_the_device() -> None:
    s = make_scene(0).rig_nominal.laser_scanners[0]
    sweep = s.beam_delays_s()
    # a mirror turning once per period: 180 degrees of beams take half of it
    assert sweep[0] == 0 and np.isclose(sweep[-1], (s.beams - 1) / s.beams * 0.5 / s.rate_hz)
    end = s.model_copy(update={"stamp_at": StampAt.END}).beam_delays_s()
    mid = s.model_copy(update={"stamp_at": StampAt.MIDDLE}).beam_delays_s()
    assert np.allclose(end, sweep - sweep[-1]) and np.allclose(mid, sweep - sweep[-1] / 2)
    flash = s.model_copy(update={"beam_timing": BeamTiming.SIMULTANEOUS}).beam_delays_s()
    assert np.all(flash == 0)


def test_gtrig_vision_says_which_defaults_it_assumed(tmp_path: Path) -> None:
    rig = make_scene(0).rig_nominal
    dump_rig(rig, tmp_path / "rig.yaml")
    (tmp_path / "rec").mkdir()
    args = ["vision", "--rig", str(tmp_path / "rig.yaml"), "--recording", str(tmp_path / "rec"),
            "--out", str(tmp_path / "gt.tum"), "--planar"]
    r = runner.invoke(app, args)
    assert r.exit_code == 2 and "Traceback" not in r.output  # an empty recording: one clear error
    assert "assumed: camera pose sigma 3 mm / 0.05 deg for cam0, cam1" in r.output
    assert "assumed: floor prior 3 mm" in r.output
    # a rig that gives its cameras' uncertainty is taken at its word
    cov = tuple(tuple(float(1e-6 if i == j else 0.0) for j in range(6)) for i in range(6))
    rig2 = rig.model_copy(update={"cameras": tuple(c.model_copy(update={"pose_cov": cov}) for c in rig.cameras)})
    dump_rig(rig2, tmp_path / "rig.yaml")
    r = runner.invoke(app, args)
    assert "assumed: camera" not in r.output and "assumed: marker pose sigma" in r.output
