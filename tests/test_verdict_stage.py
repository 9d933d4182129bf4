"""The search's verdict with confidence (search/draws.py): common random numbers through the real evaluator,
the race over several k, and verdict.csv read back as written."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from optipose.verdict.confidence import Decision, PairedDraw, Verdicts, compare_draws
from optipose.verdict.rules import Rules, VerdictConfig
from optipose.verdict.racing import race_many
from optipose.verdict.words import axis_lines, confident_line, fewer_line, ruling_line
from optipose.evaluate.objective import load_objective
from optipose.io.folders import write_csv
from optipose.io.load import read_verdicts
from optipose.verdict.ruling import Ruling
from optipose.io.tables import verdict_frame
from optipose.model.layout import Layout, SensorPose
from optipose.model.part import load_part
from optipose.search.config import SearchConfig, ValidationConfig
from optipose.search.validate import validate
from optipose.search.draws import confident_verdicts
from optipose.seeds import validation_seed, verdict_seed

FAST = Rules(replicates=400)


def _as_found(hand: Layout, k: int) -> Layout:
    """The hand layout's first k sensors, named as a search names found ones."""
    return Layout(tuple(SensorPose(f"F{i + 1}", s.T_O_S) for i, s in enumerate(hand.sensors[:k])), name=f"found_k{k}")


@pytest.mark.parametrize("cell", ["ideal", "ur10e"])
def test_the_hand_layout_found_again_is_an_exact_tie_on_every_draw(cell):
    """Found = hand, evaluated on the same draws: every k a TIE whose intervals are exactly 1 — the draws are
    common to both sides (the same cell instance, orientations, robot paths and noise)."""
    part = load_part("part_b")
    objective = load_objective("paper").in_cell(cell)
    config = SearchConfig(
        validation=ValidationConfig(protocol="reduced"),
        verdict=VerdictConfig(draws=4, scans=0 if cell == "ideal" else 7),
    )
    hand = part.layouts["hand"]
    layouts = {k: _as_found(hand, k) for k in (1, 2, 3)}
    first, draws = {}, []
    validation = validate(part, objective, layouts, seed=5, protocol="reduced", on_evaluation=first.__setitem__)
    verdicts = confident_verdicts(
        part,
        objective,
        layouts,
        validation,
        first,
        5,
        config,
        on_draw=lambda i, name, result: draws.append((i, name, result.seed)),
    )
    by_k, fewer = verdicts.by_k, verdicts.fewer
    assert sorted(by_k) == [1, 2, 3]
    # one found sensor against the hand's three rides along on the same draws, without holding the race
    last = max(v.n_draws for v in by_k.values())
    assert (fewer.k, fewer.baseline_k, fewer.baseline_name, fewer.n_draws) == (1, 3, validation.baseline[3].name, last)
    assert fewer.found_name == "F1"
    same = [
        k for k in by_k if validation.baseline[k].sensors == tuple(range(k))
    ]  # the hand's own choice is its first k sensors
    assert 3 in same
    for k in same:
        v = by_k[k]
        assert v.decision == Decision.TIE, confident_line(v)
        assert (v.score.estimate, v.score.low, v.score.high) == (1.0, 1.0, 1.0)
        # the found sensors its axes use (a copy of the hand's: the hand's used ones), the hand's k sensors
        used = validation.baseline[k].used
        assert (
            v.found == v.baseline
            and v.found_name == "".join(f"F{i + 1}" for i in used)
            and v.baseline_name.startswith("S")
        )
    # the ideal cell looks first at the validation's draw alone; a real cell waits for three instances, none of
    # them the validation's (the choices were made on it)
    expected = 1 if cell == "ideal" else 3
    assert {by_k[k].n_draws for k in same} == {expected}
    # the reduced protocol's 14 scans in the validation's draw and each later one; in the real cell 7 of them
    # in each of its own draws
    assert fewer.n_scans == (14 * last if cell == "ideal" else 7 * last)
    fresh = range(1, last) if cell == "ideal" else range(1, last + 1)
    assert sorted({(i, seed) for i, _, seed in draws}) == [(i, verdict_seed(5, i)) for i in fresh]
    assert verdict_seed(5, 0) == validation_seed(5) and len({verdict_seed(5, i) for i in range(4)}) == 4
    if (
        cell != "ideal"
    ):  # the real cell's race never reads the validation's evaluations: without them, the same verdicts
        again = confident_verdicts(part, objective, layouts, validation, {}, 5, config)
        assert [confident_line(v) for v in again.in_order()] == [confident_line(v) for v in verdicts.in_order()]


