"""Cameras' time offsets from a hand-moved board's motion (:mod:`gtrig.vision.body_timing`), against the truth.

Per seed, a 12-corner board sways by hand (three sine sways per axis and per rotation, 0.15 Hz to
``--fmax``) in front of four fixed cameras at 6 frames/s; the cameras are exposed -30, +22 and +21 ms
after cam_0, each frame stamped with a few milliseconds of jitter (known: the stamps carry it), corners with
0.3 px noise. ``--exposure-jitter-ms``: each image is also exposed up to that many milliseconds (uniform)
before or after its camera's offset, not in its stamp (a webcam whose frames are taken from a faster
stream). ``--drift``: each camera's exposures also slide against its stamps at a constant rate (cam_1
-4, cam_2 +2.5, cam_3 +1 ms per second, about the recording's midpoint: a skewed clock or a stamping
latency that changes), estimated as offsets at the midpoint and drifts. ``--reach``: the local motions run
through that many poses on each side of an instant (:func:`gtrig.vision.body_timing.local_motion`; 2 is the
degree-4 polynomial through five poses). Printed per seed: each camera's
offset error and stated sigma (and the drift's); then the coverage of the 95 % intervals over seeds, with
the stated sigma and with the variance factor's alone, and the RMS z-score.

    python bench/body_timing.py [--seeds 0 1 ... 39] [--fmax 1.0] [--exposure-jitter-ms 16.7] [--drift] [--reach 3]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.vision.body import BodyOptions, BodyView, PointBody, camera_geometry
from gtrig.vision.body_timing import CameraTiming, estimate_timing
from gtrig.vision.body_track import group_instants, track_body

K = np.array([[900.0, 0, 640], [0, 900.0, 360], [0, 0, 1]])
DIST = np.array([-0.1, 0.05, 0, 0, 0.0])
SQUARE_M = 0.054
BOARD = PointBody("board", np.array([[(c + 1) * SQUARE_M, (r + 1) * SQUARE_M, 0.0]
                                     for r in range(4) for c in range(3)]))
OFFSET_S = {"cam_0": 0.0, "cam_1": -0.030, "cam_2": 0.022, "cam_3": 0.021}
DRIFT_S_PER_S = {"cam_0": 0.0, "cam_1": -0.004, "cam_2": 0.0025, "cam_3": 0.001}
FPS = 6.0

CAMS = {f"cam_{i}": camera_geometry(f"cam_{i}", K, DIST, geo.look_at(c, np.zeros(3)), (1280, 720))
        for i, c in enumerate(np.array([[1.2, 0, 0.4], [0, 1.1, 0.5], [-0.9, -0.8, 0.3], [0.8, -1.0, 0.6]]))}


def hand_motion(rng: np.random.Generator, fmax_hz: float) -> Callable[[float], np.ndarray]:
    """``T_world_board(t)`` of a hand's sway: per axis, three sines of random frequency and phase, the
    translations' amplitudes falling with frequency (speeds up to about 0.3 m/s, 1 rad/s)."""
    f = rng.uniform(0.15, fmax_hz, (6, 3))
    phase = rng.uniform(0, 2 * np.pi, (6, 3))
    amp_m = 0.3 * rng.uniform(0.02, 0.08, (3, 3)) / np.maximum(f[:3], 0.3)
    amp_rad = rng.uniform(0.1, 0.3, (3, 3))

    def T_world_board(t: float) -> np.ndarray:
        c = np.sum(amp_m * np.sin(2 * np.pi * f[:3] * t + phase[:3]), axis=0)
        R = Rotation.from_rotvec(np.sum(amp_rad * np.sin(2 * np.pi * f[3:] * t + phase[3:]), axis=0)).as_matrix()
        return geo.make_T(R, c - R @ np.array([2 * SQUARE_M, 2.5 * SQUARE_M, 0.0]))

    return T_world_board


def run_seed(seed: int, fmax_hz: float, exposure_jitter_s: float, drift: bool = False, n: int = 44,
             sigma_px: float = 0.3, stamp_jitter_s: float = 0.005, reach: int = 3) -> CameraTiming:
    """One recording of ``n`` instants (module docstring) and its timing, fitted with drifts if ``drift``."""
    rng = np.random.default_rng(seed)
    T_world_board = hand_motion(rng, fmax_hz)
    mid_s = (n - 1) / FPS / 2
    pairs = []
    for i in range(n):
        for name, cam in CAMS.items():
            t_img = i / FPS + rng.uniform(-stamp_jitter_s, stamp_jitter_s)
            slide = DRIFT_S_PER_S[name] * (t_img - mid_s) if drift else 0.0
            t_exp = t_img + OFFSET_S[name] + slide + rng.uniform(-exposure_jitter_s, exposure_jitter_s)
            p_cam = np.array([geo.transform_points(cam.T_cam_world @ T_world_board(t_exp), p[None])[0]
                              for p in BOARD.points_body])
            uv = cv2.projectPoints(p_cam, np.zeros(3), np.zeros(3), K, DIST)[0].reshape(-1, 2)
            pairs.append((i, BodyView(name, np.arange(12), uv + rng.normal(0, sigma_px, uv.shape), t_img)))
    opts = BodyOptions(sigma_px=sigma_px)
    track = track_body(CAMS, BOARD, group_instants(pairs), opts)
    return estimate_timing(CAMS, BOARD, track.instants, track.poses, "cam_0", line_delay=False, drift=drift,
                           mid_s=mid_s if drift else None, options=opts, reach=reach)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(40)))
    ap.add_argument("--fmax", type=float, default=1.0, help="the sway's highest frequency, Hz")
    ap.add_argument("--exposure-jitter-ms", type=float, default=0.0)
    ap.add_argument("--drift", action="store_true", help="the cameras' offsets drift; fit the drifts")
    ap.add_argument("--reach", type=int, default=3, help="poses on each side of an instant in its local motion")
    a = ap.parse_args()
    z, z_model, z_drift = [], [], []
    for s in a.seeds:
        tm = run_seed(s, a.fmax, a.exposure_jitter_ms / 1000, a.drift, reach=a.reach)
        err = np.array([tm.offset_s[k] - OFFSET_S[c] for k, c in enumerate(tm.cameras)])[1:]
        z.append(err / tm.sigma_offset_s[1:])
        z_model.append(err / tm.sigma_offset_model_s[1:])
        text = "  ".join(f"{c} {1000 * e:+.2f} / {1000 * sg:.2f}" for c, e, sg in zip(tm.cameras[1:], err,
                                                                                      tm.sigma_offset_s[1:],
                                                                                      strict=True))
        if a.drift:
            err_d = np.array([tm.drift_s_per_s[k] - DRIFT_S_PER_S[c] for k, c in enumerate(tm.cameras)])[1:]
            z_drift.append(err_d / tm.sigma_drift_s_per_s[1:])
            text += "; drift (ms/s) " + "  ".join(f"{1000 * e:+.2f} / {1000 * sg:.2f}" for e, sg in
                                                  zip(err_d, tm.sigma_drift_s_per_s[1:], strict=True))
        print(f"seed {s}: error / sigma (ms) {text}; variance factor {tm.variance_factor:.2f}", flush=True)
    rows = [("stated", z), ("variance factor only", z_model)] + ([("drifts, stated", z_drift)] if a.drift else [])
    for label, zs in rows:
        zz = np.abs(np.array(zs))
        print(f"{label}: {np.mean(zz < 1.96):.1%} of {zz.size} 95 % intervals cover; "
              f"RMS z {np.sqrt(np.mean(zz**2)):.2f}")


if __name__ == "__main__":
    main()
