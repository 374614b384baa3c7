"""The range bias of each side of the hull's fabric, estimated over a whole sequence.

A time-of-flight scanner ranges a dark fabric long and a light one short (weaker pulses cross the
detection threshold later): a few millimetres between black and white on matt cloth, centimetres on
very dark or glossy cloth. The bias belongs to the side, not to the frame, so the smoother cannot
average it out. It is not a shift of the side either: a point moves *along its beam*, so its offset
from the side is ``beta cos(i)``, which changes along a side seen at a slant (a rotation of the
apparent side) and with the robot's pose (a pose error that wanders slowly as the robot drives).

Over a sequence the robot shows each side to several scanners at many incidences, and the hull's
outline is known, so the four biases are well determined: each frame's normal equations in
``(pose, beta)`` (:func:`gtrig.laser.hull_icp.side_bias_normal_equations`) are reduced to ``beta`` by
eliminating the frame's pose (Schur complement), summed over the frames, and solved with a prior
(the fabric's expected bias). A hull outline measured a few millimetres too large or small is
absorbed the same way (a side "ranged short" by the error).

The frames' errors are not independent (the laser plane cutting a tilted gown, the scanners'
calibration and clocks persist over many frames), so the formal information of a sum over thousands
of frames overstates what is known. The sequence is cut into blocks of consecutive frames; the
scatter of the blocks' own estimates about the whole's, against their formal covariances, is a
variance factor (Koch, *Parameter Estimation and Hypothesis Testing in Linear Models*, 3.2.6) that
deflates the data's information when above 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SideBias:
    """Range bias of each hull side over a sequence.

    Attributes
    ----------
    bias_m : (4,) measured minus true range on each side (hull order), metres; positive: ranged long.
    cov : (4, 4) its covariance, m^2 (the prior's where the data say nothing).
    variance_factor : scatter of the blocks' estimates against their formal covariances (>= 0).
    n_frames : frames used.
    n_blocks : blocks the frames were cut into.
    scanner_pull : (4, 3 S) how the estimate moves with the scanners' calibrated planar poses (m / m,
        m / rad; scanner ``s`` owns columns ``3 s .. 3 s + 2``), :func:`scanner_pull`; None when not known.
    """

    bias_m: np.ndarray
    cov: np.ndarray
    variance_factor: float
    n_frames: int
    n_blocks: int
    scanner_pull: np.ndarray | None = None

    @staticmethod
    def prior(cov: np.ndarray) -> SideBias:
        """No data: a zero bias with the prior's covariance (4, 4)."""
        return SideBias(np.zeros(4), np.asarray(cov, dtype=float).copy(), 1.0, 0, 0)


def reduced_normal_equations(
    H_pp: np.ndarray, H_pb: np.ndarray, H_bb: np.ndarray, g_p: np.ndarray, g_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's normal equations in ``beta`` alone, its pose eliminated.

    Parameters
    ----------
    H_pp, H_pb, H_bb, g_p, g_b : (K, 3, 3), (K, 3, 4), (K, 4), (K, 3), (K, 4) as returned by
        :func:`gtrig.laser.hull_icp.side_bias_normal_equations`.

    Returns
    -------
    N : (K, 4, 4) ``H_bb - H_pb^T H_pp^-1 H_pb``.
    u : (K, 4) ``g_b - H_pb^T H_pp^-1 g_p``; the frame alone would give ``beta = -N^-1 u``.
    """
    a = np.linalg.solve(H_pp, H_pb)  # (K, 3, 4)
    b = np.linalg.solve(H_pp, g_p[..., None])[..., 0]  # (K, 3)
    N = H_bb[:, :, None] * np.eye(4) - np.einsum("kia,kib->kab", H_pb, a)
    u = g_b - np.einsum("kia,ki->ka", H_pb, b)
    return N, u


def estimate_side_bias(
    N: np.ndarray, u: np.ndarray, stamps_s: np.ndarray, prior_cov: np.ndarray, block_s: float = 1.0,
    max_blocks: int = 20,
) -> SideBias:
    """The side biases from the frames' reduced normal equations (:func:`reduced_normal_equations`).

    Parameters
    ----------
    N, u : (K, 4, 4), (K, 4) per frame.
    stamps_s : (K,) frame times, seconds (increasing): blocks are consecutive frames spanning at least
        ``block_s`` seconds, at most ``max_blocks`` of them.
    prior_cov : (4, 4) the expected bias's covariance, m^2 (zero mean).
    block_s, max_blocks : blocking of the variance factor; with fewer than 3 blocks the factor is 1.

    Returns
    -------
    SideBias
    """
    P0 = np.linalg.inv(np.asarray(prior_cov, dtype=float))
    K = len(stamps_s)
    if K == 0:
        return SideBias.prior(prior_cov)
    Ns, us = N.sum(axis=0), u.sum(axis=0)
    beta = -np.linalg.solve(Ns + P0, us)
    span = float(stamps_s[-1] - stamps_s[0])
    n_blocks = int(min(max_blocks, np.floor(span / block_s))) if block_s > 0 else 0
    s2 = 1.0
    if n_blocks >= 3:
        edges = np.searchsorted(stamps_s, np.linspace(stamps_s[0], stamps_s[-1], n_blocks + 1)[1:-1])
        chi2, dof = 0.0, 0.0
        for idx in np.split(np.arange(K), edges):
            Nb, ub = N[idx].sum(axis=0), u[idx].sum(axis=0)
            d = -np.linalg.solve(Nb + P0, ub) - beta
            chi2 += float(d @ Nb @ d)
            # the parameters the block determines (its resolution: ~4 when it saw every side)
            dof += float(np.trace(np.linalg.solve(Nb + P0, Nb)))
        dof *= (n_blocks - 1) / n_blocks
        s2 = chi2 / dof if dof > 0 else 1.0
    cov = np.linalg.inv(Ns / max(1.0, s2) + P0)
    return SideBias(beta, 0.5 * (cov + cov.T), float(s2), K, max(n_blocks, 1))


def scanner_pull(N: np.ndarray, prior_cov: np.ndarray, du_dc: np.ndarray) -> np.ndarray:
    """(4, 3 S) how the estimate of :func:`estimate_side_bias` moves with the scanners' calibrated poses.

    A calibration error ``dc`` moves every frame's reduced right-hand side ``u`` by ``du_dc dc``
    (:func:`gtrig.laser.hull_icp.side_bias_scanner_pull`), so the estimate ``-(sum N + P0)^-1 sum u``
    moves by ``-(sum N + P0)^-1 (sum du_dc) dc``: the share of the calibration error the sides' biases
    take up, which the refitted poses then no longer carry.

    Parameters
    ----------
    N : (K, 4, 4) the frames' reduced normal matrices.
    prior_cov : (4, 4) the bias prior's covariance, m^2.
    du_dc : (4, 3 S) the frames' ``d u / d c`` summed.
    """
    P0 = np.linalg.inv(np.asarray(prior_cov, dtype=float))
    return -np.linalg.solve(N.sum(axis=0) + P0, du_dc)


__all__ = ["SideBias", "reduced_normal_equations", "estimate_side_bias", "scanner_pull"]
