"""GTvision over a whole recording: frames grouped into instants, markers detected in parallel
processes (checkpointed), the corner noise calibrated on the sequence's residuals, every instant
estimated in parallel, then flips left ambiguous resolved in time order.

Instants: which images make one pose (:mod:`gtrig.vision.instants`): in ``run``, the images of all
cameras whose stamps agree within ``sync_tol_s``; in ``validation``, every image of a static interval.

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

Memory: the client's state does not grow with the recording beyond its index (frame
indices, instants): detections are read back from the checkpoint (or a temporary file) a line at a time,
each stage's estimates are written to a temporary file chunk by chunk and read back in time order.
"""

from __future__ import annotations

import csv
import hashlib
import json
import logging
import math
import os
import pickle
import tempfile
import time
import weakref
from array import array
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.errors import FormatError, InputError
from gtrig.io.frames import FrameIndex, read_frame_index, read_image
from gtrig.io.imagetone import declared_tone
from gtrig.io.tum import Trajectory
from gtrig.kinematics import pose_velocities  # moved to the core; re-exported for its callers
from gtrig.rig.load import rig_to_dict
from gtrig.rig.models import Rig
from gtrig.trajectory import PoseTrack
from gtrig.vision.estimate import FrameEstimate, Status, VisionOptions, estimate_consecutive, estimate_frame
from gtrig.vision.init import PreviousPose
from gtrig.vision.instants import Instant, Instants, make_instants  # re-exported for their callers
from gtrig.vision.observations import FrameObservations, MarkerView, VisionModel
from gtrig.vision.track import TrackOptions

log = logging.getLogger(__name__)

CHECKPOINT_VERSION = 5
SEQUENCES = ("run", "validation")


@dataclass(frozen=True)
class VisionResult:
    """GTvision's output for one sequence.

    Attributes
    ----------
    sequence : "run" or "validation"
    estimates : one per instant, in time order (failed ones included, with their reason); from
        :func:`run_recording` a sequence read back from a temporary file, so that the client's memory does
        not grow with the recording (pickling it makes a tuple)
    observations : the detections of each instant (same order), read back from the detections' file
    images_per_camera : number of images read per camera
    detector : which corner detector was used
    seconds : wall time of the parallel pass (images read, detection), of the corner-noise
        calibration, of the estimation, and of the whole run
    corner_scale : ((camera, variance factor), ...) applied to the detector's corner covariances
        (estimated from this sequence's residuals unless given in the options; () = none)
    """

    sequence: str
    estimates: Sequence[FrameEstimate]
    observations: Sequence[FrameObservations] = field(repr=False)
    images_per_camera: dict[str, int]
    detector: str
    planar: bool
    seconds: dict[str, float]
    corner_scale: tuple[tuple[str, float], ...] = ()

    def localized(self) -> tuple[FrameEstimate, ...]:
        return tuple(e for e in self.estimates if e.ok)

    def _localized_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(stamps (M,), T_world_robot (M, 4, 4), cov (M, 6, 6))`` of the localized poses, gathered one
        estimate at a time (the estimates themselves are not kept: a long run's are on disk)."""
        stamps, Ts, covs = [], [], []
        for e in self.estimates:
            if e.ok:
                stamps.append(e.stamp_s)
                Ts.append(e.T_world_robot)
                covs.append(e.cov_6x6)
        if not stamps:
            return np.zeros(0), np.zeros((0, 4, 4)), np.zeros((0, 6, 6))
        # an OK estimate has a covariance; one without (a hand-made result) still gives a trajectory
        cov = np.stack(covs) if all(c is not None for c in covs) else None  # type: ignore[arg-type]
        return np.array(stamps), np.stack(Ts), cov  # type: ignore[arg-type,return-value]

    def trajectory(self) -> Trajectory:
        """The localized poses as ``T_world_robot`` (TUM)."""
        stamps, T, _ = self._localized_arrays()
        if not len(stamps):
            return Trajectory(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4)))
        return Trajectory.from_matrices(stamps, T)

    def to_pose_track(self) -> PoseTrack:
        """The localized poses as the one pose-track type: ``T_world_robot`` with the full (6, 6)
        covariance over the world-frame perturbation (x, y, z, rx, ry, rz), every pose OK (an instant that
        failed has no pose). A planar run's file carries the x, y, yaw marginal
        (:func:`write_pose_track_files`)."""
        stamps, T, cov = self._localized_arrays()
        if not len(stamps):
            return PoseTrack.empty("GTvision", "se3")
        return PoseTrack.from_matrices(stamps, T, cov=cov, cov_kind="se3", source="GTvision")

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


def check_image_sizes(indices: Mapping[str, FrameIndex], rig: Rig) -> None:
    """Refuse, before any detection, a camera whose first image is not the size its rig entry says."""
    for name, ix in indices.items():
        if not len(ix):
            continue
        h, w = read_image(ix.source(0)).shape[:2]
        want = tuple(int(v) for v in rig.camera(name).resolution)
        if (w, h) != want:
            raise InputError(f"{ix.source(0)}: a {w} x {h} image, but the rig's cameras.{name}.resolution is "
                             f"{want[0]} x {want[1]}")


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
                start_s, end_s = float(row[1]), float(row[2])
            except (ValueError, IndexError):
                raise FormatError(f"{path}:{line}: expected 'pose,start_s,end_s'") from None
            if not (np.isfinite(start_s) and np.isfinite(end_s) and start_s <= end_s):
                raise FormatError(f"{path}:{line}: start_s {row[1].strip()} and end_s {row[2].strip()} are not an "
                                  "interval (finite, start before end)")
            rows.append((start_s, end_s))
    return np.array(rows).reshape(-1, 2)