def _pairs(rng, i, ratio):
    hand = np.abs(rng.normal(size=(40, 3))) * 1e-4
    found = hand * np.exp(rng.normal(0.0, 0.05, size=hand.shape)) / ratio
    return PairedDraw(i, found, hand)


def test_racing_several_k_stops_each_at_its_own_look_and_ends_when_all_are_decided():
    rng = np.random.default_rng(3)
    calls = []

    def next_draws(i, keys):
        calls.append((i, keys))
        return {1: _pairs(rng, i, 3.0), 2: PairedDraw(i, *(2 * [_pairs(rng, i, 1.0).baseline]))}

    verdicts = race_many(next_draws, FAST, min_draws=2, max_draws=6, names={1: dict(k=1), 2: dict(k=2)})
    assert verdicts[1].decision == Decision.BUY and verdicts[1].n_draws == 2  # clear at the first look
    assert verdicts[2].decision == Decision.TIE and verdicts[2].n_draws == 2  # an exact copy: a tie as soon as it looks
    assert calls == [(0, None), (1, frozenset({1, 2}))]  # before any draw every key; then the undecided ones

    asked = []

    def undecided(i, keys):
        asked.append(keys)
        return {key: _pairs(rng, i, 3.0 if key == 1 else 1.0) for key in (keys or (1, 2))}

    verdicts = race_many(undecided, replace(FAST, tolerance=0.0), min_draws=2, max_draws=6)
    assert verdicts[1].decision == Decision.BUY and verdicts[1].n_draws < 6
    assert (
        verdicts[2].decision == Decision.UNDECIDED and verdicts[2].n_draws == 6
    )  # no tie within a zero tolerance: to the budget
    # once k=1 is bought its layouts are not asked for again, and the race goes on for k=2 alone
    assert asked[verdicts[1].n_draws :] == [frozenset({2})] * (6 - verdicts[1].n_draws)


def test_the_verdict_table_reads_back_as_written(tmp_path):
    rng = np.random.default_rng(4)
    verdicts = {
        k: compare_draws(
            [_pairs(rng, i, 1.0 + k) for i in range(3)],
            FAST,
            k=k,
            found_name=f"F{k}",
            baseline_name="S1",
            seconds_per_draw=2.5,
        )
        for k in (1, 2)
    }
    verdicts[3] = replace(compare_draws([_pairs(rng, 0, 1.01)], FAST, k=3), decision=Decision.UNDECIDED, more_draws=7)
    verdicts[2] = replace(verdicts[2], ruling=Ruling("robot.path", 5.2e-5, True, 0.41))  # in a cell of ranges
    fewer = compare_draws(
        [_pairs(rng, i, 0.5) for i in range(3)], FAST, k=1, found_name="F1", baseline_name="S1S2S3", baseline_k=3
    )
    write_csv(verdict_frame(Verdicts(verdicts, fewer)), tmp_path / "verdict.csv")
    back = read_verdicts(tmp_path / "verdict.csv")
    assert set(back.by_k) == {1, 2, 3} and back.fewer.baseline_k == 3
    for read, v in [*((back.by_k[k], v) for k, v in verdicts.items()), (back.fewer, fewer)]:
        assert (
            confident_line(read) == confident_line(v)
            and axis_lines(read) == axis_lines(v)
            and fewer_line(read) == fewer_line(v)
            and ruling_line(read) == ruling_line(v)
        )
        assert read.ruling == v.ruling
        assert read.score.low == pytest.approx(v.score.low, rel=1e-12) and read.more_draws == v.more_draws
        for a, b in zip((*read.found, *read.baseline), (*v.found, *v.baseline)):  # what one cell gives, read back
            assert np.allclose(
                [a.one_cell.estimate, a.one_cell.low, a.one_cell.high],
                [b.one_cell.estimate, b.one_cell.low, b.one_cell.high],
                rtol=1e-12,
                equal_nan=True,
            )
    assert any(np.isfinite(a.one_cell.low) for a in back.by_k[1].found)  # several draws: an interval to read
    assert read_verdicts(tmp_path / "none.csv") == Verdicts()
    # a verdict.csv from before the failures' rule: its failed shares and tolerance unknown (NaN), not taken as applied
    old = pd.read_csv(tmp_path / "verdict.csv").drop(
        columns=["failed", "failed_low", "failed_high", "failures", "kept"]
        + [f"{s}_cell_median_deg{e}" for s in ("found", "hand") for e in ("", "_low", "_high")]
    )
    old.to_csv(tmp_path / "old.csv", index=False)
    before = read_verdicts(tmp_path / "old.csv")
    assert all(np.isnan(v.failures) and np.isnan(v.axes[0].failed.high) and not v.kept for v in before.in_order())
    assert [confident_line(v) for v in before.in_order()] == [confident_line(v) for v in back.in_order()]
    assert all(np.isnan(a.one_cell.low) for v in before.in_order() for a in v.found)  # not given, not made up
    from optipose.report.confidence import confident_blocks
    from optipose.report.document import Table

    captions = [[b.caption for b in confident_blocks(v, "ur10e") if isinstance(b, Table)][0] for v in (back, before)]
    assert "failing its registration on more than 1 %" in captions[0] and "failing" not in captions[1]
    one_cell = [
        [b for b in confident_blocks(v, "ur10e") if isinstance(b, Table) and b.anchor == "one-cell"]
        for v in (back, before)
    ]
    assert len(one_cell[0]) == 1 and not one_cell[1]  # an older folder has no one-cell table to show


