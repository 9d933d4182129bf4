"""Which range rules a verdict in a cell of ranges (optipose.verdict.ruling): a ratio made to cross 1 at a known
magnitude is found there, on the right side; pure noise rules nothing (at about the rate the threshold is set for);
a layout against itself is ruled by nothing."""

from __future__ import annotations

import numpy as np
import pytest

from optipose.cell.ranges import draws
from optipose.verdict.confidence import ConfidentVerdict, Decision, Interval, PairedDraw
from optipose.verdict.ruling import Ruling, draw_ratio, place, ruling
from optipose.verdict.words import ruling_line

RANGES = (
    ("calibration.frame_rotation", 8.7e-5, 3.5e-3),
    ("calibration.sensor_translation", 7.5e-6, 1.5e-4),
    ("process_scale", 0.5, 2.0),
    ("robot.path", 1.4e-5, 1.4e-4),
    ("robot.path_rotation", 0.0, 8.7e-5),
    ("robot.step", 0.0, 6.5e-4),
)


def _instances(n: int, first: int = 1000) -> list[dict]:
    return [draws(RANGES, seed) for seed in range(first, first + n)]


def test_a_ratio_that_grows_with_the_path_error_is_ruled_by_it_where_it_crosses_one():
    rng = np.random.default_rng(0)
    cells = _instances(40)
    at = 4e-5  # found better above a 0.04 mm path error, as a layout that averages the path out is
    ratios = [(c["robot.path"] / at) ** 0.8 * np.exp(rng.normal(0, 0.1)) for c in cells]
    r = ruling(ratios, cells, RANGES)
    assert r is not None and r.key == "robot.path" and r.above
    assert r.at == pytest.approx(at, rel=0.25)
    assert r.share > 0.8


def test_a_ratio_that_falls_with_the_process_scale_is_ruled_below_its_crossing():
    rng = np.random.default_rng(1)
    cells = _instances(40)
    ratios = [np.exp(-1.2 * np.log(c["process_scale"]) + rng.normal(0, 0.1)) for c in cells]
    r = ruling(ratios, cells, RANGES)
    assert r is not None and r.key == "process_scale" and not r.above
    assert r.at == pytest.approx(1.0, rel=0.15)


def test_noise_rules_nothing_at_about_the_rate_the_threshold_is_set_for():
    rng = np.random.default_rng(2)
    cells = _instances(40)
    false = sum(ruling(np.exp(rng.normal(0, 0.3, 40)), cells, RANGES) is not None for _ in range(400))
    assert false / 400 < 0.03


def test_a_ratio_that_does_not_cross_one_inside_the_range_rules_nothing():
    cells = _instances(40)
    ratios = [2.0 * (c["robot.path"] / 1.4e-5) ** 0.3 for c in cells]  # better everywhere, more so at the top
    assert ruling(ratios, cells, RANGES) is None


def test_a_layout_against_itself_is_ruled_by_nothing():
    rng = np.random.default_rng(3)
    pairs = [PairedDraw(s, e, e) for s, e in ((s, rng.random((3, 3))) for s in range(40))]
    ratios = [draw_ratio(p, (1, 1, 1), 1.0, 1.0) for p in pairs]
    assert ratios == [1.0] * 40
    assert ruling(ratios, _instances(40), RANGES) is None


def test_place_is_the_draws_quantile():
    assert place(1.4e-5, 1.4e-5, 1.4e-4) == 0.0
    assert place(np.sqrt(1.4e-5 * 1.4e-4), 1.4e-5, 1.4e-4) == pytest.approx(0.5)
    assert place(3e-4, 0.0, 6e-4) == pytest.approx(0.5)


def test_the_ruling_line_says_which_magnitude_and_where():
    v = ConfidentVerdict(
        k=2,
        decision=Decision.BUY,
        found_name="F1F2",
        baseline_name="S1S2",
        score=Interval(1.5, 1.2, 1.9),
        axes=(),
        found=(),
        baseline=(),
        found_score_deg=Interval(0.1, 0.1, 0.1),
        baseline_score_deg=Interval(0.15, 0.15, 0.15),
        n_draws=40,
        n_scans=120,
        tolerance=0.1,
        confidence=0.95,
        ruling=Ruling("robot.path", 5.2e-5, True, 0.41),
    )
    assert ruling_line(v).startswith("  k=2 holds for a robot path error above 0.052 mm")
    assert "41 %" in ruling_line(v)
