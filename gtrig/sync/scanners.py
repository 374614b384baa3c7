"""Each fixed scanner's clock offset from its own foreground returns against a reference (the hull fit),
and GTlaser restamped by those offsets."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace

import numpy as np

from gtrig.sync.offset import OffsetEstimate
from gtrig.sync.reference import Reference, cost_score, jackknife, near_reference, offset_verdict, ridge
from gtrig.sync.returns import ScannerReturns, WindowedReturns
from gtrig.trajectory import PoseTrack


# ------------------------------------------------------------------------------------------ scanners
def restamp_laser(track: PoseTrack, ret: ScannerReturns | WindowedReturns, offsets_s: Mapping[str, float]) -> PoseTrack:
    """GTlaser's track on the clock the scanners' offsets refer to: GTlaser fits a frame's returns of all
    scanners in one pose, so that pose holds at the frame stamp minus the share-weighted mean of their
    offsets (each scanner's share of the frame's returns; a scanner without an offset counts as 0).
    Poses whose stamp is no frame of ``ret`` keep their stamp."""
    tau = np.array([float(offsets_s.get(n, 0.0)) for n in ret.names])
    shift = ret.frame_shares() @ tau
    k, hit = ret.frame_of(track.stamps_s)
    st = track.stamps_s - np.where(hit, shift[k], 0.0)
    order = np.argsort(st, kind="stable")
    out = track.select(order)
    return replace(out, stamps_s=st[order])


def hull_distances(corners_xy: np.ndarray, pose: np.ndarray, p: np.ndarray, origin: np.ndarray,
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Signed distance of world points ``p`` (M, 2) to the nearest side of the hull (corners (C, 2),
    counter-clockwise, robot frame) at ``pose`` (M, 3) that faces the point's scanner at ``origin``
    (M, 2); returns (distance (M,), side index (M,), its derivative by the pose (M, 3), the overshoot
    past the side's ends (M,))."""
    c0 = np.asarray(corners_xy, float)
    e = np.roll(c0, -1, axis=0) - c0
    L = np.linalg.norm(e, axis=1)
    tng = e / L[:, None]
    nrm = np.column_stack([tng[:, 1], -tng[:, 0]])
    off = np.einsum("ij,ij->i", nrm, c0)
    a0 = np.einsum("ij,ij->i", tng, c0)
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    q = p - pose[:, :2]
    pr = np.column_stack([c * q[:, 0] + s * q[:, 1], c * q[:, 1] - s * q[:, 0]])
    o = origin - pose[:, :2]
    orr = np.column_stack([c * o[:, 0] + s * o[:, 1], c * o[:, 1] - s * o[:, 0]])
    sd = pr @ nrm.T - off
    along = pr @ tng.T - a0
    over = np.maximum(0.0, np.maximum(-along, along - L))
    d2 = np.where((orr @ nrm.T - off) > 0, sd * sd + over * over, np.inf)
    k = np.argmin(d2, axis=1)
    rows = np.arange(p.shape[0])
    nw = np.column_stack([c * nrm[k, 0] - s * nrm[k, 1], s * nrm[k, 0] + c * nrm[k, 1]])
    J = np.column_stack([-nw[:, 0], -nw[:, 1], nw[:, 0] * q[:, 1] - nw[:, 1] * q[:, 0]])
    return sd[rows, k], k, J, over[rows, k]


