"""Camera image formation: supersampled projection of planar textured faces through a real lens.

The renderer never draws features where a detector will later find them; it forms the image the way a
camera does, in this order:

1. **Scene to ideal image.** Each planar face (floor, wall, box side, robot plate, marker, chessboard)
   carries a texture; its homography to the *undistorted* (ideal pinhole) image is applied with
   ``cv2.warpPerspective`` at ``s`` times the output resolution, faces painted far to near and cut to
   their outline (clipped at the near plane). Textures are sampled bilinearly at about one texel per
   supersample, so that every printed edge is a ramp about one supersample wide centred exactly on the
   edge: averaging the supersamples then places edges continuously rather than on a 1/s grid.
2. **Lens distortion.** For every supersample of the *distorted* output image its ideal location is
   looked up (the inverse of OpenCV's distortion model, solved once per camera by fixed-point
   iteration) and the ideal image is resampled there with ``cv2.remap``.
3. **Pixel integration.** ``cv2.resize(..., INTER_AREA)`` by the integer factor ``s`` averages each
   s x s block: a pixel is the mean of its area.

Pixel convention (OpenCV): pixel centres at integer coordinates. A supersample ``X`` of factor ``s``
sits at output coordinate ``x = (X + 0.5) / s - 0.5``; a texel ``c`` of a texture spanning ``[x0, x1]``
with ``N`` texels sits at ``x0 + (c + 0.5) (x1 - x0) / N``.

Layers are kept premultiplied (colour times coverage) so that a foreground layer (robot, chessboard)
rendered in a small region of interest composites over a precomputed background with antialiased
outlines. The finishing steps (defocus and motion blur, vignetting, shot and read noise, 8-bit
quantisation) are in :func:`finish` and :func:`defocus_sigma_px`; their physical sources are listed in
``docs/simulator.md``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.rig.models import Camera

NEAR_M = 0.05  # faces are clipped this close to the camera centre


@dataclass(frozen=True)
class PinholeCamera:
    """An OpenCV camera model: ``K`` (3, 3), ``dist`` (k1, k2, p1, p2, k3[, ...]), ``size`` (w, h) px."""

    K: np.ndarray
    dist: np.ndarray
    size: tuple[int, int]

    @staticmethod
    def from_rig(cam: Camera) -> PinholeCamera:
        return PinholeCamera(cam.K.copy(), cam.dist.copy(), (int(cam.resolution[0]), int(cam.resolution[1])))

    def key(self) -> tuple[bytes, bytes, tuple[int, int]]:
        return (np.asarray(self.K, float).tobytes(), np.asarray(self.dist, float).tobytes(), self.size)

    def project(self, T_world_cam: np.ndarray, p_world: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) of world points (N, 3); points behind the camera give NaN."""
        p_cam = geo.transform_points(geo.inv_T(T_world_cam), np.asarray(p_world, float).reshape(-1, 3))
        uv = geo.project_points(p_cam, self.K, self.dist)
        uv[p_cam[:, 2] <= NEAR_M] = np.nan
        return uv


@dataclass(frozen=True, eq=False)
class Face:
    """A planar, opaque, textured polygon.

    Attributes
    ----------
    T_world_face : (4, 4) pose of the face frame; the face lies in its z = 0 plane and is seen from +z
        (unless ``two_sided``).
    outline_xy : (N, 2) convex polygon in the face frame, metres.
    texture : (rows, cols) float32 texture (linear radiance, about 0..1).
    A_face_tex : (3, 3) affine map from texel coordinates ``(col, row, 1)`` (texel centres at integers)
        to face coordinates ``(x, y, 1)`` in metres.
    two_sided : draw also when seen from behind.
    """

    T_world_face: np.ndarray
    outline_xy: np.ndarray
    texture: np.ndarray
    A_face_tex: np.ndarray
    two_sided: bool = False
    name: str = field(default="", compare=False)


