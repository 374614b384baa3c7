"""docs/recording.md quotes the stages' thresholds and the simulator's defaults: they match the code, and
its first commands run as written."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

from typer.testing import CliRunner

from gtrig.calib import intrinsics, steady
from gtrig.cli.main import app
from gtrig.config import FusionConfig
from gtrig.laser import background
from gtrig.sim.config import SimConfig

DOC = Path(__file__).resolve().parents[2] / "docs" / "recording.md"
runner = CliRunner()


def _text() -> str:
    return re.sub(r"\s+", " ", DOC.read_text())


def test_quoted_figures_match_the_code() -> None:
    t = _text()
    sim = SimConfig()
    quoted = [
        f"{sim.n_intrinsic_views} views (a minute of video at 2 Hz)",
        f"at least {intrinsics.MIN_VIEWS} or the camera is refused",
        f"below {intrinsics.COVERAGE_WARN * 100:.0f} % of the image covered",
        f"tilted over {intrinsics.TILT_WARN_DEG:g} deg",
        f"principal point sigma above {intrinsics.PP_SIGMA_WARN_PX:g} px",
        f"{sim.n_pair_views} instants",
        f"| {sim.n_world_board_views} views |",
        f"moved {steady.SHIFT_PX:g} px or whose board moved {steady.MOVE_MM:g} mm / {steady.TURN_DEG:g} deg",
        f"Take **{sim.n_handheld_views} images**",
        f"**at least {sim.static_pose_s:g} s**",
        f"at least **{sim.background_s:g} s**",
        f"in at least {background.MIN_RETURN_FRACTION * 100:.0f} % of the scans",
        f"+-`fusion.sync_search_s` ({FusionConfig().sync_search_s:g} s by default, up to 60)",
        f"the first and last {FusionConfig().sync_search_s:g} s are not used",
    ]
    for phrase in quoted:
        assert phrase in t, phrase


def test_first_commands_run(tmp_path: Path) -> None:
    """Section 0's rig init, rig check and markers make --rig, as written (in a scratch REC)."""
    block = DOC.read_text().split("```bash", 1)[1].split("```", 1)[0]
    lines = [ln.split("#")[0].strip() for ln in block.strip().splitlines()]
    (tmp_path / "REC").mkdir()
    for line in lines:
        args = shlex.split(line)
        assert args[0] == "gtrig"
        if "--boards" in args:
            continue  # needs a recording's calib/boards.yaml: tests/markers/test_sheets.py prints one
        args = [str(tmp_path / a) if a.startswith(("REC/", "markers.pdf")) else a for a in args[1:]]
        r = runner.invoke(app, args)
        assert r.exit_code == 0, (line, r.output)
    assert (tmp_path / "markers.pdf").read_bytes().startswith(b"%PDF")
