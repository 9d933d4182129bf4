"""How to search: :class:`SearchConfig`, one typed section per part of the search.

Every stage of :mod:`optipose.search` reads its settings from one frozen config, in sections: ``surrogate``
(the NLopt search on the surrogate), ``constraints`` (what a layout must keep to), ``selection`` (the ICP
selection, polish and confirmation), ``validation`` (the held-out seed's protocol)
and ``verdict`` (the verdict's own record, :class:`optipose.verdict.rules.VerdictConfig`). The budgets
(:mod:`optipose.search.budgets`) are presets of these sections. A result folder saves the config
(``config.toml``, table ``search``, one sub-table a section: :func:`search_table`) so ``--resume`` continues
with the same one; :func:`search_preset` reads such a table back, and the flat ``[search]`` keys of the folders
written before the sections (:data:`FLAT_KEYS`), and a user's ``--search-config`` in either form.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace

from optipose.errors import ConfigError
from optipose.evaluate.objective import BAND_RETIRED
from optipose.model.collision import DEFAULT_MARGIN
from optipose.verdict.rules import VerdictConfig

__all__ = [
    "SearchConfig",
    "SurrogateConfig",
    "Constraints",
    "SelectionConfig",
    "ValidationConfig",
    "Preset",
    "SECTIONS",
    "FLAT_KEYS",
    "search_preset",
    "unknown_keys",
    "saved_table",
    "search_table",
    "algorithm_code",
]


@dataclass(frozen=True)
class SurrogateConfig:
    """The NLopt search on the surrogate (:mod:`optipose.search.surrogate_search`) and how it scores a layout
    against the hand one."""

    global_algorithm: str = "GN_DIRECT_L"  # best of five on all four problems: benchmarks/README.md
    local_algorithm: str = "LN_BOBYQA"
    global_evals: int = 300  # per greedy stage
    local_evals: int = 120  # per local polish
    joint_evals: int = 200  # per joint polish (k >= 2)
    max_time: float = 0.0  # s, a clock on the surrogate search (0: none; its evaluations end it)
    strategy: str = "both"  # greedy | joint | both
    random_starts: int = 8  # extra random start points scored before each greedy stage
    # before each greedy stage: score this many space-filling (scrambled Sobol) poses of the new sensor on the
    # surrogate, and polish the best screen_starts distinct ones locally (screen_evals each). DIRECT-L
    # refines around one basin; the screen finds the others, which the ICP selection then compares (quick,
    # which has none, takes the surrogate's best of them)
    screen_samples: int = 0
    screen_starts: int = 6
    screen_evals: int = 30
    # the hand-anchored candidates' found sensors moved by this many local surrogate evaluations with the
    # kept hand sensors fixed, before the selection evaluates them (0: taken as found; search/candidates.py)
    anchor_evals: int = 0
    # a layout is asked to beat the hand-placed one on every axis, not just on the sum: each axis whose
    # predicted score exceeds hand_margin x the hand-placed k-subset's adds hand_weight x the excess
    # (0 turns it off; < 1 leaves room for the surrogate's error)
    hand_margin: float = 0.5
    hand_weight: float = 5.0

    def __post_init__(self) -> None:
        if self.strategy not in ("greedy", "joint", "both"):
            raise ConfigError(f"search strategy must be greedy, joint or both, not '{self.strategy}'")
        for name in (self.global_algorithm, self.local_algorithm):
            algorithm_code(name)  # raises ConfigError for an unknown name


@dataclass(frozen=True)
class Constraints:
    """What every layout the search scores keeps to (:class:`optipose.search.problem.SurrogateProblem`)."""

    min_points: int = 2000
    clearance: float = DEFAULT_MARGIN  # m, head to swept part / keep-outs
    head_gap: float = 0.0  # m, head to head
    margin: float = 0.005  # m, how far outside the part's box the aim point may go
    alpha_max_deg: float = 60.0
    # the laser line may turn at most this far from across the motion (the angle between the line and the
    # plane normal to the scan axis): a line turned toward the motion re-scans its own strip, covers less
    # of the part across the motion, and fools the surrogate (docs/method.md, "Constraints"); 90 turns the
    # constraint off
    line_skew_max_deg: float = 60.0


@dataclass(frozen=True)
class SelectionConfig:
    """The ICP stages after the surrogate (:mod:`optipose.search.select`): the selection, the polish of a
    finalist and its confirmation on the full protocol."""

    candidates: int = 3  # per k, candidates re-ranked by ICP on a reduced protocol (0: skip)
    time: float = 0.0  # s, a clock on the selection stage (0: none; its candidates end it)
    # the ICP polish of a finalist that is not yet no worse than the hand layout on every axis (search/polish.py)
    polish_algorithm: str = "LN_COBYLA"
    polish_evals: int = 0  # evaluations for k = 1 (half for larger k); 0: no polish
    polish_time: float = 0.0  # s per k, a clock on the polish (0: none; its evaluations end it)
    polish_margin: float = 0.9  # aim below 0.9 x the hand layout's per-axis statistics
    polish_weight: float = 5.0  # cost per unit of per-axis excess over polish_margin x the hand's, on top of the sum
    polish_step: float = 0.03  # initial step in [0, 1] units (about 2 mm of aim point, 4 deg of view)
    # a finalist that beats the hand layout on the reduced protocol by less than polish_margin on some axis
    # or clear_ratio in sum, or that a polish produced, is confirmed: the best confirm_candidates of that k
    # and the one closest to dominance re-run the full protocol (selection seed) and the best there is
    # kept (0: no confirmation)
    confirm_candidates: int = 0
    clear_ratio: float = 0.4
    scans: int = 0  # of the reduced protocol's scans, this many, drawn by the selection's seed (0: all)

    def __post_init__(self) -> None:
        algorithm_code(self.polish_algorithm)  # raises ConfigError for an unknown name
        if self.scans < 0:
            raise ConfigError(f"search selection scans must be 0 (all) or more, not {self.scans}")


@dataclass(frozen=True)
class ValidationConfig:
    """The validation on the held-out seed (:mod:`optipose.search.validate`)."""

    protocol: str = "full"  # the held-out seed's protocol: full (the objective's) | reduced (end angles only)
    scans: int = 0  # of that protocol's scans, this many, drawn by the held-out seed (0: all)

    def __post_init__(self) -> None:
        if self.protocol not in ("full", "reduced"):
            raise ConfigError(f"search validation must be full or reduced, not '{self.protocol}'")
        if self.scans < 0:
            raise ConfigError(f"search validation scans must be 0 (all) or more, not {self.scans}")


SECTIONS = {
    "surrogate": SurrogateConfig,
    "constraints": Constraints,
    "selection": SelectionConfig,
    "validation": ValidationConfig,
    "verdict": VerdictConfig,
}  # SearchConfig's sections, in the order a result folder's config.toml writes them


@dataclass(frozen=True)
class SearchConfig:
    """How to search: the sensor counts to place and one section per part of the search (see the module doc).
    Budgets (``quick``, ``default``, ``thorough``: :mod:`optipose.search.budgets`) fill in the numbers."""

    sensors: tuple[int, ...] = (1, 2, 3)
    # s from the search's start, the user's clock on the whole search (``--max-time``; 0: none): every stage ends by
    # it as well as by its own counts, and the answer says what it cut (a seed's own answer has no clock)
    time_limit: float = 0.0
    surrogate: SurrogateConfig = field(default_factory=SurrogateConfig)
    constraints: Constraints = field(default_factory=Constraints)
    selection: SelectionConfig = field(default_factory=SelectionConfig)
    validation: ValidationConfig = field(default_factory=ValidationConfig)
    verdict: VerdictConfig = field(default_factory=VerdictConfig)

    def __post_init__(self) -> None:
        if not self.sensors or min(self.sensors) < 1 or max(self.sensors) > 6:
            raise ConfigError("--sensors: give sensor counts between 1 and 6, e.g. 1,2,3")
        if not self.time_limit >= 0:
            raise ConfigError(f"--max-time: give seconds >= 0 (0: no clock), not {self.time_limit}")


# the flat [search] keys of the result folders written before the sections, and of a --search-config: each
# names one field of one section (most by the field's own name; the others here)
_RENAMED = {
    "select_candidates": ("selection", "candidates"),
    "select_time": ("selection", "time"),
    "select_scans": ("selection", "scans"),
    "validation": ("validation", "protocol"),
    "validation_scans": ("validation", "scans"),
    "verdict_draws": ("verdict", "draws"),
    "verdict_time": ("verdict", "time"),
    "answer_time": ("verdict", "answer_time"),
    "verdict_scans": ("verdict", "scans"),
    "verdict_tolerance": ("verdict", "tolerance"),
    "verdict_failures": ("verdict", "failures"),
    "verdict_confidence": ("verdict", "confidence"),
    "verdict_kinds": ("verdict", "kinds"),
    "verdict_kinds_draws": ("verdict", "kinds_draws"),
}
FLAT_KEYS: dict[str, tuple[str, str]] = {
    **{f.name: (name, f.name) for name in ("surrogate", "constraints") for f in fields(SECTIONS[name])},
    **{f.name: ("selection", f.name) for f in fields(SelectionConfig) if f.name not in ("candidates", "time", "scans")},
    **_RENAMED,
}  # flat key → (section, field), for every field of every section


@dataclass(frozen=True)
class Preset:
    """Values set on top of a config: a budget, its adjustment in a real cell, a user's
    ``[search]`` table. Per section, the fields it sets (the others are left as they are); ``sensors``
    when it sets the sensor counts."""

    sensors: tuple[int, ...] | None = None
    time_limit: float | None = None
    surrogate: dict = field(default_factory=dict)
    constraints: dict = field(default_factory=dict)
    selection: dict = field(default_factory=dict)
    validation: dict = field(default_factory=dict)
    verdict: dict = field(default_factory=dict)

    def apply(self, config: SearchConfig) -> SearchConfig:
        """``config`` with this preset's values in place of its own."""
        sections = {
            name: replace(getattr(config, name), **values) for name in SECTIONS if (values := getattr(self, name))
        }
        top = {name: v for name in ("sensors", "time_limit") if (v := getattr(self, name)) is not None}
        return replace(config, **sections, **top)


