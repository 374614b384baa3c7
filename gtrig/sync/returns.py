"""The fixed scanners' foreground returns that the per-scanner clock fit uses
(:func:`gtrig.sync.sensors.scanner_offsets`), whole in memory or a window of frames at a time.

An hour of logs holds about 20 million returns (about 80 a frame at the simulated rates): 1.1 GB as
arrays, and the fit's (P, n) rows over all of them another 3 GB. :func:`returns_of_recording`
reads the logs once, a window at a time, keeps per frame only its stamp and each scanner's count of
returns (what :func:`~gtrig.sync.sensors.restamp_laser` and
:func:`~gtrig.sync.sensors.laser_clock` need), and spools the returns to a temporary binary file
(42 bytes a return) that the fit reads back a window at a time for each of its passes. Spooling is what
the measurement chose over parsing the text logs again for every pass (BENCHMARKS.md,
Scale): the logs can also be re-read (``spool=False``), for a disk without room for the file.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from gtrig.evaluate.associate import nearest_indices

#: frames per window of the fit's passes over spooled or re-read returns (about 80 returns a frame:
#: ~40 MB of the fit's temporaries per window)
WINDOW_FRAMES = 1024
#: frames per read of the logs (as GTlaser's windows: a window's scans, ranges and text, ~22 kB a frame)
READ_FRAMES = 256
#: one spooled return: firing time (s, its scanner's clock), world point (m), unit beam direction,
#: scanner index; its frame is implied by the per-frame counts (the returns are in frame order)
_RECORD = np.dtype([("t", "<f8"), ("xy", "<f8", (2,)), ("dir", "<f8", (2,)), ("sid", "<i2")])


class _Frames:
    """What the per-frame uses of the returns need: ``names`` (S,), ``frame_stamps_s`` (F,) and
    :meth:`frame_counts` (F, S)."""

    names: tuple[str, ...]
    frame_stamps_s: np.ndarray

    def frame_counts(self) -> np.ndarray:  # pragma: no cover (each class has its own)
        raise NotImplementedError

    def frame_shares(self) -> np.ndarray:
        """(F, S) each scanner's share of each frame's returns."""
        n = self.frame_counts().astype(float)
        tot = n.sum(axis=1, keepdims=True)
        return np.divide(n, tot, out=np.zeros_like(n), where=tot > 0)

    def frame_of(self, stamps_s: np.ndarray, tol_s: float = 2e-6) -> tuple[np.ndarray, np.ndarray]:
        """The frame (index into ``frame_stamps_s``) of each of ``stamps_s`` (M,), and whether it has one
        (a frame stamp within ``tol_s``; where not, the index is 0): a GTlaser pose is its frame's. The
        nearest stamp on either side, since a track read back from a TUM file carries its stamps rounded
        to the microsecond, up or down (the next frame stamp up only would miss every pose rounded up:
        2114 of 5614 on seed 0)."""
        st = np.asarray(stamps_s, float)
        k = np.zeros(st.size, np.int64)
        hit = np.zeros(st.size, bool)
        i_pose, i_frame = nearest_indices(st, self.frame_stamps_s, tol_s)
        k[i_pose] = i_frame
        hit[i_pose] = True
        return k, hit


@dataclass(frozen=True)
class ScannerReturns(_Frames):
    """The foreground returns of every fixed scanner (what GTlaser fits), each with its firing time.

    Attributes
    ----------
    names : (S,) scanner names. stamps_s : (P,) each return's firing time on its scanner's clock.
    xy_world : (P, 2) the returns, world frame, metres. scanner_index : (P,) into ``names``.
    dir_world : (P, 2) unit beam directions. origin_xy : (S, 2) scanner origins. sigma_m : (S,) range noise.
    frame_index : (P,) GTlaser's frame of each return; frame_stamps_s : (F,) the frames' stamps (GTlaser's
        pose stamps).
    """

    names: tuple[str, ...]
    stamps_s: np.ndarray
    xy_world: np.ndarray
    scanner_index: np.ndarray
    dir_world: np.ndarray
    origin_xy: np.ndarray
    sigma_m: np.ndarray
    frame_index: np.ndarray
    frame_stamps_s: np.ndarray

    @staticmethod
    def from_framed(fp) -> ScannerReturns:  # noqa: ANN001 (gtrig.laser.fuse.FramedPoints)
        """From GTlaser's framed points: a return's firing time is its frame's stamp plus its ``dt_s``."""
        fid = np.repeat(np.arange(fp.n_frames), np.diff(fp.frame_start))
        return ScannerReturns(tuple(fp.scanner_names), fp.frame_stamps_s[fid] + fp.dt_s, fp.xy_world,
                              np.asarray(fp.scanner_index, np.int64), fp.dir_world, fp.scanner_xy_world,
                              np.asarray(fp.sigma_m, float), fid, fp.frame_stamps_s)

    def frame_counts(self) -> np.ndarray:
        """(F, S) each scanner's returns in each frame."""
        F, S = self.frame_stamps_s.size, len(self.names)
        return np.bincount(self.frame_index * S + self.scanner_index, minlength=F * S).reshape(F, S)

    def windows(self) -> Iterator[ScannerReturns]:
        """The returns as the fit reads them: here all at once (they are in memory already)."""
        yield self


