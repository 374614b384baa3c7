"""Run the stages in order on one recording: validate, reuse what finished, hand products on, write.

The rules a stage can count on (gtrig.pipeline.context explains how a stage declares itself):

* the recording is checked once (a folder with ``rig.yaml``; the rig is read and validated) and the
  effective configuration is written as ``DIR/run.yaml`` before any stage runs;
* before any stage runs, every stage asked for has what it ``reads`` in the recording, else one line
  names the stage and the missing file (:class:`~gtrig.errors.InputError`, exit code 2);
* a stage whose ``consumes`` no earlier stage produced is skipped with one line naming the product; so
  is a stage that refuses its input (a :class:`~gtrig.errors.GtrigError`: too few views, no
  markers...): one stage's refusal must not hide the others' results (the run's exit code is then the
  error's);
* a finished stage is reused when its key is unchanged (gtrig.pipeline.cache); ``from_stage`` reruns
  that stage and every later one; ``only`` runs just those stages (the others reused when finished);
* the products of each stage are handed to the next as objects; a new ``rig`` is also written as
  ``DIR/rig.calibrated.yaml``; the truth rows go to ``DIR/accuracy.csv``, the checks to
  ``DIR/summary.csv``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gtrig.config import RunConfig, write_config
from gtrig.errors import ConfigError, GtrigError, InputError
from gtrig.io.recording import recording_dir
from gtrig.memory import release_free_memory
from gtrig.pipeline import cache
from gtrig.pipeline.context import AccuracyRow, Products, Stage, StageInput, StageOutput
from gtrig.pipeline.rows import write_accuracy_csv

log = logging.getLogger(__name__)

#: why a stage left out by ``--stages`` did not run
NOT_ASKED = "not asked for (--stages) and not finished before"


@dataclass(frozen=True)
class PipelineResult:
    """What a run did.

    Attributes
    ----------
    rows : the accuracy table against truth (empty without truth).
    checks : the figures that need no truth; ``ok=False`` ones are warnings.
    seconds : wall time per stage run (a reused stage: its lookup).
    skipped : {stage name: why} for the stages that did not give a result.
    refused : {stage name: the one-line message} for the stages that refused their input (also in
        ``skipped``); the caller reports each as an error.
    reused : names of the stages taken from their last run.
    products : the final context (rig, survey, pose tracks by name...).
    exit_code : 0, or the largest exit code of the errors that stopped a stage (2 bad input, 3 no
        convergence).
    """

    rows: tuple[AccuracyRow, ...]
    seconds: dict[str, float]
    skipped: dict[str, str]
    checks: tuple[AccuracyRow, ...] = ()
    reused: tuple[str, ...] = ()
    products: Products = Products()
    exit_code: int = 0
    refused: dict[str, str] = field(default_factory=dict)

    @property
    def warnings(self) -> tuple[AccuracyRow, ...]:
        return tuple(c for c in self.checks if c.ok is False)


def stage_names(stages: Sequence[Stage]) -> tuple[str, ...]:
    return tuple(s.name for s in stages)


def _check_names(stages: Sequence[Stage], names: Sequence[str], what: str) -> None:
    known = stage_names(stages)
    bad = [n for n in names if n not in known]
    if bad:
        raise ConfigError(f"{what}: unknown stage {bad[0]!r}; the stages are {', '.join(known)}")


def run_stages(stages: Sequence[Stage], rec: str | Path, out: str | Path, config: RunConfig | None = None, *,
               only: Sequence[str] | None = None, from_stage: str | None = None, reuse: bool = True,
               on_stage: Callable[[str], None] | None = None, executor: Any = None,
               progress: Callable[[int, int], None] | None = None) -> PipelineResult:
    """Run ``stages`` on the recording ``rec``, writing under ``out`` (module docstring); chunks run on
    ``executor`` (:mod:`gtrig.executor`; None: local processes, ``config.workers``), ``progress`` follows
    them."""
    from gtrig.rig import load_rig

    cfg = config or RunConfig()
    if only:
        _check_names(stages, only, "--stages")
    if from_stage:
        _check_names(stages, [from_stage], "--from")
    rec_p = recording_dir(rec)
    rig = load_rig(rec_p / "rig.yaml")
    out_p = Path(out)
    out_p.mkdir(parents=True, exist_ok=True)
    write_config(cfg, out_p / "run.yaml")
    has_truth = (rec_p / "truth").is_dir()
    for st in stages:
        if only and st.name not in only:
            continue
        missing = [r for r in st.reads if not (rec_p / r).exists()]
        if missing:
            raise InputError(f"stage {st.name} needs {rec_p / missing[0]}, which the recording lacks "
                             "(docs/formats.md; leave the stage out with --stages)")
    products = Products(rig=rig)
    producer_key: dict[str, str] = {"rig": cache.stage_key("recording", None, cache.recording_prints(rec_p, ()), {})}
    rows: list[AccuracyRow] = []
    checks: list[AccuracyRow] = []
    seconds: dict[str, float] = {}
    skipped: dict[str, str] = {}
    refused: dict[str, str] = {}
    reused: list[str] = []
    rerun = False
    exit_code = 0
    for st in stages:
        rerun = rerun or st.name == from_stage
        wanted = not only or st.name in only
        if any(not (rec_p / r).exists() for r in st.reads):
            skipped[st.name] = "not asked for (--stages), and the recording lacks what it reads"
            continue
        absent = [c for c in st.consumes if not products.has(c)]
        if absent:
            skipped[st.name] = f"needs {absent[0]}, which no earlier stage produced"
            log.warning("%s: skipped: %s", st.name, skipped[st.name])
            continue
        section = getattr(cfg, st.section).model_dump(mode="json") if st.section else None
        upstream = {c: producer_key.get(c, "") for c in (*st.consumes, *st.uses)}
        key = cache.stage_key(st.name, section, cache.recording_prints(rec_p, st.reads), upstream)
        t = time.perf_counter()
        result: StageOutput | None = None
        if reuse and not (rerun and wanted):
            result = cache.load_record(out_p, st.name, key)
            if result is not None:
                reused.append(st.name)
                log.info("%s: reused (finished before with the same inputs, options and code)", st.name)
        if result is None and not wanted:
            skipped[st.name] = NOT_ASKED
            continue
        if result is None:
            if on_stage:
                on_stage(st.title)
            cache.forget(out_p, st.name)
            inp = StageInput(rec_p, out_p, cfg, products, has_truth, cfg.workers, executor, progress)
            try:
                result = st.fn(inp)
            except GtrigError as e:
                log.debug("%s refused its input: %s", st.title, e)  # the caller reports it (``refused``)
                skipped[st.name] = refused[st.name] = str(e)
                exit_code = max(exit_code, e.exit_code)
                seconds[st.name] = time.perf_counter() - t
                continue
            st.check_output(result)
            cache.save_record(out_p, st.name, key, result)
            # what the stage freed goes back to the system before the next one allocates its own: on an
            # hour's recording the client otherwise held every stage's peak (gtrig.memory)
            release_free_memory()
        products = products.updated(result.products)
        for name in result.products:
            producer_key[name] = key
        rows.extend(result.rows)
        checks.extend(result.checks)
        seconds[st.name] = time.perf_counter() - t
    _write_rig(stages, products, skipped, out_p / "rig.calibrated.yaml")
    if rows:
        write_accuracy_csv(out_p / "accuracy.csv", rows)
    if checks:
        write_accuracy_csv(out_p / "summary.csv", checks)
    return PipelineResult(tuple(rows), seconds, skipped, tuple(checks), tuple(reused), products, exit_code,
                          refused)


def _write_rig(stages: Sequence[Stage], products: Products, skipped: dict[str, str], path: Path) -> None:
    """The run's rig into ``path``, unless a stage that calibrates part of it was left out while an earlier
    run's file is there: that file would otherwise lose the part (a run of the camera stages alone wrote
    the recording's nominal scanner poses over the calibrated ones). Nothing is written when no stage that
    calibrates the rig ran or was reused."""
    from gtrig.rig.load import dump_rig

    left_out = [st.name for st in stages if "rig" in st.produces and skipped.get(st.name) == NOT_ASKED]
    if left_out and path.is_file():
        log.warning("%s kept from an earlier run: this run left out %s", path.name, ", ".join(left_out))
        return
    if any("rig" in st.produces and st.name not in skipped for st in stages):
        dump_rig(products.rig, path)  # type: ignore[arg-type]
