"""Camera images of printed markers made apart from gtrig: this module imports only NumPy
and OpenCV, never ``gtrig``, so the detector is not checked against the renderer it was tuned on.

The markers are OpenCV's own (``cv2.aruco.generateImageMarker``: ArUco 4x4_50, 5x5_100, 6x6_250 and
AprilTag 36h11), so the bit layout is OpenCV's too. The image is made the way a camera makes one, in
linear light:

1. scene: a background of random shapes and strokes (colour or grey, pale or dark, with an
   illumination gradient), and on it each marker printed on paper (ink and paper reflectance, paper
   grain, a quiet zone of 1-2 cells and a paper margin beyond), posed in 3D in front of a pinhole
   camera and bowed (a print that is not flat: the horizontal edges sag by up to ``bow_px``);
2. optics: each marker's patch is drawn at ``supersample`` x the resolution through the exact inverse
   projection (the texture sampled bilinearly), blurred there by the point-spread function (Gaussian,
   defocus disk or a motion streak), and area-averaged down; glare (a specular blob on the print) and
   vignetting follow;
3. sensor: photon (Poisson) and read noise, saturation, optionally a BGGR Bayer mosaic demosaiced by
   OpenCV, white balance;
4. output: a tone curve (sRGB or a filmic S-curve) to 8 bits and JPEG at quality 60-95.

The true corners are the outer corners of each marker's black square, in OpenCV's order (the printed
top-left first, clockwise), in pixel coordinates with pixel centres at integers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

# family name (gtrig's MarkerFamily values) -> (OpenCV dictionary, data cells per side)
FAMILIES = {
    "aruco_4x4_50": ("DICT_4X4_50", 4),
    "aruco_5x5_100": ("DICT_5X5_100", 5),
    "aruco_6x6_250": ("DICT_6X6_250", 6),
    "apriltag_36h11": ("DICT_APRILTAG_36h11", 6),
}
SHAPE = (768, 1024)
FOCAL_PX = 900.0


@dataclass(frozen=True)
class Truth:
    """One marker in an image: its ID, its true corners ((4, 2) px) and what made it hard."""

    id: int
    corners: np.ndarray
    side_px: float
    psf: str
    blur_px: float


@dataclass(frozen=True)
class Frame:
    """A rendered grey image (what a user hands the detector), the colour JPEG it came from and truth."""

    gray: np.ndarray
    family: str
    truths: tuple[Truth, ...]
    bayer: bool
    jpeg_quality: int
    tone: str


def _marker_texture(dictionary: str, mid: int, cells: int, quiet: int, px_per_cell: int,
                    ink: float, paper: float, grain: float, rng: np.random.Generator) -> np.ndarray:
    """The print's reflectance, black square plus quiet zone, ``px_per_cell`` texture pixels a cell."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    n = (cells + 2) * px_per_cell
    img = cv2.aruco.generateImageMarker(d, mid, n, borderBits=1)
    pad = quiet * px_per_cell
    img = cv2.copyMakeBorder(img, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)
    refl = np.where(img > 127, paper, ink).astype(np.float32)
    if grain > 0:
        g = rng.normal(0.0, 1.0, refl.shape).astype(np.float32)
        g = cv2.GaussianBlur(g, (0, 0), px_per_cell / 6.0)
        g /= max(float(g.std()), 1e-6)
        refl *= 1.0 + grain * g
    return refl


