"""An uneven floor: a smooth height field that tilts the robot (up to about 0.5 deg).

Physical source: screeded concrete and tiled floors deviate by a few millimetres over metres
(DIN 18202 allows 4 mm under a 1 m straightedge), enough to tilt a robot by tenths of a degree and so
to move the line where a fixed laser plane cuts the robot's gown.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from gtrig import geometry as geo


@dataclass(frozen=True)
class Floor:
    """Height ``z(x, y) = sum_k a_k sin(kx_k x + ky_k y + phi_k)`` in metres.

    Attributes
    ----------
    amp_m, kx, ky, phase : (K,) arrays
    """

    amp_m: np.ndarray
    kx: np.ndarray
    ky: np.ndarray
    phase: np.ndarray

    @staticmethod
    def random(rng: np.random.Generator, max_tilt_deg: float = 0.5, n_waves: int = 4) -> Floor:
        wavelength = rng.uniform(2.0, 5.0, n_waves)
        direction = rng.uniform(0, np.pi, n_waves)
        k = 2 * np.pi / wavelength
        slope = np.tan(np.radians(max_tilt_deg))
        # the sum of the per-wave maximum slopes is the worst-case slope
        amp = rng.uniform(0.5, 1.0, n_waves) / k
        amp *= slope / np.sum(amp * k)
        return Floor(amp, k * np.cos(direction), k * np.sin(direction), rng.uniform(0, 2 * np.pi, n_waves))

    @staticmethod
    def flat() -> Floor:
        z = np.zeros(0)
        return Floor(z, z, z, z)

    def height(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        x = np.asarray(x, dtype=float)[..., None]
        y = np.asarray(y, dtype=float)[..., None]
        return np.sum(self.amp_m * np.sin(self.kx * x + self.ky * y + self.phase), axis=-1)

    def gradient(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(x, dtype=float)[..., None]
        y = np.asarray(y, dtype=float)[..., None]
        c = self.amp_m * np.cos(self.kx * x + self.ky * y + self.phase)
        return np.sum(c * self.kx, axis=-1), np.sum(c * self.ky, axis=-1)

    def robot_pose(self, x: float, y: float, theta: float) -> geo.Array:
        """``T_world_robot`` of a robot standing at planar pose (x, y, theta) on this floor.

        The robot frame's origin is on the floor under the robot's centre; its z axis is the floor normal
        (the robot rests on the local tangent plane), its x axis the heading projected on that plane.
        """
        gx, gy = self.gradient(x, y)
        n = np.array([-float(gx), -float(gy), 1.0])
        n /= np.linalg.norm(n)
        h = np.array([np.cos(theta), np.sin(theta), 0.0])
        xa = h - n * (h @ n)
        xa /= np.linalg.norm(xa)
        ya = np.cross(n, xa)
        return geo.make_T(np.column_stack([xa, ya, n]), [x, y, float(self.height(x, y))])
