"""Bracket sensitivity: what the mounting tolerance of an objective's band does to a layout, and which
sensor's bracket it is most sensitive to.

For one layout, at the preset's noise (scale 1) and with each of the objective's seeded mounting draws:

- **spread**: each axis's median and 75th percentile of the layout's choice per k (each axis on its fixed
  subset, :func:`~optipose.evaluate.assignment.restated`) with the brackets off by the tolerance, against
  the same cell with perfect brackets. Both cells are zeroed the same way, on the draw's master-part scan,
  so the difference is the tolerance alone; the worst over the draws.
- **bias**: the mean signed error per axis (roll, pitch, yaw in rad; x, y, z in m) an un-zeroed cell sees,
  per draw; rotation axes on the choice's subset for that axis, translations on all the choice's sensors.
  Beside it, the same cell's mean with perfect brackets (the ICP and voxel bias it has anyway).
- **per sensor**: only sensor j's bracket off (every other exactly where it was drawn), zeroed, against the
  perfect-bracket cell of the same draw: the change of each axis's term of the score (``median_weight ·
  median + p75_weight · p75``) and of the score; the worst over the draws. A subset without j is exactly
  unchanged, so a sensor outside a choice changes it by exactly 0. The sensor with the largest change is
  the bracket to make precise.

At a zero tolerance every difference above is exactly 0. The protocol is the objective's reduced one by default (:func:`~optipose.evaluate.objective.reduced_objective`):
one layout costs ``1 + draws × (3 + n sensors)`` evaluations. The choices are the caller's (e.g. a
:class:`~optipose.evaluate.robust.RobustResult`'s ``table``), else the robust choice over the mounted draws.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optipose.evaluate.assignment import Choice, best_choices, restated, stats_by_key, subset_name
from optipose.evaluate.conditions import Condition
from optipose.evaluate.evaluator import EvaluationResult, Evaluator, EvaluatorWrapper
from optipose.evaluate.objective import AXES, Objective, load_objective, reduced_objective
from optipose.evaluate.robust import robust_stats

__all__ = [
    "AxisSpread",
    "AxisBias",
    "SensorSensitivity",
    "BracketSensitivity",
    "BracketEvaluator",
    "bracket_sensitivity",
    "BIAS_AXES",
]

BIAS_AXES = AXES + ("x", "y", "z")


@dataclass(frozen=True)
class AxisSpread:
    """One axis of the choice of k sensors: its statistics (rad) with perfect brackets and with the brackets
    off by the tolerance, both zeroed, each the worst over the draws. NaN when the axis is unmeasured."""

    k: int
    axis: str
    subset: str
    nominal_median: float
    nominal_p75: float
    mounted_median: float
    mounted_p75: float

    @property
    def added(self) -> tuple[float, float]:
        """What the tolerance adds to the median and the 75th percentile (rad)."""
        return self.mounted_median - self.nominal_median, self.mounted_p75 - self.nominal_p75


@dataclass(frozen=True)
class AxisBias:
    """The mean signed error of one axis of the choice of k sensors in an un-zeroed cell under mounting draw
    ``draw`` (``bias``) and with perfect brackets (``nominal``: the ICP and voxel bias the cell has anyway);
    rad for roll, pitch, yaw, m for x, y, z; NaN when the axis is unmeasured."""

    k: int
    axis: str
    subset: str
    draw: int
    bias: float
    nominal: float

    @property
    def added(self) -> float:
        """What the brackets add to the bias (exactly 0 at a zero tolerance)."""
        return self.bias - self.nominal


@dataclass(frozen=True)
class SensorSensitivity:
    """Sensor ``sensor`` (its index in the layout; ``name`` for display) alone off its bracket, against the
    choice of k sensors with perfect brackets: ``change`` (3,) rad per axis (roll, pitch, yaw) of that axis's
    term of the score, and ``score_change`` (rad); each the worst (largest) over the draws, exactly 0 for a
    sensor outside the choice (``in_choice`` False)."""

    k: int
    sensor: int
    name: str
    change: tuple[float, float, float]
    score_change: float
    in_choice: bool = True


@dataclass(frozen=True)
class BracketSensitivity:
    """A layout's bracket sensitivity (see the module doc). translation (m) and rotation (rad) are the ±
    tolerance per axis; draws the mounting draws used; n_scans and reduced say which protocol ran."""

    layout: str
    names: tuple[str, ...]
    translation: float
    rotation: float
    draws: tuple[int, ...]
    n_scans: int
    reduced: bool
    spread: tuple[AxisSpread, ...]
    bias: tuple[AxisBias, ...]
    sensors: tuple[SensorSensitivity, ...]

    def worst_bias(self, k: int) -> dict[str, float]:
        """Per axis the largest |bias| over the draws of the choice of k sensors (rad or m)."""
        rows = [b for b in self.bias if b.k == k]
        out = {}
        for axis in BIAS_AXES:
            values = [abs(b.bias) for b in rows if b.axis == axis and np.isfinite(b.bias)]
            out[axis] = max(values) if values else float("nan")
        return out

    def ranking(self, k: int | None = None) -> list[SensorSensitivity]:
        """The sensors of the choice of k (default: all the layout's sensors), most sensitive first; a
        change that could not be measured (NaN: the subset failed) ranks first."""
        k = k or len(self.names)
        rows = [s for s in self.sensors if s.k == k and s.in_choice]
        return sorted(rows, key=lambda s: -np.nan_to_num(s.score_change, nan=np.inf))

    def most_sensitive(self, k: int | None = None) -> int:
        """The index of the sensor whose bracket to make precise for the choice of k sensors."""
        return self.ranking(k)[0].sensor


class BracketEvaluator(EvaluatorWrapper):
    """A part and an objective with a mounting tolerance, ready to measure layouts' bracket sensitivity:
    ``BracketEvaluator(part, objective)(layout, choices) -> BracketSensitivity``. The workers keep their
    scanners and reference across layouts and conditions. reduced : run the objective's reduced protocol."""

    def __init__(
        self,
        part,
        objective: Objective | str,
        seed: int = 0,
        jobs: int = 1,
        quiet: bool = True,
        reduced: bool = True,
        executor=None,
    ):
        objective = objective if isinstance(objective, Objective) else load_objective(objective)
        self.objective, self.reduced = (reduced_objective(objective) if reduced else objective), reduced
        self.evaluator = Evaluator(part, self.objective, seed=seed, jobs=jobs, quiet=quiet, executor=executor)

    def __call__(self, layout, choices: list[Choice] | None = None) -> BracketSensitivity:
        """Measure ``layout``; ``choices`` : its choice per k (k = 1 … n, e.g. a robust Table 1), default
        the robust choice over the mounted draws of this protocol."""
        cfg = self.objective.conditions
        draws = tuple(range(cfg.mounting_draws))
        runs = [self._draw(layout, d) for d in draws]
        # perfect brackets, not zeroed: the cell's own bias (ICP, voxels); the draw does not matter then
        nominal = self.evaluator(layout, Condition(1.0, 0, 0.0, 0.0, zeroed=False))
        if choices is None:  # the robust choice over the mounted draws
            stats = robust_stats([run["mounted"].stats for run in runs], cfg.aggregate)
            choices = best_choices(stats, list(layout.names), self.objective.statistic, nominal.n_scans)
        names = tuple(layout.names)
        return BracketSensitivity(
            layout=layout.name,
            names=names,
            translation=cfg.mounting_translation,
            rotation=cfg.mounting_rotation,
            draws=draws,
            n_scans=nominal.n_scans,
            reduced=self.reduced,
            spread=tuple(s for ch in choices for s in _spread(ch, runs, self.objective)),
            bias=tuple(b for ch in choices for b in _bias(ch, names, nominal, runs)),
            sensors=tuple(s for ch in choices for s in _sensors(ch, names, runs, self.objective)),
        )

    def _draw(self, layout, draw: int) -> dict:
        """The evaluations of one mounting draw: perfect brackets, every bracket off (zeroed and not), and
        each sensor's bracket alone off."""
        cfg, ev = self.objective.conditions, self.evaluator
        t, r = cfg.mounting_translation, cfg.mounting_rotation
        return {
            "perfect": ev(layout, Condition(1.0, draw, 0.0, 0.0)),  # zeroed on the same master scan
            "mounted": ev(layout, Condition(1.0, draw, t, r)),
            "unzeroed": ev(layout, Condition(1.0, draw, t, r, zeroed=False)),
            "only": [ev(layout, Condition(1.0, draw, t, r, only=(j,))) for j in range(len(layout))],
            "draw": draw,
        }


def bracket_sensitivity(
    part,
    layout,
    objective: Objective | str = "robust",
    seed: int = 0,
    jobs: int = 1,
    choices: list[Choice] | None = None,
    reduced: bool = True,
) -> BracketSensitivity:
    """One call: the bracket sensitivity of ``layout`` on ``part`` (see the module doc and :class:`BracketEvaluator`)."""
    with BracketEvaluator(part, objective, seed=seed, jobs=jobs, reduced=reduced) as evaluator:
        return evaluator(layout, choices)


def _under(choice: Choice, result: EvaluationResult, objective: Objective) -> Choice:
    return restated(choice, stats_by_key(result.stats), objective.statistic)


def _terms(choice: Choice, objective: Objective) -> np.ndarray:
    """(3,) rad: each axis's term of the score, ``median_weight · median + p75_weight · p75`` (NaN: unmeasured)."""
    s = objective.statistic
    return np.array(
        [s.median_weight * a.median + s.p75_weight * a.p75 if a.observable else np.nan for a in choice.axes]
    )


def _spread(choice: Choice, runs: list[dict], objective: Objective) -> list[AxisSpread]:
    perfect = [_under(choice, run["perfect"], objective) for run in runs]
    mounted = [_under(choice, run["mounted"], objective) for run in runs]
    out = []
    for a, axis in enumerate(AXES):
        worst = lambda chs, stat: float(np.max([getattr(ch.axes[a], stat) for ch in chs]))  # noqa: E731  NaN stays NaN
        out.append(
            AxisSpread(
                choice.k,
                axis,
                choice.axes[a].name,
                worst(perfect, "median"),
                worst(perfect, "p75"),
                worst(mounted, "median"),
                worst(mounted, "p75"),
            )
        )
    return out


def _bias(choice: Choice, names: tuple, nominal: EvaluationResult, runs: list[dict]) -> list[AxisBias]:
    """Mean signed errors of the choice's subsets in each draw's un-zeroed cell, beside the perfect-bracket one."""
    everything = subset_name(choice.sensors, list(names))
    subsets = [a.name if a.observable else "" for a in choice.axes] + [everything] * 3
    base = _mean_errors(nominal, subsets)
    return [
        AxisBias(choice.k, axis, subset, run["draw"], bias, b)
        for run in runs
        for axis, subset, bias, b in zip(BIAS_AXES, subsets, _mean_errors(run["unzeroed"], subsets), base)
    ]


def _mean_errors(result: EvaluationResult, subsets: list[str]) -> list[float]:
    """Per axis of BIAS_AXES the mean signed error (rad, m) of its subset's registrations marked ok."""
    rows = result.per_scan[result.per_scan["ok"]]
    out = []
    for axis, subset in zip(BIAS_AXES, subsets):
        errors = rows.loc[rows["subset"] == subset, f"err_{axis}"].to_numpy()
        out.append(float(errors.mean()) if len(errors) else float("nan"))
    return out


def _sensors(choice: Choice, names: tuple, runs: list[dict], objective: Objective) -> list[SensorSensitivity]:
    """Per sensor j, the worst over the draws of the change of each axis's term and of the score when only
    j's bracket is off (against the perfect-bracket cell of the same draw)."""
    out = []
    for j, name in enumerate(names):
        changes, scores = [], []
        for run in runs:
            base, moved = _under(choice, run["perfect"], objective), _under(choice, run["only"][j], objective)
            changes.append(_terms(moved, objective) - _terms(base, objective))
            scores.append(moved.score - base.score)
        change = np.max(changes, axis=0)  # NaN (unmeasured in some draw) stays NaN
        out.append(
            SensorSensitivity(
                choice.k, j, name, tuple(float(c) for c in change), float(np.max(scores)), j in choice.sensors
            )
        )
    return out
