"""Shared by the tests/cli/test_bad_input*.py family: a folder of inputs (valid and broken), and the
check every bad-input case makes: the exit code, one ``error:`` line naming the file, line or field, no
traceback, nothing written and no input changed.

A case's command line is a list of strings with ``{d}`` (the inputs folder, shared and never written)
and ``{o}`` (the case's own output folder, holding only ``afile``, a file, and ``afolder``, an empty
folder, when the command runs) filled in.
"""

from __future__ import annotations

import gzip
import hashlib
import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import yaml
from typer.testing import CliRunner

from gtrig.cli.main import app

runner = CliRunner()

BINARY = bytes(range(256)) * 8 + b"\xff\xfe\x00\x80" * 64
LAUGHS = "a: &a [" + ",".join(['"lol"'] * 9) + "]\n" + "".join(
    f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=True))
DEEP = "[" * 5000 + "]" * 5000


def _rig_doc() -> dict:
    from gtrig.rig.load import rig_to_dict
    from gtrig.sim.gtroom import make_scene

    return rig_to_dict(make_scene(0).rig_nominal)


def _tum(stamps: np.ndarray, xy: np.ndarray) -> str:
    return "".join(f"{t:.6f} {x:.6f} {y:.6f} 0 0 0 0 1\n" for t, (x, y) in zip(stamps, xy, strict=True))


