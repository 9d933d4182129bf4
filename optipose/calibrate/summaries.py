"""What a calibration is fitted to: a hand layout's measured figures, the median and 75th percentile of |error| per
sensor subset and axis, from a published table (:func:`read_figures`) or an evaluation of scans
(:func:`from_evaluation`), and how much a figure from a finite number of scans wanders (:meth:`Summaries.noise`).

The figures file (``--figures table.csv``, docs/calibration.md) has one row per subset and axis with the columns

    part, subset, axis, median_deg, p75_deg        (required)
    k, scans                                       (optional: the table's sensor count, for the reader; the scans
                                                    behind the figure, 77 when absent: the paper's protocol)

``part`` is the part's name (``part_a``): rows of other parts are left out, so one file can hold a whole published
table and a calibration uses the calibrated part's rows only. ``subset`` names the hand layout's sensors (``S1S3``),
``axis`` is roll, pitch or yaw. Every mistake is one :class:`~optipose.errors.ConfigError` naming the file, the row
and the column.

A figure's sampling noise: the median and the 75th percentile of n scans' |error|, each the quantile estimator of a
half-normal |N(0, σ)|, have relative standard deviations √(p(1 − p) / n) / (2 φ(z) z), z = Φ⁻¹((1 + p) / 2) (0.133
and 0.104 at n = 77), and correlate by 0.58 (p₁(1 − p₂) / √(p₁(1 − p₁) p₂(1 − p₂)), p₁ = 0.5, p₂ = 0.75). The scans
of a protocol are not independent draws of one distribution (each sets its own orientation); what that adds is in
the correction's spread (:mod:`optipose.calibrate.posterior`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import norm

from optipose.errors import ConfigError

__all__ = ["Figure", "Summaries", "read_figures", "from_evaluation", "AXES", "STATS", "PAPER_SCANS"]

AXES = ("roll", "pitch", "yaw")
STATS = ("median", "p75")
PAPER_SCANS = 77  # the paper's protocol: 7 sequences × 11 orientations
_QUANTILES = {"median": 0.5, "p75": 0.75}
_MOST_FAILED = 0.25  # an evaluated subset with more failed registrations is not a summary (a failure counts 10°)
_REQUIRED = ("part", "subset", "axis", "median_deg", "p75_deg")


@dataclass(frozen=True)
class Figure:
    """One measured figure: subset (``S1S3``), axis, stat (``median`` or ``p75``), value (rad) and the scans behind it."""

    subset: str
    axis: str
    stat: str
    value: float
    scans: int

    @property
    def label(self) -> str:
        return f"{self.subset} {self.axis} {self.stat}"


@dataclass(frozen=True)
class Summaries:
    """A hand layout's measured figures of one part, and where they came from (``origin``, for the cell file)."""

    part: str
    figures: tuple[Figure, ...]
    origin: str

    @property
    def logs(self) -> np.ndarray:
        """(figures,) the log of each figure (rad)."""
        return np.log([f.value for f in self.figures])

    def noise(self) -> np.ndarray:
        """(figures, figures) the covariance of the logs from the finite number of scans (module doc)."""
        sd = np.array([_relative_sd(_QUANTILES[f.stat], f.scans) for f in self.figures])
        cov = np.diag(sd**2)
        rho = _quantile_correlation(0.5, 0.75)
        for i, a in enumerate(self.figures):
            for j, b in enumerate(self.figures):
                if i != j and (a.subset, a.axis, a.scans) == (b.subset, b.axis, b.scans):
                    cov[i, j] = rho * sd[i] * sd[j]
        return cov


def _relative_sd(p: float, n: int) -> float:
    """The relative standard deviation of the p quantile of n draws of a half-normal."""
    z = norm.ppf((1 + p) / 2)
    return math.sqrt(p * (1 - p) / n) / (2 * norm.pdf(z) * z)


def _quantile_correlation(p1: float, p2: float) -> float:
    return p1 * (1 - p2) / math.sqrt(p1 * (1 - p1) * p2 * (1 - p2))


def read_figures(path: str | Path, part: str) -> Summaries:
    """The rows of ``part`` in a figures file (module doc) as :class:`Summaries`."""
    import pandas as pd

    from optipose.files import reading

    path = Path(path)
    with reading(path) as p:
        table = pd.read_csv(p, dtype=str, skipinitialspace=True, comment="#")
    table.columns = [str(c).strip() for c in table.columns]
    missing = [c for c in _REQUIRED if c not in table.columns]
    if missing:
        raise ConfigError(f"{path}: no column {', '.join(missing)} (a figures file has {', '.join(_REQUIRED)})")
    rows = table[table["part"].str.strip() == part]
    if rows.empty:
        found = ", ".join(sorted(set(table["part"].dropna().str.strip()))) or "none"
        raise ConfigError(f"{path}: no row of part '{part}' (parts in the file: {found})")
    figures, seen = [], set()
    for index, row in rows.iterrows():
        where = f"{path}: row {int(index) + 2}"  # the header is line 1
        subset, axis = str(row["subset"]).strip(), str(row["axis"]).strip().lower()
        if axis not in AXES:
            raise ConfigError(f"{where}: axis must be roll, pitch or yaw, got {row['axis']!r}")
        if (subset, axis) in seen:
            raise ConfigError(f"{where}: {subset} {axis} appears twice")
        seen.add((subset, axis))
        median, p75 = (_positive(row[c], c, where) for c in ("median_deg", "p75_deg"))
        if p75 < median:
            raise ConfigError(f"{where}: p75_deg {p75:g} is below median_deg {median:g}")
        scans = PAPER_SCANS
        if "scans" in rows.columns and str(row["scans"]).strip() not in ("", "nan"):
            scans = int(_positive(row["scans"], "scans", where))
        figures += [
            Figure(subset, axis, "median", math.radians(median), scans),
            Figure(subset, axis, "p75", math.radians(p75), scans),
        ]
    return Summaries(part, tuple(figures), f"figures {path.name}")


def _positive(text, column: str, where: str) -> float:
    try:
        value = float(str(text).strip())
    except ValueError:
        raise ConfigError(f"{where}: {column} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise ConfigError(f"{where}: {column} must be a finite number, got {text!r}")
    if value <= 0:
        raise ConfigError(f"{where}: {column} must be > 0 (|error| of a real cell), got {value:g}")
    return value


def from_evaluation(result, origin: str) -> Summaries:
    """The figures of an evaluation (:class:`optipose.evaluate.evaluator.EvaluationResult`, e.g. of a folder of
    scans): every subset and axis that is observable, registered in at least 75 % of its scans, and non-zero."""
    figures = []
    for row in result.stats.itertuples(index=False):
        scans = int(row.n_ok + row.n_failed)
        if row.unobservable or not scans or row.n_failed > _MOST_FAILED * scans:
            continue
        if not (np.isfinite(row.median) and np.isfinite(row.p75) and row.median > 0):
            continue
        figures += [
            Figure(str(row.subset), str(row.axis), "median", float(row.median), scans),
            Figure(str(row.subset), str(row.axis), "p75", float(row.p75), scans),
        ]
    if not figures:
        raise ConfigError(f"{origin}: no subset and axis to calibrate on (every one unobservable or failed)")
    return Summaries(str(result.part), tuple(figures), origin)
