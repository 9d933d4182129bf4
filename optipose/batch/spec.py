"""Study files: a grid (or a list) of trials, checked whole before anything runs.

A study file is TOML::

    name = "reference"                 # the study's folder name (default: the file's stem)
    description = "..."

    [grid]                             # every combination of these is a trial
    parts = ["part_a", "parts/*.stl"]  # shipped names, part/mesh files or globs (relative to this file)
    tasks = ["search"]                 # search | evaluate
    objectives = ["paper"]             # shipped names or TOML paths (default: paper)
    sensors = [1, 2, 3]                # k, the sensor count of each trial
    budgets = ["default"]              # search budgets (quick | default | thorough); other tasks have none
    seeds = [0]

    [[trials]]                         # explicit trials, on top of the grid or instead of it
    part = "part_b"
    task = "evaluate"
    sensors = 2                        # the other keys as in [grid], one value each, same defaults

A key that is not one of these, a value of the wrong type, an empty axis, an unknown part, objective,
task or budget raise :class:`~optipose.errors.ConfigError` naming the key, so a bad study stops before
its folder exists.
"""

from __future__ import annotations

import glob
import itertools
import re
from dataclasses import dataclass
from pathlib import Path

from optipose.errors import ConfigError, read_toml

__all__ = ["TASKS", "TrialSpec", "StudySpec", "load_study_spec", "study_from_table"]

TASKS = ("search", "evaluate")
_DEFAULT_OBJECTIVE = {"search": "paper", "evaluate": "paper"}
_TOP_KEYS = {"name", "description", "grid", "trials"}
# axis in [grid] -> (key in [[trials]], element type, default values or None: required)
_AXES = {
    "parts": ("part", str, None),
    "tasks": ("task", str, ("search",)),
    "objectives": ("objective", str, ()),  # () : the task's default
    "sensors": ("sensors", int, (1, 2, 3)),
    "budgets": ("budget", str, ("default",)),
    "seeds": ("seed", int, (0,)),
}


@dataclass(frozen=True)
class TrialSpec:
    """One trial's parameters. ``part`` and ``objective`` are what the task loads (a shipped name or an
    absolute path); ``budget`` is empty for tasks other than ``search``."""

    part: str
    task: str
    objective: str
    sensors: int
    budget: str
    seed: int

    @property
    def key(self) -> str:
        """The trial's name, unique in a study: its folder under ``trials/`` and its row in the index."""
        parts = [_label(self.part), self.task, _label(self.objective), f"k{self.sensors}"]
        parts += [self.budget] if self.budget else []
        return _safe("-".join([*parts, f"s{self.seed}"]))

    def params(self) -> dict:
        return {
            "part": self.part,
            "task": self.task,
            "objective": self.objective,
            "sensors": self.sensors,
            "budget": self.budget,
            "seed": self.seed,
        }


@dataclass(frozen=True)
class StudySpec:
    """A study: its name, the file it came from (its text is saved beside the results) and its trials."""

    name: str
    description: str
    source: str
    text: str
    trials: tuple[TrialSpec, ...]


