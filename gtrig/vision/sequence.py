"""GTvision over a whole recording: frames grouped into instants, markers detected in parallel
processes (checkpointed), the corner noise calibrated on the sequence's residuals, every instant
estimated in parallel, then flips left ambiguous resolved in time order.

Instants
--------
* ``run``: the images of all cameras whose time stamps agree within ``sync_tol_s`` form one instant
  (free-running cameras rarely agree, so an instant is then one camera's frame; GTvision never mixes
  images of a moving robot taken at different times).
* ``validation``: the robot stands still during each interval of ``validation/poses.csv``, so all the
  images of all cameras inside one interval are one instant, stamped at the interval's middle (the
  stamps of ``truth/validation.tum``).

Corner noise: the detector's corner covariances are scaled by a variance factor per camera,
estimated from the residuals of (a sample of) this sequence's instants, iterated with the estimates
(:func:`calibrate_noise`, :mod:`gtrig.vision.noise`); only then are instants tested for consistency.

Determinism: each instant is detected and estimated independently of the others, so the output does
not depend on the number of workers or on the order chunks finish; the noise factors are a sum over
a fixed sample, and the only sequential step (the previous pose breaking a flip) runs afterwards, in
time order, in the main process.

Chunks: detection runs over one camera's consecutive images (a camera and a time window), estimation
over consecutive instants, on a local process pool or any executor (a Dask client: :mod:`gtrig.executor`);
the workers read their chunk's images themselves, the client never holds an image.

Resuming: every finished chunk of detections (the expensive part) is appended to a checkpoint file
by the client as it completes (JSON lines; floats are written with ``repr``, so a resumed run's output
is bit-identical; a line cut by a crash is dropped and its chunk detected again). A
checkpoint of other images, another detector, other lenses or other markers is refused; one written
before the camera or marker poses were calibrated again, or with other estimator settings, is reused
(detection does not depend on them).
"""

from __future__ import annotations

import csv
import hashlib
import json
import logging
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.errors import FormatError, InputError
from gtrig.io.frames import FrameIndex, read_frame_index, read_image
from gtrig.io.tum import Trajectory
from gtrig.kinematics import pose_velocities  # moved to the core; re-exported for its callers
from gtrig.rig.load import rig_to_dict
from gtrig.rig.models import Rig
from gtrig.trajectory import PoseTrack
from gtrig.vision.estimate import FrameEstimate, Status, VisionOptions, estimate_frame
from gtrig.vision.init import PreviousPose
from gtrig.vision.observations import FrameObservations, MarkerView, VisionModel

log = logging.getLogger(__name__)

CHECKPOINT_VERSION = 5
SEQUENCES = ("run", "validation")


@dataclass(frozen=True)
class Instant:
    """The images that make one instant: ``stamp_s`` and ``(camera, row in its frame index)``."""

    stamp_s: float
    images: tuple[tuple[str, int], ...]


@dataclass(frozen=True)
class VisionResult:
    """GTvision's output for one sequence.

    Attributes
    ----------
    sequence : "run" or "validation"
    estimates : one per instant, in time order (failed ones included, with their reason)
    observations : the detections of each instant (same order)
    images_per_camera : number of images read per camera
    detector : which corner detector was used
    seconds : wall time of the parallel pass (images read, detection), of the corner-noise
        calibration, of the estimation, and of the whole run
    corner_scale : ((camera, variance factor), ...) applied to the detector's corner covariances
        (estimated from this sequence's residuals unless given in the options; () = none)
    """

    sequence: str
    estimates: tuple[FrameEstimate, ...]
    observations: tuple[FrameObservations, ...] = field(repr=False)
    images_per_camera: dict[str, int]
    detector: str
    planar: bool
    seconds: dict[str, float]
    corner_scale: tuple[tuple[str, float], ...] = ()

    def localized(self) -> tuple[FrameEstimate, ...]:
        return tuple(e for e in self.estimates if e.ok)

    def trajectory(self) -> Trajectory:
        """The localized poses as ``T_world_robot`` (TUM)."""
        ok = self.localized()
        if not ok:
            return Trajectory(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4)))
        return Trajectory.from_matrices(np.array([e.stamp_s for e in ok]),
                                        np.stack([e.T_world_robot for e in ok]))  # type: ignore[misc]

    def to_pose_track(self) -> PoseTrack:
        """The localized poses as the one pose-track type: ``T_world_robot`` with the full (6, 6)
        covariance over the world-frame perturbation (x, y, z, rx, ry, rz), every pose OK (an instant that
        failed has no pose). A planar run's file carries the x, y, yaw marginal
        (:func:`write_pose_track_files`)."""
        ok = self.localized()
        if not ok:
            return PoseTrack.empty("GTvision", "se3")
        return PoseTrack.from_matrices(np.array([e.stamp_s for e in ok]),
                                       np.stack([e.T_world_robot for e in ok]),  # type: ignore[misc]
                                       cov=np.stack([e.cov_6x6 for e in ok]),  # type: ignore[misc]
                                       cov_kind="se3", source="GTvision")

    def covariances(self) -> np.ndarray:
        """(M, 6, 6), or (M, 3, 3) over x, y, yaw when planar, for the localized poses."""
        from gtrig.vision.covariance import planar_covariance

        covs = [e.cov_6x6 for e in self.localized() if e.cov_6x6 is not None]  # a localized pose has one
        if self.planar:
            return np.stack([planar_covariance(c) for c in covs]) if covs else np.zeros((0, 3, 3))
        return np.stack(covs) if covs else np.zeros((0, 6, 6))


