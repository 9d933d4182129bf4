"""Cells whose magnitudes are ranges (optipose.cell.ranges): a cell of points is unchanged bit for bit, each range
draws its magnitude per run seed from the distribution asked for, one seed is one instance for every layout, bad
ranges are one line, and the shipped presets load and are listed."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from cli_checks import assert_one_line_error
from scipy import stats

from optipose.cell.config import CELLS_DIR, Cell, cell_from_table, cell_names, load_cell
from optipose.cell.ranges import draws, middle
from optipose.cell.scans import CellSetup, LiveCell
from optipose.errors import ConfigError
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective, objective_from_dict
from optipose.model.layout import Layout
from optipose.model.part import load_part
from optipose.verdict.compare import Verdict

DEG = np.pi / 180
REPO = Path(__file__).resolve().parents[1]
PRESETS = ("cobot", "industrial-arm", "linear-axis")
MAGNITUDES = {
    "robot": ("path_mm", "path_rotation_deg", "path_correlation_mm", "step", "orientation_deg"),
    "calibration": ("sensor_translation_mm", "sensor_rotation_deg", "frame_translation_mm", "frame_rotation_deg"),
}


def _per_scan(cell, seed: int) -> list:
    """Part B's S2 on two orientations (roll and pitch at 1 deg) in ``cell`` at ``seed``: the per-scan errors."""
    part = load_part("part_b")
    layout = Layout((part.layouts["hand"].sensors[1],), name="S2")
    o = load_objective("paper")
    p = dataclasses.replace(o.protocol, sequences=("R", "P"), start=DEG, stop=DEG)
    with Evaluator(part, dataclasses.replace(o, protocol=p).in_cell(cell), seed=seed) as ev:
        r = ev(layout)
    cols = ["err_roll", "err_pitch", "err_yaw", "err_x", "err_y", "err_z", "rmse", "iterations"]
    return r.per_scan[cols].to_numpy(float).tolist()


# -- a cell of points is today's cell, bit for bit ------------------------------------------------------------
def test_a_point_cells_instance_and_middle_are_itself():
    ur10e = load_cell("ur10e")
    assert ur10e.ranges == ()
    for seed in (0, 1, 5, 2**31):
        assert ur10e.instance(seed) is ur10e
    assert ur10e.middle() is ur10e
    setup = CellSetup.of(ur10e, load_part("part_b"))
    assert setup.instance(3) is setup and setup.middle() is setup


@pytest.mark.parametrize("preset", ["cobot", "linear-axis"])
def test_a_ranged_cells_draw_is_the_point_cell_of_its_magnitudes_bit_for_bit(preset):
    """A draw of a cell of ranges at a seed gives the per-scan errors of the cell of points holding that draw's
    magnitudes, at the same seed, float for float: drawing the magnitudes shifts no realisation (the part as made,
    the calibration, the path, the material's draws), so a cell of points is the cell it was before ranges."""
    ranged = load_cell(preset)
    point = ranged.instance(5)
    assert ranged.ranges and point.ranges == () and point != ranged.middle()
    mine, pointwise = _per_scan(ranged, 5), _per_scan(point, 5)
    assert len(mine) == 2 and np.isfinite(mine).all()
    assert mine == pointwise  # float for float
    assert mine != _per_scan(ranged.middle(), 5)  # and the magnitudes drawn do matter


# -- the draws --------------------------------------------------------------------------------------------
def _ranged(robot: str = "", calibration: str = "", part: str = "") -> Cell:
    table = {"robot": {}, "calibration": {}, "part": {"as_made": False}}
    for name, text in (("robot", robot), ("calibration", calibration), ("part", part)):
        import tomllib

        table[name].update(tomllib.loads(text))
    return cell_from_table(table, "test")


def test_a_range_with_a_low_end_draws_log_uniform_between_its_ends():
    cell = _ranged(robot="path_mm = [0.014, 0.14]\norientation_deg = [0.002, 0.01]")
    path = np.array([cell.instance(seed).robot.path for seed in range(3000)])
    assert path.min() >= 0.014e-3 and path.max() <= 0.14e-3
    lo, hi = np.log(0.014e-3), np.log(0.14e-3)
    assert stats.kstest((np.log(path) - lo) / (hi - lo), "uniform").pvalue > 0.01
    # ... which is not uniform in the magnitude itself: the test tells them apart
    assert stats.kstest((path - 0.014e-3) / (0.126e-3), "uniform").pvalue < 1e-6
    assert np.median(path) == pytest.approx(middle(0.014e-3, 0.14e-3), rel=0.05)
    orientation = np.array([cell.instance(seed).robot.orientation for seed in range(3000)])
    assert abs(np.corrcoef(np.log(path), np.log(orientation))[0, 1]) < 0.06  # each key its own stream


