"""The odometry's random errors measured from the data: how far the odometry and a GT source disagree.

The slip model of :class:`~gtrig.fusion.process.OdometryNoise` is linear in four variances: the wheels'
slip per metre rolled (forward travel and heading, coupled through the wheelbase), a side slip per metre,
and a floor per second on position and on heading. Over a window of a few seconds between two fixes of
one pose source, the odometry's relative motion, its systematic errors corrected, differs from the fixes'
by the odometry's accumulated random error plus the two fixes' own errors (a source's run-constant error
cancels in a relative pose). The covariance of that misclosure is the fixes' (known) plus each variance
times a window's sensitivity to it: the wheels' slip and the floor follow from the misclosures' second
moments by non-negative least squares, with the fixes' share taken out, never counted as odometry noise.
The side slip stays at its stated ratio to the slip, and the heading floor equals the position floor (rad
for m): over windows of seconds the heading error's sweep dwarfs a side slip, and an even speed makes a
floor per second and a slip per metre one variance. The systematic parameters (distance scale, turn
scale, curvature) are fitted in the same windows by generalised least squares, with the noise model's
prior on them.

A run too short for the fit keeps the stated model (:class:`~gtrig.fusion.process.OdometryNoise`): the
wheels' slip and floors at :data:`FLOOR_SIGMA`. Floors of 0.5 mm and 0.5 mrad per sqrt(s), which wheels
that count nothing while the robot stands do not have, made every pose the odometry carried through a gap
look less certain than it was (the GT room's simulated robot, 3 s gaps on 75 s runs: bridged NEES/dof
0.51-0.73).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
from scipy.optimize import nnls

from gtrig.fusion.measurements import Fixes, FixModel
from gtrig.fusion.process import OdometryJumps, OdometryNoise, odometry_increments, odometry_jumps, wheel_travel
from gtrig.geometry import wrap_angle
from gtrig.io.odometry import OdometryLog

log = logging.getLogger(__name__)

#: window lengths (s): the longer ones let the odometry's drift stand above the fixes' noise, the shorter ones
#: tell a floor per second from a slip per metre where the speed changes
WINDOWS_S = (2.0, 4.0, 8.0)
#: fewer windows than this and the given model is kept: on the simulated 75 s recordings (about 126 windows
#: of two sources) the fitted slip scattered from half to 1.2 times the simulated one, with the poses bridged
#: through 3 s gaps then from 0.5 to 2.4 in NEES/dof; on 3 minutes (310 windows) within 10 % of it
MIN_WINDOWS = 250
#: the smallest slip the fit returns (m per sqrt(m)): the increments' covariances stay positive definite
#: where a slip fits to zero
MIN_SIGMA = 1e-5
#: the smallest floors (m and rad per sqrt(s)) the fit returns: a tenth of a millimetre (milliradian) per
#: sqrt(s) is below any slip worth modelling and keeps a standing robot's increments from ties a million
#: times tighter than its fixes
FLOOR_SIGMA = 1e-4
#: a window whose normalised misclosure exceeds this many times the median is left out (a slip, a gross
#: fix): chi-square(3)'s 99.9 % point over its median
TRIM = 16.27 / 2.37


@dataclass(frozen=True)
class NoiseFit:
    """The odometry's noise fitted to the data.

    Attributes
    ----------
    noise : the fitted model (the prior sigmas of the systematic parameters as given).
    windows : windows used (after trimming).
    k : (3,) the systematic parameters ``(k_dist, k_turn, k_curv)`` fitted alongside.
    nees_given, nees_fitted : the windows' mean normalised misclosure per dof under the given model and the
        fitted one (1 when the model is right).
    """

    noise: OdometryNoise
    windows: int
    k: np.ndarray
    nees_given: float
    nees_fitted: float

    def summary(self) -> dict[str, float]:
        """The fitted sigmas and the windows' NEES/dof, for a report."""
        n = self.noise
        return {"slip_m_per_sqrt_m": n.slip_m_per_sqrt_m, "lateral_ratio": n.lateral_ratio,
                "floor_m_per_sqrt_s": n.floor_m_per_sqrt_s, "floor_rad_per_sqrt_s": n.floor_rad_per_sqrt_s,
                "windows": float(self.windows), "window_nees_given": self.nees_given,
                "window_nees_fitted": self.nees_fitted}