# ------------------------------------------------------------------------------------------ instants
def camera_indices(rec_dir: Path, sequence: str, rig: Rig) -> dict[str, FrameIndex]:
    """The frame index of every rig camera that has a folder in ``REC/<sequence>/cameras``."""
    folder = rec_dir / sequence / "cameras"
    if not folder.is_dir():
        raise InputError(f"{folder}: no such folder (the recording has no {sequence} images)")
    out = {}
    for cam in rig.cameras:
        if (folder / cam.name).is_dir():
            out[cam.name] = read_frame_index(folder / cam.name)
    extra = sorted(p.name for p in folder.iterdir() if p.is_dir() and p.name not in out)
    if extra:
        log.warning("%s: folders %s are not cameras of the rig; ignored", folder, ", ".join(extra))
    if not out:
        raise InputError(f"{folder}: none of the rig's cameras ({', '.join(c.name for c in rig.cameras)}) "
                         "has a folder here")
    return out


def read_static_intervals(path: Path) -> np.ndarray:
    """``validation/poses.csv`` (pose,start_s,end_s) as (K, 2) seconds."""
    if not path.is_file():
        raise FormatError(f"{path}: no such file (the validation sequence needs its static intervals)")
    rows = []
    with open(path, newline="", encoding="utf-8") as f:
        r = csv.reader(f)
        header = next(r, None)
        if header is None or [h.strip() for h in header[:3]] != ["pose", "start_s", "end_s"]:
            raise FormatError(f"{path}:1: header must be 'pose,start_s,end_s'")
        for line, row in enumerate(r, 2):
            if not row or row[0].startswith("#"):
                continue
            try:
                rows.append((float(row[1]), float(row[2])))
            except (ValueError, IndexError):
                raise FormatError(f"{path}:{line}: expected 'pose,start_s,end_s'") from None
    return np.array(rows).reshape(-1, 2)


def make_instants(indices: dict[str, FrameIndex], sequence: str, sync_tol_s: float = 0.005,
                  intervals_s: np.ndarray | None = None) -> list[Instant]:
    """Group the images of all cameras into instants (see the module docstring)."""
    if sequence == "validation":
        if intervals_s is None:
            raise InputError("the validation sequence needs its static intervals")
        out = []
        for t0, t1 in intervals_s:
            imgs: list[tuple[str, int]] = []
            for name in sorted(indices):
                st = indices[name].stamps_s
                imgs.extend((name, int(i)) for i in np.flatnonzero((st >= t0) & (st <= t1)))
            out.append(Instant(float(0.5 * (t0 + t1)), tuple(imgs)))
        return out
    allf = sorted((float(ix.stamps_s[i]), name, i) for name, ix in indices.items() for i in range(len(ix)))
    out = []
    group: list[tuple[float, str, int]] = []
    for t, name, i in allf:
        if group and (t - group[0][0] > sync_tol_s or any(g[1] == name for g in group)):
            out.append(Instant(float(np.mean([g[0] for g in group])), tuple((g[1], g[2]) for g in group)))
            group = []
        group.append((t, name, i))
    if group:
        out.append(Instant(float(np.mean([g[0] for g in group])), tuple((g[1], g[2]) for g in group)))
    return out


# ---------------------------------------------------------------------------------- (de)serialising
def _arr(a: np.ndarray | None) -> Any:
    return None if a is None else np.asarray(a, dtype=float).tolist()


# --------------------------------------------------------------------------------------- the workers
@dataclass(frozen=True)
class WorkerContext:
    """What a worker needs besides its chunk: the rig (as its YAML document) and the detector's name.
    Small (a few kB), so it travels with every chunk, to a local process or a Dask worker alike; each
    process builds the model and the detector from it once (``token`` names it)."""

    token: str
    rig_doc: dict[str, Any] = field(repr=False)
    detector: str

    @staticmethod
    def of(rig: Rig, detector: str) -> WorkerContext:
        doc = rig_to_dict(rig)
        token = hashlib.sha256(json.dumps([doc, detector], sort_keys=True, default=str).encode()).hexdigest()[:16]
        return WorkerContext(token, doc, detector)


_W: dict[str, Any] = {}


