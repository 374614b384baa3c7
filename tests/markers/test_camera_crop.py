"""A declared crop's lens maps (gtrig.markers.detect.camera.declare_crop): the whole image's maps over the
crop, shifted by its corner, whatever crops came before, and the crop's own computation within float32's
rounding."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.markers.detect.camera import Undistorter, declare_crop

K = np.array([[1501.62, 0.0, 509.515], [0.0, 1502.15, 388.79], [0.0, 0.0, 1.0]])
DIST = np.array([-0.1105, 0.0858, -2.1e-4, -9.8e-5, 0.0])
SHAPE = (768, 1024)
BOXES = ((256, 192, 512, 448), (512, 256, 1024, 768), (0, 0, 384, 384), (640, 0, 1024, 384))


def _crop(box: tuple[int, int, int, int]) -> Undistorter:
    K_crop = declare_crop(K, DIST, SHAPE, box)
    np.testing.assert_array_equal(K_crop[:, 2], K[:, 2] - [box[0], box[1], 0])
    return Undistorter(K_crop, DIST, (box[3] - box[1], box[2] - box[0]))


def test_a_crops_maps_are_the_whole_images_over_it() -> None:
    whole = Undistorter(K, DIST, SHAPE)
    for box in BOXES:
        u = _crop(box)
        x0, y0, x1, y1 = box
        np.testing.assert_array_equal(u.map_x + np.float32(x0), whole.map_x[y0:y1, x0:x1])
        np.testing.assert_array_equal(u.map_y + np.float32(y0), whole.map_y[y0:y1, x0:x1])
        # the crop's own computation differs by float32's rounding at the whole image's coordinates
        own_x, own_y = Undistorter._compute(u.K, DIST, u.shape)
        assert np.abs(u.map_x - own_x).max() < 1e-4
        assert np.abs(u.map_y - own_y).max() < 1e-4
        # and the maps still take a raw pixel to where the lens model puts it
        uv_raw = np.array([[3.0, 5.0], [x1 - x0 - 2.0, y1 - y0 - 3.0]])
        und = u.to_undistorted(uv_raw)
        np.testing.assert_allclose(und, [[u.map_x[5, 3], u.map_y[5, 3]],
                                         [u.map_x[-3, -2], u.map_y[-3, -2]]], atol=1e-3)


def test_a_crops_maps_do_not_depend_on_the_crops_before_it() -> None:
    first = [_crop(b) for b in BOXES]
    again = [_crop(b) for b in reversed(BOXES)][::-1]
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a.map_x, b.map_x)
        np.testing.assert_array_equal(a.map_y, b.map_y)


def test_a_crop_outside_the_image_is_refused() -> None:
    with pytest.raises(ValueError, match="not inside"):
        declare_crop(K, DIST, SHAPE, (900, 0, 1100, 100))
