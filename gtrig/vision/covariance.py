"""Covariance of a GTvision pose, and the tools to check it (NEES).

The pose covariance is over the world-frame perturbation ``xi = (dt, dphi)`` of
:mod:`gtrig.vision.projection`: ``cov_6x6`` rows and columns are x, y, z (m) and the rotation vector's
x, y, z components about the world axes (rad). Its planar marginal ``cov_3x3`` is over x, y, yaw
(to first order yaw is the rotation about world z).

Two sources add up:

* the corners' noise: ``inv(J^T W J)`` with the detector's corner covariances (and the floor prior in
  planar mode);
* the rig's uncertainty, which does not average out over corners: each camera's pose (from the network
  calibration) and each marker's pose on the robot. :func:`gtrig.vision.refine.refine_pose` estimates
  a small correction for each camera and marker in view, with their covariances (:class:`RigUncertainty`)
  as Gaussian priors, and
  marginalises them out; to first order this equals "considering" them (Bierman, *Factorization
  Methods for Discrete Sequential Estimation*, 1977, ch. VI) but also weighs the cameras by how well
  they are known.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

if TYPE_CHECKING:
    from gtrig.rig.models import Rig

PLANAR_INDEX = (0, 1, 5)


@dataclass(frozen=True)
class RigUncertainty:
    """Uncertainty of the rig's camera and marker poses.

    A camera or marker with its own covariance (``camera_cov``, ``marker_cov``: the ``pose_cov`` its
    calibration wrote into the rig) gets that; the others get the isotropic sigmas.

    Attributes
    ----------
    camera_xyz_m, camera_rot_rad : one-sigma position and orientation of a camera in the world.
    marker_xyz_m, marker_rot_rad : one-sigma position and orientation of a marker on the robot.
    camera_cov : {camera name: (6 + n, 6 + n)} over the centre's move and the rotation, world axes (m,
        rad), then the first n lens parameters (``gtrig.rig.models.LENS_PARAMETERS``), jointly.
    marker_cov : {marker ID: (6, 6)} over the centre's move and the rotation, robot axes (m, rad); an
        all-zero matrix (the anchor marker) means no nuisance at all.
    variance_factor : every one of these covariances times this (the rig's variance component, estimated
        from a recording's own residuals by :func:`gtrig.vision.noise.estimate_rig_scale`).
    """

    camera_xyz_m: float = 0.002
    camera_rot_rad: float = math.radians(0.02)
    marker_xyz_m: float = 0.0005
    marker_rot_rad: float = math.radians(0.05)
    camera_cov: Mapping[str, np.ndarray] = field(default_factory=dict)
    marker_cov: Mapping[int, np.ndarray] = field(default_factory=dict)
    variance_factor: float = 1.0
    # square-root informations already computed (every frame asks for the same few)
    _sqrt_info: dict[tuple[str, str | int], np.ndarray | None] = field(
        default_factory=dict, compare=False, repr=False)
    _derived: dict[str, RigUncertainty] = field(default_factory=dict, compare=False, repr=False)

    @staticmethod
    def none() -> RigUncertainty:
        return RigUncertainty(0.0, 0.0, 0.0, 0.0)

    def with_rig(self, rig: Rig) -> RigUncertainty:
        """These sigmas, with the full covariance of every camera and marker whose ``pose_cov`` the rig
        holds (calibrated ones) unless this one already has its own; an uncertainty of exactly zero
        stays zero (no nuisance at all)."""
        if not (self.camera_xyz_m or self.camera_rot_rad or self.marker_xyz_m or self.marker_rot_rad):
            return self
        cams = {c.name: np.asarray(c.pose_cov, float) for c in rig.cameras if c.pose_cov is not None}
        marks = {m.id: np.asarray(m.pose_cov, float) for m in rig.robot.markers if m.pose_cov is not None}
        return replace(self, camera_cov={**cams, **self.camera_cov}, marker_cov={**marks, **self.marker_cov},
                       _sqrt_info={}, _derived={})

    def with_camera_timing(self, extra: Mapping[str, np.ndarray]) -> RigUncertainty:
        """The same with ``extra[c]`` (6, 6) added to camera ``c``'s pose block: an image's exposure time
        known only to ``sigma_t`` makes a moving robot look as if the camera had moved (see
        :func:`timing_camera_covariance`), a nuisance of that camera alone."""
        if not extra:
            return self
        cams = dict(self.camera_cov)
        for name, E in extra.items():
            base = cams.get(name)
            if base is None:
                base = np.diag([self.camera_xyz_m**2] * 3 + [self.camera_rot_rad**2] * 3)
            C = np.array(base, dtype=float)
            # the rig's variance factor scales its calibration, not the exposure time's motion
            C[:6, :6] += np.asarray(E, dtype=float) / self.variance_factor
            cams[name] = C
        return replace(self, camera_cov=cams, _sqrt_info={}, _derived={})

    def without_lenses(self) -> RigUncertainty:
        """The same with each camera's covariance cut to its pose (the lens's part marginalised): a
        cheaper model for ranking candidate poses, whose costs barely depend on it."""
        if "without_lenses" not in self._derived:
            self._derived["without_lenses"] = replace(
                self, camera_cov={k: np.asarray(v)[:6, :6] for k, v in self.camera_cov.items()}, _sqrt_info={},
                _derived={})
        return self._derived["without_lenses"]

    def sqrt_information(self, kind: str, key: str | int) -> np.ndarray | None:
        """``S`` (k, k) with ``S^T S`` the inverse covariance of camera (``kind="camera"``) or marker
        ``key`` (k = 6, or 6 + n for a camera whose lens is included), or None when it has no
        uncertainty (then no nuisance is added for it)."""
        if (kind, key) not in self._sqrt_info:
            S = self._sqrt_information(kind, key)
            self._sqrt_info[(kind, key)] = S if S is None else S / np.sqrt(self.variance_factor)
        return self._sqrt_info[(kind, key)]

    def scaled(self, factor: float) -> RigUncertainty:
        """The same with every covariance times ``factor`` more."""
        return replace(self, variance_factor=self.variance_factor * float(factor), _sqrt_info={}, _derived={})

    def _sqrt_information(self, kind: str, key: str | int) -> np.ndarray | None:
        cov = self.camera_cov.get(str(key)) if kind == "camera" else self.marker_cov.get(int(key))
        if cov is None:
            s_t, s_r = ((self.camera_xyz_m, self.camera_rot_rad) if kind == "camera"
                        else (self.marker_xyz_m, self.marker_rot_rad))
            if s_t <= 0 and s_r <= 0:
                return None
            return np.diag([1.0 / max(s_t, 1e-12)] * 3 + [1.0 / max(s_r, 1e-12)] * 3)
        cov = 0.5 * (cov + cov.T)
        d = np.diag(cov)
        if not np.any(d > 0):
            return None
        # a floor well below any real calibration keeps a near-singular block invertible
        L = np.linalg.cholesky(cov + np.diag(np.full(cov.shape[0], 1e-9**2)))
        return np.linalg.inv(L)


#: The rig as it stands before marker-to-robot calibration: cameras from the network calibration
#: (3 mm / 0.05 deg, deliberately above its measured 1 mm / 0.025 deg: the calibration's own error
#: estimate is not validated yet) and markers placed and measured by hand on the robot (2 mm / 0.5 deg:
#: a printed sheet glued to a plate, its pose taken with a ruler and a square). Once the markers are
#: calibrated (gtrig.markers.robotcal), their sigmas come from that calibration.
UNCALIBRATED_MARKERS = RigUncertainty(camera_xyz_m=0.003, camera_rot_rad=math.radians(0.05),
                                      marker_xyz_m=0.002, marker_rot_rad=math.radians(0.5))


#: One-sigma error of the anchor marker's pose on the robot when it is set square against the dima and
#: its offset measured with a caliper (dt x, y, z in m, then rotations about x, y, z in rad, anchor axes):
#: what ``gtrig.pipeline`` assumes for the dima-marker, and what the simulator draws.
ANCHOR_PLACEMENT_SIGMA = (0.0003, 0.0003, 0.00006, math.radians(0.02), math.radians(0.02), math.radians(0.1))


def anchor_frame_covariance(T_robot_anchor: np.ndarray, cov_anchor_6x6: np.ndarray) -> np.ndarray:
    """Covariance (6, 6) of the robot frame's own error caused by the anchor marker's measured pose.

    Every marker calibrated relative to the anchor (:mod:`gtrig.markers.robotcal`) inherits the error
    ``E = exp(eps)`` of the anchor's measured pose ``T_robot_anchor`` (``eps`` over (dt, dphi) in the
    anchor's axes, covariance ``cov_anchor_6x6``). The estimated robot frame is then the true one moved
    by ``F = T_robot_anchor E^-1 T_robot_anchor^-1``, the same at every instant: a common error that
    no averaging over markers or instants removes. Its twist in robot axes is ``-Ad(T_robot_anchor) eps``.

    Returns the covariance of ``F``'s twist over (dt, dphi), robot axes, m and rad.
    """
    T = np.asarray(T_robot_anchor, dtype=float)
    R, t = T[:3, :3], T[:3, 3]
    tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    Ad = np.block([[R, tx @ R], [np.zeros((3, 3)), R]])
    return Ad @ np.asarray(cov_anchor_6x6, dtype=float) @ Ad.T


def timing_camera_covariance(velocity_6: np.ndarray, T_world_robot: np.ndarray, camera_centre_w: np.ndarray,
                             sigma_t_s: float) -> np.ndarray:
    """Covariance (6, 6) of a camera's apparent pose (centre's move, rotation; world axes) caused by its
    exposure time's uncertainty ``sigma_t_s`` while the robot moves with ``velocity_6 = (v, omega)``
    (world frame, the robot origin's velocity; :func:`gtrig.vision.sequence.pose_velocities`).

    The robot moved by ``(v, omega) dt`` is the camera moved by ``dc = -(v + omega x (c - t)) dt``
    and ``dphi = -omega dt`` (``c`` its centre, ``t`` the robot origin), so the covariance is
    ``sigma_t^2 g g^T`` along ``g = -(v + omega x (c - t), omega)``. As a nuisance of each camera it lets
    two cameras of one instant disagree by their own jitter, which a single term on the pose cannot.
    """
    vel = np.asarray(velocity_6, dtype=float)
    lever = np.asarray(camera_centre_w, dtype=float) - np.asarray(T_world_robot, dtype=float)[:3, 3]
    g = -np.r_[vel[:3] + np.cross(vel[3:], lever), vel[3:]]
    return float(sigma_t_s) ** 2 * np.outer(g, g)


def hand_placement_frame_covariance(T_robot_anchor: np.ndarray) -> np.ndarray:
    """:func:`anchor_frame_covariance` for an anchor placed by hand with :data:`ANCHOR_PLACEMENT_SIGMA`
    (set square against the dima, offset measured with a caliper: 0.3 mm, 0.1 deg about z)."""
    return anchor_frame_covariance(T_robot_anchor, np.diag(np.asarray(ANCHOR_PLACEMENT_SIGMA) ** 2))


def add_robot_frame_covariance(T_world_robot: np.ndarray, cov_6x6: np.ndarray, cov_frame_6x6: np.ndarray
                               ) -> np.ndarray:
    """A pose covariance (world axes) plus a robot-frame error of covariance ``cov_frame_6x6`` (robot axes).

    With ``T_est = T_true exp(xi_F)``, the world-frame error is ``(R dt_F, R dphi_F)``; the two errors are
    independent, so the covariances add.
    """
    R = np.asarray(T_world_robot, dtype=float)[:3, :3]
    B = np.kron(np.eye(2), R)
    return np.asarray(cov_6x6, dtype=float) + B @ np.asarray(cov_frame_6x6, dtype=float) @ B.T


def planar_covariance(cov_6x6: np.ndarray) -> np.ndarray:
    """The x, y, yaw marginal (3, 3) of a ``cov_6x6``."""
    i = np.array(PLANAR_INDEX)
    return np.asarray(cov_6x6)[np.ix_(i, i)]


def pose_error_xi(T_est: np.ndarray, T_true: np.ndarray) -> np.ndarray:
    """The estimate's error (6,) in the covariance's parametrisation: ``t_est - t_true`` and
    ``Log(R_est R_true^T)`` (world axes)."""
    dt = T_est[:3, 3] - T_true[:3, 3]
    dphi = Rotation.from_matrix(T_est[:3, :3] @ T_true[:3, :3].T).as_rotvec()
    return np.r_[dt, dphi]


def nees(err: np.ndarray, cov: np.ndarray) -> float:
    """Normalised estimation error squared ``err^T inv(cov) err``; its mean over estimates should be
    the dimension of ``err`` when the covariances are right."""
    err = np.asarray(err, dtype=float)
    return float(err @ np.linalg.solve(cov, err))


#: the blur's pull on a marker's corners (:func:`blur_scale_sigma_px`): at ``side / blur`` of
#: :data:`BLUR_PULL_REF_RATIO` the corners sit :data:`BLUR_PULL_REF_PX` towards the marker's centre, and the
#: pull falls by e every :data:`BLUR_PULL_DECAY_RATIO` more of the ratio (test renders at blur 1.5 px, sides
#: 47-86 px: 0.44-0.51 px at 47 px, 0.32-0.36 at 52, 0.08 at 59, 0.02 at 75; at blur 0.5, 0.01 px)
BLUR_PULL_REF_RATIO = 31.5
BLUR_PULL_REF_PX = 0.5
BLUR_PULL_DECAY_RATIO = 4.5


def blur_scale_sigma_px(side_px: np.ndarray, blur_px: np.ndarray) -> np.ndarray:
    """The sigma (pixels, along each corner's direction from the marker's centre) of the shrinkage a
    blur leaves in a marker's detected corners: ``(V,)`` from the markers' mean side in the image
    ``side_px`` (V,) and the detector's fitted edge blur ``blur_px`` (V,) (NaN: no term, 0).

    A blurred marker's outer edge mixes with the edges of its own border and cells inside it, so the
    edge fits pull all four corners towards the centre together: the marker looks smaller, a single
    marker farther away. The pull is a few hundredths of a pixel while the marker's side is over 45
    blurs, and grows to half a pixel at 30 blurs (1.5 px blur on a 47 px marker: 55 mm of depth at 3.9
    m for a marker seen alone); its direction is known but its size depends on the cells next to the
    border, so it enters the covariance as a zero-mean error of this sigma, one draw per marker image.
    """
    side = np.asarray(side_px, float)
    blur = np.asarray(blur_px, float)
    ratio = np.divide(side, blur, out=np.full(side.shape, np.inf), where=np.isfinite(blur) & (blur > 0))
    return BLUR_PULL_REF_PX * np.exp(-(ratio - BLUR_PULL_REF_RATIO) / BLUR_PULL_DECAY_RATIO)


def edge_pull_jacobian(corners_px: np.ndarray) -> np.ndarray:
    """How a marker's four corners (4, 2) move (8, 4) when each of its four edges (corner k to k + 1)
    moves one pixel towards the marker's centre along its normal: a corner is where its two edges
    cross, so it follows both."""
    c = np.asarray(corners_px, float)
    e = np.roll(c, -1, axis=0) - c
    n = np.column_stack([-e[:, 1], e[:, 0]]) / np.linalg.norm(e, axis=1, keepdims=True)
    n *= np.sign(np.sum(n * (c.mean(axis=0) - c), axis=1))[:, None]  # inwards
    out = np.zeros((8, 4))
    for k in range(4):
        a, b = (k - 1) % 4, k  # the edges that meet at corner k
        M = np.vstack([n[a], n[b]])
        out[2 * k:2 * k + 2][:, [a, b]] = np.linalg.inv(M)
    return out


def blur_consider_covariance(J_whitened: np.ndarray, sqrt_info: np.ndarray, weights: np.ndarray,
                             view: np.ndarray, corners_px: np.ndarray, sigma_px: np.ndarray,
                             cov_6x6: np.ndarray) -> np.ndarray:
    """The pose covariance (6, 6) a fit takes from each view's blur pull (:func:`blur_scale_sigma_px`),
    considered (not estimated).

    Each edge of a view moves towards the centre by a shift common to the view plus one of its own,
    both of sigma ``sigma_px / sqrt(2)`` (the corner's pull along the diagonal is the edges' shift times
    sqrt 2; the test renders show the edges' own shifts as large as the common one: the cells next to
    each edge differ). The pose's first-order change is ``G = -cov_6x6 sum_i w_i J_i^T dr_i`` per edge
    shift (``dr`` the whitened residuals' change, ``-L^T`` times the corners' move of
    :func:`edge_pull_jacobian`); the covariance is ``sum_v G_v S_v G_v^T``.

    Parameters
    ----------
    J_whitened : (N, 2, 6) the fit's whitened corner Jacobian in ``xi``. sqrt_info : (N, 2, 2) ``L``
        of each corner (whitened residual ``L^T r``). weights : (N,) the fit's robust weights.
    view : (N,) each corner's view (four corners a view, in order). corners_px : (N, 2) the observed
        corners. sigma_px : (V,) each view's pull sigma. cov_6x6 : the fit's covariance (the inverse
        normal matrix's pose block).
    """
    out = np.zeros((6, 6))
    S_unit = 0.5 * np.ones((4, 4)) + 0.25 * np.eye(4)
    for v in np.flatnonzero(np.asarray(sigma_px) > 1e-6):
        m = view == v
        E = edge_pull_jacobian(corners_px[m]).reshape(4, 2, 4)
        dr = -np.einsum("nji,njk->nik", sqrt_info[m], E)  # (4, 2, 4): whitened residuals per edge shift
        G = -cov_6x6 @ np.einsum("n,nia,nik->ak", weights[m], J_whitened[m], dr)
        out += sigma_px[v] ** 2 * G @ S_unit @ G.T
    return out


def common_whitening(sqrt_info: np.ndarray, common_px: np.ndarray, own_scale: np.ndarray | None = None
                     ) -> np.ndarray | None:
    """Per view, the (8, 8) matrix that turns its corners' separately whitened residuals into ones whitened
    with the view's joint covariance (four corners of a view, in order; x and y per corner).

    The joint covariance: each corner's own part (its covariance, whose camera variance factor ``s_i`` the
    residuals estimate, less ``s_i c_i c_i^T``, at least zero) and ``c c^T`` over the view's eight coordinates. In the
    separately whitened coordinates (``u_i = L_i^T c_i``) it is ``I - blockdiag(o_i u_i u_i^T) + u u^T``, with
    ``o_i = min(s_i, 0.95 / |u_i|^2)`` so that a corner's own part keeps 5 % of its variance along ``u_i``.
    Its inverse symmetric square root keeps each corner's rows mostly its own (the robust weights stay per
    corner). A fit weighted by it takes a common shift of the four corners for what it is, an error of the
    view, rather than for four independent errors that the pose should follow.

    Parameters
    ----------
    sqrt_info : (N, 2, 2) ``L`` of each corner. common_px : (N, 2) each corner's common move, px, for one
        sigma (zeros: none). own_scale : (N,) each corner's camera variance factor (None: 1).

    Returns
    -------
    (V, 8, 8) or None : the identity for a view without a common move; None if no view has one.
    """
    n = sqrt_info.shape[0]
    if not np.any(common_px) or n % 4:
        return None
    s = np.ones(n) if own_scale is None else np.asarray(own_scale, dtype=float)
    u = np.einsum("nji,nj->ni", sqrt_info, common_px)  # (N, 2)
    uu = np.sum(u**2, axis=1)
    own = np.minimum(s, 0.95 / np.maximum(uu, 1e-300))
    V = n // 4
    S = np.broadcast_to(np.eye(8), (V, 8, 8)).copy()
    blocks = -(own[:, None, None] * u[:, :, None] * u[:, None, :])  # (N, 2, 2)
    for k in range(4):
        S[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] += blocks[k::4]
    uv = u.reshape(V, 8)
    S += uv[:, :, None] * uv[:, None, :]
    w, Q = np.linalg.eigh(S)
    return np.matmul(Q / np.sqrt(w)[:, None, :], np.swapaxes(Q, 1, 2))
