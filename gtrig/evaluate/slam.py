"""One SLAM (or localization) result scored against a ground truth: pairing, alignment, evo's and the
RAWSEEDS toolkit's metrics side by side, and the GT-aware scores.

Pipeline of :func:`evaluate_slam`: (optional) time offset -> association by stamp (nearest, evo's, or
interpolated) -> alignment over the paired poses (or an interval of them) -> evo APE / RPE -> RAWSEEDS ATE /
RPE (their own interpolation and 2-D alignment, get_ATE.m's) -> GT-aware scores and the lever-arm check.
Each part is a small module of this package; this one only wires them and lays out the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.errors import InputError
from gtrig.evaluate import gt_aware as ga
from gtrig.evaluate import metrics_evo, metrics_rawseeds
from gtrig.evaluate.align import AlignKind, Alignment, apply_alignment, fit_alignment
from gtrig.evaluate.associate import Association, AssociationChoice, associate
from gtrig.evaluate.time_offset import TimeOffset, estimate_time_offset
from gtrig.trajectory import PoseTrack

MetricSet = Literal["rawseeds", "evo", "all"]


@dataclass(frozen=True)
class Row:
    """One printed figure: ``family`` (evo, rawseeds, gt-aware, pairing), ``metric``, ``statistic``,
    ``value`` with ``unit``."""

    family: str
    metric: str
    statistic: str
    value: float
    unit: str = ""


@dataclass(frozen=True)
class SlamEvaluation:
    """Everything :func:`evaluate_slam` measured (None where a part did not run)."""

    association: Association
    alignment: Alignment
    est_aligned: PoseTrack
    ape: dict[str, metrics_evo.ErrorSeries] | None
    rpe: dict[str, metrics_evo.ErrorSeries] | None
    rawseeds_ate: metrics_rawseeds.RawseedsATE | None
    rawseeds_rpe: metrics_rawseeds.RawseedsRPE | None
    gt_aware: ga.GTAwareScores | None
    lever_arm: ga.LeverArm | None
    time_offset: TimeOffset | None
    n_gt_unusable: int = 0
    warnings: tuple[str, ...] = field(default_factory=tuple)

    def rows(self) -> list[Row]:
        """The figures as rows (evo's statistics, RAWSEEDS' ATE / RPE, GT-aware intervals, pairing counts)."""
        out: list[Row] = []
        for k, v in self.association.summary().items():
            if not isinstance(v, str):
                out.append(Row("pairing", self.association.method, k, float(v)))
        out.append(Row("pairing", "alignment " + self.alignment.kind, "scale", self.alignment.scale))
        out.append(Row("pairing", "alignment " + self.alignment.kind, "yaw", self.alignment.yaw_rad, "rad"))
        if self.time_offset is not None:
            to = self.time_offset
            out += [Row("pairing", "time offset", "value", to.offset_s, "s"),
                    Row("pairing", "time offset", "95% low", to.low_s, "s"),
                    Row("pairing", "time offset", "95% high", to.high_s, "s")]
        for fam, series in (("evo", self.ape), ("evo", self.rpe)):
            if series is None:
                continue
            for s in series.values():
                for k, v in s.stats().items():
                    out.append(Row(fam, s.name, k, v, s.unit))
        if self.rawseeds_ate is not None:
            a = self.rawseeds_ate
            for lab, v in zip(("mean", "std", "mean-3std", "mean+3std"), a.ate, strict=True):
                out.append(Row("rawseeds", "ATE", lab, v, "m"))
            for lab, v in zip(("mean", "std", "mean-3std", "mean+3std"), a.heading, strict=True):
                out.append(Row("rawseeds", "ATE heading", lab, v, "rad"))
            out.append(Row("rawseeds", "ATE", "rmse", a.rmse_m, "m"))
            out.append(Row("rawseeds", "ATE", "samples", float(len(a.dist_m))))
        if self.rawseeds_rpe is not None:
            r = self.rawseeds_rpe
            out += [Row("rawseeds", "T-RPE", "value", r.t_rpe_m, "m"), Row("rawseeds", "R-RPE", "value",
                                                                            r.r_rpe_deg, "deg"),
                    Row("rawseeds", "RPE", "relations used", float(len(r.t_i))),
                    Row("rawseeds", "RPE", "relations", float(r.n_relations))]
        g = self.gt_aware
        if g is not None:
            out += [Row("gt-aware", "poses scored", "n", float(g.n)),
                    Row("gt-aware", "share resolved", "value", g.share_resolved),
                    Row("gt-aware", "share resolved", "if perfect", 0.95),
                    Row("gt-aware", "mean d2 per dof", "value", g.mean_d2_per_dof),
                    Row("gt-aware", "GT sigma trans", "rms", g.gt_sigma_trans_m, "m")]
            for lab, iv, unit in (("RMSE trans vs truth", g.rmse_trans_m, "m"),
                                  ("RMSE rot vs truth", g.rmse_rot_rad, "rad")):
                if iv is not None:
                    out += [Row("gt-aware", lab, "value", iv.value, unit),
                            Row("gt-aware", lab, "95% low", iv.low, unit),
                            Row("gt-aware", lab, "95% high", iv.high, unit)]
            for ax, iv in g.bias.items():
                unit = "m" if ax in ("x", "y", "z") else "rad"
                out += [Row("gt-aware", f"bias {ax}", "value", iv.value, unit),
                        Row("gt-aware", f"bias {ax}", "95% low", iv.low, unit),
                        Row("gt-aware", f"bias {ax}", "95% high", iv.high, unit)]
            out.append(Row("gt-aware", "indistinguishable from GT", "verdict", float(g.indistinguishable)))
        if self.lever_arm is not None:
            la = self.lever_arm
            out += [Row("gt-aware", "lever arm", "x", float(la.xy_m[0]), "m"),
                    Row("gt-aware", "lever arm", "y", float(la.xy_m[1]), "m"),
                    Row("gt-aware", "lever arm", "resolved", float(la.resolved))]
        return out


def _usable(track: PoseTrack) -> tuple[PoseTrack, int]:
    ok = track.ok
    if bool(np.all(ok)):
        return track, 0  # select() would copy 10^6 poses for nothing
    u = track.select(ok)
    return u, len(track) - len(u)


def _se3_arrays(t: PoseTrack) -> tuple[np.ndarray, np.ndarray]:
    return t.quat_xyzw, t.xyz


def evaluate_slam(gt: PoseTrack, est: PoseTrack, *, metrics: MetricSet = "all", align: AlignKind = "se3",
                  align_interval_s: tuple[float, float] | None = None, method: AssociationChoice = "auto",
                  max_dt_s: float | None = None, t_offset_s: float | Literal["auto"] = 0.0,
                  relations: np.ndarray | None = None, rpe_delta: int = 1) -> SlamEvaluation:
    """Score ``est`` against ``gt`` (module docstring).

    Parameters
    ----------
    gt : the ground truth; only its usable poses (OK, FLAGGED) are scored.
    est : the estimate, in its own world frame and clock.
    metrics : which families: ``rawseeds``, ``evo`` or ``all``.
    align : the alignment family (gtrig.evaluate.align); the RAWSEEDS ATE uses the toolkit's 2-D alignment
        (with scale for ``sim3`` / ``sim2``), none for ``none``.
    align_interval_s : fit the alignment on the GT stamps in ``[t0, t1]`` only.
    method, max_dt_s : the association (gtrig.evaluate.associate): ``auto`` interpolates the denser track at
        the other one's stamps; ``max_dt_s`` ``None`` sizes the tolerance from the sample periods.
    t_offset_s : added to the estimate's stamps, or ``"auto"`` to estimate it (gtrig.evaluate.time_offset).
    relations : (m, 5) ``t_i, t_j, dx, dy, dyaw`` for the RAWSEEDS RPE.
    rpe_delta : evo's RPE step, in paired poses.
    """
    if metrics not in ("rawseeds", "evo", "all"):
        raise InputError(f"--metrics must be rawseeds, evo or all, got {metrics!r}")
    g, n_bad = _usable(gt)
    if not len(g):
        raise InputError(f"the GT has no usable pose ({gt.counts()})")
    warnings: list[str] = []
    to: TimeOffset | None = None
    if t_offset_s == "auto":
        to = estimate_time_offset(g, est, "se3" if align == "none" else align)
        offset = to.offset_s
    else:
        offset = float(t_offset_s)
    assoc = associate(g, est, method, max_dt_s, offset)
    mask = None
    if align_interval_s is not None:
        mask = (assoc.gt.stamps_s >= align_interval_s[0]) & (assoc.gt.stamps_s <= align_interval_s[1])
        if not np.any(mask):
            raise InputError(f"no paired pose in the alignment interval {align_interval_s[0]:g},"
                             f"{align_interval_s[1]:g} s")
    al = fit_alignment(assoc.gt.xyz, assoc.est.xyz, align, mask)
    ea = apply_alignment(assoc.est, al)
    check_quaternion_order(assoc.gt, assoc.est, al.R)
    ape_s = rpe_s = None
    if metrics in ("evo", "all"):
        Rg, tg = _se3_arrays(assoc.gt)
        Re, te = _se3_arrays(ea)
        ape_s = metrics_evo.ape(assoc.gt.stamps_s, Rg, tg, Re, te)
        rpe_s = metrics_evo.rpe(assoc.gt.stamps_s, Rg, tg, Re, te, rpe_delta) if len(ea) > rpe_delta else None
    r_ate = r_rpe = None
    if metrics in ("rawseeds", "all"):
        e_on = est.shifted(offset)
        r_ate = metrics_rawseeds.ate(g.stamps_s, g.xytheta(), e_on.stamps_s, e_on.xytheta(),
                                     unknown_scale=align in ("sim3", "sim2"), align_interval_s=align_interval_s,
                                     align=align != "none")
        if relations is not None:
            check_relations(relations, g, e_on)
            r_rpe = metrics_rawseeds.rpe(e_on.stamps_s, e_on.xytheta(), relations)
    scores = ga.score(assoc.gt, ea)
    lever = ga.lever_arm(assoc.gt, ea)
    if lever is not None and lever.resolved:
        warnings.append(f"the error turns with the heading: a lever arm of ({lever.xy_m[0]:+.3f}, "
                        f"{lever.xy_m[1]:+.3f}) m (+-{lever.sigma_m[0]:.3f}, {lever.sigma_m[1]:.3f}) between the "
                        "estimate's frame and the GT's robot frame explains "
                        f"{100 * lever.explained:.0f} % of the error variance")
    if assoc.n_anchor_in_gaps > 0.5 * assoc.n_anchor and assoc.method == "nearest":
        side = "GT" if assoc.anchor == "gt" else "estimate"
        warnings.append(f"{assoc.n_anchor_in_gaps} of {assoc.n_anchor} {side} poses have no partner within "
                        f"{assoc.max_dt_s:g} s")
    return SlamEvaluation(assoc, al, ea, ape_s, rpe_s, r_ate, r_rpe, scores, lever, to, n_bad, tuple(warnings))


def check_relations(relations: np.ndarray, gt: PoseTrack, est: PoseTrack) -> None:
    """InputError when the relations' stamps fall outside both trajectories."""
    ts = np.concatenate([relations[:, 0], relations[:, 1]])
    in_gt = (ts >= gt.stamps_s[0]) & (ts <= gt.stamps_s[-1])
    in_est = (ts >= est.stamps_s[0]) & (ts <= est.stamps_s[-1])
    if not np.any(in_gt | in_est):
        raise InputError(f"the relations' stamps ({np.min(ts):.3f}..{np.max(ts):.3f} s) fall outside both the GT "
                         f"({gt.stamps_s[0]:.3f}..{gt.stamps_s[-1]:.3f} s) and the estimate "
                         f"({est.stamps_s[0]:.3f}..{est.stamps_s[-1]:.3f} s)")


