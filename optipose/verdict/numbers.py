"""The verdict's numbers, written once for the terminal, the report and the tables: angles in millidegrees
(:func:`mdeg`, :func:`mdeg_text`, :func:`mdeg_compact`, :func:`mdeg_column`, :func:`sig_mdeg`, :func:`interval_cell`,
:func:`one_cell_cell`), ratios with their interval (:func:`ratio_cell`), a pose as XYZ + RPY (:func:`xyz_rpy_text`).
:mod:`optipose.verdict.words` writes its lines with them and gives them under its own name too."""

from __future__ import annotations

import math

import numpy as np

from optipose.evaluate.assignment import not_measured
from optipose.transforms import xyz_rpy
from optipose.verdict.confidence import Interval

__all__ = [
    "mdeg",
    "mdeg_text",
    "mdeg_compact",
    "mdeg_column",
    "sig_mdeg",
    "interval_cell",
    "one_cell_cell",
    "ratio_cell",
    "xyz_rpy_text",
]


def mdeg(rad: float) -> float:
    """Radians in millidegrees, the unit every table and line shows angles in."""
    return 1e3 * float(np.rad2deg(rad))


def mdeg_text(rad: float, decimals: int = 3, signed: bool = False, missing: str | None = None) -> str:
    """``0.250``: radians as millidegrees to ``decimals`` places (``+0.25`` with ``signed``); ``missing`` (when
    given) for a value that is not finite."""
    if missing is not None and not np.isfinite(rad):
        return missing
    return f"{mdeg(rad):{'+' if signed else ''}.{decimals}f}"


def mdeg_compact(rad: float) -> str:
    """Radians as millidegrees in at most 6 characters: 3 significant digits."""
    value = mdeg(rad)
    return f"{value:.3g}" if value < 1e4 else f"{value:.0f}"


def mdeg_column(column: str) -> str:
    """A table's ``<name>_deg`` column as it is shown, in millidegrees: ``<name>_mdeg``."""
    return column[: -len("_deg")] + "_mdeg" if column.endswith("_deg") else column


def sig_mdeg(deg: float) -> str:
    """Degrees as millidegrees to 3 significant digits."""
    return f"{1e3 * deg:.3g}"


def interval_cell(interval: Interval, scale: float = 1e3, digits: int = 3) -> str:
    """``0.203 [0.151, 0.262]``: an estimate and its interval (scale 1e3: degrees shown in mdeg; ``digits``
    significant ones)."""
    if not_measured(interval):
        return "not measured"
    # rounded to ``digits`` significant ones but written out (110, not 1.1e+02: a column of mdeg reads at a glance)
    e, lo, hi = (f"{float(f'{scale * x:.{digits}g}'):g}" for x in (interval.estimate, interval.low, interval.high))
    return f"{e} [{lo}, {hi}]" if digits > 2 else f"{e} [{lo}-{hi}]"


def one_cell_cell(error) -> str:
    """``120 [60-400]``: the median one instance of the cell gives on an axis and the interval it falls in
    (an :class:`~optipose.verdict.confidence.AxisError`'s ``one_cell``, mdeg), "not measured" for an axis no draw
    measured, and the expected median alone where no interval is given (a single draw)."""
    if not_measured(error.median_deg):
        return "not measured"
    if not math.isfinite(error.one_cell.low):
        return f"{float(f'{1e3 * error.median_deg.estimate:.2g}'):g}"
    return interval_cell(error.one_cell, digits=2)


def ratio_cell(interval: Interval) -> str:
    """``1.42x [1.21, 1.66]``: a ratio and its interval (an end past 1000 as ``>999``: a few draws' Student
    interval can reach 1e21, which says no more and would push the line past 80 columns)."""
    return f"{_ratio(interval.estimate)}x [{_ratio(interval.low)}, {_ratio(interval.high)}]"


def _ratio(x: float) -> str:
    return ">999" if x >= 1000 else f"{x:.2f}"


def xyz_rpy_text(T_O_S) -> str:
    """``XYZ 1.000 2.000 3.000 mm, RPY 0.000 90.000 0.000 deg``: a pose (4×4, metres) as one line."""
    xyz, rpy = xyz_rpy(T_O_S)
    return "XYZ " + " ".join(f"{v:.3f}" for v in xyz) + " mm, RPY " + " ".join(f"{v:.3f}" for v in rpy) + " deg"
