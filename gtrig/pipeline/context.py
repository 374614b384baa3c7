"""The pipeline's typed context and the stage interface.

What a stage gets: a :class:`StageInput` (the recording, its output folder, the run configuration and
the :class:`Products` of the stages before it). What it gives back: a :class:`StageOutput` (new
products, accuracy rows against truth, checks that need no truth). Products are objects, never files
to read again: the calibrated rig, the survey's result, and pose tracks by name
(:class:`gtrig.trajectory.PoseTrack`, e.g. ``tracks["GTlaser/run"]``).

Adding a stage
--------------
A stage is one function ``fn(inp: StageInput) -> StageOutput`` in its own module under
``gtrig/pipeline/`` and one :class:`Stage` entry in ``gtrig.pipeline.STAGES`` (the order is the order
it runs in). The entry declares

* ``consumes``: the products it reads: field names of :class:`Products` (``"rig"``, ``"survey"``...)
  or ``"tracks/<name>"`` for a pose track. The runner refuses (skips with one line) a stage whose
  consumed product no earlier stage produced, and a stage reads nothing else of the context;
* ``uses``: products it reads when they exist and does without otherwise (GTvision uses the frame
  fit when the robot-frame stage ran); like ``consumes``, they key its reuse;
* ``produces``: what its output may set, the same names. An output setting an undeclared name is a
  programming error (``ValueError``); a stage producing ``"rig"`` gets it written as
  ``DIR/rig.calibrated.yaml``;
* ``reads``: the recording's top-level entries it reads (``"survey"``, ``"run"``, ``"rig.yaml"``...):
  a missing one skips the stage with one line naming it, and a change in one reruns the stage;
* ``section``: its part of :class:`gtrig.config.RunConfig` (``None`` if it has no options).

A finished stage is reused when its key (its code's version, its configuration section, the
fingerprint of what it reads in the recording, and the keys of the stages that produced what it
consumes) is that of its last run (:mod:`gtrig.pipeline.cache`); ``--from NAME`` reruns from it on.

Example, a fusion stage::

    def fuse(inp: StageInput) -> StageOutput:
        vis, las = inp.products.tracks["GTvision/run"], inp.products.tracks["GTlaser/run"]
        fused = ...  # a PoseTrack
        write_pose_track(fused, inp.out / "gt_fused.tum", inp.out / "gt_fused_cov.csv")
        return StageOutput(products={"tracks/fusion": fused})

    Stage("fusion", "fusion", fuse, consumes=("tracks/GTvision/run", "tracks/GTlaser/run"),
          produces=("tracks/fusion",), reads=(), section="fusion")
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from gtrig.calib.recording import CalibrationReport as CameraCalibrationReport
    from gtrig.config import RunConfig
    from gtrig.laser.calibrate import CalibrationReport as LaserCalibrationReport
    from gtrig.markers.robotcal import RobotCalibration
    from gtrig.rig import Rig
    from gtrig.survey import SurveyResult
    from gtrig.trajectory import PoseTrack
    from gtrig.vision.robot_frame import FrameFit
    from gtrig.vision.sequence import VisionResult

TRACK_PREFIX = "tracks/"


@dataclass(frozen=True)
class AccuracyRow:
    """One measured figure: ``stage``, what was measured, the value with its unit, and our target."""

    stage: str
    metric: str
    value: float
    unit: str
    target: str = ""
    ok: bool | None = None


@dataclass(frozen=True)
class Products:
    """What the stages have produced so far; each stage gets a new one (never changed in place).

    Attributes
    ----------
    rig : the rig as calibrated so far (the recording's nominal ``rig.yaml`` before any calibration).
    survey : the hand-laser survey's world points and validation poses.
    camera_report : the cameras' calibration report.
    marker_calibration : the markers' poses on the robot and their covariances.
    frame_fit : the markers' robot frame tied to the surveyed one at the validation stops.
    vision_validation : GTvision on the validation stops with its own covariances (before the frame fit).
    hand_frame_cov : (6, 6) the hand-placed anchor's frame covariance the frame fit replaced.
    laser_report : the fixed scanners' calibration report.
    clock_offsets : each GT source's clock minus odometry's, seconds, where sync could measure it.
    tracks : pose tracks by name, ``"<source>/<sequence>"`` (``"GTvision/run"``, ``"GTlaser/run"``...).
    """

    rig: Rig | None = None
    survey: SurveyResult | None = None
    camera_report: CameraCalibrationReport | None = None
    marker_calibration: RobotCalibration | None = None
    frame_fit: FrameFit | None = None
    vision_validation: VisionResult | None = None
    hand_frame_cov: np.ndarray | None = None
    laser_report: LaserCalibrationReport | None = None
    clock_offsets: Mapping[str, float] | None = None
    tracks: Mapping[str, PoseTrack] = field(default_factory=lambda: MappingProxyType({}))

    def has(self, name: str) -> bool:
        """Whether the product ``name`` (a field, or ``tracks/<name>``) has been produced."""
        if name.startswith(TRACK_PREFIX):
            return name[len(TRACK_PREFIX):] in self.tracks
        return getattr(self, name) is not None

    def updated(self, changes: Mapping[str, Any]) -> Products:
        """A new context with ``changes`` (fields, ``tracks/<name>`` entries)."""
        plain: dict[str, Any] = {}
        tracks = dict(self.tracks)
        for k, v in changes.items():
            if k.startswith(TRACK_PREFIX):
                tracks[k[len(TRACK_PREFIX):]] = v
            else:
                plain[k] = v
        return dataclasses.replace(self, tracks=MappingProxyType(tracks), **plain)


PRODUCT_FIELDS = tuple(f.name for f in dataclasses.fields(Products))


def _valid_name(name: str) -> bool:
    if name.startswith(TRACK_PREFIX):
        return len(name) > len(TRACK_PREFIX)
    return name in PRODUCT_FIELDS


@dataclass(frozen=True)
class StageInput:
    """What a stage is given.

    Attributes
    ----------
    rec : the recording folder (docs/formats.md).
    out : the run's output folder (the stage writes under it).
    config : the whole validated run configuration (a stage reads its own section).
    products : the earlier stages' products.
    has_truth : the recording carries ``truth/`` (simulated): the stage may measure itself against it.
    workers : processes for parallel steps (0 = one per core); results do not depend on it.
    executor : where chunks run instead of a local pool of ``workers``: a ``concurrent.futures.Executor``
        or a Dask client (:mod:`gtrig.executor`); results do not depend on it.
    progress : ``progress(done_chunks, total_chunks)`` of the stage's chunk map, for a progress bar.
    """

    rec: Path
    out: Path
    config: RunConfig
    products: Products
    has_truth: bool
    workers: int = 0
    executor: Any = None
    progress: Callable[[int, int], None] | None = None


@dataclass(frozen=True)
class StageOutput:
    """What a stage gives back.

    Attributes
    ----------
    products : new products by name (declared in the stage's ``produces``).
    rows : figures against truth (the accuracy table, ``accuracy.csv``); empty without truth.
    checks : figures that need no truth (coverage, residuals, leave-one-out, NEES on the stops),
        ``summary.csv``; a check with ``ok=False`` is printed as a warning.
    outputs : files written, relative to the output folder (reuse checks they still exist).
    """

    products: Mapping[str, Any] = field(default_factory=dict)
    rows: tuple[AccuracyRow, ...] = ()
    checks: tuple[AccuracyRow, ...] = ()
    outputs: tuple[str, ...] = ()


@dataclass(frozen=True)
class Stage:
    """One step of the pipeline (see the module docstring for how to add one)."""

    name: str
    title: str
    fn: Callable[[StageInput], StageOutput]
    consumes: tuple[str, ...] = ()
    produces: tuple[str, ...] = ()
    uses: tuple[str, ...] = ()
    reads: tuple[str, ...] = ()
    section: str | None = None
    doc: str = ""

    def __post_init__(self) -> None:
        for n in (*self.consumes, *self.uses, *self.produces):
            if not _valid_name(n):
                raise ValueError(f"stage {self.name}: {n!r} is not a product ({', '.join(PRODUCT_FIELDS)}, "
                                 f"{TRACK_PREFIX}<name>)")

    def check_output(self, out: StageOutput) -> None:
        extra = [k for k in out.products if k not in self.produces]
        if extra:
            raise ValueError(f"stage {self.name} produced {extra} it does not declare in produces")
