"""A small, exact-enough renderer of markers for tests and benchmarks.

The marker (with its white quiet zone) is drawn at ``ss`` x supersampling inside a crop around it,
blurred with a Gaussian of ``blur_px * ss`` high-resolution pixels, area-averaged back to image
pixels and pasted over a cluttered, unevenly lit background; then Gaussian noise is added and the
result quantised to 8 bits. Pixel centres are at integer coordinates (OpenCV), so a pixel ``(u, v)``
integrates the scene over ``[u - 0.5, u + 0.5] x [v - 0.5, v + 0.5]``.

This is not the room simulator (:mod:`gtrig.sim`); it is a test fixture with known ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect.tone import linear_to_srgb
from gtrig.markers.families import marker_cells
from gtrig.rig.models import MarkerFamily

BLACK = 0.08
WHITE = 0.90


@dataclass(frozen=True)
class SynthMarker:
    """Ground truth of one rendered marker.

    ``corners_px`` (4, 2): the black square's corners top-left, top-right, bottom-right, bottom-left
    as printed, in OpenCV pixel coordinates. ``H`` (3, 3) maps marker coordinates ``(x, y, 1)``, with
    ``(0, 0)`` the top-left and ``(1, 1)`` the bottom-right corner of the black square, to pixels.
    """

    family: MarkerFamily
    marker_id: int
    corners_px: NDArray[np.float64]
    H: NDArray[np.float64]


def homography_from_pose(
    side_px: float, center: tuple[float, float], tilt_deg: float, tilt_axis_deg: float, roll_deg: float,
    focal_px: float = 900.0,
) -> NDArray[np.float64]:
    """Homography of a square of apparent side about ``side_px`` centred at ``center`` (pixels),
    tilted by ``tilt_deg`` about an in-plane axis at ``tilt_axis_deg`` and rolled by ``roll_deg``,
    seen by a pinhole camera of focal length ``focal_px`` whose principal point is ``center``."""
    from scipy.spatial.transform import Rotation

    Z = focal_px / side_px  # marker of side 1 at depth Z
    a = np.radians(tilt_axis_deg)
    R = (Rotation.from_rotvec(np.radians(tilt_deg) * np.array([np.cos(a), np.sin(a), 0.0]))
         * Rotation.from_rotvec([0.0, 0.0, np.radians(roll_deg)])).as_matrix()
    K = np.array([[focal_px, 0, center[0]], [0, focal_px, center[1]], [0, 0, 1.0]])
    # marker point (x, y) -> 3D R @ (x - 0.5, y - 0.5, 0) + (0, 0, Z)
    M = np.column_stack([R[:, 0], R[:, 1], R @ np.array([-0.5, -0.5, 0.0]) + np.array([0, 0, Z])])
    H = K @ M
    return H / H[2, 2]


def _apply_H(H: NDArray[np.float64], xy: NDArray[np.float64]) -> NDArray[np.float64]:
    p = np.column_stack([xy, np.ones(len(xy))]) @ H.T
    return p[:, :2] / p[:, 2:]


def clutter_background(
    shape: tuple[int, int], rng: np.random.Generator, n_shapes: int = 40, text: bool = True
) -> NDArray[np.float64]:
    """Reflectance image (values in [0, 1]) with rectangles, polygons, discs, lines and text."""
    h, w = shape
    bg = np.full((h, w), round(255 * rng.uniform(0.35, 0.8)), np.uint8)
    for _ in range(n_shapes):
        v = int(255 * rng.uniform(0.02, 0.95))
        kind = rng.integers(0, 5)
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        s = int(rng.integers(5, max(6, min(h, w) // 5)))
        if kind == 0:
            cv2.rectangle(bg, (x, y), (x + s, y + int(rng.integers(5, s + 6))), v, -1)
        elif kind == 1:
            cv2.circle(bg, (x, y), s // 2, v, -1, cv2.LINE_AA)
        elif kind == 2:
            cv2.line(bg, (x, y), (x + int(rng.integers(-s, s)), y + int(rng.integers(-s, s))), v,
                     int(rng.integers(1, 6)), cv2.LINE_AA)
        elif kind == 3:
            pts = (rng.uniform(-s, s, (int(rng.integers(3, 7)), 2)) + [x, y]).astype(np.int32)
            cv2.fillPoly(bg, [pts], v, cv2.LINE_AA)
        elif text:
            cv2.putText(bg, "".join(rng.choice(list("ABCDEFGH0123456789#"), 6)), (x, y),
                        cv2.FONT_HERSHEY_SIMPLEX, float(rng.uniform(0.4, 2.0)), v, int(rng.integers(1, 4)))
    # dark squares with white inside: marker-like clutter
    for _ in range(n_shapes // 8):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        s = int(rng.integers(15, 80))
        cv2.rectangle(bg, (x, y), (x + s, y + s), 20, -1)
        for _k in range(int(rng.integers(0, 6))):
            cx, cy = x + int(rng.integers(s // 4, 3 * s // 4)), y + int(rng.integers(s // 4, 3 * s // 4))
            c = max(2, s // 8)
            cv2.rectangle(bg, (cx - c, cy - c), (cx + c, cy + c), 230, -1)
    return bg.astype(np.float64) / 255.0


def textured_background(shape: tuple[int, int], rng: np.random.Generator, light: bool = False
                        ) -> NDArray[np.float64]:
    """A reflectance image (in [0, 1]) with texture at every scale (wood, carpet, fabric: noise
    filtered at 1, 4 and 16 px) under :func:`clutter_background`'s shapes; with ``light`` the scene
    is pale (0.75-0.97, a white wall or desk) so that it merges with a marker's quiet zone."""
    h, w = shape
    tex = np.zeros((h, w), np.float32)
    for s, a in ((1.0, 0.35), (4.0, 0.35), (16.0, 0.3)):
        t = cv2.GaussianBlur(rng.normal(0.0, 1.0, (h, w)).astype(np.float32), (0, 0), s)
        tex += a * t / max(float(t.std()), 1e-9)
    clutter = clutter_background(shape, rng, n_shapes=30)
    if light:
        base = 0.86 + 0.04 * tex + 0.1 * (clutter - 0.5)
        return np.clip(base, 0.75, 0.97).astype(np.float64)
    return np.clip(clutter + 0.08 * tex, 0.02, 0.98).astype(np.float64)


