"""Bad option values on every verb, refused before any work starts: one line naming the option, exit 2,
nothing written (tests/cli/bad_input_kit.py). Each case runs in process in milliseconds: the option
checks come before any input is read, so most inputs here are stand-ins."""

from __future__ import annotations

from pathlib import Path

import pytest
from bad_input_kit import case_ids, refused

# (id, command line, words the error line must hold)
CASES: list[tuple[str, list[str], list[str]]] = [
    # gtrig sim
    ("sim-seed-negative", ["sim", "--quick", "--out", "{o}/rec", "--seed", "-5"], ["--seed", "-5"]),
    ("sim-seed-2^70", ["sim", "--quick", "--out", "{o}/rec", "--seed", str(2**70)], ["--seed"]),
    ("sim-seed-not-int", ["sim", "--quick", "--out", "{o}/rec", "--seed", "abc"], ["--seed"]),
    ("sim-workers-negative", ["sim", "--quick", "--out", "{o}/rec", "--workers", "-3"], ["--workers", "-3"]),
    ("sim-workers-huge", ["sim", "--quick", "--out", "{o}/rec", "--workers", "100000"], ["--workers"]),
    ("sim-offset-nan", ["sim", "--quick", "--out", "{o}/rec", "--odometry-offset-s", "nan"],
     ["--odometry-offset-s", "finite"]),
    ("sim-offset-huge", ["sim", "--quick", "--out", "{o}/rec", "--odometry-offset-s", "1e9"], ["--odometry-offset-s"]),
    ("sim-scenario-unknown", ["sim", "--quick", "--out", "{o}/rec", "--scenario", "moon"], ["moon"]),
    ("sim-missing-out", ["sim", "--quick"], ["--out"]),
    ("sim-unknown-option", ["sim", "--out", "{o}/rec", "--speed", "3"], ["--speed"]),
    # gtrig demo
    ("demo-seed-negative", ["demo", "--quick", "--out", "{o}/demo", "--seed", "-1"], ["--seed"]),
    ("demo-seed-huge", ["demo", "--quick", "--out", "{o}/demo", "--seed", str(2**40)], ["--seed"]),
    # gtrig run
    ("run-workers-negative", ["run", "--recording", "{d}/rec", "--out", "{o}/res", "--workers", "-3"], ["--workers"]),
    ("run-workers-huge", ["run", "--recording", "{d}/rec", "--out", "{o}/res", "--workers", "5000"], ["--workers"]),
    ("run-stage-unknown", ["run", "--recording", "{d}/rec", "--out", "{o}/res", "--stages", "survey,teleport"],
     ["teleport"]),
    # gtrig vision
    *[(f"vision-{opt[2:]}-{v}", ["vision", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec", "--out", "{o}/v.tum",
                                 opt, v], [opt])
      for opt, v in (("--camera-sigma-mm", "nan"), ("--camera-sigma-mm", "-1"), ("--camera-sigma-deg", "inf"),
                     ("--marker-sigma-mm", "0"), ("--marker-sigma-deg", "-0.5"), ("--floor-sigma-mm", "nan"),
                     ("--floor-tilt-deg", "90"), ("--camera-sigma-mm", "3000"))],
    ("vision-workers-negative", ["vision", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec", "--out", "{o}/v.tum",
                                 "--workers", "-3"], ["--workers"]),
    ("vision-sequence-unknown", ["vision", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec", "--out", "{o}/v.tum",
                                 "--sequence", "runs"], ["--sequence", "runs"]),
    ("vision-detector-unknown", ["vision", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec", "--out", "{o}/v.tum",
                                 "--detector", "magic"], ["--detector"]),
    # gtrig robot-frame
    ("robot-frame-workers-negative", ["robot-frame", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec",
                                      "--out", "{o}/r.yaml", "--workers", "-1"], ["--workers"]),
    # gtrig calib
    ("calib-intrinsics-board-garbage", ["calib", "intrinsics", "--images", "{d}/images", "--board", "big",
                                        "--out", "{o}/cam.yaml"], ["--board"]),
    ("calib-intrinsics-board-mm", ["calib", "intrinsics", "--images", "{d}/images", "--board", "9x5x100",
                                   "--out", "{o}/cam.yaml"], ["--board", "millimetres"]),
    ("calib-intrinsics-board-1x1", ["calib", "intrinsics", "--images", "{d}/images", "--board", "1x1x0.1",
                                    "--out", "{o}/cam.yaml"], ["--board"]),
    *[(f"calib-steady-{opt[2:]}-{v}", ["calib", "steady", "--before", "{d}/images", "--after", "{d}/images",
                                       "--rig", "{d}/rig.yaml", opt, v], [opt])
      for opt, v in (("--shift-px", "nan"), ("--shift-px", "-1"), ("--move-mm", "nan"), ("--move-mm", "0"),
                     ("--turn-deg", "nan"), ("--turn-deg", "-0.02"))],
    ("calib-check-tol-nan", ["calib", "check", "--rig", "{d}/rig.yaml", "--images", "{d}/images",
                             "--truth", "{d}/ref.csv", "--tol-mm", "nan"], ["--tol-mm"]),
    # gtrig markers
    ("markers-make-size-nan", ["markers", "make", "--family", "artoolkitplus_simple", "--id", "3", "--size-mm", "nan",
                               "--out", "{o}/m.svg"], ["--size-mm", "finite"]),
    ("markers-make-size-metres", ["markers", "make", "--family", "artoolkitplus_simple", "--id", "3",
                                  "--size-mm", "0.16", "--out", "{o}/m.svg"], ["--size-mm", "metres given"]),
    ("markers-make-size-negative", ["markers", "make", "--family", "artoolkitplus_simple", "--id", "3",
                                    "--size-mm", "-50", "--out", "{o}/m.svg"], ["--size-mm"]),
    ("markers-make-id-negative", ["markers", "make", "--family", "artoolkitplus_simple", "--id", "-1",
                                  "--size-mm", "100", "--out", "{o}/m.svg"], ["--id"]),
    ("markers-make-dpi-nan", ["markers", "make", "--family", "artoolkitplus_simple", "--id", "3", "--size-mm", "100",
                              "--dpi", "nan", "--out", "{o}/m.png"], ["--dpi"]),
    ("markers-make-family-unknown", ["markers", "make", "--family", "qr", "--id", "3", "--size-mm", "100",
                                     "--out", "{o}/m.svg"], ["--family"]),
    ("markers-make-suffix", ["markers", "make", "--family", "artoolkitplus_simple", "--id", "3", "--size-mm", "100",
                             "--out", "{o}/m.txt"], ["m.txt"]),
    *[(f"markers-calibrate-robot-{name}", ["markers", "calibrate-robot", "--images", "{d}/images",
                                           "--camera", "{d}/cam.yaml", "--out", "{o}/markers.yaml", *extra], must)
      for name, extra, must in (
          ("side-metres", ["--side-mm", "14=0.16", "--anchor-pose", "0,0,0.5,0,0,0"], ["--side-mm", "metres given"]),
          ("side-nan", ["--side-mm", "14=nan", "--anchor-pose", "0,0,0.5,0,0,0"], ["--side-mm", "finite"]),
          ("side-garbage", ["--side-mm", "14:160", "--anchor-pose", "0,0,0.5,0,0,0"], ["--side-mm", "ID=MM"]),
          ("anchor-pose-nan", ["--side-mm", "14=160", "--anchor-pose", "nan,0,0.5,0,0,0"], ["--anchor-pose", "finite"]),
          ("anchor-pose-mm", ["--side-mm", "14=160", "--anchor-pose", "100,50,300,0,0,0"],
           ["--anchor-pose", "millimetres"]),
          ("anchor-pose-short", ["--side-mm", "14=160", "--anchor-pose", "1,2,3"], ["--anchor-pose"]),
          ("anchor-sigma-nan", ["--side-mm", "14=160", "--anchor-pose", "0,0,0.5,0,0,0", "--anchor-sigma-mm", "nan"],
           ["--anchor-sigma-mm"]),
          ("anchor-sigma-negative", ["--side-mm", "14=160", "--anchor-pose", "0,0,0.5,0,0,0",
                                     "--anchor-sigma-deg", "-1"], ["--anchor-sigma-deg"]),
          ("rig-out-without-rig", ["--side-mm", "14=160", "--rig-out", "{o}/r.yaml"], ["--rig-out"]),
          ("no-markers", ["--anchor-pose", "0,0,0.5,0,0,0"], ["--rig", "--side-mm"]),
      )],
    # gtrig laser
    ("laser-track-sequence", ["laser", "track", "--rig", "{d}/rig.yaml", "--recording", "{d}/rec", "--out", "{o}/l.tum",
                              "--sequence", "calib"], ["--sequence"]),
    # gtrig evaluate
    ("evaluate-poses-max-dt-nan", ["evaluate", "poses", "--reference", "{d}/ref.tum", "--estimate", "{d}/est.tum",
                                   "--max-dt", "nan"], ["--max-dt"]),
    ("evaluate-poses-max-dt-negative", ["evaluate", "poses", "--reference", "{d}/ref.tum", "--estimate",
                                        "{d}/est.tum", "--max-dt", "-1"], ["--max-dt"]),
    ("evaluate-poses-format", ["evaluate", "poses", "--reference", "{d}/ref.tum", "--estimate", "{d}/est.tum",
                               "--format", "xml"], ["--format"]),
    *[(f"evaluate-slam-{opt[2:]}-{v}", ["evaluate", "slam", "--gt", "{d}/ref.tum", "--estimate", "{d}/est.tum", opt, v],
       [opt]) for opt, v in (("--max-dt", "nan"), ("--max-dt", "0"), ("--rpe-delta", "0"), ("--align", "affine"),
                             ("--metrics", "best"), ("--associate", "magic"), ("--t-offset", "nan"),
                             ("--t-offset", "soon"), ("--align-interval", "5,1"), ("--align-interval", "nan,3"))],
    *[(f"evaluate-compare-{opt[2:]}-{v}", ["evaluate", "compare", "--a", "{d}/ref.tum", "--b", "{d}/est.tum", opt, v],
       [opt]) for opt, v in (("--max-gap", "nan"), ("--max-gap", "-1"), ("--t-offset", "inf"), ("--align", "x"))],
    # gtrig import / export
    ("import-image-format", ["import", "rosbag", "{d}/bin.bag", "--topics", "{d}/bin.yaml", "--out", "{o}/rec",
                             "--image-format", "gif"], ["--image-format"]),
    ("import-stamp", ["import", "rosbag", "{d}/bin.bag", "--topics", "{d}/bin.yaml", "--out", "{o}/rec",
                      "--stamp", "now"], ["--stamp"]),
    ("export-to-unknown", ["export", "{d}/ref.tum", "--to", "gpx", "--out", "{o}/x.gpx"], ["--to"]),
    ("export-storage-unknown", ["export", "{d}/ref.tum", "--to", "rosbag2", "--storage", "tape", "--out", "{o}/b"],
     ["--storage"]),
    ("export-from-unknown", ["export", "{d}/ref.tum", "--to", "kitti", "--from", "gpx", "--out", "{o}/x.kitti"],
     ["--from"]),
    # gtrig sync / fuse
    *[(f"sync-search-{v}", ["sync", "--recording", "{d}/rec", "--source", "vision={d}/est.tum,{d}/est_cov.csv",
                            "--out", "{o}/sync.yaml", "--search-s", v], ["--search-s"]) for v in ("nan", "0", "-3")],
    ("sync-source-no-name", ["sync", "--recording", "{d}/rec", "--source", "{d}/est.tum", "--out", "{o}/sync.yaml"],
     ["--source"]),
    *[(f"fuse-{opt[2:]}-{v}", ["fuse", "--vision", "{d}/est.tum", "--vision-cov", "{d}/est_cov.csv", "--odometry",
                               "{d}/odometry.csv", "--out", "{o}/gt.tum", "--covariance", "{o}/gt_cov.csv", opt, v],
       [opt])
      for opt, v in (("--max-gap", "nan"), ("--max-gap", "-1"), ("--rate", "nan"), ("--rate", "0"),
                     ("--rate", "fast"), ("--estimator", "ukf"))],
    ("fuse-vision-without-cov", ["fuse", "--vision", "{d}/est.tum", "--odometry", "{d}/odometry.csv",
                                 "--out", "{o}/gt.tum", "--covariance", "{o}/gt_cov.csv"], ["--vision-cov"]),
    # gtrig gps
    *[(f"gps-{opt[2:]}-{v}", ["gps", "--log", "{d}/bin.nmea", "--out", "{o}/g.tum", "--covariance", "{o}/g_cov.csv",
                              opt, v], [opt])
      for opt, v in (("--max-sigma", "nan"), ("--max-sigma", "-1"), ("--max-malformed", "nan"),
                     ("--max-malformed", "2"), ("--origin", "nan,9,100"), ("--origin", "45,9"),
                     ("--antenna-lever-arm", "0,0,nan"), ("--antenna-lever-arm", "0,0,1200"), ("--fix", "rtk"),
                     ("--frame", "ecef"), ("--clock", "gps"), ("--format", "ubx"))],
    # gtrig scanmatch
    *[(f"scanmatch-pairs-{opt[2:]}-{v}", ["scanmatch", "pairs", "--recording", "{d}/rec", "--out", "{o}/rel.csv",
                                          opt, v], [opt])
      for opt, v in (("--max-dist", "nan"), ("--max-dist", "0"), ("--max-angle", "nan"), ("--max-angle", "400"),
                     ("--every", "0"), ("--max-pairs", "-5"), ("--sequence", "calib"))],
    ("scanmatch-validate-reference-0", ["scanmatch", "validate", "--recording", "{d}/rec", "--out", "{o}/p.csv",
                                        "--reference", "0"], ["--reference"]),
    # gtrig survey (the policy options)
    ("survey-points-on-ambiguity", ["survey", "points", "--reference", "{d}/ref.csv", "--distances", "{d}/d.csv",
                                    "--out", "{o}/p.csv", "--on-ambiguity", "guess"], ["--on-ambiguity"]),
    ("survey-poses-on-outlier", ["survey", "poses", "--points", "{d}/points.csv", "--robot-points", "{d}/rp.csv",
                                 "--distances", "{d}/pd.csv", "--out", "{o}/p.csv", "--on-outlier", "ignore"],
     ["--on-outlier"]),
    ("survey-adjust-reference-sigma-nan", ["survey", "adjust", "--reference", "{d}/ref.csv", "--distances",
                                           "{d}/d.csv", "--robot-points", "{d}/rp.csv", "--pose-distances",
                                           "{d}/pd.csv", "--out-points", "{o}/a.csv", "--out-poses", "{o}/b.csv",
                                           "--reference-sigma", "nan"], ["--reference-sigma"]),
    ("survey-predict-margin-negative", ["survey", "predict", "--points", "{d}/points.csv", "--robot-points",
                                        "{d}/rp.csv", "--margin", "-1"], ["--margin"]),
    ("survey-predict-sigma-nan", ["survey", "predict", "--points", "{d}/points.csv", "--robot-points", "{d}/rp.csv",
                                  "--sigma", "nan"], ["--sigma"]),
]


@pytest.mark.parametrize(("args", "must"), [c[1:] for c in CASES], ids=case_ids(CASES))
def test_option_refused_before_work(d: Path, tmp_path: Path, args: list[str], must: list[str]) -> None:
    refused(args, d, tmp_path / "o", 2, must)
