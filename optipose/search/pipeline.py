"""``optipose search`` as a pipeline: its stages in order, each result on disk as soon as it exists.

1. the config goes to the result folder first, so even an interrupted run explains itself; a resumed run
   reloads the per-sensor cache and replays its earlier evaluations for free (same seed, same sequence);
2. the NLopt search on the surrogate (:mod:`optipose.search.surrogate_search`: screen, greedy, joint), the
   history and cache flushed to the folder as it goes, the surrogate's best layouts written at its end;
3. the ICP selection, polish and confirmation (:mod:`optipose.search.select`), after which the finalists
   replace the surrogate's best; under a band of conditions they score the robust statistic over the
   band's ends (:func:`optipose.search.objectives.search_objective`) and compare with the hand layout condition by condition;
4. validation on a noise seed the search never saw (:mod:`optipose.search.validate`), under every
   condition of the band: the numbers reported. A search whose objective has no band then checks the
   found layouts and the hand one under the band of ``SearchConfig.validation.band_objective`` (the ``default`` and ``thorough`` budgets in the ideal cell:
   ``objectives/robust.toml``'s noise levels and bracket tolerance), on the same held-out seed: a layout
   that wins only in the simulation's ideal cell is not a layout to buy. Every budget validates on the objective's protocol
   (``[search.validation] protocol = "reduced"`` cuts it to 14 of the paper's 77 scans; the table says so). The
   hand layout's part of it starts with step 2, in ``jobs`` processes of its own (``jobs`` ≥ 2), and is waited
   for before step 3;
5. the verdict with confidence (:mod:`optipose.search.draws`): the validation's evaluations are its first
   draw in the ideal cell (in a real cell the choices were made on them), and further draws of the cell on
   seeds of their own are raced until every k is BUY, KEEP or TIE, before the check under the band.

Every result goes to a :class:`ResultSink` the caller gives (``optipose.io.search.SearchFolder`` writes a
result folder), so the search itself never touches the file system.
"""

from __future__ import annotations

import logging
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Protocol

from optipose.errors import OptiposeError, is_interrupt
from optipose.model.layout import Layout, SensorPose
from optipose.search.config import SearchConfig
from optipose.search.objectives import stage_objective
from optipose.search.problem import SurrogateProblem
from optipose.search.records import Found, SearchOutcome, Validation
from optipose.search.space import SPACE_VERSION
from optipose.search.study import SurrogateStudy
from optipose.search.surrogate_search import run_search
from optipose.seeds import validation_seed
from optipose.model.baseline import baseline

__all__ = ["SearchReport", "ResultSink", "run", "found_layout", "NoFeasibleLayout"]

log = logging.getLogger(__name__)
_FLUSH_EVERY = 100  # evaluations between writes of the history and the cache...
_FLUSH_GAP = 10.0  # ... and seconds: what a kill can lose, and a resume recomputes


class NoFeasibleLayout(OptiposeError):
    """The search met no layout that satisfies the constraints (e.g. the sensors cannot see the part)."""


class ResultSink(Protocol):
    """Where a search's results go as they appear (``optipose.io.search.SearchFolder``)."""

    def start(
        self, part, objective, config: SearchConfig, budget: str, seed: int, validation_seed: int, band=None
    ) -> None: ...

    def load_cache(self, space_version: int) -> dict: ...

    def flush(self, history: list, cache, space_version: int) -> None: ...

    def layouts(self, layouts: dict[int, Layout], hand: Layout | None) -> None: ...

    def selection(self, records: list) -> None: ...

    def surrogate_scores(self, outcome: SearchOutcome) -> None: ...

    def evaluation(self, name: str, result) -> None: ...

    def validation(self, validation: Validation) -> None: ...

    def verdict_draw(self, draw: int, name: str, result) -> None: ...

    def verdict(self, verdicts: dict) -> None: ...

    def band_evaluation(self, name: str, result) -> None: ...

    def band(self, validation: Validation) -> None: ...


@dataclass
class SearchReport:
    """A search run: the surrogate's outcome, the layouts found per k and their validation."""

    outcome: SearchOutcome
    layouts: dict[int, Layout] = field(default_factory=dict)
    validation: Validation | None = None
    band: Validation | None = None  # the check under the band (validation.band_objective), when there was one
    band_interrupted: bool = False  # Ctrl-C stopped the check under the band (the validation is complete)
    confident: dict = field(default_factory=dict)  # k -> ConfidentVerdict (search/draws.py)

    @property
    def validated(self) -> bool:
        return self.validation is not None