@dataclass(frozen=True)
class _Windows:
    """Windows between two fixes of one source: per window (W,) the end stamps, the fixes' poses (W, 3) at
    either end and their covariances (W, 3, 3)."""

    t_a: np.ndarray
    t_b: np.ndarray
    z_a: np.ndarray
    z_b: np.ndarray
    c_a: np.ndarray
    c_b: np.ndarray


def _windows(f: Fixes, length_s: float) -> _Windows:
    """Consecutive windows between fixes of ``f`` (a pose source), each from the last one's end to the
    first fix at least ``length_s`` later; kept when no longer than twice that (one across a long gap in
    the source would measure the odometry over a span of another scale)."""
    s = f.stamps_s
    ends = [0]
    while (j := int(np.searchsorted(s, s[ends[-1]] + length_s))) < s.size:
        ends.append(j)
    i = np.asarray(ends)
    a, b = i[:-1], i[1:]
    keep = s[b] - s[a] <= 2.0 * length_s
    a, b = a[keep], b[keep]
    return _Windows(s[a], s[b], f.value[a], f.value[b], f.cov[a], f.cov[b])


def _relative(za: np.ndarray, zb: np.ndarray) -> np.ndarray:
    """(W, 3) pose b in the frame of pose a (x, y, yaw)."""
    c, s = np.cos(za[:, 2]), np.sin(za[:, 2])
    d = zb[:, :2] - za[:, :2]
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap_angle(zb[:, 2] - za[:, 2])])


def _fix_share(w: _Windows) -> np.ndarray:
    """(W, 3, 3) covariance of the fixes' relative pose from their own covariances (world x, y, yaw)."""
    r = _relative(w.z_a, w.z_b)
    c, s = np.cos(w.z_a[:, 2]), np.sin(w.z_a[:, 2])
    Jb = np.zeros((c.size, 3, 3))
    Jb[:, 0, 0], Jb[:, 0, 1], Jb[:, 1, 0], Jb[:, 1, 1], Jb[:, 2, 2] = c, s, -s, c, 1.0
    Ja = -Jb
    Ja[:, 0, 2], Ja[:, 1, 2] = r[:, 1], -r[:, 0]  # the relative position turns with a's heading
    return Ja @ w.c_a @ np.swapaxes(Ja, 1, 2) + Jb @ w.c_b @ np.swapaxes(Jb, 1, 2)


class _DeadReckoning:
    """The odometry's increments (N-1, 3) corrected by the systematic parameters ``k`` and integrated: the
    pose (heading, position) at every record, and at any stamp within the records' span."""

    def __init__(self, stamps_s: np.ndarray, u: np.ndarray, k: np.ndarray) -> None:
        self.stamps_s = stamps_s
        self.v = np.column_stack([k[0] * u[:, 0], k[0] * u[:, 1], k[1] * u[:, 2] + k[2] * u[:, 0]])
        self.th = np.r_[0.0, np.cumsum(self.v[:, 2])]
        c, s = np.cos(self.th[:-1]), np.sin(self.th[:-1])
        step = np.column_stack([c * self.v[:, 0] - s * self.v[:, 1], s * self.v[:, 0] + c * self.v[:, 1]])
        self.xy = np.vstack([np.zeros(2), np.cumsum(step, axis=0)])

    def at(self, t: np.ndarray) -> np.ndarray:
        """(W, 3) the integrated pose at stamps ``t``, linear within an increment."""
        i = np.clip(np.searchsorted(self.stamps_s, t, "right") - 1, 0, self.stamps_s.size - 2)
        a = np.clip((t - self.stamps_s[i]) / (self.stamps_s[i + 1] - self.stamps_s[i]), 0.0, 1.0)
        c, s = np.cos(self.th[i]), np.sin(self.th[i])
        v = self.v[i]
        return np.column_stack([self.xy[i, 0] + a * (c * v[:, 0] - s * v[:, 1]),
                                self.xy[i, 1] + a * (s * v[:, 0] + c * v[:, 1]), self.th[i] + a * v[:, 2]])

    def relative(self, w: _Windows) -> np.ndarray:
        return _relative(self.at(w.t_a), self.at(w.t_b))


