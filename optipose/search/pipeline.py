"""``optipose search`` as a pipeline: its stages in order, each result on disk as soon as it exists.

1. the config goes to the result folder first, so even an interrupted run explains itself; a resumed run
   reloads the per-sensor cache and replays its earlier evaluations for free (same seed, same sequence);
2. the NLopt search on the surrogate (:mod:`optipose.search.surrogate_search`: screen, greedy, joint), the
   history and cache flushed to the folder as it goes, the surrogate's best layouts written at its end;
3. the ICP selection, polish and confirmation (:mod:`optipose.search.select`), after which the finalists
   replace the surrogate's best;
4. validation on a noise seed the search never saw (:mod:`optipose.search.validate`): the numbers reported.
   Every budget validates on the objective's protocol
   (``[search.validation] protocol = "reduced"`` cuts it to 14 of the paper's 77 scans; the table says so). The
   hand layout's part of it starts with step 2, in ``jobs`` processes of its own (``jobs`` ≥ 2), and is waited
   for before step 3;
5. the verdict with confidence (:mod:`optipose.search.draws`): the validation's evaluations are its first
   draw in the ideal cell (in a real cell the choices were made on them), and further draws of the cell on
   seeds of their own are raced until every k is BUY, KEEP or TIE.

:func:`run` calls one function per step (``_surrogate_search``, ``_selection``, ``_validation``, ``_verdict``),
all sharing one :class:`SearchContext`: what the search was given and what each step produced.
Every result goes to a :class:`ResultSink` the caller gives (``optipose.io.search.SearchFolder`` writes a
result folder), so the search itself never touches the file system.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Protocol

from optipose.errors import OptiposeError
from optipose.model.layout import Layout, SensorPose
from optipose.search.config import SearchConfig
from optipose.search.problem import SurrogateProblem
from optipose.search.records import Found, SearchOutcome, Validation
from optipose.search.space import SPACE_VERSION
from optipose.search.study import SurrogateStudy
from optipose.search.surrogate_search import run_search
from optipose.seeds import validation_seed
from optipose.verdict.confidence import Verdicts
from optipose.model.baseline import baseline

if TYPE_CHECKING:
    from optipose.evaluate.objective import Objective
    from optipose.model.part import Part
    from optipose.search.validate import BaselineRun

__all__ = ["SearchReport", "ResultSink", "run", "found_layout", "NoFeasibleLayout"]

log = logging.getLogger(__name__)
_FLUSH_EVERY = 100  # evaluations between writes of the history and the cache...
_FLUSH_GAP = 10.0  # ... and seconds: what a kill can lose, and a resume recomputes


class NoFeasibleLayout(OptiposeError):
    """The search met no layout that satisfies the constraints (e.g. the sensors cannot see the part)."""


class ResultSink(Protocol):
    """Where a search's results go as they appear (``optipose.io.search.SearchFolder``)."""

    def start(self, part, objective, config: SearchConfig, budget: str, seed: int, validation_seed: int) -> None: ...

    def load_cache(self, space_version: int) -> dict: ...

    def flush(self, history: list, cache, space_version: int) -> None: ...

    def layouts(self, layouts: dict[int, Layout], baseline: Layout | None) -> None: ...

    def selection(self, records: list) -> None: ...

    def surrogate_scores(self, outcome: SearchOutcome) -> None: ...

    def evaluation(self, name: str, result) -> None: ...

    def validation(self, validation: Validation) -> None: ...

    def verdict_draw(self, draw: int, name: str, result) -> None: ...

    def verdict(self, verdicts: Verdicts) -> None: ...

    def kinds(self, kinds: dict[str, Verdicts]) -> None: ...


@dataclass
class SearchReport:
    """A search run: the surrogate's outcome, the layouts found per k and their validation."""

    outcome: SearchOutcome
    layouts: dict[int, Layout] = field(default_factory=dict)
    validation: Validation | None = None
    confident: Verdicts = field(default_factory=Verdicts)  # the verdicts with confidence (search/draws.py)
    kinds: dict[str, Verdicts] = field(default_factory=dict)  # the BUYs raced again per common kind (search/kinds.py)

    @property
    def validated(self) -> bool:
        return self.validation is not None

    @property
    def clock_cut(self) -> tuple[str, ...]:
        """What a user's clock ended before its counts, in order: the surrogate's and the selection's stages
        (``greedy:k=1``, ``selection:k=2``) and the verdict's race (``verdict:k=3``); empty without a clock."""
        raced = [f"verdict:k={v.k}" for v in self.confident.by_k.values() if v.ended == "clock"]
        return tuple(self.outcome.clock_cut) + tuple(raced)