def saved_table(table: dict) -> dict:
    """A result folder's ``[search]`` table as this version reads it: the band's key of a folder written before the
    band was retired (``band = ""``, ``validation.band_objective = ""``: no check asked for) left out; a band that
    was asked for stays, and :func:`unknown_keys` refuses it."""
    out = {k: v for k, v in table.items() if not (k in ("band", "band_objective") and v == "")}
    validation = out.get("validation")
    if isinstance(validation, dict) and validation.get("band_objective") == "":
        out["validation"] = {k: v for k, v in validation.items() if k != "band_objective"}
    return out


def unknown_keys(table: dict) -> list[str]:
    """The keys of a ``[search]`` table that name no setting (a section's as ``section.key``), sorted; the band's
    key (``band_objective``, flat ``band``), retired, is one ConfigError saying what to use instead."""
    validation = table.get("validation")
    if (
        "band" in table
        or "band_objective" in table
        or (isinstance(validation, dict) and "band_objective" in validation)
    ):
        raise ConfigError(f"search setting band_objective: {BAND_RETIRED}")
    unknown = []
    for key, value in table.items():
        if key in SECTIONS and isinstance(value, dict):  # a section (``validation`` is a flat key too)
            known = {f.name for f in fields(SECTIONS[key])}
            unknown += [f"{key}.{name}" for name in value if name not in known]
        elif key not in FLAT_KEYS and key not in ("sensors", "time_limit"):
            unknown.append(key)
    return sorted(unknown)


