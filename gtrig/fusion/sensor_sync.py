"""Each camera's and each fixed scanner's clock offset, from that sensor's own observations against a
reference trajectory on the other sensors' clock.

A source's offset to odometry (:mod:`gtrig.fusion.sync`) is limited by the odometry: its slip is a heading
random walk, so on a 75 s run the interval is a few milliseconds wide. The sensors *of* a GT system are
timed far better against each other, because the reference is then millimetre-accurate. Here:

* the **reference** is a smoothing of other GT fixes with the constant-velocity model (no odometry, so
  the odometry's clock never leaks into it: :func:`reference_track`); its clock is theirs;
* a **scanner** (:func:`scanner_offsets`), against GTvision smoothed: each foreground return, fired at
  ``t`` on the scanner's clock, lies on the robot's hull at the reference pose of ``t - tau_s``; its
  signed distance to the nearest visible side moves by ``-J . v`` per second of ``tau_s`` (``J`` the
  distance's derivative by the pose, ``v`` the reference's velocity). One weighted least-squares fit
  over every scanner's returns: per scanner ``tau_s``, per hull side a bias (the fabric's range bias, the
  hull's size, the reference frame's offset from the hull) and one yaw offset between the reference's
  robot frame and the hull;
* a **camera** (:func:`camera_offsets`), against GTlaser restamped by those scanner offsets
  (:func:`restamp_laser`) and smoothed: each GTvision pose minus the reference at its time minus the
  share-weighted offsets of the cameras that made it (:func:`checkpoint_membership`), linearised in the
  offsets (the reference's velocity), with a constant (x, y, yaw) bias per set of cameras (their
  calibration's error) as nuisance parameters; one fit for all cameras.

Why not the GTlaser track itself: it fits all scanners' points in one pose per frame, so its time is the
point-weighted mean of the scanners' clocks (shares that change with the robot's position), not any one
scanner's.

Intervals: a jackknife over blocks of ``block_s`` (the reference's errors stay correlated for about half
a second, so neither the points nor the instants are independent), Student's t with B - 1 dof.
Verdicts as in :mod:`gtrig.fusion.sync`: ``unobservable`` (too few observations, or the robot hardly
moves in the sensor's view: the white-noise interval alone is wider than ``max_ci_s``), ``ambiguous``
(the jackknife interval wider than ``max_ci_s``, or the fit's cost has its minimum elsewhere than the
solution), else ``ok``. The curve of each estimate (``lags_s``, ``corr``) is the fit's ``min cost /
cost`` over trial offsets: 1 at the estimate.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import t as student_t

from gtrig.errors import InputError
from gtrig.fusion.fuse import FusionOptions, fuse
from gtrig.fusion.measurements import Fixes
from gtrig.fusion.returns import ScannerReturns, WindowedReturns, returns_of_recording
from gtrig.fusion.returns import recording_returns as recording_returns  # re-exported (benches, tests)
from gtrig.fusion.sync import OffsetEstimate, Verdict
from gtrig.io.odometry import OdometryLog
from gtrig.io.offsets import Z95
from gtrig.trajectory import PoseTrack

_NAN2 = (float("nan"), float("nan"))
#: how cameras are timed by default: "pose" (GTvision's whole poses) or "reprojection" (each camera's corners)
CAMERA_METHOD = "pose"


# ------------------------------------------------------------------------------------------ reference
@dataclass(frozen=True)
class Reference:
    """A smoothed trajectory to time sensors against: stamps (N,) on its sources' clock, poses (N, 3)
    world (x, y m, yaw rad unwrapped), velocities (N, 3) per second, covariances (N, 3, 3)."""

    stamps_s: np.ndarray
    xytheta: np.ndarray
    velocity: np.ndarray
    cov: np.ndarray

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses and velocities (M, 3) at ``t`` (M,), linearly interpolated."""
        P = np.column_stack([np.interp(t, self.stamps_s, self.xytheta[:, k]) for k in range(3)])
        V = np.column_stack([np.interp(t, self.stamps_s, self.velocity[:, k]) for k in range(3)])
        return P, V

    def covers(self, t: np.ndarray, margin_s: float) -> np.ndarray:
        return (t >= self.stamps_s[0] + margin_s) & (t <= self.stamps_s[-1] - margin_s)


