"""The NLopt search over sensor poses on the surrogate (SPEC §6).

Flow: for k = 1, 2, 3 sensors, **greedy** places one more sensor given the ones already placed (a global
NLopt stage over 6 variables, then a local polish), and **joint** re-optimises all 6k variables at once
from the greedy layout and from the best hand-placed k-subset (local polish). The better of the two is
kept per k; both are reported. Start points include the hand-placed sensors, so the search never ends
worse than them on the surrogate.

Constraints are a documented penalty, not NLopt constraints, because the global algorithms worth using
here (DIRECT-L, CRS2, MLSL) take none: a layout whose head comes within ``clearance`` of the part swept
along the scan or of a keep-out, whose heads overlap, whose laser line turns more than
``line_skew_max_deg`` from across the motion, or whose sensor returns fewer than ``min_points``, scores
``PENALTY + violation`` (violation ≥ 0, normalised, so the optimiser is led back toward feasibility).
Infeasible layouts are recorded in the history but never become a result.

The user wants a layout that is no worse than the hand-placed one on *any* axis, not only on the sum, and
the sum is dominated by the worst axis (usually roll), so an unpenalised optimiser happily trades a
good axis for it. Each axis predicted worse than ``hand_margin`` × the best hand-placed k-subset's
therefore adds ``hand_weight`` × the excess to the score (:meth:`SurrogateProblem.shortfall`).

Every sensor pose's information matrix is cached by its parameters, so a repeated pose costs nothing and
a resumed search replays its earlier evaluations from the cache.
"""

from __future__ import annotations

import itertools
import logging
import time
from dataclasses import dataclass, field

import numpy as np

from optipose.model.collision import DEFAULT_MARGIN, collision_model, heads_clearance
from optipose.search.space import PoseSpace
from optipose.search.surrogate import SensorInfo, Surrogate, predicted_stats, protocol_turns

__all__ = ["SearchConfig", "BUDGETS", "Found", "SearchOutcome", "SurrogateProblem", "run_search", "PENALTY"]

log = logging.getLogger(__name__)

PENALTY = 1e3  # added to every infeasible layout's score; feasible scores are degrees, far below it


