"""Rendered camera recordings for the vision tests: the test renderer's images of a run, in the
recording layout (docs/formats.md)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from gtrig.io.frames import write_frame_index
from gtrig.rig.models import Rig
from gtrig.vision.synthetic import render_markers, visible_views


def write_rendered_run(out: Path, rig: Rig, Ts: Sequence[np.ndarray], stamps_s: np.ndarray,
                       rng: np.random.Generator) -> None:
    """``out/run/cameras/<camera>``: for each camera of ``rig`` that sees a marker at one of the robot
    poses ``Ts`` (4, 4 ``T_world_robot``), its images rendered at every pose (a blank grey image where it
    sees none) and its frame index, stamped ``stamps_s`` (len(Ts),) plus 1 ms per camera's place in the
    rig (unsynchronized cameras)."""
    for c, cam in enumerate(rig.cameras):
        seen = [any(n == cam.name for n, _, _ in visible_views(rig, T)) for T in Ts]
        if not any(seen):
            continue
        folder = out / "run" / "cameras" / cam.name
        folder.mkdir(parents=True)
        blank = np.full((cam.resolution[1], cam.resolution[0]), 90, np.uint8)
        for k, T in enumerate(Ts):
            cv2.imwrite(str(folder / f"{k:06d}.png"), render_markers(rig, cam.name, T, rng) if seen[k] else blank)
        write_frame_index(folder, stamps_s + 0.001 * c, [f"{k:06d}.png" for k in range(len(Ts))])


def write_rendered_stops(out: Path, rig: Rig, Ts: Sequence[np.ndarray], rng: np.random.Generator, blur_px: float,
                         noise_grey: float) -> None:
    """``out/validation``: one image per camera at each robot pose of ``Ts`` (a static interval each, 10 s
    apart), rendered with ``blur_px`` and ``noise_grey`` (a noisy grey image where a camera sees no
    marker), with the frame indices and ``poses.csv``."""
    for cam in rig.cameras:
        folder = out / "validation" / "cameras" / cam.name
        folder.mkdir(parents=True)
        for k, T in enumerate(Ts):
            seen = any(n == cam.name for n, _, _ in visible_views(rig, T))
            img = (render_markers(rig, cam.name, T, rng, blur_px=blur_px, noise_grey=noise_grey) if seen else
                   np.clip(rng.normal(90, noise_grey, (cam.resolution[1], cam.resolution[0])), 0, 255).astype(np.uint8))
            cv2.imwrite(str(folder / f"{k:06d}.png"), img)
        write_frame_index(folder, 10.0 * np.arange(len(Ts)) + 0.05, [f"{k:06d}.png" for k in range(len(Ts))])
    rows = "".join(f"{k + 1},{10.0 * k},{10.0 * k + 1.0}\n" for k in range(len(Ts)))
    (out / "validation" / "poses.csv").write_text("pose,start_s,end_s\n" + rows)