# ---------------------------------------------------------------------------------- (de)serialising
def _arr(a: np.ndarray | None) -> Any:
    return None if a is None else np.asarray(a, dtype=float).tolist()


# ------------------------------------------------------------------------------- streamed state
# The client's state over a recording is kept on disk, not in memory, so that it does not grow with the
# recording's length: the detections in their checkpoint (one JSON line per chunk, read back
# a line at a time), the estimates in a temporary file of pickled blocks (one block per chunk of
# instants). What stays in memory per instant is a few bytes (a line number, a flag, an offset).
# what is read back is read in time order (a chunk of instants at a time, as its chunk is submitted):
# the current line of each camera, and the current block of estimates, are all that is needed; a few
# more keep a re-read (a retried chunk, the motion pass right after the estimation) off the disk
_CACHED_LINES = 16
_CACHED_BLOCKS = 4


class _Spill(Sequence[Any]):
    """``n`` items in blocks of ``block`` consecutive ones, each block pickled to a temporary file as it
    is made (blocks may come in any order) and read back on demand (the last ``_CACHED_BLOCKS`` kept)."""

    def __init__(self, n: int, block: int) -> None:
        self._n, self._block = n, max(1, block)
        nb = -(-n // self._block)
        self._at = np.full(nb, -1, np.int64)
        self._size = np.zeros(nb, np.int64)
        self._f = tempfile.TemporaryFile()  # noqa: SIM115 (lives as long as this sequence)
        weakref.finalize(self, self._f.close)
        self._cache: OrderedDict[int, list[Any]] = OrderedDict()

    def put(self, b: int, items: Sequence[Any]) -> None:
        """Block ``b``'s items (``block`` of them; fewer for the last)."""
        want = min(self._block, self._n - b * self._block)
        if len(items) != want:
            raise ValueError(f"block {b}: {len(items)} items, expected {want}")
        data = pickle.dumps(list(items), protocol=5)
        self._f.seek(0, os.SEEK_END)
        self._at[b], self._size[b] = self._f.tell(), len(data)
        self._f.write(data)

    def block(self, b: int) -> list[Any]:
        got = self._cache.get(b)
        if got is None:
            if self._at[b] < 0:
                raise KeyError(f"block {b} was never written")
            self._f.seek(int(self._at[b]))
            got = pickle.loads(self._f.read(int(self._size[b])))  # noqa: S301 (this run's own file)
            self._cache[b] = got
            if len(self._cache) > _CACHED_BLOCKS:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(b)
        return got

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(self._n))]
        i = int(i)
        if i < 0:
            i += self._n
        if not 0 <= i < self._n:
            raise IndexError(i)
        return self.block(i // self._block)[i % self._block]

    def __iter__(self) -> Iterator[Any]:
        for b in range(len(self._at)):
            yield from self.block(b)

    def __reduce__(self) -> tuple[Any, ...]:  # pickled (the pipeline's cache): a tuple of the items
        return (tuple, (tuple(self),))


def _spill_in_order(items: Iterator[Any], n: int, block: int) -> _Spill:
    """``n`` items of an iterator into a :class:`_Spill`, a block at a time."""
    out, buf, b = _Spill(n, block), [], 0
    for x in items:
        buf.append(x)
        if len(buf) == out._block:
            out.put(b, buf)
            buf, b = [], b + 1
    if buf:
        out.put(b, buf)
    return out


class _DetectionFile:
    """The detections of a run, in their checkpoint file (or a temporary one): where each camera's row
    is (its chunk's line) and whether it holds a marker, in memory; the views read back a line at a time.

    The file is opened for reading and appending; a chunk's line is written, flushed, and indexed as it
    completes (an interrupted run resumes from the lines on disk)."""

    def __init__(self, indices: dict[str, FrameIndex], f: Any) -> None:
        self._f = f
        weakref.finalize(self, f.close)
        self._line = {c: np.full(len(ix), -1, np.int32) for c, ix in indices.items()}
        self._marked = {c: np.zeros(len(ix), bool) for c, ix in indices.items()}
        self._offset = array("q")
        self._cache: OrderedDict[int, dict[int, tuple[MarkerView, ...]]] = OrderedDict()

    def index(self, offset: int, camera: str, rows: dict[int, bool]) -> None:
        """The line at ``offset`` holds ``camera``'s ``rows`` (row: any marker seen)."""
        if camera not in self._line:
            return  # a camera the rig no longer has: its views were never used
        k = len(self._offset)
        self._offset.append(offset)
        line, marked = self._line[camera], self._marked[camera]
        for r, m in rows.items():
            if 0 <= r < len(line):  # a later line wins, as a dict update did
                line[r], marked[r] = k, m

    def append(self, camera: str, frames: list[list[Any]]) -> None:
        """One finished chunk: written as one line (the checkpoint's JSON form) and indexed."""
        self._f.seek(0, os.SEEK_END)
        at = self._f.tell()
        self._f.write((json.dumps({"camera": camera, "frames": frames}) + "\n").encode())
        self._f.flush()
        self.index(at, camera, {int(r): bool(v) for r, v in frames})

    def has(self, camera: str, row: int) -> bool:
        return bool(self._line[camera][row] >= 0)

    def marked(self, ins: Instant) -> bool:
        """Any marker seen in one of the instant's images."""
        return any(bool(self._marked[c][i]) for c, i in ins.images)

    def views(self, camera: str, row: int) -> tuple[MarkerView, ...]:
        k = int(self._line[camera][row])
        if k < 0:
            raise KeyError((camera, row))
        got = self._cache.get(k)
        if got is None:
            self._f.seek(self._offset[k])
            d = json.loads(self._f.readline())
            got = {int(r): _views_from_json(d["camera"], int(r), v) for r, v in d["frames"]}
            self._cache[k] = got
            if len(self._cache) > _CACHED_LINES:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(k)
        return got[row]

    def close(self) -> None:
        self._f.flush()


class _LazyObservations(Sequence[FrameObservations]):
    """The observations of each instant, made from the detections' file when asked for."""

    def __init__(self, instants: Sequence[Instant], dets: _DetectionFile) -> None:
        self._instants, self._dets = instants, dets

    def __len__(self) -> int:
        return len(self._instants)

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        ins = self._instants[i]
        return FrameObservations(ins.stamp_s, tuple(v for cam, r in ins.images for v in self._dets.views(cam, r)),
                                 tuple(sorted({c for c, _ in ins.images})), tuple(ins.images))

    def __reduce__(self) -> tuple[Any, ...]:
        return (tuple, (tuple(self),))


class _Lazy(Sequence[Any]):
    """``n`` items, item ``i`` made by ``make(i)`` each time it is asked for (the chunks of a map: made
    as they are submitted, so that their arguments are never all in memory at once)."""

    def __init__(self, n: int, make: Callable[[int], Any]) -> None:
        self._n, self._make = n, make

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(self._n))]
        if not 0 <= i < self._n:
            raise IndexError(i)
        return self._make(i)


