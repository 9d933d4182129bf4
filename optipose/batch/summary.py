"""A study's table per part and setting: its trials grouped over seeds (``optipose study DIR``).

:func:`summary_frame` groups the index by part, task, objective, budget and k; per group: how many
trials, complete and failed, and over the complete ones the median and worst score and the median of
each axis's median error (degrees); for searches also the median of hand over found and how many found
layouts were no worse than the hand-placed ones on every axis.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from optipose.evaluate.objective import AXES

__all__ = ["summary_frame", "read_study_index", "SETTING"]

SETTING = ["part", "task", "objective", "budget", "sensors"]


def read_study_index(folder: str | Path) -> pd.DataFrame:
    """A study folder's index (one row per trial; see :mod:`optipose.batch.results` for the columns)."""
    from optipose.batch.index import read_index

    return read_index(folder)


def summary_frame(index: pd.DataFrame) -> pd.DataFrame:
    """One row per part and setting (see the module doc); parts and objectives by their short names."""
    rows = []
    for setting, group in index.groupby(SETTING, sort=False, dropna=False):
        done = group[group.state == "complete"]
        row = dict(zip(SETTING, setting))
        row |= {
            "part": _short(row["part"]),
            "objective": _short(row["objective"]),
            "trials": len(group),
            "complete": len(done),
            "failed": int((group.state == "failed").sum()),
            "seeds": ",".join(str(s) for s in sorted(group.seed.unique())),
        }
        scores = pd.to_numeric(done.get("score_deg"), errors="coerce") if len(done) else pd.Series(dtype=float)
        row |= {"score_median_deg": scores.median(), "score_worst_deg": scores.max()}
        for axis in AXES:
            column = f"{axis}_median_deg"
            row[column] = (
                pd.to_numeric(done[column], errors="coerce").median() if column in done and len(done) else float("nan")
            )
        if "ratio" in done and done["ratio"].notna().any():
            row |= {
                "ratio_median": pd.to_numeric(done["ratio"], errors="coerce").median(),
                "no_worse": f"{int(done['no_worse'].fillna(False).astype(bool).sum())}/{len(done)}",
            }
        rows.append(row)
    return pd.DataFrame(rows)


def _short(spec) -> str:
    text = str(spec)
    return Path(text).stem if ("/" in text or Path(text).suffix) else text
