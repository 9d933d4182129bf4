"""Calibration (docs/calibration.md): a hidden magnitude recovered within its posterior, figures no range can produce
said in one line, bad figures files one line each, and the calibrated cell file loadable as a cell."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from cli_checks import assert_one_line_error
from optipose.calibrate.calibration import calibrate
from optipose.calibrate.emulator import Emulator
from optipose.calibrate.posterior import fit_correction
from optipose.calibrate.summaries import AXES, STATS, Figure, Summaries, from_evaluation, read_figures
from optipose.cell.config import cell_from_table, load_cell
from optipose.cell.ranges import spread
from optipose.cli.app import main
from optipose.evaluate.objective import load_objective
from optipose.model.part import load_part
from optipose.search.surrogate import predicted_stats

from meshes import TWO_SENSORS

ROOT = Path(__file__).resolve().parents[1]
# cobot with two of its ranges left and the rest at points: the small case
SMALL = {
    "name": "small",
    "robot": {
        "path_mm": [0.014, 0.14],
        "path_rotation_deg": 0.002,
        "path_correlation_mm": 30.0,
        "step": 0.0003,
        "orientation_deg": 0.005,
    },
    "calibration": {
        "sensor_translation_mm": 0.01,
        "sensor_rotation_deg": 0.01,
        "frame_translation_mm": 0.02,
        "frame_rotation_deg": [0.005, 0.2],
        "zeroed": False,
    },
    "part": {"as_made": True, "default_process": "milled"},
    "material": {"effects": True},
}
HIDDEN = {"robot.path": 0.05e-3, "calibration.frame_rotation": math.radians(0.03)}


@pytest.fixture(scope="module")
def part_a():
    return load_part("part_a")


@pytest.fixture(scope="module")
def small(part_a):
    objective = load_objective("paper").in_cell(cell_from_table(SMALL, "small"))
    return objective, Emulator(part_a, part_a.layouts["hand"], objective)


def _summaries(emulator, values: dict, scans: int = 77) -> Summaries:
    """Every subset's figures as the emulator predicts them at ``values``: what a hidden cell would show."""
    stats = emulator.stats(np.array([[values[k] for k in emulator.keys]]))
    figures = [
        Figure(sub, axis, stat, float(stats[sub][0, s, a]), scans)
        for sub in emulator.labels
        for a, axis in enumerate(AXES)
        for s, stat in enumerate(STATS)
    ]
    return Summaries("part_a", tuple(figures), "simulated figures")


def test_the_emulator_is_the_surrogates_prediction_at_its_instances(small):
    """At the surrogate's own magnitude instances (the ranges' spread), the emulator's statistics are the surrogate's:
    their geometric mean over the instances is :func:`predicted_stats`' figure, subset by subset."""
    _, emulator = small
    instances = spread(emulator.ranges, 8)
    values = np.array([[inst[k] for k in emulator.keys] for inst in instances])
    stats = emulator.stats(values)
    prediction = predicted_stats(emulator.infos)
    for s, subset in enumerate(prediction.subsets):
        name = "".join(emulator.names[i] for i in subset)
        mean = np.rad2deg(np.exp(np.log(stats[name]).mean(axis=0)))  # (2, 3)
        assert np.allclose(mean[0], prediction.median_deg[s], rtol=1e-6)
        assert np.allclose(mean[1], prediction.p75_deg[s], rtol=1e-6)


def test_calibration_recovers_a_hidden_magnitude_within_its_posterior(small, part_a):
    objective, emulator = small
    summaries = _summaries(emulator, HIDDEN)
    result = calibrate(part_a, part_a.layouts["hand"], objective, summaries, draws=4000, icp=0, seed=1)
    assert result.out == ()
    for key, hidden in HIDDEN.items():
        low, high = result.posterior.interval(key)
        assert low <= hidden <= high, (key, low, hidden, high)
        prior_low, prior_high = next((lo, hi) for k, lo, hi in objective.cell.ranges if k == key)
        assert high / low < prior_high / prior_low  # narrower than the prior
    path_low, path_high = result.posterior.interval("robot.path")
    assert path_high / path_low < 3  # the path rules pitch and yaw: pinned within a factor of 3 (prior: 10)


