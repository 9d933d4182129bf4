"""Magnitudes known only to a bracket: how a cell file writes them, and how a cell instance draws them (docs/cell.md).

A magnitude of a cell file's ``[robot]`` and ``[calibration]`` tables, and ``[part] process_scale``, is a point
(``path_mm = 0.1``) or a range ``[low, high]`` in the file's units (``path_mm = [0.014, 0.14]``), with
0 <= low <= high <= the key's bound; ``low == high`` is a point. A range is the specification's bracket where the
user's own cell is not known; each cell instance (one per run seed) draws its magnitudes from the ranges, then its
realisations (the part as made, the calibration, each scan's path) as a cell of points does:

- **log-uniform** between low and high when low > 0: a bracket of magnitudes spans a factor (a repeatability to a
  path error), and every factor within it is as likely as any other;
- **uniform on [0, high]** when low is 0: the logarithm has no lower end, and "anything up to" is the bracket.

Each key draws from a generator of its own, keyed by the run's seed, :data:`_MAGNITUDES` and the key's name, the keys
taken in sorted order: a draw depends neither on the file's order nor on which other keys are ranges, and a cell of
points draws nothing (its answers are those of a cell without ranges, bit for bit). The **middle** of a range is the
median of its draw: the geometric mean of its ends (low > 0), or high / 2 (low = 0). The **spread** of a cell's
ranges is a few instances that cover them evenly (a Latin hypercube over the draws' quantiles, the same for every
run): what the surrogate scores a cell of ranges on, where the evaluations draw.
"""

from __future__ import annotations

import zlib

import numpy as np

from optipose.errors import ConfigError

__all__ = ["magnitude", "middle", "draw", "draws", "quantile", "spread"]

_CELL, _MAGNITUDES, _SPREAD = 0xCE11, 4, 5  # the cell's seed tag (as in optipose.cell.scans), the draws', the spread's


def magnitude(value, key: str, unit: float, most: float, where: str) -> "float | tuple[float, float]":
    """A cell file's ``value`` of ``key`` (file units) in SI: a float for a point (a range whose ends are equal
    included), ``(low, high)`` for a range; one :class:`ConfigError` naming the key for anything else, or for a
    value beyond ``most`` (file units)."""
    if isinstance(value, list):
        if len(value) != 2 or not all(_number(v) for v in value):
            raise ConfigError(f"{where}: {key} must be a number or a range [low, high] of two numbers, got {value!r}")
        low, high = (float(v) for v in value)
        if low < 0:
            raise ConfigError(f"{where}: {key} = {value!r}: a range's ends must be >= 0")
        if low > high:
            raise ConfigError(f"{where}: {key} = {value!r}: its ends are swapped (a range is [low, high], low <= high)")
        if high > most:
            raise ConfigError(f"{where}: {key} = {value!r} reaches more than any cell has (at most {most:g})")
        return low * unit if low == high else (low * unit, high * unit)
    if not _number(value) or value < 0:
        raise ConfigError(f"{where}: {key} must be a number >= 0 or a range [low, high], got {value!r}")
    if value > most:
        raise ConfigError(f"{where}: {key} = {value:g} is more than any cell has (at most {most:g})")
    return float(value) * unit


def middle(low: float, high: float) -> float:
    """The median of a range's draw: the geometric mean of its ends, or ``high / 2`` when ``low`` is 0."""
    return float(np.sqrt(low * high)) if low > 0 else 0.5 * high


def draw(low: float, high: float, rng: np.random.Generator) -> float:
    """One magnitude from ``[low, high]``: log-uniform when ``low > 0``, uniform on ``[0, high]`` when it is 0."""
    if low > 0:
        return float(np.exp(rng.uniform(np.log(low), np.log(high))))
    return float(rng.uniform(0.0, high))


def draws(ranges, seed: int) -> dict[str, float]:
    """Each range's magnitude in the cell instance of ``seed``: ``ranges`` is ``(name, low, high)`` rows (SI);
    each name draws from its own generator (the seed, :data:`_MAGNITUDES` and the name's CRC-32), in sorted order."""
    out = {}
    for name, low, high in sorted(ranges):
        rng = np.random.default_rng([int(seed), _CELL, _MAGNITUDES, zlib.crc32(name.encode())])
        out[name] = draw(low, high, rng)
    return out


def quantile(low: float, high: float, q: float) -> float:
    """The ``q`` quantile (0 <= q <= 1) of a range's draw (:func:`draw`)."""
    if low > 0:
        return float(np.exp(np.log(low) + q * (np.log(high) - np.log(low))))
    return float(q * high)


def spread(ranges, count: int) -> list[dict[str, float]]:
    """``count`` magnitude instances that cover the ranges (``(name, low, high)`` rows, SI) evenly, the same on every
    call: each range's draw cut into ``count`` strata of equal probability, each stratum's middle quantile taken by
    one instance, the order per range permuted by a generator fixed by the range's name (a Latin hypercube)."""
    out: list[dict[str, float]] = [{} for _ in range(count)]
    for name, low, high in sorted(ranges):
        rng = np.random.default_rng([_CELL, _SPREAD, zlib.crc32(name.encode())])
        for i, stratum in enumerate(rng.permutation(count)):
            out[i][name] = quantile(low, high, (stratum + 0.5) / count)
    return out


def _number(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and bool(np.isfinite(value))