def _state(ctx: WorkerContext) -> dict[str, Any]:
    """This process's model and detector for ``ctx`` (built on first use; the client seeds its own)."""
    if _W.get("token") != ctx.token:
        import cv2

        from gtrig.rig.load import rig_from_dict
        from gtrig.vision.detect import make_detector
        from gtrig.vision.noise import limit_blas_threads

        cv2.setNumThreads(1)
        limit_blas_threads(1)
        rig = rig_from_dict(ctx.rig_doc)
        _W.clear()
        _W.update(token=ctx.token, model=VisionModel.from_rig(rig), detect=make_detector(rig, ctx.detector))
    return _W


def _seed(ctx: WorkerContext, model: VisionModel, detect: Any) -> None:
    """The client's own model and detector under ``ctx`` (in-process chunks and forked workers use them)."""
    _W.clear()
    _W.update(token=ctx.token, model=model, detect=detect)


def _views_to_json(views: Sequence[MarkerView]) -> list[list[Any]]:
    return [[v.marker_id, _arr(v.corners_px), _arr(v.corner_cov)] for v in views]


def _views_from_json(camera: str, row: int, d: list[list[Any]]) -> tuple[MarkerView, ...]:
    return tuple(MarkerView(camera, int(m), np.array(uv), np.array(cov), row) for m, uv, cov in d)


def _process_chunk(ctx: WorkerContext, camera: str, rows: Sequence[int], paths: Sequence[str]
                   ) -> list[list[Any]]:
    """Markers detected in one camera's images ``rows`` (read here, on the worker, from ``paths``):
    ``[[row, [[marker_id, corners, cov], ...]], ...]``, the checkpoint's JSON form."""
    st = _state(ctx)
    cam = st["model"].cameras[camera]
    out = []
    for i, path in zip(rows, paths, strict=True):
        img = read_image(path)  # an image file or a video's frame
        out.append([int(i), _views_to_json(st["detect"](img, cam))])
    return out


def _estimate_chunk(ctx: WorkerContext, obs: Sequence[FrameObservations], options: VisionOptions
                    ) -> list[FrameEstimate]:
    model = _state(ctx)["model"]
    return [estimate_frame(model, o, options) for o in obs]


def _instant_label(obs: Sequence[FrameObservations]) -> str:
    return f"instants {obs[0].stamp_s:.3f}-{obs[-1].stamp_s:.3f} s" if obs else "no instant"


def _map_in_chunks(fn: Callable[..., list[Any]], items: Sequence[Any], args: Callable[[list[Any]], tuple[Any, ...]],
                   label: Callable[[list[Any]], str], chunk_size: int, executor: Any, workers: int) -> list[Any]:
    """``fn(*args(chunk))`` over consecutive chunks of ``items``, results concatenated in order."""
    from gtrig.executor import Chunk, map_chunks

    parts = [list(items[i:i + chunk_size]) for i in range(0, len(items), chunk_size)]
    out: dict[int, list[Any]] = {}
    map_chunks(fn, [Chunk(args(p), label(p)) for p in parts], out.__setitem__, executor=executor, workers=workers)
    return [x for i in range(len(parts)) for x in out[i]]


def _estimate_all(ctx: WorkerContext, obs: list[FrameObservations], options: VisionOptions, chunk_size: int,
                  executor: Any, workers: int) -> list[FrameEstimate]:
    """Every instant estimated again from its detections (no image read), in parallel chunks."""
    return _map_in_chunks(_estimate_chunk, obs, lambda p: (ctx, p, options), _instant_label, chunk_size,
                          executor, workers)


