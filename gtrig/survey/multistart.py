"""Convergence checks by multi-start: many initial guesses, solved at once, clustered into minima.

The seeds (AD2.3, "Determination of the coordinates of the world-points" and "Collection of the validation
data") checked by hand that initial guesses within about 0.5 m converge to one solution. Here this is
automatic: a vectorised Levenberg-Marquardt runs from every start at once, converged starts are clustered
into distinct minima, and the *basin radius* is the largest ring of starts around the chosen solution
that all converge to it. A second minimum whose chi-square is close to the best one (mirror solutions,
near-collinear references) is reported, never silently discarded.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: Batched residual: starts (S, n) -> whitened residuals (S, m) and Jacobian (S, m, n).
BatchedModel = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def batched_lm(
    model: BatchedModel,
    X0: np.ndarray,
    iterations: int = 60,
    angle_index: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt from every row of ``X0`` (S, n) at once.

    Returns the final states (S, n) and their costs ``sum(r**2)`` (S,) (chi-square when the residuals
    are whitened). ``angle_index`` names a state component wrapped to [-pi, pi) after each step.
    """
    X = np.array(X0, dtype=float, copy=True)
    r, J = model(X)
    cost = np.einsum("sm,sm->s", r, r)
    lam = np.full(X.shape[0], 1e-3)
    n = X.shape[1]
    eye = np.eye(n)
    for _ in range(iterations):
        Jt = np.swapaxes(J, 1, 2)
        JtJ = Jt @ J
        g = (Jt @ r[..., None])[..., 0]
        diag = np.einsum("sii->si", JtJ)
        A = JtJ + lam[:, None, None] * (eye * (diag[:, None, :] + 1e-12))
        try:
            step = -np.linalg.solve(A, g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = -np.stack([np.linalg.lstsq(a, b, rcond=None)[0] for a, b in zip(A, g, strict=True)])
        Xn = X + step
        if angle_index is not None:
            Xn[:, angle_index] = (Xn[:, angle_index] + np.pi) % (2 * np.pi) - np.pi
        rn, Jn = model(Xn)
        cn = np.einsum("sm,sm->s", rn, rn)
        ok = np.isfinite(cn) & (cn < cost)
        X[ok], r[ok], J[ok], cost[ok] = Xn[ok], rn[ok], Jn[ok], cn[ok]
        lam = np.where(ok, lam * 0.3, lam * 10.0)
        lam = np.clip(lam, 1e-9, 1e9)
        done = (np.abs(step).max(axis=1) < 1e-9 * (1.0 + np.abs(X).max(axis=1))) | (lam >= 1e8)
        if np.all(done):
            break
    return X, cost


@dataclass(frozen=True)
class Minimum:
    """One distinct minimum: state (n,), chi-square, and how many starts reached it."""

    x: np.ndarray
    chi2: float
    n_starts: int


@dataclass(frozen=True)
class Basin:
    """Outcome of a multi-start.

    Attributes
    ----------
    n_starts : starts tried.
    n_to_best : starts that reached the chosen solution.
    radius_m : largest ring radius (metres) all of whose starts, and all smaller rings', reached the
        chosen solution (for poses the heading of the ring starts is also off by ``radius_m`` rad per m);
        0 when even the smallest ring failed; the largest tried ring when all succeeded.
    alternatives : the other minima, best first.
    ambiguous : a second minimum is within ``ambiguity_chi2`` of the best one.
    """

    n_starts: int
    n_to_best: int
    radius_m: float
    alternatives: tuple[Minimum, ...]
    ambiguous: bool

    def describe(self) -> str:
        s = f"{self.n_to_best}/{self.n_starts} starts converge here, basin radius >= {self.radius_m:g} m"
        if self.alternatives:
            a = self.alternatives[0]
            s += f"; {len(self.alternatives)} other minimum(a), best chi2 {a.chi2:.3g} at " + ", ".join(
                f"{v:.4f}" for v in a.x
            )
        return s


def cluster(X: np.ndarray, cost: np.ndarray, tol: float, angle_index: int | None = None) -> list[Minimum]:
    """Group final states closer than ``tol`` (metres; radians for the angle) into minima, best first."""
    ok = np.isfinite(cost)
    X, cost = X[ok], cost[ok]
    left = np.argsort(cost)
    out: list[Minimum] = []
    while left.size:
        i = left[0]
        d = X[left] - X[i]
        if angle_index is not None:
            d[:, angle_index] = (d[:, angle_index] + np.pi) % (2 * np.pi) - np.pi
        near = np.max(np.abs(d), axis=1) < tol
        out.append(Minimum(X[i].copy(), float(cost[i]), int(near.sum())))
        left = left[~near]
    return out


def ring_starts(
    x_best: np.ndarray, radii: tuple[float, ...], n_angles: int = 12, angle_index: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Starts on rings around ``x_best`` (position offsets of the given radii; for a pose the heading is
    alternately offset by +radius and -radius rad). Returns starts (S, n) and their ring radius (S,)."""
    starts, rad = [], []
    for r in radii:
        for k in range(n_angles):
            a = 2 * np.pi * k / n_angles
            x = x_best.copy()
            x[0] += r * np.cos(a)
            x[1] += r * np.sin(a)
            if angle_index is not None:
                x[angle_index] += r * (1 if k % 2 == 0 else -1)
            starts.append(x)
            rad.append(r)
    return np.array(starts), np.array(rad)


def analyse(
    model: BatchedModel,
    x_best: np.ndarray,
    extra_starts: np.ndarray,
    radii: tuple[float, ...] = (0.1, 0.25, 0.5, 1.0, 2.0),
    tol: float = 1e-3,
    ambiguity_chi2: float = 16.0,
    angle_index: int | None = None,
) -> Basin:
    """Multi-start around ``x_best`` (rings) plus ``extra_starts`` (S, n); cluster and report.

    ``model`` gives residuals divided by their standard deviations (the correlations between readings
    are left out of the exploration; the chosen minimum is refined with them by the caller).

    A minimum other than the best is *ambiguous* when its chi-square exceeds the best by less than
    ``ambiguity_chi2`` (16 = a likelihood ratio of about 3000:1 for Gaussian readings).
    """
    # the minimum of the exploration metric next to the caller's solution
    xb, cb = batched_lm(model, x_best[None], angle_index=angle_index)
    x_best, chi2_best = xb[0], float(cb[0])
    ring, rad = ring_starts(x_best, radii, angle_index=angle_index)
    starts = np.vstack([ring, extra_starts.reshape(-1, x_best.size)]) if extra_starts.size else ring
    X, cost = batched_lm(model, starts, angle_index=angle_index)
    d = X - x_best
    if angle_index is not None:
        d[:, angle_index] = (d[:, angle_index] + np.pi) % (2 * np.pi) - np.pi
    to_best = np.max(np.abs(d), axis=1) < tol
    radius = 0.0
    for ring_r in radii:
        if np.all(to_best[: ring.shape[0]][rad <= ring_r]):
            radius = ring_r
        else:
            break
    # a start that stopped on a slope (gradient not ~0) did not find a minimum: leave it out
    res, J = model(X)
    grad = np.linalg.norm((np.swapaxes(J, 1, 2) @ res[..., None])[..., 0], axis=1)
    stationary = np.isfinite(cost) & (grad < 1e-4 * (1.0 + np.sqrt(cost)))
    keep = ~to_best & stationary
    others = cluster(X[keep], cost[keep], tol, angle_index)
    ambiguous = any(m.chi2 - chi2_best < ambiguity_chi2 for m in others)
    return Basin(
        n_starts=int(X.shape[0]),
        n_to_best=int(to_best.sum()),
        radius_m=float(radius),
        alternatives=tuple(others),
        ambiguous=bool(ambiguous),
    )
