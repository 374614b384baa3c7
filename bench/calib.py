"""Camera calibration benchmark: every acceptance figure, per seed.

For each seed, only the calibration part of a recording is simulated (the rigs, ``calib/`` and
``truth/boards.yaml``, as ``gtrig sim`` writes them; ``--views`` sweep views per camera and ``--pairs``
double-board instants per pair), then :func:`gtrig.calib.recording.calibrate_recording` runs on it.
Printed per seed: the worst camera position / orientation error of the joint solution, the camera
farthest down the chain (chain vs joint), the sweeps' reprojection RMS, the worst fx, fy and cx, cy
errors of the single-camera calibration and of the network bundle adjustment, and the 1-sigma
orientation with and without the intrinsics' uncertainty.

Steadiness: the simulator renders the camera that sees the world board (room background and the
board) before, and after a move (2 mm sideways, 2 mm along the optical axis, 0.05 deg pan, 0.05 deg
roll) or none; :func:`gtrig.calib.steady.check_steady` with its default thresholds must flag exactly
the moves.

    python bench/calib.py [--seeds 0 1 2] [--views 120] [--pairs 24] [--work /tmp/gtrig_bench_calib]
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np

from gtrig import geometry as geo
from gtrig.calib.chessboard import read_boards_yaml
from gtrig.calib.recording import calibrate_recording
from gtrig.calib.steady import check_steady
from gtrig.rig.load import dump_rig
from gtrig.rig.models import Pose
from gtrig.sim.config import SimConfig
from gtrig.sim.gtroom import make_scene

MOVES = {
    "steady": geo.T_from_xyz_rpy([0, 0, 0], [0, 0, 0]),
    "2 mm sideways": geo.T_from_xyz_rpy([0.002, 0, 0], [0, 0, 0]),
    "2 mm along axis": geo.T_from_xyz_rpy([0, 0, 0.002], [0, 0, 0]),
    "0.05 deg pan": geo.T_from_xyz_rpy([0, 0, 0], np.radians([0, 0.05, 0])),
    "0.05 deg roll": geo.T_from_xyz_rpy([0, 0, 0], np.radians([0, 0, 0.05])),
}


def simulate_calibration(seed: int, out: Path, views: int, pairs: int) -> Path:
    """Write the calibration part of a simulated recording into ``out`` (skipped when already there)."""
    from gtrig.sim.cameras import write_calibration_sets

    done = out / ".calib_done"
    if done.exists():
        return out
    cfg = SimConfig(seed=seed, n_intrinsic_views=views, n_pair_views=pairs)
    scene = make_scene(seed)
    dump_rig(scene.rig_nominal, out / "rig.yaml")
    dump_rig(scene.rig_true, out / "truth" / "rig.yaml")
    write_calibration_sets(scene, out, cfg)
    done.write_text("ok\n")
    return out


def steadiness(seed: int, rec: Path, rig_cal, work: Path) -> dict[str, bool]:  # noqa: ANN001
    """Render the world-board camera before and after each move; {move: flagged}."""
    from gtrig.sim.cameras import _still_frame, _StillShared

    scene = make_scene(seed)
    cams = [c for c in scene.rig_true.cameras if (rec / "calib" / "world_board" / c.name).is_dir()]
    cam = cams[0]
    T_wb = scene.T_world_board
    sh = _StillShared(scene, SimConfig(seed=seed).camera, seed + 100)
    spec = read_boards_yaml(rec / "calib" / "boards.yaml")
    c_cal = rig_cal.camera(cam.name)
    out: dict[str, bool] = {}
    before = work / "before"
    _still_frame(sh, (cam, [T_wb], str(before / cam.name / "0.png"), 0, 1))
    for k, (name, dT) in enumerate(MOVES.items()):
        moved = cam.model_copy(update={"T_world_cam": Pose.from_matrix(cam.T_world_cam.matrix() @ dT)})
        after = work / f"after{k}"
        _still_frame(sh, (moved, [T_wb], str(after / cam.name / "0.png"), 0, 2 + k))
        res = check_steady(before, after, {cam.name: (c_cal.K, c_cal.dist)}, spec.board)
        r = res[0]
        out[name] = bool(r.moved)
        bs = r.board
        out[name + " detail"] = (  # type: ignore[assignment]
            f"{r.shift_px:.2f} px"
            + ("" if bs is None else f", {bs.move_mm:.2f} mm / {bs.turn_deg:.3f} deg")
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--views", type=int, default=120, help="sweep views per camera")
    ap.add_argument("--pairs", type=int, default=24, help="double-board instants per pair")
    ap.add_argument("--work", type=Path, default=Path("/tmp/gtrig_bench_calib"))
    ap.add_argument("--no-steady", action="store_true", help="skip the steadiness renders")
    ap.add_argument("--sim-only", action="store_true", help="only simulate the recordings")
    a = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    rows, steady_rows = [], []
    for seed in a.seeds:
        rec = a.work / f"seed{seed}_v{a.views}_p{a.pairs}"
        t0 = time.perf_counter()
        simulate_calibration(seed, rec, a.views, a.pairs)
        t_sim = time.perf_counter() - t0
        if a.sim_only:
            print(f"seed {seed}: simulated in {t_sim:.0f} s -> {rec}")
            continue
        t0 = time.perf_counter()
        rig_cal, rep = calibrate_recording(rec)
        t_cal = time.perf_counter() - t0
        tr, net = rep.truth, rep.network
        far = max(net.chain_path, key=lambda n: (len(net.chain_path[n]), n))
        sweep_rms = max(float(x.camera.rms_px) for x in rep.intrinsics.values())
        ba_rms = max(j.rms_px_sweep for j in net.joint.values())
        f0 = max(max(abs(t["sweep_dfx_px"]), abs(t["sweep_dfy_px"])) for t in tr.values())
        c0 = max(max(abs(t["sweep_dcx_px"]), abs(t["sweep_dcy_px"])) for t in tr.values())
        f1 = max(max(abs(t["dfx_px"]), abs(t["dfy_px"])) for t in tr.values())
        c1 = max(max(abs(t["dcx_px"]), abs(t["dcy_px"])) for t in tr.values())
        sd_fix = max(float(np.degrees(np.linalg.norm(j.sigma_rot_rad_fixed_intrinsics))) for j in net.joint.values())
        sd_cx = max(max(j.intrinsics.extra["std"]["cx"], j.intrinsics.extra["std"]["cy"]) for j in net.joint.values())
        sd_cx0 = max(max(x.std["cx"], x.std["cy"]) for x in rep.intrinsics.values())
        sd_all = max(float(np.degrees(np.linalg.norm(j.sigma_rot_rad))) for j in net.joint.values())
        z = max(tr[n]["joint_deg"] / np.degrees(np.linalg.norm(j.sigma_rot_rad)) for n, j in net.joint.items())
        rows.append(
            f"| {seed} | {max(t['joint_mm'] for t in tr.values()):.2f} | "
            f"{max(t['joint_deg'] for t in tr.values()):.3f} | {far}: {tr[far]['chain_mm']:.1f} / "
            f"{tr[far]['joint_mm']:.2f} ({tr[far]['chain_mm'] / tr[far]['joint_mm']:.0f} x) | "
            f"{sweep_rms:.3f} / {ba_rms:.3f} | {f0:.2f} / {c0:.2f} ({sd_cx0:.2f}) | "
            f"{f1:.2f} / {c1:.2f} ({sd_cx:.2f}) | "
            f"{sd_fix:.4f} / {sd_all:.4f} ({z:.1f}) | {t_cal:.0f} |"
        )
        if not a.no_steady:
            st = steadiness(seed, rec, rig_cal, a.work / f"steady{seed}")
            for m in MOVES:
                want = m != "steady"
                steady_rows.append(
                    f"| {seed} | {m} | {st[m + ' detail']} | {'flagged' if st[m] else 'not flagged'} | "
                    f"{'ok' if st[m] == want else 'WRONG'} |"
                )
    if a.sim_only:
        return
    print(f"sweeps of {a.views} views per camera, {a.pairs} double-board instants per pair")
    print()
    print(
        "| seed | worst position error, joint (mm) | worst orientation error, joint (deg) | farthest camera: "
        "chain / joint (mm) | sweep RMS (px): single camera / in the BA | worst fx, fy / cx, cy error, "
        "single camera (px) (worst sigma cx, cy) | worst fx, fy / cx, cy error, network BA (px) (worst sigma "
        "cx, cy) | worst 1-sigma rotation (deg): "
        "intrinsics held / included (worst error / sigma) | calibration time (s) |"
    )
    print("|---" * 9 + "|")
    print("\n".join(rows))
    if steady_rows:
        print()
        print("| seed | move of the world-board camera | image shift, board shift | verdict | |")
        print("|---" * 5 + "|")
        print("\n".join(steady_rows))


if __name__ == "__main__":
    main()