def calibrate_noise(obs: Sequence[FrameObservations], options: VisionOptions, cameras: Sequence[str],
                    estimate: Callable[[VisionOptions, list[FrameObservations]], list[FrameEstimate]],
                    max_rounds: int = 1, tol: float = 0.05, sample: int = 300, rig_component: bool = False,
                    ) -> tuple[VisionOptions, list[tuple[tuple[str, float], ...]]]:
    """Variance factors of the corner covariances from the residuals of the sequence's instants
    (:mod:`gtrig.vision.noise`; one step by default, see there why).

    The factors are estimated on at most ``sample`` instants with detections, evenly spread over the
    sequence (their redundancy, thousands of corners, pins a factor to a few per cent; estimating every
    instant at every round would cost more than the detection). ``estimate(opts, observations)``
    estimates a list of instants. With ``max_rounds`` > 1 the factors are re-estimated with the new
    ones until none moves by more than ``tol`` (relative). Returns the options with the final factors and the history of
    factors (one entry per round).

    With ``rig_component`` the residuals are split between two components: the corners of each camera
    (their own chi-square over their redundancy) and the rig's stated uncertainty (its nuisance priors',
    :func:`gtrig.vision.noise.estimate_rig_scale`), iterated together until neither moves by more than
    ``tol``; the history's entries then end with ``("rig", factor)``, the rig's total factor. Charging
    everything to the corners (one component) kept a rig stated ten times worse than it is dominating
    every pose's covariance. The split needs instants that over-determine the rig's nuisances (several
    markers per camera, as static validation stops have); on moving instants that show one marker to
    one camera it runs away (:attr:`gtrig.vision.estimate.VisionOptions.rig_variance_component`).
    """
    from gtrig.vision.noise import estimate_corner_scale, estimate_rig_scale, scale_change

    with_views = [i for i, o in enumerate(obs) if o.views]
    if len(with_views) > sample:
        with_views = [with_views[int(k)] for k in np.linspace(0, len(with_views) - 1, sample).round()]
    sub = [obs[i] for i in with_views]
    history: list[tuple[tuple[str, float], ...]] = []
    if not sub:
        return options, history
    ests = estimate(options, sub)
    for k in range(max_rounds):
        good = [e for e in ests if e.status in (Status.OK, Status.INCONSISTENT)]
        fits = [e.corner_noise if rig_component else e.noise for e in good]
        scale = estimate_corner_scale(fits, cameras, dict(options.corner_scale))
        if not scale:
            break
        change = scale_change(options.corner_scale, scale)
        options = replace(options, corner_scale=scale)
        s_rig = estimate_rig_scale([e.rig_noise for e in good]) if rig_component else None
        if s_rig is not None:
            options = replace(options, rig_uncertainty=options.rig_uncertainty.scaled(s_rig))
            change = max(change, abs(s_rig - 1.0))
            scale = scale + (("rig", options.rig_uncertainty.variance_factor),)
        history.append(scale)
        if change <= tol or k == max_rounds - 1:
            break
        ests = estimate(options, sub)
    return options, history


# ----------------------------------------------------------------------------------------- the runner
def _key(rig: Rig, sequence: str, detector: str, paths: dict[str, list[str]], rec: Path | None = None) -> str:
    """What the checkpointed detections depend on: the images, the detector, the lenses and the markers'
    families and sizes; not the poses, the estimator's options nor how images group into instants, so a
    re-estimation with a newly calibrated rig or other settings reuses them. The images count by their
    path inside the recording ``rec``, so a recording moved or copied elsewhere keeps its detections."""
    if rec is not None:
        paths = {c: [os.path.relpath(p, rec) for p in ps] for c, ps in paths.items()}
    doc_rig = rig_to_dict(rig)
    for c in doc_rig["cameras"]:
        for k in ("T_world_cam", "pose_cov", "stamp_sigma_s"):
            c.pop(k, None)
        # a calibration repeated on another machine differs in the last digits (threaded BLAS), which
        # does not change a detection
        c["camera_matrix"] = [[float(f"{v:.9g}") for v in row] for row in c["camera_matrix"]]
        c["dist_coeffs"] = [float(f"{v:.9g}") for v in c["dist_coeffs"]]
    markers = [{k: m[k] for k in ("family", "id", "side_m")} for m in doc_rig["robot"]["markers"]]
    doc = {"v": CHECKPOINT_VERSION, "cameras": doc_rig["cameras"], "markers": markers, "sequence": sequence,
           "detector": detector, "paths": paths}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:20]


#: detections by camera and row of its frame index
Detections = dict[str, dict[int, tuple[MarkerView, ...]]]


def _load_checkpoint(path: Path, key: str) -> tuple[Detections, int]:
    """The detections in ``path`` and the length of its good part (a line cut by an interruption, and
    what follows it, is dropped: that chunk is detected again)."""
    if not path.is_file():
        return {}, 0
    dets: Detections = {}
    with open(path, "rb") as f:
        first = f.readline()
        try:
            head = json.loads(first)
        except (json.JSONDecodeError, UnicodeDecodeError):
            head = {}
        if not isinstance(head, dict) or not isinstance(head.get("key"), str):
            # not what run_recording writes (a corrupt or foreign file): never trusted, started afresh
            log.warning("%s: not a GTvision checkpoint (corrupt header); starting afresh", path)
            return {}, 0
        if head["key"] != key:
            raise InputError(f"{path}: checkpoint of another run (other images, detector, lenses or markers); "
                             "delete it or choose another output")
        good = f.tell()
        for line in f:
            try:
                d = json.loads(line)
                cam = d["camera"]
                got = {int(r): _views_from_json(cam, int(r), v) for r, v in d["frames"]}
            except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError, ValueError, InputError):
                break  # a line cut by an interruption, or damaged: never trusted, detected again
            if not line.endswith(b"\n"):
                break
            dets.setdefault(cam, {}).update(got)
            good += len(line)
    return dets, good


