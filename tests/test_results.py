"""Result folders read back (optipose.io.load_result) and the verdict against the hand layout."""

from __future__ import annotations

import numpy as np
import pytest

from optipose.errors import ConfigError
from optipose.evaluate.assignment import AxisChoice, Choice
from optipose.verdict.compare import Verdict, dominates, excess, rank
from optipose.verdict.words import one_versus_many, verdict_line
from optipose.io import load_result
from optipose.io.folders import write_config
from optipose.io.results import SearchResult
from optipose.io.search import SearchFolder
from optipose.model.layout import Layout, SensorPose
from optipose.search.records import Validation


def _choice(sensors, names, per_axis_mdeg):
    """A Choice of sensor indices with (median, p75) per axis in millidegrees, every axis on all of them."""
    name = "".join(names[i] for i in sensors)
    axes = tuple(
        AxisChoice(a, tuple(sensors), name, np.deg2rad(m * 1e-3), np.deg2rad(p * 1e-3))
        for a, (m, p) in zip(("roll", "pitch", "yaw"), per_axis_mdeg)
    )
    return Choice(
        len(sensors), tuple(sensors), name, axes, float(np.deg2rad(sum(m + p for m, p in per_axis_mdeg) * 1e-3))
    )


F, S = ["F1", "F2", "F3"], ["S1", "S2", "S3"]
VALIDATION = Validation(
    "full",
    1234,
    found={3: _choice((0, 1, 2), F, [(0.05, 0.1)] * 3), 1: _choice((0,), F, [(0.1, 0.2), (0.1, 0.25), (0.05, 0.1)])},
    baseline={1: _choice((0,), S, [(3.0, 5.0), (0.1, 0.2), (0.1, 0.2)]), 3: _choice((0, 1, 2), S, [(0.1, 0.2)] * 3)},
)


def test_the_verdict_names_every_worse_axis_and_what_to_keep():
    one, three = VALIDATION.verdicts()
    # by hand: hand 3 + 5 + 0.1 + 0.2 + 0.1 + 0.2 = 8.6 mdeg, found 0.1 + 0.2 + 0.1 + 0.25 + 0.05 + 0.1 = 0.8
    assert one.ratio == pytest.approx(8.6 / 0.8) and not one.no_worse
    assert [(g.axis, g.statistic) for g in one.worse] == [("pitch", "p75")]
    assert verdict_line(one) == (
        "k=1: found F1 10.75x better in sum than hand S1, but worse on pitch p75 0.250 vs 0.200 mdeg: "
        "keep S1 if no axis may get worse"
    )
    assert (
        three.no_worse
        and verdict_line(three) == "k=3: found F1F2F3 2.00x better in sum than hand S1S2S3, no worse on any axis"
    )
    assert (
        VALIDATION.verdict_lines()[-1] == "one found sensor beats the hand-placed S1S2S3 in sum (0.800 vs 0.900 mdeg)"
    )


def test_a_found_layout_worse_in_sum_says_keep_and_a_bare_part_gets_no_verdict():
    pair = Validation(
        "full",
        1,
        found={2: _choice((0, 1), F, [(0.5, 0.6), (0.1, 0.2), (0.1, 0.2)])},
        baseline={2: _choice((0, 1), S, [(0.4, 0.5), (0.1, 0.2), (0.1, 0.2)])},
    )
    (line,) = pair.verdict_lines()
    assert line.startswith("k=2: found F1F2 1.13x worse in sum than hand S1S2 and worse on roll median 0.500 vs 0.400")
    assert line.endswith(": keep S1S2")
    assert Validation("full", 1, found=VALIDATION.found).verdict_lines() == []  # a bare STL: no hand layout, no verdict


def test_a_found_layout_that_ties_the_hand_one_is_not_bought():
    # a found triple whose choice measures every axis on the hand sensors it keeps ties the hand layout:
    # no worse, but nothing gained, so the answer is to keep the hand layout, not to buy a bracket
    from optipose.verdict.compare import bought
    from optipose.verdict.words import verdict_headline

    hand = _choice((0, 1, 2), S, [(0.1, 0.2), (0.05, 0.1), (0.1, 0.3)])
    tie = Verdict(3, Choice(3, (0, 1, 2), "F1F2F3", hand.axes, hand.score), hand)
    assert tie.no_worse and tie.tie and not bought(tie)
    assert verdict_line(tie) == "k=3: found F1F2F3 ties hand S1S2S3 on every axis: keep S1S2S3"
    assert verdict_headline(tie) == "k=3: KEEP hand S1S2S3: found F1F2F3 ties it on every axis"
    better = Verdict(
        3, _choice((0, 1, 2), F, [(0.1, 0.2), (0.05, 0.1), (0.1, 0.25)]), hand
    )  # yaw p75 better, the rest equal
    assert better.no_worse and not better.tie and bought(better)


def test_dominance_excess_and_rank_agree():
    hand, found = VALIDATION.baseline[1], VALIDATION.found[1]
    assert not dominates(found, hand) and dominates(hand, hand)
    assert excess(found, hand) == pytest.approx(np.deg2rad(0.05e-3)) and excess(hand, hand) == 0.0
    assert excess(hand, hand, 0.5) > 0  # a margin below 1 asks for a clear win
    assert rank(VALIDATION.found[3], VALIDATION.baseline[3]) < rank(found, hand)  # no worse anywhere ranks first
    assert rank(found, None) == (False, found.score)
    worse = Verdict(1, hand, found)  # the other way round: worse in sum and on axes
    assert verdict_line(worse).startswith("k=1: found S1 10.75x worse in sum than hand F1 and worse on roll median")
    assert verdict_line(worse).endswith(": keep F1")
    assert one_versus_many(hand, VALIDATION.baseline[3]).startswith("one found sensor does not beat")


