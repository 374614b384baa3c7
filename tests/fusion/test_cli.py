"""gtrig fuse / gtrig sync on files: outputs written, bad inputs one line and exit code 2, nothing half-written."""

import numpy as np
import yaml
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.io.odometry import write_odometry_csv
from gtrig.io.posetrack import read_pose_track, write_pose_track


def _files(tmp_path, run):
    write_pose_track(run.vision, tmp_path / "v.tum", tmp_path / "v.csv")
    write_pose_track(run.laser, tmp_path / "l.tum", tmp_path / "l.csv")
    write_odometry_csv(tmp_path / "odo.csv", run.odometry)
    return ["--vision", str(tmp_path / "v.tum"), "--vision-cov", str(tmp_path / "v.csv"), "--laser",
            str(tmp_path / "l.tum"), "--laser-cov", str(tmp_path / "l.csv"), "--odometry", str(tmp_path / "odo.csv")]


def test_fuse_and_sync_verbs(tmp_path, run) -> None:
    args = _files(tmp_path, run)
    r = CliRunner().invoke(app, ["sync", "--reference", str(tmp_path / "odo.csv"), "--source",
                                 f"laser={tmp_path / 'l.tum'},{tmp_path / 'l.csv'}", "--out", str(tmp_path / "s.yaml"),
                                 "--figure", str(tmp_path / "s.png")])
    assert r.exit_code == 0, r.output
    doc = yaml.safe_load((tmp_path / "s.yaml").read_text())
    assert doc["sources"]["laser"]["verdict"] == "ok" and abs(doc["sources"]["laser"]["offset_s"]) < 0.002
    r = CliRunner().invoke(app, ["fuse", *args, "--sync", str(tmp_path / "s.yaml"), "--out", str(tmp_path / "gt.tum"),
                                 "--covariance", str(tmp_path / "gt.csv"), "--report", str(tmp_path / "r.json")])
    assert r.exit_code == 0, r.output
    gt = read_pose_track(tmp_path / "gt.tum", tmp_path / "gt.csv")
    assert gt.cov_kind == "xyyaw" and len(gt) > 1000 and np.all(np.isfinite(gt.cov))


def test_bad_inputs(tmp_path, run) -> None:
    args = _files(tmp_path, run)
    out = ["--out", str(tmp_path / "gt.tum"), "--covariance", str(tmp_path / "gt.csv")]
    # a covariance file whose rows do not match the trajectory
    lines = (tmp_path / "l.csv").read_text().splitlines()
    (tmp_path / "l.csv").write_text("\n".join(lines[:-5]) + "\n")
    r = CliRunner().invoke(app, ["fuse", *args, *out])
    assert r.exit_code == 2 and "rows" in r.output and len(r.output.strip().splitlines()) == 1
    assert not (tmp_path / "gt.tum").exists() and not (tmp_path / "gt.csv").exists()
    # non-monotonic stamps
    args = _files(tmp_path, run)
    tum = (tmp_path / "v.tum").read_text().splitlines()
    tum[3], tum[4] = tum[4], tum[3]
    (tmp_path / "v.tum").write_text("\n".join(tum) + "\n")
    r = CliRunner().invoke(app, ["fuse", *args, *out])
    assert r.exit_code == 2 and not (tmp_path / "gt.tum").exists()
    # odometry in millimetres
    args = _files(tmp_path, run)
    o = run.odometry
    from gtrig.io.odometry import OdometryLog

    write_odometry_csv(tmp_path / "odo.csv", OdometryLog(o.stamps_s, o.xytheta * [1000, 1000, 1], o.v_mps * 1000,
                                                         o.omega_radps))
    r = CliRunner().invoke(app, ["fuse", *args, *out])
    assert r.exit_code == 2 and "unit" in r.output and not (tmp_path / "gt.tum").exists()


def test_per_sensor_sync_needs_the_rig(tmp_path, run) -> None:
    _files(tmp_path, run)
    src = ["--source", f"vision={tmp_path / 'v.tum'},{tmp_path / 'v.csv'}",
           "--source", f"laser={tmp_path / 'l.tum'},{tmp_path / 'l.csv'}"]
    r = CliRunner().invoke(app, ["sync", "--reference", str(tmp_path / "odo.csv"), *src, "--per-camera",
                                 "--out", str(tmp_path / "s.yaml")])
    assert r.exit_code == 2 and "--rig" in r.output and len(r.output.strip().splitlines()) == 1
    assert not (tmp_path / "s.yaml").exists()


def test_fuse_considers_the_sources_bias_files(tmp_path, run) -> None:
    from gtrig.io.biascov import write_bias_cov

    args = _files(tmp_path, run)
    write_bias_cov(tmp_path / "lb.yaml", "GTlaser", {"scanners' calibration": np.diag([1e-3, 1e-3, 4e-4]) ** 2})
    outs = []
    for extra, name in (([], "a"), (["--laser-bias", str(tmp_path / "lb.yaml")], "b")):
        r = CliRunner().invoke(app, ["fuse", *args, *extra, "--out", str(tmp_path / f"{name}.tum"),
                                     "--covariance", str(tmp_path / f"{name}.csv")])
        assert r.exit_code == 0, r.output
        outs.append(read_pose_track(tmp_path / f"{name}.tum", tmp_path / f"{name}.csv"))
    plain, cons = outs
    np.testing.assert_array_equal(cons.xyz, plain.xyz)
    # the laser's 1 mm run-constant error cannot average out: every pose's x sigma grows
    assert np.all(cons.cov[:, 0, 0] > plain.cov[:, 0, 0])
    # a bias file that is not one, and one for a source not given: one line, exit 2, nothing written
    (tmp_path / "bad.yaml").write_text("format: something else\n")
    for extra in (["--laser-bias", str(tmp_path / "bad.yaml")], ["--vision-bias", str(tmp_path / "lb.yaml")]):
        a = args if "--laser-bias" in extra else args[4:]
        r = CliRunner().invoke(app, ["fuse", *a, *extra, "--out", str(tmp_path / "c.tum"),
                                     "--covariance", str(tmp_path / "c.csv")])
        assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1, r.output
        assert not (tmp_path / "c.tum").exists()