def _background(rng: np.random.Generator, colour: bool) -> np.ndarray:
    """Linear reflectance, (H, W, 3): random shapes, strokes and a smooth illumination field."""
    h, w = SHAPE
    pale = rng.random() < 0.35
    base = rng.uniform(0.55, 0.85) if pale else rng.uniform(0.05, 0.6)
    img = np.full((h, w, 3), base, np.float32)
    for _ in range(int(rng.integers(30, 120))):
        col = rng.uniform(0.5, 0.9, 3) if pale else rng.uniform(0.02, 0.9, 3)
        if not colour:
            col[:] = col.mean()
        col_t = tuple(float(c) for c in col)
        kind = rng.integers(0, 4)
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        if kind == 0:
            cv2.rectangle(img, (x, y), (x + int(rng.integers(5, 200)), y + int(rng.integers(5, 200))), col_t, -1)
        elif kind == 1:
            cv2.circle(img, (x, y), int(rng.integers(3, 80)), col_t, -1, lineType=cv2.LINE_AA)
        elif kind == 2:
            cv2.line(img, (x, y), (int(rng.integers(0, w)), int(rng.integers(0, h))), col_t,
                     int(rng.integers(1, 6)), lineType=cv2.LINE_AA)
        else:  # a small dark square-ish blob: what a detector may take for a marker
            s = int(rng.integers(6, 40))
            pts = np.array([[x, y], [x + s, y + rng.integers(-3, 4)], [x + s, y + s], [x, y + s]], np.int32)
            cv2.fillPoly(img, [pts], col_t, lineType=cv2.LINE_AA)
    for _ in range(int(rng.integers(0, 25))):  # print on the walls: text, small dark strokes
        text = "".join(rng.choice(list("ABCDEFGHKMNPRSTWXYZ0123456789#"), size=int(rng.integers(2, 9))))
        col = (0.05,) * 3 if pale else tuple(float(c) for c in rng.uniform(0.02, 0.9, 3))
        ink = np.zeros((h, w), np.uint8)  # putText draws 8-bit only: draw coverage, then blend
        cv2.putText(ink, text, (int(rng.integers(0, w)), int(rng.integers(0, h))), int(rng.integers(0, 8)),
                    float(rng.uniform(0.3, 1.5)), 255, int(rng.integers(1, 3)), cv2.LINE_AA)
        a = (ink.astype(np.float32) / 255)[:, :, None]
        img = img * (1 - a) + np.array(col, np.float32) * a
    if rng.random() < 0.5:  # fine texture: fabric, wood, concrete
        tex = rng.normal(0.0, 1.0, (h, w)).astype(np.float32)
        tex = cv2.GaussianBlur(tex, (0, 0), rng.uniform(0.6, 2.5))
        img *= (1.0 + rng.uniform(0.05, 0.25) * tex / max(float(tex.std()), 1e-6))[:, :, None]
    img = cv2.GaussianBlur(img, (0, 0), rng.uniform(0.3, 1.2))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    gx, gy = rng.uniform(-1, 1, 2)
    light = 0.75 + 0.35 * (gx * (xx / w - 0.5) + gy * (yy / h - 0.5))
    return img * light[:, :, None]


def _pose_homography(rng: np.random.Generator, side_px: float, centre: np.ndarray, tilt_deg: float
                     ) -> np.ndarray:
    """The homography from the marker plane (unit square [-1, 1]^2, y down as printed) to pixels."""
    k = np.array([[FOCAL_PX, 0, SHAPE[1] / 2 - 0.5], [0, FOCAL_PX, SHAPE[0] / 2 - 0.5], [0, 0, 1]])
    axis = rng.normal(size=2)
    axis = np.array([axis[0], axis[1], 0.0]) / np.linalg.norm(axis)
    rvec_tilt = axis * np.radians(tilt_deg)
    rvec_roll = np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)])
    r = cv2.Rodrigues(rvec_tilt)[0] @ cv2.Rodrigues(rvec_roll)[0]
    half = 0.05  # metres: half the black square's side
    z = FOCAL_PX * 2 * half / side_px
    t = z * np.linalg.solve(k, np.array([centre[0], centre[1], 1.0]))
    return k @ np.column_stack([r[:, 0] * half, r[:, 1] * half, t])


def _cross2(a: np.ndarray, b: np.ndarray) -> float:
    """The z component of the cross product of two 2-vectors."""
    return float(a[0] * b[1] - a[1] * b[0])


