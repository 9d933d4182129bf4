"""The verdict with confidence (optipose/verdict/confidence.py and racing.py, issue #33) on synthetic per-scan errors:
a layout against itself on the same draws is an exact tie, a BUY needs the interval, racing stops when the
interval is clear, the intervals cover the true ratio at their nominal rate, and all of it is reproducible."""

from __future__ import annotations

from dataclasses import dataclass, replace

import warnings
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from optipose.verdict import racing
from optipose.evaluate.assignment import UNOBSERVABLE, UNOBSERVABLE_PENALTY, AxisChoice, Choice
from optipose.verdict.confidence import (
    Decision,
    Interval,
    PairedDraw,
    compare_draws,
    paired_draw,
    paired_draws,
    scan_errors,
)
from optipose.verdict.racing import looks, race
from optipose.verdict.words import axis_lines, confident_line, fewer_line, open_line, ratio_cell
from optipose.verdict.rules import Rules
from optipose.evaluate.statistics import FAILED_ERROR

N_SCANS = 77
FAST = Rules(replicates=400)


def _draws(rng, n_draws, ratio=1.0, extra=0.1, cell=0.2, start=0):
    """Paired draws shaped like per-scan |errors| (rad): per draw a cell scale shared by both layouts, found's
    own factor exp(N(0, extra)) / ratio, the two layouts' scans correlated (0.5). The true hand / found of
    any statistic's expectation over draws is ratio · exp(-extra² / 2)."""
    out = []
    for i in range(n_draws):
        a = 1e-4 * np.exp(rng.normal(0.0, cell))
        z = rng.normal(size=(N_SCANS, 3))
        w = 0.5 * z + np.sqrt(0.75) * rng.normal(size=(N_SCANS, 3))
        out.append(PairedDraw(start + i, np.abs(w) * a * np.exp(rng.normal(0.0, extra)) / ratio, np.abs(z) * a))
    return out


def test_a_layout_against_itself_on_the_same_draws_is_an_exact_tie():
    rng = np.random.default_rng(1)
    same = [PairedDraw(d.seed, d.baseline.copy(), d.baseline) for d in _draws(rng, 4)]
    verdict = compare_draws(same, FAST, k=2, found_name="S1S2", baseline_name="S1S2")
    assert verdict.decision == Decision.TIE
    assert (verdict.score.estimate, verdict.score.low, verdict.score.high) == (1.0, 1.0, 1.0)
    assert all((a.ratio.low, a.ratio.high, a.median.low, a.p75.high) == (1.0, 1.0, 1.0, 1.0) for a in verdict.axes)
    assert verdict.found == verdict.baseline  # the predicted errors too
    for n in (1, 2, 3):  # with any number of draws, even one
        assert compare_draws(same[:n], FAST).decision == Decision.TIE


def test_a_buy_needs_the_interval_not_the_point_estimate():
    hand = _draws(np.random.default_rng(2), 1)[0].baseline
    # found 5 % better in sum on these three draws, but by 1.6x on one and worse on two: a wide interval
    wide = [PairedDraw(i, hand / f, hand) for i, f in enumerate((1.6, 0.85, 0.95))]
    verdict = compare_draws(wide, FAST)
    assert verdict.score.estimate == pytest.approx(3 / (1 / 1.6 + 1 / 0.85 + 1 / 0.95))
    assert 1.04 < verdict.score.estimate < 1.06
    assert verdict.score.low < 1.0 < verdict.score.high
    assert verdict.decision == Decision.UNDECIDED and verdict.more_draws > 0
    # the same 5 % on every draw and scan: the interval is the point, and found is bought
    tight = [PairedDraw(i, hand / 1.05, hand) for i in range(3)]
    verdict = compare_draws(tight, FAST)
    assert verdict.decision == Decision.BUY and verdict.score.low == pytest.approx(1.05)


