"""ChArUco corners on the simulator's intrinsic sweeps, against the truth.

Per seed and camera, ``--views`` hand-held board poses are drawn as the simulator draws its sweeps
(:func:`gtrig.sim.cameras.sample_intrinsic_poses`) and rendered twice, with the simulator's ChArUco board
(``calib_board: charuco``) and with its chessboard. Printed: the corner RMS (2-D, pixels) against the
projected truth of OpenCV's ChArUco corners, of gtrig's (OpenCV's refined on their saddles,
:class:`gtrig.calib.charuco.CharucoCornerDetector`) and of the chessboard's
(:func:`gtrig.calib.chessboard.detect_corners`); the share of ChArUco corners refined;
the median NEES / 2 of the refined corners with their stated covariances (1 when they fit the errors);
each camera's lens calibrated from the refined ChArUco corners and from the chessboard's
(:func:`gtrig.calib.intrinsics.calibrate_point_sets`), and the mean over cameras of the NEES / 4 of its
fx, fy, cx, cy against the simulator's true lens with OpenCV's sigmas (corners independent).

    python bench/calib_charuco.py [--seeds 0 1 2] [--views 12]
"""

from __future__ import annotations

import argparse

import numpy as np

from gtrig import geometry as geo
from gtrig.calib.charuco import CharucoCornerDetector
from gtrig.calib.chessboard import Board, detect_corners
from gtrig.calib.intrinsics import calibrate_point_sets
from gtrig.sim.cameras import make_view, render_faces_frame, sample_intrinsic_poses
from gtrig.sim.config import SimConfig
from gtrig.sim.gtroom import make_scene
from gtrig.sim.render import PinholeCamera
from gtrig.sim.textures import (
    board_face,
    board_object_points,
    board_outline_board,
    charuco_face,
    sim_charuco_board,
)


def seed_errors(seed: int, n_views: int) -> dict[str, list[np.ndarray]]:
    """Per corner kind (``opencv``, ``refined``, ``nees``, ``refined_ok``, ``chessboard``), arrays over views."""
    ccfg = SimConfig(seed=seed).camera
    scene = make_scene(seed)
    board = sim_charuco_board()
    det = CharucoCornerDetector(board)
    # the ChArUco frame's origin is the outer corner, a square before the chessboard's first inner corner
    P_charuco = board.object_points() - [board.square_m, board.square_m, 0.0]
    chess = Board(board.squares_x - 1, board.squares_y - 1, board.square_m)
    out: dict[str, list[np.ndarray]] = {k: [] for k in ("opencv", "refined", "nees", "refined_ok", "chessboard",
                                                         "lens_nees_charuco", "lens_nees_chessboard")}
    for ci, cam in enumerate(scene.rig_true.cameras):
        pc, T_world_cam = PinholeCamera.from_rig(cam), cam.T_world_cam.matrix()
        views: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {"charuco": [], "chessboard": []}
        view = make_view(scene, pc, T_world_cam, ccfg)
        rng = np.random.default_rng(1000 * seed + ci)
        for T in sample_intrinsic_poses(pc, T_world_cam, n_views, rng):
            extent = geo.transform_points(T, np.vstack([board_object_points(), board_outline_board()]))
            face = charuco_face(T, pc, T_world_cam, ccfg.supersample)
            grey = render_faces_frame(view, [face], ccfg, rng, extent)
            uv = pc.project(T_world_cam, geo.transform_points(T, P_charuco))
            corners, ids, _mc, _mi = det._detector.detectBoard(grey)  # OpenCV's own, the peer
            if ids is None:
                continue
            ids_ = np.asarray(ids).ravel()
            out["opencv"].append(np.asarray(corners).reshape(-1, 2) - uv[ids_])
            v = det.detect(grey)
            if v is None or v.cov_px is None:
                continue
            ok = np.isfinite(v.cov_px[:, 0, 0])
            d = (v.corners_px - uv[v.ids])
            out["refined"].append(d)
            out["refined_ok"].append(ok)
            out["nees"].append(np.einsum("ni,nij,nj->n", d[ok], np.linalg.inv(v.cov_px[ok]), d[ok]))
            views["charuco"].append((P_charuco[v.ids], v.corners_px))
            face = board_face(T, pc, T_world_cam, ccfg.supersample)
            c = detect_corners(render_faces_frame(view, [face], ccfg, rng, extent), chess)
            if c is not None:
                uv_c = pc.project(T_world_cam, geo.transform_points(T, board_object_points()))
                a, b = c - uv_c, c[::-1] - uv_c  # the chessboard's grid is known up to a half turn
                flipped = np.abs(a).mean() >= np.abs(b).mean()
                out["chessboard"].append(b if flipped else a)
                views["chessboard"].append((board_object_points(), c[::-1] if flipped else c))
        for kind, vs in views.items():
            out[f"lens_nees_{kind}"].append(np.array([_lens_nees(vs, pc)]))
    return out


def _lens_nees(views: list[tuple[np.ndarray, np.ndarray]], truth: PinholeCamera) -> float:
    """NEES / 4 of fx, fy, cx, cy calibrated from ``views`` (board points, pixels) against ``truth``."""
    keep = [(P, uv) for P, uv in views if len(P) >= 6]
    fit = calibrate_point_sets([P for P, _ in keep], [uv for _, uv in keep], [str(k) for k in range(len(keep))],
                               truth.size)
    K = fit.camera.camera_matrix
    err = np.array([K[0, 0] - truth.K[0, 0], K[1, 1] - truth.K[1, 1], K[0, 2] - truth.K[0, 2],
                    K[1, 2] - truth.K[1, 2]])
    sd = np.array([fit.std[k] for k in ("fx", "fy", "cx", "cy")])
    return float(np.mean((err / sd) ** 2))


def _rms(parts: list[np.ndarray]) -> float:
    return float(np.sqrt(np.mean(np.sum(np.concatenate(parts) ** 2, axis=1))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--views", type=int, default=12, help="board poses per camera")
    a = ap.parse_args()
    print("| seed | corners | OpenCV ChArUco RMS (px) | gtrig ChArUco RMS (px) | refined | OpenCV / gtrig | "
          "median NEES / 2 | chessboard RMS (px) | gtrig ChArUco / chessboard | lens NEES / 4, ChArUco | "
          "lens NEES / 4, chessboard |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for s in a.seeds:
        e = seed_errors(s, a.views)
        cv, rf, cb = _rms(e["opencv"]), _rms(e["refined"]), _rms(e["chessboard"])
        ok = np.concatenate(e["refined_ok"])
        nees = np.median(np.concatenate(e["nees"])) / 2
        print(f"| {s} | {ok.size} | {cv:.4f} | {rf:.4f} | {100 * ok.mean():.1f} % | {cv / rf:.2f}x | {nees:.2f} | "
              f"{cb:.4f} | {rf / cb:.2f} | {np.mean(e['lens_nees_charuco']):.2f} | "
              f"{np.mean(e['lens_nees_chessboard']):.2f} |", flush=True)


if __name__ == "__main__":
    main()
