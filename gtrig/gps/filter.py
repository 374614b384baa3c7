"""Fix-aware filtering: which epochs are ground truth, and why the others are not.

Three tests, in order, each naming its reason on the epochs it refuses:

1. fix type: ``fixed`` keeps RTK fixed-integer fixes only (GGA quality 4), the only ones good to a
   few centimetres (RAWSEEDS deliverable, "Outdoor Ground Truth"); ``float`` adds RTK float (5);
   ``any`` keeps every fix with a position (1, 2, 3, 4, 5, 9).
2. the receiver's sigmas: the latitude and longitude 1-sigma must both be below ``max_sigma_m``
   (0.2 m: the RAWSEEDS toolkit's read_gps.m cut); without GST, the HDOP model's.
3. multipath outliers (the RTK float and code fixes only): a fix is compared with a robust local
   fit of the other kept fixes within ``window_s`` (a quadratic in time per axis, Tukey-weighted, so
   a reflected-path block of a few epochs does not drag it); the normalised squared residual over
   the chi-square gate (3 dof) rejects it.
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
    window_s : half-width of the outlier test's local fit, seconds.
    """

    fix: FixKind = "fixed"
    max_sigma_m: float | None = 0.2
    outlier_gate: float | None = GATE_3DOF
    window_s: float = 2.0


def _outliers(t: np.ndarray, xyz: np.ndarray, cov: np.ndarray, testable: np.ndarray, opts: FilterOptions,
              ) -> np.ndarray:
    """Indices (into the arrays) rejected as outliers: each testable fix against a robust local fit.

    For fix ``i`` the other fixes within ``window_s`` are fitted, per axis, with a quadratic in time
    (a path with bounded acceleration through a turn) by iteratively reweighted least squares with
    Tukey's biweight (c = 4.685 sigmas, started from a Huber fit), which ignores a multipath block of
    up to about a third of
    the window; fix ``i`` itself is left out. Its normalised squared residual, with the fit's
    prediction variance added to its own, over ``outlier_gate`` (3 dof) rejects it. Fixes with fewer
    than 5 neighbours are not judged.
    """
    n = t.size
    w_s = opts.window_s
    lo = np.searchsorted(t, t - w_s, "left")
    hi = np.searchsorted(t, t + w_s, "right")
    K = int(np.max(hi - lo)) if n else 0
    if n < 6 or K < 6:
        return np.zeros(0, np.int64)
    j = lo[:, None] + np.arange(K)[None, :]
    valid = (j < hi[:, None]) & (j != np.arange(n)[:, None])
    j = np.minimum(j, n - 1)
    tau = np.where(valid, t[j] - t[:, None], 0.0)
    # one side is enough (the start of a float stretch after a loss): the fit's prediction variance
    # grows by itself when it extrapolates
    judged = testable & (valid.sum(axis=1) >= 5)
    A = np.stack([np.ones_like(tau), tau, tau * tau], axis=-1)  # (n, K, 3)
    var = np.diagonal(cov, axis1=1, axis2=2)  # (n, 3) per-axis variances
    nis = np.zeros(n)
    for ax in range(3):
        y = xyz[j, ax]
        s2 = var[j, ax] + 1e-12
        w = np.where(valid, 1.0 / s2, 0.0)
        # a convex start (Huber, k = 1.345) so that Tukey's redescending weights begin near the path
        for it in range(7):
            N = np.einsum("nki,nk,nkj->nij", A, w, A) + 1e-12 * np.eye(3)
            b = np.einsum("nki,nk,nk->ni", A, w, y)
            coef = np.linalg.solve(N, b[..., None])[..., 0]
            r = np.abs(y - np.einsum("nki,ni->nk", A, coef)) / np.sqrt(s2)
            if it < 3:
                w = np.where(valid, np.minimum(1.0, 1.345 / np.maximum(r, 1e-12)) / s2, 0.0)
            else:
                u = r / 4.685
                w = np.where(valid & (u < 1), (1 - u * u) ** 2 / s2, 0.0)
        N = np.einsum("nki,nk,nkj->nij", A, w, A) + 1e-12 * np.eye(3)
        b = np.einsum("nki,nk,nk->ni", A, w, y)
        coef = np.linalg.solve(N, b[..., None])[..., 0]
        var_pred = np.linalg.inv(N)[:, 0, 0]
        nis += (xyz[:, ax] - coef[:, 0]) ** 2 / (var[:, ax] + var_pred)
    gate = GATE_3DOF if opts.outlier_gate is None else opts.outlier_gate
    return np.flatnonzero(judged & (nis > gate))


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

    finite = np.all(np.isfinite(ep.cov_enu), axis=(1, 2)) & (ep.cov_enu[:, 0, 0] > 0) & (ep.cov_enu[:, 1, 1] > 0)
    refuse(~finite, "no covariance (no usable GST, no HDOP)")
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
