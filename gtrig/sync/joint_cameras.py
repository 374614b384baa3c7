"""The cameras' clock offsets refined in the joint fit: GTvision, GTlaser and odometry smoothed together,
each camera's poses shifted by its offset, until the offsets fitted against that smoothing reproduce
themselves.

Why: against GTlaser alone (:func:`gtrig.sync.sensors.camera_offsets`) a camera's offset inherits
GTlaser's pose errors over that camera's view. Those errors are slow (correlated over seconds, 0.5-0.8 mm
on the simulated runs) and differ from one part of the room to another (which hull sides the scanners
see), so they read as 0.5-1.5 ms of offset that differs by camera. Odometry's shape over a few seconds
is far better than that (0.1 mm per 20 ms increment), and the other cameras' poses pin the track where
they see the robot; the joint smoothing is the best trajectory the recording holds. It holds each
camera's own poses too, so a fit against it sees only part of that camera's offset: with the poses shifted
by ``tau`` the fit returns about ``(1 - w) tau_true + w tau`` (``w`` the camera's weight in the smoothing
over its view). The fixed point ``tau = fit(tau)`` is the joint estimate; ``w`` is measured per camera by
one probe (the fit's response to a shift of that camera alone), and Newton steps
``tau += (fit(tau) - tau) / (1 - w)`` reach the fixed point in two or three fits.

Interval: at the fixed point the estimate's error is the fit's error over ``1 - w`` (the fit's own
jackknife interval is scaled by ``1 / (1 - w)``), since the smoothing follows the camera's own noise by
the same share. Offsets are relative to GTvision's clock, as the pose fit's.

Measured on the three simulated seeds: largest camera error 0.69 /
0.80 / 1.18 ms against GTlaser, 0.36 / 0.97 / 0.93 ms jointly (the pipeline).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from gtrig.fusion.fuse import FusionOptions, fuse
from gtrig.fusion.measurements import fixes_from_track
from gtrig.io.odometry import OdometryLog
from gtrig.sync.cameras import camera_membership, camera_offsets, checkpoint_membership
from gtrig.sync.offset import OffsetEstimate
from gtrig.sync.reference import Reference
from gtrig.trajectory import PoseTrack

#: the shift of one camera's poses that measures its weight in the joint smoothing (s)
PROBE_S = 1e-3
#: a weight this close to 1 means the camera makes the smoothing alone there: no joint estimate
MAX_WEIGHT = 0.9


def joint_reference(vision: PoseTrack, laser: PoseTrack, odometry: OdometryLog, odometry_offset_s: float,
                    ) -> Reference:
    """GTvision and GTlaser (both on GTvision's clock) smoothed with odometry, as a :class:`Reference` on
    GTvision's clock; ``odometry_offset_s`` = GTvision's clock minus odometry's (``gtrig sync``)."""
    off = {"vision": odometry_offset_s, "laser": odometry_offset_s}
    track, _ = fuse([fixes_from_track(laser, "laser"), fixes_from_track(vision, "vision")], odometry,
                    FusionOptions(offsets_s=off))
    xyt = track.xytheta()
    xyt[:, 2] = np.unwrap(xyt[:, 2])
    stamps = track.stamps_s + odometry_offset_s
    cov = track.cov_xytheta()
    assert cov is not None  # fusion always gives one
    return Reference(stamps, xyt, np.gradient(xyt, stamps, axis=0), cov)


def restamped(vision: PoseTrack, times_s: np.ndarray) -> PoseTrack:
    """``vision`` (usable poses) at ``times_s``, sorted, a repeated time dropped."""
    order = np.argsort(times_s, kind="stable")
    keep = np.r_[True, np.diff(times_s[order]) > 0]
    return vision.select(order[keep], stamps_s=times_s[order][keep])


def joint_camera_offsets(vision: PoseTrack, camera_stamps_s: Mapping[str, np.ndarray], laser: PoseTrack,
                         odometry: OdometryLog, odometry_offset_s: float, first: list[OffsetEstimate],
                         checkpoint: str | os.PathLike[str] | None = None, steps: int = 3,
                         ) -> list[OffsetEstimate]:
    """Each camera's offset to GTvision's clock from the joint fit (module docstring).

    Parameters
    ----------
    vision : GTvision's track with covariances. camera_stamps_s : per camera, its frame stamps.
    laser : GTlaser's track on GTvision's clock (restamped by the scanners' offsets).
    odometry : the wheel odometry; odometry_offset_s : GTvision's clock minus odometry's, seconds.
    first : the pose fit against GTlaser (:func:`~gtrig.sync.sensors.camera_offsets`), one per camera
        in ``camera_stamps_s``'s order: the start, and the answer for a camera the joint fit cannot time.
    checkpoint : GTvision's checkpoint of detections (which camera made each pose, and when).
    steps : Newton steps after the probes.

    Returns
    -------
    One :class:`OffsetEstimate` per camera (``vision/<camera>``).
    """
    u = vision.usable()
    if checkpoint is not None:
        when, share = checkpoint_membership(u.stamps_s, checkpoint, camera_stamps_s)
    else:
        when, share = u.stamps_s, camera_membership(u.stamps_s, camera_stamps_s)
    ok = np.array([e.verdict == "ok" for e in first])
    if not ok.any():
        return first

    def fit(tau: np.ndarray, relative: bool = False) -> list[OffsetEstimate]:
        ref = joint_reference(restamped(u, when - share @ tau), laser, odometry, odometry_offset_s)
        return camera_offsets(u, camera_stamps_s, ref, membership=(when, share), relative=relative)

    def values(est: list[OffsetEstimate]) -> np.ndarray:
        return np.array([e.offset_s if e.verdict == "ok" else np.nan for e in est])

    # the iteration runs on offsets to the smoothing's own clock (a shift of one camera moves GTvision's
    # clock too, which offsets relative to it would hide from the probe); relative ones at the end
    tau = np.where(ok, values(first), 0.0)
    base = values(fit(tau))
    w = np.full(tau.size, np.nan)
    for k in np.flatnonzero(ok & np.isfinite(base)):
        probe = tau.copy()
        probe[k] += PROBE_S
        w[k] = (values(fit(probe))[k] - base[k]) / PROBE_S
    usable = ok & np.isfinite(base) & np.isfinite(w) & (w < MAX_WEIGHT)
    w = np.clip(np.where(usable, w, 0.0), 0.0, MAX_WEIGHT)
    for _ in range(steps):
        tau = np.where(usable, tau + (base - tau) / (1.0 - w), tau)
        base = values(fit(tau))
        usable &= np.isfinite(base)
    fixed = np.where(usable, tau + (base - tau) / (1.0 - w), tau)  # one more Newton step, not fitted again
    rel = fit(tau, relative=True)
    common = np.nanmedian(base - values(rel)) if usable.any() else 0.0  # the smoothing's clock to GTvision's
    out = []
    for c, (e0, e) in enumerate(zip(first, rel, strict=True)):
        if not usable[c] or e.verdict != "ok":
            out.append(e0)
            continue
        t = float(fixed[c] - common)
        half = (e.ci95_s[1] - e.ci95_s[0]) / 2 / (1.0 - w[c])
        out.append(replace(e, offset_s=t, ci95_s=(t - half, t + half), lags_s=e.lags_s + (t - e.offset_s),
                           reason=f"{e.reason}; joint with GTlaser and odometry (weight {w[c]:.2f}); "
                                  f"against GTlaser alone {e0.offset_s * 1e3:+.2f} ms"))
    return out
