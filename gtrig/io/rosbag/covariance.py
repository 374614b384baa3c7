"""gtrig's pose covariances as ROS's ``geometry_msgs/PoseWithCovariance.covariance`` and back.

ROS's 6 x 6 row-major array is over ``(x, y, z, rotation about X, about Y, about Z)``, the rotations
about the fixed axes of the header's frame: the world-frame perturbation gtrig.trajectory uses, so a
``"se3"`` covariance is copied as it is. A planar ``"xyyaw"`` 3 x 3 fills x, y, yaw and states
:data:`UNMEASURED_VAR` for z, roll and pitch (REP 105 planar robots; robot_localization reads a large
variance as "not measured"); a position-only ``"xyz"`` block states it for the three rotations.

Reading back: an all-zero array (what most PoseStamped-derived publishers send) is "no covariance";
gtrig's own planar and position-only patterns come back as ``"xyyaw"`` and ``"xyz"``; anything else
is ``"se3"``, exactly as published (AMCL's zeros for z, roll and pitch included).
"""

from __future__ import annotations

import numpy as np

from gtrig.trajectory import PLANAR_INDEX, CovKind, PoseTrack

#: variance (m^2 or rad^2) stated for the axes a planar or position-only track does not measure
UNMEASURED_VAR = 1.0e6

_XYZ_INDEX = (0, 1, 2)


def _embed(cov: np.ndarray, index: tuple[int, ...]) -> np.ndarray:
    n = len(cov)
    out = np.zeros((n, 6, 6))
    others = [i for i in range(6) if i not in index]
    out[:, others, others] = UNMEASURED_VAR
    i = np.array(index)
    out[:, i[:, None], i[None, :]] = cov
    return out


def to_ros(track: PoseTrack) -> np.ndarray:
    """(N, 36) row-major ROS covariances of ``track`` (zeros where it has none; ``nan`` rows too)."""
    n = len(track)
    if track.cov is None:
        return np.zeros((n, 36))
    if track.cov_kind == "se3":
        C = np.array(track.cov, dtype=float)
    elif track.cov_kind == "xyyaw":
        C = _embed(track.cov, PLANAR_INDEX)
    else:
        C = _embed(track.cov, _XYZ_INDEX)
    C[~np.all(np.isfinite(C), axis=(1, 2))] = 0.0
    return C.reshape(n, 36)


def _is_embedded(C: np.ndarray, index: tuple[int, ...]) -> bool:
    others = [i for i in range(6) if i not in index]
    mask = np.zeros((6, 6), bool)
    mask[np.ix_(index, index)] = True
    o = np.array(others)
    diag_ok = np.all(C[:, o, o] == UNMEASURED_VAR)
    off = ~mask
    off[o, o] = False
    return bool(diag_ok and np.all(C[:, off] == 0.0))


def from_ros(flat: np.ndarray) -> tuple[np.ndarray | None, CovKind]:
    """``(cov, cov_kind)`` from (N, 36) ROS covariances (see the module docstring)."""
    C = np.asarray(flat, dtype=float).reshape(-1, 6, 6)
    if not len(C) or not np.any(C):
        return None, "se3"
    for kind, index in (("xyyaw", PLANAR_INDEX), ("xyz", _XYZ_INDEX)):
        if _is_embedded(C, index):
            i = np.array(index)
            return C[:, i[:, None], i[None, :]].copy(), kind  # type: ignore[return-value]
    return C.copy(), "se3"
