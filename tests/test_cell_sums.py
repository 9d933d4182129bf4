"""The compiled pass of the surrogate's cell term (optipose.search.cell_sums) against the numpy formulation it
replaced, written out here: the same maps to float32 rounding, on real turns of part A, B and C in the
paper's cell (fan rays, form, faces, path, step, material) and on a synthetic cloud under parallel rays."""

from __future__ import annotations

import numpy as np
import pytest

from optipose.cell.asmade import Process
from optipose.cell.config import Cell
from optipose.cell.robot import CalibrationErrors, RobotErrors
from optipose.cell.scans import CellSetup
from optipose.evaluate.objective import load_objective
from optipose.model.material import MaterialEffects
from optipose.model.part import load_part
from optipose.search import surrogate as surrogate_module
from optipose.search.cell_terms import CellMaps, CellModel, sensor_maps
from optipose.search.mounting import displacement


def _reference_turn(model: CellModel, T_O_S: np.ndarray, raw_per_voxel: float, v, n, face, R) -> tuple:
    """One turn's maps as cell_terms computed them before the compiled pass (numpy, per-point temporaries)."""
    c = model.centre
    p, n_O = (v - c) @ R.T + c, n @ R.T
    J = np.hstack([np.cross(p - c, n_O), n_O])
    L = np.einsum("ij,ijk->ik", n_O, displacement(p, T_O_S))
    own = J.T @ (L * model.own_sigma)
    Rs, o = T_O_S[:3, :3], T_O_S[:3, 3]
    a = o - c
    frame = np.zeros((6, 6))
    frame[:3, :3], frame[3:, 3:] = Rs.T, Rs.T
    frame[3:, :3] = -Rs.T @ np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    shared = np.hstack([J.T @ (L @ frame * model.frame_sigma), J.T @ model.part_columns(v, n)])
    y_S = T_O_S[:3, 1]
    s = (T_O_S[:3, 3] - p) @ y_S / np.copysign(max(abs(float(y_S[0])), 1e-3), float(y_S[0]))
    path = np.zeros((6, 0))
    if model.modes.shape[1]:
        at = np.clip(np.searchsorted(model.offsets, s), 0, len(model.offsets) - 1)
        JJ = J[:, :, None] * (J * model.path_sigma)[:, None, :]
        path = (model.modes[at].T @ JJ.reshape(len(J), 36)).reshape(-1, 6, 6).transpose(1, 0, 2).reshape(6, -1)
    if model.step:
        path = np.hstack([path, (J.T @ (n_O[:, 0] * s * model.step))[:, None]])
    if np.isfinite(model.apex_z):
        apex = T_O_S[:3, :3] @ np.array([0.0, 0.0, model.apex_z]) + T_O_S[:3, 3]
        u = p + s[:, None] * np.array([1.0, 0.0, 0.0]) - apex
        rays = u / np.linalg.norm(u, axis=1, keepdims=True)
    else:
        rays = np.broadcast_to(T_O_S[:3, 2], p.shape)
    cos = np.einsum("ij,ij->i", rays, n_O)
    white = (J * (cos**2 * model.white / max(raw_per_voxel, 1.0))[:, None]).T @ J
    bias = J.T @ (cos * model.sub_bias)
    plane, cols = _face_columns(model, v, n, face)
    planes = np.unique(plane) if cols.shape[1] else np.zeros(0, np.int64)
    per_plane = np.zeros((len(planes), 6, cols.shape[1]))
    if len(planes):
        order = np.argsort(plane, kind="stable")
        runs = np.searchsorted(plane[order], planes)
        per_plane = np.add.reduceat((J[order, :, None] * cols[order, None, :]), runs, axis=0)
    return J.T @ J, own, shared, path, white, bias, planes, per_plane


def _face_columns(model: CellModel, x, n, face) -> tuple:
    """Each point's plane number (m,), and per unit random number its plane's offset and tilt (m, 4)."""
    p = model.process
    if not model.face_width:
        return np.zeros(len(x), np.int64), np.zeros((len(x), 0))
    plane = model.plane[face]
    arm = np.cross(x - model.made.plane_centroid[plane], n)  # tilt τ turns the point's normal offset by τ·(arm × n)
    return plane, np.hstack([np.full((len(x), 1), p.face_offset), arm * p.face_tilt])


