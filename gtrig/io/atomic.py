"""Write outputs atomically: to a temporary file in the same folder, then rename.

A crash or an error never leaves a half-written result behind.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w", **kwargs: object) -> Iterator[IO]:  # type: ignore[type-arg]
    """Open ``path`` for writing through a temporary file renamed into place on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
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
    previous outputs are left as they were."""
    finals = [Path(p) for p in paths]
    if len({p.resolve() for p in finals}) != len(finals):
        raise ValueError("two outputs of one group name the same file")
    tmps: list[Path] = []
    try:
        for p in finals:
            p.parent.mkdir(parents=True, exist_ok=True)
            fd, name = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
            os.close(fd)
            tmps.append(Path(name))
        yield tmps
        for t, p in zip(tmps, finals, strict=True):
            os.replace(t, p)
    except BaseException:
        for t in tmps:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(t)
        raise
