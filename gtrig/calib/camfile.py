"""Moved to :mod:`gtrig.io.camfile` (a core module every stage may use); re-exported here for old imports."""

from gtrig.io.camfile import (  # noqa: F401
    CameraIntrinsics,
    _floats,
    cam_from_dict,
    cam_to_dict,
    read_cam_yaml,
    write_cam_yaml,
)
