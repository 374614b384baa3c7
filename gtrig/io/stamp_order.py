"""Time stamps as evo takes them: a repeated stamp dropped, a stamp that steps back sorted into place.

evo reads a trajectory whatever its stamps do and pairs by searching them; gtrig's
:class:`~gtrig.trajectory.PoseTrack` needs strictly increasing stamps. :func:`stamp_order` gives the rows
to keep, in time order, and says once per file what it did:

- a stamp equal to an earlier one (TUM's freiburg2_desk ground truth has one): the later pose is dropped
  (evo's nearest search would find the first one);
- a stamp a little before the previous one (a message written out of order): the poses are sorted by stamp
  (evo would pair them, but its RPE and interpolation would run through them out of order);
- a stamp far before the previous one (more than :data:`MAX_STEP_BACK_PERIODS` median intervals: a clock
  reset, two runs in one file): a :class:`~gtrig.errors.FormatError`, since sorting would interleave two
  paths and evo would score the mix too.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError

log = logging.getLogger(__name__)

#: the largest step back sorted into place, in median stamp intervals
MAX_STEP_BACK_PERIODS = 10.0


def _where(p: Path, k: int, line_numbers: np.ndarray | list[int] | None) -> str:
    return f"{p}:{line_numbers[k]}" if line_numbers is not None else f"{p}: pose {k + 1}"


def stamp_order(p: Path, stamps_s: np.ndarray, line_numbers: np.ndarray | list[int] | None = None
                ) -> np.ndarray | None:
    """The indices of the rows to keep, in increasing stamp order, or ``None`` when the stamps already
    increase strictly (nothing to do: the common case costs one ``np.diff``).

    Parameters
    ----------
    p : the file, for the messages.
    stamps_s : (N,) the stamps as read (s).
    line_numbers : (N,) 1-based lines of the rows, for the messages (``None``: pose numbers).
    """
    t = np.asarray(stamps_s, float)
    d = np.diff(t)
    if not np.any(d <= 0):
        return None
    back = np.flatnonzero(d < 0)
    if back.size:
        pos = d[d > 0]
        period = float(np.median(pos)) if pos.size else 0.0
        worst = int(back[np.argmin(d[back])])
        if -d[worst] > MAX_STEP_BACK_PERIODS * period:
            raise FormatError(f"{_where(p, worst + 1, line_numbers)}: the time stamp steps back "
                              f"{-d[worst]:.6g} s ({float(t[worst])!r} then {float(t[worst + 1])!r}), over "
                              f"{MAX_STEP_BACK_PERIODS:g} sample intervals: a clock reset or two runs in one "
                              "file? Split the file or fix its stamps")
    order = np.argsort(t, kind="stable")
    ts = t[order]
    first = np.concatenate([[True], np.diff(ts) > 0])
    keep = order[first]
    n_dup = int(t.size - keep.size)
    what = []
    if back.size:
        what.append(f"{back.size} stamp(s) step back (first at {_where(p, int(back[0]) + 1, line_numbers)}): "
                    "poses sorted by stamp")
    if n_dup:
        dup_at = int(order[np.flatnonzero(~first)[0]])
        what.append(f"{n_dup} repeated stamp(s) (first at {_where(p, dup_at, line_numbers)}): the later pose "
                    "dropped")
    log.warning("%s: %s", p, "; ".join(what))
    return keep