def test_a_draw_of_fewer_scans_keeps_the_protocols_orientations_in_proportion():
    from optipose.evaluate.protocol import perturbations

    full = perturbations(load_objective("paper").in_cell("ideal").protocol, seed=3)
    part = full.sample(20, 11)
    assert len(part) == 20 and full.sample(0, 11) is full and full.sample(len(full), 11) is full
    rows = [
        int(np.flatnonzero((full.seeds == s))[0]) for s in part.seeds
    ]  # each a scan of the protocol, once, in order
    assert rows == sorted(set(rows)) and np.array_equal(full.rpy[rows], part.rpy)
    assert np.array_equal(full.sample(20, 11).seeds, part.seeds) and not np.array_equal(
        full.sample(20, 12).seeds, part.seeds
    )


def test_a_buy_says_which_bracket_to_move_and_which_hand_sensors_stay():
    from optipose.model.layout import kept_sensors
    from optipose.verdict.words import mount_line

    hand = load_part("part_b").layouts["hand"]
    moved = hand.sensors[0].T_O_S.copy()
    moved[:3, 3] += [0.0, 0.002, 0.0]  # S1's bracket 2 mm along y
    found = Layout((SensorPose("F1", moved), SensorPose("F2", hand.sensors[1].T_O_S)), name="found_k2")
    assert kept_sensors(found, hand) == {"F2": "S2"}
    buy = replace(
        compare_draws(
            [_pairs(np.random.default_rng(5), i, 3.0) for i in range(2)],
            FAST,
            k=2,
            found_name="F1F2",
            baseline_name="S1S2",
        ),
        decision=Decision.BUY,
    )
    assert mount_line(buy, found, hand) == "k=2: mount F1 (new), keep S2; S1 freed"
    assert mount_line(replace(buy, decision=Decision.TIE), found, hand) == ""
    assert mount_line(replace(buy, found_name="F2", baseline_name="S2S3"), found, hand) == "k=2: keep S2; S3 freed"


def test_a_found_sensor_no_axis_measures_on_is_not_named_or_mounted():
    # part A's quick triple of 2026-11-27 measured every axis on F1 and F2: its verdict named F1F2F3 and mounted
    # all three. The name is the sensors the choice's axes use, in the k layout's own names (here inside a
    # larger layout of four whose first is not the k layout's)
    from optipose.evaluate.assignment import AxisChoice, Choice
    from optipose.verdict.words import mount_line
    from optipose.search.draws import _found_name

    hand = load_part("part_b").layouts["hand"]
    poses = [np.eye(4) for _ in range(4)]
    for i, T in enumerate(poses):
        T[:3, 3] = [0.1 * (i + 1), 0.0, 0.3]
    big = Layout(tuple(SensorPose(f"F{i + 1}", T) for i, T in enumerate(poses)), name="found_k4")
    triple = Layout(
        tuple(SensorPose(f"F{i + 1}", T) for i, T in enumerate(poses[1:])), name="found_k3"
    )  # big's F2, F3, F4
    axes = (
        AxisChoice("roll", (1,), "F2", 1e-4, 2e-4),
        AxisChoice("pitch", (1, 2), "F2F3", 1e-4, 2e-4),
        AxisChoice("yaw", (2,), "F3", 1e-4, 2e-4),
    )
    choice = Choice(3, (1, 2, 3), "F2F3F4", axes, 1e-3)
    assert _found_name(triple, choice, big) == "F1F2"  # big's F2, F3 are the triple's F1, F2; its F3 unused
    blind = Choice(
        3,
        (1, 2, 3),
        "F2F3F4",
        tuple(AxisChoice(a, (), "", np.nan, np.nan, "unobservable") for a in ("roll", "pitch", "yaw")),
        1e-3,
    )
    assert _found_name(triple, blind, big) == "F1F2F3"  # nothing measured: the choice's sensors
    buy = replace(
        compare_draws(
            [_pairs(np.random.default_rng(5), i, 3.0) for i in range(2)],
            FAST,
            k=3,
            found_name=_found_name(triple, choice, big),
            baseline_name="S1S2S3",
        ),
        decision=Decision.BUY,
    )
    assert mount_line(buy, triple, hand) == "k=3: mount F1, F2 (new); S1, S2, S3 freed"


