"""The problem the search solves: score a layout (6k numbers in [0, 1]) on the surrogate, with constraints.

A layout is **infeasible** when a sensor's laser line turns more than ``line_skew_max_deg`` from across the
motion, its head comes within ``clearance`` of the part swept along the scan or of a keep-out, it returns
fewer than ``min_points``, or two heads come within ``head_gap`` of each other. Its :class:`LayoutScore`
then names the first violated constraint and how far (normalised, ≥ 0) the layout is from feasible;
optimisers see ``PENALTY + violation`` (:attr:`LayoutScore.objective`), so they are led back toward
feasibility, and an infeasible layout never becomes a result.

The user wants a layout that is no worse than the hand-placed one on *any* axis, not only on the sum, and
the sum is dominated by the worst axis (usually roll), so an unpenalised optimiser happily trades a good
axis for it. Each axis predicted worse than ``hand_margin`` × the best hand-placed k-subset's (the
``targets``) therefore adds ``hand_weight`` × the excess to the value (:meth:`SurrogateProblem.shortfall`).

Every sensor pose's information (or violation) is cached by its parameters, so a repeated pose costs
nothing and a resumed search replays its earlier evaluations from the cache (:mod:`optipose.io.search`
saves it).
"""

from __future__ import annotations

import itertools
from types import MappingProxyType
from typing import NamedTuple

import numpy as np

from optipose.cell.scans import CellSetup
from optipose.verdict.compare import weighted_excess
from optipose.model.collision import collision_model, heads_clearance
from optipose.search.config import SearchConfig
from optipose.search.records import LayoutScore
from optipose.search.space import PoseSpace
from optipose.search.surrogate import Prediction, SensorInfo, Surrogate, predicted_stats, protocol_turns

__all__ = ["SurrogateProblem", "Violation"]


class Violation(NamedTuple):
    """A sensor pose that is infeasible on its own: which constraint, and by how much (≥ 1, normalised)."""

    constraint: str
    amount: float


def _key(u6) -> tuple:
    """A sensor's cache key: its six numbers rounded to 1e-9."""
    return tuple(np.round(np.asarray(u6, dtype=float), 9))


