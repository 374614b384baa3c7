"""One way to map chunks of work over processes: this machine's process pool or a Dask cluster.

Every stage that maps over frames, instants or scan pairs cuts its work into chunks (a camera and a
time window, a run of instants, a run of pairs) and hands them to :func:`map_chunks` with an
*executor*:

* ``None``: a local process pool of ``workers`` processes (0 = one per core, 1 = in this process),
  opened for the map and closed after it (:func:`gtrig.parallel.process_pool`);
* any object with ``submit(fn, *args) -> future`` whose future has ``result()``: a
  ``concurrent.futures.Executor`` or a ``distributed.Client`` (a user's own, or the one
  :func:`open_executor` makes for ``--dask local:N`` and ``--dask tcp://HOST:PORT``).

Chunks are independent and their results are handed back to the caller in the client as they
complete (the caller checkpoints them), so the output never depends on the executor, the number of
workers or the order chunks finish. A chunk that raises is submitted again (``retries`` times),
then reported with its label (camera and time window) while the others go on; the map then raises
:class:`ChunkError` naming them. Only a window of chunks is in flight at once, so neither the
client nor the cluster holds more than that many results. Dask is imported only when asked for
(``pip install gtrig[dask]``).
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from gtrig.errors import GtrigError, InputError

log = logging.getLogger(__name__)

#: seconds to wait for a Dask scheduler before saying it cannot be reached
CONNECT_TIMEOUT_S = 10.0


class ExecutorLike(Protocol):
    """What :func:`map_chunks` needs of an executor (``concurrent.futures.Executor``, ``distributed.Client``)."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Any: ...


#: ``progress(done_chunks, total_chunks)``, called in the client
Progress = Callable[[int, int], None]


class ChunkError(GtrigError):
    """Chunks that failed after their retries; the others finished (and were checkpointed). Exit code 2
    when every one failed on bad input (an unreadable image: never retried), else 1."""

    exit_code = 1


@dataclass(frozen=True)
class _Failure:
    index: int
    message: str
    bad_input: bool


@dataclass(frozen=True)
class Chunk:
    """One unit of work: ``fn(*args)`` run on a worker; ``label`` says what it covers (for messages)."""

    args: tuple[Any, ...]
    label: str


def is_dask(executor: Any) -> bool:
    """A ``distributed.Client`` (told apart without importing Dask)."""
    return type(executor).__module__.split(".")[0] == "distributed"


def slots(executor: Any, workers: int = 0) -> int:
    """How many chunks the executor runs at once (Dask: the cluster's threads now; it may grow)."""
    if executor is None:
        return workers if workers > 0 else (os.cpu_count() or 1)
    if is_dask(executor):
        try:
            return max(1, sum(executor.nthreads().values()))
        except Exception:  # a scheduler that went away answers on the next submit
            return 1
    return max(1, int(getattr(executor, "_max_workers", 0) or os.cpu_count() or 1))


# ------------------------------------------------------------------------------------ opening one
def parse_dask(spec: str) -> tuple[str, int | str]:
    """``local:N`` -> ("local", N); ``tcp://HOST:PORT`` (any ``scheme://``) -> ("address", spec).

    Raises
    ------
    InputError
        Anything else (one line naming ``--dask``).
    """
    s = spec.strip()
    m = re.fullmatch(r"local:(\d+)", s)
    if m:
        n = int(m.group(1))
        if not 1 <= n <= 256:
            raise InputError(f"--dask {spec}: local:N needs 1 <= N <= 256 worker processes")
        return "local", n
    if re.fullmatch(r"[a-z][a-z0-9+]*://\S+", s):
        return "address", s
    raise InputError(f"--dask {spec!r}: expected local:N (a cluster on this machine) or a scheduler's "
                     "address such as tcp://HOST:8786")


def _import_distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise InputError("--dask needs Dask's distributed scheduler: pip install 'gtrig[dask]'") from None
    return distributed


