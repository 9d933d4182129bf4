"""Invariances of the whole pipeline (scan, down-sampling, ICP, errors) on part B's hand layout: moving
the part and its sensors together, turning the whole cell about the motion axis, or giving the mesh in
millimetres must leave every per-axis error where it was (issue #17: 1e-4° = 1.7 µrad)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective, reduced_objective
from optipose.model.mesh import load_mesh
from optipose.model.part import Keepout, load_part
from optipose.transforms import make_T, rpy_to_matrix

AXES = ["err_roll", "err_pitch", "err_yaw"]
BOUND_DEG = 1e-4
# S2 alone looks straight down at B's top: only the edges of its pocket and holes hold its yaw (and,
# under a pitch offset, its roll), and its ICP stops anywhere in that flat valley: a nanometre anywhere
# (the mm mesh's float32 STL) moves it by up to 0.13°, the size of its own error there (0.06°). It is
# held to a bound of its own; every other subset, single or not, to 1e-4°.
WEAK_SUBSET, WEAK_BOUND_DEG = "S2", 0.2


@pytest.fixture(scope="module")
def part_b():
    return load_part("part_b")


def _short(sequences):
    objective = load_objective("paper").in_cell("ideal")
    return replace(objective, protocol=replace(reduced_objective(objective).protocol, sequences=sequences))


def _errors_deg(part, sequences=("R", "P")) -> tuple[np.ndarray, np.ndarray]:
    """(subset names (n,), per-scan errors (n, 3) in degrees) of the part's hand layout, seed 3."""
    with Evaluator(part, _short(sequences), seed=3) as evaluator:
        per_scan = evaluator(part.layouts["hand"]).per_scan
    assert per_scan["ok"].all()
    return per_scan["subset"].to_numpy(), np.rad2deg(per_scan[AXES].to_numpy())


def _moved(part, T: np.ndarray):
    """The cell (mesh, rotation centre, keep-outs, hand layout) moved by the rigid T (4, 4)."""
    mesh = part.mesh.copy()
    mesh.apply_transform(T)
    corners = lambda k: np.array(np.meshgrid(*zip(k.lo, k.hi))).reshape(3, -1).T @ T[:3, :3].T + T[:3, 3]  # noqa: E731
    keepouts = [Keepout(k.name, corners(k).min(axis=0), corners(k).max(axis=0)) for k in part.keepouts]
    hand = part.layouts["hand"]
    layout = replace(hand, sensors=tuple(replace(s, T_O_S=T @ s.T_O_S) for s in hand.sensors))
    centre = T[:3, :3] @ part.rotation_centre + T[:3, 3]
    return replace(part, mesh=mesh, rotation_centre=centre, keepouts=keepouts, layouts={"hand": layout})


def _assert_same(subsets, before, after):
    change = np.abs(after - before)
    weak = subsets == WEAK_SUBSET
    print(f"largest change {change[~weak].max():.2g} deg, {WEAK_SUBSET} alone {change[weak].max():.2g} deg")
    assert change[~weak].max() < BOUND_DEG
    assert change[weak].max() < WEAK_BOUND_DEG


@pytest.mark.parametrize("t", [[1.0, -1.0, 1.0], [10.0, 0.0, 0.0], [0.0, 0.0, 10.0], [10.0, -10.0, 10.0]])
def test_moving_the_whole_cell_far_from_O_changes_no_error(part_b, t):
    subsets, before = _errors_deg(part_b)
    _, after = _errors_deg(_moved(part_b, make_T(t=t)))
    _assert_same(subsets, before, after)


@pytest.mark.parametrize("angle_deg", [90, 180, -90])
def test_turning_the_whole_cell_about_the_motion_axis_turns_the_errors(part_b, angle_deg):
    # roll about x_O commutes with the turn, so the scans are the turned scans; an error rotation ω of the
    # estimate becomes Rx·ω: roll stays, (pitch, yaw) turn by the angle
    subsets, before = _errors_deg(part_b, ("R",))
    _, after = _errors_deg(_moved(part_b, make_T(rpy_to_matrix([np.deg2rad(angle_deg), 0, 0]))), ("R",))
    c, s = np.cos(np.deg2rad(angle_deg)), np.sin(np.deg2rad(angle_deg))
    back = np.column_stack([after[:, 0], c * after[:, 1] + s * after[:, 2], -s * after[:, 1] + c * after[:, 2]])
    _assert_same(subsets, before, back)


def test_a_mesh_in_millimetres_gives_the_errors_of_the_mesh_in_metres(part_b, tmp_path):
    mesh = part_b.mesh.copy()
    mesh.apply_scale(1000.0)
    mesh.export(tmp_path / "part_b_mm.stl")
    in_mm = load_mesh(tmp_path / "part_b_mm.stl", units="auto")  # 72 "units" across: taken as mm
    assert np.abs(in_mm.vertices - part_b.mesh.vertices).max() < 1e-8  # float32 STL: nanometres
    subsets, before = _errors_deg(part_b)
    _, after = _errors_deg(replace(part_b, mesh=in_mm))
    _assert_same(subsets, before, after)