def test_a_range_from_zero_draws_uniform_up_to_its_high_end():
    cell = _ranged(calibration="frame_rotation_deg = [0, 0.2]")
    rotation = np.array([cell.instance(seed).calibration.frame_rotation for seed in range(3000)]) / (0.2 * DEG)
    assert rotation.min() >= 0 and rotation.max() <= 1
    assert stats.kstest(rotation, "uniform").pvalue > 0.01
    assert stats.kstest(np.log(rotation[rotation > 0.01]), "uniform", args=(np.log(0.01), -np.log(0.01))).pvalue < 1e-6
    assert cell.calibration.frame_rotation == pytest.approx(0.1 * DEG)  # the record holds the middle


def test_the_draws_follow_neither_the_files_order_nor_the_other_ranges():
    one = _ranged(robot="path_mm = [0.01, 0.1]\nstep = [0, 0.001]", calibration="sensor_rotation_deg = [0.01, 0.3]")
    other = _ranged(calibration="sensor_rotation_deg = [0.01, 0.3]", robot="step = [0, 0.001]\npath_mm = [0.01, 0.1]")
    alone = _ranged(robot="path_mm = [0.01, 0.1]")
    for seed in (0, 7, 123):
        assert one.instance(seed) == other.instance(seed)
        assert one.instance(seed).robot.path == alone.instance(seed).robot.path
    assert one.instance(0) != one.instance(1)
    assert [name for name, _, _ in one.ranges] == sorted(name for name, _, _ in one.ranges)
    assert draws(one.ranges, 7) == {k: v for k, v in sorted(draws(one.ranges, 7).items())}


def test_an_instance_is_a_cell_of_points_and_a_zero_range_is_off():
    cell = _ranged(robot="path_mm = [0.01, 0.1]", part="process_scale = [0.5, 2.0]")
    instance = cell.instance(4)
    assert instance.ranges == () and instance.instance(9) is instance
    assert 0.5 <= instance.process_scale <= 2.0 and instance.process_scale != 1.0
    assert cell.middle().robot.path == pytest.approx(np.sqrt(0.01 * 0.1) * 1e-3) and cell.middle().ranges == ()
    off = _ranged(robot="path_mm = [0, 0]\norientation_deg = [0.0, 0.0]", calibration="sensor_rotation_deg = [0, 0]")
    assert off.ideal and off.ranges == () and off.instance(3) is off
    point = _ranged(robot="path_mm = [0.05, 0.05]")
    assert point.ranges == () and point.robot.path == pytest.approx(0.05e-3)
    assert not _ranged(robot="path_mm = [0, 0.01]").ideal


def test_a_drawn_process_scale_scales_the_parts_process():
    cell = dataclasses.replace(load_cell("cobot"), ranges=(("process_scale", 0.5, 2.0),), process_scale=1.0)
    setup = CellSetup.of(cell, load_part("part_a"))
    instance = setup.instance(6)
    factor = instance.cell.process_scale
    assert factor != 1.0 and instance.process.face_offset == pytest.approx(setup.process.face_offset * factor)


def test_the_surrogate_scores_the_middle():
    from optipose.search.cell_terms import CellModel

    cobot = load_cell("cobot")
    box = load_part("part_b")
    import trimesh

    mesh = trimesh.creation.box((0.04, 0.03, 0.01))
    model = CellModel(CellSetup.of(cobot, box), mesh.vertices, mesh.faces, np.zeros(3), np.zeros(3), np.inf)
    assert model.cell == cobot.middle() and model.cell.ranges == ()
    assert model.cell.robot.path == pytest.approx(np.sqrt(0.014 * 0.14) * 1e-3)


def test_a_saved_cell_keeps_its_ranges():
    import tomllib

    import tomli_w

    objective = load_objective("paper").in_cell("industrial-arm")
    saved = tomllib.loads(tomli_w.dumps({"objective": objective.to_dict()}))["objective"]
    assert objective_from_dict(saved).cell == load_cell("industrial-arm")


