"""One notion of conditions: the band is retired (one line each where it is still asked for), and
``optipose robustness`` checks layouts in cell instances: held-out draws of a cell's ranges, its ranges' ends, other
presets. The scanner's bracket model the cells use (a sensor off its drawn pose, its cloud built with the drawn one)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from optipose.batch.spec import study_from_table
from optipose.cell.config import load_cell
from optipose.errors import ConfigError
from optipose.evaluate.instances import check, instances
from optipose.evaluate.objective import BAND_RETIRED, load_objective, objective_from_table, reduced_objective
from optipose.model.part import load_part
from optipose.model.sensor import load_sensor
from optipose.scan.cloud import rebuilt_with
from optipose.scan.profiles import profiles_to_points
from optipose.scan.scanner import PartPose, part_scanner
from optipose.search.config import search_preset, unknown_keys
from optipose.seeds import held_out_seed, selection_seed, validation_seed, verdict_seed
from optipose.transforms import make_T, rpy_to_matrix


@pytest.fixture(scope="module")
def part_b():
    return load_part("part_b")


def _off(translation: float, rotation_deg: float, seed: int) -> np.ndarray:
    """A bracket error (4, 4): a rigid motion within the given tolerance."""
    rng = np.random.default_rng(seed)
    return make_T(rpy_to_matrix(rng.uniform(-1, 1, 3) * np.deg2rad(rotation_deg)), rng.uniform(-1, 1, 3) * translation)


# -- the band, retired: one line each ------------------------------------------------------------------------
@pytest.mark.parametrize(
    "table",
    [
        {"conditions": {"noise_scale": [1.0, 5.0]}},
        {"conditions": {"mounting_translation_mm": 0.2, "mounting_draws": 2}},
        {"name": "x", "conditions": {"aggregate": 0.9}},
        {"conditions": "worst"},
    ],
)
def test_an_objective_asking_for_a_band_is_one_line_saying_what_to_use(table):
    with pytest.raises(ConfigError) as err:
        objective_from_table(table, where="my.toml")
    assert str(err.value) == f"my.toml: {BAND_RETIRED}" and "\n" not in str(err.value)
    assert "--cell cobot" in str(err.value) and "retired" in str(err.value)


def test_a_conditions_table_of_the_nominal_cell_alone_still_loads():
    # what the shipped objectives wrote out before the band was retired, and every evaluation is now
    nominal = {
        "noise_scale": [1.0],
        "mounting_translation_mm": 0.0,
        "mounting_rotation_deg": 0.0,
        "mounting_draws": 1,
        "aggregate": "worst",
    }
    for conditions in (nominal, {}, {"noise_scale": 1}):
        assert objective_from_table({"conditions": conditions}) == objective_from_table({})


def test_the_objective_robust_is_retired_in_one_line():
    with pytest.raises(ConfigError, match="objective 'robust': the band of conditions .* was retired"):
        load_objective("robust")
    assert load_objective("paper").name == "paper"  # the shipped objectives carry no [conditions] any more


@pytest.mark.parametrize(
    "table",
    [{"band": "robust"}, {"band_objective": ""}, {"validation": {"band_objective": "robust", "protocol": "full"}}],
)
def test_a_search_config_with_the_band_is_one_line(table):
    for call in (unknown_keys, search_preset):
        with pytest.raises(ConfigError, match="search setting band_objective: the band of conditions"):
            call(table)
    assert unknown_keys({"validation": {"protocol": "full"}}) == []


def test_the_batch_task_robustness_is_refused_in_one_line():
    with pytest.raises(ConfigError, match="task 'robustness' was retired with the band of conditions"):
        study_from_table({"trials": [{"part": "part_c", "task": "robustness", "sensors": 2}]})
    with pytest.raises(ConfigError, match="task 'robustness' was retired"):
        study_from_table({"grid": {"parts": ["part_c"], "tasks": ["evaluate", "robustness"]}})


# -- cell instances: held-out draws and the ranges' ends ------------------------------------------------------
def test_an_instance_at_the_low_ends_has_every_magnitude_at_its_low_end():
    cobot = load_cell("cobot")
    assert cobot.ranges  # every magnitude of the preset is a range
    for end, column in (("low", 1), ("high", 2)):
        at = cobot.at(end)
        assert at.ranges == ()
        for name, *ends in cobot.ranges:
            group, _, field = name.partition(".")
            value = getattr(getattr(at, group), field) if field else getattr(at, group)
            assert value == ends[column - 1], (end, name)
    assert cobot.at("low").robot.path == pytest.approx(0.014e-3) and cobot.at("high").robot.path == pytest.approx(
        0.14e-3
    )
    assert cobot.at("low").calibration.zeroed is False and load_cell("cobot:zeroed").at("high").calibration.zeroed
    ur10e = load_cell("ur10e")  # points: its ends are itself
    assert ur10e.at("low") is ur10e and ur10e.at("high") is ur10e
    with pytest.raises(ValueError, match="'low' or 'high'"):
        cobot.at("middle")


def test_the_held_out_instances_are_seeded_and_none_of_the_searchs_seeds():
    got = instances(["cobot", "ur10e"], seed=7, draws=2)
    assert [(i.cell, i.label) for i in got] == [
        ("cobot", "draw 1"),
        ("cobot", "draw 2"),
        ("cobot", "low ends"),
        ("cobot", "high ends"),
        ("ur10e", "draw 1"),
        ("ur10e", "draw 2"),
    ]  # a cell of points has no ends of its own
    assert [i.seed for i in got] == [i.seed for i in instances(["cobot", "ur10e"], seed=7, draws=2)]
    held = {held_out_seed(7, i) for i in range(2)}
    assert {i.seed for i in got} == held and len(held) == 2
    search_seeds = {7, selection_seed(7), validation_seed(7), *(verdict_seed(7, d) for d in range(200))}
    assert not held & search_seeds
    assert got[2].the_cell == load_cell("cobot").at("low") and got[0].the_cell == load_cell("cobot")
    with pytest.raises(ConfigError, match="nosuch"):
        instances(["nosuch"], seed=0)


def test_a_layout_against_itself_is_an_exact_tie_in_every_instance(part_b):
    # one evaluator per instance, one seed: the same part as made, calibration, paths and noise for both layouts
    objective = reduced_objective(load_objective("paper"))
    objective = replace(objective, protocol=replace(objective.protocol, sequences=("R", "P")))
    hand = part_b.layouts["hand"]
    copy = replace(hand, name="copy")
    checked = instances(["cobot:zeroed"], seed=3, draws=1)
    rows = check(part_b, hand, {"copy": copy}, objective, checked, jobs=1)
    assert {(r.cell, r.instance) for r in rows} == {("cobot:zeroed", s) for s in ("draw 1", "low ends", "high ends")}
    assert len(rows) == 3 * 3 * 3  # instances x k x axes
    assert all(r.score == r.hand_score and r.ratio == 1.0 and r.holds for r in rows)
    assert all(r.median == r.hand_median and r.p75 == r.hand_p75 and r.sensors == r.hand_sensors for r in rows)
    # the instances differ: the ranges' ends are not one cell
    score = {(r.instance, r.k): r.score for r in rows}
    assert score[("low ends", 3)] < score[("high ends", 3)]


# -- the scanner's bracket model, which the cells' calibration uses -------------------------------------------
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


def test_a_cloud_rebuilt_with_another_pose_is_what_the_raw_profiles_give(part_b):
    T_drawn = part_b.layouts["hand"].poses[0]
    T_true = T_drawn @ _off(0.5e-3, 0.3, 1)
    scanner = part_scanner(part_b)
    scan = scanner.scan(T_true, part_b.motion, PartPose(centre=part_b.rotation_centre), rng=3)
    shifts = part_b.motion.offsets()
    assert np.allclose(rebuilt_with(scan, T_true, shifts).points, scan.points, atol=1e-12)
    rebuilt = rebuilt_with(scan, T_drawn, shifts)
    from_raw, _, _ = profiles_to_points(scan.raw, scanner.sensor, T_drawn, shifts)  # the device's own route
    key = lambda p: p[np.lexsort(np.round(p, 9).T)]  # noqa: E731
    assert np.allclose(key(rebuilt.points), key(from_raw), atol=1e-9)
    assert np.abs(rebuilt.points - scan.points).max() > 1e-4  # the bracket error moved the cloud


def test_a_cloud_built_with_the_drawn_pose_is_the_scan_rebuilt_with_it(part_b):
    # a cell builds a sensor's cloud with the pose it believes straight from the sensor-frame measurements
    # (Scanner.scan_levels(built=)); it must be the true pose's scan rebuilt, to rounding
    T_drawn = part_b.layouts["hand"].poses[1]
    T_true = T_drawn @ _off(0.2e-3, 0.1, 4)
    scanner, rpy = part_scanner(part_b, threads=1), np.deg2rad([-1.2, 0.4, 2.0])
    (true,) = scanner.scan_levels([T_true], part_b.motion, (5.0,), PartPose(rpy, part_b.rotation_centre), rng=8)[0]
    (built,) = scanner.scan_levels(
        [T_true], part_b.motion, (5.0,), PartPose(rpy, part_b.rotation_centre), rng=8, built=[T_drawn]
    )[0]
    rebuilt = rebuilt_with(true, T_drawn, part_b.motion.offsets())
    assert np.array_equal(built.T_O_S, T_drawn) and np.array_equal(built.face, true.face)
    assert np.abs(built.points - rebuilt.points).max() < 1e-12
    assert np.abs(built.points - true.points).max() > 1e-5  # the bracket error is there


def test_the_robustness_table_has_a_row_per_cell_instance_layout_k_and_axis():
    from optipose.evaluate.instances import Instance, InstanceRow
    from optipose.io.tables import instances_frame

    inst = Instance("cobot", "low ends", 5, load_cell("cobot").at("low"))
    rows = [
        InstanceRow(
            inst.cell, inst.label, inst.seed, "found_k2", 2, "F1F2", a, "F1", 1e-3, 2e-3, "S1S2", 2e-3, 3e-3, s, h
        )
        for a, s, h in (("roll", 0.01, 0.02), ("pitch", 0.01, 0.02), ("yaw", 0.01, 0.02))
    ]
    frame = instances_frame(rows)
    assert list(frame[["cell", "instance", "layout", "k", "axis"]].itertuples(index=False, name=None)) == [
        ("cobot", "low ends", "found_k2", 2, axis) for axis in ("roll", "pitch", "yaw")
    ]
    assert frame.ratio.tolist() == [2.0] * 3 and frame.holds.all()
    assert frame.median_deg.iloc[0] == pytest.approx(np.rad2deg(1e-3))
    assert isinstance(frame, pd.DataFrame)
