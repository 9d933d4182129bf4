"""The study index: one row per trial in ``index.parquet`` and ``index.csv``, each replaced whole.

Every change of a trial's state rewrites both files through a temporary file and ``os.replace``, so a
reader (or a study killed at any instant) sees either the old index or the new one, never half of one.
The trial folders are the truth the index is rebuilt from: a folder ``trials/<key>/`` with its
``trial.toml`` is a complete trial, whatever the index said when the study stopped (it may have been
killed between the folder's rename and the index's write), so a resumed study never runs it again.
"""

from __future__ import annotations

import io
import logging
import shutil
import tomllib
from pathlib import Path

import pandas as pd

from optipose.batch.records import TrialRecord, TrialState
from optipose.batch.results import RESULT_COLUMNS, VERDICT_COLUMNS, trial_results
from optipose.batch.spec import TrialSpec
from optipose.batch.trial import TMP_PREFIX, TRIAL_FILE
from optipose.errors import ConfigError
from optipose.files import atomic_path, reading

__all__ = ["StudyIndex", "read_index", "INDEX_FILE", "INDEX_CSV"]

log = logging.getLogger(__name__)
INDEX_FILE = "index.parquet"
INDEX_CSV = "index.csv"


class StudyIndex:
    """The records of a study's trials by key, in the study's order, and their files."""

    def __init__(self, folder: Path, records: list[TrialRecord]):
        self.folder = Path(folder)
        self.records = {r.key: r for r in records}

    def __getitem__(self, key: str) -> TrialRecord:
        return self.records[key]

    def set(self, record: TrialRecord) -> None:
        self.records[record.key] = record

    def count(self, state: TrialState) -> int:
        return sum(r.state == state for r in self.records.values())

    def frame(self) -> pd.DataFrame:
        rows = [r.row() for r in self.records.values()]
        frame = pd.DataFrame(rows)
        for column in RESULT_COLUMNS:  # the same columns before any trial has finished
            if column not in frame:
                frame[column] = pd.Series(dtype="object" if column.endswith(("subset", "used")) else "float64")
        return frame

    def write(self) -> None:
        """Both files, each replaced whole (see the module doc)."""
        frame = self.frame()
        _replace(self.folder / INDEX_FILE, lambda p: frame.to_parquet(p, index=False))
        _replace(self.folder / INDEX_CSV, lambda p: frame.to_csv(p, index=False))

    @classmethod
    def open(cls, folder: Path, trials: tuple[TrialSpec, ...], resume: bool) -> "StudyIndex":
        """The index of ``trials`` in ``folder``: complete where a trial's folder says so, pending
        otherwise (failed and interrupted trials run again); rows of trials the study file no longer
        names are kept as they were. Leftover temporary folders of killed trials are removed."""
        folder = Path(folder)
        trial_dir = folder / "trials"
        if trial_dir.is_dir():
            for tmp in trial_dir.glob(f"{TMP_PREFIX}*"):
                shutil.rmtree(tmp, ignore_errors=True)
        old = _old_records(folder) if resume else {}
        records = [_from_folder(folder, t) or TrialRecord(t) for t in trials]
        names = {t.key for t in trials}
        records += [_stopped(r) for key, r in old.items() if key not in names]
        return cls(folder, records)


def read_index(folder: str | Path) -> pd.DataFrame:
    """A study's index as written (ConfigError when the folder holds none)."""
    path = Path(folder) / INDEX_FILE
    if not path.is_file():
        raise ConfigError(f"{folder}: no {INDEX_FILE} there (not an optipose study folder)")
    # One open, one read: pyarrow's dataset reader takes the file's size from a stat and reads the footer
    # through a second open, so a study replacing the file in between gave it the new file at the old size.
    with reading(path):
        return pd.read_parquet(io.BytesIO(path.read_bytes()))


def _from_folder(folder: Path, trial: TrialSpec) -> TrialRecord | None:
    """The complete record of a trial whose folder exists (its trial.toml and read-back results)."""
    path = folder / "trials" / trial.key
    if not (path / TRIAL_FILE).is_file():
        return None
    try:
        saved = tomllib.loads((path / TRIAL_FILE).read_text())
        results = trial_results(path, trial)
    except Exception as exc:  # a folder that cannot be read back is not a complete trial: run it again
        log.warning("trial %s: its folder cannot be read back (%s); running it again", trial.key, exc)
        return None
    return TrialRecord(
        trial,
        TrialState.COMPLETE,
        started=saved["started"],
        finished=saved["finished"],
        seconds=float(saved["seconds"]),
        cpu_seconds=float(saved.get("cpu_seconds", "nan")),
        worker=saved["worker"],
        folder=f"trials/{trial.key}",
        results=results,
    )


def _old_records(folder: Path) -> dict[str, TrialRecord]:
    """The rows of an existing index as records (for trials the study file no longer names)."""
    if not (folder / INDEX_FILE).is_file():
        return {}
    params = ("part", "task", "objective", "sensors", "budget", "seed")
    out = {}
    with reading(folder / INDEX_FILE):  # a row it cannot take is damage too, said in one line
        for row in read_index(folder).to_dict("records"):
            trial = TrialSpec(*(int(row[p]) if p in ("sensors", "seed") else str(row[p]) for p in params))
            fields = {
                k: ("" if pd.isna(row[k]) else row[k]) for k in ("error", "started", "finished", "worker", "folder")
            }
            results = {k: row[k] for k in RESULT_COLUMNS + VERDICT_COLUMNS if k in row and not _missing(row[k])}
            seconds = {k: float(row.get(k, float("nan"))) for k in ("seconds", "cpu_seconds")}
            out[row["key"]] = TrialRecord(trial, TrialState(row["state"]), results=results, **seconds, **fields)
    return out


def _stopped(record: TrialRecord) -> TrialRecord:
    return TrialRecord(record.trial) if record.state == TrialState.RUNNING else record


def _missing(value) -> bool:
    try:
        return bool(pd.isna(value))
    except (TypeError, ValueError):
        return False


def _replace(path: Path, write) -> None:
    with atomic_path(path) as tmp:
        write(tmp)