def test_keep_when_hand_is_better_in_sum_or_an_axis_is_worse_beyond_the_tolerance():
    hand = _draws(np.random.default_rng(3), 1)[0].baseline
    assert compare_draws([PairedDraw(0, hand * 1.3, hand)], FAST).decision == Decision.KEEP
    # 2x better on roll and pitch, 1.5x worse on yaw: better in sum, and yaw's error alone adds about a sixth
    # to the hand layout's total (each axis about a third of it): worse on yaw beyond 10 %
    found = hand / np.array([2.0, 2.0, 1 / 1.5])
    verdict = compare_draws([PairedDraw(0, found, hand)], FAST, k=1, found_name="F1", baseline_name="S2")
    assert verdict.score.low > 1.0 and verdict.decision == Decision.KEEP
    assert "worse on yaw" in confident_line(verdict)
    # 5 % worse on yaw, within the tolerance, and better in sum: bought
    found = hand / np.array([1.5, 1.5, 1 / 1.05])
    assert compare_draws([PairedDraw(0, found, hand)], FAST).decision == Decision.BUY


def test_a_layout_that_fails_more_registrations_is_not_bought_for_a_better_score():
    rng = np.random.default_rng(7)
    hand = [d.baseline for d in _draws(rng, 10)]
    # found 1.6x better on every scan, but its pitch registration fails on 2, 1, 0, 0, 0, 0, 1, 2, 0, 1 of 77 scans
    # (hand's never): the medians and p75s do not see it, the failed share does
    counts = (2, 1, 0, 0, 0, 0, 1, 2, 0, 1)
    draws = []
    for i, (h, c) in enumerate(zip(hand, counts)):
        f = h / 1.6
        f[:c, 1] = FAILED_ERROR
        draws.append(PairedDraw(i, f, h))
    verdict = compare_draws(draws, FAST, k=3, found_name="F1F2F3", baseline_name="S1S2S3")
    assert verdict.score.low > 1.0  # better in sum with confidence
    pitch = verdict.axes[1].failed
    # the interval by hand: the scans' spread (each draw's 0/1 per scan, c(n - c) / (n(n - 1)) over n) exceeds the
    # draws' here, so Student's t on every scan's degrees of freedom (10 x 76) over the draws' mean of it
    shares = np.array(counts) / N_SCANS
    within = np.mean([c * (N_SCANS - c) / (N_SCANS * (N_SCANS - 1)) / N_SCANS for c in counts])
    assert within > shares.var(ddof=1)
    half = 1.963087 * np.sqrt(within / len(counts))  # t(0.975, 760)
    assert pitch.estimate == pytest.approx(shares.mean())
    assert (pitch.low, pitch.high) == pytest.approx((shares.mean() - half, shares.mean() + half), rel=1e-4)
    assert pitch.low < 0.01 < pitch.high  # found may fail more than one scan in a hundred: not bought
    assert verdict.decision == Decision.UNDECIDED and verdict.more_draws > 0
    assert confident_line(verdict) == "k=3: UNDECIDED F1F2F3 1.60x [1.58, 1.60] vs hand S1S2S3; pitch fails +0.9 %"
    assert all((a.failed.low, a.failed.high) == (0.0, 0.0) for a in (verdict.axes[0], verdict.axes[2]))
    # found failing 5 of 77 pitch scans on every draw: more than 1 % with confidence, so the hand layout is kept
    for d in draws:
        d.found[:5, 1] = FAILED_ERROR
    verdict = compare_draws(draws, FAST, k=3, found_name="F1F2F3", baseline_name="S1S2S3")
    assert verdict.decision == Decision.KEEP and "fails 6.5 % more pitch" in confident_line(verdict)
    # failures beyond a tolerance of 10 %: bought, as on its score alone
    assert compare_draws(draws, Rules(replicates=400, failures=0.1)).decision == Decision.BUY
    # the same failures on both sides, scan for scan, are no difference at all
    same = [PairedDraw(d.seed, d.found, np.where(d.found == FAILED_ERROR, FAILED_ERROR, d.found * 1.6)) for d in draws]
    verdict = compare_draws(same, FAST)
    assert verdict.decision == Decision.BUY and all((a.failed.low, a.failed.high) == (0.0, 0.0) for a in verdict.axes)


