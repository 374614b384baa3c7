"""Pictures of the detector's candidates and why each was dropped (``gtrig markers detect --debug``).

Drawn with OpenCV on the image (no plotting library): detections in green with their ID, and every
rejected candidate in a colour per stage with its reason, so a user whose photo fails can see
whether no peer found the marker (it is not outlined), the edge model could not fit its edges, or
gtrig's cells contradicted the peer's ID. The legend lists the reasons with numbers drawn beside the outlines.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect import Detection, Rejection

__all__ = ["STAGE_COLOURS", "debug_image"]

#: BGR colour of each stage's outlines
STAGE_COLOURS: dict[str, tuple[int, int, int]] = {
    "fit": (0, 0, 255),  # red: the edge fits were refused
    "decode": (255, 0, 255),  # magenta: gtrig's cells contradict the peer's ID
    "duplicate": (128, 128, 0),  # teal: another detection holds the place
}


def debug_image(gray: NDArray[np.uint8], detections: list[Detection], rejections: list[Rejection]
                ) -> NDArray[np.uint8]:
    """A BGR picture (H', W', 3) of ``gray`` with the detections and the rejected candidates drawn,
    upscaled so that small markers stay legible (at least 1000 px wide, at most 4x), and a legend
    strip below listing every numbered rejection's stage and reason."""
    h, w = gray.shape[:2]
    k = float(np.clip(1000.0 / max(w, 1), 1.0, 4.0))
    img = cv2.cvtColor(cv2.resize(gray, (round(w * k), round(h * k)), interpolation=cv2.INTER_NEAREST),
                       cv2.COLOR_GRAY2BGR)
    lines: list[tuple[str, tuple[int, int, int]]] = []
    for n, r in enumerate(rejections, 1):
        col = STAGE_COLOURS.get(r.stage, (0, 255, 255))
        q = np.round(r.quad_px * k + 0.5 * (k - 1)).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [q], True, col, 1, cv2.LINE_AA)
        x, y = q.reshape(-1, 2).min(axis=0)
        cv2.putText(img, str(n), (int(x), max(int(y) - 2, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.35, col, 1, cv2.LINE_AA)
        lines.append((f"{n}: {r.stage}: {r.reason}", col))
    for d in detections:
        q = np.round(d.corners_px * k + 0.5 * (k - 1)).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [q], True, (0, 200, 0), 2, cv2.LINE_AA)
        cv2.circle(img, tuple(int(v) for v in q[0, 0]), 3, (0, 200, 0), -1)  # the printed top-left
        c = d.corners_px.mean(axis=0) * k
        cv2.putText(img, str(d.id), (int(c[0]) - 6, int(c[1]) + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 200, 0), 1,
                    cv2.LINE_AA)
    head = f"{len(detections)} detection(s) (green, dot at the printed top-left), {len(rejections)} rejected"
    lines.insert(0, (head, (255, 255, 255)))
    lines.insert(1, ("  " + ", ".join(STAGE_COLOURS) + ": red, magenta, teal", (255, 255, 255)))
    # legend in columns below the picture
    row_h, col_w = 14, 480
    per_col = 60
    cols = max(1, -(-len(lines) // per_col))
    legend = np.zeros((row_h * min(len(lines), per_col) + 6, max(img.shape[1], cols * col_w), 3), np.uint8)
    for i, (txt, col) in enumerate(lines):
        x, y = (i // per_col) * col_w + 4, (i % per_col) * row_h + 12
        cv2.putText(legend, txt[:80], (x, y), cv2.FONT_HERSHEY_SIMPLEX, 0.38, col, 1, cv2.LINE_AA)
    if legend.shape[1] > img.shape[1]:
        img = np.pad(img, ((0, 0), (0, legend.shape[1] - img.shape[1]), (0, 0)))
    return np.vstack([img, legend])
