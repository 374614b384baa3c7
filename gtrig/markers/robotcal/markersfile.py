"""``markers.yaml`` (the calibrated marker poses), the anchor pose argument, and merging into a rig.

``markers.yaml``::

    anchor: 14
    markers:                       # one entry per calibrated marker, the anchor included
    - family: artoolkitplus_simple   # these four fields are a rig.yaml ``robot.markers`` entry
      id: 3
      side_m: 0.156
      T_robot_marker: {xyz: [x, y, z], quat_xyzw: [qx, qy, qz, qw]}
      covariance: [[...] x 6]        # (dt, dphi), robot axes, m^2 / rad^2 (see RobotCalibration.cov)
      sigma_mm: 0.12                 # sqrt(trace) of the position block, mm
      sigma_deg: 0.010               # sqrt(trace) of the rotation block, degrees
      views: 28                      # images whose corners of this marker were used
      path: [14, 3]                  # chain used to start it (longer than 2: bridged)
    images: {total: 30, used: 30}
    rms_px: 0.05
    variance_factor: 1.3
    pairs: [[3, 6, 28], ...]       # co-visible pairs and their agreeing images
    bridged_pairs: [[a, b], ...]
    rejected_images: {file: reason}
    rejected_views: [{image: file, id: N, reason: text}]
    uncalibrated: {id: reason}
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from gtrig import geometry as geo
from gtrig.errors import FormatError, InputError
from gtrig.io.atomic import atomic_write_text
from gtrig.io.yamlfile import load_yaml
from gtrig.markers.robotcal.calibrate import RobotCalibration
from gtrig.markers.robotcal.observe import Array, MarkerSpec
from gtrig.rig.models import Marker, MarkerFamily, Pose, Rig, pose_cov_rows


def parse_anchor_pose(text: str) -> Array:
    """The anchor marker's pose on the robot, ``T_robot_marker`` (4, 4), from a command-line value.

    Either six comma-separated numbers ``x,y,z,roll,pitch,yaw`` (metres, degrees; ``R = Rz Ry Rx`` as in
    the rig file's ``rpy_deg``), or a YAML file holding a rig-file pose (``xyz`` and ``quat_xyzw`` or
    ``rpy_deg``), optionally under a ``T_robot_marker`` key.
    """
    s = text.strip()
    parts = s.split(",")
    if len(parts) == 6:
        try:
            v = [float(p) for p in parts]
        except ValueError:
            raise InputError(f"--anchor-pose {text!r}: expected x,y,z,roll,pitch,yaw (m, deg) numbers") from None
        if not all(math.isfinite(x) for x in v):
            raise InputError(f"--anchor-pose {text!r}: every value must be a finite number")
        if max(abs(x) for x in v[:3]) > 5.0:  # a marker on a robot is within metres of its origin
            raise InputError(f"--anchor-pose {text!r}: x, y, z are in metres and must be within 5 m of the robot's "
                             "origin (millimetres given for metres?)")
        return Pose(xyz=(v[0], v[1], v[2]), rpy_deg=(v[3], v[4], v[5])).matrix()
    p = Path(s)
    if not p.is_file():
        raise InputError(f"--anchor-pose {text!r}: neither x,y,z,roll,pitch,yaw (m, deg) nor a YAML file")
    d = load_yaml(p)
    if isinstance(d, dict) and "T_robot_marker" in d:
        d = d["T_robot_marker"]
    try:
        return Pose.model_validate(d).matrix()
    except Exception as e:  # pydantic's message, first line only
        msg = str(e).splitlines()
        raise FormatError(f"{p}: expected a pose (xyz and quat_xyzw or rpy_deg): "
                          f"{msg[-1].strip() if msg else e}") from None


def specs_from_rig(rig: Rig) -> list[MarkerSpec]:
    """The markers of a rig (family, ID, side) as calibration targets."""
    return [MarkerSpec(m.id, m.side_m, m.family) for m in rig.robot.markers]


def _f(x: float, nd: int = 9) -> float:
    return float(round(float(x), nd))


def markers_document(cal: RobotCalibration, specs: list[MarkerSpec]) -> dict[str, Any]:
    """The ``markers.yaml`` document of a calibration."""
    by_id = {m.id: m for m in specs}
    out = []
    for mid, T in cal.T_robot_marker.items():
        sp = by_id[mid]
        pose = Pose.from_matrix(T)
        c = cal.cov[mid]
        s_m, s_r = cal.sigma(mid)
        out.append({
            "family": MarkerFamily(sp.family).value,
            "id": int(mid),
            "side_m": float(sp.side_m),
            "T_robot_marker": {"xyz": [_f(x) for x in pose.xyz],
                               "quat_xyzw": [_f(q, 12) for q in (pose.quat_xyzw or ())]},
            "covariance": [[float(f"{x:.6e}") for x in row] for row in c],
            "sigma_mm": _f(s_m * 1000, 4),
            "sigma_deg": _f(math.degrees(s_r), 5),
            "views": int(cal.n_views.get(mid, 0)),
            "path": [int(x) for x in cal.paths.get(mid, (mid,))],
        })
    return {
        "anchor": int(cal.anchor),
        "markers": out,
        "images": {"total": cal.images_total, "used": cal.images_used},
        "rms_px": _f(cal.rms_px, 4),
        "variance_factor": _f(cal.variance_factor, 4),
        "pairs": [[int(a), int(b), int(n)] for (a, b), n in sorted(cal.pairs.items())],
        "bridged_pairs": [[int(a), int(b)] for a, b in cal.bridged_pairs],
        "rejected_pairs": [[int(a), int(b)] for a, b in cal.rejected_pairs],
        "rejected_images": dict(cal.rejected_images),
        "rejected_views": [{"image": im, "id": int(m), "reason": r} for (im, m), r in cal.rejected_views.items()],
        "uncalibrated": {int(k): v for k, v in cal.uncalibrated.items()},
        "unknown_ids": {int(k): int(v) for k, v in cal.unknown_ids.items()},
    }


def write_markers_yaml(path: str | os.PathLike[str], cal: RobotCalibration, specs: list[MarkerSpec]) -> None:
    """Write ``markers.yaml`` atomically."""
    text = yaml.safe_dump(markers_document(cal, specs), sort_keys=False, default_flow_style=None, width=140)
    atomic_write_text(path, text)


def read_markers_yaml(path: str | os.PathLike[str]) -> tuple[list[Marker], dict[int, Array]]:
    """The calibrated markers of ``markers.yaml`` as rig markers, and their covariances {ID: (6, 6)}."""
    p = Path(path)
    d = load_yaml(p)
    if not isinstance(d, dict) or not isinstance(d.get("markers"), list):
        raise FormatError(f"{p}: markers: expected a list of calibrated markers")
    markers, cov = [], {}
    for k, e in enumerate(d["markers"]):
        try:
            m = Marker.model_validate({x: e[x] for x in ("family", "id", "side_m", "T_robot_marker")})
            c = np.asarray(e["covariance"], float)
        except Exception:
            raise FormatError(f"{p}: markers[{k}]: expected family, id, side_m, T_robot_marker, covariance")\
                from None
        if c.shape != (6, 6):
            raise FormatError(f"{p}: markers[{k}].covariance: expected 6 x 6")
        markers.append(m)
        cov[m.id] = c
    return markers, cov


def apply_to_rig(rig: Rig, cal: RobotCalibration) -> Rig:
    """``rig`` with the calibrated markers' ``T_robot_marker`` and ``pose_cov`` replaced (others
    unchanged)."""
    new = []
    for m in rig.robot.markers:
        T = cal.T_robot_marker.get(m.id)
        if T is None:
            new.append(m)
            continue
        upd: dict[str, object] = {"T_robot_marker": Pose.from_matrix(T)}
        if m.id in cal.cov_relative:
            upd["pose_cov"] = pose_cov_rows(cal.cov_relative[m.id])
        new.append(m.model_copy(update=upd))
    robot = rig.robot.model_copy(update={"markers": tuple(new)})
    return rig.model_copy(update={"robot": robot})


def marker_errors(cal: RobotCalibration, truth: Rig, relative: bool = False) -> dict[int, tuple[float, float]]:
    """{ID: (position error m, rotation error rad)} of the calibrated markers against a true rig.

    With ``relative``, the errors of the poses relative to the anchor, ``T_anchor_marker`` (the anchor
    left out): what the calibration measured, without the error of the anchor's given pose.
    """
    true = {m.id: m.T_robot_marker.matrix() for m in truth.robot.markers}
    est = {m: T for m, T in cal.T_robot_marker.items() if m in true}
    if relative:
        a = cal.anchor
        return {m: geo.pose_error(np.linalg.inv(est[a]) @ T, np.linalg.inv(true[a]) @ true[m])
                for m, T in est.items() if m != a}
    return {m: geo.pose_error(T, true[m]) for m, T in est.items()}
