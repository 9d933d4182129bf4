"""The search config in sections: every budget gives the settings the flat config gave but its clocks (a budget is
work, not seconds: no budget sets a clock), and both forms of a ``[search]`` table (the sections, and the flat keys of older result folders and ``--search-config`` files) read
back to the same config."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import pytest

from optipose.errors import ConfigError
from optipose.search.budgets import config_from_budget
from optipose.search.config import FLAT_KEYS, SECTIONS, SearchConfig, saved_table, search_preset, search_table

ROOT = Path(__file__).resolve().parent.parent

# the flat config as it was before the sections (its defaults and its three tables), the regression's reference
FLAT_DEFAULTS = dict(
    global_algorithm="GN_DIRECT_L",
    local_algorithm="LN_BOBYQA",
    global_evals=300,
    local_evals=120,
    joint_evals=200,
    max_time=600.0,
    sensors=(1, 2, 3),
    strategy="both",
    min_points=2000,
    clearance=0.002,
    head_gap=0.0,
    margin=0.005,
    alpha_max_deg=60.0,
    line_skew_max_deg=60.0,
    random_starts=8,
    screen_samples=0,
    screen_starts=6,
    screen_evals=30,
    select_candidates=3,
    select_time=300.0,
    anchor_evals=0,
    hand_margin=0.5,
    hand_weight=5.0,
    polish_algorithm="LN_COBYLA",
    polish_evals=0,
    polish_time=150.0,
    polish_margin=0.9,
    polish_weight=5.0,
    polish_step=0.03,
    confirm_candidates=0,
    clear_ratio=0.4,
    validation="full",
    validation_scans=0,
    verdict_draws=12,
    verdict_time=120.0,
    answer_time=0.0,
    verdict_scans=0,
    verdict_tolerance=0.10,
    verdict_failures=0.01,
    verdict_confidence=0.95,
    select_scans=0,  # since the sections: the selection on a share of the reduced protocol's scans (0: all)
    verdict_kinds="",  # since the sections: the common kinds of cell a BUY is raced again in (none by default)
    verdict_kinds_draws=12,
)
FLAT_BUDGETS = {
    "quick": dict(
        global_evals=70,
        local_evals=20,
        max_time=25.0,
        random_starts=4,
        select_candidates=0,
        strategy="greedy",
        screen_samples=1024,
        screen_starts=4,
        screen_evals=20,
        verdict_draws=1,
    ),
    "default": dict(
        global_evals=400,
        local_evals=120,
        joint_evals=200,
        max_time=240.0,
        select_candidates=3,
        select_time=240.0,
        polish_evals=90,
        confirm_candidates=3,
        screen_samples=4096,
        verdict_time=60.0,
    ),
    "thorough": dict(
        global_evals=2000,
        local_evals=400,
        joint_evals=1000,
        max_time=3000.0,
        random_starts=16,
        screen_samples=16384,
        screen_starts=12,
        screen_evals=60,
        select_candidates=6,
        select_time=1800.0,
        polish_time=900.0,
        polish_evals=200,
        confirm_candidates=6,
        verdict_draws=30,
        verdict_time=900.0,
    ),
}
FLAT_CELL = {
    "quick": dict(
        max_time=15.0,
        screen_samples=64,
        screen_starts=3,
        screen_evals=15,
        global_algorithm="LN_BOBYQA",
        global_evals=20,
        local_evals=10,
        validation="reduced",
        validation_scans=7,
        verdict_draws=8,
        verdict_time=12.0,
        verdict_scans=3,
        answer_time=23.0,
    ),
    "default": dict(
        max_time=150.0,
        screen_samples=512,
        screen_starts=4,
        screen_evals=20,
        global_evals=200,
        local_evals=60,
        joint_evals=60,
        random_starts=4,
        select_candidates=1,
        select_time=45.0,
        polish_evals=0,
        confirm_candidates=0,
        validation="reduced",
        verdict_scans=3,
        verdict_draws=40,
        verdict_time=60.0,
    ),
    "thorough": dict(verdict_scans=3, verdict_draws=120),
}
CLOCKS = ("max_time", "select_time", "polish_time", "verdict_time", "answer_time")  # 0 in every budget: none
CASES = [(b, cell) for b in ("quick", "default", "thorough") for cell in (False, True)]


def flat(config: SearchConfig) -> dict:
    """Every leaf of a sectioned config under its flat key, with the sensor counts."""
    return {key: getattr(getattr(config, s), f) for key, (s, f) in FLAT_KEYS.items()} | {"sensors": config.sensors}


def budget_flat(budget: str, cell: bool, sensors=(1, 2, 3)) -> dict:
    """The flat config's settings, its clocks none (0)."""
    adjusted = FLAT_CELL.get(budget, {}) if cell else {}
    return {**FLAT_DEFAULTS, "sensors": sensors, **FLAT_BUDGETS[budget], **adjusted} | dict.fromkeys(CLOCKS, 0.0)


def test_every_flat_key_names_one_field_of_one_section():
    leaves = [(s, f.name) for s, cls in SECTIONS.items() for f in fields(cls)]
    assert sorted(FLAT_KEYS.values()) == sorted(leaves)  # each field once
    assert set(FLAT_KEYS) | {"sensors"} == set(FLAT_DEFAULTS)  # and every old key
    assert flat(SearchConfig()) == FLAT_DEFAULTS | dict.fromkeys(CLOCKS, 0.0)