@contextlib.contextmanager
def open_executor(dask: str | None = None, *, connect_timeout_s: float | None = None) -> Iterator[Any]:
    """The executor ``--dask`` asks for, closed on exit; ``None`` when ``dask`` is None (each map
    then opens its own local process pool).

    ``local:N``: a ``LocalCluster`` of N worker processes of one thread each, on 127.0.0.1, started
    here and stopped on exit. An address: a client of that running scheduler (its workers must see
    the recording and the results folder at the same paths, docs/scale.md).

    Raises
    ------
    InputError
        Dask not installed, a malformed spec, or a scheduler that does not answer within
        ``connect_timeout_s`` (default :data:`CONNECT_TIMEOUT_S`; one line).
    """
    if dask is None:
        yield None
        return
    kind, value = parse_dask(dask)
    distributed = _import_distributed()
    from dask import config as dask_config

    with contextlib.ExitStack() as stack:
        # Dask's event logs keep whole messages, a chunk's arguments included, 10,000 of them: a client
        # (and a LocalCluster's scheduler, in this process) then grows by the size of the chunks sent
        # (18 kB per GTvision instant, bench/scale.py). A hundred are enough to diagnose.
        stack.enter_context(dask_config.set({"distributed.admin.log-length": 100,
                                             "distributed.admin.low-level-log-length": 100}))
        if kind == "local":
            # our cluster's own chatter (scheduler, nannies, a dashboard port taken) is not the user's news
            quiet = logging.getLogger("distributed")
            stack.callback(quiet.setLevel, quiet.level)
            quiet.setLevel(logging.WARNING)
            # Dask's statistical profiler samples every worker's stack 100 times a second: not for
            # CPU-bound chunks (docs/scale.md: turn it off on a cluster of your own the same way)
            stack.enter_context(dask_config.set({"distributed.worker.profile.enabled": False}))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                # one thread per worker: the stages are CPU-bound Python/NumPy; OpenCV and BLAS are kept to
                # one thread inside each task too
                cluster = stack.enter_context(distributed.LocalCluster(
                    n_workers=int(value), threads_per_worker=1, processes=True, host="127.0.0.1",
                    dashboard_address="127.0.0.1:0" if _has_dashboard() else None, silence_logs=logging.WARNING))
                client = stack.enter_context(distributed.Client(cluster))
        else:
            wait_s = CONNECT_TIMEOUT_S if connect_timeout_s is None else connect_timeout_s
            try:
                client = distributed.Client(str(value), timeout=f"{wait_s}s")
            except (OSError, TimeoutError) as e:
                raise InputError(f"--dask {value}: no Dask scheduler answers there within {wait_s:g} s "
                                 f"({type(e).__name__}); start one with 'dask scheduler' or check the address"
                                 ) from None
            stack.callback(client.close)
        link = dashboard_link(client)
        log.debug("Dask: %s, %d worker thread(s)%s", getattr(client, "scheduler", None) and
                 client.scheduler.address, slots(client), f"; dashboard {link}" if link else "")
        yield client


def _has_dashboard() -> bool:
    try:
        import bokeh  # noqa: F401
    except ImportError:
        return False
    return True


def dashboard_link(executor: Any) -> str | None:
    """Dask's dashboard address, when there is one (bokeh installed on the scheduler)."""
    if not is_dask(executor):
        return None
    try:
        info = executor.scheduler_info()
        port = info.get("services", {}).get("dashboard")
    except Exception:
        return None
    return executor.dashboard_link if port else None


# ------------------------------------------------------------------------------------- the map
def _pickled_call(fn: Callable[..., Any], *args: Any) -> bytes:
    """``fn(*args)`` pickled on the worker. Dask hands NumPy arrays back as views into the message that
    carried them, so one small array kept (a pose) would pin its whole chunk's message in the client:
    with the result pickled in-band, every array owns its own memory (measured: 18 kB per GTvision
    instant kept otherwise, bench/scale.py)."""
    import pickle

    return pickle.dumps(fn(*args), protocol=pickle.HIGHEST_PROTOCOL)