#: increments per slice in :func:`_sensitivities`: its temporaries stay a slice's, not an hour's
CHUNK = 1 << 15


def _sensitivities(dr: _DeadReckoning, w: _Windows, u: np.ndarray, wheelbase_m: float) -> np.ndarray:
    """(4, W, 3, 3): each window's relative-pose covariance per unit of each variance (wheel slip and side
    slip, m^2 per m rolled; position and heading floors, m^2 and rad^2 per s), from the increments ``u``
    (N-1, 3) whose middle lies inside it: an increment's error moves the window's end by its own
    translation error turned into the window's frame (columns ``c0``, ``c1``), and by its heading error
    times the lever from the increment's end to the window's end (``c2``)."""
    st = dr.stamps_s
    mid = 0.5 * (st[:-1] + st[1:])
    out = np.zeros((4, w.t_a.size, 3, 3))
    # windows of one source and length do not overlap: each increment belongs to one at most
    win = np.searchsorted(w.t_a, mid, "right") - 1
    inside = np.flatnonzero((win >= 0) & (mid < w.t_b[np.maximum(win, 0)]))
    end, start = dr.at(w.t_b), dr.at(w.t_a)
    for a in range(0, inside.size, CHUNK):
        i = inside[a:a + CHUNK]
        j = win[i]
        th0 = start[j, 2]
        c, s = np.cos(dr.th[i] - th0), np.sin(dr.th[i] - th0)
        lever = end[j, :2] - dr.xy[i + 1]  # world of the dead reckoning; turned into the window's frame below
        ca, sa = np.cos(th0), np.sin(th0)
        lx, ly = ca * lever[:, 0] + sa * lever[:, 1], -sa * lever[:, 0] + ca * lever[:, 1]
        zero, one = np.zeros(i.size), np.ones(i.size)
        c0, c1, c2 = (np.column_stack(v) for v in ((c, s, zero), (-s, c, zero), (-ly, lx, one)))
        wr, wl = wheel_travel(u[i], wheelbase_m)
        dt = st[i + 1] - st[i]

        def outer(x: np.ndarray, y: np.ndarray, f: np.ndarray) -> np.ndarray:
            return f[:, None, None] * x[:, :, None] * y[:, None, :]

        # the slip model's covariance per increment (process.odometry_increments) per unit of each variance
        terms = (outer(c0, c0, (wr + wl) / 4) + outer(c2, c2, (wr + wl) / wheelbase_m**2)
                 + outer(c0, c2, (wr - wl) / (2 * wheelbase_m)) + outer(c2, c0, (wr - wl) / (2 * wheelbase_m)),
                 outer(c1, c1, (wr + wl) / 4), outer(c0, c0, dt) + outer(c1, c1, dt), outer(c2, c2, dt))
        # the increments are in time order, so their windows are too: one sum per run of equal windows
        first = np.flatnonzero(np.r_[True, j[1:] != j[:-1]])
        for k, t in enumerate(terms):
            out[k, j[first]] += np.add.reduceat(t, first, axis=0)
    return out


def _vech(M: np.ndarray) -> np.ndarray:
    """(..., 6) the unique elements of symmetric (..., 3, 3) matrices."""
    a, b = np.triu_indices(3)
    return M[..., a, b]


