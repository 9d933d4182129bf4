"""A search's BUYs raced again in the common kinds of cell, for a user who named none (search/kinds.py): its own
draws per kind, the choices the search made, the line that says whether a BUY holds in every kind, and kinds.csv
read back as written."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from optipose.evaluate.objective import load_objective
from optipose.io.load import read_kinds
from optipose.io.search import SearchFolder
from optipose.model.layout import Layout, SensorPose
from optipose.model.part import load_part
from optipose.search.budgets import config_from_budget
from optipose.search.config import SearchConfig, ValidationConfig
from optipose.search.kinds import COMMON_KINDS, across_kinds, buys, kinds_of, qualified
from optipose.search.validate import validate
from optipose.seeds import kind_seed, verdict_seed
from optipose.verdict.confidence import Decision, PairedDraw, Verdicts, compare_draws
from optipose.verdict.rules import Rules, VerdictConfig
from optipose.verdict.ruling import Ruling
from optipose.verdict.words import confident_line, kinds_line, open_line, ruling_line

FAST = Rules(replicates=400)


def _draws(rng, ratio: float, n: int = 6) -> list[PairedDraw]:
    """``n`` paired draws whose hand / found is about ``ratio`` on every axis."""
    out = []
    for i in range(n):
        hand = np.abs(rng.normal(size=(20, 3))) * 1e-4
        out.append(PairedDraw(i, hand * np.exp(rng.normal(0.0, 0.03, size=hand.shape)) / ratio, hand))
    return out


def _verdicts(ratio: dict[int, float], seed: int = 0) -> Verdicts:
    rng = np.random.default_rng(seed)
    return Verdicts(
        {k: compare_draws(_draws(rng, r), FAST, k=k, found_name=f"F{k}", baseline_name="S1") for k, r in ratio.items()}
    )


def test_the_line_says_a_buy_holds_in_every_kind_or_on_which_it_depends():
    here = _verdicts({1: 1.5, 2: 1.5})
    assert buys(here) == [1, 2] and all(v.decision == Decision.BUY for v in here.by_k.values())
    kinds = {"cobot": _verdicts({1: 1.5, 2: 1.4}, 1), "linear-axis": _verdicts({1: 0.7, 2: 1.6}, 2)}
    assert kinds["linear-axis"].by_k[1].decision == Decision.KEEP
    one, two = kinds_line(1, kinds), kinds_line(2, kinds)
    assert one.startswith("  k=1 the BUY depends on your cell: holds in cobot 1.5") and "--cell NAME" in one
    assert "not in linear-axis (KEEP 0.7" in one
    assert (
        two.startswith("  k=2 the BUY holds in every common kind of cell: cobot 1.39x") and "linear-axis 1.60x" in two
    )
    assert "(at most 6 draws each)" in two
    assert kinds_line(3, kinds) == ""  # a k not raced there (not a BUY)
    nowhere = kinds_line(1, {"linear-axis": kinds["linear-axis"]})
    assert "holds in" not in nowhere and "not in linear-axis (KEEP" in nowhere


def test_at_a_ranges_ends_the_line_says_where_the_cell_must_lie():
    ends = {"cobot:low": _verdicts({1: 1.4}, 1), "cobot:high": _verdicts({1: 0.95}, 2)}
    line = kinds_line(1, ends)
    assert line.startswith("  k=1 the BUY depends on where your cell lies in its ranges: holds at cobot:low 1.4")
    assert "not at cobot:high (" in line and "optipose calibrate" in line
    both = {"cobot:low": _verdicts({1: 1.4}, 1), "cobot:high": _verdicts({1: 1.3}, 2)}
    assert kinds_line(1, both).startswith("  k=1 the BUY holds at both ends of the cell's ranges: cobot:low 1.4")


def test_a_buy_not_borne_out_at_its_ranges_ends_or_in_the_common_kinds_is_open():
    said = _verdicts({1: 1.5, 2: 1.5, 3: 0.7})
    rng = np.random.default_rng(5)  # one found sensor better than the hand's three, on the same draws
    said = replace(
        said, fewer=compare_draws(_draws(rng, 1.5), FAST, k=1, found_name="F1", baseline_name="S1S2S3", baseline_k=3)
    )
    ends = {"cobot:low": _verdicts({1: 1.4, 2: 1.4}, 1), "cobot:high": _verdicts({1: 0.95, 2: 1.3}, 2)}
    assert ends["cobot:high"].by_k[1].decision != Decision.BUY
    settled = qualified(said, ends)
    one = settled.by_k[1]
    assert (one.decision, one.ended) == (Decision.UNDECIDED, "ends") and one.score == said.by_k[1].score
    assert settled.by_k[2] is said.by_k[2] and settled.by_k[3] is said.by_k[3]  # borne out; not a BUY
    assert said.fewer.decision == Decision.BUY and (settled.fewer.decision, settled.fewer.ended) == (
        Decision.UNDECIDED,
        "ends",
    )  # its one sensor is k = 1's
    assert open_line(one).startswith("  k=1 open: 1.49x") and "depends on where your cell lies" in open_line(one)
    assert one.ruling is None and one.n_draws < 8 and "no one range" not in open_line(one)  # too few to look
    assert "no one range decides it" in open_line(replace(one, n_draws=40))  # looked for, none rules it
    ruled = replace(one, ruling=Ruling("robot.path", 5e-5, True, 0.4))
    assert "no one range" not in open_line(ruled) and "robot path error: found better above 0.05 mm" in ruling_line(
        ruled
    )
    assert qualified(said, {}) is said  # nothing raced again: nothing to qualify
    # in the common kinds (a user who named no cell): a BUY not borne out in every kind is open as well
    kinds = {"cobot": ends["cobot:low"], "linear-axis": ends["cobot:high"]}
    in_kinds = qualified(said, kinds)
    assert (in_kinds.by_k[1].decision, in_kinds.by_k[1].ended) == (Decision.UNDECIDED, "kinds")
    assert in_kinds.by_k[2] is said.by_k[2] and in_kinds.fewer.ended == "kinds"
    assert "depends on your kind of cell" in open_line(in_kinds.by_k[1])


def test_the_cells_a_search_checks_its_buys_in():
    from optipose.cell.config import load_cell
    from optipose.cli.search import _checked_in

    assert _checked_in(None, load_cell("ur10e")) == COMMON_KINDS  # named none: the objective's cell of points
    assert _checked_in("ur10e", load_cell("ur10e")) == ()  # named it: that cell's answer
    assert _checked_in("cobot", load_cell("cobot")) == ("cobot:low", "cobot:high")
    assert _checked_in("cobot:zeroed", load_cell("cobot:zeroed")) == ("cobot:zeroed:low", "cobot:zeroed:high")
    assert load_cell("cobot:zeroed:low").calibration.zeroed and not load_cell("cobot:zeroed:low").ranges
    assert _checked_in(None, load_cell("ideal")) == ()


def test_kinds_csv_reads_back_as_written(tmp_path):
    kinds = {"cobot": _verdicts({1: 1.5, 3: 0.9}, 1), "industrial-arm": _verdicts({1: 1.2}, 2)}
    SearchFolder(tmp_path).kinds(kinds)
    back = read_kinds(tmp_path / "kinds.csv")
    assert list(back) == ["cobot", "industrial-arm"]
    for name, verdicts in kinds.items():
        assert sorted(back[name].by_k) == sorted(verdicts.by_k)
        for k, v in verdicts.by_k.items():
            assert confident_line(back[name].by_k[k]) == confident_line(v)
        assert kinds_line(1, back) == kinds_line(1, kinds)
    assert read_kinds(tmp_path / "none.csv") == {}
    SearchFolder(tmp_path / "empty").kinds({})  # nothing raced: no file
    assert not (tmp_path / "empty" / "kinds.csv").exists()


def test_only_a_user_who_named_no_cell_gets_the_common_kinds_and_an_override_wins():
    assert kinds_of(config_from_budget("quick", (1, 2), cell=True, kinds=COMMON_KINDS)) == list(COMMON_KINDS)
    assert kinds_of(config_from_budget("quick", (1, 2), cell=True)) == []
    from optipose.search.config import search_preset

    mine = search_preset({"verdict": {"kinds": "cobot", "kinds_draws": 4}})
    config = config_from_budget("default", (1,), mine, cell=True, kinds=COMMON_KINDS)
    assert kinds_of(config) == ["cobot"] and config.verdict.kinds_draws == 4


def test_a_buy_is_raced_again_in_each_kind_on_draws_of_its_own_with_the_searchs_choices():
    """The hand layout found again, said to be bought at k = 3 (a TIE in truth: the hand's own three sensors): in
    each kind its race is the search's race on the kind's own draws, an exact tie, so the line says the BUY is not
    shown there."""
    part = load_part("part_b")
    objective = load_objective("paper")  # ur10e: a cell of points, as a user who names none gets
    hand = part.layouts["hand"]
    layouts = {
        k: Layout(tuple(SensorPose(f"F{i + 1}", s.T_O_S) for i, s in enumerate(hand.sensors[:k]))) for k in (1, 2, 3)
    }
    layouts = {k: replace(lay, name=f"found_k{k}") for k, lay in layouts.items()}
    validation = validate(part, objective, layouts, seed=5, protocol="reduced", scans=4)
    config = SearchConfig(
        validation=ValidationConfig(protocol="reduced"),
        verdict=VerdictConfig(draws=40, scans=2, kinds="cobot,linear-axis", kinds_draws=3),
    )
    said = _verdicts({1: 1.0, 3: 1.5})  # the search's verdicts: a BUY at k = 3 only
    assert buys(said) == [3]
    kinds = across_kinds(part, objective, layouts, validation, said, 5, config)
    assert list(kinds) == ["cobot", "linear-axis"]
    for name, verdicts in kinds.items():
        assert sorted(verdicts.by_k) == [3]  # the BUY alone
        v = verdicts.by_k[3]
        assert v.decision == Decision.TIE and (v.score.low, v.score.high) == (1.0, 1.0) and v.n_draws <= 3
    assert kind_seed(5, 0) != kind_seed(5, 1) and kind_seed(5, 0) not in {verdict_seed(5, i) for i in range(50)}
    line = kinds_line(3, kinds)
    assert "depends on your cell" in line and "cobot (TIE 1.00x [1.00, 1.00])" in line
    assert across_kinds(part, objective, layouts, validation, _verdicts({1: 1.0}), 5, config) == {}  # no BUY