def _block_sums(blocks: np.ndarray, B: int, A: np.ndarray, w: np.ndarray, f: np.ndarray,
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per block of time, ``sum w A^T A`` (B, n, n) and ``sum w A^T f`` (B, n) of rows A (M, n)."""
    n = A.shape[1]
    H_b = np.zeros((B, n, n))
    g_b = np.zeros((B, n))
    for a in range(n):
        wa = w * A[:, a]
        g_b[:, a] = np.bincount(blocks, wa * f, minlength=B)
        for b in range(a, n):
            H_b[:, a, b] = H_b[:, b, a] = np.bincount(blocks, wa * A[:, b], minlength=B)
    return H_b, g_b


@dataclass(frozen=True)
class _HullFit:
    """The scanner fit's constants: ``corners`` (C, 2) the hull, robot frame; ``sigma_m`` (S,) each scanner's
    range noise; the hull model's error, the gate and the Huber threshold (:func:`scanner_offsets`)."""

    corners: np.ndarray
    sigma_m: np.ndarray
    sigma_model_m: float
    gate_m: float
    huber_k: float


def _kept_windows(ret: ScannerReturns | WindowedReturns, ref: Reference,
                  ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Per window of ``ret``, its returns with reference poses within 50 ms on both sides: stamps (M,),
    world points (M, 2), scanner indices (M,), beam directions (M, 2), their scanners' origins (M, 2)."""
    for r in ret.windows():
        keep = near_reference(ref, r.stamps_s, 0.05)
        sid = r.scanner_index[keep]
        yield r.stamps_s[keep], r.xy_world[keep], sid, r.dir_world[keep], r.origin_xy[sid]


def _hull_rows(win: tuple[np.ndarray, ...], ref: Reference, fit: _HullFit, tau: np.ndarray, bias: np.ndarray,
               dth: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One window's rows of the scanner fit linearised at (``tau`` (S,), ``bias`` (C,), ``dth``): the
    residuals' derivatives A (M, S + C + 1) by (tau, side biases, hull yaw), the weights w (M,) (0: not the
    hull's, Huber-reduced beyond ``huber_k``) and the residuals f (M,), metres."""
    t, p, sid, dirs, org = win
    S, C = tau.size, bias.size
    P, V = ref.at(t - tau[sid])
    P[:, 2] += dth
    d, k, J, over = hull_distances(fit.corners, P, p, org)
    f = d - bias[k]
    cos_i = -(dirs[:, 0] * J[:, 0] + dirs[:, 1] * J[:, 1])
    var = fit.sigma_m[sid] ** 2 * cos_i**2 + fit.sigma_model_m**2
    z = np.abs(f) / np.sqrt(var)
    inl = np.isfinite(f) & (np.abs(f) < fit.gate_m) & (over <= 0.05)
    w = np.where(inl, np.where(z <= fit.huber_k, 1.0, fit.huber_k / np.maximum(z, 1e-12)) / var, 0.0)
    f = np.where(inl, f, 0.0)
    A = np.zeros((t.size, S + C + 1))
    A[np.arange(t.size), sid] = -(J * V).sum(axis=1)  # d f / d tau_s
    A[np.arange(t.size), S + k] = -1.0
    A[:, -1] = J[:, 2]
    return A, w, f


def _blocks_of(t: np.ndarray, t0: float, block_s: float) -> np.ndarray:
    """The block of time (index from 0 at ``t0``, ``block_s`` long) of each stamp of ``t`` (M,), seconds."""
    return np.floor((t - t0) / block_s).astype(int)


def _scanner_curves(ret: ScannerReturns | WindowedReturns, ref: Reference, fit: _HullFit,
                    blocks: tuple[float, float, int], weights_at: tuple[np.ndarray, np.ndarray, float],
                    at: tuple[np.ndarray, np.ndarray, float],
                    search_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The fit's cost over 41 trial offsets of each scanner (the rest held at ``at`` = (tau, bias, dth)),
    with the weights of the fit's last pass (linearised at ``weights_at``), summed window by window.
    ``blocks`` = (first stamp, block_s, B). Returns the trial offsets (S, 41), the costs (S, 41), each
    scanner's returns with weight (S,) and its blocks of time with any (S,)."""
    tau, bias, dth = at
    S = tau.size
    t0, block_s, B = blocks
    taus = tau[:, None] + np.linspace(-search_s, search_s, 41)[None, :]
    cost = np.zeros(taus.shape)
    n_obs = np.zeros(S, np.int64)
    seen = np.zeros((S, B), bool)
    for win in _kept_windows(ret, ref):
        t, p, sid, _, org = win
        _, w, _ = _hull_rows(win, ref, fit, *weights_at)
        for s in range(S):
            m = (sid == s) & (w > 0)
            n_obs[s] += int(m.sum())
            seen[s, _blocks_of(t[m], t0, block_s)] = True
            for j, ts in enumerate(taus[s]):
                P, _ = ref.at(t[m] - ts)
                P[:, 2] += dth
                dd, kk, _, _ = hull_distances(fit.corners, P, p[m], org[m])
                cost[s, j] += float(np.sum(w[m] * (dd - bias[kk]) ** 2))
    return taus, cost, n_obs, seen.sum(axis=1)


def scanner_offsets(ret: ScannerReturns | WindowedReturns, ref: Reference, corners_xy: np.ndarray,
                    block_s: float = 5.0, gate_m: float = 0.02, sigma_model_m: float = 0.002, huber_k: float = 3.0,
                    max_ci_s: float = 0.01, search_s: float = 0.02, min_returns: int = 200,
                    ) -> list[OffsetEstimate]:
    """Every scanner's clock offset to the reference's clock (see the module docstring), one fit.

    The returns are read a window at a time (``ret.windows()``) for each of the fit's passes: one for the
    first stamp, four Gauss-Newton iterations and the cost curves; what is held across windows is per block
    of time (the normal equations, (B, n, n)) or per scanner, so the memory does not grow with the
    recording's length when ``ret`` is a :class:`WindowedReturns`.

    Parameters
    ----------
    ret : the scanners' foreground returns (:func:`returns_of_recording`, or in memory:
        :meth:`ScannerReturns.from_framed`).
    ref : the reference trajectory (:func:`reference_track` of GTvision's poses), its clock.
    corners_xy : (C, 2) the hull's corners, counter-clockwise, robot frame (``rig.robot.hull.corners_xy()``).
    gate_m : returns farther than this from the hull are not the hull's (a leg, a reflection).
    sigma_model_m : the hull model's own error, added to each return's range noise (as GTlaser does).
    huber_k : Huber threshold of the whitened residuals, sigmas.
    max_ci_s, search_s, block_s : as in :func:`camera_offset`.

    Returns
    -------
    One :class:`OffsetEstimate` per scanner, named ``laser/<scanner>``, in ``ret.names`` order.
    """
    S, C = len(ret.names), int(np.asarray(corners_xy).shape[0])
    fit = _HullFit(np.asarray(corners_xy, float), np.asarray(ret.sigma_m, float), sigma_model_m, gate_m, huber_k)
    # the blocks of time count from the first kept return, so a pass over the stamps comes first
    t0, t1 = np.inf, -np.inf
    for t, *_ in _kept_windows(ret, ref):
        if t.size:
            t0, t1 = min(t0, float(t.min())), max(t1, float(t.max()))
    if not np.isfinite(t0):
        return [offset_verdict(f"laser/{nm}", float("nan"), float("inf"), float("inf"), 0, np.zeros(0), np.zeros(0),
                         max_ci_s, 0, min_returns) for nm in ret.names]
    B = int(np.floor((t1 - t0) / block_s)) + 1
    n = S + C + 1  # tau per scanner, a bias per hull side, the hull's yaw in the reference's robot frame
    state: tuple[np.ndarray, np.ndarray, float] = (np.zeros(S), np.zeros(C), 0.0)
    for _ in range(4):
        H_b, g_b = np.zeros((B, n, n)), np.zeros((B, n))
        for win in _kept_windows(ret, ref):
            A, w, f = _hull_rows(win, ref, fit, *state)
            h, g = _block_sums(_blocks_of(win[0], t0, block_s), B, A, w, f)
            H_b += h
            g_b += g
        x, se, _ = jackknife(H_b, g_b, np.arange(S))
        last, (tau, bias, dth) = state, state
        state = (tau + x[:S], bias + x[S:S + C], dth + float(x[-1]))
    H = H_b.sum(axis=0)
    white = np.sqrt(np.diag(np.linalg.inv(H + ridge(H)))[:S])
    taus, cost, n_obs, nb = _scanner_curves(ret, ref, fit, (t0, block_s, B), last, state, search_s)
    return [offset_verdict(f"laser/{nm}", float(state[0][s]), float(se[s]), float(white[s]), int(nb[s]), taus[s],
                     cost_score(cost[s]), max_ci_s, int(n_obs[s]), min_returns) for s, nm in enumerate(ret.names)]
