"""Trajectory files in the formats SLAM people use, through one front door.

:func:`read_trajectory` and :func:`write_trajectory` take the format from the file name or from an
explicit ``fmt``; a name and a ``fmt`` that disagree, or a file whose content is another format than
the one asked for, is a one-line :class:`~gtrig.errors.FormatError`.

=========  =====================================================  =======================================
fmt        file                                                   precision kept on a round trip
=========  =====================================================  =======================================
tum        ``NAME.tum``: ``t tx ty tz qx qy qz qw``                stamps as read (gtrig.stamps), 1 nm, 1e-12
gtrig      ``NAME.tum`` + ``NAME_cov.csv`` (status, covariance)    as tum; covariance exact
kitti      ``NAME.kitti`` (3x4 row-major) + ``NAME_times.txt``     1e-12 relative; stamps as tum
euroc      ``state_groundtruth_estimate0/data.csv``                stamps 1 ns, 1 nm, 1e-12 quaternion
rawseeds   ``t,x,y,theta`` [+ 3x3 covariance], ``*-GROUNDTRUTH``   6 decimals (published); cov exact
csv        gtrig's one-file CSV (pose, status, covariance)         stamps as tum; the rest exact
rosbag1    ``NAME.bag`` (ROS 1)                                    see gtrig.io.rosbag
rosbag2    a ROS 2 bag folder (sqlite3) or ``NAME.mcap``           see gtrig.io.rosbag
=========  =====================================================  =======================================

``.txt`` and ``.csv`` are read by their content (TUM: 8 numbers separated by whitespace or commas, the
stamp in seconds; KITTI: 12; RAWSEEDS: 4 or 13 comma-separated; EuRoC: a ``#timestamp`` header, or 8 or
17 comma-separated with an integer nanosecond stamp; csv: gtrig's header); writing them needs an
explicit ``fmt``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Literal, get_args

from gtrig.errors import ConfigError, FormatError, InputError
from gtrig.trajectory import PoseTrack

TrajectoryFormat = Literal["tum", "gtrig", "kitti", "euroc", "rawseeds", "csv", "rosbag1", "rosbag2"]
FORMATS: tuple[str, ...] = get_args(TrajectoryFormat)
TEXT_FORMATS = ("tum", "gtrig", "kitti", "euroc", "rawseeds", "csv")
BAG_FORMATS = ("rosbag1", "rosbag2")


def format_from_name(path: str | os.PathLike[str]) -> str | None:
    """The format a file name implies, or ``None`` when only the content can tell (``.txt``, ``.csv``)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".tum":
        return "tum"
    if suffix == ".kitti":
        return "kitti"
    if suffix == ".bag":
        return "rosbag1"
    if suffix in (".mcap", ".db3") or (p.is_dir() and (p / "metadata.yaml").is_file()):
        return "rosbag2"
    if p.name == "data.csv" and p.parent.name.startswith("state_groundtruth_estimate"):
        return "euroc"
    if suffix == ".csv" and (p.name.endswith("-GROUNDTRUTH.csv") or p.name.startswith("SOLUTION_")):
        return "rawseeds"
    return None


def sniff_format(path: str | os.PathLike[str]) -> str | None:
    """The text format of a file's content (see the module docstring), or ``None`` when none fits."""
    from gtrig.io.formats.csv import MAGIC

    p = Path(path)
    try:
        with open(p, encoding="utf-8-sig") as f:
            head = [f.readline() for _ in range(50)]
    except (OSError, UnicodeDecodeError):
        return None
    for line in head:
        s = line.strip()
        if s.startswith(MAGIC) or s.startswith("stamp_s,x,y,z,qx"):
            return "csv"
        if s.lower().startswith("#timestamp") or s.lower().startswith("# timestamp ["):
            return "euroc"
        if not s or s.startswith("#"):
            continue
        if "," in s:
            cells = [c.strip() for c in s.split(",")]
            if len(cells) == 8 and not cells[0].lstrip("+-").isdigit():
                return "tum"  # TUM with commas: EuRoC's first column is integer nanoseconds
            return {4: "rawseeds", 13: "rawseeds", 8: "euroc", 17: "euroc"}.get(len(cells))
        return {8: "tum", 12: "kitti"}.get(len(s.split()))
    return None


def _resolve(path: Path, fmt: str | None, reading: bool) -> str:
    if fmt is not None and fmt not in FORMATS:
        raise ConfigError(f"format {fmt!r} is none of {', '.join(FORMATS)}")
    by_name = format_from_name(path)
    if fmt is None:
        if by_name is not None:
            return by_name
        if reading:
            sniffed = sniff_format(path)
            if sniffed is None:
                if not path.exists():
                    raise FormatError(f"{path}: no such file")
                raise FormatError(f"{path}: not a trajectory in any known format ({', '.join(TEXT_FORMATS)})")
            return sniffed
        raise ConfigError(f"{path}: the name does not say which format to write; give one of {', '.join(FORMATS)}")
    compatible = {fmt, "tum" if fmt == "gtrig" else fmt}
    if by_name is not None and by_name not in compatible:
        raise FormatError(f"{path}: the name says {by_name}, but {fmt} was asked for")
    if reading and fmt in TEXT_FORMATS and by_name is None:
        sniffed = sniff_format(path)
        if sniffed is not None and sniffed not in compatible:
            raise FormatError(f"{path}: the content is {sniffed}, but {fmt} was asked for")
    return fmt


