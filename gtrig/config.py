"""The run configuration: every stage's options in one validated model (``gtrig run --config run.yaml``).

One pydantic model, :class:`RunConfig`, one section per stage. Its defaults are the stages' own
dataclass defaults (``TrackSettings``, ``IcpSettings``, ``VisionOptions``, ``RobotCalOptions``...), read
from those classes, so a default changed in a stage changes here too and never drifts. A YAML file
overrides any part of it (``laser: {max_gap_s: 0.3}`` changes that one value); unknown keys and wrong
types are refused with one line naming the field (:class:`~gtrig.errors.ConfigError`, exit code 2).
The effective configuration is written next to the results as ``DIR/run.yaml``.

A section's options reach its stage as the keyword arguments or dataclass fields that differ from the
defaults (:meth:`Section.overrides`), so a default configuration runs exactly the code the stages run
on their own.
"""

from __future__ import annotations

import dataclasses
import os
import typing
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model

from gtrig.errors import ConfigError, GtrigError
from gtrig.laser.hull_icp import IcpSettings
from gtrig.laser.track import TrackSettings
from gtrig.markers.robotcal.bundle import BundleOptions
from gtrig.markers.robotcal.calibrate import RobotCalOptions
from gtrig.vision.estimate import VisionOptions
from gtrig.vision.track import TrackOptions

_SCALARS = (bool, int, float, str)


class Section(BaseModel):
    """A configuration section: unknown keys refused, values validated on assignment too."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=True)

    def overrides(self, exclude: tuple[str, ...] = ()) -> dict[str, Any]:
        """The values that differ from the defaults (nested sections as their own overrides)."""
        out: dict[str, Any] = {}
        for name in type(self).model_fields:
            if name in exclude:
                continue
            v = getattr(self, name)
            if isinstance(v, Section):
                sub = v.overrides()
                if sub:
                    out[name] = sub
            elif v != type(self).model_fields[name].default:
                out[name] = v
        return out


def _scalar_type(hint: Any) -> Any | None:
    """``hint`` if it is a scalar type or a Literal of scalars, else None (nested or array fields)."""
    if hint in _SCALARS:
        return hint
    if typing.get_origin(hint) is Literal:
        return hint
    return None


# The ranges of the stages' options, checked at load (a negative gap or a NaN tolerance is refused
# naming the field before any work). A float is finite and positive, an int at least 1, unless named here.
_MAY_BE_ZERO = frozenset({
    "tol_m", "tol_rad", "step_tol", "end_margin_m", "min_jump_m", "min_jump_rad", "min_motion_m",
    "prior_max_gap_s", "reacquire_gap_s", "floor_std_m", "floor_std_rad", "surface_bias_std_m",
    "side_bias_std_m", "corner_floor_px", "corner_sigma_floor_px", "previous_max_gap_s",
})
_RANGES: dict[str, dict[str, float]] = {
    "view_p": {"gt": 0, "lt": 1},
    "image_bad_fraction": {"gt": 0, "le": 1},
    "frame_scale_level": {"gt": 0, "lt": 1},
    "smoother_order": {"ge": 2, "le": 3},
    "min_points": {"ge": 3},
}


def _range(name: str, t: Any) -> dict[str, Any]:
    """The pydantic ``Field`` constraints of the dataclass option ``name`` of type ``t``."""
    if t is float:
        return {"allow_inf_nan": False, **_RANGES.get(name, {"ge": 0} if name in _MAY_BE_ZERO else {"gt": 0})}
    if t is int:
        return _RANGES.get(name, {"ge": 0} if name in _MAY_BE_ZERO else {"ge": 1})
    return {}


def section_from_dataclass(name: str, cls: type, exclude: tuple[str, ...] = (),
                           nested: dict[str, type[Section]] | None = None) -> type[Section]:
    """A :class:`Section` with the scalar fields of the frozen dataclass ``cls`` and its defaults
    (``nested`` maps a field holding another dataclass to its section)."""
    hints = typing.get_type_hints(cls)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        if nested and f.name in nested:
            sec = nested[f.name]
            fields[f.name] = (sec, Field(default_factory=sec))
            continue
        t = _scalar_type(hints[f.name])
        if t is None or f.default is dataclasses.MISSING:
            continue
        d = f.default
        # numpy scalars as plain Python ones (the same value; YAML writes them)
        d = t(d) if t in (int, float) else d
        fields[f.name] = (t, Field(default=d, **_range(f.name, t)))
    model = create_model(name, __base__=Section, **fields)
    model.__doc__ = f"Options of :class:`{cls.__module__}.{cls.__qualname__}` (its defaults)."
    return model


def apply_to_dataclass(section: Section, obj: Any) -> Any:
    """``obj`` (a frozen dataclass) with the section's non-default values (nested ones too)."""
    changes: dict[str, Any] = {}
    for k, v in section.overrides().items():
        sub = getattr(section, k)
        changes[k] = apply_to_dataclass(sub, getattr(obj, k)) if isinstance(sub, Section) else v
    return dataclasses.replace(obj, **changes) if changes else obj


