"""The four real webcams' lenses from three recordings of a hand-held ChArUco board, compared.

The recordings (../shared/data/multicam_real/caliscope): the two extrinsic sessions (``charuco_calibration``,
``post_optimization``) and the per-camera intrinsic videos (``prerecorded_calibration``, no frame-time
file: stamped here at the video's nominal rate; cam_1's is mirrored, and flipped back). Per camera and
recording: the lens of :func:`gtrig.calib.video_calib.fit_lens` (every ``--step``-th frame), its
reprojection RMS against caliscope's stated ``error``, fx fy cx cy with OpenCV's, the single-view and the
1 s block jackknife's sigmas. Per pair of recordings and camera: the largest difference in combined sigmas
with each kind of sigma (:mod:`gtrig.calib.lens_compare`), and the RMS of all differences.

Then whether the lens itself differs: one lens is fitted to every recording's views of the camera, and the
focal length of each single view is refitted with that lens's principal point, aspect ratio and distortion
held (its pose free). Averaged over 1 s blocks (a second's views share their errors), the recordings' mean
focal lengths are compared in combined standard errors of the block means: a refocused or zoomed lens
shifts them, the trade of focal length against principal point and distortion in a few-view fit does not.
The single views' focal lengths' correlation between views 0-0.5 s, 0.5-1 s, ... apart shows how long a
video's views share their errors.

    python bench/lens_sessions.py [--step 2]
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
from pathlib import Path

import cv2
import numpy as np

from gtrig.calib.charuco import read_board_file
from gtrig.calib.intrinsics import calibrate_point_sets
from gtrig.calib.lens_compare import compare_lenses
from gtrig.calib.video_calib import LENS_BLOCK_S, MIN_LENS_CORNERS, fit_lens
from gtrig.calib.video_detect import VideoDetections, detect_videos, find_videos
from gtrig.calib.view_jackknife import time_blocks
from gtrig.io.caliscope import read_caliscope_cameras
from gtrig.io.camfile import CameraIntrinsics

ROOT = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "multicam_real" / "caliscope"
RECORDINGS = {"first": "charuco_calibration/calibration/extrinsic", "second": "post_optimization/calibration/extrinsic",
              "intrinsic": "prerecorded_calibration/calibration/intrinsic"}
MIRRORED = {"intrinsic": ("cam_1",)}  # the webcam's mirror mode was on for this video only
KEYS = ("fx", "fy", "cx", "cy")
# single-view focal lengths less certain than this share of the focal length are left out (a board nearly
# parallel to the image plane cannot tell focal length from distance)
MAX_VIEW_F_SIGMA = 0.05


def stamped_copy(folder: Path, tmp: Path) -> Path:
    """``folder``'s videos linked into ``tmp`` with plain frame-time files at each video's nominal rate."""
    for v in sorted(folder.glob("*.mp4")):
        cap = cv2.VideoCapture(str(v))
        n, fps = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), cap.get(cv2.CAP_PROP_FPS)
        cap.release()
        (tmp / v.name).symlink_to(v.resolve())
        (tmp / f"{v.stem}.timestamps.csv").write_text(
            "frame,stamp_s\n" + "".join(f"{i},{i / fps:.6f}\n" for i in range(n)))
    return tmp


def view_focals(views: list[tuple[np.ndarray, np.ndarray, float]], lens: CameraIntrinsics) -> np.ndarray:
    """(V, 3) stamp, focal length and its sigma (pixels) of each view refitted alone with ``lens``'s principal
    point, aspect ratio and distortion held; views whose focal length is unobservable left out."""
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_ASPECT_RATIO
             | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_FIX_TANGENT_DIST)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rows = []
    for obj, img, t in views:
        r = cv2.calibrateCameraExtended([obj.astype(np.float32)], [img.astype(np.float32).reshape(-1, 1, 2)],
                                        lens.image_size, lens.camera_matrix.copy(), lens.dist_coeffs.copy(),
                                        flags=flags, criteria=crit)
        sd = float(np.max(np.ravel(r[5])[:2]))
        if sd < MAX_VIEW_F_SIGMA * lens.camera_matrix[0, 0]:
            rows.append((t, float(r[1][0, 0]), sd))
    return np.array(rows).reshape(-1, 3)


def lag_correlation(f: np.ndarray) -> str:
    """The correlation of the single-view focal lengths' normalised deviations (``f`` as from
    :func:`view_focals`) between views 0-0.5, 0.5-1, 1-1.5 and 1.5-3 s apart."""
    w = 1 / f[:, 2] ** 2
    z = (f[:, 1] - np.sum(w * f[:, 1]) / w.sum()) / f[:, 2]
    dt = np.abs(f[:, 0][:, None] - f[:, 0][None, :])
    out = []
    for lo, hi in ((0, 0.5), (0.5, 1.0), (1.0, 1.5), (1.5, 3.0)):
        i, j = np.nonzero((dt > max(lo, 1e-6)) & (dt <= hi + 1e-6))
        out.append(f"{np.mean(z[i] * z[j]) / np.mean(z**2):+.2f}" if i.size >= 6 else "-")
    return " / ".join(out)


def shared_lens_focals(dets: dict[str, VideoDetections], P: np.ndarray) -> None:
    """Print one camera's shared lens and each recording's 1 s block means of the single-view focal lengths."""
    views = {r: [(P[v.ids], v.corners_px, float(t)) for v, t in zip(d.views, d.stamps_s, strict=True)
                 if len(v.ids) >= MIN_LENS_CORNERS] for r, d in dets.items()}
    alls = [x for r in views for x in views[r]]
    size = next(iter(dets.values())).image_size
    for k3 in (True, False):  # the lens without k3 (gtrig's default) last: its single views are refitted
        fit = calibrate_point_sets([x[0] for x in alls], [x[1] for x in alls], [str(i) for i in range(len(alls))],
                                   size, estimate_k3=k3)
        K = fit.camera.camera_matrix
        rec = np.repeat(list(views), [len(v) for v in views.values()])[[int(n) for n in fit.names]]
        n_c = np.array([len(alls[int(n)][0]) for n in fit.names])
        rms = {r: float(np.sqrt(np.sum((n_c * fit.per_view_rms_px**2)[rec == r]) / n_c[rec == r].sum()))
               for r in views}
        print(f"  one lens{' with k3' if k3 else ''} for {', '.join(views)}: fx {K[0, 0]:.1f} fy {K[1, 1]:.1f} "
              f"cx {K[0, 2]:.1f} cy {K[1, 2]:.1f} px, RMS {fit.camera.rms_px:.3f} px over {len(fit.names)} views ("
              + ", ".join(f"{r} {v:.3f}" for r, v in rms.items()) + ")")
    mean = {}
    for r, vs in views.items():
        f = view_focals(vs, fit.camera)
        b = np.array([f[g, 1].mean() for g in time_blocks(f[:, 0], LENS_BLOCK_S)])
        if b.size >= 3:
            mean[r] = (b.mean(), b.std(ddof=1) / np.sqrt(b.size))
            print(f"    {r}: single-view focal {mean[r][0]:.1f} ± {mean[r][1]:.1f} px over {b.size} blocks "
                  f"({f.shape[0]} views; block means in time order {np.round(b).astype(int).tolist()}); "
                  f"correlation of views 0-0.5 / 0.5-1 / 1-1.5 / 1.5-3 s apart {lag_correlation(f)}")
    for a, b_ in itertools.combinations(mean, 2):
        d = mean[a][0] - mean[b_][0]
        print(f"    {a} - {b_}: {d:+.1f} px, {abs(d) / np.hypot(mean[a][1], mean[b_][1]):.2f} combined sigma")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step", type=int, default=2, help="read every n-th frame")
    args = ap.parse_args()
    board = read_board_file(ROOT / "charuco_calibration" / "charuco.toml")
    P = board.object_points()
    peer = read_caliscope_cameras(ROOT / "post_optimization" / "camera_array.toml")
    with tempfile.TemporaryDirectory() as tmp:
        dets = {}
        for r, sub in RECORDINGS.items():
            folder = ROOT / sub
            if not any(folder.glob("*timestamps.csv")):
                folder = stamped_copy(folder, Path(tmp))
            dets[r] = detect_videos(find_videos(folder), board, args.step, MIRRORED.get(r, ()))
    cams = sorted(dets["first"])
    lenses: dict[str, dict[str, CameraIntrinsics]] = {r: {} for r in dets}
    for c in cams:
        print(f"{c} (caliscope's error {peer[c].error_px:.3f} px)")
        for r in dets:
            if sum(len(v.ids) >= MIN_LENS_CORNERS for v in dets[r][c].views) < 6:
                print(f"  {r}: too few views")
                continue
            f = fit_lens(dets[r][c], board)
            lenses[r][c] = lens = f.camera
            K, x = lens.camera_matrix, lens.extra
            vals = (K[0, 0], K[1, 1], K[0, 2], K[1, 2])
            print(f"  {r}: {len(f.names)} views, RMS {lens.rms_px:.3f} px; " + "; ".join(
                f"{k} {v:.1f} ({x['std'][k]:.1f} / {x['std_views'][k]:.1f} / {x['std_blocks'][k]:.1f})"
                for k, v in zip(KEYS, vals, strict=True)))
            own = view_focals([(P[v.ids], v.corners_px, float(t)) for v, t in zip(dets[r][c].views, dets[r][c].stamps_s,
                                                                                strict=True)
                               if len(v.ids) >= MIN_LENS_CORNERS], lens)
            z = f.T_cam_board[:, 2, 3]
            print(f"    single-view focal with this lens {own[:, 1].min():.0f}-{own[:, 1].max():.0f} px over "
                  f"{np.ptp(own[:, 0]):.1f} s; board {z.min():.2f}-{z.max():.2f} m away")
        shared_lens_focals({r: dets[r][c] for r in dets if c in lenses[r]}, board.object_points())
    print("largest difference between recordings per camera, combined sigmas (OpenCV / max with the "
          "single-view jackknife / std_honest, the block jackknife's too):")
    every: list[list[float]] = [[], [], []]
    for a, b in itertools.combinations(dets, 2):
        worst: dict[str, list[str]] = {}
        for i, kinds in enumerate((("std",), ("std", "std_views"), ("std", "std_views", "std_blocks"))):
            la, lb = ({c: with_sigmas(v, kinds) for c, v in lenses[r].items()} for r in (a, b))
            every[i] += [d.z for d in compare_lenses(la, lb)]
            for c in sorted(set(la) & set(lb)):
                d = max((d for d in compare_lenses(la, lb) if d.camera == c), key=lambda d: d.z)
                worst.setdefault(c, []).append(f"{d.z:.2f} {d.parameter}")
        print(f"  {a} - {b}: " + "; ".join(f"{c} " + " / ".join(w) for c, w in worst.items()))
    print("  RMS of all " + str(len(every[0])) + " differences: " + " / ".join(
        f"{np.sqrt(np.mean(np.square(z))):.2f}" for z in every) + " (1 when the sigmas are right, correlated)")


def with_sigmas(lens: CameraIntrinsics, kinds: tuple[str, ...]) -> CameraIntrinsics:
    """``lens`` whose ``std_honest`` is the largest of its sigmas ``kinds`` (``std``, ``std_views``, ...)."""
    honest = {k: max(lens.extra[n][k] for n in kinds) for k in KEYS}
    return CameraIntrinsics(lens.image_size, lens.camera_matrix, lens.dist_coeffs, lens.rms_px,
                            {"std_honest": honest})


if __name__ == "__main__":
    main()
