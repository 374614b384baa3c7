"""What a simulated recording's truth says about its clocks, for the stages' accuracy rows."""

from __future__ import annotations

from pathlib import Path


def true_odometry_offset(rec: Path) -> float:
    """The simulated odometry clock minus the GT clock (truth/robot_clock.yaml; 0 when absent). A source's
    offset to odometry is then its own clock (the GT clock) minus odometry's: ``-offset``."""
    from gtrig.io.yamlfile import load_yaml

    p = rec / "truth" / "robot_clock.yaml"
    if not p.is_file():
        return 0.0
    doc = load_yaml(p) or {}
    return -float(doc.get("offset_s", 0.0)) if isinstance(doc, dict) else 0.0