# -- one seed, one instance: common random numbers and the exact tie ------------------------------------------
def test_every_layout_of_a_seed_gets_the_same_instance():
    import trimesh

    box = trimesh.creation.box((0.04, 0.03, 0.01))
    part = load_part("part_b")
    setup = CellSetup.of(load_cell("cobot"), part)

    def live(seed):
        return LiveCell(setup, np.asarray(box.vertices), np.asarray(box.faces), np.zeros(3), seed)

    first, second, other = live(11), live(11), live(12)
    assert first.setup.cell == second.setup.cell == load_cell("cobot").instance(11)
    assert first.setup.cell.ranges == () and other.setup.cell != first.setup.cell
    poses = [s.T_O_S for s in part.layouts["hand"].sensors]
    # two layouts (three sensors, and the first two of them) under one seed: the same calibration
    assert all(np.array_equal(a, b) for a, b in zip(first.poses(poses), second.poses(poses[:2])))
    assert not np.array_equal(first.poses(poses)[0], other.poses(poses)[0])


@pytest.fixture(scope="module")
def cobot_runs():
    part = load_part("part_b")
    layout = Layout((part.layouts["hand"].sensors[1],), name="S2")
    objective = load_objective("paper")
    protocol = dataclasses.replace(objective.protocol, sequences=("R",), start=DEG, stop=DEG)
    objective = dataclasses.replace(objective, protocol=protocol).in_cell("cobot")
    runs = []
    for seed in (5, 5, 6):
        with Evaluator(part, objective, seed=seed) as ev:
            runs.append(ev(layout))
    return runs


def test_a_layout_against_itself_under_a_ranged_cell_is_an_exact_tie(cobot_runs):
    first, again, other = (r.per_scan[["err_roll", "err_pitch", "err_yaw", "rmse"]].to_numpy(float) for r in cobot_runs)
    assert np.isfinite(first).all()
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)  # another seed, another instance
    verdict = Verdict(1, cobot_runs[0].table[0], cobot_runs[1].table[0])
    assert verdict.tie and not verdict.worse


# -- bad ranges: one line, exit 2 -------------------------------------------------------------------------
BAD_RANGES = {
    "swapped.toml": ("[robot]\npath_mm = [0.14, 0.014]\n", "path_mm = [0.14, 0.014]: its ends are swapped"),
    "three.toml": ("[calibration]\nframe_rotation_deg = [0.1, 0.2, 0.3]\n", "frame_rotation_deg must be a number or"),
    "one.toml": ("[robot]\nstep = [0.001]\n", "step must be a number or a range [low, high] of two numbers"),
    "words.toml": ('[robot]\norientation_deg = ["a", "b"]\n', "orientation_deg must be a number or a range"),
    "negative.toml": ("[robot]\npath_mm = [-0.1, 0.1]\n", "path_mm = [-0.1, 0.1]: a range's ends must be >= 0"),
    "beyond.toml": ("[robot]\npath_mm = [1, 50]\n", "path_mm = [1, 50] reaches more than any cell has (at most 10)"),
    "scale.toml": ("[part]\nprocess_scale = [2, 1]\n", "process_scale = [2, 1]: its ends are swapped"),
    "correlation.toml": ("[robot]\npath_correlation_mm = [0, 30]\n", "path_correlation_mm must be > 0"),
}


@pytest.mark.parametrize("name", [*BAD_RANGES, "suffix"])
def test_a_bad_range_or_suffix_is_one_line_and_exit_2(tmp_path, capsys, name):
    from optipose.cli.app import main

    if name == "suffix":
        cell, fragment = "cobot:zero", "cell 'cobot:zero': unknown suffix ':zero'"
    else:
        (tmp_path / name).write_text(BAD_RANGES[name][0])
        cell, fragment = str(tmp_path / name), BAD_RANGES[name][1]
    with pytest.raises(SystemExit) as info:
        main(["evaluate", "part_b", "--cell", cell, "--out", str(tmp_path / "out")])
    assert_one_line_error(SimpleNamespace(returncode=info.value.code, stderr=capsys.readouterr().err), fragment)
    assert not (tmp_path / "out").exists()


def test_a_process_preset_takes_no_range(tmp_path, monkeypatch):
    from optipose.cell import config

    (tmp_path / "processes.toml").write_text("[ranged]\nform_rms_mm = [0.001, 0.01]\n")
    monkeypatch.setattr(config, "_PROCESSES", tmp_path / "processes.toml")
    with pytest.raises(ConfigError, match="form_rms_mm must be a number >= 0"):
        config.load_process("ranged")