@dataclass
class SearchContext:
    """One search as its stages share it: what it was given, and what each stage produced.

    started : ``time.monotonic()`` when the search started (a
    user's clock, ``SearchConfig.time_limit`` and the verdict's ``answer_time``, counts from here); on_stage : told when a stage starts (or None); baseline_run :
    the hand layout's validation, running beside the search (None in one process); study : the live surrogate search; first : the validation's evaluations by name (the
    verdict's first draw); report : what the stages found so far."""

    part: Part
    objective: Objective
    config: SearchConfig
    seed: int
    sink: ResultSink
    jobs: int
    started: float
    on_stage: Callable[[str], None] | None = None
    baseline_run: BaselineRun | None = None
    study: SurrogateStudy | None = None
    baseline: Layout | None = None
    first: dict = field(default_factory=dict)
    report: SearchReport | None = None

    def stage(self, text: str) -> None:
        """Tell ``on_stage`` that a stage starts."""
        if self.on_stage:
            self.on_stage(text)

    def seconds(self, own: float = 0.0, since_start: float = 0.0) -> float:
        """A stage's clock, s: its own ``own`` (0: none), what is left of ``since_start`` s after the search
        started (0: none) and of the user's ``time_limit`` (0: none); inf where no clock is set, at least a
        moment where one is (a stage then does what it must and stops)."""
        now = time.monotonic() - self.started
        clocks = ([own] if own > 0 else []) + [
            limit - now for limit in (since_start, self.config.time_limit) if limit > 0
        ]
        return max(1e-3, min(clocks)) if clocks else math.inf


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
        ctx = _start(part, objective, config, seed, sink, budget, jobs, on_stage)
        with _beside(ctx):
            ctx.study = _study(ctx, resume, on_eval)  # after the hand layout's processes start: they set up beside it
            _surrogate_search(ctx)
            _selection(ctx)
            sink.surrogate_scores(ctx.report.outcome)
            if not ctx.report.outcome.interrupted:
                _validation(ctx)
                _verdict(ctx)
                _kinds(ctx)
            return ctx.report


def _start(part, objective, config, seed, sink, budget, jobs, on_stage) -> SearchContext:
    """The search's context, its config written first; the clock starts here."""
    started = time.monotonic()  # a user's clock counts from here
    sink.start(part, objective, config, budget, seed, validation_seed(seed))
    ctx = SearchContext(part, objective, config, seed, sink, jobs, started, on_stage)
    # at once: the surrogate's set-up and the start of the hand layout's processes are part of the stage
    ctx.stage("searching on the surrogate")
    return ctx


@contextmanager
def _beside(ctx: SearchContext):
    """The part's shared reference and the hand layout's processes (its validation), for as long as the search
    runs."""
    with _shared_reference(ctx.part, ctx.jobs) as folder, _baseline_run(ctx, ctx.objective, folder) as baseline_run:
        ctx.baseline_run = baseline_run
        yield


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


def _baseline_run(ctx: SearchContext, objective, folder: str | None):
    """The hand layout's validation in ``objective`` (the search's), started beside the surrogate search when
    there are cores for both (``jobs`` ≥ 2), in ``jobs`` processes mapping the reference in ``folder``; a
    do-nothing context otherwise."""
    from contextlib import nullcontext

    from optipose.search.validate import BaselineRun

    if ctx.jobs < 2:
        return nullcontext()
    validation = ctx.config.validation
    return BaselineRun(
        ctx.part,
        objective,
        ctx.seed,
        validation.protocol,
        processes=ctx.jobs,
        reference_dir=folder,
        scans=validation.scans,
    )


def _surrogate_search(ctx: SearchContext) -> None:
    """The NLopt search on the surrogate; its best layouts on disk before anything slower."""
    seconds = ctx.seconds(ctx.config.surrogate.max_time)
    outcome = run_search(ctx.part, ctx.objective, ctx.config, ctx.seed, ctx.study, seconds=seconds)
    _flush(ctx.sink, ctx.study)
    if not outcome.found:
        constraints = ctx.config.constraints
        raise NoFeasibleLayout(
            f"no feasible layout for '{ctx.part.name}': in {len(outcome.history)} evaluations no sensor pose returned "
            f"{constraints.min_points} points without its head hitting the part or a keep-out (can the sensors see "
            f"this part at all? check --units, the material and the part's size against the {constraints.clearance * 1e3:.0f} mm clearance)"
        )
    ctx.baseline = baseline(ctx.part)
    ctx.report = SearchReport(outcome, _layouts(outcome.found))
    ctx.sink.layouts(ctx.report.layouts, ctx.baseline)


