"""Per-axis orientation errors, their statistics, and which axes a cloud can observe at all.

Errors are ``rpy_estimated − rpy_set`` (radians, signed; statistics use the magnitude, docs/method.md, "The evaluator"). A scan
whose registration failed or did not converge is counted in ``n_failed``, never silently dropped: the
median and 75th percentile (what Table 1 and every score use) count it as an error of ``FAILED_ERROR``
(10°, worse than any measured one), so failures push a subset's order statistics up instead of leaving
its few successes to speak for it; the mean and max describe the registrations that converged, never
averaging a stand-in in. With no failure both are the plain statistics of the measured errors.

Observability: the point-to-plane information matrix ``H`` (6×6, rotation about the cloud's centroid,
then translation) is made unitless by scaling rotation by the cloud's RMS radius. A rotation axis is
*unobservable* when the rotation's own information, the translation left free (the Schur complement
``H_rr − H_rt H_tt⁺ H_tr``, with the translations below the cut left out of ``H_tt⁺``), has that axis
mostly (> ½ of its squared length) in the span of eigenvectors whose eigenvalues are below ``tolerance ×
λ_max`` (λ_max of the whole ``H``); a translation axis when it lies so in the null span of ``H_tt`` (the
rotation held). A flat plate seen
from above leaves yaw and in-plane translation there; a patch of a sphere every rotation, which about the
patch's centroid is a rotation about the sphere's centre plus a translation (the rotation the estimate reports
is the same).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from optipose.evaluate.objective import AXES, StatisticConfig
from optipose.registration.preprocess import scaled_information

__all__ = ["unobservable_axes", "error_stats", "summarize", "STAT_COLUMNS", "FAILED_ERROR"]

STAT_COLUMNS = ("median", "p75", "mean", "max")
FAILED_ERROR = np.deg2rad(
    10.0
)  # rad: a failed registration in the order statistics, worse than any measured error under ±2°


def unobservable_axes(information: np.ndarray, scale: float, tolerance: float = 1e-6) -> np.ndarray:
    """(6,) bool: roll, pitch, yaw, x, y, z the cloud cannot constrain.

    information : (6, 6) ``H`` from :func:`optipose.registration.preprocess.information_matrix`.
    scale : m, a length for the cloud (its RMS radius), making rotation and translation comparable.
    """
    if not np.any(information):
        return np.ones(6, dtype=bool)
    H, _ = scaled_information(information, scale)
    cut = tolerance * np.linalg.eigvalsh(H)[-1]
    out = np.empty(6, dtype=bool)
    w, V = np.linalg.eigh(H[3:, 3:])
    out[3:] = (V[:, w < cut] ** 2).sum(axis=1) > 0.5  # the translations with the rotation held
    free = H[:3, 3:] @ V[:, w > cut]  # the rotation's coupling to the translations the cloud observes
    marginal = H[:3, :3] - free @ np.diag(1.0 / w[w > cut]) @ free.T
    w, V = np.linalg.eigh(0.5 * (marginal + marginal.T))
    out[:3] = (V[:, w < cut] ** 2).sum(axis=1) > 0.5
    return out


def error_stats(abs_errors: np.ndarray, n_failed: int = 0) -> dict[str, float]:
    """Median, 75th percentile, mean and max of (n,) magnitudes (rad) of the converged registrations, the
    median and p75 with ``n_failed`` failures counted as ``FAILED_ERROR`` each; NaN where there is nothing."""
    ranked = np.concatenate([abs_errors, np.full(n_failed, FAILED_ERROR)])
    out = dict.fromkeys(STAT_COLUMNS, float("nan"))
    if len(ranked):
        out |= {"median": float(np.median(ranked)), "p75": float(np.percentile(ranked, 75))}
    if len(abs_errors):
        out |= {"mean": float(np.mean(abs_errors)), "max": float(np.max(abs_errors))}
    return out


def summarize(per_scan: pd.DataFrame, cfg: StatisticConfig | None = None) -> pd.DataFrame:
    """Statistics per subset and axis from the per-scan table of :mod:`optipose.evaluate.evaluator`.

    per_scan : columns ``subset``, ``ok``, ``err_roll``/``err_pitch``/``err_yaw`` (rad) and
        ``unobservable_roll``/... (bool).
    Returns one row per (subset, axis): median, p75 (rad, every scan, a failure as ``FAILED_ERROR``),
    mean, max (rad, the converged scans), n_ok, n_failed, unobservable (True when the axis is unobservable
    in at least half of the scans).
    """
    rows = []
    for subset, group in per_scan.groupby("subset", sort=False):
        ok = group["ok"].to_numpy(bool)
        for axis in AXES:
            stats = error_stats(np.abs(group.loc[ok, f"err_{axis}"].to_numpy()), int((~ok).sum()))
            blind = group[f"unobservable_{axis}"].to_numpy(bool)
            rows.append(
                {
                    "subset": subset,
                    "axis": axis,
                    **stats,
                    "n_ok": int(ok.sum()),
                    "n_failed": int((~ok).sum()),
                    "unobservable": bool(blind.mean() >= 0.5) if len(blind) else True,
                }
            )
    return pd.DataFrame(rows)