def _fit_parameters(m_of: Callable[[np.ndarray], np.ndarray], rel_fix: np.ndarray, S: np.ndarray, k: np.ndarray,
                    k0: np.ndarray, Pk: np.ndarray) -> np.ndarray:
    """One Gauss-Newton step of the systematic parameters ``k`` (3,) on the windows' misclosures (their
    covariances ``S`` (W, 3, 3)), with the prior ``(k0, Pk)``; ``m_of(k)`` the odometry's relative poses."""
    m = m_of(k)
    r0 = rel_fix - m
    r0[:, 2] = wrap_angle(r0[:, 2])
    G = np.zeros((r0.shape[0], 3, 3))
    for a in range(3):
        h = np.zeros(3)
        h[a] = 1e-6
        G[:, :, a] = (m_of(k + h) - m) / 1e-6
    Si = np.linalg.inv(S)
    H = np.einsum("wia,wij,wjb->ab", G, Si, G) + np.linalg.inv(Pk)
    g = np.einsum("wia,wij,wj->a", G, Si, r0) + np.linalg.solve(Pk, k0 - k)
    return k + np.linalg.solve(H, g)


def _fit_variances(r: np.ndarray, F: np.ndarray, A: np.ndarray, S: np.ndarray, side_ratio: float) -> np.ndarray:
    """The variances (4,) >= 0 whose sensitivities ``A`` (4, W, 3, 3), plus the fixes' ``F`` (W, 3, 3),
    best match the misclosures' second moments ``r r^T`` (r (W, 3)), each element weighed by its standard
    deviation under the current covariances ``S`` (W, 3, 3) (Gaussian: var(r_i r_j) = S_ii S_jj + S_ij^2).
    Two are free: the wheels' slip (the side slip at ``side_ratio`` of it) and the floor (on position and
    heading alike, in m^2 and rad^2 per second)."""
    y = _vech(r[:, :, None] * r[:, None, :] - F).ravel()
    d = np.diagonal(S, axis1=1, axis2=2)
    a, b = np.triu_indices(3)
    sd = np.sqrt(d[:, a] * d[:, b] + S[:, a, b] ** 2).ravel()
    cols = (A[0] + side_ratio**2 * A[1], A[2] + A[3])
    X = np.stack([_vech(c).ravel() for c in cols], axis=1) / sd[:, None]
    scale = np.maximum(np.abs(X).max(axis=0), 1e-300)  # columns per metre and per second differ by orders
    theta, _ = nnls(X / scale, y / sd)
    slip2, floor2 = theta / scale
    return np.array([slip2, side_ratio**2 * slip2, floor2, floor2])


def _noise_of(theta: np.ndarray, given: OdometryNoise) -> OdometryNoise:
    return OdometryNoise(slip_m_per_sqrt_m=max(float(np.sqrt(theta[0])), MIN_SIGMA), wheelbase_m=given.wheelbase_m,
                         lateral_ratio=given.lateral_ratio,
                         floor_m_per_sqrt_s=max(float(np.sqrt(theta[2])), FLOOR_SIGMA),
                         floor_rad_per_sqrt_s=max(float(np.sqrt(theta[3])), FLOOR_SIGMA),
                         sigma_dist_scale=given.sigma_dist_scale, sigma_turn_scale=given.sigma_turn_scale,
                         sigma_curv_rad_per_m=given.sigma_curv_rad_per_m)


def _theta_of(n: OdometryNoise) -> np.ndarray:
    s2 = n.slip_m_per_sqrt_m**2
    return np.array([s2, n.lateral_ratio**2 * s2, n.floor_m_per_sqrt_s**2, n.floor_rad_per_sqrt_s**2])