def render(
    shape: tuple[int, int],
    markers: list[tuple[MarkerFamily, int, NDArray[np.float64]]],
    *,
    blur_px: float = 0.0,
    noise: float = 3.0,
    gain: float = 230.0,
    gradient: float = 0.0,
    quiet_cells: float = 2.0,
    background: NDArray[np.float64] | None = None,
    rng: np.random.Generator | None = None,
    ss: int = 8,
    ink: float = BLACK,
    paper: float = WHITE,
    paper_texture: float = 0.0,
    bend_px: float = 0.0,
    glare: list[tuple[float, float, float, float]] | None = None,
    bayer: bool = False,
    jpeg_quality: int | None = None,
    srgb: bool = False,
) -> tuple[NDArray[np.uint8], list[SynthMarker]]:
    """Render markers into an 8-bit grayscale image (or, with ``bayer``, a BGR image).

    The keywords after ``ss`` add what real photos have and clean renders lack; their
    defaults leave the image exactly as without them.

    Parameters
    ----------
    shape : (height, width) in pixels.
    markers : list of (family, id, H)
        ``H`` (3, 3) maps marker coordinates (unit black square, y down as printed) to pixels.
    blur_px : Gaussian blur sigma, image pixels (optics; pixel integration comes on top).
    noise : sigma of additive Gaussian noise, 8-bit grey levels.
    gain : grey level of a reflectance of 1 at the image centre.
    gradient : relative illumination change across the image width (0 = uniform).
    quiet_cells : width of the white paper margin around the black square, in cells.
    background : reflectance image (H, W) in [0, 1]; default uniform 0.6.
    ink, paper : reflectance of the printed black and of the paper (print gain: toner is rarely
        darker than 0.1 and often lighter than 0.2; paper 0.7-0.92).
    paper_texture : relative SD of the paper's and the ink's texture (fibres, toner grain), a
        pattern about one image pixel across, multiplying the printed reflectance.
    bend_px : slight non-flatness of the print: every edge bows by up to this many pixels at its
        middle (a sheet curled along both axes; the corners stay where the homography puts them).
    glare : specular highlights ``(x, y, sigma_px, amplitude)`` added to the light (amplitude in
        units of ``gain``, so 0.5 lifts black and white by half of the paper's brightness; what
        exceeds 255 clips).
    bayer : a colour camera: the light has a warm tint (R, G, B gains 1.0, 0.85, 0.6), each pixel
        records one channel of a BGGR Bayer mosaic (with its own noise), and OpenCV's bilinear
        demosaicing gives back a BGR image (H, W, 3); the markers stay neutral grey.
    jpeg_quality : JPEG compression and decompression at this quality (OpenCV's encoder, 4:2:0
        chroma for colour images).
    srgb : store the light through sRGB's tone curve, as phones and webcams do (after the noise and
        the demosaicing, before the JPEG compression); without it the stored levels are proportional
        to the light, as a machine-vision camera's are. A blurred edge's midpoint between the stored
        black and white then lies inside the black (``DetectorParams(tone="srgb")`` undoes it).
    """
    rng = np.random.default_rng() if rng is None else rng
    h, w = shape
    refl = np.full((h, w), 0.6) if background is None else background.astype(np.float64).copy()
    truths = []
    crops = []
    for fam, mid, H in markers:
        cells = marker_cells(fam, mid).astype(np.float64)
        n = cells.shape[0]
        q = quiet_cells / n
        paper_poly = _apply_H(H, np.array([[-q, -q], [1 + q, -q], [1 + q, 1 + q], [-q, 1 + q]]))
        pad = int(np.ceil(4 * blur_px)) + 3
        x0 = max(int(np.floor(paper_poly[:, 0].min())) - pad, 0)
        y0 = max(int(np.floor(paper_poly[:, 1].min())) - pad, 0)
        x1 = min(int(np.ceil(paper_poly[:, 0].max())) + pad + 1, w)
        y1 = min(int(np.ceil(paper_poly[:, 1].max())) + pad + 1, h)
        if x1 <= x0 or y1 <= y0:
            continue
        cw, ch = x1 - x0, y1 - y0
        # high-res pixel (p, q) centre <-> image coordinate (p + 0.5) / ss - 0.5 + x0
        S = np.array([[1 / ss, 0, 0.5 / ss - 0.5 + x0], [0, 1 / ss, 0.5 / ss - 0.5 + y0], [0, 0, 1]])
        Hinv = np.linalg.inv(H) @ S  # high-res pixel -> marker coords
        gy, gx = np.mgrid[0 : ch * ss, 0 : cw * ss].astype(np.float32)
        den = Hinv[2, 0] * gx + Hinv[2, 1] * gy + Hinv[2, 2]
        mx = (Hinv[0, 0] * gx + Hinv[0, 1] * gy + Hinv[0, 2]) / den
        my = (Hinv[1, 0] * gx + Hinv[1, 1] * gy + Hinv[1, 2]) / den
        base = cv2.resize(refl[y0:y1, x0:x1].astype(np.float32), (cw * ss, ch * ss),
                          interpolation=cv2.INTER_NEAREST)
        inside_paper = (mx >= -q) & (mx < 1 + q) & (my >= -q) & (my < 1 + q)
        if bend_px > 0:
            # the printed point seen at (mx, my): each edge bows by bend_px at its middle, in marker
            # units of this marker's mean side
            side = float(np.mean(np.linalg.norm(np.diff(_apply_H(H, np.array([[0.0, 0], [1, 0], [1, 1], [0, 1],
                                                                               [0, 0]])), axis=0), axis=1)))
            b = bend_px / max(side, 1e-9)
            mx, my = mx - b * 4 * my * (1 - my), my - b * 4 * mx * (1 - mx)
        ci = np.clip(np.floor(my * n), 0, n - 1).astype(np.int32)
        cj = np.clip(np.floor(mx * n), 0, n - 1).astype(np.int32)
        in_sq = (mx >= 0) & (mx < 1) & (my >= 0) & (my < 1)
        val = np.where(in_sq, np.where(cells[ci, cj] > 0, paper, ink), paper).astype(np.float32)
        if paper_texture > 0:
            grain = cv2.GaussianBlur(rng.normal(0.0, 1.0, val.shape).astype(np.float32), (0, 0), 0.5 * ss)
            grain = grain * np.float32(paper_texture / max(float(grain.std()), 1e-9))
            val = val * (1.0 + grain)
        hr = np.where(inside_paper, val, base)
        if blur_px > 0:
            hr = cv2.GaussianBlur(hr, (0, 0), blur_px * ss)
        crops.append((y0, y1, x0, x1, hr.reshape(ch, ss, cw, ss).mean(axis=(1, 3))))
        corners = _apply_H(H, np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]]))
        truths.append(SynthMarker(MarkerFamily(fam), int(mid), corners, H))
    if blur_px > 0:  # away from the markers the background is blurred at image resolution
        refl = cv2.GaussianBlur(refl.astype(np.float32), (0, 0), blur_px).astype(np.float64)
    for y0, y1, x0, x1, lo in crops:
        refl[y0:y1, x0:x1] = lo
    yy, xx = np.mgrid[0:h, 0:w]
    light = gain * (1.0 + gradient * (xx / w - 0.5))
    img = refl * light
    for gx, gy, gs, ga in glare or ():
        img = img + ga * gain * np.exp(-((xx - gx) ** 2 + (yy - gy) ** 2) / (2.0 * gs * gs))
    if not bayer:
        img = img + rng.normal(0.0, noise, (h, w))
        if srgb:
            img = linear_to_srgb(img)
        out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    else:
        tint = {0: 0.6, 1: 0.85, 2: 1.0}  # B, G, R gains of a warm light
        chan = np.where((yy % 2 == 0) & (xx % 2 == 0), 0, np.where((yy % 2 == 1) & (xx % 2 == 1), 2, 1))
        gains = np.choose(chan, [tint[0], tint[1], tint[2]])
        mosaic = np.clip(np.rint(img * gains + rng.normal(0.0, noise, (h, w))), 0, 255).astype(np.uint8)
        # B at (even, even), R at (odd, odd): OpenCV names this layout BayerRG (its names are those of
        # the second row and column)
        out = cv2.cvtColor(mosaic, cv2.COLOR_BayerRG2BGR)
        if srgb:
            out = cv2.LUT(out, np.clip(np.rint(linear_to_srgb(np.arange(256.0))), 0, 255).astype(np.uint8))
    if jpeg_quality is not None:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        out = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    return out, truths