def _apply_h(h: np.ndarray, pts: np.ndarray) -> np.ndarray:
    p = np.column_stack([pts, np.ones(len(pts))]) @ h.T
    return p[:, :2] / p[:, 2:3]


def _psf_kernel(kind: str, size_px: float, angle: float, scale: int) -> np.ndarray | None:
    """The point-spread function sampled at ``scale`` x the image resolution, normalised to sum 1."""
    if size_px <= 0:
        return None
    if kind == "gauss":
        r = int(np.ceil(3.5 * size_px * scale))
        x = np.arange(-r, r + 1, dtype=np.float32)
        g = np.exp(-0.5 * (x / (size_px * scale)) ** 2)
        k = np.outer(g, g)
    elif kind == "disk":
        r = int(np.ceil(size_px * scale)) + 1
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float32)
        k = np.clip(size_px * scale + 0.5 - np.hypot(xx, yy), 0.0, 1.0)
    else:  # motion: a straight streak of length size_px
        half = size_px * scale / 2
        r = int(np.ceil(half)) + 1
        k = np.zeros((2 * r + 1, 2 * r + 1), np.float32)
        n = max(int(4 * half), 2)
        for s in np.linspace(-half, half, n):
            x, y = r + s * np.cos(angle), r + s * np.sin(angle)
            x0, y0 = int(np.floor(x)), int(np.floor(y))
            fx, fy = x - x0, y - y0
            k[y0, x0] += (1 - fx) * (1 - fy)
            k[y0, x0 + 1] += fx * (1 - fy)
            k[y0 + 1, x0] += (1 - fx) * fy
            k[y0 + 1, x0 + 1] += fx * fy
    k = k.astype(np.float32)
    return k / k.sum()


def _render_marker(scene: np.ndarray, tex: np.ndarray, quiet_cells: int, cells: int, h_unit: np.ndarray,
                   bow_px: float, paper_margin: float, paper: float, psf: np.ndarray | None, ss: int,
                   margin_px: int) -> tuple[int, int, int, int]:
    """Draw one print into ``scene`` ((H, W, 3) linear, changed in place: it is this module's canvas);
    the rectangle drawn, (x0, y0, x1, y1), already blurred."""
    total = cells + 2 + 2 * quiet_cells  # texture cells per side
    ext = (total / (cells + 2)) * (1 + paper_margin)  # the paper's half-extent in unit-square units
    outline = _apply_h(h_unit, np.array([[-ext, -ext], [ext, -ext], [ext, ext], [-ext, ext]]))
    x0 = int(np.floor(outline[:, 0].min())) - margin_px
    y0 = int(np.floor(outline[:, 1].min())) - margin_px
    x1 = int(np.ceil(outline[:, 0].max())) + margin_px + 1
    y1 = int(np.ceil(outline[:, 1].max())) + margin_px + 1
    hh, ww = scene.shape[:2]
    if x0 < 0 or y0 < 0 or x1 > ww or y1 > hh:
        raise ValueError("patch outside the image")
    pw, ph = x1 - x0, y1 - y0
    # supersampled pixel (i, j) has its centre at image coordinate x0 + (i + 0.5) / ss - 0.5
    ii, jj = np.meshgrid(np.arange(pw * ss, dtype=np.float64), np.arange(ph * ss, dtype=np.float64))
    xs = x0 + (ii + 0.5) / ss - 0.5
    ys = y0 + (jj + 0.5) / ss - 0.5
    hinv = np.linalg.inv(h_unit)
    den = hinv[2, 0] * xs + hinv[2, 1] * ys + hinv[2, 2]
    u = (hinv[0, 0] * xs + hinv[0, 1] * ys + hinv[0, 2]) / den
    v = (hinv[1, 0] * xs + hinv[1, 1] * ys + hinv[1, 2]) / den
    # the bow: every horizontal line of the print sags by bow_px at its middle and not at all above
    # the corners (u = +-1), so the corners stay where the pose puts them; bow_px is converted to
    # unit-square units by the image scale (px per unit)
    scale_px = np.linalg.norm(outline[1] - outline[0]) / (2 * ext)
    v = v - (bow_px / scale_px) * (1.0 - np.clip(u, -1, 1) ** 2)
    n_tex = tex.shape[0]
    # unit square [-1, 1] is the black square: texture pixels quiet*ppc - 0.5 .. n - quiet*ppc - 0.5
    ppc = n_tex / total
    tu = ((u + 1) / 2 * (cells + 2) + quiet_cells) * ppc - 0.5
    tv = ((v + 1) / 2 * (cells + 2) + quiet_cells) * ppc - 0.5
    inside = (np.abs(u) <= ext) & (np.abs(v) <= ext)
    vals = cv2.remap(tex, tu.astype(np.float32), tv.astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=float(paper))
    under = cv2.resize(scene[y0:y1, x0:x1], (pw * ss, ph * ss), interpolation=cv2.INTER_LINEAR)
    alpha = inside.astype(np.float32)
    patch = under * (1 - alpha[:, :, None]) + (vals * alpha)[:, :, None]
    if psf is not None:
        patch = cv2.filter2D(patch, -1, psf, borderType=cv2.BORDER_REFLECT)
    down = cv2.resize(patch, (pw, ph), interpolation=cv2.INTER_AREA)
    m = margin_px // 2  # keep the outer half of the margin as it was: its blur came from outside
    scene[y0 + m:y1 - m, x0 + m:x1 - m] = down[m:ph - m, m:pw - m]
    return x0 + m, y0 + m, x1 - m, y1 - m