def test_a_keep_for_failures_says_why_in_80_columns_and_a_zero_tolerance_still_counts_the_draws_to_add():
    rng = np.random.default_rng(8)
    draws = []
    for i, d in enumerate(_draws(rng, 6)):
        f = d.baseline / np.array([1.6, 1 / 1.5, 1.6])  # worse on pitch beyond the tolerance
        f[:5, 1] = FAILED_ERROR  # and failing it on 5 of 77 scans where hand never does
        draws.append(PairedDraw(i, f, d.baseline))
    verdict = compare_draws(draws, FAST, k=3, found_name="F1F2F3", baseline_name="S1S2S3", reference="conventional")
    line = confident_line(verdict)
    assert verdict.decision == Decision.KEEP and len(line) <= 80, line
    assert "worse on pitch" in line and "fails 6.5 % more pitch" in line  # the reasons kept, the ratio left out
    # a tolerance of 0 with no failure on either side: met (its test is <=), and the draws to add come from the rest
    close = [PairedDraw(d.seed, d.baseline / 1.02, d.baseline) for d in _draws(np.random.default_rng(9), 3)]
    strict = compare_draws(close, Rules(replicates=400, tolerance=0.0, failures=0.0))
    assert all((a.failed.low, a.failed.high) == (0.0, 0.0) for a in strict.axes)
    assert strict.decision in (Decision.BUY, Decision.UNDECIDED) and (
        strict.decision == Decision.BUY or strict.more_draws is not None
    )


def test_an_axis_is_worse_by_what_it_adds_to_the_hand_layouts_total():
    """The tolerance is a share of the hand layout's score: an axis of a fiftieth of it may double, one of a
    third may not grow by a third. Checked against the hand computation of the axis's test."""
    hand = _draws(np.random.default_rng(3), 1)[0].baseline * np.array([0.03, 1.0, 1.0])  # roll a small share
    found = hand / np.array([0.5, 1.5, 1.5])  # roll twice the hand's, pitch and yaw 1.5x better
    verdict = compare_draws([PairedDraw(0, found, hand)], FAST)
    share = lambda x: np.median(x, axis=0) + np.percentile(x, 75, axis=0)  # noqa: E731
    h, f = share(hand), share(found)
    assert verdict.axes[0].ratio.estimate == pytest.approx(h.sum() / (h.sum() - h[0] + f[0]))
    assert verdict.axes[0].ratio.estimate > 1 / 1.1 and verdict.axes[0].median.estimate == pytest.approx(0.5)
    assert verdict.decision == Decision.BUY
    # roll doubled where it is a third of the total adds a third: found is kept, though better in sum
    hand = _draws(np.random.default_rng(3), 1)[0].baseline
    verdict = compare_draws([PairedDraw(0, hand / np.array([0.5, 3.0, 3.0]), hand)], FAST)
    assert verdict.score.low > 1.0 and verdict.decision == Decision.KEEP and "worse on roll" in confident_line(verdict)


def test_racing_stops_when_the_interval_is_clear():
    rng = np.random.default_rng(4)
    verdict = race(lambda i: _draws(rng, 1, ratio=2.0, start=i)[0], FAST, min_draws=3, max_draws=40, k=2)
    assert verdict.decision == Decision.BUY and verdict.n_draws <= 5  # the first or second look
    assert verdict.confidence > 0.95  # each look spends a share of the 5 %
    # an exact copy on the same draws: a tie at the first look
    verdict = race(lambda i: PairedDraw(i, *(2 * [_draws(rng, 1)[0].baseline])), FAST, max_draws=40)
    assert verdict.decision == Decision.TIE and verdict.n_draws == 3


def test_a_race_whose_draws_leave_out_an_undecided_key_says_so_instead_of_waiting_forever():
    rng = np.random.default_rng(10)
    draws = _draws(rng, 6, ratio=1.0)
    with pytest.raises(ValueError, match=r"no paired draw for \['2'\] at position 0"):
        racing.race_many(lambda i, keys: {1: draws[i]}, FAST, min_draws=3, max_draws=6, draws={1: [], 2: []})