def disk_psf(radius_px: float, ss: int = 8) -> NDArray[np.float64]:
    """A defocus point-spread function: a uniform disk of ``radius_px`` image pixels, integrated over
    each pixel (``ss`` x supersampled), summing to 1; (k, k), k odd. Unlike a Gaussian it has a hard
    rim and zeros in its transfer function."""
    n = 2 * int(np.ceil(radius_px)) + 1
    y, x = (np.mgrid[0:n * ss, 0:n * ss] + 0.5) / ss - n / 2.0
    k = cv2.resize((x * x + y * y <= radius_px * radius_px).astype(np.float64), (n, n), interpolation=cv2.INTER_AREA)
    return k / k.sum()


def motion_psf(length_px: float, angle_rad: float, ss: int = 8) -> NDArray[np.float64]:
    """A linear motion blur of ``length_px`` image pixels along ``angle_rad`` (from the x axis), one pixel
    wide, integrated over each pixel (``ss`` x supersampled), summing to 1; (k, k), k odd."""
    n = int(np.ceil(length_px)) + 3
    n += 1 - n % 2
    y, x = (np.mgrid[0:n * ss, 0:n * ss] + 0.5) / ss - n / 2.0
    along = x * np.cos(angle_rad) + y * np.sin(angle_rad)
    across = -x * np.sin(angle_rad) + y * np.cos(angle_rad)
    line = ((np.abs(along) <= length_px / 2.0) & (np.abs(across) <= 0.5)).astype(np.float64)
    k = cv2.resize(line, (n, n), interpolation=cv2.INTER_AREA)
    return k / k.sum()


