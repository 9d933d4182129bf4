"""Bracket sensitivity: the spread a mounting tolerance adds, the bias of an un-zeroed cell, and which
sensor's bracket matters (optipose.evaluate.sensitivity)."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from optipose.evaluate.conditions import Condition, ConditionsConfig, mounting_error
from optipose.evaluate.objective import load_objective, reduced_objective
from optipose.evaluate.sensitivity import (
    AxisBias,
    BracketEvaluator,
    BracketSensitivity,
    SensorSensitivity,
    bracket_sensitivity,
)
from optipose.model.part import load_part

TURN = np.deg2rad(0.3)  # a bracket tolerance well above the noise's few mdeg, so the bias is plain


@pytest.fixture(scope="module")
def part_b():
    return load_part("part_b")


def _objective(translation=0.0, rotation=TURN, draws=1):
    """The paper's protocol cut to sequences R and P at their end angles (4 scans), with a bracket tolerance."""
    base = load_objective("paper").in_cell("ideal")
    protocol = replace(reduced_objective(base).protocol, sequences=("R", "P"))
    return replace(base, protocol=protocol, conditions=ConditionsConfig((1.0,), translation, rotation, draws))


def _sensors(part, *indices, name="some"):
    hand = part.layouts["hand"]
    return replace(hand, sensors=tuple(hand.sensors[i] for i in indices), name=name)


@pytest.fixture(scope="module")
def s1_turned(part_b):
    """Hand sensor S1 alone, its bracket off by up to 0.3 deg (and 0.2 mm), seed 1."""
    return bracket_sensitivity(part_b, _sensors(part_b, 0), _objective(0.2e-3), seed=1)


def test_a_zero_tolerance_adds_exactly_no_spread_no_bias_and_no_sensitivity(part_b):
    sens = bracket_sensitivity(part_b, _sensors(part_b, 0, 1), _objective(0.0, 0.0), seed=3)
    assert len(sens.spread) == 2 * 3 and len(sens.bias) == 2 * 6 and len(sens.sensors) == 2 * 2  # k = 1, 2
    perfect = np.array([(s.nominal_median, s.nominal_p75) for s in sens.spread])
    off = np.array([(s.mounted_median, s.mounted_p75) for s in sens.spread])
    assert np.isfinite(perfect).sum() >= 8  # measured numbers, equal, not two NaNs
    np.testing.assert_array_equal(off, perfect)
    np.testing.assert_array_equal([b.bias for b in sens.bias], [b.nominal for b in sens.bias])
    assert all(b.added == 0.0 for b in sens.bias if np.isfinite(b.bias))
    assert all(s.change == (0.0, 0.0, 0.0) and s.score_change == 0.0 for s in sens.sensors)


def test_one_turned_bracket_biases_the_unzeroed_roll_by_its_turn_about_x_in_the_part_frame(s1_turned, part_b):
    # The cell rebuilds the cloud with the drawn pose T_O_S while the head stands at T_O_S @ E: a point the
    # head measures at q lies at T_O_S E q but is reported at T_O_S q, i.e. the cloud is moved by
    # M = T_O_S E^-1 T_O_S^-1. Its rotation vector is -R_S w_E (w_E: E's rotation vector, in S), so ICP
    # reports the part turned by that: roll (about x_O) biased by -(R_S w_E)_x. The scan's travel along x_O
    # shears the cloud (it adds no turn about x_O), and E's translation turns nothing.
    E = mounting_error(Condition(1.0, 0, 0.2e-3, TURN), 1, 0)
    R_S = part_b.layouts["hand"].poses[0][:3, :3]
    expected = -(R_S @ Rotation.from_matrix(E[:3, :3]).as_rotvec())[0]
    assert abs(expected) > np.deg2rad(0.1)  # this draw turns S1 visibly about x_O
    roll = next(b for b in s1_turned.bias if b.axis == "roll" and b.k == 1)
    assert roll.subset == "S1" and roll.draw == 0
    assert roll.added == pytest.approx(expected, rel=0.05)  # the bracket's share of the bias
    assert abs(roll.nominal) < 0.05 * abs(expected)  # the perfect cell's own bias is small beside it
    assert s1_turned.worst_bias(1)["roll"] == abs(roll.bias)
    assert s1_turned.most_sensitive(1) == 0 and s1_turned.ranking(1)[0].name == "S1"


