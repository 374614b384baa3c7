"""Load and save ``rig.yaml``: one-line errors naming the file, line and field path."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from gtrig.errors import ConfigError, FormatError
from gtrig.io.atomic import atomic_write_text
from gtrig.io.yamlfile import compose_yaml, construct_yaml
from gtrig.rig.models import Rig

LineMap = dict[tuple[str | int, ...], int]


def _line_map(node: yaml.Node, path: tuple[str | int, ...] = (), out: LineMap | None = None) -> LineMap:
    """Map every field path of a composed YAML document to its 1-based line."""
    out = {} if out is None else out
    out[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            key = k.value
            out[path + (key,)] = k.start_mark.line + 1
            _line_map(v, path + (key,), out)
    elif isinstance(node, yaml.SequenceNode):
        for i, v in enumerate(node.value):
            _line_map(v, path + (i,), out)
    return out


def _format_loc(loc: tuple[str | int, ...]) -> str:
    s = ""
    for p in loc:
        s += f"[{p}]" if isinstance(p, int) else (f".{p}" if s else str(p))
    return s or "(top level)"


def deep_merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in override.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = v
    return out


class RigValidationError(ConfigError):
    """An invalid rig document. The message is the first problem (one line, with how many more);
    ``problems`` holds every one of them, each a line naming the file, line and field."""

    def __init__(self, problems: list[str]) -> None:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        super().__init__(problems[0] + more)
        self.problems = tuple(problems)


def _problem(err: Any, source: str, lines: LineMap | None) -> str:
    # pydantic appends the union/enum branch to the location; keep only real field names
    loc = tuple(p for p in err["loc"] if isinstance(p, int) or not str(p).startswith(("function-", "tuple[")))
    line = None
    if lines:
        for n in range(len(loc), -1, -1):
            if loc[:n] in lines:
                line = lines[loc[:n]]
                break
    where = f"{source}:{line}" if line else source
    msg = err["msg"].removeprefix("Value error, ")
    if err["type"] == "missing":
        msg = "missing field"
    elif err["type"] == "extra_forbidden":
        msg = "unknown field"
    return f"{where}: {_format_loc(loc)}: {msg}"


def rig_from_dict(data: Any, source: str = "<rig>", lines: LineMap | None = None) -> Rig:
    """Validate a parsed rig document; raise :class:`RigValidationError` (a :class:`ConfigError`: one line, the
    first problem; ``.problems`` lists them all) on failure."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the rig file must be a mapping of sections (world, cameras, ...)")
    try:
        return Rig.model_validate(data)
    except ValidationError as e:
        problems = list(dict.fromkeys(_problem(err, source, lines) for err in e.errors()))
        raise RigValidationError(problems) from None


def load_rig(path: str | os.PathLike[str], overrides: dict[str, Any] | None = None) -> Rig:
    """Read and validate a rig file.

    Parameters
    ----------
    path
        ``rig.yaml``.
    overrides
        A partial document deep-merged over the file before validation.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such file") from None
    except (IsADirectoryError, UnicodeDecodeError) as e:
        raise ConfigError(f"{p}: cannot read the rig file ({type(e).__name__})") from None
    try:
        node = compose_yaml(text, str(p))
        data = construct_yaml(node, str(p))
    except FormatError as e:
        raise ConfigError(str(e)) from None
    lines = _line_map(node) if node is not None else {}
    if overrides:
        data = deep_merge(data if isinstance(data, dict) else {}, overrides)
    return rig_from_dict(data, str(p), lines)


def rig_to_dict(rig: Rig) -> dict[str, Any]:
    """A plain document (lists, not tuples), as written to YAML."""
    return rig.model_dump(mode="json", exclude_none=True)


def rig_text(rig: Rig) -> str:
    """The rig file's text (what :func:`dump_rig` writes)."""
    return yaml.safe_dump(rig_to_dict(rig), sort_keys=False, default_flow_style=None, width=120)


def dump_rig(rig: Rig, path: str | os.PathLike[str]) -> None:
    """Write a rig file atomically."""
    atomic_write_text(path, rig_text(rig))
