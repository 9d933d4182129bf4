"""Conditions of a real cell: a noise band, bracket tolerances with a zeroed cell, and the robust statistic."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from optipose.errors import ConfigError
from optipose.evaluate.assignment import best_choices
from optipose.evaluate.conditions import Condition, ConditionsConfig, conditions, conditions_from_table, mounting_error
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import StatisticConfig, load_objective, reduced_objective
from optipose.evaluate.robust import evaluate_robust, robust_stats
from optipose.model.part import load_part
from optipose.model.sensor import load_sensor
from optipose.scan.cloud import rebuilt_with
from optipose.scan.scanner import PartPose, part_scanner
from optipose.scan.profiles import profiles_to_points
from optipose.transforms import matrix_to_rpy


@pytest.fixture(scope="module")
def part_b():
    return load_part("part_b")


def _one_sensor(part):
    return replace(part.layouts["hand"], sensors=part.layouts["hand"].sensors[:1])


def _short(objective, sequences=("R", "P")):
    """The objective's protocol cut to a few sequences at their end angles."""
    return replace(objective, protocol=replace(reduced_objective(objective).protocol, sequences=sequences))


def test_the_shipped_objectives_and_the_trivial_band(part_b):
    assert load_objective("paper").in_cell("ideal").conditions.trivial
    robust = load_objective("robust").conditions
    assert robust.noise_scales == (1.0, 5.0) and robust.mounting_draws == 2 and not robust.trivial
    assert robust.mounting_translation == pytest.approx(0.2e-3) and robust.mounting_rotation == pytest.approx(
        np.deg2rad(0.1)
    )
    assert len(conditions(robust)) == 4 and conditions(robust)[0].label == "noise x1, mounting draw 0"
    assert conditions(ConditionsConfig()) == [Condition()] and Condition().nominal


@pytest.mark.parametrize(
    "table, message",
    [
        ({"noise": [1]}, "unknown key"),
        ({"noise_scale": [0.0]}, "positive"),
        ({"noise_scale": []}, "positive"),
        ({"mounting_rotation_deg": -1}, ">= 0"),
        ({"mounting_draws": 0}, ">= 1"),
        ({"aggregate": "mean"}, "quantile"),
        ({"aggregate": 1.5}, "quantile"),
        ({"noise_scale": ["x"]}, "numbers"),
    ],
)
def test_bad_conditions_are_refused_naming_the_key(table, message):
    with pytest.raises(ConfigError, match=message):
        conditions_from_table(table, "robust.toml [conditions]")


def test_a_zero_tolerance_and_a_one_level_band_give_exactly_the_objective(part_b):
    objective = _short(load_objective("paper").in_cell("ideal"))
    layout = _one_sensor(part_b)
    with Evaluator(part_b, objective, seed=4) as evaluator:
        plain = evaluator(layout)
    robust = evaluate_robust(part_b, layout, objective, seed=4)
    assert len(robust.results) == 1
    assert robust.results[0][1].per_scan.equals(plain.per_scan) and robust.table == plain.table


def test_one_cast_gives_every_noise_level_exactly_as_a_scanner_of_that_noise(part_b):
    # where a ray hits does not depend on the noise: Scanner.scan_levels casts once and writes each level,
    # which must be what a scanner whose sensor has that many times the noise gives, bit for bit
    poses, rpy = part_b.layouts["hand"].poses, np.deg2rad([0.8, -0.4, 1.2])
    scanner = part_scanner(part_b, threads=1)
    levels = scanner.scan_levels(poses, part_b.motion, (1.0, 5.0), PartPose(rpy, part_b.rotation_centre), rng=9)
    sensor = load_sensor(part_b.sensor)
    noisier = part_scanner(part_b, sensor=replace(sensor, noise_sigma=sensor.noise_sigma * 5.0), threads=1)
    for level, alone in zip(levels, (scanner, noisier)):
        for a, b in zip(level, alone.scan_many(poses, part_b.motion, PartPose(rpy, part_b.rotation_centre), rng=9)):
            assert (
                np.array_equal(a.points, b.points) and np.array_equal(a.raw, b.raw) and np.array_equal(a.face, b.face)
            )
    assert not np.array_equal(levels[0][0].points, levels[1][0].points)  # the noise differs, the hits do not
    assert np.array_equal(levels[0][0].face, levels[1][0].face)