@dataclass(frozen=True)
class SearchConfig:
    """How to search. Budgets (``quick``, ``default``, ``thorough``) fill in the numbers."""

    global_algorithm: str = "GN_DIRECT_L"  # best of five on all four problems: benchmarks/README.md
    local_algorithm: str = "LN_BOBYQA"
    global_evals: int = 300  # per greedy stage
    local_evals: int = 120  # per local polish
    joint_evals: int = 200  # per joint polish (k >= 2)
    max_time: float = 600.0  # s, the whole surrogate search
    sensors: tuple[int, ...] = (1, 2, 3)
    strategy: str = "both"  # greedy | joint | both
    min_points: int = 2000
    clearance: float = DEFAULT_MARGIN  # m, head to swept part / keep-outs
    head_gap: float = 0.0  # m, head to head
    margin: float = 0.005  # m, how far outside the part's box the aim point may go
    alpha_max_deg: float = 60.0
    # the laser line may turn at most this far from across the motion (the angle between the line and the
    # plane normal to the scan axis): a line turned toward the motion re-scans its own strip, covers less
    # of the part across the motion, and fools the surrogate (part B, line 66° from across: predicted
    # 0.51 mdeg, 18.9 mdeg in ICP); 90 turns the constraint off
    line_skew_max_deg: float = 60.0
    random_starts: int = 8  # extra random start points scored before each greedy stage
    # before each greedy stage: score this many space-filling (scrambled Sobol) poses of the new sensor on the
    # surrogate, and polish the best screen_starts distinct ones locally (screen_evals each). DIRECT-L
    # refines around one basin; the screen finds the others, which the ICP selection then compares (so
    # quick, which has no ICP selection, skips it: with 256 points it cost 8 s and changed no layout on B)
    screen_samples: int = 0
    screen_starts: int = 6
    screen_evals: int = 30
    select_candidates: int = 3  # per k, candidates re-ranked by ICP on a reduced protocol (0: skip)
    select_time: float = 300.0  # s, the selection stage
    # a layout is asked to beat the hand-placed one on every axis, not just on the sum: each axis whose
    # predicted score exceeds hand_margin x the hand-placed k-subset's adds hand_weight x the excess
    # (0 turns it off; < 1 leaves room for the surrogate's error)
    hand_margin: float = 0.5
    hand_weight: float = 5.0
    # the ICP polish of a finalist that is not yet no worse than the hand layout on every axis (refine.py)
    polish_algorithm: str = "LN_COBYLA"
    polish_evals: int = 0  # evaluations for k = 1 (half for larger k); 0: no polish
    polish_time: float = 150.0  # s per k, a safety net: the evaluations should end the polish
    polish_margin: float = 0.9  # aim below 0.9 x the hand layout's per-axis statistics
    polish_weight: float = 5.0  # cost per unit of per-axis excess over polish_margin x the hand's, on top of the sum
    polish_step: float = 0.03  # initial step in [0, 1] units (about 2 mm of aim point, 4 deg of view)
    # a finalist that beats the hand layout on the reduced protocol by less than polish_margin on some axis
    # or clear_ratio in sum, or that a polish produced, is confirmed: the best confirm_candidates of that k
    # and the one closest to dominance re-run the full protocol (selection seed) and the best there is
    # kept (0: no confirmation)
    confirm_candidates: int = 0
    clear_ratio: float = 0.4
    validation: str = "full"  # the held-out seed's protocol: full (the objective's) | reduced (end angles only)

    def __post_init__(self) -> None:
        from optipose.errors import ConfigError

        if not self.sensors or min(self.sensors) < 1 or max(self.sensors) > 6:
            raise ConfigError("--sensors: give sensor counts between 1 and 6, e.g. 1,2,3")
        if self.validation not in ("full", "reduced"):
            raise ConfigError(f"search validation must be full or reduced, not '{self.validation}'")
        if self.strategy not in ("greedy", "joint", "both"):
            raise ConfigError(f"search strategy must be greedy, joint or both, not '{self.strategy}'")
        for name in (self.global_algorithm, self.local_algorithm, self.polish_algorithm):
            _algorithm(name)  # raises ConfigError for an unknown name


BUDGETS: dict[str, dict] = {
    # quick: greedy only, so the layouts are nested and one run validates k = 1, 2, 3; on the reduced protocol
    "quick": dict(
        global_evals=70, local_evals=20, max_time=25.0, random_starts=4, select_candidates=0, strategy="greedy",
        validation="reduced",
    ),  # fmt: skip
    "default": dict(
        global_evals=400, local_evals=120, joint_evals=200, max_time=240.0, select_candidates=3, select_time=240.0,
        polish_evals=90, confirm_candidates=3, screen_samples=4096,
    ),  # fmt: skip
    "thorough": dict(
        global_evals=2000, local_evals=400, joint_evals=1000, max_time=3000.0, random_starts=16, screen_samples=16384,
        screen_starts=12, screen_evals=60,
        select_candidates=6, select_time=1800.0, polish_time=900.0, polish_evals=200, confirm_candidates=6,
    ),  # fmt: skip
}


def _algorithm(name: str) -> int:
    import nlopt

    from optipose.errors import ConfigError

    value = getattr(nlopt, name, None)
    if not isinstance(value, int) or not name[:3] in ("GN_", "LN_", "GD_", "LD_", "G_M", "AUG"):
        raise ConfigError(f"unknown NLopt algorithm '{name}' (e.g. GN_CRS2_LM, GN_DIRECT_L, GN_ISRES, LN_BOBYQA)")
    if name.startswith(("GD_", "LD_")):
        raise ConfigError(f"NLopt algorithm '{name}' needs gradients; the objective has none (use GN_*/LN_*)")
    return value