def read_trajectory(path: str | os.PathLike[str], fmt: str | None = None, **options: Any) -> PoseTrack:
    """Read a trajectory file (or a bag topic) as a :class:`PoseTrack`.

    Parameters
    ----------
    path : the file (or bag: a ``.bag`` file, a ROS 2 bag folder or ``.mcap``).
    fmt : one of :data:`FORMATS`; ``None``: from the name, else from the content.
    options : per format: ``cov_path`` (tum, gtrig), ``times_path`` (kitti), ``topic``, ``stamp``
        (bags: see :func:`gtrig.io.rosbag.read_bag_trajectory`; without ``topic``, gtrig's ``/gtrig/pose`` or
        the bag's only trajectory, else an error listing them).
    """
    p = Path(path)
    f = _resolve(p, fmt, reading=True)
    if f in BAG_FORMATS:
        from gtrig.io.rosbag import read_bag_trajectory
        from gtrig.io.rosbag.trajectory import choose_topic

        if options.get("topic") is None:
            options = {**options, "topic": choose_topic(p)}
        return read_bag_trajectory(p, **options)
    _check_options(f, options, {"tum": {"cov_path"}, "gtrig": {"cov_path"}, "kitti": {"times_path"}})
    if f in ("tum", "gtrig"):
        from gtrig.io.formats.tum import read_tum_track

        return read_tum_track(p, options.get("cov_path"), pair=True if f == "gtrig" else None)
    if f == "kitti":
        from gtrig.io.formats.kitti import read_kitti

        return read_kitti(p, options.get("times_path"))
    if f == "euroc":
        from gtrig.io.formats.euroc import read_euroc

        return read_euroc(p)
    if f == "rawseeds":
        from gtrig.io.formats.rawseeds import read_rawseeds

        return read_rawseeds(p)
    from gtrig.io.formats.csv import read_csv

    return read_csv(p)


def outputs_of(path: str | os.PathLike[str], fmt: str) -> list[Path]:
    """Every file :func:`write_trajectory` writes for ``path`` in ``fmt``."""
    p = Path(path)
    if fmt == "gtrig":
        from gtrig.io.formats.tum import cov_path_for

        return [p, cov_path_for(p)]
    if fmt == "kitti":
        from gtrig.io.formats.kitti import times_path_for

        return [p, times_path_for(p)]
    return [p]


def write_trajectory(track: PoseTrack, path: str | os.PathLike[str], fmt: str | None = None, *,
                     force: bool = False, **options: Any) -> list[Path]:
    """Write ``track`` in ``fmt`` (from the name when ``None``); every output is written all or none.

    An existing output is refused (:class:`InputError`) unless ``force``. ``options``: ``decimals``
    (rawseeds), ``frame_id``, ``child_frame_id``, ``topic`` ... (bags: see
    :func:`gtrig.io.rosbag.write_bag_trajectory`). Returns the paths written.
    """
    p = Path(path)
    f = _resolve(p, fmt, reading=False)
    existing = [o for o in outputs_of(p, f) if o.exists()]
    if existing and not force:
        raise InputError(f"{existing[0]}: exists; refusing to overwrite it (use --force)")
    if f in BAG_FORMATS:
        from gtrig.io.rosbag import write_bag_trajectory

        return write_bag_trajectory(track, p, ros_version=1 if f == "rosbag1" else 2, force=force, **options)
    _check_options(f, options, {"rawseeds": {"decimals", "theta"}})
    if f in ("tum", "gtrig"):
        from gtrig.io.formats.tum import write_tum_track

        return write_tum_track(track, p, pair=f == "gtrig")
    if f == "kitti":
        from gtrig.io.formats.kitti import write_kitti

        return write_kitti(track, p)
    if f == "euroc":
        from gtrig.io.formats.euroc import write_euroc

        return write_euroc(track, p)
    if f == "rawseeds":
        from gtrig.io.formats.rawseeds import write_rawseeds

        return write_rawseeds(track, p, **options)
    from gtrig.io.formats.csv import write_csv

    return write_csv(track, p)


def _check_options(fmt: str, options: dict[str, Any], allowed: dict[str, set[str]]) -> None:
    extra = set(options) - allowed.get(fmt, set())
    if extra:
        raise ConfigError(f"option(s) {', '.join(sorted(extra))} do not apply to format {fmt}")
