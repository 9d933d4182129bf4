"""A finished trial's per-axis results, read back from its folder as a report would read them.

Evaluate and search folders go through :func:`optipose.io.load_result`. The columns, in degrees:

- ``sensors_used`` (the choice's sensors), ``score_deg``, and per axis ``<axis>_median_deg``,
  ``<axis>_p75_deg``, ``<axis>_subset``: the trial's choice of k sensors (evaluate: the hand layout's
  Table 1 row k; search: the found layout on the held-out validation);
- search only: ``hand_score_deg``, ``hand_<axis>_median_deg``, ``hand_<axis>_p75_deg`` (the hand layout's
  k sensors on the same validation), ``ratio`` (hand score over found) and ``no_worse`` (found no worse
  on every axis statistic).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from optipose.batch.spec import TrialSpec
from optipose.evaluate.objective import AXES

__all__ = ["trial_results", "RESULT_COLUMNS", "VERDICT_COLUMNS"]

RESULT_COLUMNS = ["sensors_used", "score_deg"] + [f"{a}_{s}" for a in AXES for s in ("median_deg", "p75_deg", "subset")]
VERDICT_COLUMNS = [
    "hand_score_deg",
    "ratio",
    "no_worse",
    "band_ratio",
    "band_no_worse",
]  # a search's, against the hand layout


def trial_results(folder: str | Path, trial: TrialSpec) -> dict:
    """The per-axis columns of a complete trial's folder (see the module doc)."""
    folder = Path(folder)
    from optipose.io import load_result

    result = load_result(folder)
    if trial.task == "evaluate":
        return _choice_columns(result.table[trial.sensors - 1])
    verdict = {v.k: v for v in result.verdicts()}.get(trial.sensors)
    if verdict is None:  # no hand layout to compare with (a bare mesh): the found layout alone
        return _choice_columns(result.validation.found[trial.sensors])
    baseline = {
        f"hand_{key}": value for key, value in _choice_columns(verdict.reference).items() if not key.endswith("subset")
    }
    baseline.pop("hand_sensors_used")
    return {
        **_choice_columns(verdict.found),
        **baseline,
        "ratio": verdict.ratio,
        "no_worse": bool(verdict.no_worse),
    }


def _choice_columns(choice) -> dict:
    out = {"sensors_used": choice.name, "score_deg": float(np.rad2deg(choice.score))}
    for a in choice.axes:
        out |= {
            f"{a.axis}_median_deg": float(np.rad2deg(a.median)),
            f"{a.axis}_p75_deg": float(np.rad2deg(a.p75)),
            f"{a.axis}_subset": a.label,
        }
    return out