def _layout(name, n, prefix):
    return Layout(
        tuple(SensorPose(f"{prefix}{i + 1}", np.eye(4) + np.diag([0, 0, 0, 0]) + _shift(i)) for i in range(n)),
        name=name,
    )


def _shift(i):
    T = np.zeros((4, 4))
    T[0, 3] = 0.01 * i
    return T


def test_a_search_folder_reads_back_with_the_same_verdicts(tmp_path):
    write_config(
        tmp_path,
        {
            "command": "search",
            "part": {"name": "part_x", "source": ""},
            "seed": 7,
            "budget": "quick",
            "validation_seed": 1234,
        },
    )
    sink = SearchFolder(tmp_path)
    sink.layouts({1: _layout("found_k1", 1, "F"), 3: _layout("found_k3", 3, "F")}, _layout("hand", 3, "S"))
    sink.validation(VALIDATION)
    result = load_result(tmp_path)
    assert isinstance(result, SearchResult) and (result.part, result.seed, result.budget) == ("part_x", 7, "quick")
    assert sorted(result.layouts) == [1, 3] and result.baseline.names == S
    assert result.verdict_lines() == VALIDATION.verdict_lines()
    loaded = result.validation.found[1]
    assert loaded.sensors == (0,) and [a.subset for a in loaded.axes] == [(0,)] * 3  # indices recovered from names
    assert all(a.median == pytest.approx(b.median, rel=1e-15) for a, b in zip(loaded.axes, VALIDATION.found[1].axes))


def test_an_evaluation_folder_reads_back_with_the_same_table(tmp_path):
    from dataclasses import replace

    from optipose.evaluate.evaluator import evaluate
    from optipose.evaluate.objective import load_objective
    from optipose.io.evaluation import write_evaluation
    from optipose.model.part import load_part

    objective = load_objective("paper").in_cell("ideal")
    objective = replace(
        objective,
        protocol=replace(
            objective.protocol, sequences=("R", "P"), step=objective.protocol.stop - objective.protocol.start
        ),
    )
    part = load_part("part_b")
    result = evaluate(part, replace(part.layouts["hand"], sensors=part.layouts["hand"].sensors[:2]), objective, seed=3)
    write_config(tmp_path, {})  # overwritten by write_evaluation
    write_evaluation(result, tmp_path, part_source="part_b")
    loaded = load_result(tmp_path)
    assert loaded.table == result.table  # the same choices, to the last bit
    assert loaded.per_scan.equals(result.per_scan) and loaded.layout.names == result.layout.names
    assert loaded.objective.protocol == objective.protocol and loaded.seed == 3


def test_config_toml_reads_back_once_as_a_typed_record(tmp_path):
    from optipose.io.config import RunConfig, run_config
    from optipose.io.folders import RESULT_FORMAT, read_config

    write_config(
        tmp_path,
        {
            "command": "search",
            "part": {"name": "part_x", "source": "p.toml"},
            "seed": 7,
            "validation_seed": 9,
            "budget": "default",
            "search": {"sensors": (1, 2)},
            "objective": {"name": "mine"},
            "versions": {"optipose": "0.1.0"},
        },
    )
    config = read_config(tmp_path)
    assert (
        config.command,
        config.format,
        config.part_name,
        config.part_source,
        config.seed,
        config.validation_seed,
        config.budget,
    ) == ("search", RESULT_FORMAT, "part_x", "p.toml", 7, 9, "default")
    assert config.sensors == (1, 2) and config.objective_name == "mine" and config.versions == {"optipose": "0.1.0"}
    assert config.table["search"] == {"sensors": [1, 2]}  # the file as written, for showing it
    # a folder written before a key existed: its field is left empty, nothing fails
    old = run_config({"command": "evaluate"})
    assert old == RunConfig(command="evaluate") and old.format is None and old.layouts == () and old.sensors == ()


def test_a_folder_that_is_not_a_result_is_refused_in_one_line(tmp_path):
    with pytest.raises(ConfigError, match="no config.toml"):
        load_result(tmp_path)
    write_config(tmp_path, {"command": "scan"})
    with pytest.raises(ConfigError, match="'scan' result"):
        load_result(tmp_path)


def test_a_selection_with_an_unobservable_axis_reads_back(tmp_path):
    # a candidate whose yaw no subset measures writes empty cells; they read back as an unobservable axis
    # (the reference search of part C wrote one and its report failed on it)
    from optipose.evaluate.assignment import UNOBSERVABLE
    from optipose.io.folders import write_csv
    from optipose.io.load import load_selection
    from optipose.io.tables import selection_frame
    from optipose.search.records import IcpEvaluation

    axes = (
        AxisChoice("roll", (0,), "F1", 0.01, 0.02),
        AxisChoice("pitch", (0,), "F1", 0.003, 0.004),
        AxisChoice("yaw", (), "", np.nan, np.nan, UNOBSERVABLE),
    )
    record = IcpEvaluation(1, "subset of k=3", 2.0, "reduced", Choice(1, (0,), "F1", axes, 0.5), False)
    write_csv(selection_frame([record]), tmp_path / "selection.csv")
    (back,) = load_selection(tmp_path)
    assert [a.observable for a in back.choice.axes] == [True, True, False]
    assert back.choice.axes[2].reason == UNOBSERVABLE and np.isnan(back.choice.axes[2].median)
    assert back.choice.axes[0].median == pytest.approx(0.01) and back.choice.axes[0].name == "F1"