def psf_scene(rng: np.random.Generator, psf: str, side: float, family: MarkerFamily | str = "apriltag_36h11",
              shape: tuple[int, int] = (768, 1024), noise: float = 3.0) -> tuple[NDArray[np.uint8], list[SynthMarker]]:
    """Three markers of about ``side`` px (IDs drawn from 0-586), tilted up to 50 deg, on clutter, the
    sharp 8-bit scene then blurred by ``psf`` ("disk R": :func:`disk_psf`, "motion L": :func:`motion_psf`
    along a random direction; px) with noise of SD ``noise`` added: optics that are not Gaussian, for
    ``tests/markers/test_psf.py`` and ``bench/markers.py --psf``."""
    kind, size = psf.split()
    markers = []
    for c, mid in zip([(220, 250), (520, 520), (800, 260)], rng.choice(587, 3, replace=False), strict=True):
        H = homography_from_pose(side, (c[0] + rng.uniform(-40, 40), c[1] + rng.uniform(-40, 40)),
                                 rng.uniform(0, 50), rng.uniform(0, 360), rng.uniform(0, 360))
        markers.append((MarkerFamily(family), int(mid), H))
    bg = clutter_background(shape, rng, n_shapes=40)
    sharp, truths = render(shape, markers, blur_px=0.0, noise=0.0, background=bg, rng=rng)
    k = disk_psf(float(size)) if kind == "disk" else motion_psf(float(size), rng.uniform(0, np.pi))
    img = cv2.filter2D(sharp.astype(np.float64), -1, k, borderType=cv2.BORDER_REFLECT) + rng.normal(0, noise, shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), truths
