"""Simulator settings: one typed model, validated once, written next to every recording."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

#: appended, with the draw, to a noise stream's key: no stream of draw 0 has a key of that form
NOISE_DRAW_SALT = 0x4E015E


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
    clock_offset_sigma_s: float = Field(
        default=0.002, ge=0, description="standard deviation of each fixed scanner's fixed clock offset, seconds "
                                         "(0: scanners on one clock; the same noise otherwise)")
    beam_timing: Literal["sweep", "simultaneous"] = Field(
        default="sweep", description="the fixed scanners' beams sweep over the period or fire together")
    stamp_at: Literal["start", "middle", "end"] = Field(
        default="start", description="the instant of the sweep the fixed scanners' stamps refer to")
    blocked_scanner: int | None = Field(
        default=None, ge=0, description="index of a fixed scanner partly blocked by clutter next to it")
    blocked_fraction: float = Field(default=0.5, gt=0, lt=1, description="share of its field of view blocked")
    gown_reflectivity: tuple[float, float, float, float] | None = Field(
        default=None, description="per hull side (rear, right, front, left fabric; 0 black, 1 white); "
                                  "None: one light fabric all round")
    surface_draw: int = Field(
        default=0, ge=0, description="0: the room's designed wall and clutter materials; k > 0: the k-th seeded "
        "draw of every wall's and box's reflectivity, so of its range bias (gtrig.sim.lasers.surface_reflectivities)")


class MotionSimConfig(_Cfg):
    """The continuous run's speed profile. ``cruise``: the default, 0.3 m/s with 1 s ramps at the ends.
    ``agile``: as fast as ``speed_mps`` on straights, slowed in bends by the lateral acceleration and yaw
    rate limits, accelerating and braking at ``accel_mps2`` (gtrig.sim.motion.agile_path)."""

    profile: Literal["cruise", "agile"] = "cruise"
    speed_mps: float = Field(default=0.3, gt=0, le=3.0)
    accel_mps2: float = Field(default=1.0, gt=0, le=5.0)
    lat_accel_mps2: float = Field(default=1.0, gt=0, le=5.0)
    yaw_rate_max_radps: float = Field(default=2.0, gt=0, le=6.0)


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
    calib_board: Literal["chessboard", "charuco"] = Field(
        default="chessboard", description="the board the intrinsic sweeps show (the double board and the world "
        "board stay chessboards); charuco: gtrig.sim.textures.sim_charuco_board, same size and poses")
    workers: int = Field(default=0, ge=0, description="processes; 0 = one per core")
    odometry_clock_offset_s: float = Field(
        default=0.0, ge=-60, le=60,
        description="the robot's clock (odometry, onboard scanners) minus the GT room's clock; written to "
        "truth/robot_clock.yaml, for checking time sync")
    noise_draw: int = Field(
        default=0, ge=0, description="0: the seed's own measurement noise; k > 0: the k-th independent draw of "
        "it, everything else (scene, rig, paths, people, clock offsets, odometry calibration, calibration "
        "poses) the seed's: Monte Carlo evaluation (docs/simulator.md, 'Noise draws')")
    noise_redrawn: Literal["all", "sensors", "calibration"] = Field(
        default="all", description="what noise_draw redraws: every measurement's noise; the sensors' "
        "(cameras, scanners, odometry), the survey's readings kept; or only the calibration images' "
        "(calib/, handheld/)")
    camera: CameraSimConfig = CameraSimConfig()
    laser: LaserSimConfig = LaserSimConfig()
    motion: MotionSimConfig = MotionSimConfig()

    def noise_draw_of(self, data: Literal["calibration", "sensors", "survey"]) -> int:
        """The noise draw of ``data``: ``calibration`` the calibration images (``calib/``, ``handheld/``),
        ``sensors`` the sequences' images and stamps, the scans and the odometry, ``survey`` the hand
        laser's readings; 0 is the seed's own noise."""
        redrawn = {"all": ("calibration", "sensors", "survey"), "sensors": ("calibration", "sensors"),
                   "calibration": ("calibration",)}[self.noise_redrawn]
        return self.noise_draw if data in redrawn else 0

    @classmethod
    def quick_defaults(cls, seed: int = 0) -> SimConfig:
        return cls(seed=seed, quick=True, run_duration_s=6.0, static_pose_s=0.2, background_s=1.0,
                   n_intrinsic_views=8, n_pair_views=4, n_world_board_views=1, n_handheld_views=8)


def noise_stream(rng: np.random.Generator, key: Sequence[int], draw: int) -> np.random.Generator:
    """The generator of a measurement's noise: ``rng`` itself for draw 0 (the seed's own noise, which
    ``rng`` may share with geometric draws made before it), else an independent stream of ``key``
    (the integers ``rng`` was seeded with) and ``draw``, which leaves ``rng``'s geometric draws as they are."""
    if draw == 0:
        return rng
    return np.random.default_rng([*(int(k) for k in key), NOISE_DRAW_SALT, int(draw)])
