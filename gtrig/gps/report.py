"""The GPS report: time share of each fix type, satellites and HDOP over time, lost-fix intervals,
what became of every line, the clock offset. A plain dict (JSON), for ``gtrig gps --report`` and for
``gtrig report``.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from gtrig.gps.covariance import COV_SOURCE_NAMES
from gtrig.gps.epochs import FIX_NAMES
from gtrig.gps.groundtruth import GpsResult


def epoch_durations(utc_s: np.ndarray) -> tuple[np.ndarray, float]:
    """(N,) seconds each epoch stands for (to the next one, at most 1.5 nominal periods) and the
    nominal period (the median step)."""
    if utc_s.size < 2:
        return np.ones(utc_s.size), 1.0
    step = np.diff(utc_s)
    period = float(np.median(step))
    d = np.minimum(np.concatenate([step, [period]]), 1.5 * period)
    return d, period


def fix_shares(utc_s: np.ndarray, quality: np.ndarray, t_begin: float, t_end: float) -> dict[str, float]:
    """Share of the time span [t_begin, t_end] under each fix type, and ``no_fix`` for the rest
    (quality-0 epochs, silent receiver)."""
    d, _ = epoch_durations(utc_s)
    span = max(t_end - t_begin, float(d.sum()), 1e-9)
    out = {FIX_NAMES.get(int(q), str(int(q))): float(d[quality == q].sum() / span) for q in np.unique(quality)}
    out["no_fix"] = max(0.0, 1.0 - sum(out.values()))
    return out


def lost_intervals(t_all: np.ndarray, t_kept: np.ndarray, min_s: float = 1.0) -> list[tuple[float, float]]:
    """Intervals (start, end) longer than ``min_s`` without a kept fix inside the recorded span."""
    if t_kept.size == 0:
        return [(float(t_all[0]), float(t_all[-1]))] if t_all.size else []
    edges = np.concatenate([[t_all[0]], t_kept, [t_all[-1]]])
    gaps = np.diff(edges)
    i = np.flatnonzero(gaps > min_s)
    return [(float(edges[k]), float(edges[k + 1])) for k in i]


def coverage_data(res: GpsResult, ellipse_every: int = 50) -> dict[str, Any]:
    """What the coverage map draws: every epoch's horizontal position in the output frame (m, to the
    millimetre), its GGA quality and whether it was kept, and ``[x, y, cov_xx, cov_xy, cov_yy]``
    (m, m^2) of every ``ellipse_every``-th kept fix."""
    xy = res.all_epochs.xyz[:, :2]
    kept = res.track
    every = max(1, int(ellipse_every))
    ell = ([[round(float(v), 9) for v in (p[0], p[1], c[0, 0], c[0, 1], c[1, 1])]
            for p, c in zip(kept.xyz[::every], kept.cov[::every], strict=True)] if kept.cov is not None else [])
    return {"frame": res.frame, "x_m": np.round(xy[:, 0], 3).tolist(), "y_m": np.round(xy[:, 1], 3).tolist(),
            "quality": res.epochs.quality.astype(int).tolist(), "kept": res.all_epochs.ok.astype(int).tolist(),
            "ellipse_every": every, "ellipses": ell}


def gps_report(res: GpsResult, log_span_utc: tuple[float, float] | None = None,
               ellipse_every: int = 50) -> dict[str, Any]:
    """The report of one run (module docstring); every count adds up to the lines of the log. Its
    ``series_1hz`` and ``coverage`` are what the figures draw (:mod:`gtrig.gps.plots`)."""
    ep = res.epochs
    t0, t1 = log_span_utc or (float(ep.utc_s[0]), float(ep.utc_s[-1]))
    _, period = epoch_durations(ep.utc_s)
    kept = res.all_epochs.ok
    lost = lost_intervals(res.all_epochs.stamps_s, res.track.stamps_s, min_s=max(1.0, 3 * period))
    durations = [b - a for a, b in lost]
    reasons = Counter(r for r, k in zip(res.all_epochs.reasons, kept, strict=True) if not k)
    rep: dict[str, Any] = {
        "log_format": res.log_format,
        "frame": res.frame,
        "origin": {"lat_deg": res.origin.lat_deg, "lon_deg": res.origin.lon_deg, "h_m": res.origin.h_m},
        "clock": res.clock,
        "epochs": len(ep),
        "rate_hz": 1.0 / period if period > 0 else None,
        "kept": int(kept.sum()),
        "flagged_hdop_covariance": int(np.sum(res.track.status == 1)),
        "refused": dict(reasons),
        "fix_share_time": fix_shares(ep.utc_s, ep.quality, t0, t1),
        "kept_share_time": float(epoch_durations(ep.utc_s)[0][kept].sum() / max(t1 - t0, 1e-9)),
        "lost_fix_intervals": {"count": len(lost), "total_s": float(sum(durations)),
                               "longest_s": float(max(durations, default=0.0)),
                               "intervals": [[a, b] for a, b in lost],
                               "t0_s": float(res.all_epochs.stamps_s[0])},
        "satellites": {"median": float(np.nanmedian(ep.n_sat)) if len(ep) else None,
                       "min": float(np.nanmin(ep.n_sat)) if len(ep) else None},
        "hdop": {"median": float(np.nanmedian(ep.hdop)) if np.any(np.isfinite(ep.hdop)) else None,
                 "p95": float(np.nanpercentile(ep.hdop, 95)) if np.any(np.isfinite(ep.hdop)) else None},
        "sigma_kept_m": {"median_horizontal": float(np.median(np.sqrt(res.track.cov[:, 0, 0] + res.track.cov[:, 1, 1])))
                         if len(res.track) and res.track.cov is not None else None},
        "covariance_source": {n: int(np.sum(ep.cov_source == i)) for i, n in enumerate(COV_SOURCE_NAMES)},
        "clock_offset_log_minus_utc_s": res.clock_offset_s,
        "not_epochs": dict(ep.dropped),
    }
    # satellites, HDOP and fix type over time, one sample a second (a figure or `gtrig report` draws them)
    step = max(1, int(round(1.0 / period))) if period > 0 else 1
    rep["series_1hz"] = {"t_s": np.round(ep.utc_s[::step] - ep.utc_s[0], 3).tolist(),
                         "n_sat": np.nan_to_num(ep.n_sat[::step], nan=-1).astype(int).tolist(),
                         "hdop": [None if not np.isfinite(v) else float(v) for v in ep.hdop[::step]],
                         "quality": ep.quality[::step].astype(int).tolist()}
    rep["coverage"] = coverage_data(res, ellipse_every)
    if res.account is not None:
        a = res.account
        rep["lines"] = {"total": a.n_lines, "decoded": a.decoded, "ignored": a.ignored, "blank": a.blank,
                        "malformed": a.malformed, "malformed_lines": [list(x) for x in a.malformed_lines],
                        "checksums": a.checksums}
    return rep


def report_lines(rep: dict[str, Any]) -> list[str]:
    """A few lines for the console."""
    shares = ", ".join(f"{k} {v:.1%}" for k, v in sorted(rep["fix_share_time"].items(), key=lambda kv: -kv[1]))
    lost = rep["lost_fix_intervals"]
    out = [f"{rep['epochs']} epochs at {rep['rate_hz']:.1f} Hz; kept {rep['kept']} "
           f"({rep['kept_share_time']:.1%} of the time)",
           f"fix types over time: {shares}",
           f"lost-fix intervals: {lost['count']} ({lost['total_s']:.0f} s, longest {lost['longest_s']:.0f} s)"]
    if rep["refused"]:
        out.append("refused: " + "; ".join(f"{v} {k}" for k, v in rep["refused"].items()))
    if "lines" in rep:
        ln = rep["lines"]
        out.append(f"lines: {ln['total']} = {sum(ln['decoded'].values())} decoded + {ln['ignored']} ignored + "
                   f"{ln['blank']} blank + {sum(ln['malformed'].values())} malformed; checksums {ln['checksums']}")
    off = rep["clock_offset_log_minus_utc_s"]
    if off:
        out.append(f"log clock - UTC: {off['median']:.3f} s (min {off['min']:.3f}, max {off['max']:.3f}, "
                   f"drift {off['drift'] * 1e6:.0f} ppm)")
    return out


def report_markdown(rep: dict[str, Any], figures: list[str] | None = None) -> str:
    """The report as a Markdown summary (``gtrig report`` shows every stage's ``*.md`` in a results folder)."""
    out = ["# RTK-GPS ground truth", ""]
    out += [f"- {line}" for line in report_lines(rep)]
    out += ["", "| fix type | share of the time |", "|---|---|"]
    out += [f"| {k} | {v:.1%} |" for k, v in sorted(rep["fix_share_time"].items(), key=lambda kv: -kv[1])]
    lost = rep["lost_fix_intervals"]["intervals"]
    t0 = rep["lost_fix_intervals"]["t0_s"]
    if lost:
        out += ["", "| lost-fix interval | start (s from the first epoch) | end (s) | length (s) |",
                "|---|---|---|---|"]
        out += [f"| {i + 1} | {a - t0:.1f} | {b - t0:.1f} | {b - a:.1f} |" for i, (a, b) in enumerate(lost)]
    if "smoothed" in rep:
        s = rep["smoothed"]
        out += ["", f"Smoothed with odometry: {s['poses']} poses, {s['ok']} observed, {s['bridged']} bridged, "
                f"{s['heading_not_observable']} with the heading not observable."]
    for f in figures or []:
        out += ["", f"![{Path(f).stem}]({f})"]
    return "\n".join(out) + "\n"
