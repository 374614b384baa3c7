"""A pose track of the folder against the recording's truth, compared as the track is estimated: a planar
track (``x, y, yaw``; z and tilt not estimated) in the plane, against the truth's ``x, y, yaw`` (the truth's
height and tilt are no error of a planar track); any other in 3-D."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from gtrig.errors import GtrigError
from gtrig.evaluate.slam import SlamEvaluation
from gtrig.trajectory import PoseTrack

#: the largest stamp gap the truth is interpolated across (s)
MAX_DT_S = 0.05


def is_planar(track: PoseTrack) -> bool:
    """A track of ``x, y, yaw`` only: its covariance is planar, or it has none and its height and tilt are
    constant."""
    if track.planar:
        return True
    if track.cov is not None or not len(track):
        return False
    level = np.allclose(track.quat_xyzw[:, :2], 0.0, atol=1e-9)
    return bool(level and np.ptp(track.xyz[:, 2]) < 1e-9)


def in_plane(track: PoseTrack) -> PoseTrack:
    """``track`` as ``x, y, yaw`` (z = 0, level), its planar covariance, status and reasons kept."""
    return PoseTrack.from_xytheta(track.stamps_s, track.xytheta(), cov=track.cov_xytheta(), status=track.status,
                                  reasons=track.reasons, source=track.source)


@dataclass(frozen=True)
class TruthScore:
    """One track against truth: ``planar`` says whether compared in the plane; ``evaluation`` the full
    result (pairing, errors, GT-aware scores), None with ``error`` when it could not be made."""

    planar: bool
    evaluation: SlamEvaluation | None
    error: str = ""

    def rmse_mm(self) -> float:
        return self._trans("rmse")

    def max_mm(self) -> float:
        return self._trans("max")

    def _trans(self, stat: str) -> float:
        ev = self.evaluation
        if ev is None or not ev.ape:
            return float("nan")
        return 1000 * float(ev.ape["trans"].stats().get(stat, float("nan")))

    def rot_rmse_deg(self) -> float:
        ev = self.evaluation
        if ev is None or not ev.ape or "rot" not in ev.ape:
            return float("nan")
        return float(np.degrees(ev.ape["rot"].stats().get("rmse", float("nan"))))


@lru_cache(maxsize=16)
def _score(track_path: str, truth_path: str) -> TruthScore:
    from gtrig.io.formats import read_trajectory

    tr, truth = read_trajectory(Path(track_path)), read_trajectory(Path(truth_path))
    return score_against_truth(tr, truth)


def score_against_truth(track: PoseTrack, truth: PoseTrack) -> TruthScore:
    """``track`` (the GT, with its covariance) against ``truth``: in the plane when the track is planar."""
    from gtrig.evaluate.slam import evaluate_slam

    planar = is_planar(track)
    if planar:
        track, truth = in_plane(track), in_plane(truth)
    if len(track.usable()) < 2:
        return TruthScore(planar, None, "fewer than 2 usable poses")
    try:
        ev = evaluate_slam(track, truth, metrics="evo", align="none", method="interpolate", max_dt_s=MAX_DT_S)
    except GtrigError as e:
        return TruthScore(planar, None, str(e))
    return TruthScore(planar, ev)


def score_files(track_path: Path, truth_path: Path) -> TruthScore:
    """:func:`score_against_truth` of two files, computed once per report (the accuracy table and the
    track's own section both show it)."""
    return _score(str(track_path), str(truth_path))
