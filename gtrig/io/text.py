"""Reading a text input with one-line errors: the one place that maps a missing file, a folder, an
undecodable (binary) file and an unreadable one to a :class:`~gtrig.errors.FormatError` naming it."""

from __future__ import annotations

import os
from pathlib import Path

from gtrig.errors import FormatError, GtrigError


def read_text(path: str | os.PathLike[str], what: str = "text file", encoding: str = "utf-8",
              error: type[GtrigError] = FormatError) -> str:
    """The text of ``path``; ``what`` names the expected kind of file in the messages."""
    p = Path(path)
    try:
        return p.read_text(encoding=encoding)
    except FileNotFoundError:
        raise error(f"{p}: no such file") from None
    except IsADirectoryError:
        raise error(f"{p}: is a folder, expected a {what}") from None
    except UnicodeDecodeError:
        raise error(f"{p}: not a {what} (undecodable bytes: a binary file?)") from None
    except OSError as e:
        raise error(f"{p}: cannot read ({e.strerror or e})") from None
