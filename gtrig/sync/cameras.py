"""Each camera's clock offset from GTvision's whole poses against a reference (the pose fit), and which
cameras made each GTvision pose (the checkpoint's membership)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from gtrig.sync.offset import OffsetEstimate
from gtrig.sync.reference import Reference, cost_score, jackknife, near_reference, offset_verdict, ridge
from gtrig.trajectory import PoseTrack

#: GTvision instants whose normal equations are formed at once in the per-camera fit: an instant's
#: (n, n) block for n = cameras + 3 x their groups is a few kB, an hour's 40,000 instants at once took
#: the client ~300 MB over its baseline, four times per fit
CAMERA_ROWS_PER_BLOCK = 4096



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
    from pathlib import Path

    from gtrig.io.checkpoint import checkpoint_records
    from gtrig.io.frames import FrameIndex
    from gtrig.vision.sequence import make_instants

    def when(seen: list[str], rows: dict[str, int], t: float) -> float:
        if len(seen) == 1 and seen[0] in rows and seen[0] in camera_stamps_s:
            return float(np.asarray(camera_stamps_s[seen[0]])[rows[seen[0]]])
        return t

    by_stamp: dict[float, tuple[float, list[str]]] = {}
    with_views: dict[str, set[int]] = {}
    for d in checkpoint_records(checkpoint):
        try:
            if "camera" in d:
                with_views.setdefault(str(d["camera"]), set()).update(int(r) for r, v in d["frames"] if v)
                continue
            items = d["items"]
        except (KeyError, TypeError, ValueError):
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
    keep = near_reference(ref, when, 0.05) & (share.sum(axis=1) > 0)
    t, z, share = when[keep], u.xytheta()[keep], share[keep]
    # GTvision's own covariance weighs each instant (the reference's errors, correlated over time and
    # inflated by fusion's decorrelation, are left to the jackknife)
    W = np.linalg.inv(cov[keep])
    C = len(names)
    if t.size < min_instants:
        return [offset_verdict(f"vision/{c}", float("nan"), float("inf"), float("inf"), 0, np.zeros(0), np.zeros(0),
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
        x, se, _ = jackknife(H_b, g_b, np.arange(C), L)
        tau = tau + x[:C]
        bias = x[C:].reshape(G, 3)
    H = H_b.sum(axis=0)
    white = np.sqrt(np.diag(L @ np.linalg.inv(H + ridge(H))[:C, :C] @ L.T))
    fit = (t, z, W * hub[:, None, None], share, bias[group])
    common = float(mean_share @ tau) if relative else 0.0
    out = []
    for c, name in enumerate(names):
        taus, curve = _camera_curve(fit, ref, tau, c, search_s)
        e = offset_verdict(f"vision/{name}", float(tau[c]) - common, float(se[c]), float(white[c]),
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
    return taus, cost_score(cost)


def camera_frame_stamps(rec_dir, rig, sequence: str = "run") -> dict[str, np.ndarray]:  # noqa: ANN001
    """Each camera's frame stamps (its ``timestamps.csv``) on ``rec_dir/<sequence>``."""
    from pathlib import Path

    from gtrig.vision.sequence import camera_indices

    return {name: ix.stamps_s for name, ix in camera_indices(Path(rec_dir), sequence, rig).items()}
