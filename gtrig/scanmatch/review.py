"""One HTML page to audit matches: an overlay picture of every accepted and rejected pair.

Each picture (OpenCV drawing, PNG inlined as base64) shows the reference scan in grey and the current
scan moved by the match in green (accepted) or red (rejected), with the verdict's statistics, so a
person audits the test's decisions instead of inspecting every pair.
"""

from __future__ import annotations

import base64
import html
import os

import numpy as np

from gtrig.io.atomic import atomic_write_text
from gtrig.scanmatch import se2
from gtrig.scanmatch.scan import PlanarScan


def overlay_png(ref: PlanarScan, cur: PlanarScan, pose: np.ndarray, accepted: bool, size_px: int = 220,
                span_m: float = 12.0) -> bytes:
    """PNG bytes of the overlay, robot at the centre, ``span_m`` across."""
    import cv2

    img = np.full((size_px, size_px, 3), 255, np.uint8)
    k = size_px / span_m

    def px(xy: np.ndarray) -> np.ndarray:
        return np.column_stack([size_px / 2 + k * xy[:, 0], size_px / 2 - k * xy[:, 1]]).astype(int)

    for p in px(ref.xy):
        cv2.circle(img, (int(p[0]), int(p[1])), 1, (150, 150, 150), -1)
    colour = (40, 160, 40) if accepted else (40, 40, 220)
    for p in px(se2.apply(pose, cur.xy)):
        cv2.circle(img, (int(p[0]), int(p[1])), 1, colour, -1)
    ok, buf = cv2.imencode(".png", img)
    return buf.tobytes() if ok else b""


def write_review(path: str | os.PathLike[str], items: list[tuple[str, PlanarScan, PlanarScan, np.ndarray, bool, str]],
                 title: str = "gtrig scanmatch review") -> None:
    """Write the page; ``items`` are (label, ref, cur, pose, accepted, statistics text)."""
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>",
             "<style>body{font-family:sans-serif} figure{display:inline-block;margin:4px;width:230px;"
             "font-size:11px;vertical-align:top} .rej{color:#b00}</style></head><body>",
             f"<h1>{html.escape(title)}</h1>",
             f"<p>{sum(1 for i in items if i[4])} accepted, {sum(1 for i in items if not i[4])} rejected. "
             "Grey: reference scan; green / red: current scan moved by the match (accepted / rejected).</p>"]
    for accepted_first in (False, True):
        parts.append(f"<h2>{'accepted' if accepted_first else 'rejected'}</h2>")
        for label, ref, cur, pose, acc, stats in items:
            if acc != accepted_first:
                continue
            b64 = base64.b64encode(overlay_png(ref, cur, pose, acc)).decode()
            cls = "" if acc else " class='rej'"
            parts.append(f"<figure><img src='data:image/png;base64,{b64}'><figcaption{cls}>{html.escape(label)}"
                         f"<br>{html.escape(stats)}</figcaption></figure>")
    parts.append("</body></html>")
    atomic_write_text(path, "\n".join(parts))
