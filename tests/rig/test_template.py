"""``gtrig rig init``: a commented template that ``gtrig rig check`` accepts, every field explained."""

from __future__ import annotations

import re
import types
import typing
from pathlib import Path

import pytest
import yaml
from pydantic import BaseModel
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.rig import load_rig
from gtrig.rig.models import Rig
from gtrig.rig.template import FIELD_NOTES, LATER_NOTES, template_field_paths, template_rig

runner = CliRunner()

KEY = re.compile(r"^(\s*)(- )?([A-Za-z_]\w*):")


def _model_paths(model: type[BaseModel], path: str = "") -> set[str]:
    """Every field path of a pydantic model, list items as ``[]`` (as in FIELD_NOTES)."""
    out: set[str] = set()
    for name, field in model.model_fields.items():
        p = f"{path}.{name}" if path else name
        out.add(p)
        ann = field.annotation
        stack, suffix = [ann], ""
        while stack:
            a = stack.pop()
            origin = typing.get_origin(a)
            if origin in (typing.Union, types.UnionType):
                stack.extend(typing.get_args(a))
            elif origin is tuple and typing.get_args(a)[-1:] == (Ellipsis,):
                suffix = "[]"
                stack.append(typing.get_args(a)[0])
            elif isinstance(a, type) and issubclass(a, BaseModel):
                out |= _model_paths(a, p + suffix)
    return out


@pytest.mark.parametrize("args", [["--cameras", "3", "--scanners", "2"], ["--cameras", "1", "--scanners", "0"],
                                  ["--cameras", "0", "--scanners", "4"], ["--odometry-only"]])
def test_init_writes_a_rig_that_check_accepts(tmp_path: Path, args: list[str]) -> None:
    out = tmp_path / "rig.yaml"
    r = runner.invoke(app, ["rig", "init", *args, "--out", str(out)])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["rig", "check", str(out)])
    assert r.exit_code == 0, r.output
    rig = load_rig(out)
    if args == ["--odometry-only"]:
        assert not rig.cameras and not rig.laser_scanners and not rig.robot.markers and rig.robot.hull is None
        assert rig.robot.onboard_scanners and rig.robot.odometry.rate_hz > 0
    else:
        n, m = int(args[1]), int(args[3])
        assert [c.name for c in rig.cameras] == [f"cam{i}" for i in range(n)]
        assert [s.name for s in rig.laser_scanners] == [f"laser{i}" for i in range(m)]
        assert (rig.robot.hull is not None) == (m > 0) and bool(rig.robot.markers) == (n > 0)
        assert rig == template_rig(n, m)


def test_every_key_has_a_comment_above_its_first_occurrence(tmp_path: Path) -> None:
    out = tmp_path / "rig.yaml"
    assert runner.invoke(app, ["rig", "init", "--out", str(out)]).exit_code == 0
    lines = out.read_text().splitlines()
    # the comments do not change the document
    bare = "\n".join(x for x in lines if not x.lstrip().startswith("#"))
    assert yaml.safe_load(bare) == yaml.safe_load(out.read_text())
    first_line_of: dict[str, int] = {}
    for i, line in enumerate(lines):
        m = KEY.match(line)
        if m:
            first_line_of.setdefault(m.group(3), i)
    for key, i in first_line_of.items():
        assert lines[i - 1].lstrip().startswith("#"), f"{key} at line {i + 1} has no comment above it"


def test_every_rig_field_is_explained() -> None:
    """A field added to the rig model fails here until the template explains it."""
    explained = set(FIELD_NOTES)
    for anchor, note in LATER_NOTES.items():
        explained.add(f"{anchor}.{note.split(':')[0]}")
    # quat_xyzw, the other way to write a rotation, is explained with the frames
    poses = {p for p in _model_paths(Rig) if p.endswith(".quat_xyzw")}
    assert "quat_xyzw" in FIELD_NOTES["world"]
    assert _model_paths(Rig) - poses - explained == set()
    # and the template writes every explained field but those a calibration adds
    written = set(template_field_paths(template_rig(2, 2)))
    assert written == set(FIELD_NOTES)
    for p in written:
        assert FIELD_NOTES[p].strip(), p


def test_init_refusals(tmp_path: Path) -> None:
    out = tmp_path / "rig.yaml"
    for args, words in ((["--odometry-only", "--cameras", "2"], "--odometry-only takes no --cameras"),
                        (["--cameras", "0", "--scanners", "0"], "--odometry-only"),
                        (["--cameras", "-1"], "--cameras")):
        r = runner.invoke(app, ["rig", "init", *args, "--out", str(out)])
        assert r.exit_code == 2 and words in r.output and len(r.output.strip().splitlines()) == 1, r.output
        assert not out.exists()
    out.write_text("mine\n")
    r = runner.invoke(app, ["rig", "init", "--out", str(out)])
    assert r.exit_code == 2 and "exists" in r.output and out.read_text() == "mine\n"


def test_odometry_only_rig_imports_a_bag(tmp_path: Path, shared_dir: Path) -> None:
    """What the odometry-only template is for: a bag's odometry into a recording, checked against it."""
    rig = tmp_path / "rig.yaml"
    assert runner.invoke(app, ["rig", "init", "--odometry-only", "--out", str(rig)]).exit_code == 0
    topics = tmp_path / "topics.yaml"
    topics.write_text("sequence: run\nstamp: header\nodometry: /odom\n")
    out = tmp_path / "rec"
    r = runner.invoke(app, ["import", "rosbag", str(shared_dir / "data/rosbags/nav2_turtlebot.mcap"),
                            "--topics", str(topics), "--rig", str(rig), "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert load_rig(out / "rig.yaml") == load_rig(rig)
    assert len((out / "run/odometry.csv").read_text().splitlines()) == 1 + 2639