@dataclass(frozen=True)
class WindowedReturns(_Frames):
    """The returns of a recording's logs, read a window of frames at a time (:func:`returns_of_recording`).

    Attributes
    ----------
    names, origin_xy, sigma_m, frame_stamps_s : as :class:`ScannerReturns`.
    counts : (F, S) each scanner's returns in each frame (int64).
    spool : the binary file of the returns in frame order (``_RECORD`` rows), or None: read from ``frames``.
    frames : the logs (:class:`gtrig.laser.recording.LoggedFrames`) when not spooled.
    window_frames : frames per window of :meth:`windows`.

    Once the ``with`` block of :func:`returns_of_recording` has ended, the spool is gone and
    :meth:`windows` fails; the per-frame uses (:meth:`frame_shares`, :meth:`frame_of`) go on working.
    """

    names: tuple[str, ...]
    origin_xy: np.ndarray
    sigma_m: np.ndarray
    frame_stamps_s: np.ndarray
    counts: np.ndarray
    spool: Path | None
    frames: object | None
    window_frames: int = WINDOW_FRAMES

    def frame_counts(self) -> np.ndarray:
        return self.counts

    def windows(self) -> Iterator[ScannerReturns]:
        """The returns of ``window_frames`` frames at a time, in frame order (``frame_index`` into the whole
        ``frame_stamps_s``)."""
        F = self.frame_stamps_s.size
        start = np.r_[0, np.cumsum(self.counts.sum(axis=1))]
        if self.spool is None:
            for a in range(0, F, self.window_frames):
                yield from _log_windows(self.frames, a, min(a + self.window_frames, F), self.frame_stamps_s)
            return
        with open(self.spool, "rb") as f:  # plain reads: mapped pages would count in the process's RSS
            for a in range(0, F, self.window_frames):
                b = min(a + self.window_frames, F)
                rec = np.fromfile(f, _RECORD, count=int(start[b] - start[a]))
                fid = np.repeat(np.arange(a, b), np.diff(start[a:b + 1]))
                yield ScannerReturns(self.names, rec["t"], rec["xy"], rec["sid"].astype(np.int64), rec["dir"],
                                     self.origin_xy, self.sigma_m, fid, self.frame_stamps_s)


def _log_windows(frames, a: int, b: int, frame_stamps_s: np.ndarray | None = None,  # noqa: ANN001
                 read_frames: int = READ_FRAMES) -> Iterator[ScannerReturns]:
    """Frames ``[a, b)`` of ``frames`` (LoggedFrames) read ``read_frames`` at a time, as returns whose
    ``frame_index`` counts from 0 at frame 0 of ``frames`` (and whose ``frame_stamps_s`` are
    ``frame_stamps_s`` when given, else the window's own)."""
    for _, _, r in _log_reads(frames, a, b, read_frames):
        yield r if frame_stamps_s is None else replace(r, frame_stamps_s=frame_stamps_s)


def _log_reads(frames, a: int, b: int, read_frames: int = READ_FRAMES,  # noqa: ANN001
               ) -> Iterator[tuple[int, int, ScannerReturns]]:
    """(lo, hi, the returns of frames ``[lo, hi)``, ``frame_index`` from frame 0 of ``frames``, the
    window's own ``frame_stamps_s``) over ``[a, b)``, ``read_frames`` at a time."""
    for lo in range(a, b, read_frames):
        hi = min(lo + read_frames, b)
        r = ScannerReturns.from_framed(frames.window(lo, hi, scans=False))
        yield lo, hi, replace(r, frame_index=r.frame_index + lo)