def test_a_stages_clock_is_its_own_and_what_is_left_of_the_users_whatever_the_stages_before_it_took():
    import math
    import time

    from optipose.errors import ConfigError
    from optipose.search.config import SearchConfig
    from optipose.search.pipeline import SearchContext

    def context(ago: float, time_limit: float = 0.0) -> SearchContext:
        config = SearchConfig(time_limit=time_limit)
        return SearchContext(None, None, config, 0, None, 1, time.monotonic() - ago)

    assert context(100.0).seconds() == math.inf  # no clock anywhere: the counts end the stage
    assert context(100.0).seconds(12.0) == 12.0  # the stage's own
    assert context(20.0).seconds(12.0, 23.5) == pytest.approx(3.5, abs=0.1)  # what is left of 23.5 s (answer_time)
    assert context(5.0).seconds(12.0, 23.5) == 12.0  # never more than the stage's own
    assert 0 < context(60.0).seconds(12.0, 23.5) < 0.01  # past it: a moment, not "no limit"
    assert context(4.0).seconds(0.0, 10.0) == pytest.approx(6.0, abs=0.1)
    assert context(30.0, time_limit=90.0).seconds() == pytest.approx(60.0, abs=0.1)  # --max-time's rest
    assert context(30.0, time_limit=90.0).seconds(20.0) == 20.0
    with pytest.raises(ConfigError, match="answer_time"):
        VerdictConfig(answer_time=-1.0)
    with pytest.raises(ConfigError, match="--max-time"):
        SearchConfig(time_limit=-1.0)