#: a reference longer than this is smoothed in windows of this length (seconds), each with
#: :data:`REFERENCE_OVERLAP_S` more fixes on either side (issue 24: one batch over an hour held ~600 MB)
REFERENCE_WINDOW_S = 600.0
#: the fixes beyond each window's ends that its smoothing sees: a fix's pull on the constant-velocity
#: smoothing dies out within seconds, so with 30 s of them the kept part of a window is the whole batch's
#: to 1e-13 m on a synthetic 1000 s run (tests/fusion/test_sensor_sync.py)
REFERENCE_OVERLAP_S = 30.0
#: GTvision instants whose normal equations are formed at once in the per-camera fit: an instant's
#: (n, n) block for n = cameras + 3 x their groups is a few kB, an hour's 40,000 instants at once took
#: the client ~300 MB over its baseline, four times per fit (issue 24)
CAMERA_ROWS_PER_BLOCK = 4096


def reference_track(fixes: list[Fixes], rate_hz: float = 50.0, max_gap_s: float = 0.5,
                    window_s: float = REFERENCE_WINDOW_S, overlap_s: float = REFERENCE_OVERLAP_S) -> Reference:
    """The fixes smoothed by the constant-velocity model (robust batch MAP, no odometry) on a ``rate_hz``
    grid, one segment per stretch without a gap over ``max_gap_s``; the fits use only times with poses of
    the reference within 50 ms on both sides, so no gap is interpolated across.

    Fixes spanning more than ``window_s`` are smoothed a window of ``window_s`` at a time (each seeing
    ``overlap_s`` of fixes beyond its ends, its own part kept), so that the memory does not grow with the
    recording's length; a shorter span is one batch, as before."""
    t0 = min(float(f.stamps_s[0]) for f in fixes if len(f))
    t1 = max(float(f.stamps_s[-1]) for f in fixes if len(f))
    if t1 - t0 <= window_s:
        return _reference_part(fixes, rate_hz, max_gap_s)
    parts = []
    n_win = int(np.ceil((t1 - t0) / window_s))
    for w in range(n_win):
        a, b = t0 + w * window_s, (t0 + (w + 1) * window_s if w + 1 < n_win else np.inf)
        sel = [f.between(a - overlap_s, b + overlap_s) for f in fixes]
        if sum(len(f) for f in sel) < 3:
            continue
        try:
            ref = _reference_part([f for f in sel if len(f)], rate_hz, max_gap_s)
        except InputError:  # a window of a few scattered fixes (a long gap) has no segment to smooth
            continue
        keep = (ref.stamps_s >= a) & (ref.stamps_s < b)
        parts.append(Reference(ref.stamps_s[keep], ref.xytheta[keep], ref.velocity[keep], ref.cov[keep]))
    if not parts:
        raise InputError("fusion: no segment with at least three fixes")
    xyt = np.concatenate([p.xytheta for p in parts])
    xyt[:, 2] = np.unwrap(xyt[:, 2])  # each window's yaw was unwrapped from its own start
    return Reference(np.concatenate([p.stamps_s for p in parts]), xyt, np.concatenate([p.velocity for p in parts]),
                     np.concatenate([p.cov for p in parts]))


def _reference_part(fixes: list[Fixes], rate_hz: float, max_gap_s: float) -> Reference:
    """:func:`reference_track` of fixes smoothed in one batch."""
    # no innovation weighting: one source against a constant-velocity prediction has no other to
    # disagree with (its turns would read as disagreement)
    track, _ = fuse(fixes, None, FusionOptions(rate_hz=rate_hz, max_gap_s=max_gap_s, innovation_window_s=0.0))
    xyt = track.xytheta()
    xyt[:, 2] = np.unwrap(xyt[:, 2])
    vel = np.gradient(xyt, track.stamps_s, axis=0)
    cov = track.cov_xytheta()
    assert cov is not None  # fusion always gives one
    return Reference(track.stamps_s, xyt, vel, cov)


def _near_reference(ref: Reference, t: np.ndarray, tol_s: float) -> np.ndarray:
    """True where ``t`` has reference poses within ``tol_s`` on both sides (no interpolation over gaps)."""
    k = np.clip(np.searchsorted(ref.stamps_s, t), 1, ref.stamps_s.size - 1)
    return (t - ref.stamps_s[k - 1] <= tol_s) & (ref.stamps_s[k] - t <= tol_s) & ref.covers(t, 0.0)


# ------------------------------------------------------------------------------------------ the fit
def _score(cost: np.ndarray) -> np.ndarray:
    """``min cost / cost`` of a cost curve: 1 at its minimum; 0 where the cost is 0 (no observation)."""
    return np.divide(cost.min(), cost, out=np.zeros_like(cost), where=cost > 0)


def _ridge(H: np.ndarray) -> np.ndarray:
    """A ridge far below any informed direction of ``H``: what nobody informs (a hull side never seen, the
    difference of two cameras always seen together) stays at zero, and its variance comes out huge."""
    return 1e-12 * max(float(np.trace(H)) / H.shape[0], 1e-300) * np.eye(H.shape[0])