class _Pending:
    """The chunks in flight on one executor, waited on the way that executor's futures need."""

    def __init__(self, executor: Any) -> None:
        self.ex = executor
        self.dask = is_dask(executor)
        self.futures: dict[Any, int] = {}

    def submit(self, fn: Callable[..., Any], i: int, args: tuple[Any, ...]) -> None:
        # pure=False: a chunk submitted again after a failure must run again, not reuse the failed key
        fut = self.ex.submit(_pickled_call, fn, *args, pure=False) if self.dask else self.ex.submit(fn, *args)
        self.futures[fut] = i

    def result(self, fut: Any) -> Any:
        if self.dask:
            import pickle

            return pickle.loads(fut.result())
        return fut.result()

    def wait(self) -> list[tuple[int, Any]]:
        """Block until one or more chunks finish; their (index, future), removed from the pending."""
        if self.dask:
            from distributed import wait
        else:
            from concurrent.futures import wait
        done, _ = wait(list(self.futures), return_when="FIRST_COMPLETED")
        return [(self.futures.pop(f), f) for f in done]

    def cancel(self) -> None:
        for f in self.futures:
            f.cancel()
        self.futures.clear()


def _in_process(fn: Callable[..., Any], chunks: Sequence[Chunk], todo: Sequence[int], retries: int,
                on_result: Callable[[int, Any], None], failed: list[_Failure], tick: Callable[[], None]) -> None:
    for i in todo:
        for attempt in range(retries + 1):
            try:
                res = fn(*chunks[i].args)
            except MemoryError:
                raise
            except Exception as e:
                if _give_up(chunks[i].label, i, e, attempt + 1, retries, failed):
                    break
                continue
            on_result(i, res)
            break
        tick()


def _give_up(label: str, i: int, e: Exception, attempt: int, retries: int, failed: list[_Failure]) -> bool:
    """Log a chunk's failure; True (and recorded in ``failed``) when it is not to be submitted again: its
    retries are used up, or its input is bad (a GtrigError: the same again)."""
    bad_input = isinstance(e, GtrigError)
    if attempt <= retries and not bad_input:
        log.warning("chunk %s failed (attempt %d of %d), submitted again: %s: %s", label, attempt, retries + 1,
                    type(e).__name__, e)
        return False
    log.error("chunk %s failed%s; going on without it: %s: %s", label, "" if bad_input else f" {attempt} times",
              type(e).__name__, e)
    failed.append(_Failure(i, f"{label}: {e}" if bad_input else f"{label}: {type(e).__name__}: {e}", bad_input))
    return True


def map_chunks(fn: Callable[..., Any], chunks: Sequence[Chunk], on_result: Callable[[int, Any], None], *,
               executor: Any = None, workers: int = 0, todo: Sequence[int] | None = None, retries: int = 2,
               progress: Progress | None = None, window: int | None = None) -> None:
    """Run ``fn(*chunk.args)`` for the chunks ``todo`` (default all) and hand each result to
    ``on_result(index, result)`` in this process, in the order they finish.

    Parameters
    ----------
    fn : a module-level function (pickled by reference to the workers).
    chunks : every chunk of the job (``progress`` counts those not in ``todo`` as done).
    on_result : called in the client for each finished chunk (checkpoint it here).
    executor : ``None`` (a local pool of ``workers``), a ``concurrent.futures.Executor`` or a Dask client.
    workers : local processes when ``executor`` is None (0 = one per core, 1 = in this process).
    retries : submissions after a chunk's first failure (a dead worker is a failure too).
    window : chunks in flight at once (default: four per worker slot).

    Raises
    ------
    ChunkError
        Some chunks failed ``retries + 1`` times: after every other chunk finished, naming each.
    """
    todo = list(range(len(chunks))) if todo is None else list(todo)
    n_done = len(chunks) - len(todo)
    failed: list[_Failure] = []

    def tick() -> None:
        nonlocal n_done
        n_done += 1
        if progress:
            progress(n_done, len(chunks))

    if progress:
        progress(n_done, len(chunks))
    if executor is None and (slots(None, workers) == 1 or len(todo) <= 1):
        _in_process(fn, chunks, todo, retries, on_result, failed, tick)
    elif executor is None:
        _local_pool_map(fn, chunks, todo, slots(None, workers), retries, on_result, failed, tick, window)
    else:
        _distributed_map(fn, chunks, todo, executor, retries, on_result, failed, tick, window)
    if failed:
        err = ChunkError(f"{len(failed)} chunk(s) failed (after up to {retries + 1} attempts; the rest are "
                         "checkpointed, rerun to retry them): " + "; ".join(f.message for f in failed[:5])
                         + (" ..." if len(failed) > 5 else ""))
        if all(f.bad_input for f in failed):
            err.exit_code = 2
        raise err


