"""Build the one-page HTML report of a results folder: everything inline (styles, images as base64 PNG, one
small script that checks the figures decoded), nothing fetched from the network.

Sections, each shown only when its files are present (the others are named as not in the folder, with why):
the run's checks (``summary.csv``, its misses and unmeasured figures as warnings), accuracy against truth
(``accuracy.csv`` and, with a truth folder, each track against it), the pose tracks (summary, path with
ellipses and flagged poses, errors with 3-sigma bounds against truth, status over time, NEES histogram), RTK-GPS
(``gtrig gps --report``'s JSON; shown only when present, as it is no pipeline stage's), the consistency of two
GT sources (without truth too), the fusion (``fusion_report.json``), GTvision's per-camera coverage, the fixed
scanners' coverage, the survey, the calibration (its summary and residuals), time sync (``sync.yaml`` and
correlation curves), and every stage's Markdown summary.
"""

from __future__ import annotations

import datetime as _dt
import html
import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from gtrig.errors import GtrigError
from gtrig.report.collect import ResultsInventory, inventory
from gtrig.report.section import Section, read_csv

log = logging.getLogger(__name__)

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0;color:#222;background:#fafafa}
header{background:#1f3a5f;color:#fff;padding:14px 24px}header h1{margin:0;font-size:22px}
header p{margin:4px 0 0;font-size:13px;opacity:.85}
nav{padding:8px 24px;background:#e8eef5;font-size:13px}nav a{margin-right:14px;color:#1f3a5f}
section{background:#fff;margin:14px 24px;padding:10px 18px;border:1px solid #ddd;border-radius:6px}
h2{font-size:18px;border-bottom:1px solid #eee;padding-bottom:4px}h3{font-size:15px}h4,h5,h6{font-size:14px}
table{border-collapse:collapse;font-size:12px;margin:8px 0}th,td{border:1px solid #ccc;padding:3px 7px;text-align:left}
th{background:#f0f3f7}td.n{text-align:right;white-space:nowrap}
.ok{color:#17803d;font-weight:600}.miss{color:#c0392b;font-weight:600}.note{color:#777;font-size:12px}
.warn{background:#fff5e0;border-left:4px solid #e6a700;padding:6px 10px 6px 26px;font-size:13px}
p.warn{padding-left:10px}li{margin:2px 0}
figure{margin:10px 0}figure img{width:100%;max-width:1300px;height:auto;border:1px solid #eee}
figcaption{font-size:13px;color:#444}
"""

CHECK_JS = """
window.addEventListener('load',function(){var imgs=document.querySelectorAll('figure img');var ok=0;var pct=100;
for(var i=0;i<imgs.length;i++){var im=imgs[i];if(im.complete&&im.naturalWidth>0){ok++;}
var sec=im.closest('section');var cs=getComputedStyle(sec);
var inner=sec.clientWidth-parseFloat(cs.paddingLeft)-parseFloat(cs.paddingRight);
pct=Math.min(pct,100*im.getBoundingClientRect().width/inner);}
document.body.setAttribute('data-figures-loaded',String(ok));
document.body.setAttribute('data-figure-min-width-pct',String(Math.round(pct)));
document.body.setAttribute('data-tables',String(document.querySelectorAll('table').length));
document.body.setAttribute('data-load-ms',String(Math.round(performance.now())));});
"""


# --- sections ----------------------------------------------------------------------------------------------

def _checks(inv: ResultsInventory) -> Section | None:
    from gtrig.report.checks import checks_section

    if inv.summary_csv is None:
        return None
    return checks_section(inv.summary_csv, "checks", "Checks of the run",
                          "The pipeline's own checks (summary.csv), made with or without truth:")


def _accuracy(inv: ResultsInventory) -> Section | None:
    """``accuracy.csv`` and, with a truth folder, each pose track against the truth."""
    from gtrig.report.checks import checks_section

    s = None
    if inv.accuracy is not None:
        s = checks_section(inv.accuracy, "accuracy", "Accuracy against truth",
                           "The pipeline's accuracy against the simulated truth (accuracy.csv):")
    rows = _truth_rows(inv)
    if rows:
        s = s or Section("accuracy", "Accuracy against truth")
        s.add("<h3>Each pose track against the truth</h3>")
        s.table(["track", "compared", "poses paired", "RMSE position (mm)", "max position (mm)",
                 "RMSE yaw / rotation (deg)", "NEES / dof", "within the GT's 95 % region (%)"], rows)
        s.add('<p class="note">A planar track (x, y, yaw) is compared in the plane with the truth\'s x, y, yaw: '
              "the truth's height and tilt are not its error. The truth is interpolated at the track's stamps "
              "(gaps over 50 ms left out).</p>")
    return s


def _truth_rows(inv: ResultsInventory) -> list[list[str]]:
    from gtrig.report.truth import score_files

    rows = []
    for name, (tum, _cov) in inv.tracks.items():
        truth_p = _truth_for(inv, name)
        if name.startswith("truth") or truth_p is None:
            continue
        sc = score_files(tum, truth_p)
        ev = sc.evaluation
        how = "in the plane" if sc.planar else "in 3-D"
        if ev is None:
            rows.append([name, how, sc.error, "-", "-", "-", "-", "-"])
            continue
        g = ev.gt_aware
        rows.append([name, how, str(len(ev.association.gt)), f"{sc.rmse_mm():.2f}", f"{sc.max_mm():.2f}",
                     f"{sc.rot_rmse_deg():.3f}", f"{g.mean_d2_per_dof:.2f}" if g is not None else "-",
                     f"{100 * g.share_resolved:.1f}" if g is not None else "-"])
    return rows


def _truth_for(inv: ResultsInventory, name: str) -> Path | None:
    if inv.truth is None:
        return None
    cand = inv.truth / ("validation.tum" if "validation" in name else "run.tum")
    return cand if cand.is_file() else None


def _track_row(name: str, tr: Any) -> list[str]:
    """The summary table's row of one track (the truth columns filled by the caller)."""
    c = tr.counts()
    C = tr.cov_xytheta() if tr.cov is not None and tr.cov_kind != "xyz" else tr.cov
    sig = (f"{1000 * np.nanmedian(np.sqrt(C[:, 0, 0] + C[:, 1, 1])):.2f}" if C is not None else "-")
    sig_yaw = (f"{np.degrees(np.nanmedian(np.sqrt(C[:, 2, 2]))):.3f}" if C is not None and tr.cov_kind != "xyz"
               else "-")
    t0, t1 = tr.span_s()
    rate = (len(tr) - 1) / (t1 - t0) if t1 > t0 else float("nan")
    return [name, str(len(tr)), f"{t1 - t0:.1f}", f"{rate:.1f}", str(c["ok"]), str(c["flagged"]),
            str(c["bridged"]), str(c["rejected"]), sig, sig_yaw, "-", "-", "-"]


def _track_section(inv: ResultsInventory, name: str, tum: Path, tr: Any, row: list[str]) -> Section:
    """One track's section (path, errors against truth, d2, status); fills ``row``'s truth columns."""
    from gtrig.evaluate import plots
    from gtrig.io.formats import read_trajectory
    from gtrig.report.figures import status_figure, track_figure
    from gtrig.report.truth import score_files

    sec = Section(f"track-{name.replace('/', '-')}", f"Track {name}")
    truth_p = _truth_for(inv, name)
    truth = read_trajectory(truth_p) if truth_p is not None else None
    fig, caption = track_figure(tr, truth, name)
    sec.figure(fig, caption)
    if truth_p is not None:
        sc = score_files(tum, truth_p)
        ev = sc.evaluation
        if ev is None:
            sec.add(f'<p class="warn">against truth: {html.escape(sc.error)}</p>')
        else:
            how = "in the plane (x, y, yaw)" if sc.planar else "in 3-D"
            sec.figure(plots.error_bounds_figure(ev.association.gt, ev.est_aligned,
                                                 f"truth - {name} (minus the GT's error), {how}"),
                       f"{name}: error against truth, {how}, with the GT's own 3-sigma bounds")
            row[10] = f"{sc.rmse_mm():.2f}"
            if ev.gt_aware is not None:
                row[11] = f"{ev.gt_aware.mean_d2_per_dof:.2f}"
                row[12] = f"{100 * ev.gt_aware.share_resolved:.1f}"
                sec.figure(plots.d2_figure(ev.gt_aware.d2, len(ev.gt_aware.axes), f"{name} against truth"),
                           f"{name}: d2 of the error under its covariance, against chi2")
    sec.figure(status_figure(tr, f"{name}: status over time"), f"{name}: status, sigma and gaps over time")
    return sec


def _tracks(inv: ResultsInventory) -> list[Section]:
    from gtrig.io.formats import read_trajectory

    out = []
    summary = Section("tracks", "Pose tracks")
    rows = []
    for name, (tum, _cov) in inv.tracks.items():
        if name.startswith("truth"):
            continue
        try:
            tr = read_trajectory(tum)
        except GtrigError as e:
            summary.add(f'<p class="warn">{html.escape(name)}: not read ({html.escape(str(e))})</p>')
            continue
        if not len(tr):
            continue
        row = _track_row(name, tr)
        out.append(_track_section(inv, name, tum, tr, row))
        rows.append(row)
    if not rows:
        return []
    summary.table(["track", "poses", "span (s)", "rate (Hz)", "ok", "flagged", "bridged", "rejected",
                   "median sigma xy (mm)", "median sigma yaw (deg)", "RMSE vs truth (mm)", "NEES / dof",
                   "within 95 % (%)"], rows)
    if inv.truth is not None:
        summary.add('<p class="note">Against truth, a planar track is compared in the plane (x, y, yaw).</p>')
    return [summary, *out]


def _consistency(inv: ResultsInventory) -> Section | None:
    """Two GT sources of the run against each other (what stands in for truth on a real recording)."""
    from gtrig.evaluate.compare import compare_sources
    from gtrig.evaluate.plots import d2_figure, error_bounds_figure
    from gtrig.io.formats import read_trajectory

    names = [n for n, (_, cov) in inv.tracks.items() if cov is not None and "validation" not in n]
    if len(names) < 2:
        return None
    s = Section("consistency", "Consistency of the GT sources")
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            ref, other = names[i], names[j]
            a, b = read_trajectory(inv.tracks[ref][0]), read_trajectory(inv.tracks[other][0])
            if len(b) < len(a):  # the denser source is interpolated at the sparser one's stamps
                a, b, ref, other = b, a, other, ref
            try:
                c = compare_sources(a, b, "none", 0.2)
            except GtrigError as e:
                s.add(f'<p class="note">{html.escape(other)} against {html.escape(ref)}: '
                      f"{html.escape(str(e))}</p>")
                continue
            s.add(f"<h3>{html.escape(other)} against {html.escape(ref)}</h3>")
            s.table(["metric", "statistic", "value", "unit"], [[m, st, f"{v:.5g}", u] for m, st, v, u in c.rows()])
            s.figure(error_bounds_figure(c.association.gt, c.association.est, f"{other} - {ref}"),
                     f"{other} - {ref} with {ref}'s 3-sigma bounds")
            if c.d2 is not None:
                s.figure(d2_figure(c.d2, len(c.axes), "d2 under the sum of both covariances"),
                         f"{other} against {ref}: d2 under both covariances, against chi2")
    return s


def _cameras(inv: ResultsInventory) -> Section | None:
    from gtrig.report.coverage import cameras_section

    return cameras_section(inv.vision_checkpoints, inv.rig_yaml)


def _scanners(inv: ResultsInventory) -> Section | None:
    from gtrig.report.coverage import scanners_section

    return scanners_section(inv.sync_yaml)


def _fusion(inv: ResultsInventory) -> Section | None:
    from gtrig.report.fusion import fusion_section

    return fusion_section(inv.fusion_json)


def _survey(inv: ResultsInventory) -> Section | None:
    from gtrig.report.figures import survey_figure

    if inv.world_points is None:
        return None
    s = Section("survey", "Survey")
    rows = read_csv(inv.world_points)
    pts = {r["name"]: np.array([float(r["x"]), float(r["y"])]) for r in rows}
    cov = None
    if rows and "cov_xx" in rows[0]:
        cov = np.array([[[float(r["cov_xx"]), float(r["cov_xy"])], [float(r["cov_xy"]), float(r["cov_yy"])]]
                        for r in rows])
    truth = None
    if inv.truth is not None and (inv.truth / "world_points.csv").is_file():
        truth = {r["name"]: np.array([float(r["x"]), float(r["y"])]) for r in read_csv(inv.truth /
                                                                                          "world_points.csv")}
    poses = pose_cov = None
    if inv.validation_poses is not None:
        vr = read_csv(inv.validation_poses)
        poses = np.array([[float(r["x"]), float(r["y"]), float(r["theta"])] for r in vr])
        if vr and "cov_xx" in vr[0]:
            pose_cov = np.array([[[float(r["cov_xx"]), float(r["cov_xy"])], [float(r["cov_xy"]), float(r["cov_yy"])]]
                                 for r in vr])
    table = []
    for n, p in pts.items():
        sd = "-"
        if cov is not None:
            k = list(pts).index(n)
            sd = f"{1000 * np.sqrt(cov[k, 0, 0]):.2f}, {1000 * np.sqrt(cov[k, 1, 1]):.2f}"
        err = f"{1000 * np.linalg.norm(p - truth[n]):.2f}" if truth and n in truth else "-"
        table.append([n, f"{p[0]:.4f}", f"{p[1]:.4f}", sd, err])
    s.table(["point", "x (m)", "y (m)", "sigma x, y (mm)", "error vs truth (mm)"], table)
    s.figure(survey_figure(pts, cov, truth, poses, pose_cov, 200.0),
             "world points (blue) and validation poses (green arrows) with their 3-sigma ellipses"
             + (" and their errors against truth (red arrows)" if truth else "") + ", magnified 200x")
    return s


def _calibration(inv: ResultsInventory) -> Section | None:
    from gtrig.io.text import read_text
    from gtrig.io.yamlfile import safe_load
    from gtrig.report.figures import bars_figure

    if inv.calibration_yaml is None:
        return None
    s = Section("calibration", "Calibration residuals")
    d = safe_load(read_text(inv.calibration_yaml, "YAML file")) or {}
    groups: dict[str, dict[str, float]] = {}
    for cam, v in (d.get("intrinsics") or {}).items():
        if isinstance(v, dict) and "rms_px" in v:
            groups.setdefault("intrinsics RMS (px)", {})[str(cam)] = float(v["rms_px"])
    for cam, v in ((d.get("network") or {}).get("world_board_rms_px") or {}).items():
        groups.setdefault("world board RMS (px)", {})[str(cam)] = float(v)
    truth = d.get("truth") or {}
    tgroups: dict[str, dict[str, float]] = {}
    for cam, v in truth.items():
        if isinstance(v, dict):
            for k in ("joint_mm", "chain_mm"):
                if k in v:
                    tgroups.setdefault(k.replace("_mm", " position error (mm)"), {})[str(cam)] = float(v[k])
    if groups:
        s.figure(bars_figure(groups, "px", "reprojection residuals per camera"), "calibration residuals per camera")
    if tgroups:
        s.figure(bars_figure(tgroups, "mm", "camera position error against truth: joint bundle vs chain"),
                 "camera pose errors against truth")
    net = d.get("network") or {}
    if "rms_px" in net:
        s.add(f'<p class="note">network bundle adjustment RMS {float(net["rms_px"]):.4f} px, residual sigma '
              f'{float(net.get("sigma_px", float("nan"))):.4f} px</p>')
    for w in (net.get("warnings") or []):
        s.add(f'<p class="warn">{html.escape(str(w))}</p>')
    return s if s.parts else None


def _sync(inv: ResultsInventory) -> Section | None:
    from gtrig.report.sync import sync_section

    return sync_section(inv.sync_yaml, inv.sync)


def _gps_section(inv: ResultsInventory, path: Path, key: str) -> Section | None:
    """One ``gtrig gps --report`` JSON: its summary lines, the fix-type shares, the lost-fix intervals,
    the coverage map and satellites / HDOP / fix type over time (drawn from the JSON itself)."""
    from gtrig.gps.plots import coverage_figure, lost_since_first, time_series_figure
    from gtrig.gps.report import report_lines

    name = str(path.relative_to(inv.root))
    try:
        rep = json.loads(path.read_text(encoding="utf-8"))
    except ValueError as e:  # undecodable or not JSON
        s = Section(key, f"RTK-GPS: {name}")
        s.add(f'<p class="warn">{html.escape(name)}: not read ({html.escape(str(e))})</p>')
        return s
    if not isinstance(rep, dict) or "fix_share_time" not in rep:
        return None  # a JSON of another kind whose name holds "gps"
    s = Section(key, f"RTK-GPS: {name}")
    s.add('<ul class="note">' + "".join(f"<li>{html.escape(x)}</li>" for x in report_lines(rep)) + "</ul>")
    shares = sorted(rep["fix_share_time"].items(), key=lambda kv: -kv[1])
    s.add("<h3>Fix types over time</h3>")
    s.table(["fix type", "share of the time (%)"], [[k, f"{100 * v:.1f}"] for k, v in shares]
            + [["kept as ground truth", f"{100 * rep['kept_share_time']:.1f}"]])
    lost = rep["lost_fix_intervals"]
    rel = lost_since_first(rep)
    s.add(f"<h3>Lost-fix intervals: {lost['count']} ({lost['total_s']:.0f} s, longest {lost['longest_s']:.0f} s)</h3>")
    if rel:
        shown = rel[:50]
        s.table(["interval", "start (s from the first epoch)", "end (s)", "length (s)"],
                [[str(i + 1), f"{a:.1f}", f"{b:.1f}", f"{b - a:.1f}"] for i, (a, b) in enumerate(shown)])
        if len(rel) > len(shown):
            s.add(f'<p class="note">{len(rel) - len(shown)} more in {html.escape(name)}</p>')
    if "coverage" in rep:
        c = rep["coverage"]
        s.figure(coverage_figure(c), f"{name}: coverage map, each epoch coloured by its fix type, the kept fixes on "
                                     f"grey, 1-sigma ellipses (magnified as the title says) every {c['ellipse_every']} "
                                     "kept fixes")
    else:
        s.add(f'<p class="warn">{html.escape(name)} has no coverage data (written by an older gtrig): run '
              "gtrig gps again for the coverage map</p>")
    s.figure(time_series_figure(rep["series_1hz"], rel),
             f"{name}: satellites, HDOP and fix type over time, lost-fix intervals shaded")
    return s


def _gps(inv: ResultsInventory) -> list[Section]:
    out: list[Section] = []
    for p in inv.gps_reports:
        got = _gps_section(inv, p, "gps" if not out else f"gps-{len(out) + 1}")
        if got is not None:
            out.append(got)
    return out


def _summaries(inv: ResultsInventory) -> Section | None:
    from gtrig.report.markdown import markdown_to_html

    if not inv.summaries:
        return None
    s = Section("summaries", "Stage summaries")
    shown_by_gps = {g.with_suffix(".md") for g in inv.gps_reports}  # the GPS section shows those
    for p in (p for p in inv.summaries if p not in shown_by_gps):
        s.add(f"<h3>{html.escape(str(p.relative_to(inv.root)))}</h3>")
        s.add(markdown_to_html(p.read_text(encoding="utf-8")))
    return s if s.parts else None


SECTIONS: tuple[tuple[str, Callable[[ResultsInventory], Any]], ...] = (
    ("checks of the run", _checks),
    ("accuracy against truth", _accuracy),
    ("pose tracks", _tracks),
    ("RTK-GPS", _gps),
    ("consistency of GT sources", _consistency),
    ("fusion", _fusion),
    ("cameras", _cameras),
    ("scanners", _scanners),
    ("survey", _survey),
    ("calibration", _calibration),
    ("time sync", _sync),
    ("stage summaries", _summaries),
)


#: what a section reads, named when the folder lacks it
ABSENT = {
    "checks of the run": "no summary.csv",
    "accuracy against truth": "no accuracy.csv and no truth folder: give --truth, the recording's truth/",
    "pose tracks": "no *.tum",
    "RTK-GPS": "no gps JSON",
    "consistency of GT sources": "fewer than two tracks with a covariance",
    "fusion": "no fusion_report.json",
    "cameras": "no gt_vision_*.checkpoint holding detections",
    "scanners": "no sync.yaml with a laser/<scanner> entry",
    "survey": "no survey/world_points.csv",
    "calibration": "no calibration/calibration_report.yaml",
    "time sync": "no sync.yaml and no correlation curve CSV",
    "stage summaries": "no *.md",
}

#: sections of verbs outside the pipeline (``gtrig gps``): shown when their files are there, not named when absent
OPTIONAL_SECTIONS = frozenset({"RTK-GPS"})


def build_report(results_dir: str | Path, truth_dir: str | Path | None = None) -> str:
    """The report's HTML for ``results_dir`` (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    from gtrig import __version__

    inv = inventory(results_dir, truth_dir)
    from gtrig.errors import InputError

    if not inv.root.is_dir():
        raise InputError(f"{inv.root}: no such results folder")
    if truth_dir is not None and not Path(truth_dir).is_dir():
        raise InputError(f"--truth {truth_dir}: no such folder")
    sections: list[Section] = []
    skipped: list[str] = []
    for label, fn in SECTIONS:
        try:
            got = fn(inv)
        except (GtrigError, ValueError, KeyError, IndexError, OSError) as e:
            log.warning("report: %s skipped (%s)", label, e)
            skipped.append(f"{label}: could not be read ({e})")
            continue
        got = [got] if isinstance(got, Section) else (got or [])
        if not got and label not in OPTIONAL_SECTIONS:
            skipped.append(f"{label}: no input in the folder ({ABSENT[label]})")
        sections += got
    n_fig = sum(s.n_figures for s in sections)
    when = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    nav = "".join(f'<a href="#{s.key}">{html.escape(s.title)}</a>' for s in sections)
    notes = "".join(f"<li>{html.escape(x)}</li>" for x in skipped)
    head = (f"<header><h1>gtrig report: {html.escape(str(inv.root))}</h1><p>gtrig {__version__}, {when}; "
            f"{len(sections)} sections, {n_fig} figures; truth: "
            f"{html.escape(str(inv.truth)) if inv.truth else 'none (consistency figures instead)'}</p></header>")
    body = "\n".join(s.html() for s in sections)
    skipped_html = f'<section id="skipped"><h2>Not in this folder</h2><ul class="note">{notes}</ul></section>' \
        if skipped else ""
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>gtrig report</title>'
            f"<style>{CSS}</style></head><body data-figures-expected=\"{n_fig}\">{head}<nav>{nav}</nav>{body}"
            f"{skipped_html}<script>{CHECK_JS}</script></body></html>\n")


def write_report(results_dir: str | Path, out: str | Path, truth_dir: str | Path | None = None) -> Path:
    """Write :func:`build_report` to ``out`` atomically; returns the path."""
    from gtrig.io.atomic import atomic_write_text

    text = build_report(results_dir, truth_dir)
    atomic_write_text(out, text)
    return Path(out)
