"""The evaluator: scan a layout at every orientation of a protocol, register every sensor subset, and
assign each axis its best subset (paper Algorithms 3–4, Table 1).

Per orientation the sensors are scanned once (one ``Scanner.scan_many`` call per sensor model), each
sensor's scan is voxel-down-sampled once, and each subset's floating cloud is the union of its sensors'
down-sampled scans; the reference and its search structure are built once per part (per worker process),
and the first closest-point search at identity is done once per sensor and shared by every subset
(:mod:`optipose.evaluate.worker`). Orientations are spread over the workers of an executor
(:mod:`optipose.parallel.executors`); each scan's noise seed comes from the run's seed and its index, so
the result does not depend on the executor or its number of workers.

For the search, :class:`Evaluator` keeps the part, objective and workers' state between calls:
``Evaluator(part, objective)(layout) -> EvaluationResult``.
"""

from __future__ import annotations

import functools
import logging
import time
import uuid
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from optipose.parallel import shared
from optipose.cell.scans import CellSetup
from optipose.evaluate.assignment import Choice, best_choices
from optipose.parallel.executors import Executor, make_executor
from optipose.evaluate.objective import Objective, load_objective
from optipose.evaluate.protocol import Perturbations, perturbations
from optipose.evaluate.statistics import summarize
from optipose.evaluate.memo import Registered
from optipose.evaluate.worker import WorkerSetup, record_chunk, run_chunk, run_item
from optipose.model.layout import Layout, SensorPose
from optipose.scan.scanner import registered_motion

__all__ = ["Evaluator", "EvaluationResult", "evaluate", "evaluate_many", "log_failures"]

log = logging.getLogger(__name__)


@dataclass
class EvaluationResult:
    """A layout evaluated under an objective. Angles in radians, lengths in metres.

    per_scan : one row per (scan, subset): set and estimated orientation, signed errors, registration
        outcome (ok, converged, failure, iterations, fitness, rmse), observability flags.
    points : one row per (scan, sensor): points returned and left after down-sampling (paper Fig. 9).
    stats : per (subset, axis): median, p75, mean, max of |error|, n_ok, n_failed, unobservable.
    table : the best choice for k = 1 … n sensors, each axis with its subset (paper Table 1).
    timings : seconds of CPU work summed over workers ("scan", "register") and the wall time ("wall").
    """

    part: str
    layout: Layout
    objective: Objective
    seed: int
    per_scan: pd.DataFrame = field(repr=False)
    points: pd.DataFrame = field(repr=False)
    stats: pd.DataFrame = field(repr=False)
    table: list[Choice] = field(repr=False)
    timings: dict = field(repr=False, default_factory=dict)

    @property
    def n_scans(self) -> int:
        return int(self.per_scan["scan"].nunique())

    @property
    def n_failed(self) -> int:
        return int((~self.per_scan["ok"]).sum())

    def score(self, k: int | None = None) -> float:
        """The objective's score (rad) of the best choice of k sensors (default: all of them)."""
        return self.table[(k or len(self.layout)) - 1].score

    def __repr__(self) -> str:
        n_scans = self.per_scan["scan"].nunique()
        lines = [
            f"EvaluationResult(part={self.part!r}, layout={self.layout.name!r} {self.layout.names}, "
            f"objective={self.objective.name!r}, seed={self.seed}, {n_scans} scans x {self.per_scan['subset'].nunique()} subsets, "
            f"{self.n_failed} failed registrations, wall {self.timings.get('wall', float('nan')):.1f} s)"
        ]
        lines += [f"  {choice!r}" for choice in self.table]
        return "\n".join(lines)


def evaluate(
    part, layout: Layout | None = None, objective: Objective | str = "paper", seed: int = 0, jobs: int = 1
) -> EvaluationResult:
    """Evaluate ``layout`` (default: the part's hand-placed one) on ``part`` (a :class:`optipose.model.part.Part`)."""
    if layout is None:
        from optipose.model.baseline import baseline

        layout = baseline(part)
        if layout is None:
            from optipose.errors import ConfigError

            raise ConfigError(f"part '{part.name}' has no hand-placed layout; give one with --layout")
    with Evaluator(part, objective, seed=seed, jobs=jobs) as evaluator:
        return evaluator(layout)