def _selection(ctx: SearchContext) -> None:
    """The ICP selection (with its polish and confirmation), after the hand layout's validation: the finalists
    replace the surrogate's best."""
    outcome, selection = ctx.report.outcome, ctx.config.selection
    if selection.candidates <= 0 or outcome.interrupted:
        return
    from optipose.search.select import select_finalists

    if ctx.baseline_run is not None:  # a clock on the selection is wall time: it runs alone on the cores
        ctx.stage("evaluating the hand layout (held-out noise seed)")
        ctx.baseline_run.wait()
    ctx.stage("selecting finalists by ICP on a reduced protocol")
    finalists, records = select_finalists(
        ctx.part,
        ctx.objective,
        outcome,
        ctx.study,
        ctx.seed,
        selection.candidates,
        ctx.seconds(selection.time),
        ctx.on_stage,
        ctx.jobs,
    )
    ctx.sink.selection(records)
    ctx.report.outcome = replace(outcome, clock_cut=tuple(ctx.study.cut))  # with the selection's, where a clock cut it
    ctx.report.layouts = _layouts({**outcome.found, **finalists})
    ctx.sink.layouts(ctx.report.layouts, ctx.baseline)


def _validation(ctx: SearchContext) -> None:
    """The found layouts and the hand one on the held-out seed; in a real cell, the baseline's choice where it did
    better."""
    from optipose.search.draws import choice_draw_counts
    from optipose.search.validate import baseline_where_better, validate

    report, protocol = ctx.report, ctx.config.validation.protocol
    ctx.stage(f"validating on the {protocol} protocol (held-out noise seed)")

    def evaluation(name, result) -> None:
        ctx.first[name] = result
        ctx.sink.evaluation(name, result)

    report.validation = validate(
        ctx.part,
        ctx.objective,
        report.layouts,
        ctx.seed,
        ctx.jobs,
        protocol,
        evaluation,
        ctx.baseline_run,
        ctx.config.validation.scans,
    )
    if report.validation.baseline and not choice_draw_counts(ctx.objective):
        answered, report.validation = baseline_where_better(report.layouts, report.validation, ctx.baseline)
        if answered is not report.layouts:  # some k answered with the hand layout's own sensors: their files
            report.layouts = answered
            ctx.sink.layouts(report.layouts, ctx.baseline)
    ctx.sink.validation(report.validation)


def _verdict(ctx: SearchContext) -> None:
    """The verdict with confidence, raced on draws of the cell (nothing to compare without a hand choice)."""
    report = ctx.report
    if not report.validation.baseline:
        return
    from optipose.search.draws import confident_verdicts

    verdict = ctx.config.verdict
    ctx.stage(f"the verdict with confidence (up to {verdict.draws} draws of the cell)")
    raced = replace(ctx.config, verdict=replace(verdict, time=ctx.seconds(verdict.time, verdict.answer_time)))
    report.confident = confident_verdicts(
        ctx.part,
        ctx.objective,
        report.layouts,
        report.validation,
        ctx.first,
        ctx.seed,
        raced,
        ctx.jobs,
        ctx.sink.verdict_draw,
    )
    ctx.sink.verdict(report.confident)


def _kinds(ctx: SearchContext) -> None:
    """The BUYs raced again where the user's cell may lie (``verdict.kinds``: the common kinds of cell where the user
    named none, the ends of the ranges of a cell of ranges), and the verdicts they did not bear out opened."""
    from optipose.search.kinds import across_kinds, buys, kinds_of, qualified

    report, verdict = ctx.report, ctx.config.verdict
    kinds = kinds_of(ctx.config)
    if not kinds or not buys(report.confident):
        return
    ctx.stage(f"the BUYs in {', '.join(kinds)} (up to {verdict.kinds_draws} draws each)")
    raced = replace(ctx.config, verdict=replace(verdict, time=ctx.seconds(verdict.time, verdict.answer_time)))
    report.kinds = across_kinds(
        ctx.part, ctx.objective, report.layouts, report.validation, report.confident, ctx.seed, raced, ctx.jobs
    )
    ctx.sink.kinds(report.kinds)
    settled = qualified(report.confident, report.kinds)  # a BUY not borne out where it was raced again is open
    if settled is not report.confident:
        report.confident = settled
        ctx.sink.verdict(report.confident)


def _study(ctx: SearchContext, resume: bool, on_eval) -> SurrogateStudy:
    """The live search, with the sink's cache when resuming, flushing to the sink as it goes."""
    part, objective, config, sink = ctx.part, ctx.objective, ctx.config, ctx.sink
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
