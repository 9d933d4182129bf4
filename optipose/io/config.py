"""A result folder's ``config.toml`` read back once, as a frozen :class:`RunConfig`.

:func:`optipose.io.folders.write_config` writes the file (its format is unchanged by this record); every
reader — :func:`optipose.io.load_result`, the reports' provenance, ``search --resume`` — takes its values
from the record's fields instead of the parsed table. A field is None (or empty) where the file has no such
key: folders written before a key existed still load, and a caller that needs the key says so itself (the
resume names a missing one, as it did when it read the table). The values are kept as TOML gave them (no
conversion here), so a damaged file fails where its value is used, with the message it always had there.
``table`` keeps the parsed file whole, for nothing but showing the config as written.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["RunConfig", "run_config", "given"]


@dataclass(frozen=True)
class RunConfig:
    """What a result folder's ``config.toml`` says produced it (see the module doc).

    command : evaluate | search | robustness | batch; format : the folder layout's version
    (``RESULT_FORMAT``), None before it was recorded; part_name, part_source : the part and the file it was
    loaded from, part_units the ``--units`` it was loaded with (None: auto); seed : the run's seed; validation_seed : a search's held-out seed; budget : a search's
    budget; search : the search's settings as written, in file order: ``sensors`` and one sub-table per section of
    ``SearchConfig`` (``surrogate``, ``constraints`` …), or in a folder written before the sections, its flat
    keys (``global_evals``, ``verdict_draws`` …; :func:`optipose.search.config.search_preset` reads both);
    objective : the resolved objective's table (:func:`~optipose.evaluate.objective.objective_from_dict`
    reads it), objective_name its name, objective_file the objective file as written; layout : an
    evaluation's layout table (:func:`~optipose.model.layout.layout_from_table` reads it), layout_name and
    layout_source its name and where it came from; layouts, layout_sources : a robustness run's layout
    names and the files given; timings : an evaluation's
    seconds per phase; failed_registrations : an evaluation's count; versions : package → version.
    """

    command: str | None = None
    format: int | None = None
    part_name: str | None = None
    part_source: str | None = None
    part_units: str | None = None
    seed: int | None = None
    validation_seed: int | None = None
    budget: str | None = None
    search: dict | None = field(default=None, repr=False)
    objective: dict = field(default_factory=dict, repr=False)
    objective_name: str | None = None
    objective_file: str | None = field(default=None, repr=False)
    layout: dict | None = field(default=None, repr=False)
    layout_name: str | None = None
    layout_source: str | None = None
    layouts: tuple[str, ...] = ()
    layout_sources: tuple[str, ...] = ()
    timings: dict = field(default_factory=dict, repr=False)
    failed_registrations: int | None = None
    versions: dict = field(default_factory=dict, repr=False)
    table: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def sensors(self) -> tuple:
        """A search's sensor counts (``[search] sensors``), () when not written."""
        return tuple((self.search or {}).get("sensors") or ())

    @property
    def search_settings(self) -> tuple[tuple[str, object], ...]:
        """The search's settings one value a row, in file order: a section's as ``section.key`` (a folder
        written before the sections: its flat keys as they are); () when not written."""
        return tuple(
            (f"{key}.{name}", v) if isinstance(value, dict) else (key, value)
            for key, value in (self.search or {}).items()
            for name, v in (value.items() if isinstance(value, dict) else ((None, value),))
        )

    @property
    def part(self) -> str | None:
        """Where the part can be loaded from again: its source file, else its name."""
        return self.part_source or self.part_name

    @property
    def cell_name(self) -> str:
        """The name of the cell the run was evaluated in (its sources are in ``[objective.cell]``; ideal without one)."""
        return str((self.objective or {}).get("cell", {}).get("name", "ideal"))


def run_config(table: dict) -> RunConfig:
    """The :class:`RunConfig` of a parsed ``config.toml`` (keys it lacks left at their defaults)."""
    part, layout, objective = _table(table.get("part")), _table(table.get("layout")), _table(table.get("objective"))
    return RunConfig(
        command=table.get("command"),
        format=table.get("format"),
        part_name=part.get("name"),
        part_source=part.get("source"),
        part_units=part.get("units"),
        seed=table.get("seed"),
        validation_seed=table.get("validation_seed"),
        budget=table.get("budget"),
        search=table.get("search"),
        objective=objective,
        objective_name=objective.get("name"),
        objective_file=table.get("objective_file"),
        layout=table.get("layout"),
        layout_name=layout.get("name"),
        layout_source=layout.get("source"),
        layouts=_names(table.get("layouts")),
        layout_sources=_names(table.get("layout_sources")),
        timings=_table(table.get("timings_s")),
        failed_registrations=table.get("failed_registrations"),
        versions=_table(table.get("versions")),
        table=table,
    )


def given(value, default):
    """A field of a :class:`RunConfig`, or ``default`` where the file has no such key (None)."""
    return default if value is None else value


def _table(value) -> dict:
    """A sub-table of the file, {} where there is none (or the key holds something else)."""
    return value if isinstance(value, dict) else {}


def _names(value) -> tuple:
    """A list of the file as a tuple, () where there is none."""
    return tuple(value) if isinstance(value, list) else ()