class Evaluator:
    """A part and an objective, ready to evaluate layouts; the costly set-up is done once.

    part : :class:`optipose.model.part.Part`. objective : an :class:`Objective` or a name/path.
    jobs : worker processes over orientations (1 = in this process), when no ``executor`` is given.
    quiet : report failed registrations at INFO instead of WARNING (a search's hundreds of internal
        evaluations; the counts stay in ``per_scan`` and ``stats``).
    executor : where the orientations run (:mod:`optipose.parallel.executors`); default
        ``make_executor(jobs)``. An executor given here is the caller's to close; one made from
        ``jobs`` is closed with the evaluator.
    scans : evaluate this many of the protocol's scans, drawn by the seed (0: all; :meth:`Perturbations.sample`).
    reference_dir : a folder of the CAD-surface reference already on this machine (:mod:`optipose.parallel.shared`),
        which the workers map instead of building it (a search's, for the hand layout's processes).
    """

    def __init__(
        self,
        part,
        objective: Objective | str = "paper",
        seed: int = 0,
        jobs: int = 1,
        quiet: bool = False,
        executor: Executor | None = None,
        scans: int = 0,
        reference_dir: str | None = None,
    ):
        self.part = part
        self.objective = objective if isinstance(objective, Objective) else load_objective(objective)
        self.seed = int(seed)
        self._owns_executor = executor is None
        self.executor: Executor = make_executor(jobs) if executor is None else executor
        self.jobs = self.executor.n_workers
        self._failure_level = logging.INFO if quiet else logging.WARNING
        self.perturbations: Perturbations = perturbations(self.objective.protocol, self.seed).sample(scans, self.seed)
        self.setup = WorkerSetup(
            token=uuid.uuid4().hex,
            vertices=np.asarray(part.mesh.vertices, dtype=np.float64),
            faces=np.asarray(part.mesh.faces, dtype=np.int64),
            sensor=part.sensor,
            material=part.material,
            motion=registered_motion(part.motion),  # a long part in longer steps (SCAN_PROFILES)
            centre=np.asarray(part.rotation_centre, dtype=float),
            registration=replace(
                self.objective.registration, null_tolerance=self.objective.statistic.observability_tolerance
            ),
            observability_tolerance=self.objective.statistic.observability_tolerance,
            seed=self.seed,
            threads=None if self.jobs == 1 else 1,
            occluders=tuple(getattr(part, "occluders", ())),
            column_stride=self.objective.scan.column_stride,
            cell=None if self.objective.cell.ideal else CellSetup.of(self.objective.cell, part),
        )
        self._shared = None
        if self.objective.registration.reference != "cad-sample" and (reference_dir is not None or self.jobs > 1):
            if reference_dir is None:  # with workers in other processes, the CAD-surface reference is built here once
                self._shared, reference_dir = shared.acquire(self.setup.vertices, self.setup.faces)
            self.setup = replace(self.setup, reference_dir=reference_dir)
        self._registered = Registered(self.setup)  # what it registered, for the layouts sharing those sensors

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        """Release the workers of an executor this evaluator made."""
        if self._owns_executor:
            self.executor.close()
        if self._shared is not None:
            shared.release(self._shared)
            self._shared = None

    def tasks(self) -> list[tuple]:
        """The protocol's orientations as worker tasks: (scan index, rpy (3,) rad, offset (3,) m, noise seed, label)."""
        p = self.perturbations
        return [(i, p.rpy[i], p.offset[i], int(p.seeds[i]), str(p.label[i])) for i in range(len(p))]

    def __call__(self, layout: Layout | list[np.ndarray], subsets=None) -> EvaluationResult:
        """Evaluate a layout (or a list of 4×4 ``T_O_S``, named S1, S2, …). ``subsets``: register only these
        sensor subsets (tuples of indices; default every one): the result's table then chooses among them alone
        (a verdict's draw, which needs only the subsets its choices use)."""
        return self.result(layout, [self.raw(layout, subsets=subsets)])

    def many(self, items: list[tuple]) -> list[EvaluationResult]:
        """``[self(layout, subsets) for layout, subsets in items]``: :func:`evaluate_many` of this evaluator."""
        return evaluate_many([(self, layout, subsets) for layout, subsets in items])

    def raw(self, layout: Layout | list[np.ndarray], share: tuple[int, int] = (0, 1), subsets=None) -> tuple:
        """What ``self(layout)`` makes its result of: the workers' outputs and the wall time (s), of the
        orientations ``share[0]``, ``share[0] + share[1]``, … only. The shares of several calls (other
        processes') make one result together (:meth:`result`), the one ``self(layout)`` gives: each scan's
        noise comes from the seed and its index."""
        layout = _as_layout(layout)
        subsets = _checked(layout, subsets)
        first, every = share
        items, known = self._items(layout, subsets, self.tasks()[first::every], keep=self._registered.on)
        t0 = time.perf_counter()
        outputs = self.executor.map(run_item, items) if items else []
        self._registered.add(layout, outputs)
        return [*outputs, *known], time.perf_counter() - t0

    def _items(self, layout: Layout, subsets, tasks: list[tuple], keep: bool) -> tuple[list[tuple], list[tuple]]:
        """The workers' items (:func:`~optipose.evaluate.worker.run_item`) of ``layout`` at ``tasks``, each with the
        clouds this evaluator kept of its scans (``keep``: the workers return theirs), and what it registered
        already as worker outputs (:class:`~optipose.evaluate.memo.Registered`); no item when that is all."""
        todo, known, scanned, given = self._registered.plan(layout, subsets, [t[0] for t in tasks])
        items = [
            (self.setup, layout, todo, chunk, {t[0]: given[t[0]] for t in chunk if t[0] in given}, keep)
            for chunk in (_chunks(tasks, self.jobs) if scanned else [])
        ]
        return items, [known] if known else []

    def record(self, layout: Layout | list[np.ndarray], write) -> list[list]:
        """Scan ``layout`` at every orientation of the protocol as :meth:`__call__` scans it (the cell's sources,
        the noise: the same clouds) and hand each scan's raw profiles to ``write(i, j, raw)`` in the workers
        (:func:`~optipose.evaluate.worker.record_chunk`); what it returned, per scan and sensor."""
        layout = _as_layout(layout)
        chunks = _chunks(self.tasks(), self.jobs)
        outputs = self.executor.map(functools.partial(record_chunk, self.setup, layout, write=write), chunks)
        by_scan = {task[0]: out for chunk, done in zip(chunks, outputs) for task, out in zip(chunk, done)}
        return [by_scan[i] for i in range(len(self.perturbations))]

    def replay(self, layout: Layout | list[np.ndarray], read) -> EvaluationResult:
        """Evaluate recorded scans of ``layout`` (a real cell's, or :meth:`record`'s): ``read(i)`` gives scan
        ``i`` of the protocol, one :class:`~optipose.scan.cloud.Scan` per sensor, registered as :meth:`__call__`
        registers the scans it makes. The cell's sources are in the scans: none is added."""
        layout = _as_layout(layout)
        setup = replace(self.setup, token=uuid.uuid4().hex, cell=None)
        t0 = time.perf_counter()
        run = functools.partial(run_chunk, setup, layout, read=read)
        outputs = self.executor.map(run, _chunks(self.tasks(), self.jobs))
        return self._result(layout, list(outputs), time.perf_counter() - t0)

    def result(self, layout: Layout | list[np.ndarray], raws: list[tuple]) -> EvaluationResult:
        """The evaluation from the :meth:`raw` outputs of the shares of its orientations (their wall time the
        longest)."""
        return self._result(
            _as_layout(layout), [o for outputs, _ in raws for o in outputs], max(wall for _, wall in raws)
        )

    def _result(self, layout: Layout, outputs: list[tuple], wall: float) -> EvaluationResult:
        """The workers' (rows, point rows, seconds) as an :class:`EvaluationResult`."""
        rows = [r for out in outputs for r in out[0]]
        point_rows = [r for out in outputs for r in out[1]]
        per_scan = pd.DataFrame(rows).sort_values(["scan", "subset_index"], kind="stable").reset_index(drop=True)
        points = pd.DataFrame(point_rows).sort_values(["scan", "sensor_index"], kind="stable").reset_index(drop=True)
        stats = summarize(per_scan, self.objective.statistic)
        table = best_choices(
            stats, layout.names, self.objective.statistic, len(self.perturbations), set(per_scan["subset"])
        )
        timings = {k: float(sum(out[2][k] for out in outputs)) for k in ("scan", "register")}
        timings["wall"] = wall
        log_failures(per_scan, self._failure_level)
        return EvaluationResult(
            self.part.name, layout, self.objective, self.seed, per_scan, points, stats, table, timings
        )