def test_racing_a_layout_better_by_the_tolerance_runs_to_the_budget():
    rng = np.random.default_rng(5)
    calls = []

    def little(i):
        calls.append(i)
        return _draws(rng, 1, ratio=1.1, start=i)[0]

    verdict = race(little, FAST, min_draws=3, max_draws=8)
    assert calls == list(range(8)) and verdict.n_draws == 8
    assert verdict.decision == Decision.UNDECIDED and verdict.more_draws > 0
    # as the rules say: neither better, nor within 10 %, nor short of a 10 % gain
    assert verdict.score.low < 1.0 < 1.1 < verdict.score.high
    assert not verdict.score.within(1 / 1.1, 1.1)


def test_racing_an_equal_layout_stops_early_as_keep_it_cannot_gain_the_tolerance():
    """The futility stop: found no better than hand, the score's interval below 1 + tolerance at the first look:
    KEEP, its line saying why; a layout that does gain more than the tolerance is turned away so at most at the
    intervals' one-sided rate (2.5 %; 5 % allowed over these 100 races)."""
    rng = np.random.default_rng(5)
    equal = race(lambda i: _draws(rng, 1, ratio=1.0, start=i)[0], FAST, min_draws=3, max_draws=8)
    assert equal.decision == Decision.KEEP and equal.n_draws == 3
    assert equal.score.low < 1.0 < equal.score.high < 1.1
    assert confident_line(equal).startswith("k=0: KEEP hand hand; found") and "gains under 10 %" in confident_line(
        equal
    )
    turned = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        better = race(lambda i: _draws(rng, 1, ratio=1.15, start=i)[0], FAST, min_draws=3, max_draws=8)
        turned += better.decision == Decision.KEEP
    assert turned <= 5


def test_racing_stops_before_a_draw_would_end_past_the_time_budget():
    rng, now = np.random.default_rng(6), [0.0]

    def slow(i):
        now[0] += 10.0  # each draw takes 10 s of the fake clock
        return _draws(rng, 1, ratio=1.0, start=i)[0]

    verdict = race(slow, FAST, min_draws=3, max_draws=40, seconds=45.0, clock=lambda: now[0])
    assert verdict.n_draws == 4 and verdict.seconds_per_draw == 10.0  # a fifth would end at 50 s
    if verdict.decision == Decision.UNDECIDED:
        assert verdict.more_minutes == pytest.approx(verdict.more_draws * 10.0 / 60.0)
        assert confident_line(verdict).endswith(f"(4 draws; +{verdict.more_draws})")  # no minutes: the machine's
        assert verdict.ended == "clock" and "the clock ended the race at 4 draws" in open_line(verdict)
        assert f"about {verdict.more_minutes:.0f} min here" in open_line(verdict)


def test_the_race_plans_its_looks_for_the_draws_its_time_holds():
    rng, now = np.random.default_rng(6), [0.0]

    def slow(i):
        now[0] += 10.0
        return _draws(rng, 1, ratio=1.0, start=i)[0]

    # 3 draws take 30 s of 45: the time holds one more, so the looks are at 3 and 4; the one at 3 spends
    # (3/4)^ρ of the 5 %, the last the rest
    verdict = race(slow, FAST, min_draws=3, max_draws=40, seconds=45.0, clock=lambda: now[0])
    assert verdict.n_draws == 4 and verdict.confidence == pytest.approx(1 - 0.05 * (1 - (3 / 4) ** racing.SPENDING))
    # draws slow down after the plan (3, 5, 8, 9) is made: the time ends the race at 5, whose last look
    # spends what the look at 3 left: the shares of the looks at 5, 8 and 9
    now[0], took = 0.0, iter([5.0, 5.0, 5.0, 20.0, 20.0] + [20.0] * 10)

    def slowing(i):
        now[0] += next(took)
        return _draws(rng, 1, ratio=1.0, start=i)[0]

    verdict = race(slowing, FAST, min_draws=3, max_draws=40, seconds=45.0, clock=lambda: now[0])
    assert verdict.n_draws == 5 and verdict.confidence == pytest.approx(1 - 0.05 * (1 - (3 / 9) ** racing.SPENDING))