# --------------------------------------------------------------------------------------- the workers
@dataclass(frozen=True)
class WorkerContext:
    """What a worker needs besides its chunk: the rig (as its YAML document) and the detector's name.
    Small (a few kB), so it travels with every chunk, to a local process or a Dask worker alike; each
    process builds the model and the detector from it once (``token`` names it)."""

    token: str
    rig_doc: dict[str, Any] = field(repr=False)
    detector: str
    track: TrackOptions = TrackOptions(enabled=False)

    @staticmethod
    def of(rig: Rig, detector: str, track: TrackOptions | None = None) -> WorkerContext:
        doc = rig_to_dict(rig)
        track = track or TrackOptions(enabled=False)
        token = hashlib.sha256(json.dumps([doc, detector, track.key()], sort_keys=True,
                                          default=str).encode()).hexdigest()[:16]
        return WorkerContext(token, doc, detector, track)


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
    # the detector's blur only where it gave one, and a clipped marker's common corner move after it (a
    # view without them reads back as before)
    out = []
    for v in views:
        e = [v.marker_id, _arr(v.corners_px), _arr(v.corner_cov)]
        if math.isfinite(v.blur_px):
            e.append(v.blur_px)
            if v.corner_common is not None:
                e.append(_arr(v.corner_common))
        out.append(e)
    return out


def _views_from_json(camera: str, row: int, d: list[list[Any]]) -> tuple[MarkerView, ...]:
    return tuple(MarkerView(camera, int(e[0]), np.array(e[1]), np.array(e[2]), row,
                            float(e[3]) if len(e) > 3 else math.nan, np.array(e[4]) if len(e) > 4 else None)
                 for e in d)


def _process_chunk(ctx: WorkerContext, camera: str, rows: Sequence[int], paths: Sequence[str],
                   stamps_s: Sequence[float] | None = None) -> list[list[Any]]:
    """Markers detected in one camera's images ``rows`` (read here, on the worker, from ``paths``;
    stamped ``stamps_s``, needed when tracking), in order, markers tracked from image to image when
    ``ctx.track`` says so (:class:`gtrig.vision.track.CameraTracker`, started afresh in every chunk; markers
    that appear looked for back in the chunk's images before, :mod:`gtrig.vision.backfill`; markers cut by
    the image's edge looked for where the image's other markers place them, :mod:`gtrig.vision.siblings`):
    ``[[row, [[marker_id, corners, cov(, blur)], ...]], ...]``, the checkpoint's JSON form (the detector's
    blur where it gave one)."""
    from gtrig.vision.backfill import track_with_backfill
    from gtrig.vision.siblings import cut_siblings
    from gtrig.vision.track import CameraTracker

    st = _state(ctx)
    cam = st["model"].cameras[camera]
    out = []
    # one camera's files share a format: the first one says how they store light (gtrig.io.imagetone)
    tone = declared_tone(paths[0]) if paths else "linear"
    detect = st["detect"]
    expect = getattr(detect, "expected", None)
    tracker = CameraTracker(lambda img, box: detect(img, cam, tone, box), cam.size, ctx.track,
                            None if expect is None else (lambda img, predicted: expect(img, cam, tone, predicted)),
                            lambda views: cut_siblings(views, cam, st["model"]))
    if ctx.track.enabled and (stamps_s is None or len(stamps_s) != len(rows)):
        raise ValueError("tracking needs the images' time stamps")
    # each image file or video frame read as the tracker asks for it
    frames = ((read_image(path), float(stamps_s[k]) if stamps_s is not None else 0.0)
              for k, path in enumerate(paths))
    for i, views in zip(rows, track_with_backfill(tracker, frames), strict=True):
        out.append([int(i), _views_to_json(views)])
    log.debug("camera %s, %d images: %s", camera, len(rows), tracker.stats)
    return out