def test_conditions_of_one_bracket_draw_evaluated_together_are_each_evaluated_alone(part_b):
    # Evaluator.under scans the noise levels of a draw together; each result must be the one the condition
    # gives on its own, on two workers too (the master scans' zeros are shared, the noise is not)
    objective = _short(load_objective("paper").in_cell("ideal"))
    layout = part_b.layouts["hand"]
    band = [Condition(s, d, 0.2e-3, np.deg2rad(0.1)) for s in (1.0, 5.0) for d in (0, 1)]
    with Evaluator(part_b, objective, seed=6, jobs=2) as evaluator:
        together = evaluator.under(layout, band)
        alone = [evaluator(layout, c) for c in band]
    for a, b in zip(together, alone):
        assert a.per_scan.equals(b.per_scan) and a.stats.equals(b.stats)
    assert not together[0].per_scan.equals(together[2].per_scan)  # x1 and x5 of draw 0 differ


def test_mounting_draws_are_reproducible_within_the_tolerance_and_differ_per_sensor_and_draw():
    cond = Condition(1.0, 0, 0.2e-3, np.deg2rad(0.1))
    E = mounting_error(cond, 7, 0)
    assert np.array_equal(E, mounting_error(cond, 7, 0))  # the seed, the draw and the sensor decide it
    assert not np.array_equal(E, mounting_error(cond, 7, 1)) and not np.array_equal(
        E, mounting_error(replace(cond, draw=1), 7, 0)
    )
    assert not np.array_equal(E, mounting_error(cond, 8, 0))
    for sensor in range(20):
        E = mounting_error(cond, 7, sensor)
        assert np.all(np.abs(E[:3, 3]) <= 0.2e-3) and np.all(
            np.abs(matrix_to_rpy(E[:3, :3])) <= np.deg2rad(0.1) + 1e-12
        )
    assert np.array_equal(mounting_error(Condition(), 7, 0), np.eye(4))


def test_a_cloud_rebuilt_with_another_pose_is_what_the_raw_profiles_give(part_b):
    T_drawn = part_b.layouts["hand"].poses[0]
    T_true = T_drawn @ mounting_error(Condition(1.0, 0, 0.5e-3, np.deg2rad(0.3)), 1, 0)
    scanner = part_scanner(part_b)
    scan = scanner.scan(T_true, part_b.motion, PartPose(centre=part_b.rotation_centre), rng=3)
    shifts = part_b.motion.offsets()
    assert np.array_equal(rebuilt_with(scan, T_true, shifts).points, scan.points) or np.allclose(
        rebuilt_with(scan, T_true, shifts).points, scan.points, atol=1e-12
    )
    rebuilt = rebuilt_with(scan, T_drawn, shifts)
    from_raw, _, _ = profiles_to_points(scan.raw, scanner.sensor, T_drawn, shifts)  # the device's own route
    key = lambda p: p[np.lexsort(np.round(p, 9).T)]  # noqa: E731
    assert np.allclose(key(rebuilt.points), key(from_raw), atol=1e-9)
    assert np.abs(rebuilt.points - scan.points).max() > 1e-4  # the bracket error moved the cloud


def test_a_cloud_built_with_the_drawn_pose_is_the_scan_rebuilt_with_it(part_b):
    # the evaluator builds a mounted sensor's cloud with the drawn pose straight from the sensor-frame
    # measurements (Scanner.scan_levels(built=)); it must be the true pose's scan rebuilt, to rounding
    T_drawn = part_b.layouts["hand"].poses[1]
    T_true = T_drawn @ mounting_error(Condition(1.0, 0, 0.2e-3, np.deg2rad(0.1)), 4, 1)
    scanner, rpy = part_scanner(part_b, threads=1), np.deg2rad([-1.2, 0.4, 2.0])
    (true,) = scanner.scan_levels([T_true], part_b.motion, (5.0,), PartPose(rpy, part_b.rotation_centre), rng=8)[0]
    (built,) = scanner.scan_levels(
        [T_true], part_b.motion, (5.0,), PartPose(rpy, part_b.rotation_centre), rng=8, built=[T_drawn]
    )[0]
    rebuilt = rebuilt_with(true, T_drawn, part_b.motion.offsets())
    assert np.array_equal(built.T_O_S, T_drawn) and np.array_equal(built.face, true.face)
    assert np.abs(built.points - rebuilt.points).max() < 1e-12
    assert np.abs(built.points - true.points).max() > 1e-5  # the bracket error is there