def make_inputs(d: Path) -> Path:
    """Every input the cases name, in ``d``."""
    d.mkdir(parents=True, exist_ok=True)
    for name in ("bin.dat", "bin.csv", "bin.yaml", "bin.tum", "bin.png", "bin.nmea", "bin.bag", "bin.pos"):
        (d / name).write_bytes(BINARY)
    (d / "text.png").write_text("not an image\n")
    (d / "empty.csv").write_text("")
    doc = _rig_doc()
    (d / "rig.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    bad = yaml.safe_load((d / "rig.yaml").read_text())
    bad["cameras"][0]["camera_matrix"][0][0] = float("nan")
    (d / "rig_nan.yaml").write_text(yaml.safe_dump(bad, sort_keys=False))
    bad = yaml.safe_load((d / "rig.yaml").read_text())
    bad["cameras"][0]["name"] = "../../../../rec0/run/cameras/cam0"
    (d / "rig_escape.yaml").write_text(yaml.safe_dump(bad, sort_keys=False))
    bad = yaml.safe_load((d / "rig.yaml").read_text())
    bad["laser_scanners"][0]["range_max_m"] = 30000.0
    (d / "rig_range_mm.yaml").write_text(yaml.safe_dump(bad, sort_keys=False))
    (d / "rig_list.yaml").write_text("- 1\n- 2\n")
    (d / "laughs.yaml").write_text(LAUGHS)
    (d / "deep.yaml").write_text(DEEP)
    (d / "x[").mkdir(exist_ok=True)  # the path ".../x[/b]y.yaml": a Rich closing tag with no opening one
    (d / "x[" / "b]y.yaml").write_text("cameras: [\n")
    (d / "run_unknown.yaml").write_text("no_such_section: {a: 1}\n")
    # trajectories: a reference and an estimate of the same path
    t = np.arange(10.0) + 0.25
    xy = np.c_[0.1 * t, 0.05 * t]
    (d / "ref.tum").write_text(_tum(t, xy))
    (d / "est.tum").write_text(_tum(t, xy + 0.001))
    (d / "est_nan.tum").write_text(_tum(t, xy).replace("0.525000", "nan", 1))
    cov = ("# gtrig pose covariance v1; source=x\nstamp_s,status,reason,"
           + ",".join(f"cov_{a}_{b}" for a in ("x", "y", "yaw") for b in ("x", "y", "yaw")) + "\n"
           + "".join(f"{s:.6f},ok,," + ",".join(str(v) for v in np.eye(3).ravel() * 1e-6) + "\n" for s in t))
    (d / "est_cov.csv").write_text(cov)
    (d / "odometry.csv").write_text("stamp_s,x,y,theta,v,omega\n"
                                    + "".join(f"{s:.3f},{s * 0.1:.4f},0,0,0.1,0\n" for s in np.arange(0, 11, 0.1)))
    # survey tables
    (d / "ref.csv").write_text("name,x,y,sigma\nO,0,0,0.0005\nA,0,2.5,0.0005\nB,2.5,0,0.0005\nC,2.5,2.5,0.0005\n")
    (d / "ref_markup.csv").write_text("name,x,y,sigma\n[/i],0,0,0.0005\nA,0,2.5,0.0005\nB,2.5,0,0.0005\n")
    (d / "d.csv").write_text("point,reference,distance,sigma\n1,O,1.8028,0.00075\n1,A,1.4142,0.00075\n"
                             "1,B,2.1213,0.00075\n1,C,1.5811,0.00075\n")
    (d / "d_sigma0.csv").write_text((d / "d.csv").read_text().replace("1.8028,0.00075", "1.8028,0"))
    (d / "d_markup.csv").write_text("point,reference,distance,sigma\n1,[/i],1.8028,0.00075\n1,A,1.4142,0.00075\n"
                                    "1,B,2.1213,0.00075\n1,Q[/b],1.5,0.00075\n")
    (d / "points.csv").write_text("name,x,y\nO,0,0\nA,0,2.5\nB,2.5,0\nC,2.5,2.5\n")
    (d / "rp.csv").write_text("name,x,y\nO,0,0\nX,0.5,0\nY,0,0.5\n")
    (d / "rp_coincident.csv").write_text("name,x,y\nO,0.2,0.1\nX,0.2,0.1\nY,0.2,0.1\n")
    (d / "pd.csv").write_text("pose,robot_point,world_point,distance,sigma\n"
                              + "".join(f"1,{r},{w},{dist},0.00075\n" for r in ("O", "X", "Y")
                                        for w, dist in (("O", 1.5), ("A", 1.6), ("B", 1.7), ("C", 1.8))))
    # cameras, images, folders
    (d / "cam.yaml").write_text("image_size: [64, 48]\ncamera_matrix: [[60.0, 0.0, 32.0], [0.0, 60.0, 24.0], "
                                "[0.0, 0.0, 1.0]]\ndist_coeffs: [0.0, 0.0, 0.0, 0.0, 0.0]\nrms_px: 0.2\n")
    import cv2

    (d / "images").mkdir(exist_ok=True)
    cv2.imwrite(str(d / "images" / "0.png"), np.full((48, 64), 128, np.uint8))
    (d / "rec").mkdir(exist_ok=True)  # a recording folder (empty: the option checks come first)
    (d / "results").mkdir(exist_ok=True)
    (d / "carmen.log.gz").write_bytes(gzip.compress(b"garbage\n" * 3, mtime=0))
    rig = yaml.safe_load((d / "rig.yaml").read_text())
    for sc in rig["laser_scanners"]:  # a static sequence with ranges in millimetres
        f = d / "static_mm" / "lasers" / f"{sc['name']}.csv"
        f.parent.mkdir(parents=True, exist_ok=True)
        n = sc["beams"]
        f.write_text("timestamp," + ",".join(f"r_{i}" for i in range(n)) + "\n"
                     + "".join(f"{t:.3f}," + ",".join(["2401.0"] * n) + "\n" for t in np.arange(0, 1, 0.1)))
    cam = rig["cameras"][0]["name"]
    idx = d / "rec_escape" / "run" / "cameras" / cam / "timestamps.csv"
    idx.parent.mkdir(parents=True)
    idx.write_text("frame,stamp_s,file\n0,0.0,../../../../../../etc/passwd\n")
    (d / "object.yaml").write_text("corners_xy: [[0, 0], [0.6, 0], [0.6, 0.4], [0, 0.4]]\n")
    (d / "sources.yaml").write_text("sources: {vision: {verdict: ok, offset_s: .nan}}\n")
    return d


def case_ids(cases: Sequence[tuple[object, ...]]) -> list[str]:
    """The cases' names, checked unique (a duplicate would hide a case)."""
    ids = [str(c[0]) for c in cases]
    assert len(ids) == len(set(ids)), sorted(i for i in ids if ids.count(i) > 1)
    return ids


def snapshot(*folders: Path) -> dict[str, str]:
    """Every file and folder under ``folders`` with a hash of its bytes (temporaries included)."""
    out: dict[str, str] = {}
    for f in folders:
        for root, dirs, files in os.walk(f):
            for name in dirs:
                out[os.path.join(root, name)] = "dir"
            for name in files:
                p = os.path.join(root, name)
                out[p] = hashlib.sha1(Path(p).read_bytes()).hexdigest()
    return out


def prepare_out(o: Path) -> None:
    o.mkdir(parents=True, exist_ok=True)
    (o / "afile").write_text("a file in the way\n")
    (o / "afolder").mkdir(exist_ok=True)


def fill(args: Sequence[str], d: Path, o: Path) -> list[str]:
    return [a.replace("{d}", str(d)).replace("{o}", str(o)) for a in args]


def refused(args: Sequence[str], d: Path, o: Path, code: int = 2, must: Sequence[str] = (),
            setup: Callable[[Path], None] | None = None) -> str:
    """Run ``gtrig ARGS`` in process and check the refusal (module docstring); returns the error line.
    ``setup(o)`` puts what the case needs in its output folder first (a corrupt state file, ...)."""
    prepare_out(o)
    if setup is not None:
        setup(o)
    argv = fill(args, d, o)
    before = snapshot(d, o)
    r = runner.invoke(app, argv)
    out = r.output
    assert "Traceback" not in out, out
    assert r.exit_code == code, f"exit {r.exit_code} for {argv}:\n{out}\n{r.exception!r}"
    lines = [x for x in out.splitlines() if x.strip()]
    # GTvision says which defaults it assumes before it starts: the only lines allowed before the error
    lines = [x for x in lines if not x.startswith("assumed:")]
    assert len(lines) == 1 and lines[0].startswith("error:"), out
    line = lines[0]
    for m in must:
        assert fill([m], d, o)[0] in line, f"{m!r} not in {line!r}"
    assert snapshot(d, o) == before, f"something was written or changed: {argv}"
    return line
