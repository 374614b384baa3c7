"""What the CLI prints is the user's text as given: help strings keep their brackets, a path or name holding
Rich markup prints as it is on success too, and a malformed ``--dask`` is refused while the options are
parsed, on every verb that takes it, before any work starts."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.rig import dump_rig
from gtrig.sim.gtroom import make_scene

runner = CliRunner()


def _help(*verb: str) -> str:
    r = runner.invoke(app, [*verb, "--help"], env={"COLUMNS": "250"})
    assert r.exit_code == 0, r.output
    return " ".join(r.output.replace("│", " ").split())  # a wrapped help text, joined again


def test_help_keeps_its_brackets():
    # Typer renders help through Rich: an unescaped "[dask]" or "[default 0.002]" was silently dropped
    assert "pip install 'gtrig[dask]'" in _help("run")
    assert "[default 0.002]" in _help("survey", "points")


@pytest.mark.parametrize("verb", [["run", "-r", "{d}", "-o", "{d}/out"], ["demo", "--out", "{d}/demo"],
                                  ["vision"], ["laser", "track"], ["scanmatch", "pairs"]])
@pytest.mark.parametrize(("value", "why"), [("bogus", "local:N"), ("local:0", "1 <= N <= 256"),
                                            ("tcp//host", "local:N")])
def test_malformed_dask_refused_before_work(tmp_path: Path, verb: list[str], value: str, why: str):
    args = [a.replace("{d}", str(tmp_path)) for a in verb] + ["--dask", value]
    t = time.perf_counter()
    r = runner.invoke(app, args)
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "--dask" in lines[0] and why in lines[0], r.output
    assert time.perf_counter() - t < 5  # nothing simulated or detected first
    assert not (tmp_path / "out").exists() and not (tmp_path / "demo").exists()


def test_rig_check_prints_a_markup_name_as_is(tmp_path: Path):
    folder = tmp_path / "lab[/b]"
    folder.mkdir(parents=True)  # "lab[" and "b]": the path reads "lab[/b]", a closing tag
    p = folder / "rig[red].yaml"
    dump_rig(make_scene(3).rig_true, p)
    r = runner.invoke(app, ["rig", "check", str(p)], env={"COLUMNS": "400"})
    assert r.exit_code == 0, r.output
    assert f"{p}: valid rig" in r.output