def _local_pool_map(fn: Callable[..., Any], chunks: Sequence[Chunk], todo: list[int], nproc: int, retries: int,
                    on_result: Callable[[int, Any], None], failed: list[_Failure], tick: Callable[[], None],
                    window: int | None) -> None:
    """A pool of our own: a worker that died (killed, out of memory) breaks a ``ProcessPoolExecutor``
    for good, so a new pool takes over the chunks that were not finished."""
    from concurrent.futures.process import BrokenProcessPool

    from gtrig.parallel import process_pool

    finished: set[int] = set()

    def keep(i: int, res: Any) -> None:
        finished.add(i)
        on_result(i, res)

    for attempt in range(retries + 1):
        gave_up = {f.index for f in failed}
        rest = [i for i in todo if i not in finished and i not in gave_up]
        try:
            with process_pool(nproc) as ex:
                _distributed_map(fn, chunks, rest, ex, retries, keep, failed, tick, window)
            return
        except BrokenProcessPool:
            if attempt == retries:
                raise
            log.warning("a worker process died; a new pool takes over the %d unfinished chunk(s)",
                        len([i for i in todo if i not in finished]))


def _distributed_map(fn: Callable[..., Any], chunks: Sequence[Chunk], todo: list[int], ex: Any, retries: int,
                     on_result: Callable[[int, Any], None], failed: list[_Failure], tick: Callable[[], None],
                     window: int | None) -> None:
    from concurrent.futures.process import BrokenProcessPool

    pending = _Pending(ex)
    attempts = dict.fromkeys(todo, 0)
    queue = list(reversed(todo))  # popped from the end: submitted in order
    limit, asked = window or 4 * slots(ex), time.monotonic()
    try:
        while queue or pending.futures:
            if window is None and time.monotonic() - asked > 5.0:  # a cluster may grow (or shrink)
                limit, asked = 4 * slots(ex), time.monotonic()
            while queue and len(pending.futures) < limit:
                i = queue.pop()
                attempts[i] += 1
                pending.submit(fn, i, chunks[i].args)
            for i, fut in pending.wait():
                try:
                    res = pending.result(fut)
                except (MemoryError, BrokenProcessPool):
                    raise  # a broken local pool cannot take more: its owner starts another (done chunks kept)
                except Exception as e:
                    if not _give_up(chunks[i].label, i, e, attempts[i], retries, failed):
                        queue.append(i)
                    else:
                        tick()
                    continue
                del fut  # a Dask result is released on the cluster as soon as it is handed on
                on_result(i, res)
                tick()
    except BaseException:
        # interrupted (Ctrl-C) or failed: drop what has not started rather than waiting for it
        pending.cancel()
        raise


__all__ = ["CONNECT_TIMEOUT_S", "Chunk", "ChunkError", "ExecutorLike", "Progress", "dashboard_link",
           "is_dask", "map_chunks", "open_executor", "parse_dask", "slots"]
