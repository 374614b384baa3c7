"""Simulator settings: one typed model, validated once, written next to every recording."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class _Cfg(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class CameraSimConfig(_Cfg):
    supersample: int = Field(default=4, ge=1, le=8)
    noise_sigma: float = Field(default=2.0, ge=0, description="8-bit grey levels, at mid grey")
    defocus_sigma_px: float = Field(default=0.5, ge=0, description="at the focus distance's edges")
    motion_blur: bool = True
    exposure_s: float = Field(default=0.008, gt=0)
    vignetting: float = Field(default=0.25, ge=0, le=1, description="relative fall-off at the corners")
    sunlight: bool = True
    stamp_jitter_s: float = Field(default=0.002, ge=0)
    png_compression: int = Field(default=1, ge=0, le=9)


class LaserSimConfig(_Cfg):
    people: int = Field(default=2, ge=0)
    mixed_pixels: bool = True
    dropout_prob: float = Field(default=0.003, ge=0, le=1)
    reflectivity_bias_m: float = Field(default=0.008, ge=0, description="range bias between dark and bright")


class SimConfig(_Cfg):
    """What ``gtrig sim`` simulates. ``quick`` shortens every sequence for tests."""

    scenario: str = "gtroom"
    seed: int = 0
    quick: bool = False
    run_duration_s: float | None = Field(default=None, gt=0, description="None: the whole path")
    static_pose_s: float = Field(default=1.0, gt=0, description="time the robot stands at each validation pose")
    background_s: float = Field(default=4.0, gt=0)
    # a minute of sweep video at 2 Hz with the board carried over the whole image: with fewer views the
    # principal point stays uncertain to about 0.5 px (docs/calibration.md measures 20 against 120)
    n_intrinsic_views: int = Field(default=120, ge=3)
    n_pair_views: int = Field(default=24, ge=2)
    n_world_board_views: int = Field(default=3, ge=1)
    n_handheld_views: int = Field(default=30, ge=2)
    workers: int = Field(default=0, ge=0, description="processes; 0 = one per core")
    odometry_clock_offset_s: float = Field(
        default=0.0, ge=-60, le=60,
        description="the robot's clock (odometry, onboard scanners) minus the GT room's clock; written to "
        "truth/robot_clock.yaml, for checking time sync")
    camera: CameraSimConfig = CameraSimConfig()
    laser: LaserSimConfig = LaserSimConfig()

    @classmethod
    def quick_defaults(cls, seed: int = 0) -> SimConfig:
        return cls(seed=seed, quick=True, run_duration_s=6.0, static_pose_s=0.2, background_s=1.0,
                   n_intrinsic_views=8, n_pair_views=4, n_world_board_views=1, n_handheld_views=8)
