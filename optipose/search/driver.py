"""The NLopt driver: one way to run a global or local NLopt algorithm on [0, 1]ⁿ (docs/method.md, "The search").

The objective records what it sees (a :class:`~optipose.search.study.SurrogateStudy` keeps the history
and the best), so :func:`optimize` returns nothing; NLopt's own stops end quietly, a
:class:`~optipose.search.study.Stop` (time up, Ctrl-C) or any other exception the objective raises propagates
once NLopt has returned.
"""

from __future__ import annotations

import logging

import numpy as np

from optipose.search.config import algorithm_code

__all__ = ["optimize", "local_best", "apart", "SubProblem"]

log = logging.getLogger(__name__)
_HUGE = 1e300  # what NLopt is told after the objective raised, until it stops


def optimize(
    fn,
    algorithm: str,
    x0: np.ndarray,
    maxeval: int,
    seed: int | None,
    local: str | None = None,
    step: float = 0.08,
    xtol_rel: float | None = 1e-5,
    xtol_abs: float | None = None,
) -> None:
    """One NLopt run of ``fn(u, grad)`` on [0, 1]^n from ``x0`` (n,), at most ``maxeval`` evaluations.

    seed : NLopt's random seed (None: leave it as it is). local : the local algorithm of a multi-start
    (MLSL) run. step, xtol_rel, xtol_abs : a local algorithm's initial step and stopping tolerances in
    [0, 1] units (None: NLopt's default).
    """
    import nlopt

    n = len(x0)
    opt = nlopt.opt(algorithm_code(algorithm), n)
    opt.set_lower_bounds(np.zeros(n))
    opt.set_upper_bounds(np.ones(n))
    pending: list[BaseException] = []

    def guarded(u, grad) -> float:
        # an exception raised into NLopt does not stop every algorithm at once: DIRECT-L called the objective
        # again with it still set, and the next call into numpy failed as a SystemError. Keep it, ask NLopt
        # to stop, and raise it once optimize returns
        if pending:
            return _HUGE
        try:
            return fn(u, grad)
        except BaseException as exc:  # noqa: BLE001 - re-raised below, whatever it is (Ctrl-C too)
            pending.append(exc)
            opt.force_stop()
            return _HUGE

    opt.set_min_objective(guarded)
    opt.set_maxeval(int(maxeval))
    if algorithm.startswith(("LN_",)):
        opt.set_initial_step(np.full(n, step))
        if xtol_rel is not None:
            opt.set_xtol_rel(xtol_rel)
        if xtol_abs is not None:
            opt.set_xtol_abs(xtol_abs)
    if algorithm.startswith("GN_MLSL") or algorithm.startswith("G_MLSL"):
        sub = nlopt.opt(algorithm_code(local or "LN_BOBYQA"), n)
        sub.set_xtol_rel(1e-4)
        sub.set_maxeval(max(10, maxeval // 10))
        opt.set_local_optimizer(sub)
    if algorithm.startswith(("GN_CRS", "GN_ISRES")):
        # NLopt's default populations (CRS2 10(n+1), ISRES 20(n+1)) would spend most of a small budget on
        # one random generation; cap them at a fifth of the budget
        opt.set_population(int(min(10 * (n + 1), max(n + 2, maxeval // 5))))
    if seed is not None:
        nlopt.srand(int(seed) % (2**31))
    try:
        opt.optimize(np.clip(x0, 0.0, 1.0))
    except (nlopt.ForcedStop, nlopt.RoundoffLimited):  # what the objective raised (a Stop too) is in pending
        pass
    except RuntimeError as exc:  # NLopt's generic failure: keep what was found
        if not pending:
            log.warning("NLopt %s stopped: %s", algorithm, exc)
    if pending:
        raise pending[0]


def local_best(fn, algorithm: str, x0: np.ndarray, maxeval: int, seed: int, history: list | None = None):
    """Run a local NLopt search on ``fn`` (a study or a sub-problem of one, whose evaluations are recorded
    in ``history``, by default ``fn.history``) and return the best feasible evaluation it produced, or
    None when it met no feasible layout."""
    history = fn.history if history is None else history
    before = len(history)
    optimize(fn, algorithm, x0, maxeval, seed)
    rows = [r for r in history[before:] if r.feasible]
    return min(rows, key=lambda r: r.value) if rows else None


def apart(u: np.ndarray, others, min_distance: float) -> bool:
    """``u`` lies more than ``min_distance`` from every one of ``others`` in some [0, 1] unit (max norm)."""
    return all(np.max(np.abs(np.asarray(u) - np.asarray(o))) > min_distance for o in others)


class SubProblem:
    """The new sensor's 6 numbers as NLopt's variables, the sensors already ``placed`` (6(k-1),) fixed:
    every evaluation is the full layout's, recorded by the study."""

    def __init__(self, study, placed: np.ndarray):
        self.study, self.placed = study, placed

    @property
    def history(self) -> list:
        return self.study.history

    def __call__(self, u6, grad=None) -> float:
        return self.study(np.concatenate([self.placed, np.asarray(u6)]))
