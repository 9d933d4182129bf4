"""Stage: validation. The found layouts and the hand-placed one on the objective's protocol (``quick``: the
reduced one) with a noise seed the search never saw (:func:`optipose.seeds.validation_seed`); these are
the numbers reported.

The hand layout's evaluation does not depend on what the search finds: :class:`BaselineRun` starts it in
processes of its own at a low priority when the search starts, beside the surrogate search, and
:func:`validate` takes its result instead of evaluating the hand layout again. It is the same result,
whatever runs it: the scans' noise comes from the seed and the scan's index, not from the worker."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from optipose.evaluate.assignment import choice_of
from optipose.evaluate.evaluator import Evaluator, log_failures
from optipose.errors import WorkerError
from optipose.model.layout import Layout
from optipose.search.objectives import stage_objective
from optipose.search.records import Validation
from optipose.seeds import validation_seed
from optipose.model.baseline import baseline

__all__ = ["validate", "BaselineRun", "nested_groups", "indices_in", "baseline_where_better"]

log = logging.getLogger(__name__)
_NICE = 10  # the hand layout's evaluation takes the cores the search leaves idle, and yields where it wants them


class BaselineRun:
    """The hand layout's validation evaluation (:func:`optipose.model.baseline.baseline`), running in
    processes of its own from the moment it is made (:class:`optipose.parallel.background.Background`, one
    thread each) at a low priority, so it takes the cores the search leaves idle.

    ``result()`` waits for it: ``None`` when the part has no baseline, or the evaluation failed or was
    stopped (the validation then evaluates the hand layout itself); ``close()`` stops it. ``processes``: its
    scans are shared out over up to this many processes, so that once the search and the found layouts' validation are done the
    hand layout's takes every core, not one. ``reference_dir``: the CAD-surface reference the search holds on
    this machine (:mod:`optipose.parallel.shared`), mapped by the processes instead of built by each.
    """

    def __init__(
        self,
        part,
        objective,
        seed: int,
        protocol: str = "full",
        processes: int = 1,
        reference_dir: str | None = None,
        scans: int = 0,
    ):
        import multiprocessing
        import pickle

        from optipose.parallel.background import Background

        self._calls, self._result = [], None
        layout = baseline(part)
        if layout is None or multiprocessing.current_process().daemon:  # a daemonic worker (Dask) may not start one
            return
        objective = stage_objective(objective, "validation", protocol)
        self._objective = objective
        self._part, self._seed, self._layout, self._scans = part, validation_seed(seed), layout, scans
        n = max(1, processes)
        try:
            the_part = pickle.dumps(
                part, protocol=pickle.HIGHEST_PROTOCOL
            )  # once, not once a process: a dense mesh takes seconds
            for first in range(n):
                args = (the_part, objective, self._seed, layout, (first, n), reference_dir, self._scans)
                self._calls.append(Background(_evaluate, *args, nice=_NICE))
        except (OSError, pickle.PicklingError, AttributeError, TypeError) as exc:  # the validation evaluates it instead
            self.close()
            log.warning("could not start the hand layout's evaluation beside the search (%s)", exc)

    def wait(self) -> None:
        """Wait until the evaluation has ended (and its processes with it)."""
        if not self._calls:
            return
        try:
            raws = [call.result() for call in self._calls]
            with Evaluator(self._part, self._objective, seed=self._seed, quiet=True, scans=self._scans) as evaluator:
                self._result = evaluator.result(self._layout, raws)
            # it ran quiet in its own process: say here what the validation's own evaluation would have said
            log_failures(self._result.per_scan, what="hand layout: ")
        except WorkerError as exc:  # the validation evaluates the hand layout itself instead
            log.warning("the hand layout's evaluation beside the search failed (%s); evaluating it again", exc)
        finally:
            self.close()

    def result(self):
        """The finished evaluation (waits for it), or ``None``."""
        self.wait()
        return self._result

    def close(self) -> None:
        for call in self._calls:
            call.close()
        self._calls = []

    def __enter__(self) -> "BaselineRun":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _evaluate(
    part: bytes,
    objective,
    seed: int,
    layout,
    scans: tuple[int, int],
    reference_dir: str | None,
    share: int = 0,
) -> tuple:
    """The hand layout's raw evaluation on some of its scans (``scans``: first, every, of the ``share`` the seed
    draws, 0: all), in a process of its own; ``part`` pickled."""
    import pickle

    with Evaluator(
        pickle.loads(part), objective, seed=seed, jobs=1, quiet=True, reference_dir=reference_dir, scans=share
    ) as evaluator:
        return evaluator.raw(layout, scans)


def validate(
    part,
    objective,
    layouts: dict[int, Layout],
    seed: int,
    jobs: int = 1,
    protocol: str = "full",
    on_evaluation=None,
    baseline_run=None,
    scans: int = 0,
) -> Validation:
    """Evaluate ``layouts`` (k → found layout) and the part's hand layout on the held-out seed of ``seed``.

    on_evaluation(name, result) : told of each evaluation as it ends (``found_k3``, ``hand``), so it can
    be saved before the next one starts.
    baseline_run : a :class:`BaselineRun` of the same part, objective, seed and protocol, whose result stands for
    the hand layout's evaluation (the hand layout is evaluated here when it has none).
    """
    vseed = validation_seed(seed)
    objective = stage_objective(objective, "validation", protocol)
    done = on_evaluation or (lambda name, result: None)
    found, baseline_choices = {}, {}
    with Evaluator(part, objective, seed=vseed, jobs=jobs, scans=scans) as evaluator:
        for members in nested_groups(layouts):
            big = layouts[max(members)]
            result = evaluator(big)
            done(f"found_k{max(members)}", result)
            for k in members:
                found[k] = choice_of(result, tuple(indices_in(layouts[k], big)))
        if baseline(part) is not None:
            result = (baseline_run.result() if baseline_run is not None else None) or evaluator(baseline(part))
            done("hand", result)
            baseline_choices = {choice.k: choice for choice in result.table if choice.k in layouts}
    return Validation(protocol, vseed, found, baseline_choices)


def nested_groups(layouts: dict[int, Layout]) -> list[list[int]]:
    """Which found layouts can share one evaluation: a layout whose poses all belong to a larger one.
    Each group lists the largest k first."""
    groups: list[tuple[list[np.ndarray], list[int]]] = []
    for k in sorted(layouts, reverse=True):
        poses = layouts[k].poses
        for pool, members in groups:
            if all(any(np.allclose(T, P) for P in pool) for T in poses):
                members.append(k)
                break
        else:
            groups.append((list(poses), [k]))
    return [members for _, members in groups]


def indices_in(layout: Layout, big: Layout) -> list[int]:
    """Indices in ``big`` of the poses of ``layout``."""
    return [next(i for i, P in enumerate(big.poses) if np.allclose(T, P)) for T in layout.poses]


_TIE = 1e-9  # relative: scores this close are one


def baseline_where_better(
    layouts: dict[int, Layout], validation: Validation, baseline: Layout
) -> tuple[dict[int, Layout], Validation]:
    """In a real cell, the search's answer for each k whose found layout the baseline's choice of k sensors beat or
    tied on the validation's draw (a score as low, to rounding): that choice's own sensors (the baseline's names and
    poses, in a layout ``found_k<k>``), with the baseline's choice restated in it (the inputs themselves where no k is
    replaced). There is nothing to buy there, and the verdict pairs the baseline's evaluation with itself: an exact TIE, the
    baseline's sensors staying in their brackets (docs/method.md, "The verdict with confidence"). The found layouts
    that stay keep their choices, restated in the largest of them that holds them where the one they were validated
    inside was replaced. In the ideal cell the validation's draw is the race's first and is not also used to choose
    (:func:`optipose.search.draws.choice_draw_counts`)."""
    out, found, replaced = dict(layouts), dict(validation.found), set()
    for k, h in validation.baseline.items():
        f = found.get(k)
        # a tie did not beat it either: the same sensors in a sub-layout and in the whole one can differ in the last
        # bits of a statistic (the order of a sum)
        if f is None or k not in out or not h.score <= f.score * (1.0 + _TIE):
            continue
        replaced.add(k)
        why = (
            f"{baseline.name}'s {h.name}: no found layout of {k} sensor{'s' * (k > 1)} beat it on the validation's draw"
        )
        out[k] = Layout(tuple(baseline.sensors[i] for i in h.sensors), name=f"found_k{k}", description=why)
        found[k] = _restated(h, baseline, out[k])
        log.info(
            "k=%d: %s (%.3f deg) beat the found layout (%.3f deg) on the validation's draw: the search answers with it",
            k,
            h.name,
            np.rad2deg(h.score),
            np.rad2deg(f.score),
        )
    if not replaced:
        return layouts, validation
    # a choice names the sensors of its group's largest layout, which may have been replaced
    validated = {k: layouts[max(g)] for g in nested_groups(layouts) for k in g}
    kept = {k: out[k] for k in out if k not in replaced}
    now = {k: kept[max(g)] for g in nested_groups(kept) for k in g}
    found |= {k: _restated(found[k], validated[k], now[k]) for k in kept if k in found and now[k] is not validated[k]}
    return out, replace(validation, found=found)


def _restated(choice, old: Layout, new: Layout):
    """``choice`` (sensor indices and names of ``old``) restated in ``new``, which holds the sensors it uses (by pose)."""
    at = {
        i: indices_in(Layout((old.sensors[i],)), new)[0]
        for i in {*choice.sensors, *(i for a in choice.axes for i in a.subset)}
    }

    def name(indices) -> str:
        return "".join(new.names[j] for j in sorted(at[i] for i in indices))

    axes = tuple(
        replace(a, subset=tuple(sorted(at[i] for i in a.subset)), name=name(a.subset) if a.subset else a.name)
        for a in choice.axes
    )
    return replace(choice, sensors=tuple(sorted(at[i] for i in choice.sensors)), name=name(choice.sensors), axes=axes)
