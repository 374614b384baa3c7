"""Reuse of finished stages: a stage's record under ``DIR/.gtrig/stages/`` keyed on what it depends on.

A stage's key is a hash of

* the code's version: gtrig's version and the bytes of every module of the package (conservative: an
  edit anywhere reruns every stage; never a stale result);
* its configuration section (``run.yaml``'s part for it);
* the fingerprint of what it reads in the recording (path, size and modification time of every file
  under the top-level folder of each of its ``reads``, and of ``rig.yaml`` and ``truth/``);
* the keys of the stages that produced what it consumes (a rerun upstream reruns it).

The record holds the stage's :class:`~gtrig.pipeline.context.StageOutput` (its products as objects,
pickled; records are local, written by this program, never exchanged) and is written atomically after
the stage's files, so an interrupted run reuses exactly the stages that finished. A record is used only
when its key matches and every file it lists still exists.
"""

from __future__ import annotations

import hashlib
import json
import logging
import pickle
from functools import lru_cache
from pathlib import Path
from typing import Any

from gtrig.pipeline.context import StageOutput

log = logging.getLogger(__name__)

RECORD_DIR = ".gtrig/stages"
RECORD_VERSION = 1

#: where the run's laser logs' parsed ranges are kept, in the results folder (gtrig.io.scans.index_scans:
#: the laser stage parses each log once; the laser-clock stage and a resumed run parse none)
SCAN_CACHE = ".gtrig/scans"


@lru_cache(maxsize=1)
def code_version() -> str:
    """A hash of gtrig's version and of every module's source (about 200 files, a few ms)."""
    import gtrig

    root = Path(gtrig.__file__).parent
    h = hashlib.sha256(gtrig.__version__.encode())
    for p in sorted(root.rglob("*.py")):
        h.update(str(p.relative_to(root)).encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def fingerprint(rec: Path, entry: str) -> str:
    """Hash of the names, sizes and modification times of the files under ``rec/entry`` ("-" if absent)."""
    p = rec / entry
    if not p.exists():
        return "-"
    h = hashlib.sha256()
    files = [p] if p.is_file() else sorted(f for f in p.rglob("*") if f.is_file())
    for f in files:
        st = f.stat()
        h.update(f"{f.relative_to(rec)}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return h.hexdigest()[:16]


def stage_key(name: str, section: Any, prints: dict[str, str], upstream: dict[str, str]) -> str:
    doc = {"v": RECORD_VERSION, "stage": name, "code": code_version(), "config": section,
           "recording": prints, "upstream": upstream}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:20]


def _path(out: Path, name: str) -> Path:
    return out / RECORD_DIR / f"{name}.pkl"


def load_record(out: Path, name: str, key: str) -> StageOutput | None:
    """The stage's last output if its key is ``key`` and its files are all there, else None."""
    p = _path(out, name)
    if not p.is_file():
        return None
    try:
        with open(p, "rb") as f:
            doc = pickle.load(f)  # noqa: S301 (this program's own record, in the run's own folder)
    except Exception as e:  # a record of another version of the classes, or cut: run the stage again
        log.debug("%s: unreadable stage record (%s); running the stage again", p, e)
        return None
    if not isinstance(doc, dict) or doc.get("key") != key:
        return None
    output = doc.get("output")
    if not isinstance(output, StageOutput) or any(not (out / f).is_file() for f in output.outputs):
        return None
    return output


def save_record(out: Path, name: str, key: str, output: StageOutput) -> bool:
    """Write the stage's record; False (and a warning) when its products cannot be pickled: the stage
    then runs again next time, which costs time, never correctness."""
    from gtrig.io.atomic import atomic_open

    # pickled straight into the file: on an hour's recording the products are hundreds of MB, and a
    # pickle.dumps would hold their copy in memory next to them (the client's peak)
    try:
        with atomic_open(_path(out, name), "wb") as f:
            pickle.dump({"key": key, "output": output}, f, protocol=5)
    except (pickle.PicklingError, TypeError, AttributeError) as e:
        log.warning("%s: its products cannot be kept for reuse (%s); it will run again next time", name, e)
        return False
    return True


def forget(out: Path, name: str) -> None:
    _path(out, name).unlink(missing_ok=True)


def recording_prints(rec: Path, reads: tuple[str, ...]) -> dict[str, str]:
    """Fingerprints of the top-level entries holding ``reads`` (``calib/boards.yaml`` -> all of ``calib/``:
    a stage may read more of a folder than it requires), of ``rig.yaml`` and of ``truth/``."""
    tops = {Path(r).parts[0] for r in reads}
    return {e: fingerprint(rec, e) for e in sorted({*tops, "rig.yaml", "truth"})}


__all__ = ["code_version", "fingerprint", "forget", "load_record", "recording_prints", "save_record", "stage_key"]