def _open_checkpoint(ck: Path, key: str, stale: str) -> tuple[Detections, Any]:
    """The detections already in the checkpoint ``ck`` and the file opened to append the next chunks."""
    try:
        dets, good = _load_checkpoint(ck, key)
    except InputError as err:
        if stale != "restart":
            raise
        log.warning("%s; starting afresh", err)
        dets, good = {}, 0
    ck.parent.mkdir(parents=True, exist_ok=True)
    if good == 0:
        f = open(ck, "w", encoding="utf-8")  # noqa: SIM115
        f.write(json.dumps({"key": key, "version": CHECKPOINT_VERSION}) + "\n")
        f.flush()
    else:
        with open(ck, "r+b") as g:  # drop a torn last line
            g.truncate(good)
        f = open(ck, "a", encoding="utf-8")  # noqa: SIM115
    return dets, f


def detection_chunks(instants: Sequence[Instant], indices: dict[str, FrameIndex], chunk_size: int
                     ) -> list[tuple[str, list[int]]]:
    """The detection work: for each camera, the rows of its frame index that some instant uses, in
    runs of ``chunk_size`` consecutive ones (a camera and a time window)."""
    rows: dict[str, set[int]] = {}
    for ins in instants:
        for cam, i in ins.images:
            rows.setdefault(cam, set()).add(i)
    out: list[tuple[str, list[int]]] = []
    for cam in sorted(rows):
        r = sorted(rows[cam])
        out.extend((cam, r[k:k + chunk_size]) for k in range(0, len(r), chunk_size))
    return out


def _detect_all(ctx: WorkerContext, chunks: list[tuple[str, list[int]]], indices: dict[str, FrameIndex],
                dets: Detections, ckf: Any, executor: Any, workers: int,
                progress: Callable[[int, int], None] | None) -> None:
    """The chunks not in ``dets`` detected on the workers, each appended to the checkpoint ``ckf`` as one
    line as it completes (the images are read by the workers, never sent from here)."""
    from gtrig.executor import Chunk, map_chunks

    jobs = []
    for cam, rows in chunks:
        ix = indices[cam]
        label = f"camera {cam}, {ix.stamps_s[rows[0]]:.3f}-{ix.stamps_s[rows[-1]]:.3f} s"
        jobs.append(Chunk((ctx, cam, rows, [ix.source(i) for i in rows]), label))
    todo = [k for k, (cam, rows) in enumerate(chunks) if not all(i in dets.get(cam, {}) for i in rows)]
    if len(todo) < len(chunks):
        log.info("resuming: %d of %d detection chunks already checkpointed", len(chunks) - len(todo), len(chunks))

    def record(k: int, frames: list[list[Any]]) -> None:
        cam = chunks[k][0]
        if ckf is not None:  # one line per finished chunk: an interrupted run resumes from here
            ckf.write(json.dumps({"camera": cam, "frames": frames}) + "\n")
            ckf.flush()
        dets.setdefault(cam, {}).update((int(r), _views_from_json(cam, int(r), v)) for r, v in frames)

    map_chunks(_process_chunk, jobs, record, executor=executor, workers=workers, todo=todo, progress=progress)


def _observations(instants: Sequence[Instant], dets: Detections) -> list[FrameObservations]:
    return [FrameObservations(ins.stamp_s, tuple(v for cam, i in ins.images for v in dets[cam][i]),
                              tuple(sorted({c for c, _ in ins.images})), tuple(ins.images)) for ins in instants]


def _resolve_flips(model: VisionModel, obs: list[FrameObservations], ests: list[FrameEstimate],
                   options: VisionOptions) -> list[FrameEstimate]:
    """Re-estimate ambiguous instants with the previous localized pose, in time order."""
    last: FrameEstimate | None = None
    out = []
    for o, e in zip(obs, ests, strict=True):
        if e.status is Status.AMBIGUOUS and last is not None and \
                o.stamp_s - last.stamp_s <= options.previous_max_gap_s:
            assert last.T_world_robot is not None
            e = estimate_frame(model, o, options, PreviousPose(last.T_world_robot))
            if e.ok:
                e = replace(e, reason="flip resolved by the previous pose")
        if e.ok:
            last = e
        out.append(e)
    return out


def camera_time_offsets(obs: Sequence[FrameObservations], indices: dict[str, FrameIndex]
                        ) -> list[dict[str, float]]:
    """Per instant, each camera's image stamp minus the instant's stamp, seconds (the mean of its
    images' stamps: cameras that are not triggered together fall up to ``sync_tol_s`` apart)."""
    out = []
    for o in obs:
        per: dict[str, list[float]] = {}
        for cam, row in o.frames:
            per.setdefault(cam, []).append(float(indices[cam].stamps_s[row]) - o.stamp_s)
        out.append({c: float(np.mean(v)) for c, v in per.items()})
    return out


def _moving_instant(model: VisionModel, o: FrameObservations, options: VisionOptions, first: FrameEstimate,
                    deltas: dict[str, np.ndarray], extra: dict[str, np.ndarray]) -> FrameEstimate:
    opts = replace(options, rig_uncertainty=options.rig_uncertainty.with_camera_timing(extra))
    # the first estimate settled the flip: start from it (a third of the cost of a new search)
    return estimate_frame(model.with_camera_motion(deltas) if deltas else model, o, opts, start=first)