def test_moving_one_bracket_leaves_every_subset_without_it_exactly_unchanged(part_b):
    layout, objective = _sensors(part_b, 0, 1), _objective()
    with BracketEvaluator(part_b, objective, seed=2, reduced=False) as evaluator:
        sens = evaluator(layout)
        cond = Condition(1.0, 0, 0.0, TURN)
        perfect = evaluator.evaluator(layout, replace(cond, rotation=0.0)).per_scan
        only_s2 = evaluator.evaluator(layout, replace(cond, only=(1,))).per_scan
    rows = lambda frame, subset: frame[frame.subset == subset].reset_index(drop=True)  # noqa: E731
    assert rows(only_s2, "S1").equals(rows(perfect, "S1"))  # S1's scans, registrations and zeroing: untouched
    assert not rows(only_s2, "S2")["err_roll"].equals(rows(perfect, "S2")["err_roll"])  # S2's are not
    for s in sens.sensors:
        if not s.in_choice:  # a sensor outside the choice of k: its bracket changes nothing in it
            assert s.change == (0.0, 0.0, 0.0) and s.score_change == 0.0
    assert sum(not s.in_choice for s in sens.sensors) == 1  # k = 1 leaves one of the two sensors out
    assert {s.sensor for s in sens.ranking(2)} == {0, 1} and len(sens.ranking(1)) == 1


def test_bracket_sensitivity_is_reproducible_from_the_seed(s1_turned, part_b):
    again = bracket_sensitivity(part_b, _sensors(part_b, 0), _objective(0.2e-3), seed=1)
    assert repr(again) == repr(s1_turned)  # every number (NaN included) the same
    other = bracket_sensitivity(part_b, _sensors(part_b, 0), _objective(0.2e-3), seed=2)
    assert other.bias != s1_turned.bias


def test_the_ranking_puts_the_largest_change_first_and_an_unmeasurable_one_before_it():
    def sensor(j, score, in_choice=True):
        return SensorSensitivity(2, j, f"S{j + 1}", (score, 0.0, 0.0), score, in_choice)

    def bias(axis, draw, value):
        return AxisBias(2, axis, "S1S2", draw, value, 0.0)

    sens = BracketSensitivity(
        "x",
        ("S1", "S2", "S3"),
        2e-4,
        1e-3,
        (0, 1),
        4,
        True,
        (),
        (bias("roll", 0, -3.0), bias("roll", 1, 2.0)),
        (sensor(0, 1.0), sensor(1, 5.0), sensor(2, 9.0, in_choice=False)),
    )
    assert [s.sensor for s in sens.ranking(2)] == [1, 0] and sens.most_sensitive(2) == 1  # S3 is not in the choice
    assert sens.worst_bias(2)["roll"] == 3.0 and np.isnan(sens.worst_bias(2)["x"])
    failed = replace(sens, sensors=(sensor(0, 1.0), sensor(1, float("nan"))))
    assert failed.most_sensitive(2) == 1


BAND = """name = "band"
[protocol]
sequences = ["R"]
start_deg = 2.0
stop_deg = 2.0
step_deg = 1.0
[conditions]
mounting_translation_mm = 0.2
mounting_rotation_deg = 0.1
"""


def _optipose(*args):
    return subprocess.run(
        [sys.executable, "-m", "optipose", *map(str, args)], capture_output=True, text=True, timeout=600
    )


def test_robustness_prints_and_saves_the_brackets_of_each_layout(tmp_path, part_b):
    from optipose.model.layout import write_layout

    (tmp_path / "band.toml").write_text(BAND)
    write_layout(_sensors(part_b, 1, name="only_s2"), tmp_path / "only_s2.toml")
    out = tmp_path / "run"
    result = _optipose(
        "robustness",
        "part_b",
        "--layout",
        tmp_path / "only_s2.toml",
        "--objective",
        tmp_path / "band.toml",
        "--out",
        out,
    )
    assert result.returncode == 0, result.stderr
    assert "brackets off by ±0.2 mm, ±0.1°" in result.stdout and "make S2's bracket precise" in result.stdout
    assert max(len(line) for line in result.stdout.splitlines()) <= 80
    axes, sensors = pd.read_csv(out / "brackets.csv"), pd.read_csv(out / "bracket_sensors.csv")
    assert list(dict.fromkeys(axes["layout"])) == ["hand", "only_s2"] and set(axes["k"]) == {1, 2, 3}
    assert list(axes.loc[axes.layout == "only_s2", "axis"]) == ["roll", "pitch", "yaw", "x", "y", "z"]
    assert (axes["reduced_protocol"]).all() and (axes["n_scans"] == 1).all()
    assert list(sensors.loc[(sensors.layout == "hand") & (sensors.k == 3), "rank"]) == [1, 2, 3]


def test_brackets_on_an_objective_without_a_tolerance_is_one_line_and_exit_2(tmp_path):
    result = _optipose("robustness", "part_b", "--objective", "paper", "--brackets", "--out", tmp_path / "run")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [result.stderr.strip()] and "no mounting tolerance" in result.stderr
    assert not (tmp_path / "run").exists()  # refused before any evaluation
