"""The error layer: every failure one plain line and an exit code; YAML limits; all-or-none outputs;
temporaries removed on SIGTERM and after a SIGKILL; outputs with the umask's mode."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from typer.testing import CliRunner

from gtrig.cli.common import handle_errors
from gtrig.cli.main import app
from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_group, atomic_open, remove_stale_temporaries
from gtrig.io.yamlfile import MAX_DEPTH, parse_yaml

runner = CliRunner()


def _one_error_line(output: str) -> str:
    lines = [x for x in output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), output
    assert "Traceback" not in output
    return lines[0]


LAUGHS = "a: &a [" + ",".join(['"lol"'] * 9) + "]\n" + "".join(
    f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=True))


@pytest.mark.parametrize(("text", "why"), [
    (LAUGHS, "aliases are expanded"),
    ("[" * (MAX_DEPTH + 5) + "]" * (MAX_DEPTH + 5), "nested deeper"),
    ("a: &x [*x]", "not valid YAML|recursive"),
    ("a: [1, 2\n", "not valid YAML"),
])
def test_yaml_refused_in_bounded_time(tmp_path, text, why):
    p = tmp_path / "rig.yaml"
    p.write_text(text)
    t = time.perf_counter()
    r = runner.invoke(app, ["rig", "check", str(p)])
    assert r.exit_code == 2
    line = _one_error_line(r.output)
    assert str(p) in line
    import re
    assert re.search(why, line), line
    assert time.perf_counter() - t < 10


def test_yaml_ordinary_aliases_still_load():
    doc = parse_yaml("base: &b {x: 1}\nother: *b\n", "t.yaml")
    assert doc == {"base": {"x": 1}, "other": {"x": 1}}


def test_markup_in_a_file_name_prints_as_is(tmp_path):
    p = tmp_path / "x[/b]y[/i].yaml"
    r = runner.invoke(app, ["rig", "check", str(p)])
    assert r.exit_code == 2
    assert "x[/b]y[/i].yaml" in _one_error_line(r.output)


def test_binary_rig_is_one_line(tmp_path):
    p = tmp_path / "rig.yaml"
    p.write_bytes(bytes(range(256)) * 4)
    r = runner.invoke(app, ["rig", "check", str(p)])
    assert r.exit_code == 2
    _one_error_line(r.output)


@pytest.mark.parametrize(("exc", "code", "text"), [
    (FormatError("f.csv:3: bad"), 2, "f.csv:3: bad"),
    (FileNotFoundError(2, "No such file or directory", "/nowhere/x"), 2, "/nowhere/x"),
    (IsADirectoryError(21, "Is a directory", "/tmp"), 2, "is a folder"),
    (PermissionError(13, "Permission denied", "/root/x"), 2, "Permission denied"),
    (ValueError("something\nwe did not expect"), 1, "unexpected ValueError"),
])
def test_handle_errors_maps_to_one_line(capsys, monkeypatch, tmp_path, exc, code, text):
    monkeypatch.setenv("GTRIG_LOG_DIR", str(tmp_path))

    @handle_errors
    def verb() -> None:
        raise exc

    with pytest.raises(SystemExit) as e:
        verb()
    assert e.value.code == code
    err = capsys.readouterr().err
    line = _one_error_line(err)
    assert text in line
    if code == 1:
        # the traceback is kept in a log named on the line
        logs = list(tmp_path.glob("gtrig-crash-*.log"))
        assert logs and "Traceback" in logs[0].read_text() and str(logs[0]) in line


def test_atomic_group_all_or_none(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    with pytest.raises(RuntimeError), atomic_group(a, b) as (ta, tb):
        ta.write_text("new a")
        raise RuntimeError("the second output failed")
    assert a.read_text() == "old a" and not b.exists()
    assert not list(tmp_path.glob(".*.tmp"))
    with atomic_group(a, b) as (ta, tb):
        ta.write_text("new a")
        tb.write_text("new b")
    assert a.read_text() == "new a" and b.read_text() == "new b"
    # a folder in the way of the second output: refused before the first is replaced
    c = tmp_path / "c.txt"
    c.mkdir()
    with pytest.raises(IsADirectoryError), atomic_group(a, c) as (ta, tc):
        ta.write_text("newer a")
        tc.write_text("c")
    assert a.read_text() == "new a" and c.is_dir() and not list(tmp_path.glob(".*.tmp"))


def test_outputs_follow_the_umask(tmp_path):
    with atomic_open(tmp_path / "x.txt") as f:
        f.write("x")
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "x.txt").stat().st_mode & 0o777 == 0o666 & ~mask


def test_stale_temporaries_of_dead_processes_removed(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)
    pid = int(dead.stdout)
    stale = tmp_path / f".out.tum.{pid}.abc123.tmp"
    stale.write_text("half")
    mine = tmp_path / f".out.tum.{os.getpid()}.def456.tmp"
    mine.write_text("in progress")
    assert remove_stale_temporaries(tmp_path) == [stale]
    assert mine.exists() and not stale.exists()


def test_sigterm_removes_the_temporary(tmp_path):
    script = f"""
import signal, time
from gtrig.cli.main import _terminate
from gtrig.io.atomic import atomic_open
signal.signal(signal.SIGTERM, _terminate)
with atomic_open({str(tmp_path / 'out.txt')!r}) as f:
    f.write('partial')
    print('writing', flush=True)
    time.sleep(60)
"""
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert p.stdout is not None and p.stdout.readline().strip() == "writing"
    assert list(tmp_path.glob(".out.txt.*.tmp"))
    p.send_signal(signal.SIGTERM)
    assert p.wait(timeout=30) == 128 + signal.SIGTERM
    assert not list(tmp_path.iterdir())