def _moving_chunk(ctx: WorkerContext, items: Sequence[tuple[Any, ...]], options: VisionOptions
                  ) -> list[FrameEstimate]:
    model = _state(ctx)["model"]
    return [_moving_instant(model, o, options, e, d, x) for o, e, d, x in items]


def compensate_motion(model: VisionModel, obs: Sequence[FrameObservations], ests: Sequence[FrameEstimate],
                      offsets: Sequence[dict[str, float]], stamp_sigma_s: dict[str, float],
                      options: VisionOptions, *, max_gap_s: float = 0.5, chunk_size: int = 16,
                      context: WorkerContext | None = None, executor: Any = None, workers: int = 1
                      ) -> tuple[list[FrameEstimate], set[int]]:
    """The moving instants estimated again with their cameras' exposure times.

    Two things the first estimate of an instant cannot know, from the velocity of the neighbouring
    poses (:func:`pose_velocities`):

    * cameras exposed at different times: free-running cameras whose images fall within 5 ms are one
      instant, stamped at their mean. At 0.3 m/s two cameras 4 ms apart see the robot 1.2 mm apart;
      fitted together, their views disagree and the compromise lands off the path, across it as much as
      along it. Each camera's view is moved to the instant's stamp by the motion over its offset
      ``offsets[i][c]`` (:meth:`VisionModel.with_camera_motion`).
    * each camera's own time-stamp jitter (``stamp_sigma_s``): a camera nuisance along the motion
      (:func:`gtrig.vision.covariance.timing_camera_covariance`), so that the cameras may disagree by
      their own jitter and the pose's covariance holds it (this replaces
      :func:`with_timing_uncertainty` for these instants).

    Only instants whose views come from two cameras or more are estimated again: one camera's timing
    error moves its view exactly as the robot's motion over that time would, so for a single camera the
    nuisance equals :func:`with_timing_uncertainty`'s term on the pose and the estimate is unchanged.

    Returns the estimates and the indices of those whose covariance now includes the timing; an instant
    whose second estimate fails keeps its first.
    """
    from gtrig.vision.covariance import timing_camera_covariance

    ok = [i for i, e in enumerate(ests) if e.ok]
    out = list(ests)
    if len(ok) < 2:
        return out, set()
    T = np.stack([ests[i].T_world_robot for i in ok])  # type: ignore[misc]
    vel = pose_velocities(np.array([ests[i].stamp_s for i in ok]), T, max_gap_s)
    jobs: list[tuple[int, tuple[Any, ...]]] = []
    for k, i in enumerate(ok):
        if not np.any(vel[k]) or len(obs[i].cameras_with_views()) < 2:
            continue
        t = T[k][:3, 3]
        deltas, extra = {}, {}
        for c, dt in offsets[i].items():
            if c not in model.cameras:
                continue
            if abs(dt) > 1e-6:
                D = np.eye(4)
                D[:3, :3] = Rotation.from_rotvec(vel[k, 3:] * dt).as_matrix()
                D[:3, 3] = t + vel[k, :3] * dt - D[:3, :3] @ t
                deltas[c] = D
            sig = stamp_sigma_s.get(c, 0.0)
            if sig > 0:
                extra[c] = timing_camera_covariance(vel[k], T[k], model.cameras[c].T_world_cam[:3, 3], sig)
        if deltas or extra:
            jobs.append((i, (obs[i], ests[i], deltas, extra)))
    if context is None:  # ``model`` is not a rig's: estimated here
        res = [_moving_instant(model, o, options, e, d, x) for _, (o, e, d, x) in jobs]
    else:
        res = _map_in_chunks(_moving_chunk, [it for _, it in jobs], lambda p: (context, p, options),
                             lambda p: _instant_label([it[0] for it in p]), chunk_size, executor, workers)
    done: set[int] = set()
    for (i, _), e in zip(jobs, res, strict=True):
        if e.ok:
            out[i] = e
            done.add(i)
    log.info("%d moving instants estimated again with their cameras' exposure times", len(done))
    return out, done


