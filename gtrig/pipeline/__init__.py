"""The whole job on one recording, as a table of contents: each stage that exists runs in turn.

``run(rec, out)`` reads a recording, runs the stages of :data:`STAGES` in order and, when the
recording carries its truth (simulated), measures every result against it (gtrig.evaluate.truth).
Stages hand each other objects through a typed context (gtrig.pipeline.context, which also says how a
new stage declares what it consumes and produces); finished stages are reused (gtrig.pipeline.cache);
the runner's rules are in gtrig.pipeline.runner.

=============  ==========================================  ==============================================
stage          consumes (uses)                              produces
=============  ==========================================  ==============================================
survey         -                                            survey
cameras        rig                                          rig, camera_report
markers        rig                                          rig, marker_calibration
robot-frame    rig, survey, marker_calibration              rig, frame_fit, vision_validation, hand_frame_cov
laser          rig                                          rig, laser_report, tracks/GTlaser/run
vision         rig (marker_calibration, frame_fit, ...)     tracks/GTvision/{validation,run}
sync           tracks/GTvision/run, tracks/GTlaser/run, rig  clock_offsets (per camera and scanner too)
laser-clock    rig, laser_report (clock_offsets, sync.yaml)   tracks/GTlaser-synced/run (GTvision's clock)
fusion         the same, clock_offsets (*)                  tracks/fusion/run
=============  ==========================================  ==============================================

(*) used when present: either GT source alone is enough.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from gtrig.pipeline.cameras import camera_calibration
from gtrig.pipeline.context import AccuracyRow, Products, Stage, StageInput, StageOutput
from gtrig.pipeline.fusion import fusion, sync
from gtrig.pipeline.laser import gtlaser, gtlaser_clock
from gtrig.pipeline.markers import marker_calibration
from gtrig.pipeline.robot_frame import robot_frame
from gtrig.pipeline.rows import read_accuracy_csv, write_accuracy_csv
from gtrig.pipeline.runner import PipelineResult, run_stages
from gtrig.pipeline.survey import survey
from gtrig.pipeline.vision import gtvision

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from gtrig.config import RunConfig

_VISION_PRODUCTS = ("tracks/GTvision/validation", "tracks/GTvision/run")

_SURVEY_FILES = ("survey/reference_points.csv", "survey/world_distances.csv", "survey/robot_points.csv",
                 "survey/pose_distances.csv")

STAGES: tuple[Stage, ...] = (
    Stage("survey", "survey", survey, produces=("survey",), reads=_SURVEY_FILES, section="survey"),
    Stage("cameras", "camera calibration", camera_calibration, consumes=("rig",),
          produces=("rig", "camera_report"), reads=("calib/boards.yaml", "calib/world_board"),
          section="cameras"),
    Stage("markers", "marker calibration", marker_calibration, consumes=("rig",),
          produces=("rig", "marker_calibration"), reads=("handheld/camera.yaml", "handheld/images"),
          section="markers"),
    Stage("robot-frame", "robot frame", robot_frame, consumes=("rig", "survey", "marker_calibration"),
          produces=("rig", "frame_fit", "vision_validation", "hand_frame_cov"),
          reads=("validation/poses.csv", "validation/cameras"), section="vision"),
    Stage("laser", "GTlaser", gtlaser, consumes=("rig",),
          produces=("rig", "laser_report", "tracks/GTlaser/run"),
          reads=("background/lasers", "run/lasers", "calib/laser_object.yaml"), section="laser"),
    Stage("vision", "GTvision", gtvision, consumes=("rig",),
          uses=("marker_calibration", "frame_fit", "vision_validation", "hand_frame_cov", "survey"),
          produces=_VISION_PRODUCTS, reads=("validation/poses.csv", "validation/cameras", "run/cameras"),
          section="vision"),
    Stage("sync", "time sync", sync, uses=("tracks/GTvision/run", "tracks/GTlaser/run", "rig"),
          produces=("clock_offsets",), reads=("run/odometry.csv", "run/cameras", "run/lasers", "background/lasers"),
          section="fusion"),
    Stage("laser-clock", "GTlaser on one clock", gtlaser_clock, consumes=("rig", "laser_report"),
          uses=("clock_offsets",), produces=("tracks/GTlaser-synced/run",),
          reads=("background/lasers", "run/lasers", "run/odometry.csv"), section="laser"),
    Stage("fusion", "fusion", fusion, uses=("tracks/GTvision/run", "tracks/GTlaser/run", "clock_offsets"),
          produces=("tracks/fusion/run",), reads=("run/odometry.csv",), section="fusion"),
)


def run(rec: str | Path, out: str | Path, on_stage: Callable[[str], None] | None = None, *,
        config: RunConfig | None = None, only: Sequence[str] | None = None, from_stage: str | None = None,
        reuse: bool = True, executor: Any = None, progress: Callable[[int, int], None] | None = None
        ) -> PipelineResult:
    """Run every available stage on the recording ``rec``, writing under ``out``
    (:func:`gtrig.pipeline.runner.run_stages` with :data:`STAGES`). ``executor``: a
    ``concurrent.futures.Executor`` or a Dask ``distributed.Client`` to run the chunks on (default: local
    processes, ``config.workers``); the outputs do not depend on it."""
    return run_stages(STAGES, rec, out, config, only=only, from_stage=from_stage, reuse=reuse, on_stage=on_stage,
                      executor=executor, progress=progress)


__all__ = ["STAGES", "AccuracyRow", "PipelineResult", "Products", "Stage", "StageInput", "StageOutput",
           "read_accuracy_csv", "run", "write_accuracy_csv"]
