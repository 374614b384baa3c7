"""The camera's tone curve (gtrig.markers.detect.tone): a marker rendered in light and stored through
sRGB's curve, as a phone stores it, is fitted in light with ``tone="srgb"``."""

from __future__ import annotations

import numpy as np

from gtrig.markers.detect import DetectorParams, MarkerDetector
from gtrig.markers.detect.tone import linear_to_srgb, srgb_to_linear, to_levels, to_light
from gtrig.markers.synth import homography_from_pose, render

FAMILY = "apriltag_36h11"


def test_round_trip_and_clip_bounds() -> None:
    v = np.arange(256, dtype=np.float64)
    assert np.allclose(linear_to_srgb(srgb_to_linear(v)), v, atol=1e-9)
    light = to_light(v, "srgb")
    # levels 1-254 stay inside the edge fits' clip bounds; 0 and 255 are the clipped ones
    assert light[0] == 0.0 and light[255] == 255.0 and light[1:255].min() > 0.5 and light[1:255].max() < 254.5
    assert np.allclose(to_levels(light[7:], "srgb"), v[7:], atol=1e-9)
    assert to_light(v, "linear") is v


def test_srgb_stored_marker_fits_better_in_light() -> None:
    """A blurred marker (sigma 2 px) stored through sRGB: the midpoint of the stored levels lies inside
    the black, so the corners fitted in stored levels are pulled in (0.3-0.4 px); fitted in light they
    are back on the truth."""
    shape = (260, 260)
    H = homography_from_pose(150, (130, 130), 20, 30, 10)
    stored, truths = render(shape, [(FAMILY, 7, H)], blur_px=2.0, noise=0.5, rng=np.random.default_rng(3), srgb=True)
    err = {}
    for tone in ("linear", "srgb"):
        dets = MarkerDetector(FAMILY, params=DetectorParams(tone=tone)).detect(stored)
        assert [d.id for d in dets] == [7]
        err[tone] = float(np.sqrt(np.mean(np.sum((dets[0].corners_px - truths[0].corners_px) ** 2, axis=1))))
    assert err["srgb"] < 0.1 < err["linear"], err


def test_cli_reads_each_file_in_the_tone_it_declares(tmp_path) -> None:
    """``gtrig markers detect`` (``--tone auto``): the same sRGB-stored marker as a JPEG (display
    encoded) is fitted in light, as a PNG written by OpenCV (no claim) in stored levels; ``--tone
    srgb`` overrides the PNG's. The JSON says which tone each file was read in."""
    import json

    import cv2
    from typer.testing import CliRunner

    from gtrig.cli.main import app

    H = homography_from_pose(150, (130, 130), 20, 30, 10)
    stored, truths = render((260, 260), [(FAMILY, 7, H)], blur_px=2.0, noise=0.5, rng=np.random.default_rng(3),
                            srgb=True)
    cv2.imwrite(str(tmp_path / "phone.jpg"), stored, [cv2.IMWRITE_JPEG_QUALITY, 98])
    cv2.imwrite(str(tmp_path / "machine.png"), stored)
    runner = CliRunner()

    def run(*extra: str) -> dict[str, tuple[str, float]]:
        out = tmp_path / "det.json"
        r = runner.invoke(app, ["markers", "detect", str(tmp_path), "--family", FAMILY, "--out", str(out), *extra])
        assert r.exit_code == 0, r.output
        res = {}
        for im in json.loads(out.read_text())["images"]:
            (d,) = im["detections"]
            err = np.sqrt(np.mean(np.sum((np.array(d["corners"]) - truths[0].corners_px) ** 2, axis=1)))
            res[im["file"].rsplit("/", 1)[-1]] = (im["tone"], float(err))
        return res

    auto = run()
    assert auto["phone.jpg"][0] == "srgb" and auto["machine.png"][0] == "linear"
    assert auto["phone.jpg"][1] < 0.15 < auto["machine.png"][1], auto
    forced = run("--tone", "srgb")
    assert forced["machine.png"][0] == "srgb" and forced["machine.png"][1] < 0.1, forced
    r = runner.invoke(app, ["markers", "detect", str(tmp_path), "--family", FAMILY, "--out",
                            str(tmp_path / "x.json"), "--tone", "gamma"])
    assert r.exit_code == 2 and "--tone 'gamma'" in r.output and not (tmp_path / "x.json").exists()