def run(
    part,
    objective,
    config: SearchConfig,
    seed: int,
    sink: ResultSink,
    budget: str = "default",
    jobs: int = 1,
    resume: bool = False,
    on_eval=None,
    on_stage=None,
) -> SearchReport:
    """Search, validate and hand everything to ``sink``. ``on_eval(evaluation)`` follows the surrogate
    search; ``on_stage(text)`` is told when a stage starts; ``resume`` reloads the sink's cache."""
    from threadpoolctl import threadpool_limits

    # one BLAS thread in this process: its products are the surrogate's small ones (6 × points), and the hand
    # layout's processes run beside it on every core, where a second BLAS thread only waits for a busy core and
    # slows every product many times over (benchmarks/README.md, "bench_surrogate_threads.py")
    with threadpool_limits(limits=1, user_api="blas"):
        return _search(part, objective, config, seed, sink, budget, jobs, resume, on_eval, on_stage)


def _search(part, objective, config, seed, sink, budget, jobs, resume, on_eval, on_stage) -> SearchReport:
    started = time.monotonic()  # answer_time counts from here
    band = stage_objective(
        objective, "band", band=config.validation.band_objective
    )  # a bad name fails here, before any work
    sink.start(part, objective, config, budget, seed, validation_seed(seed), band)
    if on_stage:  # at once: the surrogate's set-up and the start of the hand layout's processes are part of the stage
        on_stage("searching on the surrogate")
    with (
        _shared_reference(part, jobs) as folder,
        _baseline_run(part, objective, config, seed, jobs, folder) as hand_run,
        _baseline_run(part, band, config, seed, jobs, folder, last=True) as band_run,
    ):
        study = _study(
            part, objective, config, sink, resume, on_eval
        )  # after the hand layout's processes start: they set up beside it
        return _run(part, objective, config, seed, sink, jobs, study, on_stage, hand_run, band, band_run, started)


@contextmanager
def _shared_reference(part, jobs: int):
    """The folder of the part's CAD-surface reference on this machine (:mod:`optipose.parallel.shared`), built
    once for the search's processes: its surrogate, the hand layout's processes and the validation's workers
    map it. ``None`` in one process (``jobs`` 1): the surrogate builds its own, as the evaluator's one worker."""
    from optipose.parallel import shared

    if jobs < 2:
        yield None
        return
    key, folder = shared.acquire(part.mesh.vertices, part.mesh.faces)
    try:
        yield folder
    finally:
        shared.release(key)


def _baseline_run(part, objective, config: SearchConfig, seed: int, jobs: int, folder: str | None, last: bool = False):
    """The hand layout's validation (``objective``: the search's, or the band's for the check after it),
    started beside the surrogate search when there are cores for both (``jobs`` ≥ 2), in ``jobs`` processes
    mapping the reference in ``folder``; a do-nothing context otherwise, or without an objective. ``last``: at
    the lowest priority, so that it takes only what nothing else wants (it is not waited for before the
    selection, whose clock is wall time)."""
    from contextlib import nullcontext

    from optipose.search.validate import BaselineRun

    if objective is None or jobs < 2:
        return nullcontext()
    return BaselineRun(
        part, objective, seed, config.validation.protocol, last=last, processes=jobs, reference_dir=folder
    )