def _estimate_chunk(ctx: WorkerContext, obs: Sequence[FrameObservations], options: VisionOptions
                    ) -> list[FrameEstimate]:
    model = _state(ctx)["model"]
    return estimate_consecutive(model, obs, options)  # a chunk's instants follow each other


def _instant_label(obs: Sequence[FrameObservations]) -> str:
    return f"instants {obs[0].stamp_s:.3f}-{obs[-1].stamp_s:.3f} s" if obs else "no instant"


def _map_in_chunks(fn: Callable[..., list[Any]], items: Sequence[Any], args: Callable[[list[Any]], tuple[Any, ...]],
                   label: Callable[[list[Any]], str], chunk_size: int, executor: Any, workers: int,
                   spill: bool = False) -> Sequence[Any]:
    """``fn(*args(chunk))`` over consecutive chunks of ``items``, results concatenated in order: a list, or
    with ``spill`` a :class:`_Spill` written chunk by chunk as they finish. A chunk's items are taken from
    ``items`` when it is submitted (``items`` may be read from disk)."""
    from gtrig.executor import Chunk, map_chunks

    n = len(items)
    n_chunks = -(-n // chunk_size)

    def chunk(k: int) -> Chunk:
        part = [items[i] for i in range(k * chunk_size, min(n, (k + 1) * chunk_size))]
        return Chunk(args(part), label(part))

    if spill:
        store = _Spill(n, chunk_size)
        map_chunks(fn, _Lazy(n_chunks, chunk), store.put, executor=executor, workers=workers)
        return store
    out: dict[int, list[Any]] = {}
    map_chunks(fn, _Lazy(n_chunks, chunk), out.__setitem__, executor=executor, workers=workers)
    return [x for i in range(n_chunks) for x in out[i]]


def _estimate_all(ctx: WorkerContext, obs: Sequence[FrameObservations], options: VisionOptions, chunk_size: int,
                  executor: Any, workers: int, spill: bool = False) -> Sequence[FrameEstimate]:
    """Every instant estimated again from its detections (no image read), in parallel chunks."""
    return _map_in_chunks(_estimate_chunk, obs, lambda p: (ctx, p, options), _instant_label, chunk_size,
                          executor, workers, spill)


def calibrate_noise(obs: Sequence[FrameObservations], options: VisionOptions, cameras: Sequence[str],
                    estimate: Callable[[VisionOptions, list[FrameObservations]], Sequence[FrameEstimate]],
                    max_rounds: int = 1, tol: float = 0.05, sample: int = 300, rig_component: bool = False,
                    with_views: Sequence[int] | None = None,
                    ) -> tuple[VisionOptions, list[tuple[tuple[str, float], ...]]]:
    """Variance factors of the corner covariances from the residuals of the sequence's instants
    (:mod:`gtrig.vision.noise`; one step by default, see there why).

    The factors are estimated on at most ``sample`` instants with detections, evenly spread over the
    sequence (their redundancy, thousands of corners, pins a factor to a few per cent; estimating every
    instant at every round would cost more than the detection). ``estimate(opts, observations)``
    estimates a list of instants. With ``max_rounds`` > 1 the factors are re-estimated with the new
    ones until none moves by more than ``tol`` (relative). ``with_views``: the indices of the instants
    that hold a view, when the caller knows them (``obs`` is then read only at the sample, not scanned).
    Returns the options with the final factors and the history of factors (one entry per round).

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

    if with_views is None:
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
def detector_label(name: str, version: str, track: TrackOptions, chunk_size: int) -> str:
    """What makes the detections besides the images and the rig, as the checkpoint's key holds it: the
    detector's name and version, and when tracking, its settings and the chunk size (each chunk starts
    with a whole-image pass); untracked, the label of before tracking existed."""
    return f"{name}/{version}" + ("" if not track.enabled else f"/{track.key()}/chunk {chunk_size}")


def _key(rig: Rig, sequence: str, detector: str, paths: Mapping[str, Iterable[str]], rec: Path | None = None) -> str:
    """What the checkpointed detections depend on: the images, the detector, the lenses and the markers'
    families and sizes; not the poses, the estimator's options nor how images group into instants, so a
    re-estimation with a newly calibrated rig or other settings reuses them. The images count by their
    path inside the recording ``rec``, so a recording moved or copied elsewhere keeps its detections.
    ``paths`` (camera: its images' paths) is read once, a path at a time: the key of an hour's 144,000
    images is hashed without their list."""
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
           "detector": detector, "paths": {}}
    # the hash of json.dumps(doc with the paths, sort_keys=True), its "paths" value written piece by piece
    head, tail = json.dumps(doc, sort_keys=True).split('"paths": {}')
    h = hashlib.sha256((head + '"paths": {').encode())
    for i_cam, cam in enumerate(sorted(paths)):
        h.update(((", " if i_cam else "") + json.dumps(cam) + ": [").encode())
        for j, p in enumerate(paths[cam]):
            h.update(((", " if j else "") + json.dumps(p if rec is None else os.path.relpath(p, rec))).encode())
        h.update(b"]")
    h.update(("}" + tail).encode())
    return h.hexdigest()[:20]


def _scan_checkpoint(path: Path, key: str,
                     on_line: Callable[[int, str, dict[int, tuple[MarkerView, ...]]], None]) -> int:
    """``on_line(offset, camera, {row: views})`` for every good line of the checkpoint ``path``, in file
    order; returns the length of its good part (0: no usable checkpoint). Each line is parsed in full, so
    a damaged one is never trusted, and dropped once looked at."""
    if not path.is_file():
        return 0
    with open(path, "rb") as f:
        first = f.readline()
        try:
            head = json.loads(first)
        except (json.JSONDecodeError, UnicodeDecodeError):
            head = {}
        if not isinstance(head, dict) or not isinstance(head.get("key"), str):
            # not what run_recording writes (a corrupt or foreign file): never trusted, started afresh
            log.warning("%s: not a GTvision checkpoint (corrupt header); starting afresh", path)
            return 0
        if head["key"] != key:
            raise InputError(f"{path}: checkpoint of another run (other images, detector, tracking, lenses or "
                             "markers); delete it or choose another output")
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
            on_line(good, cam, got)
            good += len(line)
    return good


def _open_checkpoint(ck: Path | None, key: str, stale: str, indices: dict[str, FrameIndex]) -> _DetectionFile:
    """The detections' file: the checkpoint ``ck`` (its good lines indexed, opened to append the next
    chunks) or, without one, a temporary file (the detections are read back from disk either way)."""
    if ck is None:
        f = tempfile.TemporaryFile()  # noqa: SIM115 (owned by the _DetectionFile)
        f.write((json.dumps({"key": key, "version": CHECKPOINT_VERSION}) + "\n").encode())
        return _DetectionFile(indices, f)
    lines: list[tuple[int, str, dict[int, bool]]] = []

    def keep(at: int, cam: str, got: dict[int, tuple[MarkerView, ...]]) -> None:
        lines.append((at, cam, {r: bool(v) for r, v in got.items()}))

    try:
        good = _scan_checkpoint(ck, key, keep)
    except InputError as err:
        if stale != "restart":
            raise
        log.warning("%s; starting afresh", err)
        good, lines = 0, []
    ck.parent.mkdir(parents=True, exist_ok=True)
    if good == 0:
        f = open(ck, "w+b")  # noqa: SIM115
        f.write((json.dumps({"key": key, "version": CHECKPOINT_VERSION}) + "\n").encode())
        f.flush()
        lines = []
    else:
        f = open(ck, "r+b")  # noqa: SIM115
        f.truncate(good)  # drop a torn last line
    out = _DetectionFile(indices, f)
    for at, cam, rows in lines:
        out.index(at, cam, rows)
    return out


def detection_chunks(instants: Sequence[Instant], indices: dict[str, FrameIndex], chunk_size: int
                     ) -> list[tuple[str, list[int]]]:
    """The detection work: for each camera, the rows of its frame index that some instant uses, in
    runs of ``chunk_size`` consecutive ones (a camera and a time window)."""
    if isinstance(instants, Instants):
        rows = {cam: r.tolist() for cam, r in instants.camera_rows().items()}
    else:
        used: dict[str, set[int]] = {}
        for ins in instants:
            for cam, i in ins.images:
                used.setdefault(cam, set()).add(i)
        rows = {cam: sorted(r) for cam, r in used.items()}
    out: list[tuple[str, list[int]]] = []
    for cam in sorted(rows):
        r = rows[cam]
        out.extend((cam, r[k:k + chunk_size]) for k in range(0, len(r), chunk_size))
    return out


def _detect_all(ctx: WorkerContext, chunks: list[tuple[str, list[int]]], indices: dict[str, FrameIndex],
                dets: _DetectionFile, executor: Any, workers: int,
                progress: Callable[[int, int], None] | None) -> None:
    """The chunks not in ``dets`` detected on the workers, each appended to the detections' file as one
    line as it completes (the images are read by the workers, never sent from here)."""
    from gtrig.executor import Chunk, map_chunks

    def job(k: int) -> Chunk:
        cam, rows = chunks[k]
        ix = indices[cam]
        label = f"camera {cam}, {ix.stamps_s[rows[0]]:.3f}-{ix.stamps_s[rows[-1]]:.3f} s"
        return Chunk((ctx, cam, rows, [ix.source(i) for i in rows], [float(ix.stamps_s[i]) for i in rows]), label)

    jobs = _Lazy(len(chunks), job)
    todo = [k for k, (cam, rows) in enumerate(chunks) if not all(dets.has(cam, i) for i in rows)]
    if len(todo) < len(chunks):
        log.info("resuming: %d of %d detection chunks already checkpointed", len(chunks) - len(todo), len(chunks))

    prepare = getattr(_state(ctx)["detect"], "prepare_lens_maps", None)
    if executor is None and todo and prepare is not None:  # a local pool forks from here: its workers share them
        model = _state(ctx)["model"]
        prepare([model.cameras[c] for c in sorted({chunks[k][0] for k in todo})])

    def record(k: int, frames: list[list[Any]]) -> None:
        dets.append(chunks[k][0], frames)  # one line per finished chunk: an interrupted run resumes from here

    map_chunks(_process_chunk, jobs, record, executor=executor, workers=workers, todo=todo, progress=progress)


def _resolve_flips(model: VisionModel, obs: Sequence[FrameObservations], ests: Sequence[FrameEstimate],
                   options: VisionOptions) -> list[FrameEstimate]:
    """Re-estimate ambiguous instants with the previous localized pose, in time order."""
    return list(_iter_flips(model, obs, ests, options))


def _iter_flips(model: VisionModel, obs: Sequence[FrameObservations], ests: Sequence[FrameEstimate],
                options: VisionOptions) -> Iterator[FrameEstimate]:
    """:func:`_resolve_flips` one instant at a time (the previous localized pose is all it keeps); the
    observations are read only for the ambiguous instants."""
    last: FrameEstimate | None = None
    if len(obs) != len(ests):
        raise ValueError(f"{len(obs)} instants but {len(ests)} estimates")
    for i, e in enumerate(ests):
        o = obs[i] if e.status is Status.AMBIGUOUS and last is not None else None
        if o is not None and last is not None and o.stamp_s - last.stamp_s <= options.previous_max_gap_s:
            assert last.T_world_robot is not None
            e = estimate_frame(model, o, options, PreviousPose(last.T_world_robot))
            if e.ok:
                e = replace(e, reason="flip resolved by the previous pose")
        if e.ok:
            last = e
        yield e


def camera_time_offsets(obs: Sequence[FrameObservations], indices: dict[str, FrameIndex]
                        ) -> list[dict[str, float]]:
    """Per instant, each camera's image stamp minus the instant's stamp, seconds (the mean of its
    images' stamps: cameras that are not triggered together fall up to ``sync_tol_s`` apart)."""
    return [_time_offsets(o.stamp_s, o.frames, indices) for o in obs]


def _time_offsets(stamp_s: float, frames: Sequence[tuple[str, int]], indices: dict[str, FrameIndex]
                  ) -> dict[str, float]:
    per: dict[str, list[float]] = {}
    for cam, row in frames:
        per.setdefault(cam, []).append(float(indices[cam].stamps_s[row]) - stamp_s)
    return {c: float(np.mean(v)) for c, v in per.items()}


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
                      ) -> tuple[Sequence[FrameEstimate], set[int]]:
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

    Returns the estimates (a list for a list of ``ests``, else a sequence over them and the new ones,
    which are kept on disk) and the indices of those whose covariance now includes the timing; an
    instant whose second estimate fails keeps its first. ``obs``, ``ests`` and ``offsets`` are read
    instant by instant, never copied.
    """
    ok, T, vel = _ok_velocities(ests, max_gap_s)
    if len(ok) < 2:
        return list(ests), set()
    sigma = {c: stamp_sigma_s.get(c, 0.0) for c in model.cameras}

    def moves(k: int) -> bool:  # some camera of instant ok[k] to move or to give its jitter
        i = int(ok[k])
        return bool(np.any(vel[k])) and len(obs[i].cameras_with_views()) >= 2 and any(
            c in model.cameras and (abs(dt) > 1e-6 or sigma[c] > 0) for c, dt in offsets[i].items())

    # the instants estimated again: a few bytes each; their arguments are made as their chunk is sent
    jobs = np.array([k for k in range(len(ok)) if moves(k)], dtype=np.int64)

    def job(j: int) -> tuple[Any, ...]:
        k = int(jobs[j])
        i = int(ok[k])
        deltas, extra = _camera_motion(model, vel[k], T[k], offsets[i], sigma)
        return obs[i], ests[i], deltas, extra

    items = _Lazy(len(jobs), job)
    if context is None:  # ``model`` is not a rig's: estimated here
        res: Sequence[FrameEstimate] = [_moving_instant(model, o, options, e, d, x) for o, e, d, x in items]
    else:
        res = _map_in_chunks(_moving_chunk, items, lambda p: (context, p, options),
                             lambda p: _instant_label([it[0] for it in p]), chunk_size, executor, workers,
                             spill=not isinstance(ests, list))
    at = ok[jobs] if len(jobs) else np.zeros(0, np.int64)
    good = np.fromiter((e.ok for e in res), bool, len(at))
    done = {int(i) for i in at[good]}
    log.info("%d moving instants estimated again with their cameras' exposure times", len(done))
    if isinstance(ests, list):
        out = list(ests)
        for i, g, e in zip(at, good, res, strict=True):
            if g:
                out[int(i)] = e
        return out, done
    return _Merged(ests, at[good], _Lazy(int(good.sum()), _Picked(res, np.flatnonzero(good)))), done


def _ok_velocities(ests: Sequence[FrameEstimate], max_gap_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The indices (M,) of the localized estimates, their poses (M, 4, 4) and velocities (M, 6)
    (:func:`pose_velocities`), gathered one estimate at a time."""
    ok, Ts, stamps = [], [], []
    for i, e in enumerate(ests):
        if e.ok:
            ok.append(i)
            Ts.append(e.T_world_robot)
            stamps.append(e.stamp_s)
    if len(ok) < 2:
        return np.array(ok, np.int64), np.zeros((len(ok), 4, 4)), np.zeros((len(ok), 6))
    T = np.stack(Ts)  # type: ignore[arg-type]
    return np.array(ok, np.int64), T, pose_velocities(np.array(stamps), T, max_gap_s)