@pytest.mark.parametrize("seed", range(20))
def test_the_looks_made_spend_at_most_the_error_rate(seed, monkeypatch):
    """Whatever the draws' times and the budgets, the looks a race makes spend at most its 5 % in all."""
    rng, now, spent = np.random.default_rng(seed), [0.0], []

    @dataclass(frozen=True)
    class Open:  # what the race reads of a verdict: its decision, and what ended it
        decision: Decision = Decision.UNDECIDED
        ended: str = ""

    def undecided(draws, rules, **names):
        spent.append(1.0 - rules.confidence)
        return Open()

    monkeypatch.setattr(racing, "compare_draws", undecided)

    def draw(i):
        now[0] += float(rng.exponential(rng.choice([1.0, 5.0])))
        return None

    racing.race(
        draw,
        FAST,
        min_draws=int(rng.integers(1, 5)),
        max_draws=int(rng.integers(1, 30)),
        seconds=float(rng.choice([np.inf, rng.uniform(1.0, 60.0)])),
        clock=lambda: now[0],
    )
    assert spent and sum(spent) <= 0.05 + 1e-12


def test_an_early_looks_wide_interval_does_not_hang_on_a_few_replicates():
    """At 99.9 % (a racing look's share) the interval is the 95 % one's, widened by the quantiles' ratio: as
    steady from one bootstrap seed to the next as the 95 % one, not the one or two most extreme replicates."""
    draws = _draws(np.random.default_rng(7), 5, ratio=1.3)
    widths = {
        c: [
            np.log(v.score.high / v.score.low)
            for v in (compare_draws(draws, Rules(confidence=c, seed=s)) for s in range(6))
        ]
        for c in (0.95, 0.999)
    }
    for c, w in widths.items():
        assert np.ptp(w) / np.mean(w) < 0.05, (c, w)
    assert 2.0 < np.mean(widths[0.999]) / np.mean(widths[0.95]) < 4.0  # wider, by about t(0.9995)/t(0.975) at 4 df


def test_an_interval_widened_past_any_scale_stays_finite():
    """Two draws of few scans can widen an early look's deviations a thousandfold: the sides stay numbers."""
    from optipose.verdict.bootstrap import log_interval
    from optipose.verdict.confidence import Interval

    samples = np.random.default_rng(0).normal(-4.6, 0.25, 2000)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        iv = Interval(*log_interval(-4.6, samples, 1443.9, 0.9998))
        deg = Interval(*log_interval(-4.6, samples, 1443.9, 0.9998, lambda v: np.rad2deg(np.exp(v))))
    assert 0.0 <= iv.low < iv.estimate < iv.high < np.inf and deg.high < np.inf


def test_the_looks_spend_little_early_and_most_at_the_last():
    plan = looks(3, 9)
    shares = np.diff([0.0] + [racing.spent(n, plan) for n in plan])
    assert plan == (3, 5, 8, 9) and shares.sum() == pytest.approx(1.0)
    assert np.all(np.diff(shares[:-1]) > 0) and shares[0] < 0.15  # growing; the first look's share 1/9
    assert racing.spent(8, plan) == pytest.approx((8 / 9) ** racing.SPENDING) and racing.spent(
        9, plan
    ) == 1.0 == racing.spent(12, plan)


def test_the_looks():
    assert looks(3, 20) == (3, 5, 8, 12, 18, 20)
    assert looks(3, 3) == (3,)
    assert looks(1, 4) == (1, 2, 3, 4)


@pytest.mark.parametrize("n_draws, extra", [(5, 0.1), (3, 0.3)])
def test_intervals_cover_the_true_ratio_at_their_nominal_rate(n_draws, extra):
    rng, trials = np.random.default_rng(7 + n_draws), 200
    truth = 1.2 * np.exp(-(extra**2) / 2)
    score = median = 0
    for t in range(trials):
        verdict = compare_draws(_draws(rng, n_draws, ratio=1.2, extra=extra), Rules(replicates=300, seed=t))
        score += verdict.score.low <= truth <= verdict.score.high
        median += verdict.axes[0].median.low <= truth <= verdict.axes[0].median.high
    sd = np.sqrt(0.95 * 0.05 / trials)  # binomial: 1.5 %
    assert 0.95 - 3 * sd <= score / trials <= 0.95 + 3 * sd
    assert 0.95 - 3 * sd <= median / trials <= 0.95 + 3 * sd


