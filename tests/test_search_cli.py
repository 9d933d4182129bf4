"""``optipose search`` end to end on a small budget and a short protocol."""

from __future__ import annotations

import subprocess
import sys
import tomllib

import numpy as np
import pandas as pd
import pytest
import trimesh

SMALL = """[search]
global_evals = 25
local_evals = 8
joint_evals = 10
random_starts = 2
select_candidates = 0
"""
SHORT = """name = "short"
[protocol]
sequences = ["R", "P", "Y"]
start_deg = -2.0
stop_deg = 2.0
step_deg = 4.0
"""


def run(*args):
    return subprocess.run(
        [sys.executable, "-m", "optipose", *map(str, args)], capture_output=True, text=True, timeout=900
    )


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("search")
    (d / "small.toml").write_text(SMALL)
    (d / "short.toml").write_text(SHORT)
    trimesh.creation.box((0.0004, 0.0004, 0.0004)).export(d / "speck.stl")
    return d


def test_search_without_a_part_says_so():
    result = run("search")
    assert result.returncode == 2 and "give a PART" in result.stderr


def test_a_part_no_sensor_can_see_ends_with_a_clear_message(files):
    result = run(
        "search", files / "speck.stl", "--units", "m", "--search-config", files / "small.toml", "--out", files / "speck"
    )
    assert result.returncode == 2, result.stderr
    assert "no feasible layout" in result.stderr and "Traceback" not in result.stderr
    assert (files / "speck" / "history.csv").is_file()  # what was tried is kept


@pytest.fixture(scope="module")
def searched(files):
    out = files / "b"
    result = run(
        "search",
        "part_b",
        "--sensors",
        "1,2",
        "--search-config",
        files / "small.toml",
        "--objective",
        files / "short.toml",
        "--seed",
        4,
        "--out",
        out,
        "--no-report",
    )
    assert result.returncode == 0, result.stderr
    return out, result


def test_search_writes_a_result_folder_that_explains_itself(searched):
    out, result = searched
    config = tomllib.loads((out / "config.toml").read_text())
    assert config["seed"] == 4 and config["validation_seed"] != 4
    assert config["search"]["surrogate"]["global_evals"] == 25 and config["objective"]["name"] == "short"
    history = pd.read_csv(out / "history.csv")
    assert len(history) > 50 and set(history["k"]) == {1, 2}
    comparison = pd.read_csv(out / "comparison.csv")
    assert set(comparison["layout"]) == {"found", "hand"} and set(comparison["k"]) == {1, 2}
    assert np.all(comparison["median_deg"] >= 0)
    assert set(comparison["protocol"]) == {"full"} and "full protocol" in result.stdout
    for k in (1, 2):
        text = (out / "layouts" / f"found_k{k}.toml").read_text()
        assert text.count("[[sensors]]") == k
    assert "found vs. hand" in result.stdout
    # each found layout and the hand one drawn beside its file, whole PNGs (no temporary left behind)
    drawn = sorted(p.name for p in (out / "layouts").iterdir() if not p.name.endswith(".toml"))
    assert drawn == ["found_k1.png", "found_k2.png", "hand.png"]
    assert all((out / "layouts" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for name in drawn)


def test_search_progress_off_a_terminal_counts_each_stage_within_its_budget(searched):
    import re

    from optipose.cli.search import stage_budget
    from optipose.search.config import SearchConfig, search_preset

    out, result = searched
    config = search_preset(tomllib.loads((out / "config.toml").read_text())["search"]).apply(SearchConfig())
    history = pd.read_csv(out / "history.csv")
    for stage, n in history.groupby("stage").size().items():  # what each stage did, at most its budget
        assert stage_budget(config, stage) is not None and n <= stage_budget(config, stage), stage
    progress = [line for line in result.stderr.splitlines() if line.startswith("part_b: ")]
    assert "part_b: searching on the surrogate, 0 s" in progress
    for stage, n in history.groupby("stage", sort=False).size().items():  # one whole line as each stage ends
        assert any(line.startswith(f"part_b: {stage} done, {n} evaluations, best k=") for line in progress), stage
    for done, total in re.findall(r" (\d+)/(\d+) evaluations", result.stderr):
        assert int(done) <= int(total)


def test_resume_replays_from_the_cache_to_the_same_layout(searched):
    out, _ = searched
    before = (out / "layouts" / "found_k2.toml").read_text()
    n_before = len(pd.read_csv(out / "history.csv"))
    result = run("search", "--resume", out)
    assert result.returncode == 0, result.stderr
    assert (out / "layouts" / "found_k2.toml").read_text() == before
    assert len(pd.read_csv(out / "history.csv")) == n_before


def test_every_budget_validates_on_the_full_protocol_and_reduced_is_still_there():
    from optipose.evaluate.objective import load_objective
    from optipose.evaluate.objective import reduced_objective
    from optipose.search.budgets import config_from_budget
    from optipose.search.config import search_preset

    budgets = ("quick", "default", "thorough")
    assert {config_from_budget(b, (1, 2, 3)).validation.protocol for b in budgets} == {"full"}
    reduced = search_preset({"validation": "reduced"})
    assert config_from_budget("quick", (1, 2, 3), reduced).validation.protocol == "reduced"
    # the paper's 7 sequences at their two end angles: 14 of the 77 scans
    from optipose.evaluate.protocol import perturbations

    assert len(perturbations(reduced_objective(load_objective("paper").in_cell("ideal")).protocol, 0)) == 14
