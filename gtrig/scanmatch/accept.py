"""The acceptance test: the seeds' manual inspection of every match, made a statistical test.

A low fitness can still be a wrong match (the seeds' own warning), so a match is accepted only when
every one of these holds:

1. ``explained``: the share of the current scan's points that land on a reference surface within
   ``inlier_sigma`` of their expected noise is at least ``min_explained`` (a wrong alignment leaves
   walls hanging in free space; a right one explains all but the unshared view and the people);
2. ``inlier_share``: of the points that found a reference point nearby, the share that are inliers is
   at least ``min_inlier_share`` (residuals concentrated at zero, not spread over the association
   radius, which is what a shifted match gives);
3. ``s_ratio``: the measured residual deviation over the expected one (both scans' range noise) is at
   most ``max_s_ratio`` (a residual-distribution test: a match off by a fraction of the noise widens
   the inliers' residuals);
4. ``sd``: the match is determinate: the covariance's smallest position deviation (its minor axis) is
   under ``max_sd_m`` and the heading's under ``max_sd_rad``. A match whose major axis is wider (a
   corridor is degenerate along its axis) is accepted as *degenerate* with that covariance, large along
   the axis, when ``degenerate == "report"`` (the default), refused when ``"refuse"``: what it says
   across the axis is as good as any match's, and its covariance says what it does not know;
5. ``guess``: the match agrees with the guess within their joint uncertainty: the squared Mahalanobis
   distance is under the chi-square(3) quantile ``guess_quantile``.

6. ``probe`` (in :func:`gtrig.scanmatch.validate.match_pair`): the match is unique: the local matcher
   restarted ``probe_m`` either side along the match's least determined direction finds no other pose
   explaining as many points (within ``probe_margin``). A corridor with a few doors fits well at
   several places along its axis, each with a small covariance; real scans showed it (CARMEN logs).
   With ``degenerate == "report"`` such a match is kept with its covariance widened to span the other
   solution (``cov + d d^T``, ``d`` the difference between the two), never with its own small one.

Every threshold is physical (noise multiples, the accuracy a GT relation must have); the verdicts are
measured against truth in docs/scanmatch.md, not assumed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.stats import chi2

from gtrig.scanmatch import se2
from gtrig.scanmatch.icp import IcpResult


@dataclass(frozen=True)
class AcceptParams:
    """Thresholds of the acceptance test (see the module docstring)."""

    min_explained: float = 0.45
    min_inlier_share: float = 0.6
    max_s_ratio: float = 1.6
    max_sd_m: float = 0.005
    max_sd_rad: float = float(np.radians(0.12))
    guess_quantile: float = 0.9999
    probe_m: float = 0.3
    probe_margin: float = 0.05
    degenerate: Literal["report", "refuse"] = "report"


DEFAULT_ACCEPT = AcceptParams()


@dataclass(frozen=True)
class Verdict:
    """The acceptance test's statistics and verdict for one match."""

    accepted: bool
    reason: str
    explained: float
    inlier_share: float
    s_ratio: float
    sd_max_m: float
    sd_theta_rad: float
    mahalanobis2: float
    #: accepted though wide along one direction (its covariance says how wide): a corridor's axis
    degenerate: bool = False

    @property
    def score(self) -> float:
        """A ranking of two verdicts on one pair (more explained points is better)."""
        return self.explained + (1.0 if self.accepted else 0.0)

    @staticmethod
    def reference() -> Verdict:
        return Verdict(True, "reference", 1.0, 1.0, 0.0, 0.0, 0.0, 0.0)


def judge(res: IcpResult, cov: np.ndarray, guess: np.ndarray, guess_cov: np.ndarray,
          p: AcceptParams = AcceptParams()) -> Verdict:
    """Apply the test to a match ``res`` with full covariance ``cov`` against its ``guess``."""
    n = max(1, res.n_points)
    explained = res.n_inliers / n
    share = res.n_inliers / max(1, res.n_matched)
    exp_sig = float(np.sqrt(np.nanmean(res.expected_sigma_m[res.inlier] ** 2))) if res.n_inliers else np.inf
    s_ratio = float(res.s_m / exp_sig) if res.n_inliers > 3 else np.inf
    if np.all(np.isfinite(cov)):
        ev = np.linalg.eigvalsh(cov[:2, :2])
        sd_min, sd_max = (float(np.sqrt(max(0.0, e))) for e in ev)
        sd_th = float(np.sqrt(max(0.0, cov[2, 2])))
    else:
        sd_min = sd_max = sd_th = np.inf
    d = se2.relative(guess, res.pose)
    S = np.asarray(guess_cov, dtype=float) + (cov if np.all(np.isfinite(cov)) else 0.0)
    try:
        m2 = float(d @ np.linalg.solve(S, d))
    except np.linalg.LinAlgError:
        m2 = np.inf
    fails = []
    if not res.converged:
        fails.append("not converged")
    if explained < p.min_explained:
        fails.append(f"explained {explained:.2f} < {p.min_explained:g}")
    if share < p.min_inlier_share:
        fails.append(f"inlier share {share:.2f} < {p.min_inlier_share:g}")
    if not s_ratio <= p.max_s_ratio:
        fails.append(f"residual spread {s_ratio:.2f} x expected > {p.max_s_ratio:g}")
    degenerate = bool(np.isfinite(sd_max) and sd_max > p.max_sd_m)
    if not sd_min <= p.max_sd_m or (degenerate and p.degenerate == "refuse"):
        worst = sd_max if p.degenerate == "refuse" else sd_min
        fails.append(f"position sd {worst * 1000:.1f} mm > {p.max_sd_m * 1000:g} mm (degenerate)")
    if not sd_th <= p.max_sd_rad:
        fails.append(f"heading sd {np.degrees(sd_th):.3f} deg > {np.degrees(p.max_sd_rad):.3f} deg")
    if not m2 <= chi2.ppf(p.guess_quantile, 3):
        fails.append(f"disagrees with the guess (Mahalanobis^2 {m2:.1f})")
    reason = "; ".join(fails)
    if not fails and degenerate:
        reason = f"degenerate: position sd {sd_max * 1000:.1f} mm along its major axis (reported, not refused)"
    return Verdict(not fails, reason, float(explained), float(share), s_ratio, sd_max, sd_th, m2,
                   degenerate=degenerate and not fails)