def texture_affine(x0: float, y_top: float, texel_m_x: float, texel_m_y: float) -> np.ndarray:
    """``A_face_tex`` of a texture whose top-left texel corner is at face point ``(x0, y_top)``, columns
    running along +x and rows along -y (image-like, y up as printed), with the given texel sizes."""
    return np.array([
        [texel_m_x, 0.0, x0 + 0.5 * texel_m_x],
        [0.0, -texel_m_y, y_top - 0.5 * texel_m_y],
        [0.0, 0.0, 1.0],
    ])


# ------------------------------------------------------------------------------------------- lens model
@functools.lru_cache(maxsize=16)
def _undistort_map_cached(key: tuple[bytes, bytes, tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    K = np.frombuffer(key[0]).reshape(3, 3)
    dist = np.frombuffer(key[1])
    w, h = key[2]
    # Solved exactly on a grid of every second pixel, then interpolated bilinearly: the map is smooth
    # (second derivative ~1e-4 px per px^2 for k1 ~ -0.1), so the interpolation error is ~1e-4 px.
    gx = np.arange(-2, w + 3, 2, dtype=float)
    gy = np.arange(-2, h + 3, 2, dtype=float)
    u, v = np.meshgrid(gx, gy)
    ideal = undistort_pixels(np.column_stack([u.ravel(), v.ravel()]), K, dist)
    cx = ideal[:, 0].reshape(u.shape)
    cy = ideal[:, 1].reshape(u.shape)
    # full map with one pixel of margin: pixel x in -1..w sits at grid coordinate (x + 2) / 2
    qx, qy = np.meshgrid((np.arange(-1, w + 1) + 2) / 2.0, (np.arange(-1, h + 1) + 2) / 2.0)
    ix = np.minimum(qx.astype(int), len(gx) - 2)
    iy = np.minimum(qy.astype(int), len(gy) - 2)
    fx, fy = qx - ix, qy - iy

    def interp(c: np.ndarray) -> np.ndarray:
        top = c[iy, ix] * (1 - fx) + c[iy, ix + 1] * fx
        bot = c[iy + 1, ix] * (1 - fx) + c[iy + 1, ix + 1] * fx
        return (top * (1 - fy) + bot * fy).astype(np.float32)

    return interp(cx), interp(cy)


def undistort_pixels(uv: np.ndarray, K: np.ndarray, dist: np.ndarray, iterations: int = 60) -> np.ndarray:
    """Ideal (undistorted) pixel coordinates (N, 2) of distorted pixels ``uv`` (N, 2).

    Inverts :func:`gtrig.geometry.project_points` by fixed-point iteration in normalised coordinates
    (the same scheme as OpenCV's ``undistortPoints``, run to convergence in float64).
    """
    K = np.asarray(K, float)
    d = np.zeros(8)
    dc = np.asarray(dist, float).ravel()
    d[: min(8, dc.size)] = dc[:8]
    k1, k2, p1, p2, k3, k4, k5, k6 = d
    uv = np.asarray(uv, float).reshape(-1, 2)
    yd = (uv[:, 1] - K[1, 2]) / K[1, 1]
    xd = (uv[:, 0] - K[0, 2] - K[0, 1] * yd) / K[0, 0]
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        xn = (xd - dx) / radial
        yn = (yd - dy) / radial
        step = max(float(np.max(np.abs(xn - x), initial=0.0)), float(np.max(np.abs(yn - y), initial=0.0)))
        x, y = xn, yn
        if step < 1e-12:
            break
    return np.column_stack([K[0, 0] * x + K[0, 1] * y + K[0, 2], K[1, 1] * y + K[1, 2]])


def undistort_map(cam: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """Ideal pixel coordinates of every distorted pixel, ``(h + 2, w + 2)`` float32 each, with one pixel
    of margin: entry ``[v + 1, u + 1]`` belongs to distorted pixel ``(u, v)``. Cached per camera."""
    return _undistort_map_cached(cam.key())


def _super_map(cam: PinholeCamera, roi: tuple[int, int, int, int], s: int) -> tuple[np.ndarray, np.ndarray]:
    """Ideal coordinates of the supersamples of output region ``roi`` = (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = roi
    mx, my = undistort_map(cam)
    # crop with one pixel of margin (the map itself has one), upsample with the half-pixel convention
    # (cv2.resize INTER_LINEAR samples source (X + 0.5) / s - 0.5), drop the margin
    cx = mx[y0: y1 + 2, x0: x1 + 2]
    cy = my[y0: y1 + 2, x0: x1 + 2]
    if s == 1:
        return cx[1:-1, 1:-1], cy[1:-1, 1:-1]
    size = ((x1 - x0 + 2) * s, (y1 - y0 + 2) * s)
    ux = cv2.resize(cx, size, interpolation=cv2.INTER_LINEAR)[s:-s, s:-s]
    uy = cv2.resize(cy, size, interpolation=cv2.INTER_LINEAR)[s:-s, s:-s]
    return ux, uy


# --------------------------------------------------------------------------------------------- drawing
def _clip_near(p_cam: np.ndarray, near: float = NEAR_M) -> np.ndarray:
    """Sutherland-Hodgman clip of a polygon (N, 3) to z >= near."""
    out = []
    n = len(p_cam)
    for i in range(n):
        a, b = p_cam[i], p_cam[(i + 1) % n]
        ina, inb = a[2] >= near, b[2] >= near
        if ina:
            out.append(a)
        if ina != inb:
            t = (near - a[2]) / (b[2] - a[2])
            out.append(a + t * (b - a))
    return np.array(out).reshape(-1, 3)


@dataclass(frozen=True)
class Layer:
    """A rendered layer over an output region: premultiplied ``colour`` and ``alpha`` (h, w) float32,
    ``roi`` = (x0, y0, x1, y1) in output pixels, optional ``inv_depth`` (1/m, premultiplied)."""

    colour: np.ndarray
    alpha: np.ndarray
    roi: tuple[int, int, int, int]
    inv_depth: np.ndarray | None = None


def render_layer(
    cam: PinholeCamera,
    T_world_cam: np.ndarray,
    faces: list[Face],
    roi: tuple[int, int, int, int] | None = None,
    s: int = 4,
    with_depth: bool = False,
) -> Layer:
    """Render ``faces`` (painted in the given order, far to near) over ``roi`` of the distorted image.

    Parameters
    ----------
    cam : the true camera model.
    T_world_cam : (4, 4) camera pose (OpenCV camera frame).
    faces : faces in painter's order (each later face covers the earlier ones).
    roi : (x0, y0, x1, y1) output pixels, x1/y1 exclusive; default the whole image.
    s : supersampling factor.
    with_depth : also render the inverse depth (1/m) of the visible surface (for defocus).

    Returns
    -------
    Layer
        Premultiplied colour and coverage at output resolution.
    """
    w, h = cam.size
    if roi is None:
        roi = (0, 0, w, h)
    x0, y0, x1, y1 = roi
    ux, uy = _super_map(cam, roi, s)
    # ideal-image window covering the region (plus margin for bilinear lookups), in ideal pixels
    u0 = math.floor(float(ux.min())) - 2
    v0 = math.floor(float(uy.min())) - 2
    u1 = math.ceil(float(ux.max())) + 3
    v1 = math.ceil(float(uy.max())) + 3
    W, H = (u1 - u0) * s, (v1 - v0) * s
    # ideal pixel (u, v) -> supersample (X, Y) of the window
    S = np.array([[s, 0.0, -s * u0 + (s - 1) / 2], [0.0, s, -s * v0 + (s - 1) / 2], [0.0, 0.0, 1.0]])
    col = np.zeros((H, W), np.float32)
    cover = np.zeros((H, W), np.uint8)
    inv_depth = np.zeros((H, W), np.float32) if with_depth else None
    T_cam_world = geo.inv_T(T_world_cam)
    K = np.asarray(cam.K, float)
    for face in faces:
        T_cam_face = T_cam_world @ face.T_world_face
        R, t = T_cam_face[:3, :3], T_cam_face[:3, 3]
        normal, d = R[:, 2], float(R[:, 2] @ t)
        if not face.two_sided and d >= 0:
            continue  # seen from behind
        poly3 = np.column_stack([face.outline_xy, np.zeros(len(face.outline_xy))]) @ R.T + t
        poly3 = _clip_near(poly3)
        if len(poly3) < 3:
            continue
        q = (S @ K @ poly3.T).T
        q = q[:, :2] / q[:, 2:3]
        bx0 = max(0, math.floor(float(q[:, 0].min())))
        by0 = max(0, math.floor(float(q[:, 1].min())))
        bx1 = min(W, math.ceil(float(q[:, 0].max())) + 1)
        by1 = min(H, math.ceil(float(q[:, 1].max())) + 1)
        if bx1 <= bx0 or by1 <= by0:
            continue
        bw, bh = bx1 - bx0, by1 - by0
        P = np.column_stack([R[:, 0], R[:, 1], t])  # face (x, y, 1) -> camera ray
        M = np.array([[1.0, 0, -bx0], [0, 1.0, -by0], [0, 0, 1]]) @ S @ K @ P @ face.A_face_tex
        warped = cv2.warpPerspective(
            face.texture, np.linalg.inv(M), (bw, bh),
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE,
        )
        mask = np.zeros((bh, bw), np.uint8)
        shift = 8
        pts = np.round((q - [bx0, by0]) * (1 << shift)).astype(np.int32)
        cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=shift)
        np.copyto(col[by0:by1, bx0:bx1], warped, where=mask.view(bool))
        np.bitwise_or(cover[by0:by1, bx0:bx1], mask, out=cover[by0:by1, bx0:bx1])
        if inv_depth is not None:
            # 1/z is affine in the ideal image for a plane n.X = d: 1/z = n.(x_n, y_n, 1) / d
            a = normal @ np.linalg.inv(S @ K) / d
            iz = np.add.outer(np.float32(a[1]) * np.arange(by0, by1, dtype=np.float32) + np.float32(a[2]),
                              np.float32(a[0]) * np.arange(bx0, bx1, dtype=np.float32))
            np.copyto(inv_depth[by0:by1, bx0:bx1], np.abs(iz), where=mask.view(bool))
    # distorted supersamples look up their ideal location in the window
    mapx = ux * np.float32(s) + np.float32(-s * u0 + (s - 1) / 2)
    mapy = uy * np.float32(s) + np.float32(-s * v0 + (s - 1) / 2)
    planes = [col, cover.astype(np.float32)] + ([inv_depth] if inv_depth is not None else [])
    out = []
    for pl in planes:
        r = cv2.remap(pl, mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if s > 1:
            r = cv2.resize(r, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
        out.append(r)
    return Layer(out[0], out[1], roi, out[2] if with_depth else None)


# ------------------------------------------------------------------------------------------- finishing
def defocus_sigma_px(inv_depth: np.ndarray | float, sigma_edge_px: float, near_m: float = 2.0,
                     far_m: float = 5.0) -> np.ndarray:
    """Gaussian sigma (px) of defocus blur, thin-lens model.

    The blur circle's diameter is proportional to ``|1/d_focus - 1/d|`` (aperture times image
    distance). The lens is focused so that the depth of field ``[near_m, far_m]`` is sharp within
    ``sigma_edge_px``: ``1/d_focus`` is the mean of ``1/near`` and ``1/far``.
    """
    inv_f = 0.5 * (1 / near_m + 1 / far_m)
    half = 0.5 * (1 / near_m - 1 / far_m)
    return sigma_edge_px * np.abs(inv_f - np.asarray(inv_depth, dtype=float)) / half


def blur_by_depth(img: np.ndarray, sigma_px: np.ndarray, levels: int = 5) -> np.ndarray:
    """Spatially varying Gaussian blur: ``img`` blurred at a few sigmas, then per pixel interpolated
    between the two levels bracketing ``sigma_px`` (h, w)."""
    smax = float(np.max(sigma_px)) if sigma_px.size else 0.0
    if smax < 0.05:
        return img
    sig = np.linspace(0.0, smax, levels)
    stack = [img] + [cv2.GaussianBlur(img, (0, 0), float(x)) for x in sig[1:]]
    pos = np.clip(sigma_px / smax * (levels - 1), 0, levels - 1 - 1e-6)
    i = pos.astype(np.int32)
    f = (pos - i).astype(np.float32)
    st = np.stack(stack)
    rows, cols = np.indices(img.shape)
    return (st[i, rows, cols] * (1 - f) + st[i + 1, rows, cols] * f).astype(np.float32)


def vignetting_map(cam: PinholeCamera, falloff: float) -> np.ndarray:
    """Relative illumination (h, w) float32: natural cos^4 fall-off of the off-axis angle scaled so that
    the image corners lose ``falloff`` of the centre's light."""
    w, h = cam.size
    K = cam.K
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    r2 = ((u - K[0, 2]) / K[0, 0]) ** 2 + ((v - K[1, 2]) / K[1, 1]) ** 2
    cos4 = 1.0 / (1.0 + r2) ** 2
    cmin = float(cos4.min())
    if falloff <= 0 or cmin >= 1:
        return np.ones((h, w), np.float32)
    return (1.0 - falloff * (1.0 - cos4) / (1.0 - cmin)).astype(np.float32)


@functools.lru_cache(maxsize=2)
def _noise_pool(n: int) -> np.ndarray:
    # A fixed pool of standard normal samples, identical in every process; a frame uses a window at a
    # random offset (and a random sign): drawing 0.8 M fresh normals per frame costs a third of the
    # frame budget, while pixels within a frame stay independent.
    return np.random.default_rng(0x5EED).standard_normal(n, dtype=np.float32)


def noise_sd(img_levels: np.ndarray, sigma_mid: float) -> np.ndarray:
    """Per-pixel noise standard deviation (grey levels) of :func:`add_sensor_noise`."""
    read = 0.5 * sigma_mid
    gain = (sigma_mid ** 2 - read ** 2) / 128.0
    return cv2.sqrt(np.maximum(img_levels, 0) * np.float32(gain) + np.float32(read ** 2))


def add_sensor_noise(img_levels: np.ndarray, sigma_mid: float, rng: np.random.Generator,
                     sd: np.ndarray | None = None) -> np.ndarray:
    """Shot plus read noise on an image in 8-bit grey levels, then rounding and clipping to uint8.

    Variance ``read^2 + g * I``: read noise is half of ``sigma_mid``, the rest of the variance at mid
    grey (128) is photon shot noise, which grows linearly with the signal. ``sd`` (h, w), if given,
    is the precomputed :func:`noise_sd` of the image.
    """
    if sigma_mid <= 0:
        return np.clip(np.rint(img_levels), 0, 255).astype(np.uint8)
    n = img_levels.size
    pool = _noise_pool(1 << 22)
    off = int(rng.integers(0, pool.size - n))
    noise = pool[off: off + n].reshape(img_levels.shape)
    if sd is None:
        sd = noise_sd(img_levels, sigma_mid)
    sign = np.float32(1.0 if rng.random() < 0.5 else -1.0)
    out = img_levels + sd * noise * sign
    return cv2.convertScaleAbs(out)  # rounds and saturates to 0..255


def encode_png(img: np.ndarray, compression: int = 1) -> bytes:
    """8-bit PNG; the SUB filter with Huffman-only coding is about 3x faster than zlib's default on
    noisy images and compresses them as well."""
    ok, buf = cv2.imencode(".png", img, [
        cv2.IMWRITE_PNG_COMPRESSION, int(compression),
        cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY,
        cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB,
    ])
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def composite(base: np.ndarray, layer: Layer, sigma_px: float = 0.0,
              gain: np.ndarray | None = None) -> None:
    """Composite ``layer`` over ``base`` (h, w) in place, blurring the layer's premultiplied colour and
    coverage by ``sigma_px`` first (defocus of an object at one depth), and multiplying its colour by
    ``gain`` (the vignetting crop) if given."""
    x0, y0, x1, y1 = layer.roi
    c, a = layer.colour, layer.alpha
    if sigma_px > 0.05:
        c = cv2.GaussianBlur(c, (0, 0), sigma_px)
        a = cv2.GaussianBlur(a, (0, 0), sigma_px)
    if gain is not None:
        c = c * gain[y0:y1, x0:x1]
    region = base[y0:y1, x0:x1]
    region *= 1.0 - a
    region += c