def evaluate_many(items: list[tuple]) -> list[EvaluationResult]:
    """``[evaluator(layout, subsets) for evaluator, layout, subsets in items]``, the same results, in one map of the
    first evaluator's executor (the evaluators must share it): every layout's orientations, of every evaluator (a
    draw of the verdict each), share the workers, where a few scans of one layout at a time would leave one idle."""
    work = []
    for evaluator, layout, subsets in items:
        layout = _as_layout(layout)
        # a draw's layouts are scanned in one map, not one after another, and each draw is an evaluator of its own:
        # nothing is kept for another, what the evaluator kept before is taken
        chunks, known = evaluator._items(layout, _checked(layout, subsets), evaluator.tasks(), keep=False)
        work.append((evaluator, layout, chunks, known))
    if not work:
        return []
    t0 = time.perf_counter()
    outputs = work[0][0].executor.map(run_item, [item for _, _, chunks, _ in work for item in chunks])
    wall = time.perf_counter() - t0
    results, at = [], 0
    for evaluator, layout, chunks, known in work:
        mine = list(outputs[at : at + len(chunks)])
        results.append(evaluator.result(layout, [(mine + known, wall)]))
        at += len(chunks)
    return results


def _checked(layout: Layout, subsets) -> list[tuple] | None:
    """``subsets`` as sorted index tuples of ``layout``'s sensors (None: every subset); a bad one is refused."""
    if subsets is None:
        return None
    n = len(layout)
    subsets = [tuple(sorted(set(map(int, s)))) for s in subsets]
    if not subsets or not all(s and 0 <= s[0] and s[-1] < n for s in subsets):
        raise ValueError(f"subsets: non-empty tuples of sensor indices 0..{n - 1}, got {subsets}")
    return subsets


def _as_layout(layout: Layout | list[np.ndarray]) -> Layout:
    """A layout, or a list of 4×4 ``T_O_S`` named S1, S2, … as one."""
    if isinstance(layout, Layout):
        return layout
    return Layout(tuple(SensorPose(f"S{i + 1}", np.asarray(T, float)) for i, T in enumerate(layout)), name="poses")


def log_failures(per_scan: pd.DataFrame, level: int = logging.WARNING, what: str = "") -> None:
    """Log how many of an evaluation's registrations failed or did not converge, and why (nothing if none)."""
    failed = int((~per_scan["ok"]).sum())
    if failed:
        reasons = per_scan.loc[~per_scan["ok"], "failure"].value_counts().to_dict()
        log.log(level, "%s%d of %d registrations failed or did not converge: %s", what, failed, len(per_scan), reasons)


def _chunks(tasks: list, n_workers: int) -> list[list]:
    """One chunk for one worker; else 2 per worker, interleaved so each gets a spread of orientations."""
    if n_workers == 1:
        return [tasks]
    return [c for c in (tasks[j :: n_workers * 2] for j in range(n_workers * 2)) if c]