def _run(
    part, objective, config, seed, sink, jobs, study, on_stage, hand_run, band, band_run, started: float
) -> SearchReport:
    stage = on_stage or (lambda text: None)
    outcome = run_search(part, objective, config, seed, study)
    _flush(sink, study)
    if not outcome.found:
        raise NoFeasibleLayout(
            f"no feasible layout for '{part.name}': in {len(outcome.history)} evaluations no sensor pose returned "
            f"{config.constraints.min_points} points without its head hitting the part or a keep-out (can the sensors see "
            f"this part at all? check --units, the material and the part's size against the {config.constraints.clearance * 1e3:.0f} mm clearance)"
        )
    hand = baseline(part)
    report = SearchReport(outcome, _layouts(outcome.found))
    sink.layouts(report.layouts, hand)  # the surrogate's best, on disk before anything slower
    if config.selection.candidates > 0 and not outcome.interrupted:
        from optipose.search.select import select_finalists

        if hand_run is not None:  # the selection's clock is wall time: it runs alone on the cores
            stage("evaluating the hand layout (held-out noise seed)")
            hand_run.wait()
        stage("selecting finalists by ICP on a reduced protocol")
        finalists, records = select_finalists(
            part, objective, outcome, study, seed, config.selection.candidates, config.selection.time, on_stage, jobs
        )
        sink.selection(records)
        report.layouts = _layouts({**outcome.found, **finalists})
        sink.layouts(report.layouts, hand)
    sink.surrogate_scores(outcome)
    if outcome.interrupted:
        return report
    from optipose.search.validate import hand_where_better, validate
    from optipose.search.draws import choice_draw_counts

    stage(f"validating on the {config.validation.protocol} protocol (held-out noise seed)")
    first: dict = {}

    def evaluation(name, result) -> None:
        first[name] = result
        sink.evaluation(name, result)

    report.validation = validate(
        part, objective, report.layouts, seed, jobs, config.validation.protocol, evaluation, hand_run
    )
    # a real cell: the baseline's choice where it did better (under a band the verdict is the band's, not raced)
    if report.validation.hand and not choice_draw_counts(objective) and objective.conditions.trivial:
        answered, report.validation = hand_where_better(report.layouts, report.validation, hand)
        if answered is not report.layouts:  # some k answered with the hand layout's own sensors: their files
            report.layouts = answered
            sink.layouts(report.layouts, hand)
    sink.validation(report.validation)
    if report.validation.hand:
        from optipose.search.draws import confident_verdicts

        stage(f"the verdict with confidence (up to {config.verdict.draws} draws of the cell)")
        raced = replace(config, verdict=replace(config.verdict, time=_verdict_seconds(config.verdict, started)))
        report.confident = confident_verdicts(
            part, objective, report.layouts, report.validation, first, seed, raced, jobs, sink.verdict_draw
        )
        sink.verdict(report.confident)
    if band is None or not report.validation.hand:  # no band, or nothing to compare with: no check
        return report
    from optipose.evaluate.conditions import conditions

    stage(f"checking under the band ({len(conditions(band.conditions))} conditions, held-out seed)")
    try:
        report.band = validate(
            part, band, report.layouts, seed, jobs, config.validation.protocol, sink.band_evaluation, band_run
        )
    except (KeyboardInterrupt, SystemError) as exc:  # the validation is done and saved: hand it back, unchecked
        if not is_interrupt(exc):
            raise
        report.band_interrupted = True
        return report
    sink.band(report.band)
    return report


def _verdict_seconds(verdict, started: float) -> float:
    """The verdict's ``time`` (0: no limit), ended by ``answer_time`` s after ``started`` when that is set:
    what is left then, at least a moment (the race adds one draw and looks at what it has)."""
    if verdict.answer_time <= 0:
        return verdict.time
    left = max(1e-3, verdict.answer_time - (time.monotonic() - started))
    return min(verdict.time, left) if verdict.time > 0 else left


def _study(part, objective, config, sink: ResultSink, resume: bool, on_eval) -> SurrogateStudy:
    """The live search, with the sink's cache when resuming, flushing to the sink as it goes."""
    cache = sink.load_cache(SPACE_VERSION) if resume else {}
    if resume:
        log.info("resuming with %d cached sensor poses", len(cache))
    study = SurrogateStudy(SurrogateProblem(part, objective, config, cache=cache))
    if on_eval:
        study.callbacks.append(on_eval)
    flushed = {"n": 0, "at": time.monotonic(), "took": 0.0}

    def flush(_evaluation) -> None:
        # every _FLUSH_EVERY evaluations, but no sooner than _FLUSH_GAP s and 10x the last write's own time
        # after it: a write is the whole history and cache, so counting evaluations alone made the writes
        # grow with the search until they took a large share of its time
        now = time.monotonic()
        if len(study.history) - flushed["n"] >= _FLUSH_EVERY and now - flushed["at"] >= max(
            _FLUSH_GAP, 10 * flushed["took"]
        ):
            _flush(sink, study)
            flushed.update(n=len(study.history), at=time.monotonic(), took=time.monotonic() - now)

    study.callbacks.append(flush)
    return study


def _flush(sink: ResultSink, study: SurrogateStudy) -> None:
    sink.flush(study.history, study.problem.cache, SPACE_VERSION)


def _layouts(found: dict[int, Found]) -> dict[int, Layout]:
    return {k: found_layout(f) for k, f in found.items()}


def found_layout(found: Found) -> Layout:
    """A found layout as a :class:`Layout` of sensors F1 … Fk, named ``found_k<k>``."""
    sensors = tuple(SensorPose(f"F{i + 1}", T) for i, T in enumerate(found.poses))
    return Layout(
        sensors,
        name=f"found_k{found.k}",
        description=f"found by the {found.strategy} search, surrogate score {found.score:.5f} deg",
    )