@pytest.mark.parametrize("budget, cell", CASES)
def test_every_budget_gives_the_settings_of_the_flat_config(budget, cell):
    new = flat(config_from_budget(budget, (1, 2, 3), cell=cell))
    old = budget_flat(budget, cell)
    assert new == old
    assert {k: type(v) for k, v in new.items()} == {k: type(v) for k, v in old.items()}  # 25.0 stays a float


@pytest.mark.parametrize("budget, cell", CASES)
def test_a_config_reads_back_from_its_sections_and_from_its_flat_keys(budget, cell):
    config = config_from_budget(budget, (1, 3), cell=cell)
    assert search_preset(search_table(config)).apply(SearchConfig()) == config
    assert search_preset(flat(config)).apply(SearchConfig()) == config  # an older result folder's table


def test_a_search_table_takes_sections_flat_keys_or_both_and_the_user_word_last():
    both = search_preset({"global_evals": 25, "selection": {"candidates": 0}, "verdict": {"draws": 2}})
    config = config_from_budget("default", (1,), both)
    assert (config.surrogate.global_evals, config.selection.candidates) == (25, 0)
    assert config.verdict.draws == 2
    assert config.validation.protocol == "full" and config.surrogate.local_evals == 120  # the rest the budget's
    assert search_preset({"validation": "reduced"}).validation == {"protocol": "reduced"}  # the flat key
    assert search_preset({"validation": {"protocol": "reduced"}}).validation == {"protocol": "reduced"}  # the section
    assert config_from_budget("quick", (1,), search_preset({"sensors": [2, 3]})).sensors == (2, 3)


@pytest.mark.parametrize(
    "table, message",
    [
        ({"global_eval": 3}, "unknown search setting(s) global_eval"),
        ({"surrogate": {"draws": 3}, "colour": 1}, "unknown search setting(s) colour, surrogate.draws"),
        ({"verdict_draws": 3, "verdict": {"draws": 4}}, "verdict.draws given twice"),
    ],
)
def test_a_search_table_with_an_unknown_or_repeated_key_is_one_config_error(table, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        search_preset(table)


def test_a_search_config_file_in_either_form_overrides_the_budget(tmp_path):
    from optipose.cli.search import _overrides

    (tmp_path / "flat.toml").write_text('[search]\nglobal_evals = 25\nselect_candidates = 0\nvalidation = "reduced"\n')
    (tmp_path / "sections.toml").write_text(
        '[search.surrogate]\nglobal_evals = 25\n[search.selection]\ncandidates = 0\n[search.validation]\nprotocol = "reduced"\n'
    )
    flat_file, sections = (
        config_from_budget("quick", (1,), _overrides(tmp_path / n)) for n in ("flat.toml", "sections.toml")
    )
    assert flat_file == sections and sections.surrogate.global_evals == 25 and sections.validation.protocol == "reduced"
    (tmp_path / "bad.toml").write_text("[search]\nglobal_eval = 25\n[search.verdict]\nrounds = 2\n")
    with pytest.raises(ConfigError) as bad:
        _overrides(tmp_path / "bad.toml")
    said = str(bad.value)
    assert said.startswith(
        f"search config {tmp_path / 'bad.toml'}: unknown key(s) global_eval, verdict.rounds (known: "
    )
    assert "\n" not in said and "verdict_draws" in said


def test_the_committed_search_folders_written_flat_still_resume_with_their_settings():
    from optipose.cli.search import _settings
    from optipose.io.folders import read_config

    # every committed search folder, and one written flat before the sections (a quick search of part A, kept in
    # tests/data as it was written, its part's path made relative)
    folders = [
        p.parent
        for root in (ROOT / "results", ROOT / "tests" / "data")
        for p in sorted(root.rglob("config.toml"))
        if 'command = "search"' in p.read_text()
    ]
    flat_folders = [folder for folder in folders if "global_evals" in read_config(folder).search]
    assert ROOT / "tests" / "data" / "flat_search" in flat_folders
    for folder in flat_folders:
        saved = read_config(folder)
        config = _settings(saved)[1]
        written = saved_table(saved.search)  # a band = "" of a folder written before the band was retired: no check
        assert flat(config) == {**FLAT_DEFAULTS, **written, "sensors": tuple(saved.search["sensors"])}, folder
    for folder in set(folders) - set(flat_folders):  # written by section: read back as written
        saved = read_config(folder)
        assert search_preset(saved_table(saved.search)).apply(SearchConfig()) == _settings(saved)[1], folder


def test_the_report_shows_a_sectioned_config_one_value_a_row():
    from optipose.io.config import run_config

    sectioned = run_config({"search": search_table(SearchConfig())})
    rows = dict(sectioned.search_settings)
    assert rows["surrogate.global_evals"] == 300 and rows["verdict.draws"] == 12 and rows["sensors"] == (1, 2, 3)
    assert sectioned.sensors == (1, 2, 3)
    assert dict(run_config({"search": {"global_evals": 5, "sensors": [1]}}).search_settings) == {
        "global_evals": 5,
        "sensors": [1],
    }
