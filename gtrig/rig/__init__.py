"""The rig file: one ``rig.yaml`` describing the installation, validated once at load."""

from gtrig.rig.load import dump_rig, load_rig, rig_from_dict
from gtrig.rig.models import (
    Camera,
    Hull,
    LaserScanner,
    Marker,
    MarkerFamily,
    Pose,
    Rig,
)

__all__ = [
    "Camera",
    "Hull",
    "LaserScanner",
    "Marker",
    "MarkerFamily",
    "Pose",
    "Rig",
    "dump_rig",
    "load_rig",
    "rig_from_dict",
]