# -- the shipped presets ------------------------------------------------------------------------------------
def test_the_machined_bracket_preset_is_the_retired_bands_brackets_as_sourced_ranges():
    # the band: brackets off by up to +-0.2 mm and +-0.1 deg (uniform per axis), the cell zeroed, the CAD part and an
    # exact robot; as a cell: sigma = tolerance / sqrt(3) at the high end, a dowel-pinned seat at the low end
    import tomllib

    table = tomllib.loads((CELLS_DIR / "machined-bracket.toml").read_text())
    cell = load_cell("machined-bracket")
    assert cell.calibration.zeroed and not cell.as_made and cell.material and not cell.robot.moves
    ranges = {name: (lo, hi) for name, lo, hi in cell.ranges}
    assert list(ranges) == ["calibration.sensor_rotation", "calibration.sensor_translation"]
    assert ranges["calibration.sensor_translation"] == pytest.approx(
        (0.005e-3, 0.2e-3 / np.sqrt(3)), rel=5e-3
    )  # the file's three figures
    assert ranges["calibration.sensor_rotation"] == pytest.approx(
        (0.011 * DEG, 0.1 * DEG / np.sqrt(3)), rel=5e-3
    )  # the file's three figures
    for key in ("sensor_translation_mm", "sensor_rotation_deg"):
        assert (
            "retired band" in table["calibration"][f"{key}_source"] and "low:" in table["calibration"][f"{key}_source"]
        )


@pytest.mark.parametrize("name", PRESETS)
def test_a_shipped_preset_has_every_magnitude_a_sourced_range(name):
    import tomllib

    table = tomllib.loads((CELLS_DIR / f"{name}.toml").read_text())
    cell = load_cell(name)
    assert cell.name == name and cell.description and not cell.calibration.zeroed
    assert cell.as_made and cell.default_process == "milled" and cell.material  # as ur10e.toml
    assert len(cell.ranges) == 9
    for section, keys in MAGNITUDES.items():
        for key in keys:
            low, high = table[section][key]
            assert 0 <= low < high, (key, low, high)
            assert len(table[section][f"{key}_source"]) > 40, key  # a source, not a word
    zeroed = load_cell(f"{name}:zeroed")
    assert zeroed.calibration.zeroed and zeroed.name == f"{name}:zeroed" and zeroed.ranges == cell.ranges
    assert zeroed.description.endswith("zeroed on a master part") and "not zeroed" not in zeroed.description
    assert load_cell(zeroed.name) == zeroed  # a run's config names it so, and --cell reads it back


def test_optipose_cells_lists_the_shipped_cells(capsys):
    from optipose.cli.app import main

    with pytest.raises(SystemExit) as info:
        main(["cells"])
    assert info.value.code in (0, None)
    lines = capsys.readouterr().out.splitlines()
    assert set(cell_names()) == {"ideal", "ur10e", "common", "machined-bracket", *PRESETS}
    for name in cell_names():
        (line,) = [line for line in lines if line.split() and line.split()[0] == name]
        assert ("9 ranges" in line) == (name in (*PRESETS, "common"))
        assert ("not zeroed" in line) == (name != "machined-bracket")
        assert load_cell(CELLS_DIR / f"{name}.toml").description[:30] in line


def test_the_common_cell_is_the_envelope_of_the_presets_ranges():
    from optipose.cell.config import load_cell

    kinds = [
        dict((f, (lo, hi)) for f, lo, hi in load_cell(n).ranges) for n in ("cobot", "industrial-arm", "linear-axis")
    ]
    common = load_cell("common")
    assert {f for f, _, _ in common.ranges} == set(kinds[0]) == set(kinds[1]) == set(kinds[2])
    for field, low, high in common.ranges:
        assert low == pytest.approx(min(k[field][0] for k in kinds), rel=1e-12)
        assert high == pytest.approx(max(k[field][1] for k in kinds), rel=1e-12)
    assert not common.calibration.zeroed and common.as_made and common.material


def test_a_cells_ends_put_every_range_at_its_low_or_its_high_end():
    from optipose.cell.config import load_cell
    from optipose.errors import ConfigError

    cobot = load_cell("cobot")
    for end, pick in (("low", 0), ("high", 1)):
        cell = load_cell(f"cobot:{end}")
        assert cell.name == f"cobot:{end}" and not cell.ranges
        assert cell.robot.path == pytest.approx(dict((f, (lo, hi)) for f, lo, hi in cobot.ranges)["robot.path"][pick])
        values = {f: (lo, hi)[pick] for f, lo, hi in cobot.ranges}
        assert cell.calibration.frame_rotation == pytest.approx(values["calibration.frame_rotation"])
        assert cell.robot.step == pytest.approx(values["robot.step"]) and cell.instance(7) == cell
    assert load_cell("cobot:high:zeroed").calibration.zeroed
    with pytest.raises(ConfigError, match="no range"):
        load_cell("ur10e:low")
    with pytest.raises(ConfigError, match="unknown suffix"):
        load_cell("cobot:middle")
