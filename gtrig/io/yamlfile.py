"""Reading YAML with limits, and with one-line errors that name the file.

Every YAML document gtrig reads (rig files, run configurations, topic maps, calibration files) goes
through :func:`parse_yaml`, which refuses what no real configuration needs and what would make a
loader hang or exhaust memory:

- more than :data:`MAX_BYTES` of text;
- more than :data:`MAX_ALIASES` alias references (``*name``): the "billion laughs" document expands a
  few hundred bytes into 10^9 nodes through nested aliases;
- more than :data:`MAX_NODES` nodes once aliases are expanded;
- nesting deeper than :data:`MAX_DEPTH` (a deeply nested list would otherwise overflow the stack).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from gtrig.errors import FormatError, InputError

MAX_BYTES = 64 * 2**20
MAX_ALIASES = 1000
MAX_NODES = 5_000_000
MAX_DEPTH = 100


class _Limits:
    """Counts aliases and depth while composing (mixed into a loader before its composer)."""

    _aliases: int
    _depth: int

    def compose_node(self, parent: yaml.Node | None, index: int) -> yaml.Node | None:
        if self.check_event(yaml.AliasEvent):  # type: ignore[attr-defined]
            self._aliases += 1
            if self._aliases > MAX_ALIASES:
                raise _RefusedError(f"more than {MAX_ALIASES} aliases")
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _RefusedError(f"nested deeper than {MAX_DEPTH} levels")
            return super().compose_node(parent, index)  # type: ignore[misc]
        finally:
            self._depth -= 1


class _LimitedLoader(_Limits, yaml.SafeLoader):
    """A safe loader (pure Python) that counts aliases and depth while composing."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._aliases = 0
        self._depth = 0


if getattr(yaml, "__with_libyaml__", False):
    class _FastLimitedLoader(yaml._yaml.CParser, _Limits, yaml.composer.Composer,
                             yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
        """libyaml's event parser (C, about ten times faster than PyYAML's scanner) under the same
        Python composer and limits; the composer's ``get_single_node`` is called explicitly because
        the C parser has its own, without limits."""

        def __init__(self, stream: str) -> None:
            yaml._yaml.CParser.__init__(self, stream)
            yaml.composer.Composer.__init__(self)
            yaml.constructor.SafeConstructor.__init__(self)
            yaml.resolver.Resolver.__init__(self)
            self._aliases = 0
            self._depth = 0

        def get_single_node(self) -> yaml.Node | None:
            return yaml.composer.Composer.get_single_node(self)

    _Loader: type = _FastLimitedLoader
else:  # pragma: no cover - PyYAML built without libyaml
    _Loader = _LimitedLoader


def _one_line(msg: object) -> str:
    return " ".join(str(msg).split())[:200]


class _RefusedError(Exception):
    pass


def _expanded_size(node: yaml.Node, memo: dict[int, int], stack: set[int]) -> int:
    """Nodes of the document with every alias expanded (the shared sub-trees counted each time)."""
    key = id(node)
    if key in memo:
        return memo[key]
    if key in stack:
        raise _RefusedError("a recursive alias")
    stack.add(key)
    n = 1
    if isinstance(node, yaml.SequenceNode):
        n += sum(_expanded_size(c, memo, stack) for c in node.value)
    elif isinstance(node, yaml.MappingNode):
        n += sum(_expanded_size(k, memo, stack) + _expanded_size(v, memo, stack) for k, v in node.value)
    stack.discard(key)
    memo[key] = n
    if n > MAX_NODES:
        raise _RefusedError(f"more than {MAX_NODES} nodes once its aliases are expanded")
    return n


def compose_yaml(text: str, source: str) -> yaml.Node | None:
    """The node tree of ``text`` (for line numbers), within the module's limits."""
    if len(text) > MAX_BYTES:
        raise FormatError(f"{source}: {len(text) / 2**20:.0f} MiB of YAML, more than the {MAX_BYTES >> 20} MiB "
                          "a configuration may have")
    loader = None
    try:
        loader = _Loader(text)  # the reader refuses control characters here
        node = loader.get_single_node()
        if node is not None:
            _expanded_size(node, {}, set())
        return node
    except _RefusedError as e:
        raise FormatError(f"{source}: refused: {e}") from None
    except RecursionError:
        raise FormatError(f"{source}: refused: nested too deeply") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark else source
        raise FormatError(f"{where}: not valid YAML ({_one_line(getattr(e, 'problem', None) or e)})") from None
    finally:
        if loader is not None:
            loader.dispose()


def construct_yaml(node: yaml.Node | None, source: str) -> Any:
    """The Python document of a node tree from :func:`compose_yaml`."""
    if node is None:
        return None
    loader = _LimitedLoader("")
    try:
        return loader.construct_document(node)
    except RecursionError:
        raise FormatError(f"{source}: refused: nested too deeply") from None
    except yaml.YAMLError as e:
        raise FormatError(f"{source}: not valid YAML ({_one_line(getattr(e, 'problem', None) or e)})") from None
    finally:
        loader.dispose()


def parse_yaml(text: str, source: str) -> Any:
    """The document in ``text`` (``source`` names it in errors), within the module's limits."""
    return construct_yaml(compose_yaml(text, source), source)


def safe_load(text: str) -> Any:
    """``yaml.safe_load`` within the module's limits, for readers with their own messages: a refusal is a
    ``yaml.YAMLError`` (which they already report) rather than a hang or a RecursionError."""
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _expanded_size(node, {}, set())
        return loader.construct_document(node)
    except _RefusedError as e:
        raise yaml.YAMLError(f"refused: {e}") from None
    except RecursionError:
        raise yaml.YAMLError("refused: nested too deeply") from None
    finally:
        loader.dispose()


def read_text_file(path: str | os.PathLike[str], what: str = "file") -> str:
    """The text of ``path``, with one-line errors: missing, a folder, not text, unreadable."""
    return decode_text_file(path, read_bytes_file(path, what), what)


def read_bytes_file(path: str | os.PathLike[str], what: str = "file") -> bytes:
    """The bytes of ``path``, with :func:`read_text_file`'s messages: missing, a folder, unreadable."""
    from gtrig.io.text import read_bytes

    return read_bytes(path, what, InputError, missing=f"no such {what}")


def decode_text_file(path: str | os.PathLike[str], data: bytes, what: str = "file") -> str:
    """``data``, the bytes of ``path``, as UTF-8 text; undecodable bytes are one :class:`FormatError`."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise FormatError(f"{Path(path)}: not a text {what} (undecodable bytes)") from None


def load_yaml(path: str | os.PathLike[str]) -> Any:
    """The document in ``path``; :class:`InputError` when the file is missing, :class:`FormatError` when
    it is not valid YAML (with the parser's problem, not its multi-line report) or beyond the limits."""
    p = Path(path)
    return parse_yaml(read_text_file(p, "YAML file"), str(p))
