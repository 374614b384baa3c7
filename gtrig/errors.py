"""Exceptions that carry a one-line, user-facing message.

Library code raises these; only the CLI turns them into a message and an exit code.
"""

from __future__ import annotations


class GtrigError(Exception):
    """A user-facing error: bad input, bad configuration, a missing file.

    The message is one line and names the file, line or field at fault.
    """

    exit_code = 2


class ConfigError(GtrigError):
    """A rig or configuration file is invalid."""


class FormatError(GtrigError):
    """A data file (CSV, TUM, images) does not follow the documented format."""


class InputError(GtrigError):
    """Inputs are valid files but cannot be processed together (too few views, unknown names...)."""


class ConvergenceError(GtrigError):
    """An estimate did not converge or is ambiguous, and gtrig refuses to pick silently."""

    exit_code = 3