def test_figures_no_range_can_produce_are_named(small, part_a):
    objective, emulator = small
    summaries = _summaries(emulator, HIDDEN)
    # S1S2S3's roll ten times below the lowest the ranges give
    figures = tuple(
        Figure(f.subset, f.axis, f.stat, f.value / 30 if (f.subset, f.axis) == ("S1S2S3", "roll") else f.value, 77)
        for f in summaries.figures
    )
    result = calibrate(part_a, part_a.layouts["hand"], objective, Summaries("part_a", figures, "x"), draws=2000, icp=0)
    assert result.out and all("S1S2S3 roll" in line for line in result.out)


def test_the_correction_is_the_mean_log_ratio_and_its_spread():
    emulated = np.log(np.array([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]]))
    icp = emulated + np.log([[1.9, 2.1], [2.1, 1.9], [2.0, 2.0]])
    c = fit_correction(emulated, icp, [[(0, 1)]], (0, 1, 2), 1.0)
    assert np.allclose(c.log_ratio, np.log(2.0), atol=0.01)
    assert c.cov[0, 1] == pytest.approx(0.0, abs=1e-6) and np.all(np.diag(c.cov) > 0)  # opposite residuals: none


FIGURES = "part,k,subset,axis,median_deg,p75_deg\npart_a,1,S1,roll,{m},0.066\npart_a,1,S1,pitch,0.13,0.243\n"


def test_a_figures_file_reads_in_radians_with_its_noise(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text(FIGURES.format(m=0.045) + "part_b,1,S1,roll,0.039,0.091\n")
    s = read_figures(path, "part_a")  # part B's row is left out
    assert [f.label for f in s.figures] == ["S1 roll median", "S1 roll p75", "S1 pitch median", "S1 pitch p75"]
    assert math.isclose(s.figures[0].value, math.radians(0.045))
    sd = np.sqrt(np.diag(s.noise()))
    assert sd[0] == pytest.approx(0.133, abs=0.002) and sd[1] == pytest.approx(0.104, abs=0.002)


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("part,subset,axis,median_deg\npart_a,S1,roll,0.04\n", "no column p75_deg"),
        (FIGURES.format(m=-0.04), "median_deg must be > 0"),
        (FIGURES.format(m="nan"), "median_deg must be a finite number"),
        (FIGURES.format(m="abc"), "median_deg must be a number"),
        (FIGURES.format(m=0.5), "p75_deg 0.066 is below median_deg 0.5"),
        (FIGURES.format(m=0.04).replace("pitch", "tilt"), "axis must be roll, pitch or yaw"),
        (FIGURES.format(m=0.04).replace("part_a", "part_x"), "no row of part 'part_a'"),
        (FIGURES.format(m=0.04).replace("S1,pitch", "S4,pitch"), "subset S4"),
    ],
)
def test_a_bad_figures_file_is_one_line_and_exit_2(tmp_path, capsys, text, fragment):
    path = tmp_path / "t.csv"
    path.write_text(text)
    args = ["calibrate", "part_a", "--figures", str(path), "--cell", "cobot", "--out", str(tmp_path / "c.toml")]
    with pytest.raises(SystemExit) as info:
        main([*args, "--icp", "0", "--draws", "200"])
    assert_one_line_error(SimpleNamespace(returncode=info.value.code, stderr=capsys.readouterr().err), fragment)
    assert not (tmp_path / "c.toml").exists()


