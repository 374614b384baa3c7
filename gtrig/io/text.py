"""Reading a text input with one-line errors: the one place that maps a missing file, a folder, an
undecodable (binary) file and an unreadable one to a :class:`~gtrig.errors.FormatError` naming it."""

from __future__ import annotations

import os
from pathlib import Path

from gtrig.errors import FormatError, GtrigError


def read_bytes(path: str | os.PathLike[str], what: str = "text file", error: type[GtrigError] = FormatError,
               missing: str = "no such file") -> bytes:
    """The bytes of ``path`` (for the compiled parsers); the messages of :func:`read_text` (``missing``
    when there is no such file)."""
    p = Path(path)
    try:
        return p.read_bytes()
    except FileNotFoundError:
        raise error(f"{p}: {missing}") from None
    except IsADirectoryError:
        raise error(f"{p}: is a folder, expected a {what}") from None
    except OSError as e:
        raise error(f"{p}: cannot read ({e.strerror or e})") from None


def decode_text(path: str | os.PathLike[str], data: bytes, what: str = "text file", encoding: str = "utf-8",
                error: type[GtrigError] = FormatError) -> str:
    """``data`` (the bytes of ``path``) as text; undecodable bytes are one error naming the file."""
    try:
        return data.decode(encoding)
    except UnicodeDecodeError:
        raise error(f"{Path(path)}: not a {what} (undecodable bytes: a binary file?)") from None


def read_text(path: str | os.PathLike[str], what: str = "text file", encoding: str = "utf-8",
              error: type[GtrigError] = FormatError) -> str:
    """The text of ``path``; ``what`` names the expected kind of file in the messages."""
    return decode_text(path, read_bytes(path, what, error), what, encoding, error)
