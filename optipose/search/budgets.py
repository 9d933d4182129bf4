"""The budgets: named presets of :class:`~optipose.search.config.SearchConfig`'s sections.

A budget (``quick``, ``default``, ``thorough``: :data:`BUDGETS`) sets some fields of some sections; in a real cell
(:data:`IN_A_CELL`) a budget is adjusted by a preset of its own; a user's ``[search]`` table goes last
(:func:`config_from_budget`).

A budget is work, not seconds: every stage ends by its counts (evaluations, candidates, draws), so a seed gives the
same layouts, draws and verdict lines on any machine at any load. No budget sets a clock; a user may
(``--max-time``, or a section's ``max_time`` / ``time``), and the answer then says what the clock cut.
"""

from __future__ import annotations

from optipose.errors import ConfigError
from optipose.search.config import Preset, SearchConfig

__all__ = ["BUDGETS", "IN_A_CELL", "config_from_budget"]


BUDGETS: dict[str, Preset] = {
    # quick: greedy only, so the layouts are nested and one evaluation validates k = 1, 2, 3 (the hand
    # layout's runs beside the search); a small screen finds basins DIRECT-L's 70 evaluations miss (docs/method.md,
    # "Budgets")
    "quick": Preset(
        surrogate=dict(
            global_evals=70,
            local_evals=20,
            random_starts=4,
            strategy="greedy",
            screen_samples=1024,
            screen_starts=4,
            screen_evals=20,
        ),
        selection=dict(candidates=0),
        verdict=dict(draws=1),
    ),
    "default": Preset(
        surrogate=dict(global_evals=400, local_evals=120, joint_evals=200, screen_samples=4096),
        selection=dict(candidates=3, polish_evals=90, confirm_candidates=3),
    ),
    "thorough": Preset(
        surrogate=dict(
            global_evals=2000,
            local_evals=400,
            joint_evals=1000,
            random_starts=16,
            screen_samples=16384,
            screen_starts=12,
            screen_evals=60,
        ),
        selection=dict(candidates=6, polish_evals=200, confirm_candidates=6),
        verdict=dict(draws=30),
    ),
}


# In a real cell (an objective's cell other than the ideal one) an ICP evaluation costs several nominal ones
# (the cell's sources move every point; the paper's pipeline removes outliers) and the verdict's draws, not a
# confirmation on one seed, say how sure a difference is: no ICP polish or confirmation, less surrogate search; the verdict's draws after the
# validation's evaluate a share of the protocol's scans each: in a real cell the spread between cell instances rules
# the intervals, so more draws of fewer scans decide sooner (benchmarks/README.md, "Whole commands", for what the
# counts cost).
IN_A_CELL: dict[str, Preset] = {
    # quick: a screen of 64 poses (a cell pose costs the surrogate several nominal ones), its three best polished,
    # then per sensor a local BOBYQA from the best start and its polish, few enough evaluations that BOBYQA mostly
    # probes each of the six numbers around its start: DIRECT-L's evaluations went to the surrogate's optimistic
    # corners, and ICP rated the local stage's layouts better (docs/results.md, "`--budget quick` in the real
    # cell"). The validation on 7 of the reduced protocol's 14 scans (it makes each layout's choice); the verdict's
    # draws of 3 scans each, so that its work sees several times as many cell instances as draws of the reduced
    # protocol would, at most 8
    "quick": Preset(
        surrogate=dict(
            screen_samples=64,
            screen_starts=3,
            screen_evals=15,
            global_algorithm="LN_BOBYQA",
            global_evals=20,
            local_evals=10,
        ),
        validation=dict(protocol="reduced", scans=7),
        verdict=dict(draws=8, scans=3),
    ),
    # default: half the nominal surrogate search (a 512-pose screen, four starts polished, DIRECT-L's 200
    # evaluations, a joint stage of 60) and the selection's fewest candidates (four for one sensor, two for two, one
    # for three, with the anchored, nested and subset ones); the validation on the reduced protocol's 14 scans
    # (it makes each layout's choice; its draw is not the race's); the race at most 40 draws of 3 scans each: the
    # spread between cell instances rules the intervals, so draws of fewer scans decide on fewer scans
    # (benchmarks/README.md, "bench_search_stages.py": where the work goes, and the draws' sizes tried)
    "default": Preset(
        surrogate=dict(
            screen_samples=512,
            screen_starts=4,
            screen_evals=20,
            global_evals=200,
            local_evals=60,
            joint_evals=60,
            random_starts=4,
        ),
        selection=dict(candidates=1, polish_evals=0, confirm_candidates=0),
        validation=dict(protocol="reduced"),
        verdict=dict(scans=3, draws=40),
    ),
    # thorough: the race at most 120 draws of 3 scans (360 scans a layout, thrice the default's)
    "thorough": Preset(verdict=dict(scans=3, draws=120)),
}


def config_from_budget(
    budget: str, sensors: tuple[int, ...], overrides: Preset | None = None, cell: bool = False, kinds: tuple = ()
) -> SearchConfig:
    """The config of a named budget for these sensor counts, with ``overrides`` (a ``[search]`` table's
    preset, :func:`optipose.search.config.search_preset`) on top; ``cell``: it runs in a real cell
    (:data:`IN_A_CELL` adjusts the budget first); ``kinds``: the cells its BUYs are raced again in (a cell the user
    did not name: :mod:`optipose.search.kinds`), before the overrides."""
    if budget not in BUDGETS:
        raise ConfigError(f"unknown budget '{budget}' (use {', '.join(BUDGETS)})")
    presets = (
        BUDGETS[budget],
        IN_A_CELL.get(budget) if cell else None,
        Preset(verdict={"kinds": ",".join(kinds)}) if kinds else None,
        overrides,
    )
    config = SearchConfig(sensors=sensors)
    for preset in presets:
        if preset is not None:
            config = preset.apply(config)
    return config