def run_recording(rec_dir: str | os.PathLike[str], rig: Rig, sequence: str = "validation",
                  planar: bool = True, workers: int = 0, *, options: VisionOptions | None = None,
                  detector: str = "auto",
                  checkpoint: str | os.PathLike[str] | None = None,
                  progress: Callable[[int, int], None] | None = None, chunk_size: int | None = None,
                  sync_tol_s: float = 0.005, estimate_noise: bool = True,
                  stale_checkpoint: str = "refuse", executor: Any = None) -> VisionResult:
    """GTvision over one sequence of a recording.

    Parameters
    ----------
    rec_dir : the recording folder (docs/formats.md).
    rig : the calibrated rig (cameras and markers); never the truth.
    sequence : "validation" (one pose per static interval) or "run" (one pose per instant).
    planar : use the floor prior (``options.planar`` is overridden by this).
    workers : local processes when ``executor`` is None; 0 = one per core, 1 = in this process.
    executor : a ``concurrent.futures.Executor`` or a Dask ``distributed.Client`` to map the chunks over
        (:mod:`gtrig.executor`); None: a local pool of ``workers``. The output does not depend on it.
    options : estimation settings (default :class:`VisionOptions`).
    detector : "auto", "gtrig" or "aruco" (see :func:`gtrig.vision.detect.make_detector`).
    checkpoint : file to resume from and append to; None: no checkpoint.
    stale_checkpoint : a checkpoint of other images, lenses or markers is refused ("refuse": a user's
        file is not overwritten by guess) or started afresh ("restart": a folder the caller owns).
    progress : called as ``progress(done_chunks, total_chunks)`` over the detection chunks (each: one
        camera's ``chunk_size`` images in a time window).
    estimate_noise : estimate the corner covariances' variance factor per camera from this sequence's
        residuals and estimate every instant again with it (:func:`calibrate_noise`); ignored when
        ``options.corner_scale`` is given (those factors are used as they are).
    Returns
    -------
    VisionResult
        For the run, each pose's covariance includes the motion hidden by its cameras' time-stamp
        jitter (``stamp_sigma_s`` in the rig; :func:`with_timing_uncertainty`); every pose's, the
        markers' common frame error when the rig gives one (``robot.markers_frame_cov``).
    """
    from gtrig.vision.detect import make_detector

    t_start = time.perf_counter()
    if sequence not in SEQUENCES:
        raise InputError(f"unknown sequence {sequence!r}; choose run or validation")
    rec = Path(rec_dir)
    opts = options or VisionOptions()
    # the cameras' and markers' own calibrated covariances, where the rig holds them
    opts = replace(opts, planar=planar, rig_uncertainty=opts.rig_uncertainty.with_rig(rig))
    model = VisionModel.from_rig(rig)
    det = make_detector(rig, detector)
    det_name = det.name
    indices = camera_indices(rec, sequence, rig)
    intervals = read_static_intervals(rec / "validation" / "poses.csv") if sequence == "validation" else None
    instants = make_instants(indices, sequence, sync_tol_s, intervals)
    paths = {name: [ix.source(i) for i in range(len(ix))] for name, ix in indices.items()}
    if chunk_size is None:
        # at least 32 chunks where the sequence allows, so that an interruption loses little; it depends
        # on the sequence alone, never on the workers, so a run resumed with other workers finds the same
        chunk_size = min(16, max(1, sum(len(ins.images) for ins in instants) // 32))
    chunks = detection_chunks(instants, indices, chunk_size)
    # a new version of the detector's code makes other detections: not the checkpoint's
    key = _key(rig, sequence, f"{det.name}/{det.version}", paths, rec)
    del paths  # the workers read their chunk's images by path; the client keeps no list of them
    ctx = WorkerContext.of(rig, detector)
    _seed(ctx, model, det)
    dets: Detections = {}
    ckf = None
    if checkpoint is not None:
        dets, ckf = _open_checkpoint(Path(checkpoint), key, stale_checkpoint)
    t_par = time.perf_counter()
    try:
        _detect_all(ctx, chunks, indices, dets, ckf, executor, workers, progress)
    finally:
        if ckf:
            ckf.close()
    t_par = time.perf_counter() - t_par
    obs = _observations(instants, dets)
    del dets
    t_noise = time.perf_counter()
    if estimate_noise and not opts.corner_scale:
        opts, history = calibrate_noise(obs, opts, sorted(indices),
                                        lambda o, x: _estimate_all(ctx, x, o, chunk_size, executor, workers),
                                        max_rounds=10 if opts.rig_variance_component else 1,
                                        rig_component=opts.rig_variance_component)
        for k, sc in enumerate(history):
            log.info("corner noise, round %d: variance factors %s", k + 1,
                     ", ".join(f"{c} {f:.3g}" for c, f in sc))
    t_noise = time.perf_counter() - t_noise
    t_est = time.perf_counter()
    ests = _estimate_all(ctx, obs, opts, chunk_size, executor, workers)
    ests = _resolve_flips(model, obs, ests, opts)
    stamp_sigma = {c.name: c.stamp_sigma_s for c in rig.cameras}
    timed: set[int] = set()
    if sequence == "run":
        ests, timed = compensate_motion(model, obs, ests, camera_time_offsets(obs, indices), stamp_sigma, opts,
                                        chunk_size=chunk_size, context=ctx, executor=executor, workers=workers)
    t_est = time.perf_counter() - t_est
    for e in ests:  # an empty view is the common case in a run: not worth a line each
        if not e.ok:
            log.log(logging.DEBUG if e.status is Status.NO_MARKER else logging.INFO,
                    "t=%.6f not localized: %s: %s", e.stamp_s, e.status.value, e.reason)
    counts = {name: len(ix) for name, ix in indices.items()}
    res = VisionResult(sequence, tuple(ests), tuple(obs), counts, det_name, planar,
                       {"parallel": t_par, "noise": t_noise, "estimate": t_est,
                        "total": time.perf_counter() - t_start},
                       opts.corner_scale)
    res = with_timing_uncertainty(res, stamp_sigma, skip=timed)
    if rig.robot.markers_frame_cov is not None:
        res = with_robot_frame_uncertainty(res, np.asarray(rig.robot.markers_frame_cov, float))
    return res


def with_robot_frame_uncertainty(result: VisionResult, cov_frame_6x6: np.ndarray) -> VisionResult:
    """A new result whose pose covariances include a common error of the robot frame itself
    (``cov_frame_6x6`` over (dt, dphi) in robot axes, e.g. from
    :func:`gtrig.vision.covariance.anchor_frame_covariance`); the poses are unchanged."""
    from gtrig.vision.covariance import add_robot_frame_covariance

    ests = tuple(
        replace(e, cov_6x6=add_robot_frame_covariance(e.T_world_robot, e.cov_6x6, cov_frame_6x6))
        if e.cov_6x6 is not None and e.T_world_robot is not None else e
        for e in result.estimates
    )
    return replace(result, estimates=ests)


def with_timing_uncertainty(result: VisionResult, stamp_sigma_s: dict[str, float],
                            max_gap_s: float = 0.5, skip: set[int] | frozenset[int] = frozenset()
                            ) -> VisionResult:
    """A new result whose moving poses' covariances include the motion hidden by time-stamp jitter.

    An image stamped ``t`` was exposed at ``t + e``, ``e ~ N(0, sigma_t^2)`` (``sigma_t``: the
    camera's ``stamp_sigma_s``; the largest of an instant's cameras). The estimate is the pose at
    ``t + e``, so as the pose at ``t`` it is off by ``xi = (v, omega) e``: the covariance gains
    ``sigma_t^2 xi_dot xi_dot^T``, with the velocity from the neighbouring localized poses
    (:func:`pose_velocities`). At 0.3 m/s and 2 ms that is 0.6 mm, the size of the corner noise's
    own share on a near marker; static sequences (validation) are left alone, and so are the estimates
    whose indices are in ``skip`` (their cameras' timing is in their covariance already,
    :func:`compensate_motion`). Poses are unchanged.
    """
    ok = [i for i, e in enumerate(result.estimates) if e.ok]
    if result.sequence != "run" or len(ok) < 2 or not any(v > 0 for v in stamp_sigma_s.values()):
        return result
    ests = list(result.estimates)
    T = np.stack([ests[i].T_world_robot for i in ok])  # type: ignore[misc]
    vel = pose_velocities(np.array([ests[i].stamp_s for i in ok]), T, max_gap_s)
    for k, i in enumerate(ok):
        e = ests[i]
        if i in skip:
            continue
        sig = max((stamp_sigma_s.get(cam, 0.0) for cam, _ in e.views), default=0.0)
        if sig > 0 and e.cov_6x6 is not None:
            ests[i] = replace(e, cov_6x6=e.cov_6x6 + sig**2 * np.outer(vel[k], vel[k]))
    return replace(result, estimates=tuple(ests))


def file_track(result: VisionResult) -> PoseTrack:
    """The track as written: the localized poses with their x, y, yaw covariance when planar (the floor
    prior fixes z, roll and pitch), else the full 6 x 6."""
    track = result.to_pose_track()
    return track.with_cov(track.cov_xytheta(), "xyyaw") if result.planar else track


def write_pose_track_files(result: VisionResult, tum_path: str | os.PathLike[str],
                           cov_path: str | os.PathLike[str] | None = None) -> None:
    """The TUM file and (with ``cov_path``) the one covariance CSV layout of gtrig.io.posetrack, both or
    neither."""
    from gtrig.io.posetrack import write_pose_track

    write_pose_track(file_track(result), tum_path, cov_path)


def write_covariance_csv(path: str | os.PathLike[str], result: VisionResult) -> None:
    """The covariance CSV alone (gtrig.io.posetrack's layout: ``stamp_s,status,reason,cov_x_x,...``),
    one row per localized pose, atomically."""
    from gtrig.io.atomic import atomic_write_text
    from gtrig.io.posetrack import covariance_text

    atomic_write_text(path, covariance_text(file_track(result)))


def read_covariance_csv(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps_s (M,), cov (M, k, k))`` from :func:`write_covariance_csv` (or the layout before it)."""
    from gtrig.io.posetrack import read_covariance_csv as read_any

    stamps, cov, kind, *_ = read_any(path)
    if cov is None:
        raise FormatError(f"{path}: no covariance columns")
    return stamps, cov
