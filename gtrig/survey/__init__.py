"""Stage: survey (GTvalidation): world points and validation poses from hand-laser distances.

Public API: :func:`run_recording_survey`, :func:`compare_to_truth`, :func:`run_survey`,
:func:`~gtrig.survey.points.estimate_world_points`, :func:`~gtrig.survey.poses.estimate_poses`,
:func:`~gtrig.survey.predict.predict_pose_uncertainty`.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "SurveyAccuracy",
    "SurveyResult",
    "accuracy",
    "compare_to_truth",
    "run_recording_survey",
    "run_survey",
]


def __getattr__(name: str) -> Any:  # lazy: importing gtrig.survey stays cheap
    if name in __all__:
        from gtrig.survey import recording

        return getattr(recording, name)
    raise AttributeError(name)