def _jackknife(H_b: np.ndarray, g_b: np.ndarray, cols: np.ndarray, L: np.ndarray | None = None,
               ) -> tuple[np.ndarray, np.ndarray, int]:
    """Solve ``sum_b H_b x = -sum_b g_b`` (blocks (B, n, n), (B, n)) and the jackknife standard error of
    ``x[cols]`` (or, with ``L`` (k, len(cols)), of ``L x[cols]``); returns (x, se, number of blocks with
    data)."""
    H, g = H_b.sum(axis=0) + _ridge(H_b.sum(axis=0)), g_b.sum(axis=0)
    x = -np.linalg.solve(H, g)
    used = np.flatnonzero(np.abs(g_b).sum(axis=1) > 0)
    B = used.size
    Lm = np.eye(cols.size) if L is None else L
    if B < 3:
        return x, np.full(Lm.shape[0], np.inf), B
    loo = np.array([Lm @ -np.linalg.solve(H - H_b[b], g - g_b[b])[cols] for b in used])
    se = np.sqrt((B - 1) / B * np.sum((loo - loo.mean(axis=0)) ** 2, axis=0))
    return x, se, B


def _verdict(name: str, tau: float, se: float, white_se: float, B: int, taus: np.ndarray, curve: np.ndarray,
             max_ci_s: float, n_obs: int, min_obs: int) -> OffsetEstimate:
    half = float(student_t.ppf(0.975, max(B - 1, 1))) * se if np.isfinite(se) else float("inf")
    v: Verdict = "ok"
    if n_obs < min_obs or B < 3:
        v, reason = "unobservable", f"{n_obs} observations in {B} blocks of time"
    elif 2 * 1.96 * white_se > max_ci_s:
        v, reason = "unobservable", "the robot hardly moves in this sensor's view"
    elif 2 * half > max_ci_s:
        v, reason = "ambiguous", f"the 95 % interval ({2 * half * 1e3:.1f} ms) is wider than {max_ci_s * 1e3:.1f} ms"
    elif curve.size and abs(taus[int(np.argmax(curve))] - tau) > 2 * (taus[1] - taus[0]) + half:
        v, reason = "ambiguous", "the fit's cost has its minimum away from the estimate"
    else:
        reason = f"{n_obs} observations, {B} blocks of time"
    if v != "ok":
        return OffsetEstimate(name, v, float("nan"), _NAN2, float("nan"), float("nan"), float("nan"), taus, curve,
                              B, reason)
    return OffsetEstimate(name, "ok", tau, (tau - half, tau + half), float("nan"), 1.0, float("nan"), taus, curve,
                          B, reason)


# ------------------------------------------------------------------------------------------ cameras
def camera_membership(stamps_s: np.ndarray, camera_stamps_s: Mapping[str, np.ndarray], sync_tol_s: float = 0.005,
                      ) -> np.ndarray:
    """(N, C) share of each camera in each GTvision instant: an instant is the images of the cameras whose
    frame stamps lie within ``sync_tol_s`` of it (GTvision stamps a group at its images' mean stamp,
    gtrig.vision.sequence.make_instants); its time is their mean, so each member has the share 1 / count.
    A row of zeros: no camera frame near that stamp."""
    st = np.asarray(stamps_s, float)
    M = np.zeros((st.size, len(camera_stamps_s)))
    for j, cs in enumerate(camera_stamps_s.values()):
        cs = np.r_[-np.inf, np.sort(np.asarray(cs, float)), np.inf]
        k = np.searchsorted(cs, st)
        M[:, j] = np.minimum(st - cs[k - 1], cs[k] - st) <= sync_tol_s
    n = M.sum(axis=1, keepdims=True)
    return np.divide(M, n, out=np.zeros_like(M), where=n > 0)


