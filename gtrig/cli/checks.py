"""Checks of command-line values, made before any work starts: a verb never begins a long run on an
argument it would refuse later. Each failure is one :class:`~gtrig.errors.InputError` line naming the
option."""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

from gtrig.errors import InputError

#: seeds are NumPy SeedSequence entropy; 2^32 keeps them portable to every generator we use
MAX_SEED = 2**32 - 1
MAX_WORKERS = 256


def number(option: str, value: float | None, *, lo: float | None = None, hi: float | None = None,
           lo_open: bool = False, unit: str = "", unit_hint: str = "", lo_hint: str = "") -> None:
    """``value`` is finite and within ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``); ``None`` passes.

    ``unit_hint`` is added when ``value`` is above ``hi``, ``lo_hint`` when it is positive and below
    ``lo``: the likely unit mistake (e.g. "millimetres given for metres")."""
    if value is None:
        return
    u = f" {unit}" if unit else ""
    if not math.isfinite(value):
        raise InputError(f"{option}: must be a finite number{u}, got {value}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        hint = f" ({lo_hint}?)" if lo_hint and value > 0 else ""
        raise InputError(f"{option}: must be {'>' if lo_open else '>='} {lo:g}{u}, got {value:g}{hint}")
    if hi is not None and value > hi:
        hint = f" ({unit_hint}?)" if unit_hint else ""
        raise InputError(f"{option}: must be <= {hi:g}{u}, got {value:g}{hint}")


def sigma_m(option: str, value: float | None, hi: float = 0.5) -> None:
    """A standard deviation in metres: positive, finite and below ``hi``."""
    number(option, value, lo=0.0, lo_open=True, hi=hi, unit="m", unit_hint="millimetres given for metres")


def seed(value: int) -> None:
    if not 0 <= value <= MAX_SEED:
        raise InputError(f"--seed: must be between 0 and {MAX_SEED}, got {value}")


def workers(value: int) -> None:
    if not 0 <= value <= MAX_WORKERS:
        raise InputError(f"--workers: must be between 0 (one per core) and {MAX_WORKERS}, got {value}")


def outputs(inputs: Iterable[Path | None], outs: Iterable[Path | None]) -> None:
    """No output is an input or another output, none is an existing folder, and none lies under a file."""
    ins = {p.resolve(): p for p in inputs if p is not None}
    seen: dict[Path, Path] = {}
    for o in outs:
        if o is None:
            continue
        r = o.resolve()
        if r in ins:
            raise InputError(f"{o}: an output may not overwrite an input ({ins[r]})")
        if r in seen:
            raise InputError(f"{o}: named for two outputs")
        seen[r] = o
        if r.is_dir():
            raise InputError(f"{o}: is a folder, expected a file to write")
        for parent in r.parents:
            if parent.exists():
                if not parent.is_dir():
                    raise InputError(f"{o}: {parent} is a file, not a folder")
                break


def output_folder(option: str, folder: Path) -> None:
    """``folder`` is a folder or can be made one (it is not a file, nor under one)."""
    r = folder.resolve()
    if r.exists() and not r.is_dir():
        raise InputError(f"{option} {folder}: is a file, expected a folder")
    for parent in r.parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(f"{option} {folder}: {parent} is a file, not a folder")
            break


def choice(option: str, value: str | None, allowed: Iterable[str]) -> None:
    """``value`` is one of ``allowed`` (``None`` passes)."""
    allowed = tuple(allowed)
    if value is not None and value not in allowed:
        raise InputError(f"{option}: must be one of {', '.join(allowed)}, got {value!r}")


def count(option: str, value: int | None, lo: int | None = None, hi: int | None = None) -> None:
    """An integer option within ``[lo, hi]`` (``None`` passes)."""
    if value is None:
        return
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        span = f"between {lo} and {hi}" if lo is not None and hi is not None else (
            f">= {lo}" if lo is not None else f"<= {hi}")
        raise InputError(f"{option}: must be {span}, got {value}")


def input_folder(option: str, folder: Path) -> None:
    """``folder`` exists and is a folder."""
    if not folder.exists():
        raise InputError(f"{option} {folder}: no such folder")
    if not folder.is_dir():
        raise InputError(f"{option} {folder}: is a file, expected a folder")


def not_inside(option: str, out: Path, folder: Path, what: str = "the recording") -> None:
    """An output folder is not ``folder`` itself nor inside it (a recording is read, never written)."""
    o, f = out.resolve(), folder.resolve()
    if o == f or f in o.parents:
        raise InputError(f"{option} {out}: inside {what} ({folder}); outputs go elsewhere")


def floats(option: str, text: str | None, n: int, unit: str = "") -> tuple[float, ...] | None:
    """``text`` as ``n`` comma-separated finite numbers (``None`` passes)."""
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != n:
        raise InputError(f"{option} {text!r}: expected {n} comma-separated numbers{f' ({unit})' if unit else ''}")
    if not all(math.isfinite(v) for v in vals):
        raise InputError(f"{option} {text!r}: every value must be a finite number")
    return vals
