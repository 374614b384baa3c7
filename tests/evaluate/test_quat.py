"""The batched quaternion helpers agree with SciPy's Rotation."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.evaluate import quat


def test_against_scipy() -> None:
    a, b = Rotation.random(500, random_state=1), Rotation.random(500, random_state=2)
    small = Rotation.from_rotvec(np.random.default_rng(3).normal(0, 1e-9, (500, 3)))
    qa, qb = a.as_quat(), b.as_quat()
    ab = quat.mul(qa, qb)
    assert np.allclose(np.abs(np.sum(ab * (a * b).as_quat(), axis=1)), 1.0, atol=1e-12)
    assert np.allclose(quat.angle(quat.mul(quat.conj(qa), qb)), (a.inv() * b).magnitude(), atol=1e-12)
    assert np.allclose(quat.rotvec(ab), (a * b).as_rotvec(), atol=1e-9)
    assert np.allclose(quat.rotvec(small.as_quat()), small.as_rotvec(), rtol=1e-9, atol=1e-18)
    v = np.random.default_rng(4).normal(size=(500, 3))
    assert np.allclose(quat.rotate(qa, v), a.apply(v), atol=1e-12)
    assert np.allclose(quat.rotate(qa, v, inverse=True), a.apply(v, inverse=True), atol=1e-12)