@dataclass
class Found:
    """The best layout found for k sensors, on the surrogate."""

    k: int
    strategy: str  # greedy | joint
    u: np.ndarray  # (6k,) in [0, 1]
    poses: list[np.ndarray]
    score: float
    stats: dict = field(repr=False, default_factory=dict)


@dataclass
class SearchOutcome:
    found: dict[int, Found]  # k -> the winner of greedy and joint
    greedy: dict[int, Found]
    joint: dict[int, Found]
    hand: dict[int, Found]  # k -> the best hand-placed k-subset on the surrogate
    history: list[dict]
    interrupted: bool = False
    seconds: float = 0.0


class _Stop(Exception):
    """Raised inside the objective to end the whole search (time is up, or Ctrl-C)."""


class SurrogateProblem:
    """Scores layouts on the surrogate with constraints; caches per-sensor results; keeps the history."""

    def __init__(self, part, objective, config: SearchConfig, surrogate: Surrogate | None = None):
        self.part, self.config = part, config
        stat = objective.statistic
        self._weights = (tuple(stat.weights), stat.median_weight, stat.p75_weight)
        self.surrogate = surrogate or Surrogate(part, voxel=objective.registration.voxel_size, turns=protocol_turns(objective))
        self.space = PoseSpace.around(np.asarray(part.mesh.bounds), config.margin, config.alpha_max_deg)
        self.collision = collision_model(part)
        self.cache: dict[tuple, SensorInfo | float] = {}
        self.history: list[dict] = []
        self.best: dict[int, tuple[float, np.ndarray]] = {}
        self.deadline = np.inf
        self.targets: dict[int, np.ndarray] = {}  # k -> per-axis surrogate scores (deg) a layout should beat
        self.stage = ""
        self.on_eval = None  # callback(row) for progress bars
        self.interrupted = False

    # --- one sensor ------------------------------------------------------------------------------
    def sensor(self, u6: np.ndarray) -> SensorInfo | float:
        """The sensor's information, or its constraint violation (> 0) when it is infeasible on its own."""
        key = tuple(np.round(np.asarray(u6, dtype=float), 9))
        if key not in self.cache:
            T = self.space.to_pose(np.asarray(key))
            skew, limit = abs(T[0, 0]), np.sin(np.deg2rad(self.config.line_skew_max_deg))  # |x_S · x_O|
            if skew > limit + 1e-12:  # checked first: it needs no collision test and no scan
                self.cache[key] = 1.0 + (skew - limit) / max(1.0 - limit, 1e-9)
            elif (gap := self.collision.clearance(T).distance) < self.config.clearance:
                self.cache[key] = 1.0 + min(self.config.clearance - gap, 1.0) / self.config.clearance
            else:
                info = self.surrogate.info(T)
                short = self.config.min_points - info.n_points
                self.cache[key] = info if short <= 0 else short / self.config.min_points
        return self.cache[key]

    # --- a layout ----------------------------------------------------------------------------------
    def evaluate(self, u: np.ndarray, constrained: bool = True) -> tuple[float, dict | None]:
        """Score of a layout (6k,) and its surrogate stats; infeasible: PENALTY + violation, None.

        ``constrained=False`` scores a given layout (the hand-placed one) whatever its clearances.
        """
        k = len(u) // 6
        if not constrained:
            stats = predicted_stats([self.surrogate.info(T) for T in self.space.to_poses(u)], *self._weights)
            return stats["score"], stats
        parts = [self.sensor(u[6 * i : 6 * i + 6]) for i in range(k)]
        violation = sum(p for p in parts if not isinstance(p, SensorInfo))
        if k > 1:
            poses = self.space.to_poses(u)
            sensor = self.collision.sensor
            for a, b in itertools.combinations(range(k), 2):
                gap = heads_clearance(sensor, poses[a], sensor, poses[b])
                if gap < self.config.head_gap:
                    violation += 1.0 + min(self.config.head_gap - gap, 0.1) * 10
        if violation > 0:
            return PENALTY + violation, None
        stats = predicted_stats(parts, *self._weights)
        return stats["score"] + self.shortfall(k, stats), stats

    def shortfall(self, k: int, stats: dict) -> float:
        """The per-axis penalty (deg) for axes predicted worse than the margin times the hand layout's."""
        target = self.targets.get(k, self.targets.get(max(self.targets, default=0)))
        if target is None or self.config.hand_margin <= 0:
            return 0.0
        excess = np.clip(stats["axis_score"] - self.config.hand_margin * target, 0.0, None)
        return float(self.config.hand_weight * np.dot(self._weights[0], excess))

    def __call__(self, u: np.ndarray, grad=None) -> float:
        if time.monotonic() > self.deadline:
            raise _Stop("time budget used up")
        try:
            value, stats = self.evaluate(np.asarray(u, dtype=float))
        except KeyboardInterrupt:
            self.interrupted = True
            raise _Stop("interrupted") from None
        k = len(u) // 6
        feasible = stats is not None
        if feasible and value < self.best.get(k, (np.inf,))[0]:
            self.best[k] = (value, np.array(u, dtype=float))
        row = {
            "eval": len(self.history), "stage": self.stage, "k": k, "value": value, "feasible": feasible,
            "best": self.best.get(k, (np.nan,))[0], "u": np.round(np.asarray(u, float), 9).tolist(),
        }  # fmt: skip
        self.history.append(row)
        if self.on_eval:
            self.on_eval(row)
        return float(value)


