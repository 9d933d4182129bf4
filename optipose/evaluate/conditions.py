"""Conditions a layout must survive (docs/conditions.md): a band of sensor noise and the brackets' mounting tolerance.

An objective file's ``[conditions]`` table says which::

    [conditions]
    noise_scale = [1.0, 3.0, 5.0]    # the sensor's noise σ (at full intensity) times each of these
    mounting_translation_mm = 0.2    # each sensor's true pose is off the drawn one by up to ± this per axis
    mounting_rotation_deg = 0.1      # ... and turned by up to ± this about each of its axes
    mounting_draws = 2               # independent bracket-error draws per noise level
    aggregate = "worst"              # or a quantile in (0, 1], e.g. 0.9: over the conditions, per statistic

A condition is one noise level with one draw of mounting errors (none when the tolerance is zero). Under
it, each sensor scans from its true pose while the cloud is rebuilt with the drawn (nominal) pose, and the
cell is zeroed on the part at its nominal orientation: a master-part scan's registration is the constant
bias, and it is taken off every later estimate, as a cell's calibration would. What remains and is scored
is the distortion between sensors and how it changes with the part's orientation.

The defaults (one level at the preset's σ, zero tolerance) are exactly the objective without conditions.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from optipose.errors import ConfigError
from optipose.seeds import mounting_seed
from optipose.transforms import make_T, rpy_to_matrix

__all__ = [
    "ConditionsConfig",
    "Condition",
    "conditions",
    "by_draw",
    "band_ends",
    "mounting_error",
    "conditions_from_table",
    "aggregate",
]

_MM, _DEG = 1e-3, np.pi / 180


@dataclass(frozen=True)
class ConditionsConfig:
    """The band of conditions (SI). See the module doc for the file keys."""

    noise_scales: tuple[float, ...] = (1.0,)
    mounting_translation: float = 0.0  # m, ± per axis
    mounting_rotation: float = 0.0  # rad, ± about each axis
    mounting_draws: int = 1
    aggregate: str | float = "worst"  # "worst" or a quantile in (0, 1]

    @property
    def mounted(self) -> bool:
        """Whether the brackets are off at all."""
        return self.mounting_translation > 0 or self.mounting_rotation > 0

    @property
    def trivial(self) -> bool:
        """One condition that is the nominal one: the objective without conditions."""
        return self.noise_scales == (1.0,) and not self.mounted


@dataclass(frozen=True)
class Condition:
    """One condition: the noise scale and, when the brackets are off, the draw whose errors apply."""

    noise_scale: float = 1.0
    draw: int | None = None  # None: every sensor exactly where it was drawn
    translation: float = 0.0  # m, the tolerance the draw is within
    rotation: float = 0.0  # rad
    zeroed: bool = True  # the cell is zeroed on a master part (False: the constant bias stays in)
    only: tuple[int, ...] | None = None  # the sensors whose brackets are off (None: every sensor)

    @property
    def label(self) -> str:
        mount = "" if self.draw is None else f", mounting draw {self.draw}"
        if self.draw is not None and self.only is not None:
            mount += f" of sensor{'s' if len(self.only) > 1 else ''} {', '.join(str(j + 1) for j in self.only)}"
        return f"noise x{self.noise_scale:g}{mount}{'' if self.zeroed else ', not zeroed'}"

    @property
    def slug(self) -> str:
        """The label as a folder name, e.g. ``noise-x3-draw-1``."""
        mount = "" if self.draw is None else f"-draw-{self.draw}"
        only = "" if self.only is None or self.draw is None else "-of-" + "-".join(str(j + 1) for j in self.only)
        return f"noise-x{self.noise_scale:g}{mount}{only}{'' if self.zeroed else '-unzeroed'}"

    @property
    def nominal(self) -> bool:
        return self.noise_scale == 1.0 and self.draw is None


def conditions(cfg: ConditionsConfig) -> list[Condition]:
    """Every condition of the band: each noise level with each mounting draw (noise levels first)."""
    draws = list(range(cfg.mounting_draws)) if cfg.mounted else [None]
    return [Condition(s, d, cfg.mounting_translation, cfg.mounting_rotation) for s in cfg.noise_scales for d in draws]


def by_draw(conditions: list[Condition]) -> list[list[Condition]]:
    """The conditions grouped by what they share but the noise scale (a bracket draw at several noise
    levels), in the order they first appear: the conditions one ray cast serves
    (:meth:`optipose.evaluate.evaluator.Evaluator.under`)."""
    groups: dict = {}
    for c in conditions:
        groups.setdefault(replace(c, noise_scale=1.0), []).append(c)
    return list(groups.values())


def band_ends(cfg: ConditionsConfig) -> ConditionsConfig:
    """The band cut to its lowest and highest noise level (with every mounting draw): the search's cheaper
    band. An error's square is about bias² + s²·σ² at noise scale s, so the difference between two layouts
    is affine in s²: a layout no worse than another at both ends of the band is no worse anywhere in it,
    and the worst over the band is (about) the worst over its ends. (The noise's own bias through the voxels
    adds an s⁴ term, which can bend the difference in between; a band that lists a middle level scores it
    in validation.)"""
    scales = tuple(sorted({min(cfg.noise_scales), max(cfg.noise_scales)}))
    return replace(cfg, noise_scales=scales)


def mounting_error(condition: Condition, seed: int, sensor: int) -> np.ndarray:
    """The 4×4 ``T_S_true`` of sensor ``sensor`` (its index in the layout) under ``condition``: the true pose
    is ``T_O_S @ T_S_true``. Uniform within the tolerance on each axis, from the run's seed, the draw and
    the sensor's index only, so the same bracket is off the same way in every layout and every run (and
    with ``only``, whichever other brackets are off)."""
    if condition.draw is None or (condition.only is not None and sensor not in condition.only):
        return np.eye(4)
    rng = np.random.default_rng(mounting_seed(seed, condition.draw, sensor))
    t = rng.uniform(-1.0, 1.0, 3) * condition.translation
    r = rng.uniform(-1.0, 1.0, 3) * condition.rotation
    return make_T(rpy_to_matrix(r), t)


def aggregate(values: np.ndarray, how: str | float) -> np.ndarray:
    """The robust aggregate over conditions (axis 0): the worst, or a quantile."""
    values = np.asarray(values, dtype=float)
    return np.max(values, axis=0) if how == "worst" else np.quantile(values, float(how), axis=0)


def conditions_from_table(t: dict, where: str) -> ConditionsConfig:
    """``[conditions]`` of an objective file (degrees and millimetres) as a :class:`ConditionsConfig`."""
    keys = {"noise_scale", "mounting_translation_mm", "mounting_rotation_deg", "mounting_draws", "aggregate"}
    unknown = set(t) - keys
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(sorted(unknown))} (known: {', '.join(sorted(keys))})")
    scales = t.get("noise_scale", [1.0])
    scales = scales if isinstance(scales, list) else [scales]
    try:
        scales = tuple(float(s) for s in scales)
        translation = float(t.get("mounting_translation_mm", 0.0)) * _MM
        rotation = float(t.get("mounting_rotation_deg", 0.0)) * _DEG
        draws = int(t.get("mounting_draws", 1))
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: noise_scale, mounting_* must be numbers") from None
    if not scales or min(scales) <= 0 or not all(np.isfinite(scales)):
        raise ConfigError(f"{where}: noise_scale must be a non-empty list of positive numbers")
    if translation < 0 or rotation < 0 or draws < 1:
        raise ConfigError(f"{where}: mounting tolerances must be >= 0 and mounting_draws >= 1")
    how = t.get("aggregate", "worst")
    if how != "worst" and not (isinstance(how, (int, float)) and 0 < how <= 1):
        raise ConfigError(f'{where}: aggregate must be "worst" or a quantile in (0, 1], got {how!r}')
    return ConditionsConfig(scales, translation, rotation, draws, how if how == "worst" else float(how))
