"""Fix-aware filtering: which epochs are ground truth, and why the others are not.

Three tests, in order, each naming its reason on the epochs it refuses:

1. fix type: ``fixed`` keeps RTK fixed-integer fixes only (GGA quality 4), the only ones good to a
   few centimetres (RAWSEEDS deliverable, "Outdoor Ground Truth"); ``float`` adds RTK float (5);
   ``any`` keeps every fix with a position (1, 2, 3, 4, 5, 9).
2. the receiver's sigmas: the latitude and longitude 1-sigma must both be below ``max_sigma_m``
   (0.2 m: the RAWSEEDS toolkit's read_gps.m cut); without GST, the HDOP model's.
3. multipath outliers (the RTK float and code fixes only): a fix is compared with the straight line
   between its kept neighbours (at most ``max_gap_s`` away on each side); the normalised squared
   residual, with the fix's, the neighbours' and a bounded-acceleration motion covariance, over the
   chi-square gate (3 dof) rejects the worst one, and the test is repeated until none is over.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gtrig.gps.epochs import Epochs

FixKind = Literal["fixed", "float", "any"]
FIX_SETS: dict[str, tuple[int, ...]] = {"fixed": (4,), "float": (4, 5), "any": (1, 2, 3, 4, 5, 9)}
#: chi-square 3 dof at 99.9 %
GATE_3DOF = 16.27


@dataclass(frozen=True)
class FilterOptions:
    """Settings of :func:`filter_epochs`.

    Attributes
    ----------
    fix : which fix types are kept (module docstring).
    max_sigma_m : the cut on the receiver's latitude and longitude sigmas; ``None`` for none.
    outlier_gate : chi-square gate of the outlier test (3 dof); ``None`` to skip the test.
    accel_sigma_mps2 : 1-sigma acceleration of the vehicle, for the motion term of the outlier test.
    max_gap_s : neighbours farther than this do not judge a fix.
    """

    fix: FixKind = "fixed"
    max_sigma_m: float | None = 0.2
    outlier_gate: float | None = GATE_3DOF
    accel_sigma_mps2: float = 1.0
    max_gap_s: float = 2.0


def _outliers(t: np.ndarray, xyz: np.ndarray, cov: np.ndarray, testable: np.ndarray, opts: FilterOptions,
              ) -> np.ndarray:
    """Indices (into the arrays) rejected as outliers by the neighbour test."""
    n = t.size
    alive = np.ones(n, bool)
    rejected: list[int] = []
    for _ in range(max(10, n // 20)):
        idx = np.flatnonzero(alive)
        if idx.size < 3:
            break
        tt, pp, cc = t[idx], xyz[idx], cov[idx]
        t0, t1, t2 = tt[:-2], tt[1:-1], tt[2:]
        d1, d2 = t1 - t0, t2 - t1
        w = d1 / (d1 + d2)
        pred = (1 - w)[:, None] * pp[:-2] + w[:, None] * pp[2:]
        r = pp[1:-1] - pred
        # the straight line misses a path of acceleration a by up to a d1 d2 / 2
        s_m = opts.accel_sigma_mps2 * d1 * d2 / 2.0
        S = cc[1:-1] + ((1 - w) ** 2)[:, None, None] * cc[:-2] + (w**2)[:, None, None] * cc[2:]
        S = S + (s_m**2)[:, None, None] * np.eye(3)
        nis = np.einsum("ni,ni->n", r, np.linalg.solve(S, r[..., None])[..., 0])
        ok = testable[idx[1:-1]] & (d1 <= opts.max_gap_s) & (d2 <= opts.max_gap_s)
        nis = np.where(ok, nis, 0.0)
        if not np.any(nis > opts.outlier_gate):
            break
        # remove every fix that is over the gate and the worst among its neighbours, then look again
        left = np.concatenate([[0.0], nis[:-1]])
        right = np.concatenate([nis[1:], [0.0]])
        worst = (nis > opts.outlier_gate) & (nis >= left) & (nis >= right)
        out = idx[1:-1][worst]
        alive[out] = False
        rejected.extend(out.tolist())
    return np.array(sorted(rejected), np.int64)


def filter_epochs(ep: Epochs, xyz: np.ndarray, cov: np.ndarray, opts: FilterOptions) -> tuple[np.ndarray, np.ndarray]:
    """Which epochs are kept: ``(keep (N,) bool, reasons (N,) object strings, '' where kept)``.

    ``xyz`` and ``cov`` are the epochs' positions and covariances in any one metric frame (the
    outlier test needs metres).
    """
    n = len(ep)
    reason = np.full(n, "", dtype=object)

    def refuse(m: np.ndarray, why: np.ndarray | str) -> None:
        new = m & (reason == "")
        reason[new] = why if isinstance(why, str) else why[new]

    allowed = FIX_SETS[opts.fix]
    from gtrig.gps.epochs import FIX_NAMES

    names = np.array([f"fix type {FIX_NAMES.get(int(q), str(q))} ({int(q)}) not asked (--fix {opts.fix})"
                      for q in range(10)], dtype=object)
    refuse(~np.isin(ep.quality, allowed), names[np.clip(ep.quality, 0, 9)])
    if opts.max_sigma_m is not None:
        s_lat = np.where(np.isnan(ep.sigma_lat_m), np.sqrt(ep.cov_enu[:, 1, 1]), ep.sigma_lat_m)
        s_lon = np.where(np.isnan(ep.sigma_lon_m), np.sqrt(ep.cov_enu[:, 0, 0]), ep.sigma_lon_m)
        over = ~((s_lat < opts.max_sigma_m) & (s_lon < opts.max_sigma_m))
        refuse(over, f"receiver sigma >= {opts.max_sigma_m:g} m")
    if opts.outlier_gate is not None:
        cand = np.flatnonzero(reason == "")
        testable = ep.quality[cand] != 4
        if np.any(testable):
            out = _outliers(ep.utc_s[cand], xyz[cand], cov[cand], testable, opts)
            refuse(np.isin(np.arange(n), cand[out]), "multipath outlier (off the path of its neighbours)")
    return reason == "", reason