IcpSection = section_from_dataclass("IcpSection", IcpSettings)
LaserTrackSection = section_from_dataclass("LaserTrackSection", TrackSettings, nested={"icp": IcpSection})
BundleSection = section_from_dataclass("BundleSection", BundleOptions)
RobotCalSection = section_from_dataclass("RobotCalSection", RobotCalOptions, nested={"bundle": BundleSection})
VisionEstimateSection = section_from_dataclass("VisionEstimateSection", VisionOptions, exclude=("planar",))


class SurveyConfig(Section):
    """The hand-laser survey (:func:`gtrig.survey.recording.run_survey`)."""

    joint: bool = True
    multistart: bool = True
    on_ambiguity: Literal["refuse", "warn"] = "refuse"
    on_outlier: Literal["exclude", "refuse", "keep"] = "exclude"
    alpha: float = Field(default=0.001, gt=0, lt=1, allow_inf_nan=False)


class CamerasConfig(Section):
    """The cameras' intrinsic and network calibration (:func:`gtrig.calib.recording.calibrate_recording`)."""

    estimate_k3: bool = False


class MarkersConfig(Section):
    """The markers' calibration on the robot (:func:`gtrig.markers.robotcal.calibrate_markers`)."""

    anchor: int = Field(default=14, ge=0)  # the seeds' "dima-marker" (gtrig.markers.robotcal.DEFAULT_ANCHOR)
    options: RobotCalSection = Field(default_factory=RobotCalSection)  # type: ignore[valid-type]


_TRACK = TrackOptions()


class VisionTrackConfig(Section):
    """How GTvision tracks markers from image to image (:class:`gtrig.vision.track.TrackOptions`)."""

    enabled: bool = Field(default=_TRACK.enabled, description="search each image where its markers are "
                          "expected and where it changed; false: every image whole")
    full_every_s: float = Field(default=_TRACK.full_every_s, gt=0, description="a whole-image pass at least "
                                "this often per camera (s)")
    margin_px: float = Field(default=_TRACK.margin_px, ge=0)
    motion_margin: float = Field(default=_TRACK.motion_margin, ge=0)
    size_margin: float = Field(default=_TRACK.size_margin, ge=0)
    cell_px: int = Field(default=_TRACK.cell_px, ge=2)
    change_level: float = Field(default=_TRACK.change_level, gt=0)
    change_margin_px: float = Field(default=_TRACK.change_margin_px, ge=0)
    window_px: int = Field(default=_TRACK.window_px, ge=64)

    def options(self) -> TrackOptions:
        return TrackOptions(**self.model_dump())


class VisionConfig(Section):
    """GTvision (:func:`gtrig.vision.sequence.run_recording`)."""

    detector: Literal["auto", "gtrig", "aruco"] = "auto"
    planar: bool = True
    sync_tol_s: float = Field(default=0.005, ge=0, allow_inf_nan=False)
    chunk_size: int = Field(default=16, ge=1)
    estimate_noise: bool = True
    options: VisionEstimateSection = Field(default_factory=VisionEstimateSection)  # type: ignore[valid-type]
    track: VisionTrackConfig = Field(default_factory=VisionTrackConfig)