#: a rotation error (rad, RMS) that a quaternion read in the wrong order makes likely, and the factor by
#: which the other order must do better to say so
_ORDER_SUSPECT_RAD = 0.3
_ORDER_FACTOR = 4.0


def _rms_angle(q_gt_xyzw: np.ndarray, q_est_xyzw: np.ndarray, R_align: np.ndarray) -> float:
    """RMS angle (rad) of ``R_gt_i^-1 R_align R_est_i`` over the pairs: evo's APE rot after alignment."""
    rg = Rotation.from_quat(q_gt_xyzw)
    re = Rotation.from_matrix(R_align) * Rotation.from_quat(q_est_xyzw)
    return float(np.sqrt(np.mean(np.asarray((rg.inv() * re).magnitude()) ** 2)))


def _w_first(q_xyzw: np.ndarray) -> np.ndarray:
    """The quaternions a file written ``qw qx qy qz`` holds, when it was read as ``qx qy qz qw``."""
    return np.roll(q_xyzw, -1, axis=1)


def check_quaternion_order(gt: PoseTrack, est: PoseTrack, R_align: np.ndarray) -> None:
    """InputError when one side's quaternions were evidently written w first (``qw qx qy qz``, as EuRoC and
    evo's own arrays) in a format that puts w last (TUM).

    ``gt`` and ``est`` are paired pose for pose, ``R_align`` (3, 3) the alignment's rotation (fitted on the
    positions alone, so the same for either reading). As read, the aligned rotations then differ by radians,
    and reading one side w first makes them agree to a quarter of that or better. An estimate in another body
    frame than the GT's differs by radians in both readings: it is not refused.
    """
    if len(gt) < 3:
        return
    as_read = _rms_angle(gt.quat_xyzw, est.quat_xyzw, R_align)
    if as_read < _ORDER_SUSPECT_RAD:
        return
    for side, other in (("estimate", _rms_angle(gt.quat_xyzw, _w_first(est.quat_xyzw), R_align)),
                        ("GT", _rms_angle(_w_first(gt.quat_xyzw), est.quat_xyzw, R_align))):
        if other * _ORDER_FACTOR < as_read:
            raise InputError(f"the {side}'s quaternions look written w first (qw qx qy qz): the aligned "
                             f"rotations differ by {as_read:.2f} rad (RMS) read as qx qy qz qw (TUM's order) and "
                             f"by {other:.3f} rad read w first; rewrite the file as qx qy qz qw")