def test_where_the_hand_choice_beat_the_found_layout_on_the_validation_draw_the_search_answers_with_it(tmp_path):
    """In a real cell, a k whose found layout scored worse than the hand's choice on the validation's draw is answered
    with that choice's own sensors (their names and poses): the verdict pairs the hand's evaluation with itself, an
    exact TIE that rides along while the other k race, and the result folder reads back with it."""
    from optipose.evaluate.assignment import AxisChoice, Choice
    from optipose.io.config import RunConfig
    from optipose.io.load import load_search
    from optipose.io.search import SearchFolder
    from optipose.model.layout import is_part_of
    from optipose.search.records import Validation
    from optipose.search.validate import baseline_where_better

    part = load_part("part_b")
    hand = part.layouts["hand"]
    # by hand: hand's pair S2S3 (indices 1, 2; roll on S3 alone) beat the found pair (2e-3 rad against 3e-3); the
    # found triple beat hand's triple: only k = 2 is replaced, its subsets restated in the new layout's indices
    axes = (
        AxisChoice("roll", (2,), "S3", 1e-4, 2e-4),
        AxisChoice("pitch", (1, 2), "S2S3", 1e-4, 2e-4),
        AxisChoice("yaw", (1, 2), "S2S3", 1e-4, 2e-4),
    )
    pair = Choice(2, (1, 2), "S2S3", axes, 2e-3)
    found_pair = Choice(2, (0, 1), "F1F2", tuple(replace(a, subset=(0, 1), name="F1F2") for a in axes), 3e-3)
    found_triple = Choice(
        3, (0, 1, 2), "F1F2F3", tuple(replace(a, subset=(0, 1, 2), name="F1F2F3") for a in axes), 1e-3
    )
    triple = Choice(3, (0, 1, 2), "S1S2S3", tuple(replace(a, subset=(0, 1, 2), name="S1S2S3") for a in axes), 2e-3)
    layouts = {2: _as_found(hand, 2), 3: _as_found(hand, 3)}
    validation = Validation("reduced", 1, {3: found_triple, 2: found_pair}, {2: pair, 3: triple})
    answered, v = baseline_where_better(layouts, validation, hand)
    assert answered[3] is layouts[3] and v.found[3] is found_triple
    assert answered[2].names == ["S2", "S3"] and is_part_of(answered[2], hand) and not is_part_of(layouts[2], hand)
    assert [np.array_equal(T, hand.poses[i]) for i, T in zip((1, 2), answered[2].poses)] == [True, True]
    assert v.found[2].sensors == (0, 1) and [a.subset for a in v.found[2].axes] == [(1,), (0, 1), (0, 1)]
    assert (v.found[2].name, v.found[2].score) == ("S2S3", 2e-3) and v.baseline == validation.baseline
    # a found triple that ties the hand's to rounding (the same sensors in another layout: the last bits of a sum) did
    # not beat it, and is answered with it; one better by more than rounding did
    tied = replace(found_triple, score=triple.score * (1 - 1e-15))
    answered, _ = baseline_where_better(layouts, Validation("reduced", 1, {3: tied}, {3: triple}), hand)
    assert answered[3] is not layouts[3] and answered[3].names == ["S1", "S2", "S3"]
    better = replace(found_triple, score=triple.score * (1 - 1e-6))
    answered, _ = baseline_where_better(layouts, Validation("reduced", 1, {3: better}, {3: triple}), hand)
    assert answered[3] is layouts[3]

    # the largest found layout replaced: the smaller ones it held keep their choices, restated in the largest left
    # (here found_k3 = (C, A, B) held found_k1 = A as its F2 and found_k2 = (B, A) as F3F2; in found_k2 A is F2, B F1)
    poses = [np.eye(4) for _ in range(3)]
    for i, T in enumerate(poses):
        T[:3, 3] = [0.05 * (i + 1), 0.0, 0.3]
    A, B, C = poses

    def lay(*Ts):
        return Layout(tuple(SensorPose(f"F{i + 1}", T) for i, T in enumerate(Ts)), name=f"found_k{len(Ts)}")

    nested = {1: lay(A), 2: lay(B, A), 3: lay(C, A, B)}
    one = Choice(1, (1,), "F2", tuple(replace(a, subset=(1,), name="F2") for a in axes), 1e-3)
    two = Choice(
        2,
        (1, 2),
        "F2F3",
        tuple(replace(a, subset=s, name=n) for a, s, n in zip(axes, ((1,), (1, 2), (2,)), ("F2", "F2F3", "F3"))),
        1e-3,
    )
    worse = replace(found_triple, score=5e-3)
    answered, v = baseline_where_better(nested, Validation("reduced", 1, {3: worse, 2: two, 1: one}, {3: triple}), hand)
    assert is_part_of(answered[3], hand) and answered[2] is nested[2] and answered[1] is nested[1]
    assert (v.found[1].sensors, v.found[1].name, [a.subset for a in v.found[1].axes]) == (
        (1,),
        "F2",
        [(1,), (1,), (1,)],
    )
    assert (v.found[2].sensors, v.found[2].name) == ((0, 1), "F1F2")
    assert [(a.subset, a.name) for a in v.found[2].axes] == [((1,), "F2"), ((0, 1), "F1F2"), ((0,), "F1")]

    # through the real evaluator in the paper's cell: the found layouts are the hand's first k, and k = 1 is answered
    # with the hand's own single choice
    objective = load_objective("paper").in_cell("ur10e")
    config = SearchConfig(validation=ValidationConfig(protocol="reduced"), verdict=VerdictConfig(draws=4, scans=7))
    layouts = {k: _as_found(hand, k) for k in (1, 2, 3)}
    first, names = {}, []
    validation = validate(part, objective, layouts, seed=5, protocol="reduced", on_evaluation=first.__setitem__)
    # k = 1 made worse than the hand's single on this draw, k = 2 and 3 better than the hand's (whatever the draw):
    # only the single is answered with the hand's own choice
    scores = {
        1: validation.baseline[1].score * 2,
        2: validation.baseline[2].score / 2,
        3: validation.baseline[3].score / 2,
    }
    worse = replace(validation, found={k: replace(f, score=scores[k]) for k, f in validation.found.items()})
    answered, v = baseline_where_better(layouts, worse, hand)
    assert sorted(k for k in answered if is_part_of(answered[k], hand)) == [1]
    verdicts = confident_verdicts(
        part, objective, answered, v, first, 5, config, on_draw=lambda i, name, result: names.append(name)
    )
    by_k, fewer = verdicts.by_k, verdicts.fewer
    one = by_k[1]
    assert one.decision == Decision.TIE and (one.score.estimate, one.score.low, one.score.high) == (1.0, 1.0, 1.0)
    assert one.found == one.baseline and one.found_name == one.baseline_name == validation.baseline[1].name
    assert confident_line(one).startswith(f"k=1: TIE keep hand {one.baseline_name}: no found layout beat it")
    assert set(names) == {"hand", "found_k3"}  # the single is not evaluated: its side is the hand's evaluation
    assert one.n_draws == max(v.n_draws for v in by_k.values())  # it rode along to the race's last look
    assert fewer_line(fewer).startswith(f"fewer sensors: {one.baseline_name} alone")

    # the folder: layouts/found_k1.toml holds the hand's sensor, comparison.csv its choice, both read back
    sink = SearchFolder(tmp_path)
    sink.layouts(answered, hand)
    sink.validation(v)
    back = load_search(tmp_path, RunConfig(command="search", part_name="part_b", seed=5))
    assert (
        back.layouts[1].names == [validation.baseline[1].name]
        and back.validation.found[1].name == validation.baseline[1].name
    )
    assert [(a.subset, a.name) for a in back.validation.found[1].axes] == [(a.subset, a.name) for a in v.found[1].axes]
    assert [a.median for a in back.validation.found[1].axes] == pytest.approx(
        [a.median for a in v.found[1].axes], rel=1e-12
    )
    assert back.validation.found[3].name == v.found[3].name