class SurrogateProblem:
    """Scores layouts on the surrogate with constraints; caches per-sensor results.

    part, objective : the part and the objective the layouts are for.
    config : the search's settings (constraints, the hand-margin penalty).
    surrogate : shared with another problem of the same part and objective (default: a new one).
    cache : shared per-sensor cache (u key → :class:`SensorInfo` or :class:`Violation`), e.g. a resumed one.
    targets : k → per-axis surrogate scores (deg) of the best hand-placed k-subset, for the shortfall: (3,)
        or (1, 3) (``level_axis_score``).
    subsets : shared memo of sensor subsets' predicted statistics (:func:`predicted_stats`), e.g. another
        problem's of the same part and objective.
    """

    def __init__(
        self,
        part,
        objective,
        config: SearchConfig,
        surrogate: Surrogate | None = None,
        cache: dict | None = None,
        targets: dict[int, np.ndarray] | None = None,
        subsets: dict | None = None,
    ):
        self.part, self.objective, self.config = part, objective, config
        stat = objective.statistic
        self.weights = (tuple(stat.weights), stat.median_weight, stat.p75_weight)
        cell = (
            None if objective.cell.ideal else CellSetup.of(objective.cell, part)
        )  # the cell's sources, scored by the surrogate too
        self.surrogate = surrogate or Surrogate(
            part,
            voxel=objective.registration.voxel_size,
            turns=protocol_turns(objective),
            cell=cell,
        )
        self.space = PoseSpace.around(
            np.asarray(part.mesh.bounds), config.constraints.margin, config.constraints.alpha_max_deg
        )
        self.collision = collision_model(part)
        corners = self.collision.sensor.head_box_corners()
        middle = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
        self._head_sphere = (
            middle,
            float(np.linalg.norm(corners - middle, axis=1).max()),
        )  # the head box's bounding sphere in S
        self._cache: dict = {} if cache is None else cache
        if (
            self.surrogate.cell is not None
        ):  # a resumed cache holds no cell term (io.search does not save it): score those poses again
            for key in [
                k for k, v in self._cache.items() if isinstance(v, SensorInfo) and v.cell is None and v.n_voxels
            ]:
                del self._cache[key]
        self._given: dict = {}  # u key → SensorInfo of a sensor scored as given (:meth:`info`)
        self._subsets: dict = (
            {} if subsets is None else subsets
        )  # sensor subsets' predicted statistics (predicted_stats' memo)
        self._targets = dict(targets or {})

    def with_targets(self, targets: dict[int, np.ndarray]) -> "SurrogateProblem":
        """The same problem (surrogate, cache) measured against these per-axis targets."""
        return SurrogateProblem(
            self.part, self.objective, self.config, self.surrogate, self._cache, targets, self._subsets
        )

    @property
    def cache(self):
        """The per-sensor cache, read-only: u key (6 floats) → :class:`SensorInfo` or :class:`Violation`."""
        return MappingProxyType(self._cache)

    # --- one sensor ------------------------------------------------------------------------------
    def sensor(self, u6: np.ndarray) -> SensorInfo | Violation:
        """The sensor's information, or its constraint violation when it is infeasible on its own."""
        return self._cached(_key(u6))

    def _cached(self, key: tuple) -> SensorInfo | Violation:
        if key not in self._cache:
            self._cache[key] = self._sensor_at(key)
        return self._cache[key]

    def prefetch(self, us: np.ndarray, threads: int | None = None, until: float = np.inf) -> None:
        """Compute the sensors ``us`` (n, 6) not yet in the cache on ``threads`` threads (default: the cores),
        in order, a few per thread at a time, until ``time.monotonic()`` passes ``until``; scoring them later
        costs a lookup. The surrogate's scan, voxels and closest points run compiled and release the GIL:
        two threads score more poses per second than one. The cache ends the same as scoring them one
        by one."""
        import time
        from concurrent.futures import ThreadPoolExecutor

        from optipose.scan.raycast import default_threads

        keys = list(dict.fromkeys(_key(u) for u in us))
        todo = [k for k in keys if k not in self._cache]
        threads = threads or default_threads()
        if threads < 2 or len(todo) < 2:
            return
        self.surrogate.ready()
        chunk = 4 * threads
        with ThreadPoolExecutor(threads) as pool:
            for start in range(0, len(todo), chunk):
                if time.monotonic() > until:
                    return
                part = todo[start : start + chunk]
                for key, value in zip(part, pool.map(self._sensor_at, part)):
                    self._cache[key] = value

    def info(self, u6: np.ndarray) -> SensorInfo:
        """The sensor's information whatever its constraints (a given layout's sensor, e.g. a hand-placed
        one), scanned once at ``u6``'s own pose."""
        key = _key(u6)
        if key not in self._given:
            self._given[key] = self.surrogate.info(self.space.to_pose(np.asarray(u6, dtype=float)))
        return self._given[key]

    def _sensor_at(self, key: tuple) -> SensorInfo | Violation:
        return self._sensor(self.space.to_pose(np.asarray(key)))

    def _sensor(self, T: np.ndarray) -> SensorInfo | Violation:
        cfg = self.config.constraints
        skew, limit = abs(T[0, 0]), np.sin(np.deg2rad(cfg.line_skew_max_deg))  # |x_S · x_O|
        if skew > limit + 1e-12:  # checked first: it needs no collision test and no scan
            return Violation("line_skew", 1.0 + (skew - limit) / max(1.0 - limit, 1e-9))
        if (gap := self.collision.clearance(T).distance) < cfg.clearance:
            return Violation("clearance", 1.0 + min(cfg.clearance - gap, 1.0) / cfg.clearance)
        info = self.surrogate.info(T)
        short = cfg.min_points - info.n_points
        return info if short <= 0 else Violation("min_points", short / cfg.min_points)

    # --- a layout ----------------------------------------------------------------------------------
    def score(self, u: np.ndarray, constrained: bool = True) -> LayoutScore:
        """The surrogate's score of a layout (6k,).

        ``constrained=False`` scores a given layout (the hand-placed one) whatever its clearances, without
        the shortfall: it is the baseline.
        """
        if not constrained:
            stats = predicted_stats([self.info(u[6 * i : 6 * i + 6]) for i in range(len(u) // 6)], *self.weights)
            return LayoutScore(stats.score, stats)
        k = len(u) // 6
        keys = [_key(u[6 * i : 6 * i + 6]) for i in range(k)]  # the cache's, and the subsets' memo's
        parts = [self._cached(key) for key in keys]
        violated = [p for p in parts if isinstance(p, Violation)]
        violation = sum(p.amount for p in violated)
        constraint = violated[0].constraint if violated else ""
        if k > 1:
            before, violation = violation, self._head_gaps(u, violation)
            constraint = constraint or ("head_gap" if violation > before else "")
        if violation > 0:
            return LayoutScore(float("nan"), None, violation, constraint)
        stats = predicted_stats(parts, *self.weights, memo=self._subsets, keys=keys)
        return LayoutScore(stats.score + self.shortfall(k, stats), stats)

    def _head_gaps(self, u: np.ndarray, violation: float) -> float:
        """``violation`` plus that of the head-to-head gap of every pair of sensors that is below ``head_gap``.
        Two heads far enough apart that the exact test (SAT, far dearer) cannot find them too close are not
        tested: disjoint bounding spheres when ``head_gap`` ≤ 0 (the boxes are disjoint, so SAT's gap is
        positive); otherwise centres d apart, d/√3 − 2·radius beyond the gap (along one of the first box's
        axes the centres are at least d/√3 apart, and SAT tests that axis)."""
        poses = self.space.to_poses(u)
        sensor, gap_min = self.collision.sensor, self.config.constraints.head_gap
        centre, radius = self._head_sphere
        centres = [T[:3, :3] @ centre + T[:3, 3] for T in poses]
        for a, b in itertools.combinations(range(len(poses)), 2):
            d = float(np.linalg.norm(centres[a] - centres[b]))
            if (d if gap_min <= 0 else d / np.sqrt(3)) - 2 * radius > max(gap_min, 0.0) + 1e-9:
                continue
            gap = heads_clearance(sensor, poses[a], sensor, poses[b])
            if gap < gap_min:
                violation += 1.0 + min(gap_min - gap, 0.1) * 10
        return violation

    def shortfall(self, k: int, stats: Prediction) -> float:
        """The per-axis penalty (deg) for axes predicted worse than the margin times the hand layout's."""
        target = self._targets.get(k, self._targets.get(max(self._targets, default=0)))
        if target is None or self.config.surrogate.hand_margin <= 0:
            return 0.0
        margin, weights = self.config.surrogate.hand_margin, self.weights[0]
        values, target = np.atleast_2d(stats.level_axis_score), np.atleast_2d(target)
        if len(target) != len(values):
            raise ValueError(
                f"hand targets for {len(target)} noise level(s), the layout's for {len(values)}: give each level's (level_axis_score)"
            )
        return float(
            self.config.surrogate.hand_weight
            * sum(weighted_excess(v, t, margin, weights) for v, t in zip(values, target))
        )
