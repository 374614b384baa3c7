"""The scale of the detector's corner covariances, estimated from the residuals of a whole recording.

A detector's corner covariances (propagated from its edge fits) are at best right in shape and
relative size, rarely in scale: the edge model never fits a real (or simulated) image exactly, and
pixel noise is correlated. A chi-square test against covariances
that are too small refuses good frames; covariances that are too large hide bad ones and make the pose
covariances pessimistic.

The estimate is the classical a-posteriori variance factor of an adjustment (Koch, *Parameter
Estimation and Hypothesis Testing in Linear Models*, ch. 3.2.6; a variance-component estimate with one
component per camera): over all fits of a sequence,

    s_c^2 <- s_c^2 * sum_f chi2_fc / sum_f dof_fc

where ``chi2_fc`` and ``dof_fc`` are camera ``c``'s shares of fit ``f``'s chi-square (corners and the
rig's nuisance priors) and degrees of freedom, shared by the redundancy numbers of its corners.
Everything the corners' covariances do not explain (detector noise and bias, the rig's remaining
errors) is thereby charged to the corners, so that a typical frame's chi-square equals its degrees of
freedom and the consistency test refuses only frames that are worse than typical. A fit's share is
capped at ``cap`` times its dof so that a few wrong frames do not inflate every camera's noise.
Summed over hundreds of fits the factor is precise to a few per cent.

One step, from the detector's covariances plus a floor (:class:`gtrig.vision.estimate.VisionOptions`),
not iterated to a fixed point: each frame's fit carries a correction of the pose of every camera and
marker in view (the rig's uncertainty), and these absorb more of the residuals the more the corners
are trusted; iterated, the factor runs away towards zero (seed 0: 0.26, 0.10, 0.04, ... 0.006) and
good frames are refused. Corner noise and rig error are not separable frame by frame; they would be
over a whole recording, where the rig's errors are constant (a later refinement).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

#: Fewer degrees of freedom than this in a camera: its factor is not trusted on its own, the pooled
#: factor of all cameras is used instead (relative error of the estimate sqrt(2 / 200) = 10 %).
MIN_DOF = 200.0


def estimate_corner_scale(noise: Iterable[tuple[tuple[str, float, float], ...]],
                          cameras: Iterable[str], current: dict[str, float] | None = None,
                          min_dof: float = MIN_DOF, cap: float = 3.0) -> tuple[tuple[str, float], ...]:
    """Per-camera variance factors of the corner covariances.

    Parameters
    ----------
    noise : per fit, ``(camera, chi-square share, dof share)`` for each camera in it
        (:attr:`gtrig.vision.estimate.FrameEstimate.noise`), with the factors ``current``. Pass only
        fits whose residuals are meant to be noise (localized or inconsistent frames; not ambiguous
        ones, whose pose may be the wrong flip).
    cameras : every camera of the sequence (a camera without fits gets the pooled factor).
    current : the factors the fits were made with (missing: 1).
    min_dof : below this many degrees of freedom a camera gets the pooled factor.
    cap : a fit's chi-square share counts at most ``cap`` times its dof share.

    Returns
    -------
    ((camera, factor), ...) in the order of ``cameras``; an empty tuple when there is nothing to
    estimate from (the factors then stay as they are).
    """
    cur = current or {}
    chi: dict[str, float] = {}
    dof: dict[str, float] = {}
    for per_fit in noise:
        for cam, c, d in per_fit:
            if math.isfinite(c) and math.isfinite(d) and d > 0:
                chi[cam] = chi.get(cam, 0.0) + min(c, cap * d) * cur.get(cam, 1.0)
                dof[cam] = dof.get(cam, 0.0) + d
    tot = sum(dof.values())
    if tot < min_dof:
        return ()
    pooled = sum(chi.values()) / tot
    out = []
    for cam in cameras:
        d = dof.get(cam, 0.0)
        out.append((cam, float(chi[cam] / d if d >= min_dof else pooled)))
    return tuple(out)


def estimate_rig_scale(rig_noise: Iterable[tuple[float, float]], min_redundancy: float = 20.0,
                       cap: float = 3.0) -> float | None:
    """The variance factor of the rig's stated uncertainty (its cameras' and markers' covariances, one
    component for all of them): ``sum chi2_rig / sum r_rig`` over the fits, each fit's share capped at
    ``cap`` times its redundancy; None when the corners checked less than ``min_redundancy`` of it.

    A rig calibrated better than it says (an exact calibration given with a hand-measured sigma, the
    independent renderer) leaves its nuisance corrections far inside their priors; its
    covariance then dominates every pose's, which comes out cautious by as much as the rig was
    understated. Estimated jointly with the corners' factors (:func:`gtrig.vision.sequence.calibrate_noise`)
    the two components settle at the split the residuals support (Foerstner 1979, variance components
    from redundancy numbers), provided the fits over-determine the rig's nuisances (several markers per
    camera); frame by frame, one marker in one camera cannot tell its corners' noise from its camera's
    error."""
    chi = red = 0.0
    for c, r in rig_noise:
        if math.isfinite(c) and math.isfinite(r) and r > 0:
            chi += min(c, cap * r)
            red += r
    return chi / red if red >= min_redundancy else None


def scale_change(a: tuple[tuple[str, float], ...], b: tuple[tuple[str, float], ...]) -> float:
    """Largest relative change of a factor between two estimates (missing factors count as 1)."""
    da, db = dict(a), dict(b)
    names = set(da) | set(db)
    if not names:
        return 0.0
    return float(max(abs(db.get(n, 1.0) / da.get(n, 1.0) - 1.0) for n in names))


def limit_blas_threads(n: int = 1) -> int | None:
    """Limit the BLAS thread pool of this process to ``n`` threads; returns the previous count.

    GTvision's fits multiply matrices of a few hundred rows, where OpenBLAS's threads bring nothing and
    cost a great deal on a busy machine (spinning threads of several worker processes on two cores: a
    validation instant took 12 times longer). NumPy has no public call for it; OpenBLAS exports
    ``openblas_set_num_threads`` (with a prefix and suffix in NumPy's and SciPy's wheels, each of which
    bundles its own), looked up in the libraries this process has loaded. Returns the first library's
    previous count, or None (and does nothing) when no OpenBLAS is found.
    """
    import ctypes

    try:
        with open("/proc/self/maps", encoding="utf-8") as f:
            libs = sorted({line.split()[-1] for line in f if "openblas" in line.lower() and ".so" in line})
    except OSError:
        return None
    first: int | None = None
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("scipy_openblas%s_num_threads64_", "scipy_openblas%s_num_threads",
                     "openblas%s_num_threads64_", "openblas%s_num_threads"):
            setter = getattr(lib, name.replace("%s", "_set"), None)
            getter = getattr(lib, name.replace("%s", "_get"), None)
            if setter is None or getter is None:
                continue
            getter.restype = ctypes.c_int
            old = int(getter())
            setter(ctypes.c_int(int(n)))
            first = old if first is None else first
            break
    return first


__all__ = ["estimate_corner_scale", "estimate_rig_scale", "scale_change", "limit_blas_threads", "MIN_DOF"]
