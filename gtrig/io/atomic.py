"""Write outputs atomically: to a temporary file in the same folder, then rename.

A crash or an error never leaves a half-written result behind. Temporaries are named
``.<name>.<pid>.<random>.tmp``: on an error or SIGTERM they are removed; after a SIGKILL the next gtrig
process that writes into the same folder removes those whose process is gone. Outputs get the mode
the umask gives (``mkstemp`` alone would make them 0600).
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_MODE = 0o666 & ~_umask()
_cleaned: set[Path] = set()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(folder: Path) -> list[Path]:
    """Remove the temporaries in ``folder`` left by gtrig processes that no longer run; returns them."""
    removed: list[Path] = []
    try:
        entries = list(folder.iterdir())
    except OSError:
        return removed
    for e in entries:
        parts = e.name.split(".")
        # "", name..., pid, random, "tmp"
        if len(parts) < 5 or parts[0] or parts[-1] != "tmp" or not parts[-3].isdigit():
            continue
        pid = int(parts[-3])
        if pid != os.getpid() and not _pid_alive(pid):
            with contextlib.suppress(OSError):
                e.unlink()
                removed.append(e)
    return removed


def _temporary(path: Path) -> Path:
    """A new temporary file beside ``path``, with the umask's mode."""
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True)
    if folder not in _cleaned:
        _cleaned.add(folder)
        remove_stale_temporaries(folder)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=folder)
    try:
        os.fchmod(fd, _MODE)
    finally:
        os.close(fd)
    return Path(name)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w", **kwargs: object) -> Iterator[IO[Any]]:
    """Open ``path`` for writing through a temporary file renamed into place on success."""
    path = Path(path)
    tmp = _temporary(path)
    try:
        with open(tmp, mode, **kwargs) as f:  # type: ignore[call-overload]
            yield f
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(text)


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_open(path, "wb") as f:
        f.write(data)


@contextlib.contextmanager
def atomic_group(*paths: str | os.PathLike[str]) -> Iterator[list[Path]]:
    """Write several outputs all or none: yields one temporary path per output (same folder), renamed
    into place together when the block succeeds; on any error every temporary is removed and the
    previous outputs are left as they were. An output that is a folder is refused before any rename
    (a rename onto it would fail after the others had been replaced)."""
    finals = [Path(p) for p in paths]
    if len({p.resolve() for p in finals}) != len(finals):
        raise ValueError("two outputs of one group name the same file")
    tmps: list[Path] = []
    try:
        for p in finals:
            tmps.append(_temporary(p))
        yield tmps
        for p in finals:
            if p.is_dir():
                raise IsADirectoryError(errno.EISDIR, "Is a directory", str(p))
        for t, p in zip(tmps, finals, strict=True):
            os.replace(t, p)
    except BaseException:
        for t in tmps:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(t)
        raise
