"""Smoothing of pose sequences: a Rauch-Tung-Striebel smoother with a constant-velocity model.

Core (no stage imports it from another stage): GTlaser smooths each hull track with it (journal paper,
section 6), and fusion or any source that measures poses with a covariance may use it.
Vectorised where the recursion allows (the gains of the backward pass at once); about 10^5 poses/s.
"""

from __future__ import annotations

import math

import numpy as np


def white_noise_model(dt: np.ndarray, qd: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Transitions and process noises of x, y, theta each driven by white noise through ``order``
    integrators (2: constant velocity, 3: constant acceleration).

    Parameters
    ----------
    dt : (N,) time steps, seconds.
    qd : (N, 3) or (3,) spectral densities of the white noise of x, y, theta.
    order : 2 or 3.

    Returns
    -------
    F, Q : (N, 3 order, 3 order); the state is (pose, its first derivative, ...), three at a time.
    """
    dt = np.asarray(dt, dtype=float)
    N = dt.size
    qd = np.broadcast_to(np.asarray(qd, dtype=float), (N, 3))
    i = np.arange(order)
    p = i[None, :] - i[:, None]  # F_ij = dt^(j - i) / (j - i)!
    fact = np.array([math.factorial(max(int(k), 0)) for k in p.ravel()], dtype=np.float64).reshape(p.shape)
    Fn = np.where(p >= 0, dt[:, None, None] ** np.maximum(p, 0) / fact, 0.0)
    # Q_ij = q dt^(2n-1-i-j) / ((n-1-i)! (n-1-j)! (2n-1-i-j)) (integrated white noise)
    a = order - 1 - i
    e = a[:, None] + a[None, :] + 1
    den = np.array([[math.factorial(u) * math.factorial(v) for v in a] for u in a], dtype=float) * e
    Qn = dt[:, None, None] ** e / den
    F = np.einsum("kde,ab->kdaeb", Fn, np.eye(3)).reshape(N, 3 * order, 3 * order)
    Q = np.einsum("kde,ka,ab->kdaeb", Qn, qd, np.eye(3)).reshape(N, 3 * order, 3 * order)
    return F, Q


def rts_smooth(
    stamps_s: np.ndarray,
    z_xytheta: np.ndarray,
    R_z: np.ndarray,
    accel_std_mps2: float,
    ang_accel_std_radps2: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel smoothing of planar poses with a constant-velocity model.

    Parameters
    ----------
    stamps_s
        (n,) increasing times, seconds.
    z_xytheta
        (n, 3) measured poses (theta continuous, unwrapped); rows of ``nan`` are not measured.
    R_z
        (n, 3, 3) measurement covariances.
    accel_std_mps2, ang_accel_std_radps2
        Spectral densities (as standard deviations) of the white linear and angular acceleration.

    Returns
    -------
    xytheta : (n, 3) smoothed poses.
    cov_xytheta : (n, 3, 3) their covariances.
    """
    qd = np.array([accel_std_mps2**2, accel_std_mps2**2, ang_accel_std_radps2**2])
    return rts_smooth_varying(stamps_s, z_xytheta, R_z, np.broadcast_to(qd, (len(stamps_s), 3)))


#: frames per block of :func:`rts_smooth_varying`'s backward pass (its memory: a block's states, not a track's)
SMOOTH_BLOCK_FRAMES = 256


def rts_smooth_varying(
    stamps_s: np.ndarray, z_xytheta: np.ndarray, R_z: np.ndarray, qd: np.ndarray, order: int = 2
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rts_smooth` with a process noise that varies along the track, and of either order.

    Parameters
    ----------
    stamps_s, z_xytheta, R_z
        As :func:`rts_smooth`.
    qd
        (n, 3) spectral densities of the white noise driving x, y, theta over the interval ending at
        each frame: white acceleration for ``order`` 2 ((m/s^2)^2 s, (rad/s^2)^2 s), white jerk for
        ``order`` 3 ((m/s^3)^2 s, (rad/s^3)^2 s).
    order
        2: constant velocity (state pose, velocity); 3: constant acceleration (pose, velocity,
        acceleration), which follows a robot braking into a bend without the lag a constant-velocity
        model needs a loose process noise to avoid, so it can average over more frames.

    The forward filter keeps its state only at the start of each block of :data:`SMOOTH_BLOCK_FRAMES`
    frames; the backward pass runs it again over each block, from the last, from that state (the
    same operations, so the same bits): an hour-long track holds a block's predicted and filtered
    states, not ~4 kB per frame of them, for a second forward pass.
    """
    n = len(stamps_s)
    m = 3 * order
    dt = np.r_[0.0, np.diff(stamps_s)]
    qd = np.broadcast_to(np.asarray(qd, dtype=float), (n, 3))
    meas = np.isfinite(z_xytheta[:, 0])
    first = int(np.flatnonzero(meas)[0])
    x = np.zeros(m)
    x[:3] = z_xytheta[first]
    P = np.eye(m)
    P[:3, :3] = R_z[first]
    W = SMOOTH_BLOCK_FRAMES
    starts = list(range(0, n, W))

    def forward(k0: int, x: np.ndarray, P: np.ndarray, keep: bool
                ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
        """The filter over frames ``[k0, k0 + W)`` from the state before ``k0``: the state after, and
        with ``keep`` the block's transitions, predicted and filtered states."""
        k1 = min(n, k0 + W)
        F, Q = white_noise_model(dt[k0:k1], qd[k0:k1], order)
        kept: tuple[np.ndarray, ...] = (F, np.zeros((k1 - k0, m)), np.zeros((k1 - k0, m, m)), np.zeros((k1 - k0, m)),
                np.zeros((k1 - k0, m, m))) if keep else ()
        for i, k in enumerate(range(k0, k1)):
            if k > 0:
                Fk = F[i]
                x = Fk @ x
                P = Fk @ P @ Fk.T + Q[i]
            if keep:
                kept[1][i], kept[2][i] = x, P
            if meas[k]:
                Kg = P[:, :3] @ np.linalg.inv(P[:3, :3] + R_z[k])
                x = x + Kg @ (z_xytheta[k] - x[:3])
                P = P - Kg @ P[:3, :]
                P = 0.5 * (P + P.T)
            if keep:
                kept[3][i], kept[4][i] = x, P
        return x, P, kept

    checkpoints = []
    for k0 in starts:
        checkpoints.append((x, P))
        x, P, _ = forward(k0, x, P, False)
    xs_out = np.zeros((n, 3))
    Ps_out = np.zeros((n, 3, 3))
    nxt: tuple = ()  # the later block's first frame: transition, predicted state, smoothed state
    for b in range(len(starts) - 1, -1, -1):
        k0 = starts[b]
        _, _, (F, xp, Pp, xf, Pf) = forward(k0, *checkpoints[b], True)
        L = len(xf)
        if nxt:
            F1 = np.concatenate([F[1:], nxt[0][None]])
            xp1, Pp1 = np.concatenate([xp[1:], nxt[1][None]]), np.concatenate([Pp[1:], nxt[2][None]])
        else:
            F1, xp1, Pp1 = F[1:], xp[1:], Pp[1:]
        # smoother gains C_k = Pf_k F_{k+1}^T Pp_{k+1}^-1, a block at once
        C = Pf[:len(F1)] @ np.swapaxes(F1, 1, 2) @ np.linalg.inv(Pp1)
        xs, Ps = (nxt[3], nxt[4]) if nxt else (xf[L - 1], Pf[L - 1])
        if not nxt:
            xs_out[k0 + L - 1], Ps_out[k0 + L - 1] = xs[:3], Ps[:3, :3]
        for i in range(len(C) - 1, -1, -1):
            Ck = C[i]
            xs = xf[i] + Ck @ (xs - xp1[i])
            Ps = Pf[i] + Ck @ (Ps - Pp1[i]) @ Ck.T
            xs_out[k0 + i], Ps_out[k0 + i] = xs[:3], Ps[:3, :3]
        nxt = (F[0], xp[0], Pp[0], xs, Ps)
    return xs_out, Ps_out