def checkpoint_membership(stamps_s: np.ndarray, checkpoint: str | os.PathLike[str],
                          camera_stamps_s: Mapping[str, np.ndarray], sync_tol_s: float = 0.005
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Which cameras made each GTvision pose, and when, from GTvision's checkpoint of detections.

    GTvision groups the images of cameras within ``sync_tol_s`` into one instant stamped at their mean
    stamp, but when only one of those images shows markers the pose is that camera's alone, taken at *its*
    stamp: such a pose is stamped up to 2.5 ms off (on the simulated runs, 352 of 902 and 673 of 916
    poses). A pose of several cameras' views is moved to the instant's stamp by GTvision
    (``compensate_motion``).

    Parameters
    ----------
    stamps_s : (N,) GTvision's pose stamps. checkpoint : ``gt_vision_<sequence>.checkpoint`` (JSON lines:
        one camera's detections in a time window per line, or, before version 5, whole instants).
    camera_stamps_s : per camera, its frame stamps (the rows the checkpoint's frames name).
    sync_tol_s : GTvision's grouping tolerance, seconds (its instants are rebuilt from the frame stamps).

    Returns
    -------
    times : (N,) when each pose was taken on the cameras' clocks (the single view's frame stamp, else the
        instant's stamp); share : (N, C) each camera's share of the pose (1 / number of cameras with views);
        a row of zeros where the checkpoint has no instant at that stamp.
    """
    names = list(camera_stamps_s)
    col = {n: j for j, n in enumerate(names)}
    by_stamp = _instants_with_views(checkpoint, camera_stamps_s, sync_tol_s)
    st = np.asarray(stamps_s, float)
    times, share = st.copy(), np.zeros((st.size, len(names)))
    for i, s_ in enumerate(st):
        hit = by_stamp.get(round(float(s_), 6))
        if hit is None:
            continue
        seen = [c for c in hit[1] if c in col]
        if not seen:
            continue
        times[i] = hit[0]
        share[i, [col[c] for c in seen]] = 1.0 / len(seen)
    return times, share


def _instants_with_views(checkpoint: str | os.PathLike[str], camera_stamps_s: Mapping[str, np.ndarray],
                         sync_tol_s: float) -> dict[float, tuple[float, list[str]]]:
    """Per GTvision instant (keyed by its stamp rounded to the microsecond): when its pose was taken and
    the cameras whose images show markers. Reads both checkpoint layouts: per camera and time window
    (``{"camera", "frames"}``, version 5), whose instants are rebuilt as GTvision makes them, and whole
    instants (``{"chunk", "items"}``, before)."""
    import json
    from pathlib import Path

    from gtrig.io.frames import FrameIndex
    from gtrig.vision.sequence import make_instants

    def when(seen: list[str], rows: dict[str, int], t: float) -> float:
        if len(seen) == 1 and seen[0] in rows and seen[0] in camera_stamps_s:
            return float(np.asarray(camera_stamps_s[seen[0]])[rows[seen[0]]])
        return t

    by_stamp: dict[float, tuple[float, list[str]]] = {}
    with_views: dict[str, set[int]] = {}
    with open(checkpoint, encoding="utf-8") as f:
        f.readline()  # the header: the detections' key
        for line in f:
            try:
                d = json.loads(line)
                if "camera" in d:
                    with_views.setdefault(str(d["camera"]), set()).update(int(r) for r, v in d["frames"] if v)
                    continue
                items = d["items"]
            except (json.JSONDecodeError, KeyError, TypeError, ValueError):
                break  # a line cut by an interruption
            for it in items:
                o = it["obs"]
                seen = sorted({v[0] for v in o["views"]})
                t0 = float(o["stamp_s"])
                by_stamp[round(t0, 6)] = (when(seen, {c: int(r) for c, r in o["frames"]}, t0), seen)
    if with_views:
        indices = {c: FrameIndex(c, Path("."), np.arange(len(s)), np.asarray(s, float), ())
                   for c, s in camera_stamps_s.items()}
        for ins in make_instants(indices, "run", sync_tol_s):
            seen = sorted({c for c, r in ins.images if r in with_views.get(c, ())})
            by_stamp[round(ins.stamp_s, 6)] = (when(seen, dict(ins.images), ins.stamp_s), seen)
    return by_stamp


def restamp_vision(track: PoseTrack, checkpoint: str | os.PathLike[str],
                   camera_stamps_s: Mapping[str, np.ndarray]) -> PoseTrack:
    """GTvision's track with each one-camera pose at its camera's frame stamp (:func:`checkpoint_membership`)."""
    when, _ = checkpoint_membership(track.stamps_s, checkpoint, camera_stamps_s)
    order = np.argsort(when, kind="stable")
    keep = np.r_[True, np.diff(when[order]) > 0]
    return replace(track.select(order[keep]), stamps_s=when[order][keep])


def camera_offsets(vision: PoseTrack, camera_stamps_s: Mapping[str, np.ndarray], ref: Reference,
                   block_s: float = 5.0, max_ci_s: float = 0.01, search_s: float = 0.02, min_instants: int = 20,
                   huber_k: float = 3.0, checkpoint: str | os.PathLike[str] | None = None,
                   relative: bool = True, membership: tuple[np.ndarray, np.ndarray] | None = None,
                   ) -> list[OffsetEstimate]:
    """Every camera's clock offset to the reference's clock, one fit over GTvision's instants.

    An instant of cameras ``c`` sees the reference at its stamp minus ``sum_c share_c tau_c``
    (:func:`camera_membership`); its pose minus the reference, linearised in the offsets (the reference's
    velocity), with a constant (x, y, yaw) bias per set of cameras (their calibration's error) as nuisance
    parameters, weighted by GTvision's covariance.

    Parameters
    ----------
    vision : GTvision's track (with covariances), the cameras' clock.
    camera_stamps_s : per camera, its frame stamps (:func:`camera_frame_stamps`).
    ref : the reference (:func:`reference_track` of GTlaser restamped by :func:`restamp_laser`).
    block_s : the jackknife's blocks of time.
    max_ci_s : a wider 95 % interval is ``ambiguous`` (``unobservable`` if the information alone is).
    search_s : the cost curve spans this either side of each estimate.
    huber_k : Huber threshold of each instant's whitened residual (sigmas).
    checkpoint : GTvision's checkpoint of detections: which cameras saw the markers in each instant and
        when (:func:`checkpoint_membership`); without it every camera with a frame within 5 ms of a pose's
        stamp shares it.
    relative : True: offsets to GTvision's clock (the cameras' share-weighted mean over the instants, so
        the reference's own clock and any along-track shift of it cancel); False: to the reference's clock.
    membership : (times, share) of ``vision.usable()``'s poses, already read (:func:`checkpoint_membership`);
        it replaces ``checkpoint`` (for repeated fits).

    Returns
    -------
    One :class:`OffsetEstimate` per camera, named ``vision/<camera>``.
    """
    names = list(camera_stamps_s)
    u = vision.usable()
    cov = u.cov_xytheta()
    if cov is None:
        from gtrig.errors import InputError

        raise InputError("per-camera offsets need GTvision's covariances (track.tum,cov.csv)")
    if membership is not None:
        when, share = membership
    elif checkpoint is not None:
        when, share = checkpoint_membership(u.stamps_s, checkpoint, camera_stamps_s)
    else:
        when, share = u.stamps_s, camera_membership(u.stamps_s, camera_stamps_s)
    keep = _near_reference(ref, when, 0.05) & (share.sum(axis=1) > 0)
    t, z, share = when[keep], u.xytheta()[keep], share[keep]
    # GTvision's own covariance weighs each instant (the reference's errors, correlated over time and
    # inflated by fusion's decorrelation, are left to the jackknife)
    W = np.linalg.inv(cov[keep])
    C = len(names)
    if t.size < min_instants:
        return [_verdict(f"vision/{c}", float("nan"), float("inf"), float("inf"), 0, np.zeros(0), np.zeros(0),
                         max_ci_s, int(t.size), min_instants) for c in names]
    _, group = np.unique(share > 0, axis=0, return_inverse=True)
    group = group.ravel()
    G = int(group.max()) + 1
    n = C + 3 * G
    blocks = np.floor((t - t.min()) / block_s).astype(int)
    B = int(blocks.max()) + 1
    tau = np.zeros(C)
    bias = np.zeros((G, 3))
    hub = np.ones(t.size)
    # GTvision's clock is its cameras' share-weighted mean (its poses are stamped with their frames), so
    # the offsets to it are the fitted ones minus that mean: the reference's own clock error drops out.
    # It is not small: a robot-frame shift of the reference along the motion (GTlaser's hull frame moved
    # forward by a fraction of a millimetre by its per-side range biases) is, at a steady speed, a time
    # offset (0.3 mm at 0.3 m/s = 1 ms), the same for every camera.
    mean_share = share.mean(axis=0)
    L = np.eye(C) - (np.ones((C, 1)) @ mean_share[None, :] if relative else 0.0)
    for it in range(4):
        P, V = ref.at(t - share @ tau)
        e = z - P
        e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
        if it:  # Huber weights on each instant's whitened residual (a GTvision pose off by a centimetre)
            r = e - bias[group]
            z2 = np.einsum("mi,mij,mj->m", r, W, r)
            hub = np.where(z2 <= huber_k**2, 1.0, huber_k / np.sqrt(np.maximum(z2, 1e-24)))
        H_b, g_b = _camera_normal_equations(V, share, group, hub, W, e, blocks, B, n)
        x, se, _ = _jackknife(H_b, g_b, np.arange(C), L)
        tau = tau + x[:C]
        bias = x[C:].reshape(G, 3)
    H = H_b.sum(axis=0)
    white = np.sqrt(np.diag(L @ np.linalg.inv(H + _ridge(H))[:C, :C] @ L.T))
    fit = (t, z, W * hub[:, None, None], share, bias[group])
    common = float(mean_share @ tau) if relative else 0.0
    out = []
    for c, name in enumerate(names):
        taus, curve = _camera_curve(fit, ref, tau, c, search_s)
        e = _verdict(f"vision/{name}", float(tau[c]) - common, float(se[c]), float(white[c]),
                     int(np.unique(blocks[share[:, c] > 0]).size), taus - common, curve, max_ci_s,
                     int(np.sum(share[:, c] > 0)), min_instants)
        if relative:
            e = replace(e, reason=f"{e.reason}; the reference's own offset {common * 1e3:+.2f} ms taken out")
        out.append(e)
    return out


def _camera_normal_equations(V: np.ndarray, share: np.ndarray, group: np.ndarray, hub: np.ndarray, W: np.ndarray,
                             e: np.ndarray, blocks: np.ndarray, n_blocks: int, n: int,
                             ) -> tuple[np.ndarray, np.ndarray]:
    """The per-camera fit's normal equations summed per time block: (B, n, n) and (B, n).

    The residual ``e`` (M, 3) of ``z = ref(t - share . tau) + b_group`` is linear in the unknowns (the
    cameras' offset steps, then each group's (3,) bias): the design's rows are ``V (share . dtau)`` for the
    reference's velocities ``V`` (M, 3) and cameras' shares ``share`` (M, C), and ``-b`` for the instant's
    ``group`` (M,); ``hub`` (M,) Huber weights, ``W`` (M, 3, 3) GTvision's information, ``blocks`` (M,)
    each instant's time block. The instants are taken :data:`CAMERA_ROWS_PER_BLOCK` at a time, added in their order (the
    same sums as all at once), so the memory is a block's, not the run's."""
    C = share.shape[1]
    H_b = np.zeros((n_blocks, n, n))
    g_b = np.zeros((n_blocks, n))
    for a in range(0, len(e), CAMERA_ROWS_PER_BLOCK):
        s = slice(a, a + CAMERA_ROWS_PER_BLOCK)
        m = len(e[s])
        A = np.zeros((m, 3, n))
        A[:, :, :C] = V[s, :, None] * share[s, None, :]
        for i in range(3):
            A[np.arange(m), i, C + 3 * group[s] + i] = -1.0
        np.add.at(H_b, blocks[s], np.einsum("m,mia,mij,mjb->mab", hub[s], A, W[s], A))
        np.add.at(g_b, blocks[s], np.einsum("m,mia,mij,mj->ma", hub[s], A, W[s], e[s]))
    return H_b, g_b


def _camera_curve(fit: tuple[np.ndarray, ...], ref: Reference, tau: np.ndarray, c: int, search_s: float,
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Trial offsets of camera ``c`` around its estimate (the others held) and the fit's min cost / cost;
    ``fit`` = (stamps, poses, weights, shares, biases) of the instants."""
    t, z, W, share, bias = fit
    m = share[:, c] > 0
    taus = tau[c] + np.linspace(-search_s, search_s, 81)
    cost = np.empty(taus.size)
    for j, tc in enumerate(taus):
        tt = tau.copy()
        tt[c] = tc
        P, _ = ref.at(t[m] - share[m] @ tt)
        r = z[m] - P - bias[m]
        r[:, 2] = (r[:, 2] + np.pi) % (2 * np.pi) - np.pi
        cost[j] = float(np.einsum("mi,mij,mj->", r, W[m], r))
    return taus, _score(cost)


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
        keep = _near_reference(ref, r.stamps_s, 0.05)
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
    recording's length when ``ret`` is a :class:`WindowedReturns` (issue 24).

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
        return [_verdict(f"laser/{nm}", float("nan"), float("inf"), float("inf"), 0, np.zeros(0), np.zeros(0),
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
        x, se, _ = _jackknife(H_b, g_b, np.arange(S))
        last, (tau, bias, dth) = state, state
        state = (tau + x[:S], bias + x[S:S + C], dth + float(x[-1]))
    H = H_b.sum(axis=0)
    white = np.sqrt(np.diag(np.linalg.inv(H + _ridge(H)))[:S])
    taus, cost, n_obs, nb = _scanner_curves(ret, ref, fit, (t0, block_s, B), last, state, search_s)
    return [_verdict(f"laser/{nm}", float(state[0][s]), float(se[s]), float(white[s]), int(nb[s]), taus[s],
                     _score(cost[s]), max_ci_s, int(n_obs[s]), min_returns) for s, nm in enumerate(ret.names)]


def camera_frame_stamps(rec_dir, rig, sequence: str = "run") -> dict[str, np.ndarray]:  # noqa: ANN001
    """Each camera's frame stamps (its ``timestamps.csv``) on ``rec_dir/<sequence>``."""
    from pathlib import Path

    from gtrig.vision.sequence import camera_indices

    return {name: ix.stamps_s for name, ix in camera_indices(Path(rec_dir), sequence, rig).items()}


# ------------------------------------------------------------------------------------------ together
def laser_clock(ret: ScannerReturns | WindowedReturns, laser: PoseTrack, scanners: list[OffsetEstimate]
                ) -> tuple[float, float]:
    """GTlaser's clock to GTvision's (s) and its standard error: the mean over GTlaser's usable poses of
    each frame's share-weighted scanner offsets (:func:`restamp_laser`'s shift), the scanners' errors taken
    as independent; ``(nan, nan)`` unless every scanner with returns in those frames has an ``ok`` offset."""
    u = laser.usable()
    if ret.frame_stamps_s.size == 0 or len(u) == 0:
        return float("nan"), float("nan")
    k, hit = ret.frame_of(u.stamps_s)
    if not np.any(hit):
        return float("nan"), float("nan")
    w = ret.frame_shares()[k[hit]].mean(axis=0)  # (S,) each scanner's mean share of GTlaser's poses
    by = {e.source.split("/", 1)[1]: e for e in scanners}
    tau, se = np.zeros(w.size), np.zeros(w.size)
    for i, n in enumerate(ret.names):
        e = by.get(n)
        if w[i] == 0:
            continue
        if e is None or e.verdict != "ok":
            return float("nan"), float("nan")
        tau[i], se[i] = e.offset_s, (e.ci95_s[1] - e.ci95_s[0]) / 2 / Z95
    return float(w @ tau), float(np.sqrt(np.sum((w * se) ** 2)))


def sensor_offsets(rec_dir, rig, vision: PoseTrack, laser: PoseTrack | None = None,  # noqa: ANN001
                   cameras: bool = True, scanners: bool = True, sequence: str = "run",
                   checkpoint: str | os.PathLike[str] | None = None, camera_method: str = CAMERA_METHOD,
                   ) -> list[OffsetEstimate]:
    """Each scanner's and each camera's clock offset to GTvision's clock (the cameras' share-weighted mean).

    Scanners against GTvision smoothed alone (:func:`scanner_offsets`); then GTlaser restamped with the
    scanners' offsets (:func:`restamp_laser`: it is then on GTvision's clock too) is the reference of the
    cameras (:func:`camera_offsets`), which needs ``laser``. ``rig`` holds the calibrated scanners, the hull
    and the cameras. ``checkpoint``: GTvision's checkpoint of detections, which puts each one-camera pose
    at its camera's stamp (:func:`checkpoint_membership`; strongly advised). Add GTvision's own offset to a
    reference (:func:`to_reference`) for offsets to it. ``camera_method``: ``"reprojection"`` (each camera's
    own corners, :mod:`gtrig.fusion.reprojection_sync`; needs ``checkpoint``) or ``"pose"`` (GTvision's
    whole poses, :func:`camera_offsets`).
    """
    return sensor_offsets_and_laser_clock(rec_dir, rig, vision, laser, cameras, scanners, sequence, checkpoint,
                                          camera_method)[0]


def sensor_offsets_and_laser_clock(rec_dir, rig, vision: PoseTrack, laser: PoseTrack | None = None,  # noqa: ANN001
                                   cameras: bool = True, scanners: bool = True, sequence: str = "run",
                                   checkpoint: str | os.PathLike[str] | None = None,
                                   camera_method: str = CAMERA_METHOD, odometry: OdometryLog | None = None,
                                   odometry_offset_s: float = float("nan"),
                                   scan_cache: str | os.PathLike[str] | None = None,
                                   ) -> tuple[list[OffsetEstimate], tuple[float, float]]:
    """:func:`sensor_offsets` and GTlaser's clock to GTvision's with its standard error (:func:`laser_clock`;
    nan without ``laser``), seconds. With ``odometry`` and a finite ``odometry_offset_s`` (GTvision's clock
    minus odometry's, ``gtrig sync``), the pose fit's camera offsets are refined in the joint fit of GTvision,
    GTlaser and odometry (:mod:`gtrig.fusion.joint_camera_sync`). ``scan_cache``: the folder of the
    scanner logs' parsed ranges GTlaser kept (:func:`gtrig.io.scans.index_scans`), read instead of the text."""
    from gtrig.errors import ConfigError, InputError
    from gtrig.fusion.measurements import fixes_from_track

    out: list[OffsetEstimate] = []
    if not (cameras or scanners):
        return out, (float("nan"), float("nan"))
    if rig.robot.hull is None or not rig.laser_scanners:
        raise ConfigError("rig: per-scanner offsets need the fixed scanners and robot.hull")
    cam_stamps = camera_frame_stamps(rec_dir, rig, sequence)
    timed = vision if checkpoint is None else restamp_vision(vision.usable(), checkpoint, cam_stamps)
    with returns_of_recording(rec_dir, rig, sequence, scan_cache=scan_cache) as ret:  # an hour's: a file
        sc = scanner_offsets(ret, reference_track([fixes_from_track(timed, "vision")]), rig.robot.hull.corners_xy())
    if scanners:
        out += sc
    clock = laser_clock(ret, laser, sc) if laser is not None else (float("nan"), float("nan"))
    if cameras:
        if laser is None:
            raise InputError("per-camera offsets need GTlaser's track (the cameras' reference)")
        ref = camera_reference(laser, ret, sc)
        if camera_method == "reprojection" and checkpoint is not None:
            out += reprojection_offsets(rig, vision, cam_stamps, ref, checkpoint)
        elif camera_method in ("pose", "reprojection"):  # no checkpoint: no corners, the poses only
            cams = camera_offsets(vision, cam_stamps, ref, checkpoint=checkpoint)
            if odometry is not None and np.isfinite(odometry_offset_s) and camera_method == "pose":
                from gtrig.fusion.joint_camera_sync import joint_camera_offsets

                cams = joint_camera_offsets(vision, cam_stamps, restamp_laser(laser.usable(), ret, _ok_offsets(sc)),
                                            odometry, odometry_offset_s, cams, checkpoint=checkpoint)
            out += cams
        else:
            raise ConfigError(f"camera_method {camera_method!r}: 'reprojection' or 'pose'")
    return out, clock


def camera_reference(laser: PoseTrack, ret: ScannerReturns | WindowedReturns, scanners: list[OffsetEstimate]
                     ) -> Reference:
    """The cameras' reference: GTlaser's track restamped by the scanners' ``ok`` offsets (on GTvision's clock,
    :func:`restamp_laser`), smoothed (:func:`reference_track`)."""
    from gtrig.fusion.measurements import fixes_from_track

    return reference_track([fixes_from_track(restamp_laser(laser.usable(), ret, _ok_offsets(scanners)), "laser")])


def _ok_offsets(scanners: list[OffsetEstimate]) -> dict[str, float]:
    """Each scanner's ``ok`` offset by its name (``laser/<name>``)."""
    return {e.source.split("/", 1)[1]: e.offset_s for e in scanners if e.verdict == "ok"}


def reprojection_offsets(rig, vision: PoseTrack, cam_stamps: Mapping[str, np.ndarray], ref: Reference,  # noqa: ANN001
                         checkpoint: str | os.PathLike[str]) -> list[OffsetEstimate]:
    """:func:`gtrig.fusion.reprojection_sync.camera_offsets_reprojection` on the checkpoint's corners, relative
    to GTvision's clock (each camera's mean share of GTvision's poses); the pose fit where the checkpoint
    holds no per-camera corners (one of whole instants)."""
    from gtrig.fusion.reprojection_sync import camera_offsets_reprojection, read_camera_corners
    from gtrig.vision.observations import VisionModel

    corners = read_camera_corners(checkpoint, VisionModel.from_rig(rig), cam_stamps)
    if not corners:
        return camera_offsets(vision, cam_stamps, ref, checkpoint=checkpoint)
    _, share = checkpoint_membership(vision.usable().stamps_s, checkpoint, cam_stamps)
    names = [c for c in cam_stamps if c in corners]
    mean = dict(zip(list(cam_stamps), share.mean(axis=0), strict=True))
    return camera_offsets_reprojection({c: corners[c] for c in names}, ref, vision, mean)


def to_reference(sensor: OffsetEstimate, vision: OffsetEstimate) -> dict[str, object]:
    """``sensor`` (an offset to GTvision's clock, :func:`sensor_offsets`) as a ``sync.yaml`` entry: that
    offset and interval (``offset_to_vision_s``, ``ci95_to_vision_s``) and, when GTvision's own offset to the
    reference is ``ok``, the sum as ``offset_s`` with the two half-widths added in quadrature (independent
    fits)."""
    d = sensor.to_dict()
    d["offset_to_vision_s"], d["ci95_to_vision_s"] = d.pop("offset_s"), d.pop("ci95_s")
    d["offset_s"] = d["ci95_s"] = None
    if sensor.verdict == "ok" and vision.verdict == "ok":
        h = float(np.hypot(sensor.ci95_s[1] - sensor.ci95_s[0], vision.ci95_s[1] - vision.ci95_s[0])) / 2
        o = sensor.offset_s + vision.offset_s
        d["offset_s"], d["ci95_s"] = float(o), [float(o - h), float(o + h)]
    return d