class _Misclosures:
    """The windows of every pose source (:data:`WINDOWS_S` long each) on the odometry: the fixes' relative
    poses (W, 3) and their covariances (W, 3, 3); the odometry's relative poses and the windows'
    sensitivities to its variances for given systematic parameters."""

    def __init__(self, fixes: list[Fixes], odometry: OdometryLog, given: OdometryNoise, jumps: OdometryJumps) -> None:
        st = odometry.stamps_s
        xyt = odometry.xytheta.copy()
        xyt[:, 2] = np.unwrap(xyt[:, 2])
        self.stamps_s = st
        self.u, _ = odometry_increments(xyt, st, given)
        jump_n = np.r_[0, np.cumsum(odometry_jumps(self.u, np.diff(st), jumps))]
        self.wheelbase_m = given.wheelbase_m
        self.groups: list[_Windows] = []
        for f in fixes:
            f = f.between(float(st[0]), float(st[-1]))
            if f.model is not FixModel.POSE or len(f) < 3:
                continue
            for length in WINDOWS_S:
                w = _windows(f, length)
                ia, ib = (np.clip(np.searchsorted(st, t, "right") - 1, 0, st.size - 1) for t in (w.t_a, w.t_b))
                ok = jump_n[ia] == jump_n[ib]  # a window across a jump measures the jump, not the noise
                if ok.any():
                    self.groups.append(_Windows(w.t_a[ok], w.t_b[ok], w.z_a[ok], w.z_b[ok], w.c_a[ok], w.c_b[ok]))
        self.size = sum(w.t_a.size for w in self.groups)
        if self.size:
            self.rel_fix = np.concatenate([_relative(w.z_a, w.z_b) for w in self.groups])
            self.F = np.concatenate([_fix_share(w) for w in self.groups])

    def odometry(self, k: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        dr = _DeadReckoning(self.stamps_s, self.u, k)
        rel = np.concatenate([dr.relative(w) for w in self.groups])
        return rel if mask is None else rel[mask]

    def sensitivities(self, k: np.ndarray) -> np.ndarray:
        dr = _DeadReckoning(self.stamps_s, self.u, k)
        return np.concatenate([_sensitivities(dr, w, self.u, self.wheelbase_m) for w in self.groups], axis=1)


def _nis(r: np.ndarray, S: np.ndarray) -> np.ndarray:
    return np.einsum("wi,wij,wj->w", r, np.linalg.inv(S), r)


def _trimmed(q: np.ndarray) -> np.ndarray:
    return q <= TRIM * np.median(q)


def fit_odometry_noise(fixes: list[Fixes], odometry: OdometryLog, given: OdometryNoise,
                       jumps: OdometryJumps | None = None, iterations: int = 4) -> NoiseFit | None:
    """The odometry's slip model fitted to its disagreement with the pose sources over windows.

    Parameters
    ----------
    fixes : the sources' fixes on the odometry's clock (offsets applied); pose sources are used.
    odometry : the wheel odometry.
    given : the model to start from (its wheelbase, side-slip ratio and prior on the systematic
        parameters are kept).
    jumps : what increment is a jump (a window across one is left out); default :class:`OdometryJumps`.
    iterations : rounds of parameters, variances and trimming.

    Returns
    -------
    The fit, or None when fewer than :data:`MIN_WINDOWS` windows hold (too short a run, no pose source).
    """
    mis = _Misclosures(fixes, odometry, given, jumps or OdometryJumps())
    if mis.size < MIN_WINDOWS:
        return None
    k0, Pk = given.prior()
    theta, k = _theta_of(given), k0.copy()
    keep = np.ones(mis.size, bool)
    nees_given = float("nan")
    for it in range(iterations):
        if it < 2:  # after the parameters' first step the sensitivities barely move (a 1 % turn scale)
            A = mis.sensitivities(k)
        S = mis.F + np.einsum("k,kwij->wij", theta, A)
        k = _fit_parameters(partial(mis.odometry, mask=keep), mis.rel_fix[keep], S[keep], k, k0, Pk)
        r = mis.rel_fix - mis.odometry(k)
        r[:, 2] = wrap_angle(r[:, 2])
        q = _nis(r, S)
        keep = _trimmed(q)
        if it == 0:
            nees_given = float(np.mean(q[keep]) / 3)
        theta = np.maximum(_fit_variances(r[keep], mis.F[keep], A[:, keep], S[keep], given.lateral_ratio),
                           MIN_SIGMA**2)
    q = _nis(r, mis.F + np.einsum("k,kwij->wij", theta, A))
    keep = _trimmed(q)
    fit = NoiseFit(_noise_of(theta, given), int(keep.sum()), k, nees_given, float(np.mean(q[keep]) / 3))
    log.info("odometry noise fitted on %d windows: slip %.2g m/sqrt(m); window NEES/dof %.2f under the given "
             "model, %.2f fitted", fit.windows, fit.noise.slip_m_per_sqrt_m, fit.nees_given, fit.nees_fitted)
    return fit
