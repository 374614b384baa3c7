"""The camera's tone curve: grey levels to light and back, for the edge fits.

The blurred-step model of :mod:`.edges` is linear in light: the optics blur the light, and the
sensor's value is proportional to it. Machine-vision cameras (and :mod:`gtrig.markers.synth`) store
that value; phones and webcams store it through a tone curve, about sRGB's. Through the curve a
blurred step is no longer symmetric: its midpoint between the black and the white levels lies
inside the black, by a share of the blur, so the fitted square shrinks. On the 12 MP phone photo
``taggridphoto.jpg`` (233 px AprilTags, edges blurred by about 2 px) the corners fitted in the
stored levels were 0.1 px (x) and 0.4 px (y) inside OpenCV's gradient-based SUBPIX corners, and the
grid fit's residual 1.705 px against SUBPIX's 1.493 (docs/markers.md). A corner found from gradient
directions (``cornerSubPix``) does not depend on the curve, a midpoint does: the edge fits take the
band's values back to light first (``DetectorParams(tone="srgb")``).
"""

from __future__ import annotations

import functools
from typing import Literal

import numpy as np
from numpy.typing import NDArray

Tone = Literal["linear", "srgb"]


def srgb_to_linear(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """sRGB-encoded grey levels (0-255) to linear light on the same 0-255 scale (IEC 61966-2-1)."""
    x = np.asarray(v, np.float64) / 255.0
    return 255.0 * np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Linear light (0-255) to sRGB-encoded grey levels (0-255), :func:`srgb_to_linear`'s inverse."""
    x = np.clip(np.asarray(v, np.float64) / 255.0, 0.0, 1.0)
    return 255.0 * np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1.0 / 2.4) - 0.055)


@functools.lru_cache(maxsize=2)
def light_table(tone: Tone) -> NDArray[np.float64]:
    """Light (256,) of each 8-bit level, made once per tone (shared: not to be written). Levels 1-254 stay
    strictly inside (0.5, 254.5): the edge fits take the levels beyond those bounds for clipped pixels
    (:data:`.edges.CLIP_LOW`), which in light the darkest unclipped levels (1-6 in sRGB) would otherwise
    reach."""
    g = np.arange(256, dtype=np.float64)
    if tone == "linear":
        return g
    lin = srgb_to_linear(g)
    lin[1:255] = np.clip(lin[1:255], 0.51, 254.49)
    return lin


def to_light(values: NDArray[np.float64], tone: Tone) -> NDArray[np.float64]:
    """8-bit grey levels (any shape, integer-valued) as light on the 0-255 scale."""
    if tone == "linear":
        return values
    return light_table(tone)[np.clip(np.rint(values), 0, 255).astype(np.intp)]


def to_levels(light: NDArray[np.float64], tone: Tone) -> NDArray[np.float64]:
    """Light (0-255) as stored grey levels: :func:`to_light`'s inverse."""
    if tone == "linear":
        return light
    return linear_to_srgb(light)