def test_reproducible_from_the_seed():
    draws = _draws(np.random.default_rng(8), 4, ratio=1.1)
    one, two = compare_draws(draws, Rules(seed=3)), compare_draws(draws, Rules(seed=3))
    assert one == two
    other = compare_draws(draws, Rules(seed=4))
    assert other.score.estimate == one.score.estimate and other.score.low != one.score.low


def test_a_ratio_past_a_thousand_is_written_so_and_a_few_draws_fewer_line_still_ends_in_its_words():
    # three draws' Student interval reached 4.5e21 in a search's fewer-sensors line, and the line was cut at 80
    # columns in the middle of "not settled"
    assert ratio_cell(Interval(1.12, 0.0, 4.47e21)) == "1.12x [0.00, >999]"
    assert ratio_cell(Interval(999.994, 2.5, 1000.0)) == "999.99x [2.50, >999]"
    assert ratio_cell(Interval(1.0, float("nan"), 2.0)) == "1.00x [nan, 2.00]"
    rng = np.random.default_rng(9)
    hand = _draws(rng, 1)[0].baseline
    wide = compare_draws(
        [PairedDraw(0, hand, hand)] * 2, FAST, k=1, found_name="F1", baseline_name="S1S2S3", baseline_k=3
    )
    wide = replace(wide, decision=Decision.UNDECIDED, score=Interval(1.12, 0.0, 4.47e21))
    line = fewer_line(wide)
    assert len(line) <= 80 and line.endswith("not settled") and ">999" in line


def test_one_line_of_at_most_80_columns_naming_the_sensors():
    rng = np.random.default_rng(9)
    hand = _draws(rng, 1)[0].baseline
    cases = {Decision.BUY: hand / 1.5, Decision.KEEP: hand * 1.5, Decision.TIE: hand}
    for decision, found in cases.items():
        verdict = compare_draws(
            [PairedDraw(0, found, hand)] * 2, FAST, k=3, found_name="F1F2F3", baseline_name="S1S2S3"
        )
        assert verdict.decision == decision
        line = confident_line(verdict)
        assert len(line) <= 80 and line.startswith(f"k=3: {decision}") and "F1F2F3" in line and "S1S2S3" in line
    verdict = race(
        lambda i: _draws(rng, 1, start=i)[0],
        FAST,
        max_draws=4,
        k=3,
        found_name="F1F2F3",
        baseline_name="S1S2S3",
        reference="conventional",
    )
    assert (
        verdict.decision == Decision.UNDECIDED
        and len(confident_line(verdict)) <= 80
        and "conventional S1S2S3" in confident_line(verdict)
    )
    assert all(len(line) <= 80 for line in axis_lines(verdict))
    # one found sensor against the conventional placement's three: the long names fit, the ratio whole
    for decision, found in {**cases, Decision.UNDECIDED: None}.items():
        draws = [PairedDraw(0, found, hand)] * 2 if found is not None else _draws(rng, 2, extra=0.5)
        fewer = compare_draws(
            draws, FAST, k=1, found_name="F1", baseline_name="S1S2S3", reference="conventional", baseline_k=3
        )
        line, s = fewer_line(fewer), fewer.score
        assert fewer.decision == decision and len(line) <= 80, line
        assert "F1 alone" in line and "conventional S1S2S3" in line and ratio_cell(s) in line