def test_the_zeroed_cell_takes_the_constant_bias_off(part_b):
    # one sensor turned 0.2 deg on its bracket, noise all but off: the rebuilt cloud is the true one turned
    # rigidly (and sheared along the scan), so without zeroing every scan would be off by about that much;
    # noise-free master-part scans at the nominal orientation measure what the bracket adds there and
    # zeroing takes it off: at that orientation the cell reports what a cell with exact brackets reports
    objective = replace(
        _short(load_objective("paper").in_cell("ideal"), ("R",)),
        protocol=replace(
            load_objective("paper").in_cell("ideal").protocol,
            sequences=("R",),
            start=-np.deg2rad(2.0),
            stop=np.deg2rad(2.0),
            step=np.deg2rad(2.0),
        ),
    )
    layout = _one_sensor(part_b)
    cond = Condition(1e-6, 0, 0.0, np.deg2rad(0.2))
    with Evaluator(part_b, objective, seed=2, condition=cond) as evaluator:
        rows = evaluator(layout).per_scan
        exact = evaluator(layout, Condition(1e-6)).per_scan
    tilt = np.rad2deg(np.abs(matrix_to_rpy(mounting_error(cond, 2, 0)[:3, :3]))).max()
    assert tilt > 0.05  # the bracket is visibly off
    errors = np.rad2deg(rows[["err_roll", "err_pitch", "err_yaw"]].abs().to_numpy())
    at_zero = rows["roll_set"].abs().to_numpy() < 1e-12
    exact_errors = np.rad2deg(exact[["err_roll", "err_pitch", "err_yaw"]].abs().to_numpy())
    # at the master's orientation the cell reports what an exact cell does, up to the difference between a
    # noise-free master scan and a quantised one (the exact cell's own error there is that size, ~1 mdeg)
    assert (
        np.abs(errors[at_zero] - exact_errors[at_zero]).max() < 2 * max(exact_errors[at_zero].max(), 1e-4) < tilt / 50
    )
    assert errors.max() < tilt / 5  # what is left at +-2 deg is the distortion's change, far below the bias


def test_a_layout_better_at_one_noise_level_only_loses_the_robust_choice():
    def stats(s1, s2):  # per sensor (median, p75) on every axis; the pair no better than its best sensor
        rows = [
            {
                "subset": name,
                "axis": a,
                "median": m,
                "p75": p,
                "mean": m,
                "max": p,
                "n_ok": 14,
                "n_failed": 0,
                "unobservable": False,
            }
            for name, (m, p) in (("S1", s1), ("S2", s2), ("S1S2", (9, 9)))
            for a in ("roll", "pitch", "yaw")
        ]
        return pd.DataFrame(rows)

    nominal, noisy = stats((1.0, 1.5), (2.0, 2.5)), stats((10.0, 12.0), (3.0, 3.5))  # S1 wins only at the nominal noise
    cfg = StatisticConfig()
    assert best_choices(nominal, ["S1", "S2"], cfg, 14)[0].name == "S1"
    assert best_choices(robust_stats([nominal, noisy], "worst"), ["S1", "S2"], cfg, 14)[0].name == "S2"
    median = robust_stats([nominal, noisy], 0.5)  # a quantile aggregate: the middle of the two
    assert median.loc[(median.subset == "S1") & (median.axis == "roll"), "median"].item() == pytest.approx(5.5)


def test_layouts_are_compared_per_noise_level_over_its_bracket_draws():
    from types import SimpleNamespace

    from optipose.evaluate.robust import by_level

    def stats(roll):  # one sensor, roll (median, p75) as given, pitch and yaw 1
        rows = [
            {
                "subset": "S1",
                "axis": a,
                "median": m,
                "p75": p,
                "mean": m,
                "max": p,
                "n_ok": 14,
                "n_failed": 0,
                "unobservable": False,
            }
            for a, (m, p) in zip(("roll", "pitch", "yaw"), (roll, (1, 1), (1, 1)))
        ]
        return pd.DataFrame(rows)

    band = [
        (Condition(1.0, 0), stats((1, 2))),
        (Condition(1.0, 1), stats((3, 1))),
        (Condition(5.0, 0), stats((5, 6))),
        (Condition(5.0, 1), stats((4, 7))),
    ]
    results = [(c, SimpleNamespace(stats=frame)) for c, frame in band]
    levels = by_level(results, "worst")
    assert [label for label, _ in levels] == [
        "noise x1, worst of 2 bracket draws",
        "noise x5, worst of 2 bracket draws",
    ]
    roll = [frame.loc[frame.axis == "roll", ["median", "p75"]].to_numpy().tolist() for _, frame in levels]
    assert roll == [[[3, 2]], [[5, 7]]]  # each statistic the worst of its level's draws, the levels apart
    ((label, _),) = by_level(results[:1], "worst")
    assert label == "noise x1, bracket draw 0"


