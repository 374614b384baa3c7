"""``gtrig <verb>``: the entry point. Sub-commands live in one small module each and import lazily."""

from __future__ import annotations

import importlib

import typer

from gtrig import __version__
from gtrig.cli.common import ONE_LINE_ERRORS_GROUP

app = typer.Typer(
    name="gtrig",
    help="Ground-truth robot trajectories from an instrumented room.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    cls=ONE_LINE_ERRORS_GROUP,
)

# (module under gtrig.cli, name, kind): "group" modules expose `app`, "command" modules a `command`.
_SUBCOMMANDS: tuple[tuple[str, str, str], ...] = (
    ("rig", "rig", "group"),
    ("sim", "sim", "command"),
    ("demo", "demo", "command"),
    ("run", "run", "command"),
    ("survey", "survey", "group"),
    ("evaluate", "evaluate", "group"),
    ("calib", "calib", "group"),
    ("markers", "markers", "group"),
    ("vision", "vision", "command"),
    ("robot_frame", "robot-frame", "command"),
    ("laser", "laser", "group"),
    ("import_", "import", "group"),
    ("export", "export", "command"),
    ("report", "report", "command"),
    ("fuse", "fuse", "command"),
    ("sync", "sync", "command"),
    ("gps", "gps", "command"),
    ("scanmatch", "scanmatch", "group"),
    ("plan", "plan", "command"),
)


def _register() -> None:
    for module, name, kind in _SUBCOMMANDS:
        try:
            mod = importlib.import_module(f"gtrig.cli.{module}")
        except ModuleNotFoundError as e:
            if e.name == f"gtrig.cli.{module}":
                continue  # a stage not built yet
            raise
        if kind == "group":
            app.add_typer(mod.app, name=name)
        else:
            app.command(name, help=mod.command.__doc__)(mod.command)


@app.callback(invoke_without_command=True)
def _root(
    version: bool = typer.Option(False, "--version", help="Print the version and exit."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Debug logging."),
) -> None:
    from gtrig.cli.common import setup_logging

    setup_logging(verbose)
    if version:
        typer.echo(f"gtrig {__version__}")
        raise typer.Exit()


_register()


def _terminate(signum: int, frame: object) -> None:
    # SIGTERM unwinds like an interrupt, so that temporaries are removed and nothing is half-written
    raise SystemExit(128 + signum)


def main() -> None:
    import signal

    signal.signal(signal.SIGTERM, _terminate)
    app()


if __name__ == "__main__":
    main()