def _result(seed, errors, ok, subsets=("S1", "S2", "S1S2")):
    rows = [
        {
            "scan": s,
            "subset": name,
            "ok": bool(ok[s]),
            "err_roll": -errors[s],
            "err_pitch": 2 * errors[s],
            "err_yaw": 3 * errors[s],
        }
        for s in range(len(errors))
        for name in subsets
    ]
    per_scan = pd.DataFrame(rows).sample(frac=1.0, random_state=0)  # any row order
    return SimpleNamespace(seed=seed, n_scans=len(errors), per_scan=per_scan)


def test_scan_errors_take_each_axis_from_its_subset():
    errors, ok = np.array([1e-4, 2e-4, 3e-4]), np.array([True, False, True])
    axes = (
        AxisChoice("roll", (0,), "S1", 0.0, 0.0),
        AxisChoice("pitch", (0, 1), "S1S2", 0.0, 0.0),
        AxisChoice("yaw", (), "", np.nan, np.nan, UNOBSERVABLE),
    )
    choice = Choice(2, (0, 1), "S1S2", axes, 0.0)
    out = scan_errors(_result(1, errors, ok), choice)
    np.testing.assert_array_equal(out[:, 0], [1e-4, FAILED_ERROR, 3e-4])
    np.testing.assert_array_equal(out[:, 1], [2e-4, FAILED_ERROR, 6e-4])
    np.testing.assert_array_equal(out[:, 2], [UNOBSERVABLE_PENALTY] * 3)
    draw = paired_draw(_result(1, errors, ok), choice, _result(1, errors, ok), choice)
    assert draw.seed == 1 and np.array_equal(draw.found, draw.baseline)
    with pytest.raises(ValueError, match="not a paired draw"):
        paired_draw(_result(1, errors, ok), choice, _result(2, errors, ok), choice)
    found = [_result(s, errors, ok) for s in (3, 1)]
    assert [d.seed for d in paired_draws(found, choice, [_result(s, errors, ok) for s in (1, 3)], choice)] == [3, 1]
    with pytest.raises(ValueError, match="no hand evaluation"):
        paired_draws(found, choice, [_result(1, errors, ok)], choice)


def test_when_neither_layout_measures_anything_the_line_says_so_not_tie():
    # a sphere: every axis unobservable for found and hand alike, the penalty on every scan of every draw
    blind = np.full((20, 3), UNOBSERVABLE_PENALTY)
    verdict = compare_draws(
        [PairedDraw(i, blind, blind) for i in range(2)], FAST, k=2, found_name="F1F2", baseline_name="S1S2"
    )
    assert verdict.unmeasured == ["roll", "pitch", "yaw"]
    assert confident_line(verdict) == "k=2: nothing measured: F1F2 and hand S1S2 see no roll/pitch/yaw"
    wide = compare_draws(
        [PairedDraw(i, blind, blind) for i in range(2)],
        FAST,
        k=3,
        found_name="F1F2F3",
        baseline_name="S1S2S3",
        reference="conventional",
    )
    assert confident_line(wide) == "k=3: nothing measured: F1F2F3 and conventional S1S2S3 see no roll/pitch/yaw"
    assert len(confident_line(wide)) <= 80
    from optipose.verdict.words import interval_cell

    assert interval_cell(verdict.found[0].median_deg) == "not measured"
    # one axis measured: the usual line, and that axis's cell a number
    seen = blind.copy()
    seen[:, 0] = np.deg2rad(0.01)
    verdict = compare_draws(
        [PairedDraw(i, seen, seen) for i in range(2)], FAST, k=2, found_name="F1F2", baseline_name="S1S2"
    )
    assert verdict.unmeasured == ["pitch", "yaw"] and confident_line(verdict).startswith("k=2: TIE")
    assert interval_cell(verdict.found[0].median_deg) != "not measured"