BAND = """name = "band"
[protocol]
sequences = ["R", "Y"]
start_deg = -2.0
stop_deg = 2.0
step_deg = 4.0
[conditions]
noise_scale = [1.0, 5.0]
mounting_translation_mm = 0.2
mounting_rotation_deg = 0.1
"""


def test_robustness_puts_a_layout_beside_the_hand_one_under_every_condition(tmp_path, part_b):
    import subprocess
    import sys

    from optipose.model.layout import write_layout

    (tmp_path / "band.toml").write_text(BAND)
    s2 = replace(part_b.layouts["hand"], sensors=part_b.layouts["hand"].sensors[1:2], name="only_s2")
    write_layout(s2, tmp_path / "only_s2.toml")
    out = tmp_path / "run"
    args = [
        "robustness",
        "part_b",
        "--layout",
        tmp_path / "only_s2.toml",
        "--objective",
        tmp_path / "band.toml",
        "--out",
        out,
    ]
    result = subprocess.run(
        [sys.executable, "-m", "optipose", *map(str, args)], capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stderr
    rows = pd.read_csv(out / "robustness.csv")
    assert list(dict.fromkeys(rows["layout"])) == ["hand", "only_s2"] and set(rows["k"]) == {1}
    labels = ["noise x1, mounting draw 0", "noise x5, mounting draw 0", "worst"]
    assert list(dict.fromkeys(rows["condition"])) == labels
    for _, per_axis in rows.groupby(["layout", "axis"]):  # one sensor, one subset: worst = max over the band
        worst = per_axis[per_axis.condition == "worst"]["median_deg"].item()
        band = per_axis[per_axis.condition != "worst"]["median_deg"]
        assert worst == band.max() if band.notna().all() else np.isnan(worst)  # unmeasurable somewhere: so robustly
    hand_rows = rows[rows.layout == "hand"]
    assert (hand_rows["score_deg"] == hand_rows["hand_score_deg"]).all()
    assert "only_s2 (worst over the band): k=1: found S2" in result.stdout and "than hand S1" in result.stdout
    assert (out / "layouts" / "only_s2.toml").is_file() and "robustness" in (out / "config.toml").read_text()


def test_the_surrogate_predicts_across_the_noise_band_without_rescanning():
    from optipose.search.surrogate import SensorInfo, predicted_stats

    # a pure-noise information matrix (no bias turns): sigma grows with the noise scale, the prior aside
    H = np.diag([1e12, 4e12, 9e12, 1e14, 1e14, 1e14])
    one = predicted_stats([SensorInfo(H, 10_000, 1_000)])
    five = predicted_stats([SensorInfo(H / 25, 10_000, 1_000)])
    band = predicted_stats([SensorInfo(H, 10_000, 1_000)], noise_scales=(1.0, 3.0, 5.0))
    assert np.array_equal(band.median_deg, five.median_deg) and band.score == five.score  # the worst is x5
    assert np.allclose(five.median_deg / one.median_deg, 5.0, rtol=1e-3)
    assert np.array_equal(predicted_stats([SensorInfo(H, 10_000, 1_000)], noise_scales=(1.0,)).p75_deg, one.p75_deg)


def test_the_search_scores_the_bands_ends_and_spends_its_budget_there():
    from optipose.evaluate.conditions import ConditionsConfig, band_ends
    from optipose.search.budgets import config_from_budget
    from optipose.search.config import search_preset
    from optipose.search.objectives import search_objective

    band = ConditionsConfig((3.0, 1.0, 5.0, 2.0), 2e-4, 1e-3, 2)
    assert band_ends(band) == ConditionsConfig((1.0, 5.0), 2e-4, 1e-3, 2)
    assert [c.noise_scale for c in conditions(band_ends(band))] == [1.0, 1.0, 5.0, 5.0]
    paper = load_objective("paper").in_cell("ideal")
    assert search_objective(paper) is paper
    assert search_objective(replace(paper, conditions=band)).conditions.noise_scales == (1.0, 5.0)
    nominal, banded = config_from_budget("default", (1, 2, 3)), config_from_budget("default", (1, 2, 3), band=True)
    assert nominal.selection.polish_evals > 0 and banded.selection.polish_evals == 0
    assert banded.selection.confirm_candidates == 0
    user = search_preset({"polish_evals": 12})
    assert config_from_budget("default", (1,), user, band=True).selection.polish_evals == 12  # the user's word last
    assert config_from_budget("quick", (1,), band=True) == config_from_budget("quick", (1,))