def _assert_same_maps(new: CellMaps, model: CellModel, turns: list, T_O_S: np.ndarray, raw_per_voxel: float):
    """Each map of ``new`` equals the reference's per turn, to float32 rounding of the map's largest entry
    (the reference's form features are float32 cos and sin, summed over up to thousands of points)."""
    ref = [_reference_turn(model, T_O_S, raw_per_voxel, *t) for t in turns]
    planes = np.unique(np.concatenate([r[6] for r in ref]))
    assert np.array_equal(new.planes, planes)
    for i, name in enumerate(("A", "own", "shared", "path", "white", "bias")):
        got, want = getattr(new, name), np.array([r[i] for r in ref])
        wide = name in ("shared", "path")  # the wide maps float32, the 6 × 6 ones and the bias float64
        assert got.dtype == (np.float32 if wide else np.float64) and got.shape == want.shape, name
        # the frame's columns and the part's apart: the form's are some 10× smaller than the frame's
        blocks = (slice(0, 6), slice(6, None)) if name == "shared" else (slice(None),)
        for t in range(len(turns)):
            for b in blocks:
                assert _off(got[t][..., b], want[t][..., b]) <= 2e-5 * _off(want[t][..., b], 0.0) + 1e-30, (name, t)
    for t, r in enumerate(ref):
        got = new.faces[t, np.searchsorted(planes, r[6])]
        assert got.shape == r[7].shape and _off(got, r[7]) <= 2e-5 * _off(r[7], 0.0) + 1e-30
    assert new.faces.shape == (len(turns), len(planes), 6, model.face_width)


def _off(a: np.ndarray, b) -> float:
    return float(np.abs(a - b).max(initial=0.0))


@pytest.mark.parametrize("name", ["part_a", "part_b", "part_c"])
def test_the_compiled_maps_are_the_numpy_ones_on_a_parts_turns_in_the_papers_cell(name, monkeypatch):
    from optipose.search.config import SearchConfig
    from optipose.search.problem import SurrogateProblem

    part = load_part(name)
    problem = SurrogateProblem(part, load_objective("paper").in_cell("ur10e"), SearchConfig())
    surrogate, model = problem.surrogate, problem.surrogate.cell
    assert model.made is not None and model.face_width and model.modes.shape[1] and model.step
    calls = []

    def recorded(*args):
        calls.append((args, sensor_maps(*args)))
        return calls[-1][1]

    monkeypatch.setattr(surrogate_module, "sensor_maps", recorded)
    # the hand layout's heads, and random poses of the search's space (heads off the axes: a point's travel
    # lands on its profile's to rounding, and which profile it is given must be the numpy one's)
    random = [problem.space.to_pose(u) for u in np.random.default_rng(1).random((6, 6))]
    for T in [*part.layouts["hand"].poses, *random]:
        surrogate.info(T)
    assert len(calls) >= len(part.layouts["hand"].poses) + 2
    for (model_, turns, T_O_S, raw_per_voxel), new in calls:
        assert len(turns) == len(surrogate.motions) + 1 and all(len(t[0]) for t in turns)
        _assert_same_maps(new, model_, turns, T_O_S, raw_per_voxel)


def test_the_compiled_maps_are_the_numpy_ones_under_parallel_rays_and_without_the_part():
    import trimesh

    rng = np.random.default_rng(3)
    box = trimesh.creation.box((0.04, 0.04, 0.01))
    x = rng.uniform(-0.02, 0.02, (300, 3)) * [1, 1, 0.25]
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    face = rng.integers(0, len(box.faces), 300)
    R = trimesh.transformations.euler_matrix(0.1, -0.2, 0.3)[:3, :3]
    T = np.array([[0.0, 1.0, 0.0, 0.01], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.1], [0.0, 0.0, 0.0, 1.0]])
    T[:3, :3] = R @ T[:3, :3]  # a head turned off the axes: every term of the travel and the rays in play
    cell = Cell(
        name="test",
        robot=RobotErrors(path=1e-4, path_rotation=1e-4, path_correlation=0.01, step=1e-3),
        calibration=CalibrationErrors(1e-3, 2e-4, 3e-4, 4e-4),
    )
    effects = MaterialEffects(speckle=1e-5, subsurface_bias=2e-5)
    made = Process(name="printed", form_rms=3e-6, face_offset=1e-5, face_tilt=1e-4, scale=1e-3, warp=1e-4)
    for process in (made, Process()):
        model = CellModel(
            CellSetup(cell, process, effects),
            box.vertices,
            box.faces,
            np.zeros(3),
            np.linspace(-0.03, 0.03, 31),
            np.inf,
        )
        turns = [(x, n, face, np.eye(3)), (x, n, face, R)]
        _assert_same_maps(sensor_maps(model, turns, T, 3.0), model, turns, T, 3.0)