def _optimize(problem: SurrogateProblem, algorithm: str, x0: np.ndarray, maxeval: int, seed: int, local: str | None = None):
    """One NLopt run on [0, 1]^n from ``x0``. The objective records what it sees (its history and best), so
    nothing is returned; NLopt's own stops end quietly, a :class:`_Stop` (time up, Ctrl-C) propagates."""
    import nlopt

    n = len(x0)
    opt = nlopt.opt(_algorithm(algorithm), n)
    opt.set_lower_bounds(np.zeros(n))
    opt.set_upper_bounds(np.ones(n))
    opt.set_min_objective(problem)
    opt.set_maxeval(int(maxeval))
    if algorithm.startswith(("LN_",)):
        opt.set_initial_step(np.full(n, 0.08))
        opt.set_xtol_rel(1e-5)
    if algorithm.startswith("GN_MLSL") or algorithm.startswith("G_MLSL"):
        sub = nlopt.opt(_algorithm(local or "LN_BOBYQA"), n)
        sub.set_xtol_rel(1e-4)
        sub.set_maxeval(max(10, maxeval // 10))
        opt.set_local_optimizer(sub)
    if algorithm.startswith(("GN_CRS", "GN_ISRES")):
        # NLopt's default populations (CRS2 10(n+1), ISRES 20(n+1)) would spend most of a small budget on
        # one random generation; cap them at a fifth of the budget
        opt.set_population(int(min(10 * (n + 1), max(n + 2, maxeval // 5))))
    nlopt.srand(int(seed) % (2**31))
    try:
        opt.optimize(np.clip(x0, 0.0, 1.0))
    except (_Stop, nlopt.ForcedStop, nlopt.RoundoffLimited) as exc:
        if isinstance(exc, _Stop):
            raise
    except RuntimeError as exc:  # NLopt's generic failure: keep what was found
        log.warning("NLopt %s stopped: %s", algorithm, exc)


def _hand_units(problem: SurrogateProblem, hand_poses: list[np.ndarray]) -> list[np.ndarray]:
    return [problem.space.from_pose(T) for T in hand_poses]


def _best_hand_subsets(problem: SurrogateProblem, hand_u: list[np.ndarray], ks) -> dict[int, Found]:
    """The best k of the hand-placed sensors on the surrogate, scored as given (no constraint checks:
    they are the baseline, e.g. the paper's three heads overlap in our default head-box model)."""
    out = {}
    for k in ks:
        best = None
        for combo in itertools.combinations(range(len(hand_u)), k):
            u = np.concatenate([hand_u[i] for i in combo])
            value, stats = problem.evaluate(u, constrained=False)
            if stats is not None and (best is None or value < best.score):
                best = Found(k, "hand", u, problem.space.to_poses(u), value, stats)
        if best:
            out[k] = best
    return out


def run_search(part, objective, config: SearchConfig, seed: int = 0, problem: SurrogateProblem | None = None) -> SearchOutcome:
    """Greedy then joint NLopt search for every k in ``config.sensors`` (see the module doc)."""
    t0 = time.monotonic()
    problem = problem or SurrogateProblem(part, objective, config)
    rng = np.random.default_rng(seed)
    hand_poses = part.layouts["hand"].poses if "hand" in part.layouts else []
    hand_u = _hand_units(problem, hand_poses)
    ks = sorted(set(config.sensors))
    hand = _best_hand_subsets(problem, hand_u, [k for k in ks if k <= len(hand_u)])
    problem.targets = {k: f.stats["axis_score"] for k, f in hand.items()}
    # the clock starts after the hand layout is scored: that first scan also compiles the kernels
    problem.deadline = time.monotonic() + config.max_time
    greedy, joint = {}, {}
    try:
        placed = np.zeros(0)
        for k in range(1, max(ks) + 1):
            if config.strategy in ("greedy", "both") or k == 1:
                placed = _greedy_stage(problem, config, placed, hand_u, rng, seed * 1000 + k)
                if k not in problem.best:  # no feasible layout of k sensors: more sensors will not help
                    log.warning("no feasible layout of %d sensor(s) found; stopping", k)
                    break
                value, stats = problem.evaluate(placed)
                greedy[k] = Found(k, "greedy", placed.copy(), problem.space.to_poses(placed), value, stats or {})
            if k > 1 and config.strategy in ("joint", "both"):
                joint[k] = _joint_stage(problem, config, k, greedy.get(k), hand.get(k), rng, seed * 1000 + 100 + k)
                if config.strategy == "joint":
                    placed = joint[k].u
    except _Stop as why:
        unplaced = [k for k in ks if k not in problem.best]
        (log.warning if unplaced else log.info)(
            "search stopped: %s%s", why, f"; no layout of {unplaced} sensor(s) yet (raise max_time)" if unplaced else ""
        )
    found = {}
    for k in ks:
        options = [f for f in (greedy.get(k), joint.get(k), _as_found(problem, k)) if f and f.stats]
        if options:
            found[k] = min(options, key=lambda f: f.score)
    return SearchOutcome(found, greedy, joint, hand, problem.history, problem.interrupted, time.monotonic() - t0)


def _as_found(problem: SurrogateProblem, k: int) -> Found | None:
    """The best feasible layout of k sensors seen anywhere (covers a search cut short mid-stage)."""
    if k not in problem.best:
        return None
    value, u = problem.best[k]
    _, stats = problem.evaluate(u)
    return Found(k, problem.stage.split(":")[0] or "search", u, problem.space.to_poses(u), value, stats or {})


def _greedy_stage(problem, config, placed, hand_u, rng, seed) -> np.ndarray:
    """Add one sensor to ``placed`` (6(k-1),): a space-filling screen (:func:`_screen`), a global stage over
    its 6 numbers from the best start, then a local polish."""
    k = len(placed) // 6 + 1
    f = lambda u6: problem.evaluate(np.concatenate([placed, u6]))[0]  # noqa: E731

    def wrapped(u6, grad=None):
        return problem(np.concatenate([placed, np.asarray(u6)]))

    wrapped_problem = _Shim(problem, wrapped)
    screened = _screen(problem, config, wrapped_problem, k, seed - k)  # the same points at every k: cached
    starts = [u for u in hand_u] + [rng.random(6) for _ in range(config.random_starts)] + screened[:1]
    scored = sorted(((f(u), i) for i, u in enumerate(starts)), key=lambda t: t[0])
    x0 = starts[scored[0][1]] if scored else rng.random(6)
    problem.stage = f"greedy:k={k}"
    _optimize(wrapped_problem, config.global_algorithm, x0, config.global_evals, seed, config.local_algorithm)
    best_u6 = problem.best.get(k, (None, np.concatenate([placed, x0])))[1][-6:]
    problem.stage = f"greedy-polish:k={k}"
    _optimize(wrapped_problem, config.local_algorithm, best_u6, config.local_evals, seed + 1)
    if len(starts) and scored[0][1] < len(hand_u):  # also polish the best hand start, when it led
        _optimize(wrapped_problem, config.local_algorithm, x0, config.local_evals // 2, seed + 2)
    return problem.best[k][1].copy() if k in problem.best else np.concatenate([placed, x0])


def _joint_stage(problem, config, k, greedy: Found | None, hand: Found | None, rng, seed) -> Found:
    """Polish all 6k numbers at once from the greedy layout and from the best hand-placed k-subset."""
    problem.stage = f"joint:k={k}"
    best = None
    for start in [s for s in (greedy, hand) if s is not None] or [Found(k, "random", rng.random(6 * k), [], np.inf)]:
        row = local_best(problem, config.local_algorithm, start.u, config.joint_evals // (2 if hand and greedy else 1), seed)
        if row is not None:
            u = np.asarray(row["u"])
            if best is None or row["value"] < best.score:
                best = Found(k, "joint", u, problem.space.to_poses(u), row["value"], problem.evaluate(u)[1])
    return best or Found(k, "joint", greedy.u if greedy else np.zeros(6 * k), [], np.inf, {})


def _screen(problem, config, wrapped_problem, k: int, seed: int) -> list[np.ndarray]:
    """Score ``screen_samples`` scrambled-Sobol poses of the k-th sensor, then polish locally the best
    ``screen_starts`` of them that lie apart (more than 0.1 apart in some [0, 1] unit); returns the polished
    bests, best first. Every evaluation is recorded, so the ICP selection sees these basins too.
    After k = 1 the poses' information is cached, so later greedy stages re-score the same points nearly free."""
    if config.screen_samples <= 0:
        return []
    from scipy.stats import qmc

    problem.stage = f"screen:k={k}"
    points = qmc.Sobol(6, scramble=True, seed=seed).random(int(config.screen_samples))
    values = np.array([wrapped_problem(u) for u in points])
    order = np.argsort(values, kind="stable")
    picked: list[np.ndarray] = []
    for i in order:
        if values[i] >= PENALTY or len(picked) >= config.screen_starts:
            break
        if apart(points[i], picked, 0.1):
            picked.append(points[i])
    problem.stage = f"screen-polish:k={k}"
    bests = []
    for j, start in enumerate(picked):
        best = local_best(wrapped_problem, config.local_algorithm, start, config.screen_evals, seed + 10 + j, problem.history)
        if best is not None:
            bests.append((best["value"], np.asarray(best["u"], dtype=float)[-6:]))
    return [u for _, u in sorted(bests, key=lambda t: t[0])]


def local_best(fn, algorithm: str, x0: np.ndarray, maxeval: int, seed: int, history: list[dict] | None = None) -> dict | None:
    """Run a local NLopt search on ``fn`` (a :class:`SurrogateProblem` or a sub-problem of one, whose
    evaluations are recorded in ``history``, by default ``fn.history``) and return the best feasible
    history row it produced, or None when it met no feasible layout."""
    history = fn.history if history is None else history
    before = len(history)
    _optimize(fn, algorithm, x0, maxeval, seed)
    rows = [r for r in history[before:] if r["feasible"]]
    return min(rows, key=lambda r: r["value"]) if rows else None


def apart(u: np.ndarray, others, min_distance: float) -> bool:
    """``u`` lies more than ``min_distance`` from every one of ``others`` in some [0, 1] unit (max norm)."""
    return all(np.max(np.abs(np.asarray(u) - np.asarray(o))) > min_distance for o in others)


class _Shim:
    """Presents a sub-problem (the new sensor's 6 numbers) to NLopt while recording the full layout."""

    def __init__(self, problem: SurrogateProblem, fn):
        self._problem, self._fn = problem, fn

    def __call__(self, u, grad=None):
        return self._fn(u)
