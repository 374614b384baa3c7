"""Reading a YAML file with one-line errors that name it."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from gtrig.errors import FormatError, InputError


def load_yaml(path: str | os.PathLike[str]) -> Any:
    """The document in ``path``; :class:`InputError` when the file is missing, :class:`FormatError` when
    it is not valid YAML (with the parser's problem, not its multi-line report)."""
    p = Path(path)
    try:
        return yaml.safe_load(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{p}: no such file") from None
    except yaml.YAMLError as e:
        raise FormatError(f"{p}: not valid YAML ({getattr(e, 'problem', e)})") from None