def test_calibrate_writes_a_cell_file_that_loads_within_the_prior(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text(FIGURES.format(m=0.045))
    out = tmp_path / "my_cell.toml"
    with pytest.raises(SystemExit) as info:
        main(["calibrate", "part_a", "--figures", str(path), "--cell", "cobot", "--out", str(out), "--icp", "0"])
    assert info.value.code == 0, capsys.readouterr().err
    cell, prior = load_cell(out), load_cell("cobot")
    assert cell.name == "my_cell"
    bounds = {k: (lo, hi) for k, lo, hi in prior.ranges}
    for key, low, high in cell.ranges:
        assert bounds[key][0] * 0.999 <= low <= high <= bounds[key][1] * 1.001, key
    text = out.read_text()
    assert "calibrated from figures t.csv of part_a by optipose calibrate, posterior 5-95 %" in text
    assert "not calibrated" in text  # the path's correlation length: kept, and said


def test_figures_outside_every_range_warn_in_one_line_and_exit_3(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text("part,subset,axis,median_deg,p75_deg\npart_a,S1,pitch,3.0,5.0\npart_a,S1,roll,0.04,0.07\n")
    out = tmp_path / "c.toml"
    with pytest.raises(SystemExit) as info:
        main(["calibrate", "part_a", "--figures", str(path), "--cell", "cobot", "--out", str(out), "--icp", "0"])
    assert info.value.code == 3
    warnings = [line for line in capsys.readouterr().err.splitlines() if line.startswith("optipose: warning:")]
    assert len(warnings) == 1 and "missing a source" in warnings[0] and "S1 pitch median" in warnings[0]
    assert out.is_file() and "WARNING" in out.read_text()


def _evaluation(emulator, values: dict, scans: int = 77) -> SimpleNamespace:
    """A simulated EvaluationResult of the hand layout: its stats table as the emulator predicts it at ``values``, and
    a subset that failed too often and an unobservable axis, which a calibration must leave out."""
    import pandas as pd

    stats = emulator.stats(np.array([[values[k] for k in emulator.keys]]))
    rows = [
        {
            "subset": sub,
            "axis": axis,
            "median": float(stats[sub][0, 0, a]),
            "p75": float(stats[sub][0, 1, a]),
            "n_ok": scans,
            "n_failed": 0,
            "unobservable": False,
        }
        for sub in emulator.labels
        for a, axis in enumerate(AXES)
    ]
    rows[0] |= {"n_ok": scans - 30, "n_failed": 30, "median": 0.17}  # S1 roll: 30 failures at 10°
    rows[1] |= {"unobservable": True}
    return SimpleNamespace(part="part_a", stats=pd.DataFrame(rows))


def test_an_evaluation_of_scans_is_calibrated_on_its_observed_subsets(small, part_a):
    objective, emulator = small
    summaries = from_evaluation(_evaluation(emulator, HIDDEN), "scans simulated")
    labels = {f.label for f in summaries.figures}
    assert "S1 roll median" not in labels and "S1 pitch median" not in labels and "S1 yaw p75" in labels
    assert len(summaries.figures) == 2 * (3 * len(emulator.labels) - 2)
    result = calibrate(part_a, part_a.layouts["hand"], objective, summaries, draws=4000, icp=0, seed=2)
    for key, hidden in HIDDEN.items():
        low, high = result.posterior.interval(key)
        assert low <= hidden <= high, (key, low, hidden, high)


def test_calibrate_reads_a_scan_folder(tmp_path):
    """``scan --protocol --raw`` in the paper's cell (a reduced protocol of part B's S1 and S2), then ``calibrate
    --scans`` with the cobot preset as the prior: the scans are registered, and a cell file loads."""
    from cli_checks import run

    paper = (ROOT / "objectives" / "paper.toml").read_text()
    small = paper.replace('name = "paper"', 'name = "small"').replace("step_deg = 0.4", "step_deg = 2.0")
    (tmp_path / "small.toml").write_text(
        small.replace('sequences = ["R", "P", "Y", "RP", "PY", "YR", "RPY"]', 'sequences = ["R", "P"]')
    )
    (tmp_path / "two.toml").write_text(TWO_SENSORS)
    scans = tmp_path / "scans"
    wrote = run(
        "scan",
        "part_b",
        "--protocol",
        "small.toml",
        "--cell",
        "ur10e",
        "--layout",
        "two.toml",
        "--raw",
        str(scans),
        cwd=tmp_path,
    )
    assert wrote.returncode == 0, wrote.stderr
    out = tmp_path / "mine.toml"
    done = run(
        "calibrate", "part_b", "--scans", str(scans), "--cell", "cobot", "--out", str(out), "--icp", "0", cwd=tmp_path
    )
    assert done.returncode in (0, 3), done.stderr
    assert "registering the scans" in done.stderr
    assert load_cell(out).ranges and "calibrated from scans scans of part_b" in out.read_text()
