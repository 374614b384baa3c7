"""The chunk map (gtrig.executor): a chunk that keeps failing is reported with its label while the
others finish; a worker killed mid-chunk is replaced and its chunk redone, in the local pool and on a
Dask cluster of separate scheduler and worker processes (127.0.0.1); ``--dask`` refusals are one line
and exit code 2."""

from __future__ import annotations

import socket
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.errors import InputError
from gtrig.executor import Chunk, ChunkError, map_chunks, open_executor, parse_dask
from tests.scale.cluster import dask_cluster, fail_on, square_or_die

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory):
    with dask_cluster(tmp_path_factory.mktemp("dask"), nworkers=1) as address:
        yield address


def _one_line_exit_2(args: list[str]) -> str:
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "--dask" in lines[0] and "Traceback" not in r.output, (
        r.output)
    return lines[0]


def test_dask_refusals_are_one_line_and_exit_2(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    (tmp_path / "rec").mkdir()  # the options' own checks pass: what is left to refuse is --dask
    run = ["run", "--recording", str(tmp_path / "rec"), "--out", str(tmp_path / "out")]
    assert "local:N" in _one_line_exit_2([*run, "--dask", "somewhere"])
    assert "1 <= N" in _one_line_exit_2([*run, "--dask", "local:0"])
    # a scheduler that cannot be reached: a port on the loopback interface that nothing listens on
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.setattr("gtrig.executor.CONNECT_TIMEOUT_S", 2.0)
    msg = _one_line_exit_2([*run, "--dask", f"tcp://127.0.0.1:{port}"])
    assert f"tcp://127.0.0.1:{port}: no Dask scheduler answers" in msg
    # Dask not installed
    monkeypatch.setitem(sys.modules, "distributed", None)
    assert "pip install 'gtrig[dask]'" in _one_line_exit_2([*run, "--dask", "local:2"])
    assert parse_dask("local:3") == ("local", 3) and parse_dask("tcp://h:8786") == ("address", "tcp://h:8786")


@pytest.mark.parametrize("workers", [1, 2])
def test_failing_chunk_is_retried_then_reported_while_the_rest_finishes(workers: int) -> None:
    chunks = [Chunk((i, 2), f"camera c{i}, {i}.000-{i}.900 s") for i in range(6)]
    got: dict[int, int] = {}
    seen: list[tuple[int, int]] = []
    with pytest.raises(ChunkError, match=r"1 chunk\(s\) failed \(after up to 3 attempts.*camera c2, 2.000-2.900 s: "
                                         r"ValueError: chunk 2 is broken") as err:
        map_chunks(fail_on, chunks, got.__setitem__, workers=workers, retries=2,
                   progress=lambda d, n: seen.append((d, n)))
    assert got == {i: i * i for i in range(6) if i != 2}
    assert seen[0] == (0, 6) and seen[-1] == (6, 6)  # the failed chunk counts as done for the bar
    assert err.value.exit_code == 1


@pytest.mark.parametrize("workers", [1, 2])
def test_bad_input_in_a_chunk_is_not_retried_and_exits_2(workers: int, tmp_path: Path) -> None:
    counts = tmp_path / "attempts"
    got: dict[int, int] = {}
    with pytest.raises(ChunkError, match=r"camera c1, 1.000-1.900 s: image 1.png: not an image") as err:
        map_chunks(fail_on, [Chunk((i, 1, str(counts)), f"camera c{i}, {i}.000-{i}.900 s") for i in range(4)],
                   got.__setitem__, workers=workers)
    assert got == {0: 0, 2: 4, 3: 9} and counts.read_text() == "x" and err.value.exit_code == 2


def test_worker_killed_mid_chunk_is_replaced_in_the_local_pool(tmp_path: Path) -> None:
    flag = tmp_path / "killed"
    got: dict[int, tuple[int, int]] = {}
    map_chunks(square_or_die, [Chunk((i, str(flag)), f"chunk {i}") for i in range(8)], got.__setitem__, workers=2)
    assert flag.is_file() and sorted(got) == list(range(8))
    assert all(v[0] == i * i for i, v in got.items())
    assert got[3][1] != int(flag.read_text())  # chunk 3 was redone by another process


def test_worker_killed_mid_chunk_is_replaced_on_a_dask_cluster(cluster: str, tmp_path: Path) -> None:
    flag = tmp_path / "killed"
    got: dict[int, tuple[int, int]] = {}
    with open_executor(cluster) as client:
        map_chunks(square_or_die, [Chunk((i, str(flag)), f"chunk {i}") for i in range(6)], got.__setitem__,
                   executor=client)
        # the nanny started a new worker process in place of the killed one
        assert len(client.nthreads()) == 1
    assert flag.is_file() and sorted(got) == list(range(6))
    assert got[3][0] == 9 and got[3][1] != int(flag.read_text())


def test_a_concurrent_futures_executor_is_accepted() -> None:
    from concurrent.futures import ThreadPoolExecutor

    got: dict[int, int] = {}
    with ThreadPoolExecutor(2) as ex:
        with pytest.raises(ChunkError, match="chunk 1 is broken"):
            map_chunks(fail_on, [Chunk((i, 1), f"c{i}") for i in range(4)], got.__setitem__, executor=ex, retries=0)
    assert got == {0: 0, 2: 4, 3: 9}
    with pytest.raises(InputError, match="expected local:N"):
        with open_executor("nowhere"):
            pass
