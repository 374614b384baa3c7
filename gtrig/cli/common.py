"""Shared CLI helpers: the console, progress bars, and mapping known errors to one line and an exit code."""

from __future__ import annotations

import functools
import logging
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

from rich.console import Console
from rich.logging import RichHandler

# plain text by default: paths, camera and point names are printed as given, so one holding Rich markup
# ("x[/b].yaml") can neither restyle nor crash the output; a styled word is a Text (``styled``)
console = Console(soft_wrap=True, markup=False)
err_console = Console(stderr=True, soft_wrap=True, markup=False)

F = TypeVar("F", bound=Callable[..., Any])
T = TypeVar("T")


def styled(text: object, style: str) -> Any:
    """``text`` as a Rich Text in ``style`` (its characters never read as markup)."""
    from rich.text import Text

    return Text(str(text), style=style)


def setup_logging(verbose: bool = False) -> None:
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.INFO,
        format="%(message)s",
        handlers=[RichHandler(console=err_console, show_path=False, show_time=False)],
        force=True,
    )


def _one_line(msg: object) -> str:
    return " ".join(str(msg).split())


def print_error(msg: str) -> None:
    """``error: <msg>`` as one line on stderr."""
    # plain text: a file or point name holding Rich markup ("x[/b].yaml") must print as it is
    err_console.print("error: " + _one_line(msg), markup=False, highlight=False, soft_wrap=True)


def _os_error_message(e: OSError) -> str:
    where = e.filename if e.filename is not None else ""
    what = e.strerror or type(e).__name__
    if isinstance(e, IsADirectoryError):
        what = "is a folder, expected a file"
    elif isinstance(e, NotADirectoryError):
        what = "a part of this path is a file, expected a folder"
    elif isinstance(e, FileExistsError):
        what = "exists and is in the way (a file where a folder is needed, or the reverse)"
    extra = f" -> {e.filename2}" if getattr(e, "filename2", None) else ""
    return f"{where}{extra}: {what}" if where else what


def _validation_message(e: Exception) -> str:
    errors: list[dict[str, Any]] = getattr(e, "errors", list)()
    if not errors:
        return _one_line(e)
    first = errors[0]
    loc = ".".join(str(x) for x in first.get("loc", ()))
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"{loc}: {first.get('msg', 'invalid')}{more}"


def crash_log_path() -> Path:
    """Where an unexpected exception's traceback is written (``$GTRIG_LOG_DIR`` or the temp folder)."""
    import os
    import tempfile

    folder = Path(os.environ.get("GTRIG_LOG_DIR") or tempfile.gettempdir())
    return folder / f"gtrig-crash-{os.getpid()}.log"


def _write_crash_log(e: BaseException) -> Path | None:
    import traceback

    path = crash_log_path()
    try:
        path.write_text("".join(traceback.format_exception(e)), encoding="utf-8")
    except OSError:
        return None
    return path


def handle_errors(fn: F) -> F:
    """Turn every failure into ``error: <one line>`` on stderr and a non-zero exit, never a traceback.

    Exit codes: 2 a user error (bad input, missing or unwritable file, invalid value), 3 a stage that
    could not reach a result (``ConvergenceError``), 130 interrupted, 1 an unexpected error (one line and
    the path of a log holding the traceback; ``--verbose`` prints it)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from pydantic import ValidationError
        from typer import Exit

        from gtrig.errors import GtrigError

        try:
            return fn(*args, **kwargs)
        except Exit as e:  # a verb's own exit code (a verdict, or a refusal it has already printed)
            sys.exit(e.exit_code)
        except GtrigError as e:
            print_error(str(e))
            sys.exit(e.exit_code)
        except KeyboardInterrupt:
            err_console.print("interrupted; rerun the same command to resume where possible", markup=False)
            sys.exit(130)
        except OSError as e:
            print_error(_os_error_message(e))
            sys.exit(2)
        except UnicodeDecodeError as e:
            print_error(f"an input is not text ({e.reason} at byte {e.start})")
            sys.exit(2)
        except ValidationError as e:
            print_error(_validation_message(e))
            sys.exit(2)
        except MemoryError:
            print_error("out of memory: the input is larger than this machine can hold")
            sys.exit(2)
        except Exception as e:
            if type(e).__name__ == "LinAlgError":  # numpy's: a singular system, from a degenerate input
                print_error(f"a degenerate input: the estimate is not determined ({_one_line(e)}); check that "
                             "the inputs constrain every unknown")
                sys.exit(3)
            if logging.getLogger().isEnabledFor(logging.DEBUG):
                raise
            log_path = _write_crash_log(e)
            where = f"; traceback in {log_path}" if log_path else ""
            print_error(f"unexpected {type(e).__name__}: {_one_line(e)[:300]}{where} (please report it)")
            sys.exit(1)

    return wrapper  # type: ignore[return-value]


def _one_line_group() -> type:
    """The root command's class: Click's own usage errors (a missing option, a value of the wrong type, an
    unknown option) as one ``error:`` line and exit code 2, like every other refusal, instead of a
    usage panel."""
    from typer import exceptions as typer_exceptions
    from typer._click import exceptions as click  # Typer's own copy of Click: its exceptions are these
    from typer.core import TyperGroup

    class OneLineErrorsGroup(TyperGroup):
        def main(self, args: Sequence[str] | None = None, prog_name: str | None = None,
                 complete_var: str | None = None, standalone_mode: bool = True, windows_expand_args: bool = True,
                 **extra: Any) -> Any:
            call = {"args": args, "prog_name": prog_name, "complete_var": complete_var,
                    "windows_expand_args": windows_expand_args, **extra}
            if not standalone_mode:
                return super().main(standalone_mode=False, **call)
            try:
                rv = super().main(standalone_mode=False, **call)
            except click.NoArgsIsHelpError as e:
                e.show()  # `gtrig survey` alone: the help, as before
                sys.exit(e.exit_code)
            except click.ClickException as e:
                where = e.ctx.command_path if isinstance(e, click.UsageError) and e.ctx is not None else "gtrig"
                print_error(f"{where}: {e.format_message()} (--help lists the options)")
                sys.exit(2)
            except typer_exceptions.Abort:
                err_console.print("interrupted", markup=False)
                sys.exit(130)
            sys.exit(rv if isinstance(rv, int) else 0)

    return OneLineErrorsGroup


ONE_LINE_ERRORS_GROUP = _one_line_group()


def track(items: Iterable[T], description: str, total: int | None = None) -> Iterator[T]:
    """A Rich progress bar on stderr (silent when stderr is not a terminal)."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        transient=True,
    ) as progress:
        yield from progress.track(items, total=total, description=description)
