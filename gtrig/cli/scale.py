"""``--dask`` beside ``--workers``: where a command's chunks run, and one progress bar over them
(docs/scale.md)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import typer

from gtrig.cli.common import console, err_console

# "\\[" keeps the brackets: Typer renders help through Rich markup, which would swallow "[dask]"
DASK_HELP = ("Run the chunks on Dask: local:N (a cluster of N processes on this machine, started and stopped "
             "here) or a scheduler's address, tcp://HOST:8786 (pip install 'gtrig\\[dask]'; docs/scale.md).")


def _check_dask(value: str | None) -> str | None:
    """The value's form, checked while the options are parsed, so that no verb starts work on a ``--dask``
    it would refuse when the executor opens (the scheduler itself is reached only then)."""
    if value is None:
        return None
    from gtrig.errors import InputError
    from gtrig.executor import parse_dask

    try:
        parse_dask(value)
    except InputError as e:
        raise typer.BadParameter(str(e).removeprefix(f"--dask {value!r}: ").removeprefix(f"--dask {value}: ")) from None
    return value


def dask_option(annotated: bool = False) -> Any:
    """The ``--dask`` option (None: local processes, ``--workers``), its form checked on parsing;
    ``annotated``: for an ``Annotated`` parameter, whose default is given after ``=``."""
    if annotated:
        return typer.Option("--dask", help=DASK_HELP, callback=_check_dask)
    return typer.Option(None, "--dask", help=DASK_HELP, callback=_check_dask)


@contextlib.contextmanager
def executor(dask: str | None) -> Iterator[Any]:
    """The executor ``--dask`` asks for (None without it), its dashboard printed when there is one."""
    from gtrig.executor import dashboard_link, open_executor

    with open_executor(dask) as ex:
        link = dashboard_link(ex)
        if link:
            err_console.print(f"Dask dashboard: {link}", highlight=False, markup=False)
        yield ex


@dataclass
class ChunkBar:
    """Callbacks for a runner: ``on_stage(title)`` names the step, ``progress(done, total)`` moves the bar."""

    on_stage: Callable[[str], None]
    progress: Callable[[int, int], None]


@contextlib.contextmanager
def chunk_bar(title: str = "processing") -> Iterator[ChunkBar]:
    """One progress bar over a step's chunks, with its rate and time left (the same for local and Dask
    runs); on stderr, silent when stderr is not a terminal."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    class Rate(TextColumn):
        def render(self, task: Any) -> Any:  # chunks per second, once there is one
            from rich.text import Text

            return Text(f"{task.speed:.2f} chunks/s" if task.speed else "", style="progress.data.speed")

    with Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TaskProgressColumn(), Rate(""), TimeElapsedColumn(), TimeRemainingColumn(),
                  console=err_console, transient=True) as prog:
        task = prog.add_task(title, total=None)

        def on_stage(name: str) -> None:
            prog.reset(task, description=f"{title}: {name}", total=None)

        def progress(done: int, total: int) -> None:
            prog.update(task, completed=done, total=total)

        yield ChunkBar(on_stage, progress)


__all__ = ["ChunkBar", "chunk_bar", "console", "dask_option", "executor"]