def load_study_spec(path: str | Path) -> StudySpec:
    """The study in a TOML file; paths in it are relative to the file."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"study file not found: {path}")
    table, text = read_toml(path, "study file")
    return study_from_table(table, where=str(path), base=path.resolve().parent, text=text, default_name=path.stem)


def study_from_table(
    table: dict, where: str = "study", base: Path = Path("."), text: str = "", default_name: str = "study"
) -> StudySpec:
    """A :class:`StudySpec` from a parsed study file; see the module doc."""
    _check_keys(table, _TOP_KEYS, where)
    name = _string(table.get("name", default_name), f"{where}: name")
    description = _string(table.get("description", ""), f"{where}: description")
    if not re.fullmatch(r"[A-Za-z0-9._-]+", name):
        raise ConfigError(f"{where}: name '{name}' may hold only letters, digits, '.', '_' and '-' (it names a folder)")
    trials: list[TrialSpec] = []
    if "grid" in table:
        trials += _grid(_table(table["grid"], f"{where}: grid"), where, base)
    if "trials" in table:
        entries = table["trials"]
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            raise ConfigError(f"{where}: trials must be an array of tables ([[trials]])")
        for i, entry in enumerate(entries):
            trials += _explicit(entry, f"{where}: trials[{i}]", base)
    trials = list(dict.fromkeys(trials))  # a trial named twice runs once
    if not trials:
        raise ConfigError(f"{where}: the study has no trials (give a [grid] with parts, or [[trials]])")
    keys = [t.key for t in trials]
    clash = next((k for k in keys if keys.count(k) > 1), None)
    if clash:
        raise ConfigError(
            f"{where}: two different trials share the name '{clash}' (two part or objective files of one stem?)"
        )
    return StudySpec(name, description, where, text, tuple(trials))


def _grid(grid: dict, where: str, base: Path) -> list[TrialSpec]:
    _check_keys(grid, set(_AXES), f"{where}: grid")
    if "parts" not in grid:
        raise ConfigError(f"{where}: grid needs 'parts' (shipped names, files or globs)")
    axes = {axis: _values(grid, axis, f"{where}: grid.{axis}") for axis in _AXES}
    return _combine(axes, where, base)


def _explicit(entry: dict, where: str, base: Path) -> list[TrialSpec]:
    singular = {key: axis for axis, (key, _, _) in _AXES.items()}
    _check_keys(entry, set(singular), where)
    if "part" not in entry:
        raise ConfigError(f"{where}: a trial needs 'part'")
    axes = {}
    for key, axis in singular.items():
        _, kind, default = _AXES[axis]
        axes[axis] = [_element(entry[key], kind, f"{where}.{key}")] if key in entry else list(default or ())
    return _combine(axes, where, base)


def _check_task(task: str, where: str) -> None:
    """A task name this version runs; the retired ``robustness`` task is one line saying what to use instead."""
    if task == "robustness":
        raise ConfigError(
            f"{where}: task 'robustness' was retired with the band of conditions: evaluate the layouts in a "
            "cell with ranges (an evaluate task per seed with a cell's objective, or optipose robustness PART --cell NAME)"
        )
    if task not in TASKS:
        raise ConfigError(f"{where}: unknown task '{task}' (use {', '.join(TASKS)})")


def _combine(axes: dict, where: str, base: Path) -> list[TrialSpec]:
    """Every combination of the axes; parts and objectives resolved, the budget only for searches."""
    from optipose.search.budgets import BUDGETS

    for task in axes["tasks"]:
        _check_task(task, where)
    for budget in axes["budgets"]:
        if budget not in BUDGETS:
            raise ConfigError(f"{where}: unknown budget '{budget}' (use {', '.join(BUDGETS)})")
    for k in axes["sensors"]:
        if not 1 <= k <= 6:
            raise ConfigError(f"{where}: sensors must be between 1 and 6, got {k}")
    parts = [p for entry in axes["parts"] for p in _resolve_part(entry, where, base)]
    trials = []
    for part, task, k, seed in itertools.product(parts, axes["tasks"], axes["sensors"], axes["seeds"]):
        objectives = axes["objectives"] or [_DEFAULT_OBJECTIVE[task]]
        budgets = axes["budgets"] if task == "search" else [""]
        for objective, budget in itertools.product(objectives, budgets):
            trials.append(TrialSpec(part, task, _resolve_objective(objective, where, base), int(k), budget, int(seed)))
    return trials


def _resolve_part(entry: str, where: str, base: Path) -> list[str]:
    """A shipped name as it is; files (or a glob's matches) as absolute paths, so any worker finds them."""
    from optipose.model.part import list_parts

    if entry in list_parts():
        return [entry]
    if any(c in entry for c in "*?["):
        matches = sorted(glob.glob(str(base / entry), recursive=True))
        if not matches:
            raise ConfigError(f"{where}: parts: '{entry}' matches no file (relative to {base})")
        return [str(Path(m).resolve()) for m in matches]
    path = base / entry
    if path.is_file():
        return [str(path.resolve())]
    shipped = ", ".join(list_parts())
    raise ConfigError(
        f"{where}: unknown part '{entry}' (shipped parts: {shipped}; or a part .toml, a mesh file or a glob)"
    )


def _resolve_objective(entry: str, where: str, base: Path) -> str:
    """A shipped objective name as it is, a file as an absolute path; loaded once here to check it."""
    from optipose.evaluate.objective import load_objective

    path = base / entry
    resolved = str(path.resolve()) if Path(entry).suffix and path.is_file() else entry
    try:
        load_objective(resolved)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    return resolved


def _values(table: dict, axis: str, where: str) -> list:
    _, kind, default = _AXES[axis]
    if axis not in table:
        return list(default or ())
    value = table[axis]
    values = value if isinstance(value, list) else [value]
    if not values:
        raise ConfigError(f"{where} is empty (give at least one value)")
    return [_element(v, kind, where) for v in values]


def _element(value, kind: type, where: str):
    if isinstance(value, bool) or not isinstance(value, kind):
        raise ConfigError(
            f"{where}: expected {'an integer' if kind is int else 'a string'}, got {value!r} ({type(value).__name__})"
        )
    return value


def _check_keys(table: dict, known: set, where: str) -> None:
    unknown = sorted(set(table) - known)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)} (known: {', '.join(sorted(known))})")


def _table(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a table, got {type(value).__name__}")
    return value


def _string(value, where: str) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{where}: expected a string, got {value!r} ({type(value).__name__})")
    return value


def _label(spec: str) -> str:
    """A part or objective's short name: a shipped name, or a file's stem."""
    return Path(spec).stem if ("/" in spec or "\\" in spec or Path(spec).suffix) else spec


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text)