class LaserConfig(Section):
    """GTlaser (:func:`gtrig.laser.track.track_frames`)."""

    track: LaserTrackSection = Field(default_factory=LaserTrackSection)  # type: ignore[valid-type]
    clock: Literal["scanners", "vision", "odometry"] = Field(
        default="vision", description="the clock of gt_laser_synced.tum, after the sync stage: each scanner's "
        "stamps moved by its measured offset onto GTvision's (the cameras') or odometry's clock and the track "
        "fitted again (gtrig.laser.clock); 'scanners': no second track")


class FusionConfig(Section):
    """Time sync and fusion (:func:`gtrig.sync.offset.estimate_offset`, :func:`gtrig.fusion.fuse_tracks`)."""

    estimator: Literal["batch", "ekf"] = "batch"
    max_gap_s: float | None = Field(default=None, gt=0, allow_inf_nan=False,
                                     description="end a segment after this long without a fix")
    sync_search_s: float = Field(default=3.0, gt=0, le=60, allow_inf_nan=False,
                                 description="clock offsets searched, both signs (s)")
    sync_per_sensor: bool = Field(default=True, description="also each camera's and scanner's clock offset "
                                  "(gtrig.sync.sensors)")


class RunConfig(Section):
    """Everything ``gtrig run`` can be told, one section per stage."""

    workers: int = Field(default=0, ge=0, description="processes; 0 = one per core (results do not depend on it)")
    survey: SurveyConfig = Field(default_factory=SurveyConfig)
    cameras: CamerasConfig = Field(default_factory=CamerasConfig)
    markers: MarkersConfig = Field(default_factory=MarkersConfig)
    vision: VisionConfig = Field(default_factory=VisionConfig)
    laser: LaserConfig = Field(default_factory=LaserConfig)
    fusion: FusionConfig = Field(default_factory=FusionConfig)

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.model_dump(mode="json"), sort_keys=False)


def _one_line(where: str, err: ValidationError) -> str:
    e = err.errors()[0]
    loc = ".".join(str(p) for p in e["loc"]) or "(top level)"
    msg = "unknown key" if e["type"] == "extra_forbidden" else e["msg"]
    more = f" (and {err.error_count() - 1} more)" if err.error_count() > 1 else ""
    got = "" if e["type"] == "extra_forbidden" else f", got {e.get('input')!r}"
    return f"{where}: {loc}: {msg}{got}{more}"


def config_from_dict(doc: dict[str, Any] | None, where: str = "configuration") -> RunConfig:
    """A :class:`RunConfig` from a (partial) mapping; :class:`ConfigError` naming the field."""
    if doc is None:
        return RunConfig()
    if not isinstance(doc, dict):
        raise ConfigError(f"{where}: expected a mapping of sections (survey:, vision:, laser: ...)")
    try:
        return RunConfig.model_validate(doc)
    except ValidationError as e:
        raise ConfigError(_one_line(where, e)) from None


def load_config(path: str | os.PathLike[str] | None) -> RunConfig:
    """The defaults overridden by the YAML file ``path`` (``None``: the defaults)."""
    if path is None:
        return RunConfig()
    p = Path(path)
    from gtrig.io.yamlfile import parse_yaml

    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such file") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{p}: not valid YAML (undecodable bytes: a binary file?)") from None
    except IsADirectoryError:
        raise ConfigError(f"{p}: is a folder, expected a run.yaml") from None
    try:
        doc = parse_yaml(text, str(p))  # within the YAML limits (aliases, depth)
    except GtrigError as e:
        raise ConfigError(str(e)) from None
    return config_from_dict(doc, str(p))


def write_config(cfg: RunConfig, path: str | os.PathLike[str]) -> None:
    """Write the effective configuration (every value, defaults included) as YAML, atomically."""
    from gtrig.io.atomic import atomic_write_text

    atomic_write_text(path, "# gtrig run: the effective configuration of this run\n" + cfg.to_yaml())