def _logs(rec_dir, rig, sequence: str, scan_cache: str | os.PathLike[str] | None = None):  # noqa: ANN001, ANN202
    """The fixed scanners' logs of ``rec_dir/<sequence>`` as LoggedFrames (backgrounds of ``rec_dir``);
    ``scan_cache``: the folder of their parsed ranges (``index_scans(cache=)``, GTlaser's, so the logs are
    not parsed again), None: read from the text."""
    from gtrig.laser.recording import load_backgrounds, logged_frames

    rec = Path(rec_dir)
    return logged_frames(rig, rec / sequence, load_backgrounds(rec / "background", rig), scan_cache=scan_cache)[1]


def recording_returns(rec_dir, rig, sequence: str = "run", window_frames: int = READ_FRAMES) -> ScannerReturns:  # noqa: ANN001
    """The foreground returns GTlaser fits on ``rec_dir/<sequence>``, all in memory (about 4 kB a frame:
    for short recordings and benches; the fit's own path is :func:`returns_of_recording`): the fixed
    scanners' logs, the background models of ``rec_dir/background`` and the scanners' calibrated poses in
    ``rig``. The logs are read ``window_frames`` frames at a time (the same points bit for bit as the whole
    logs' reading)."""
    frames = _logs(rec_dir, rig, sequence)
    F = frames.n_frames
    parts = list(_log_windows(frames, 0, F, read_frames=window_frames)) or [
        ScannerReturns.from_framed(frames.window(0, 0, scans=False))]
    return replace(parts[0], stamps_s=np.concatenate([r.stamps_s for r in parts]),
                   xy_world=np.concatenate([r.xy_world for r in parts]),
                   scanner_index=np.concatenate([r.scanner_index for r in parts]),
                   dir_world=np.concatenate([r.dir_world for r in parts]),
                   frame_index=np.concatenate([r.frame_index for r in parts]),
                   frame_stamps_s=np.concatenate([r.frame_stamps_s for r in parts]))


@contextmanager
def returns_of_recording(rec_dir, rig, sequence: str = "run", spool: bool = True,  # noqa: ANN001
                         tmp_dir: str | os.PathLike[str] | None = None,
                         window_frames: int | None = None,
                         scan_cache: str | os.PathLike[str] | None = None) -> Iterator[WindowedReturns]:
    """The foreground returns of ``rec_dir/<sequence>``'s scanner logs (as :func:`recording_returns`, the
    same values bit for bit) for the time of the ``with`` block, in memory per frame only.

    Parameters
    ----------
    rec_dir, rig, sequence : as :func:`recording_returns`.
    spool : True: the returns are written once to a temporary file in ``tmp_dir`` (default the system's,
        ``TMPDIR``; 42 bytes a return, ~0.9 GB for an hour of the simulated logs) and read back a window
        at a time; it is removed when the block ends. False: every pass parses the logs again.
    window_frames : frames per window of the fit's passes (default :data:`WINDOW_FRAMES`).
    scan_cache : the folder of the logs' parsed ranges (:func:`gtrig.io.scans.index_scans`), or None.

    Yields
    ------
    WindowedReturns
    """
    frames = _logs(rec_dir, rig, sequence, scan_cache)
    F, S = frames.n_frames, len(frames.scanners)
    counts = np.zeros((F, S), np.int64)
    path = None
    try:
        if spool:
            fd, tmp = tempfile.mkstemp(prefix=".gtrig_returns_", suffix=".partial", dir=tmp_dir)
            path = Path(tmp)
            with os.fdopen(fd, "wb") as f:
                _spool(frames, counts, f)
            # complete only under its final name (a reader never sees a part of it)
            path = path.rename(path.with_suffix(".bin"))
        else:
            _spool(frames, counts, None)
        yield WindowedReturns(tuple(s.name for s in frames.scanners), frames.scanner_xy_world, frames.sigma_m,
                              frames.frame_stamps_s, counts, path, None if spool else frames,
                              window_frames or WINDOW_FRAMES)
    finally:
        if path is not None:
            path.unlink(missing_ok=True)


def _spool(frames, counts: np.ndarray, f) -> None:  # noqa: ANN001
    """Count each frame's returns per scanner into ``counts`` (F, S) and, with a file ``f``, write the
    returns to it in frame order."""
    for lo, hi, r in _log_reads(frames, 0, frames.n_frames):
        counts[lo:hi] = replace(r, frame_index=r.frame_index - lo).frame_counts()
        if f is not None:
            rec = np.empty(r.stamps_s.size, _RECORD)
            rec["t"], rec["xy"], rec["dir"], rec["sid"] = r.stamps_s, r.xy_world, r.dir_world, r.scanner_index
            rec.tofile(f)