def _camera_motion(model: VisionModel, vel: np.ndarray, T: np.ndarray, offsets: dict[str, float],
                   sigma: dict[str, float]) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Per camera of one instant, the motion ``(4, 4)`` over its exposure offset and its jitter's
    nuisance covariance (:func:`compensate_motion`)."""
    from gtrig.vision.covariance import timing_camera_covariance

    t = T[:3, 3]
    deltas, extra = {}, {}
    for c, dt in offsets.items():
        if c not in model.cameras:
            continue
        if abs(dt) > 1e-6:
            D = np.eye(4)
            D[:3, :3] = Rotation.from_rotvec(vel[3:] * dt).as_matrix()
            D[:3, 3] = t + vel[:3] * dt - D[:3, :3] @ t
            deltas[c] = D
        if sigma[c] > 0:
            extra[c] = timing_camera_covariance(vel, T, model.cameras[c].T_world_cam[:3, 3], sigma[c])
    return deltas, extra


@dataclass(frozen=True)
class _Picked:
    """Item ``idx[j]`` of ``items`` as item ``j``."""

    items: Sequence[Any]
    idx: np.ndarray

    def __call__(self, j: int) -> Any:
        return self.items[int(self.idx[j])]


class _Merged(Sequence[FrameEstimate]):
    """``base`` with the instants ``at`` (sorted) replaced by ``new`` (same order)."""

    def __init__(self, base: Sequence[FrameEstimate], at: np.ndarray, new: Sequence[FrameEstimate]) -> None:
        self._base, self._at, self._new = base, at, new

    def __len__(self) -> int:
        return len(self._base)

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        j = int(np.searchsorted(self._at, i))
        return self._new[j] if j < len(self._at) and self._at[j] == i else self._base[i]

    def __iter__(self) -> Iterator[FrameEstimate]:
        j = 0
        for i, e in enumerate(self._base):
            if j < len(self._at) and self._at[j] == i:
                yield self._new[j]
                j += 1
            else:
                yield e


def run_recording(rec_dir: str | os.PathLike[str], rig: Rig, sequence: str = "validation",
                  planar: bool = True, workers: int = 0, *, options: VisionOptions | None = None,
                  detector: str = "auto",
                  checkpoint: str | os.PathLike[str] | None = None,
                  progress: Callable[[int, int], None] | None = None, chunk_size: int | None = None,
                  sync_tol_s: float = 0.005, estimate_noise: bool = True,
                  stale_checkpoint: str = "refuse", executor: Any = None,
                  track: TrackOptions | None = None) -> VisionResult:
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
    track : how markers are tracked from image to image in each camera (default
        :class:`~gtrig.vision.track.TrackOptions`: tracked, a whole-image pass at least once a second and at
        every chunk's start, so the detections depend on ``chunk_size`` but never on the workers);
        ``TrackOptions(enabled=False)``: every image searched whole.
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
    check_image_sizes(indices, rig)
    intervals = read_static_intervals(rec / "validation" / "poses.csv") if sequence == "validation" else None
    instants = make_instants(indices, sequence, sync_tol_s, intervals)
    if chunk_size is None:
        # at least 32 chunks where the sequence allows, so that an interruption loses little; it depends
        # on the sequence alone, never on the workers, so a run resumed with other workers finds the same
        chunk_size = min(16, max(1, sum(len(ins.images) for ins in instants) // 32))
    chunks = detection_chunks(instants, indices, chunk_size)
    # a new version of the detector's code makes other detections: not the checkpoint's
    # the workers read their chunk's images by path; the client keeps no list of them
    paths = {name: map(ix.source, range(len(ix))) for name, ix in indices.items()}
    track = TrackOptions() if track is None else track
    key = _key(rig, sequence, detector_label(det.name, det.version, track, chunk_size), paths, rec)
    ctx = WorkerContext.of(rig, detector, track)
    _seed(ctx, model, det)
    dets = _open_checkpoint(None if checkpoint is None else Path(checkpoint), key, stale_checkpoint, indices)
    t_par = time.perf_counter()
    try:
        _detect_all(ctx, chunks, indices, dets, executor, workers, progress)
    finally:
        dets.close()
    t_par = time.perf_counter() - t_par
    obs = _LazyObservations(instants, dets)  # read back from the detections' file as needed
    t_noise = time.perf_counter()
    if estimate_noise and not opts.corner_scale:
        marked = [k for k, ins in enumerate(instants) if dets.marked(ins)]
        opts, history = calibrate_noise(obs, opts, sorted(indices),
                                        lambda o, x: _estimate_all(ctx, x, o, chunk_size, executor, workers),
                                        max_rounds=10 if opts.rig_variance_component else 1,
                                        rig_component=opts.rig_variance_component, with_views=marked)
        del marked
        for k, sc in enumerate(history):
            log.info("corner noise, round %d: variance factors %s", k + 1,
                     ", ".join(f"{c} {f:.3g}" for c, f in sc))
    t_noise = time.perf_counter() - t_noise
    t_est = time.perf_counter()
    # every stage streams: its estimates are written to disk chunk by chunk and read back in time order
    ests: Sequence[FrameEstimate] = _estimate_all(ctx, obs, opts, chunk_size, executor, workers, spill=True)
    ests = _spill_in_order(_iter_flips(model, obs, ests, opts), len(ests), chunk_size)
    stamp_sigma = {c.name: c.stamp_sigma_s for c in rig.cameras}
    timed: set[int] = set()
    if sequence == "run":
        offsets = _Lazy(len(instants), lambda i: _time_offsets(instants[i].stamp_s, instants[i].images, indices))
        ests, timed = compensate_motion(model, obs, ests, offsets, stamp_sigma, opts,
                                        chunk_size=chunk_size, context=ctx, executor=executor, workers=workers)
    t_est = time.perf_counter() - t_est
    frame_cov = None if rig.robot.markers_frame_cov is None else np.asarray(rig.robot.markers_frame_cov, float)
    timing = stamp_sigma if sequence == "run" and any(v > 0 for v in stamp_sigma.values()) else None
    final = _spill_in_order(_logged(_iter_finished(ests, timing, timed, frame_cov)), len(ests), chunk_size)
    counts = {name: len(ix) for name, ix in indices.items()}
    return VisionResult(sequence, final, obs, counts, det_name, planar,
                        {"parallel": t_par, "noise": t_noise, "estimate": t_est,
                         "total": time.perf_counter() - t_start},
                        opts.corner_scale)


def _logged(ests: Iterator[FrameEstimate]) -> Iterator[FrameEstimate]:
    """The estimates as they pass, each failed one logged."""
    for e in ests:  # an empty view is the common case in a run: not worth a line each
        if not e.ok:
            log.log(logging.DEBUG if e.status is Status.NO_MARKER else logging.INFO,
                    "t=%.6f not localized: %s: %s", e.stamp_s, e.status.value, e.reason)
        yield e


def with_robot_frame_uncertainty(result: VisionResult, cov_frame_6x6: np.ndarray) -> VisionResult:
    """A new result whose pose covariances include a common error of the robot frame itself
    (``cov_frame_6x6`` over (dt, dphi) in robot axes, e.g. from
    :func:`gtrig.vision.covariance.anchor_frame_covariance`); the poses are unchanged."""
    return replace(result, estimates=tuple(_with_frame(e, cov_frame_6x6) for e in result.estimates))


def _with_frame(e: FrameEstimate, cov_frame_6x6: np.ndarray) -> FrameEstimate:
    from gtrig.vision.covariance import add_robot_frame_covariance

    if e.cov_6x6 is None or e.T_world_robot is None:
        return e
    return replace(e, cov_6x6=add_robot_frame_covariance(e.T_world_robot, e.cov_6x6, cov_frame_6x6))


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
    ests = result.estimates
    if result.sequence != "run" or not any(v > 0 for v in stamp_sigma_s.values()):
        return result
    return replace(result, estimates=tuple(_iter_finished(ests, stamp_sigma_s, skip, None, max_gap_s)))


def _iter_finished(ests: Sequence[FrameEstimate], stamp_sigma_s: dict[str, float] | None,
                   skip: set[int] | frozenset[int], cov_frame_6x6: np.ndarray | None, max_gap_s: float = 0.5
                   ) -> Iterator[FrameEstimate]:
    """The estimates one by one with the timing term of :func:`with_timing_uncertainty` (None: none),
    then the robot frame's error of :func:`with_robot_frame_uncertainty` (None: none)."""
    ok, _, vel = _ok_velocities(ests, max_gap_s) if stamp_sigma_s else (np.zeros(0, np.int64), None, None)
    timed = stamp_sigma_s is not None and len(ok) >= 2
    k = 0
    for i, e in enumerate(ests):
        if timed and k < len(ok) and ok[k] == i:
            sig = max((stamp_sigma_s.get(cam, 0.0) for cam, _ in e.views), default=0.0)  # type: ignore[union-attr]
            if i not in skip and sig > 0 and e.cov_6x6 is not None:
                e = replace(e, cov_6x6=e.cov_6x6 + sig**2 * np.outer(vel[k], vel[k]))  # type: ignore[index]
            k += 1
        yield e if cov_frame_6x6 is None else _with_frame(e, cov_frame_6x6)


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