def _tone(x: np.ndarray, kind: str) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    if kind == "srgb":
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    # filmic: a toe and a shoulder (what phone pipelines do), normalised to map 1 -> 1
    a, b, c, d, e = 2.51, 0.03, 2.43, 0.59, 0.14
    f = lambda t: (t * (a * t + b)) / (t * (c * t + d) + e)  # noqa: E731
    return np.clip(f(x * 1.6) / f(1.6), 0.0, 1.0)


def render(rng: np.random.Generator, family: str, n_markers: int = 3,
           side_range: tuple[float, float] = (14.0, 90.0), supersample: int = 6) -> Frame:
    """One camera image of ``n_markers`` markers of ``family`` (a key of :data:`FAMILIES`)."""
    dictionary, cells = FAMILIES[family]
    colour = rng.random() < 0.6
    bayer = colour and rng.random() < 0.8
    scene = _background(rng, colour)
    n_ids = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)).bytesList.shape[0]
    ids = rng.choice(n_ids, size=n_markers, replace=False)
    truths: list[Truth] = []
    boxes: list[tuple[float, float, float]] = []
    drawn: list[tuple[int, int, int, int]] = []
    psf_kind = str(rng.choice(["gauss", "gauss", "disk", "motion"]))
    blur = {"gauss": rng.uniform(0.0, 1.3), "disk": rng.uniform(0.3, 2.0), "motion": rng.uniform(0.5, 5.0)}[psf_kind]
    angle = rng.uniform(0, np.pi)
    psf = _psf_kernel(psf_kind, blur, angle, supersample)
    margin = int(np.ceil(3.5 * blur)) + 4
    for mid in ids:
        for _ in range(200):
            side = float(np.exp(rng.uniform(np.log(side_range[0]), np.log(side_range[1]))))
            tilt = float(rng.uniform(0, 60))
            quiet = int(rng.integers(1, 3))
            paper_margin = float(rng.uniform(0.0, 0.6))
            reach = side * (cells + 2 + 2 * quiet) / (cells + 2) * (1 + paper_margin) / 2 * 2.2 + margin
            c = np.array([rng.uniform(reach, SHAPE[1] - reach), rng.uniform(reach, SHAPE[0] - reach)])
            if all(np.hypot(*(c - np.array(b[:2]))) > reach + b[2] for b in boxes):
                break
        else:
            continue
        h_unit = _pose_homography(rng, side, c, tilt)
        corners = _apply_h(h_unit, np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]))
        area = 0.5 * abs(_cross2(corners[2] - corners[0], corners[3] - corners[1]))
        ink, paper = float(rng.uniform(0.03, 0.15)), float(rng.uniform(0.6, 0.9))
        ppc = int(np.clip(np.ceil(side * supersample / (cells + 2)), 4, 48))
        tex = _marker_texture(dictionary, int(mid), cells, quiet, ppc, ink, paper,
                              float(rng.uniform(0.0, 0.04)), rng)
        try:
            rect = _render_marker(scene, tex, quiet, cells, h_unit, float(rng.uniform(0, 0.5)), paper_margin,
                           paper, psf, supersample, margin)
        except ValueError:
            continue
        boxes.append((float(c[0]), float(c[1]), reach))
        drawn.append(rect)
        truths.append(Truth(int(mid), corners, float(np.sqrt(area)), psf_kind, float(blur)))
    # the background outside the patches gets the PSF at image resolution; the patches were blurred finer
    psf1 = _psf_kernel(psf_kind, blur, angle, 1)
    blurred = scene if psf1 is None else cv2.filter2D(scene, -1, psf1, borderType=cv2.BORDER_REFLECT)
    out = _composite_blurred(scene, blurred, drawn)
    out = _glare_and_vignetting(rng, out, truths)
    gray, q, tone = _sensor_to_jpeg(rng, out, bayer)
    return Frame(gray, family, tuple(truths), bayer, q, tone)