def search_preset(table: dict) -> Preset:
    """The :class:`Preset` of a ``[search]`` table: sections as sub-tables (``[search.surrogate]`` …), the
    flat keys of :data:`FLAT_KEYS`, or both; ``sensors`` and ``time_limit`` at its top. A key it does not know
    (:func:`unknown_keys`, which callers check first to say whose table it is), or a field given twice, is a
    ConfigError."""
    if unknown := unknown_keys(table):
        raise ConfigError(f"unknown search setting(s) {', '.join(unknown)}")
    values: dict[str, dict] = {name: {} for name in SECTIONS}
    twice = []
    for key, value in table.items():
        if key in SECTIONS and isinstance(value, dict):
            given = [(key, name, v) for name, v in value.items()]
        elif key in FLAT_KEYS:
            given = [(*FLAT_KEYS[key], value)]
        else:  # sensors, time_limit
            continue
        for section, name, v in given:
            twice += [f"{section}.{name}"] if name in values[section] else []
            values[section][name] = v
    if twice:
        raise ConfigError(
            f"search setting(s) {', '.join(sorted(set(twice)))} given twice (as a flat key and in a section)"
        )
    return Preset(
        tuple(table["sensors"]) if "sensors" in table else None,
        float(table["time_limit"]) if "time_limit" in table else None,
        **values,
    )


def search_table(config: SearchConfig) -> dict:
    """The ``[search]`` table of a result folder's ``config.toml``: ``sensors`` and one sub-table a section."""
    return asdict(config)


def algorithm_code(name: str) -> int:
    """NLopt's code of a derivative-free algorithm named like ``GN_DIRECT_L``; ConfigError otherwise."""
    import nlopt

    value = getattr(nlopt, name, None)
    if not isinstance(value, int) or not name[:3] in ("GN_", "LN_", "GD_", "LD_", "G_M", "AUG"):
        raise ConfigError(f"unknown NLopt algorithm '{name}' (e.g. GN_CRS2_LM, GN_DIRECT_L, GN_ISRES, LN_BOBYQA)")
    if name.startswith(("GD_", "LD_")):
        raise ConfigError(f"NLopt algorithm '{name}' needs gradients; the objective has none (use GN_*/LN_*)")
    return value
