"""GTvision's covariance of markers whose four corners share an error (a clipped white level offsets a
marker's edges as one): a fit that takes the corners as independent averages that error away; the estimator
weights each view's corners with their joint covariance (:func:`gtrig.vision.covariance.common_whitening`)."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.vision.covariance import (
    RigUncertainty,
    common_whitening,
    edge_pull_jacobian,
    pose_error_xi,
)
from gtrig.vision.estimate import VisionOptions, estimate_frame
from gtrig.vision.observations import FrameObservations, MarkerView, VisionModel
from gtrig.vision.sequence import _views_from_json, _views_to_json
from gtrig.vision.synthetic import visible_views

#: an edge's own sigma and the sigma of the offset a marker's four edges share, px (the simulated room's
#: sunlit, moving markers: 0.035 and 0.136 px along the edges' normals)
OWN_PX, COMMON_PX = 0.035, 0.13


def _one_view() -> tuple[object, np.ndarray, str, int, np.ndarray]:
    scene = make_scene(0)
    T = scene.T_world_robot(*VALIDATION_POSES[8])
    cam, mid, uv = visible_views(scene.rig_true, T)[0]
    return scene.rig_true, T, cam, mid, uv


def _common_move(uv: np.ndarray, sigma_px: float) -> np.ndarray:
    """(4, 2) the corners' move when every edge of the marker ``uv`` moves ``sigma_px`` outwards."""
    return -(edge_pull_jacobian(uv) @ np.full(4, sigma_px)).reshape(4, 2)


def _errors_and_covariance(common_corners: bool, draws: int = 150) -> tuple[np.ndarray, np.ndarray]:
    """Pose errors (draws, 6) of ``draws`` fits (6 dof, no floor prior) of one marker whose corners carry an
    own error each (isotropic) and a common one (all edges outwards by one draw), and the mean stated
    covariance (6, 6)."""
    rig, T, cam, mid, uv = _one_view()
    model = VisionModel.from_rig(rig)  # type: ignore[arg-type]
    c = _common_move(uv, COMMON_PX)
    cov = OWN_PX**2 * np.eye(2) + np.einsum("ci,cj->cij", c, c)  # each corner's marginal: own and common
    opts = VisionOptions(planar=False, rig_uncertainty=RigUncertainty.none(), corner_floor_px=0.0, blur_pull=False,
                         common_corners=common_corners)
    rng = np.random.default_rng(3)
    err, covs = [], []
    for _ in range(draws):
        noisy = uv + rng.normal(0.0, OWN_PX, (4, 2)) + rng.normal() * c
        e = estimate_frame(model, FrameObservations(0.0, (MarkerView(cam, mid, noisy, cov, corner_common=c),), (cam,)),
                           opts)
        assert e.ok and e.T_world_robot is not None and e.cov_6x6 is not None
        err.append(pose_error_xi(e.T_world_robot, T))
        covs.append(e.cov_6x6)
    return np.array(err), np.mean(covs, axis=0)


@pytest.mark.parametrize("common_corners", [True, False])
def test_common_error_in_the_pose_covariance(common_corners: bool) -> None:
    """Along every principal axis of the stated pose covariance, the errors' variance over the stated one:
    near 1 with the joint weighting (0.68-0.97 over these 150 draws: the 2-dof frames' variance factor
    inflates a few covariances); without it the fit, which averaged the common error as four independent
    ones (and took the corners' common part for their own), states one axis about half as large as it is."""
    err, C = _errors_and_covariance(common_corners)
    w, V = np.linalg.eigh(C)
    ratio = np.einsum("ia,ij,ja->a", V, err.T @ err / len(err), V) / w
    if common_corners:
        assert np.all((ratio > 0.6) & (ratio < 1.3)), ratio.round(2)
    else:
        assert ratio.max() > 1.6, ratio.round(2)


def test_common_whitening_whitens_the_joint_covariance() -> None:
    # corners with unequal covariances, a common move and one corner whose own part is clipped
    rng = np.random.default_rng(5)
    A = rng.normal(0.0, 0.05, (4, 2, 2))
    cov = np.einsum("nij,nkj->nik", A, A) + 0.02**2 * np.eye(2)
    c = rng.normal(0.0, 0.05, (4, 2))
    c[2] = 0.5 * c[2] / np.sqrt(c[2] @ np.linalg.solve(cov[2], c[2]))  # common part 1/4 of the corner's
    s = np.array([1.0, 1.0, 6.0, 1.0])  # a camera factor that would leave corner 2 no own variance
    L = np.linalg.cholesky(np.linalg.inv(cov))
    M = common_whitening(L, c, s)
    assert M is not None and M.shape == (1, 8, 8)
    # the corners' covariances as the fit has them (already times their camera's factor): each less its
    # share of the common part, at most 95 % of what it holds along the common move
    joint = np.outer(c.reshape(8), c.reshape(8))
    Lb = np.zeros((8, 8))
    for i in range(4):
        o = min(s[i], 0.95 / float(c[i] @ np.linalg.solve(cov[i], c[i])))
        joint[2 * i:2 * i + 2, 2 * i:2 * i + 2] += cov[i] - o * np.outer(c[i], c[i])
        Lb[2 * i:2 * i + 2, 2 * i:2 * i + 2] = L[i].T
    W = M[0] @ Lb
    assert np.allclose(W @ joint @ W.T, np.eye(8), atol=1e-9)
    assert common_whitening(L, np.zeros((4, 2)), s) is None


def test_common_move_survives_the_checkpoint() -> None:
    c = np.arange(8.0).reshape(4, 2) / 10
    v = MarkerView("cam0", 3, np.ones((4, 2)), np.tile(np.eye(2), (4, 1, 1)), 7, 0.4, c)
    w = MarkerView("cam0", 4, np.ones((4, 2)), np.tile(np.eye(2), (4, 1, 1)), 7, 0.4)
    back = _views_from_json("cam0", 7, _views_to_json([v, w]))
    assert back[0].corner_common is not None and np.array_equal(back[0].corner_common, c)
    assert back[1].corner_common is None


def test_views_without_a_common_move_fit_as_before() -> None:
    # a frame none of whose markers clips has no common term: the joint weighting leaves its fit as it was
    rig, T, cam, mid, uv = _one_view()
    model = VisionModel.from_rig(rig)  # type: ignore[arg-type]
    noisy = uv + np.random.default_rng(1).normal(0.0, OWN_PX, (4, 2))
    obs = FrameObservations(0.0, (MarkerView(cam, mid, noisy, np.tile(OWN_PX**2 * np.eye(2), (4, 1, 1))),), (cam,))
    on, off = (estimate_frame(model, obs, VisionOptions(common_corners=b)) for b in (True, False))
    assert on.ok and on.T_world_robot is not None and off.T_world_robot is not None
    assert on.cov_6x6 is not None and off.cov_6x6 is not None
    assert np.array_equal(on.T_world_robot, off.T_world_robot) and np.array_equal(on.cov_6x6, off.cov_6x6)
    # with a common move the fit changes: the joint weighting is not a no-op
    c = _common_move(uv, COMMON_PX)
    obs_c = FrameObservations(0.0, (MarkerView(cam, mid, noisy, np.tile(OWN_PX**2 * np.eye(2), (4, 1, 1))
                                               + np.einsum("ci,cj->cij", c, c), corner_common=c),), (cam,))
    on_c, off_c = (estimate_frame(model, obs_c, VisionOptions(common_corners=b)) for b in (True, False))
    assert on_c.cov_6x6 is not None and off_c.cov_6x6 is not None
    assert not np.allclose(on_c.cov_6x6, off_c.cov_6x6)