def _composite_blurred(scene: np.ndarray, blurred: np.ndarray, drawn: list[tuple[int, int, int, int]]
                       ) -> np.ndarray:
    """The blurred background everywhere except inside each marker's patch, drawn already blurred."""
    out = blurred.copy()
    for x0, y0, x1, y1 in drawn:
        out[y0:y1, x0:x1] = scene[y0:y1, x0:x1]
    return out


def _glare_and_vignetting(rng: np.random.Generator, img: np.ndarray, truths: list[Truth]) -> np.ndarray:
    h, w = SHAPE
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    out = img.copy()
    for t in truths:
        if rng.random() < 0.4:  # a specular highlight somewhere on the print
            c = t.corners.mean(axis=0) + rng.uniform(-0.4, 0.4, 2) * t.side_px
            s = rng.uniform(0.15, 0.6) * t.side_px
            amp = rng.uniform(0.1, 0.6)
            out += (amp * np.exp(-0.5 * ((xx - c[0]) ** 2 + (yy - c[1]) ** 2) / s**2))[:, :, None]
    r2 = ((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    vig = 1.0 - rng.uniform(0.0, 0.45) * r2
    return out * vig[:, :, None]


def _sensor_to_jpeg(rng: np.random.Generator, linear: np.ndarray, bayer: bool) -> tuple[np.ndarray, int, str]:
    """Exposure, photon and read noise, the optional Bayer mosaic, tone, JPEG; the grey JPEG decoded."""
    full_well = rng.uniform(2000.0, 15000.0)
    exposure = rng.uniform(0.7, 1.15)  # 1: the brightest paper just below saturation
    read_e = rng.uniform(2.0, 8.0)
    wb = np.array([rng.uniform(0.7, 1.0), 1.0, rng.uniform(0.6, 1.0)], np.float32)  # B, G, R illuminant
    lin = linear * exposure * wb[None, None, :]
    if bayer:
        h, w = SHAPE
        mosaic = np.empty((h, w), np.float32)
        mosaic[0::2, 0::2] = lin[0::2, 0::2, 0]  # BGGR: B at (0, 0)
        mosaic[0::2, 1::2] = lin[0::2, 1::2, 1]
        mosaic[1::2, 0::2] = lin[1::2, 0::2, 1]
        mosaic[1::2, 1::2] = lin[1::2, 1::2, 2]
        e = rng.poisson(np.clip(mosaic, 0, None) * full_well).astype(np.float32)
        e += rng.normal(0, read_e, e.shape).astype(np.float32)
        raw = np.clip(e / full_well, 0, 1)
        raw16 = (raw * 65535 + 0.5).astype(np.uint16)
        rgb = cv2.cvtColor(raw16, cv2.COLOR_BayerRG2BGR).astype(np.float32) / 65535
        # OpenCV names Bayer patterns by the second row's first two pixels: BGGR is its "RG"
    else:
        e = rng.poisson(np.clip(lin, 0, None) * full_well).astype(np.float32)
        e += rng.normal(0, read_e, e.shape).astype(np.float32)
        rgb = np.clip(e / full_well, 0, 1)
    rgb = rgb / wb[None, None, :]
    tone = str(rng.choice(["srgb", "filmic"]))
    levels = np.clip(_tone(rgb, tone) * 255 + 0.5, 0, 255).astype(np.uint8)
    q = int(rng.integers(60, 96))
    ok, buf = cv2.imencode(".jpg", levels, [cv2.IMWRITE_JPEG_QUALITY, q])
    assert ok
    bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY), q, tone


@dataclass
class Score:
    """One detector's tally on rendered frames, by side bin: found, total, wrong, squared corner errors."""

    bins: tuple[float, ...] = (0.0, 14.0, 20.0, 40.0, 1e9)
    found: list[int] = field(init=False)
    total: list[int] = field(init=False)
    sq_err: list[list[float]] = field(init=False)
    wrong: int = 0
    ms: list[float] = field(default_factory=list)
    wrong_dets: list[tuple[int, float]] = field(default_factory=list)  # (ID, side px) of each wrong one

    def __post_init__(self) -> None:
        n = len(self.bins) - 1
        self.found, self.total = [0] * n, [0] * n
        self.sq_err = [[] for _ in range(n)]

    def bin_of(self, side: float) -> int:
        return int(np.searchsorted(self.bins, side, side="right") - 1)

    def add(self, frame: Frame, dets: list[tuple[int, np.ndarray]], ms: float) -> set[int]:
        """Score one frame's detections ((ID, (4, 2) corners) each); the IDs found correctly."""
        self.ms.append(ms)
        truth = {t.id: t for t in frame.truths}
        ok: set[int] = set()
        for mid, c in dets:
            t = truth.get(mid)
            # a detection is right when it names a marker that is there and its corners lie on that
            # marker's in the same order; anything else is a wrong ID (or a right ID in the wrong place)
            off = np.inf if t is None else float(np.max(np.linalg.norm(c - t.corners, axis=1)))
            if t is None or mid in ok or off > max(2.0, 0.25 * t.side_px):
                self.wrong += 1
                self.wrong_dets.append((mid, float(np.sqrt(0.5 * abs(_cross2(c[2] - c[0], c[3] - c[1]))))))
                continue
            ok.add(mid)
            b = self.bin_of(t.side_px)
            self.found[b] += 1
            self.sq_err[b].extend(np.sum((c - t.corners) ** 2, axis=1).tolist())
        for t in frame.truths:
            self.total[self.bin_of(t.side_px)] += 1
        return ok

    def recall(self, lo: float = 0.0) -> float:
        i = self.bin_of(lo)
        tot = sum(self.total[i:])
        return sum(self.found[i:]) / tot if tot else float("nan")

    def rms(self, lo: float = 0.0) -> float:
        e = [x for row in self.sq_err[self.bin_of(lo):] for x in row]
        return float(np.sqrt(np.mean(e))) if e else float("nan")