def test_where_every_k_is_answered_with_the_hand_choice_the_race_takes_the_kept_draws_of_the_hand_alone(monkeypatch):
    # every k worse than the hand's own choice on the validation's draw: each an exact TIE from the first draw, so no
    # draw can change a decision; the race takes KEPT_DRAWS (here 3 of the budget's 6) of the hand layout alone
    from optipose.model.layout import is_part_of
    from optipose.search import draws
    from optipose.search.validate import baseline_where_better

    monkeypatch.setattr(draws, "KEPT_DRAWS", 3)
    part = load_part("part_b")
    hand = part.layouts["hand"]
    objective = load_objective("paper").in_cell("ur10e")
    config = SearchConfig(validation=ValidationConfig(protocol="reduced"), verdict=VerdictConfig(draws=6, scans=2))
    layouts = {k: _as_found(hand, k) for k in (1, 2, 3)}
    first, names = {}, []
    validation = validate(part, objective, layouts, seed=5, protocol="reduced", on_evaluation=first.__setitem__)
    worse = replace(
        validation, found={k: replace(f, score=validation.baseline[k].score * 2) for k, f in validation.found.items()}
    )
    answered, v = baseline_where_better(layouts, worse, hand)
    assert all(is_part_of(answered[k], hand) for k in (1, 2, 3))
    verdicts = confident_verdicts(
        part, objective, answered, v, first, 5, config, on_draw=lambda i, name, result: names.append((i, name))
    )
    assert names == [(1, "hand"), (2, "hand"), (3, "hand")]
    assert all(x.decision == Decision.TIE and x.n_draws == 3 for x in verdicts.by_k.values())


def test_what_a_users_clock_cut_is_named_with_the_way_to_the_seeds_own_answer():
    from optipose.search.pipeline import SearchReport
    from optipose.search.records import SearchOutcome
    from optipose.verdict.words import clock_line

    rng = np.random.default_rng(3)
    raced = compare_draws(
        [_pairs(rng, i, 1.0) for i in range(3)], FAST, k=3, found_name="F1F2F3", baseline_name="S1S2S3"
    )
    outcome = SearchOutcome({}, {}, {}, {}, [], clock_cut=("greedy:k=2", "selection:k=2"))
    report = SearchReport(outcome, confident=Verdicts({3: replace(raced, ended="clock")}))
    assert report.clock_cut == ("greedy:k=2", "selection:k=2", "verdict:k=3")
    line = clock_line(report.clock_cut, 60.0)
    assert line.startswith(
        "the 60 s clock (--max-time) ended greedy:k=2, selection:k=2, verdict:k=3 before their counts"
    )
    assert "without the clock the seed gives its own, on any machine" in line
    assert clock_line((), 60.0) == "" and clock_line(SearchReport(outcome).clock_cut[:0], 0.0) == ""
