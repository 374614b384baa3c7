"""Bad files and paths on every verb: outputs that are folders, under files, equal to an input or to each
other; inputs that are binary, missing, YAML bombs, hold NaN or millimetres, name paths outside the
recording or hold Rich markup; corrupt resume state. Each: one line naming the file or option, exit 2 (3
for a degenerate input), nothing written, no input changed (tests/cli/bad_input_kit.py)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from bad_input_kit import case_ids, refused

VIS = ["vision", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec"]
FUSE = ["fuse", "--vision", "{d}/est.tum", "--vision-cov", "{d}/est_cov.csv", "--odometry", "{d}/odometry.csv"]
SURVEY = ["survey", "points", "--reference", "{d}/ref.csv", "--distances", "{d}/d.csv"]
ADJUST = ["survey", "adjust", "--reference", "{d}/ref.csv", "--distances", "{d}/d.csv", "--robot-points",
          "{d}/rp.csv", "--pose-distances", "{d}/pd.csv"]
CALROB = ["markers", "calibrate-robot", "--images", "{d}/images", "--camera", "{d}/cam.yaml"]


def _state(text: str) -> Callable[[Path], None]:
    def setup(o: Path) -> None:
        (o / "rec").mkdir()
        (o / "rec" / ".gtrig_sim_state.json").write_text(text)
    return setup


# (id, command line, exit code, words the error line must hold, setup of the output folder)
CASES: list[tuple[str, list[str], int, list[str], Callable[[Path], None] | None]] = [
    # outputs that are files, folders, under files, unwritable
    ("sim-out-is-a-file", ["sim", "--quick", "--out", "{o}/afile"], 2, ["{o}/afile", "is a file"], None),
    ("sim-out-under-a-file", ["sim", "--quick", "--out", "{o}/afile/rec"], 2, ["afile", "is a file"], None),
    ("sim-out-unwritable", ["sim", "--quick", "--out", "/proc/gtrig_no/rec"], 2, ["/proc/gtrig_no"], None),
    ("demo-out-is-a-file", ["demo", "--quick", "--out", "{o}/afile"], 2, ["{o}/afile"], None),
    ("run-out-is-a-file", ["run", "--recording", "{d}/rec", "--out", "{o}/afile"], 2, ["{o}/afile"], None),
    ("run-out-is-the-recording", ["run", "--recording", "{d}/rec", "--out", "{d}/rec"], 2, ["--out", "recording"],
     None),
    ("run-out-inside-the-recording", ["run", "--recording", "{d}/rec", "--out", "{d}/rec/results"], 2,
     ["--out", "inside"], None),
    ("vision-out-is-a-folder", [*VIS, "--out", "{o}/afolder"], 2, ["{o}/afolder", "folder"], None),
    ("vision-out-under-a-file", [*VIS, "--out", "{o}/afile/v.tum"], 2, ["afile", "is a file"], None),
    ("vision-out-equals-covariance", [*VIS, "--out", "{o}/v.tum", "--covariance", "{o}/v.tum"], 2,
     ["{o}/v.tum", "two outputs"], None),
    ("vision-out-equals-rig", [*VIS, "--out", "{d}/rig.yaml"], 2, ["overwrite an input"], None),
    ("laser-track-out-equals-covariance", ["laser", "track", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec",
                                           "--out", "{o}/l.tum", "--covariance", "{o}/l.tum"], 2, ["two outputs"],
     None),
    ("laser-track-out-equals-rig", ["laser", "track", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec",
                                    "--out", "{d}/rig.yaml"], 2, ["overwrite an input"], None),
    ("laser-calibrate-out-equals-rig", ["laser", "calibrate", "--rig", "{d}/rig.yaml", "--static", "{d}/static_mm",
                                        "--out", "{d}/rig.yaml"], 2, ["overwrite an input"], None),
    ("markers-detect-out-equals-image", ["markers", "detect", "{d}/images/0.png", "--family", "artoolkitplus_simple",
                                         "--out", "{d}/images/0.png"], 2, ["overwrite an input"], None),
    ("markers-detect-debug-under-a-file", ["markers", "detect", "{d}/images", "--family", "artoolkitplus_simple",
                                           "--out", "{o}/det.json", "--debug", "{o}/afile/dbg"], 2, ["--debug"], None),
    ("markers-calibrate-robot-out-equals-rig-out", [*CALROB, "--rig", "{d}/rig.yaml", "--out", "{o}/m.yaml",
                                                    "--rig-out", "{o}/m.yaml"], 2, ["two outputs"], None),
    ("markers-calibrate-robot-out-equals-camera", [*CALROB, "--side-mm", "14=160", "--anchor-pose", "0,0,0.5,0,0,0",
                                                   "--out", "{d}/cam.yaml"], 2, ["overwrite an input"], None),
    ("calib-intrinsics-out-is-a-folder", ["calib", "intrinsics", "--images", "{d}/images", "--board", "9x5x0.1",
                                          "--out", "{o}/afolder"], 2, ["folder"], None),
    ("calib-intrinsics-figure-under-a-file", ["calib", "intrinsics", "--images", "{d}/images", "--board", "9x5x0.1",
                                              "--out", "{o}/cam.yaml", "--figure", "{o}/afile/c.png"], 2, ["afile"],
     None),
    ("calib-steady-figures-under-a-file", ["calib", "steady", "--before", "{d}/images", "--after", "{d}/images",
                                           "--rig", "{d}/rig.yaml", "--figures", "{o}/afile/figs"], 2, ["--figures"],
     None),
    ("calib-network-out-equals-rig", ["calib", "network", "--rig", "{d}/rig.yaml", "--pairs", "{d}/images",
                                      "--world-board", "{d}/images", "--boards", "{d}/bin.yaml",
                                      "--out", "{d}/rig.yaml"], 2, ["overwrite an input"], None),
    ("calib-recording-missing", ["calib", "recording", "{o}/nowhere"], 2, ["nowhere", "no such folder"], None),
    ("survey-adjust-outputs-equal", [*ADJUST, "--out-points", "{o}/x.csv", "--out-poses", "{o}/x.csv"], 2,
     ["two outputs"], None),
    ("survey-adjust-out-is-a-folder", [*ADJUST, "--out-points", "{o}/afolder", "--out-poses", "{o}/p.csv"], 2,
     ["afolder"], None),
    ("fuse-out-equals-covariance", [*FUSE, "--out", "{o}/g.tum", "--covariance", "{o}/g.tum"], 2, ["two outputs"],
     None),
    ("fuse-out-equals-vision", [*FUSE, "--out", "{d}/est.tum", "--covariance", "{o}/c.csv"], 2,
     ["overwrite an input"], None),
    ("gps-out-equals-log", ["gps", "--log", "{d}/bin.nmea", "--out", "{d}/bin.nmea", "--covariance", "{o}/c.csv"], 2,
     ["overwrite an input"], None),
    ("sync-out-equals-source", ["sync", "--recording", "{d}/rec", "--source", "v={d}/est.tum,{d}/est_cov.csv",
                                "--out", "{d}/est_cov.csv"], 2, ["overwrite an input"], None),
    ("export-out-equals-input", ["export", "{d}/ref.tum", "--to", "tum", "--out", "{d}/ref.tum", "--force"], 2,
     ["overwrite an input"], None),
    ("report-out-is-a-folder", ["report", "{d}/results", "--out", "{o}/afolder"], 2, ["afolder"], None),
    ("report-results-missing", ["report", "{o}/nowhere", "--out", "{o}/r.html"], 2, ["nowhere"], None),
    ("evaluate-poses-plot-under-a-file", ["evaluate", "poses", "--reference", "{d}/ref.tum", "--estimate",
                                          "{d}/est.tum", "--plot", "{o}/afile/p.png"], 2, ["afile"], None),
    ("robot-frame-out-equals-rig", ["robot-frame", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec",
                                    "--out", "{d}/rig.yaml"], 2, ["overwrite an input"], None),
    ("scanmatch-validate-out-is-a-folder", ["scanmatch", "validate", "--recording", "{d}/rec", "--out",
                                            "{o}/afolder"], 2, ["afolder"], None),
    ("scanmatch-mounting-out-equals-rig", ["scanmatch", "mounting", "--recording", "{d}/rec", "--survey",
                                           "{d}/points.csv", "--rig", "{d}/rig.yaml", "--out", "{d}/rig.yaml"], 2,
     ["overwrite an input"], None),
    ("import-out-is-a-file", ["import", "rosbag", "{d}/bin.bag", "--topics", "{d}/bin.yaml", "--out", "{o}/afile"], 2,
     ["afile"], None),
    # undecodable, missing or wrong-kind inputs
    ("survey-points-binary-reference", ["survey", "points", "--reference", "{d}/bin.csv", "--distances", "{d}/d.csv",
                                        "--out", "{o}/p.csv"], 2, ["{d}/bin.csv"], None),
    ("survey-points-binary-distances", [*SURVEY[:4], "--distances", "{d}/bin.csv", "--out", "{o}/p.csv"], 2,
     ["{d}/bin.csv"], None),
    ("survey-points-empty-distances", [*SURVEY[:4], "--distances", "{d}/empty.csv", "--out", "{o}/p.csv"], 2,
     ["{d}/empty.csv"], None),
    ("survey-points-zero-sigma-reading", [*SURVEY[:4], "--distances", "{d}/d_sigma0.csv", "--out", "{o}/p.csv"], 2,
     ["{d}/d_sigma0.csv:2", "sigma"], None),
    ("evaluate-poses-unknown-columns", ["evaluate", "poses", "--reference", "{d}/points.csv", "--estimate",
                                        "{d}/points.csv", "--reference-columns", "a,b,c"], 2, ["{d}/points.csv"], None),
    ("gps-log-missing", ["gps", "--log", "{o}/none.nmea", "--out", "{o}/g.tum", "--covariance", "{o}/c.csv"], 2,
     ["none.nmea"], None),
    ("fuse-binary-odometry", ["fuse", "--vision", "{d}/est.tum", "--vision-cov", "{d}/est_cov.csv", "--odometry",
                              "{d}/bin.csv", "--out", "{o}/g.tum", "--covariance", "{o}/c.csv"], 2, ["{d}/bin.csv"],
     None),
    ("sync-binary-covariance", ["sync", "--recording", "{d}/rec", "--source", "v={d}/est.tum,{d}/bin.csv",
                                "--out", "{o}/s.yaml"], 2, ["{d}/bin.csv"], None),
    ("survey-points-markup-names", ["survey", "points", "--reference", "{d}/ref_markup.csv", "--distances",
                                    "{d}/d_markup.csv", "--out", "{o}/p.csv"], 2, ["Q[/b]"], None),
    ("survey-poses-coincident-robot-points", ["survey", "poses", "--points", "{d}/points.csv", "--robot-points",
                                              "{d}/rp_coincident.csv", "--distances", "{d}/pd.csv", "--out",
                                              "{o}/p.csv"], 2, ["{d}/rp_coincident.csv"], None),
    ("evaluate-poses-binary-reference", ["evaluate", "poses", "--reference", "{d}/bin.csv", "--estimate",
                                         "{d}/est.tum"], 2, ["{d}/bin.csv"], None),
    ("evaluate-poses-missing-estimate", ["evaluate", "poses", "--reference", "{d}/ref.tum", "--estimate",
                                         "{o}/none.tum"], 2, ["none.tum"], None),
    ("evaluate-slam-binary-gt", ["evaluate", "slam", "--gt", "{d}/bin.tum", "--estimate", "{d}/est.tum"], 2,
     ["{d}/bin.tum"], None),
    ("evaluate-compare-nan-in-tum", ["evaluate", "compare", "--a", "{d}/ref.tum", "--b", "{d}/est_nan.tum"], 2,
     ["{d}/est_nan.tum"], None),
    ("markers-calibrate-robot-binary-camera", [*CALROB[:4], "--camera", "{d}/bin.yaml", "--side-mm", "14=160",
                                               "--anchor-pose", "0,0,0.5,0,0,0", "--out", "{o}/m.yaml"], 2,
     ["{d}/bin.yaml"], None),
    ("markers-detect-binary-camera", ["markers", "detect", "{d}/images", "--family", "artoolkitplus_simple",
                                      "--camera", "{d}/bin.yaml", "--out", "{o}/det.json"], 2, ["{d}/bin.yaml"], None),
    ("markers-detect-not-an-image", ["markers", "detect", "{d}/text.png", "--family", "artoolkitplus_simple",
                                     "--out", "{o}/det.json"], 2, ["{d}/text.png"], None),
    ("markers-detect-missing-input", ["markers", "detect", "{o}/none.png", "--family", "artoolkitplus_simple",
                                      "--out", "{o}/det.json"], 2, ["none.png"], None),
    ("rig-check-missing", ["rig", "check", "{o}/none.yaml"], 2, ["none.yaml"], None),
    ("rig-check-folder", ["rig", "check", "{o}/afolder"], 2, ["afolder"], None),
    ("rig-check-list", ["rig", "check", "{d}/rig_list.yaml"], 2, ["{d}/rig_list.yaml"], None),
    ("rig-check-billion-laughs", ["rig", "check", "{d}/laughs.yaml"], 2, ["{d}/laughs.yaml", "aliases"], None),
    ("rig-check-deep-nesting", ["rig", "check", "{d}/deep.yaml"], 2, ["{d}/deep.yaml", "nest"], None),
    ("rig-check-markup-in-the-name", ["rig", "check", "{d}/x[/b]y.yaml"], 2, ["x[/b]y.yaml"], None),
    ("rig-check-nan-focal-length", ["rig", "check", "{d}/rig_nan.yaml"], 2, ["camera_matrix", "finite"], None),
    ("rig-check-camera-name-is-a-path", ["rig", "check", "{d}/rig_escape.yaml"], 2, ["not a plain name"], None),
    ("rig-check-range-in-mm", ["rig", "check", "{d}/rig_range_mm.yaml"], 2, ["range_max_m"], None),
    ("sim-config-is-a-list", ["sim", "--quick", "--out", "{o}/rec", "--config", "{d}/rig_list.yaml"], 2,
     ["{d}/rig_list.yaml", "mapping"], None),
    ("sim-config-billion-laughs", ["sim", "--quick", "--out", "{o}/rec", "--config", "{d}/laughs.yaml"], 2,
     ["{d}/laughs.yaml"], None),
    ("sim-config-binary", ["sim", "--quick", "--out", "{o}/rec", "--config", "{d}/bin.yaml"], 2, ["{d}/bin.yaml"],
     None),
    ("run-config-billion-laughs", ["run", "--recording", "{d}/rec", "--out", "{o}/res", "--config", "{d}/laughs.yaml"],
     2, ["{d}/laughs.yaml"], None),
    ("run-config-unknown-section", ["run", "--recording", "{d}/rec", "--out", "{o}/res", "--config",
                                    "{d}/run_unknown.yaml"], 2, ["no_such_section"], None),
    ("run-recording-missing", ["run", "--recording", "{o}/nowhere", "--out", "{o}/res"], 2, ["nowhere"], None),
    ("run-recording-is-a-file", ["run", "--recording", "{d}/bin.dat", "--out", "{o}/res"], 2, ["{d}/bin.dat"], None),
    ("vision-binary-rig", ["vision", "--rig", "{d}/bin.yaml", "--recording", "{d}/rec", "--out", "{o}/v.tum"], 2,
     ["{d}/bin.yaml"], None),
    ("vision-frame-index-escapes", ["vision", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec_escape",
                                    "--out", "{o}/v.tum"], 2, ["timestamps.csv", "not a plain file name"], None),
    ("laser-calibrate-ranges-in-mm", ["laser", "calibrate", "--rig", "{d}/rig.yaml", "--static", "{d}/static_mm",
                                      "--out", "{o}/r.yaml", "--object", "{d}/object.yaml"], 2, ["millimetres"], None),
    ("laser-calibrate-binary-object", ["laser", "calibrate", "--rig", "{d}/rig.yaml", "--static", "{d}/static_mm",
                                       "--out", "{o}/r.yaml", "--object", "{d}/bin.yaml"], 2, ["{d}/bin.yaml"], None),
    ("gps-binary-log", ["gps", "--log", "{d}/bin.nmea", "--out", "{o}/g.tum", "--covariance", "{o}/c.csv"], 2,
     ["{d}/bin.nmea"], None),
    ("gps-binary-rtklib", ["gps", "--log", "{d}/bin.pos", "--format", "rtklib", "--out", "{o}/g.tum",
                           "--covariance", "{o}/c.csv"], 2, ["{d}/bin.pos"], None),
    ("export-binary-input", ["export", "{d}/bin.dat", "--to", "tum", "--out", "{o}/x.tum"], 2, ["{d}/bin.dat"], None),
    ("scanmatch-map-binary-map", ["scanmatch", "map", "--map", "{d}/bin.yaml", "--recording", "{d}/rec", "--initial",
                                  "{d}/points.csv", "--out", "{o}/p.csv"], 2, ["{d}/bin.yaml"], None),
    ("scanmatch-map-laughs", ["scanmatch", "map", "--map", "{d}/laughs.yaml", "--recording", "{d}/rec", "--initial",
                              "{d}/points.csv", "--out", "{o}/p.csv"], 2, ["{d}/laughs.yaml"], None),
    ("import-corrupt-bag", ["import", "rosbag", "{d}/bin.bag", "--list"], 2, ["{d}/bin.bag"], None),
    ("fuse-sync-nan-offset", [*FUSE, "--sync", "{d}/sources.yaml", "--out", "{o}/g.tum", "--covariance",
                              "{o}/c.csv"], 2, ["{d}/sources.yaml"], None),
    # corrupt resume state of gtrig sim: refused, never trusted
    ("sim-state-garbage", ["sim", "--quick", "--out", "{o}/rec"], 2, ["corrupt resume state"], _state("{not json")),
    ("sim-state-a-list", ["sim", "--quick", "--out", "{o}/rec"], 2, ["corrupt resume state"], _state("[1, 2]")),
    ("sim-state-unknown-step", ["sim", "--quick", "--out", "{o}/rec"], 2, ["corrupt resume state"],
     _state('{"config": "x", "done": ["teleport"]}')),
    ("sim-state-binary", ["sim", "--quick", "--out", "{o}/rec"], 2, ["corrupt resume state"], _state("\x00\x01\x02")),
]


@pytest.mark.parametrize(("args", "code", "must", "setup"), [c[1:] for c in CASES], ids=case_ids(CASES))
def test_bad_file_refused(d: Path, tmp_path: Path, args: list[str], code: int, must: list[str],
                          setup: Callable[[Path], None] | None) -> None:
    refused(args, d, tmp_path / "o", code, must, setup)