def test_each_way_a_race_ends_open_says_what_keeps_it_open_and_what_would_settle_it():
    """An UNDECIDED line's reason: what keeps it open (the sum spanning 1, an axis spanning the tolerance, extra
    failures spanning theirs) and what would settle it (draws, or that none within the budgets can, or that no
    number of draws would); how it ended (the budget's draws, or a clock). A decided verdict has no such line."""
    rng = np.random.default_rng(5)
    equal = race(lambda i: _draws(rng, 1, ratio=1.1, start=i)[0], FAST, min_draws=3, max_draws=8)
    assert equal.decision == Decision.UNDECIDED and equal.ended == "draws" and equal.more_draws is not None
    sum_open = replace(equal, axes=tuple(replace(a, ratio=Interval(1.0, 0.95, 1.05)) for a in equal.axes))
    line = open_line(sum_open, 30)
    assert line.startswith(f"  k=0 open: the sum {ratio_cell(equal.score)} spans 1 after the budget's 8 draws; ")
    within = equal.n_draws + equal.more_draws <= 30
    assert (f"+{equal.more_draws} draws would settle it" in line) and (("none within them can" in line) != within)
    # an axis whose interval spans the tolerance, the sum clear of 1
    axis = replace(
        equal,
        score=Interval(1.5, 1.2, 1.9),
        axes=(replace(equal.axes[0], ratio=Interval(1.0, 0.8, 1.2)),) + equal.axes[1:],
    )
    assert f"open: {equal.axes[0].axis} 1.00x [0.80, 1.20] spans 0.91" in open_line(axis, 30)
    # extra failed registrations spanning the rule's 1 %
    fails = replace(
        axis,
        axes=(replace(equal.axes[0], ratio=Interval(1.3, 1.2, 1.4), failed=Interval(0.01, -0.005, 0.03)),)
        + equal.axes[1:],
    )
    assert f"open: {equal.axes[0].axis} fails -0.5 to +3.0 % more, across 1 %" in open_line(fails, 30)
    # beyond every budget's draws, and beyond any number of them
    assert "more than any budget races (30): none within them can" in open_line(replace(equal, more_draws=500), 30)
    assert "no number of draws settles it at these estimates" in open_line(replace(equal, more_draws=None), 30)
    # a clock that ended the race, and a decided verdict
    assert "the clock ended the race at 8 draws (without --max-time" in open_line(replace(equal, ended="clock"), 30)
    assert open_line(replace(equal, decision=Decision.BUY), 30) == ""


def test_one_cells_interval_holds_a_new_instance_as_often_as_it_says():
    """:func:`one_cell` from n draws of a log-normal instance spread holds a further instance in 90 % of races, at
    any n, and needs two draws; a penalty (an axis not measured) gives no interval."""
    from optipose.evaluate.statistics import FAILED_ERROR
    from optipose.verdict.confidence import ONE_CELL, one_cell

    rng = np.random.default_rng(11)
    for n in (3, 5, 12):
        held = []
        for _ in range(4000):
            x = np.exp(rng.normal(np.log(0.05), 0.6, n + 1))  # degrees: n draws and the user's cell
            iv = one_cell(x[:n])
            held.append(iv.low <= x[n] <= iv.high)
        assert abs(np.mean(held) - ONE_CELL) < 0.015, (n, np.mean(held))
    iv = one_cell([0.01, 0.04])
    assert iv.estimate == pytest.approx(0.02) and iv.low < 0.01 and iv.high > 0.04
    assert np.isnan(one_cell([0.02]).low) and np.isnan(one_cell([0.02, np.degrees(FAILED_ERROR)]).low)


def test_a_verdicts_one_cell_interval_is_of_its_draws_medians():
    """Each axis's one-cell interval is :func:`one_cell` of the draws' medians of that layout's per-scan errors."""
    from optipose.verdict.confidence import one_cell

    rng = np.random.default_rng(2)
    draws = [
        PairedDraw(s, np.abs(rng.normal(0, 1e-3 * (1 + s % 3), (20, 3))), np.abs(rng.normal(0, 2e-3, (20, 3))))
        for s in range(6)
    ]
    v = compare_draws(draws, Rules(replicates=200))
    for j, (found, hand) in enumerate(zip(v.found, v.baseline)):
        assert found.one_cell == one_cell([np.degrees(np.median(d.found[:, j])) for d in draws])
        assert hand.one_cell == one_cell([np.degrees(np.median(d.baseline[:, j])) for d in draws])
        assert found.one_cell.low < found.median_deg.low  # one cell spreads wider than the expected median
