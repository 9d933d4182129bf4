"""The surrogate's cell term (optipose.search.cell_terms): the ideal cell is today's surrogate exactly, a
source at zero magnitude adds nothing, independent sources add, and cases worked out by hand."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from optipose.cell.asmade import Process
from optipose.cell.config import IDEAL, Cell, load_cell
from optipose.cell.robot import CalibrationErrors, RobotErrors
from optipose.cell.scans import CellSetup
from optipose.evaluate.objective import load_objective
from optipose.model.material import MaterialEffects
from optipose.model.part import load_part
from optipose.search.cell_terms import CellModel, sensor_maps, subset_terms
from optipose.search.surrogate import Surrogate, predicted_stats, protocol_turns

SIGMA = 1e-3  # rad / m: an error small enough to be linear, large enough to read

# a head looking down (z_S = −z_O) whose laser plane is across the motion (y_S = x_O): a turn about its
# plane's normal is a turn of its whole cloud, about x_O, roll
T_DOWN = np.array([[0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.1], [0.0, 0.0, 0.0, 1.0]])


def _cloud() -> tuple[np.ndarray, np.ndarray]:
    """Points (m, 3) on four planes of different slopes over 40 × 40 mm, and their unit normals: all six
    pose parameters observable."""
    rng = np.random.default_rng(0)
    slopes = np.array([[0.0, 0.0], [0.3, 0.3], [-0.3, 0.2], [0.1, -0.4]])
    xy = rng.uniform(-0.02, 0.02, (400, 2))
    which = np.arange(400) % 4
    z = np.einsum("ij,ij->i", xy, slopes[which])
    n = np.c_[-slopes[which], np.ones(400)]
    return np.c_[xy, z], n / np.linalg.norm(n, axis=1, keepdims=True)


def _terms(cell: Cell, effects: MaterialEffects = MaterialEffects(), process: Process = Process(), sensors=(T_DOWN,)):
    """A subset's cell variance and bias (3,) at one turn (the nominal orientation again) for the cloud
    seen by heads at ``sensors``."""
    import trimesh

    box = trimesh.creation.box((0.04, 0.04, 0.01))
    offsets = np.linspace(-0.02, 0.02, 41)
    model = CellModel(CellSetup(cell, process, effects), box.vertices, box.faces, np.zeros(3), offsets, np.inf)
    v, n = _cloud()
    turns = [(v, n, np.zeros(len(v), np.int64), np.eye(3))] * 2
    var, bias = subset_terms([sensor_maps(model, turns, T, 4.0) for T in sensors])
    return var[0], bias[0]


def _cell(**kw) -> Cell:
    robot = kw.pop("robot", RobotErrors())
    return Cell(name="test", robot=robot, calibration=CalibrationErrors(**kw))


def test_a_heads_own_turn_about_its_laser_plane_normal_is_the_estimates_roll():
    var, bias = _terms(_cell(sensor_rotation=SIGMA))
    # σ per axis of the head's own rotation; only its turn about y_S (= x_O) is rigid: roll gets σ² of it
    assert var[0] == pytest.approx(SIGMA**2, rel=0.02)
    assert np.all(bias == 0)


def test_the_frames_roll_maps_to_the_estimate_directly():
    var, _ = _terms(_cell(frame_rotation=SIGMA), sensors=(T_DOWN, T_DOWN @ _shifted(0.03)))
    assert var[0] == pytest.approx(SIGMA**2, rel=0.02)


def _shifted(dy: float) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = dy
    return T


def test_a_constant_path_rotation_is_the_parts_pose_error():
    # a path error correlated over far more than the travel is one rigid pose error of the part for the
    # whole scan: the estimate moves by it, on every axis
    robot = RobotErrors(path_rotation=SIGMA, path_correlation=1e3)
    var, _ = _terms(_cell(robot=robot))
    assert var == pytest.approx(np.full(3, SIGMA**2), rel=0.02)


def test_the_set_orientation_adds_its_variance_to_every_axis():
    # the protocol's ground truth is off by it: every layout alike, it does not rank
    var, _ = _terms(_cell(robot=RobotErrors(orientation=SIGMA)))
    assert var == pytest.approx(np.full(3, SIGMA**2))


def test_a_sub_surface_bias_along_parallel_rays_moves_the_cloud_without_turning_it():
    # every point moved by b along one direction is a translation of the cloud: no rotation, whatever the faces
    _, bias = _terms(_cell(robot=RobotErrors(orientation=1e-9)), effects=MaterialEffects(subsurface_bias=SIGMA))
    assert np.abs(bias).max() < 1e-6 * SIGMA


def test_a_source_at_zero_magnitude_adds_nothing_and_independent_sources_add():
    base = _cell(robot=RobotErrors(orientation=SIGMA))
    zero = {
        "calibration": dict(cell=replace(base, calibration=CalibrationErrors(zeroed=False))),
        "robot": dict(cell=replace(base, robot=RobotErrors(orientation=SIGMA, path_correlation=0.03))),
        "material": dict(cell=base, effects=MaterialEffects()),
        "part": dict(cell=base, process=Process(name="milled", form_wavelengths=(0.01, 0.06))),
    }
    alone = _terms(base)[0]
    for name, kw in zero.items():
        assert np.array_equal(_terms(**kw)[0], alone), name
    sources = {
        "calibration": dict(cell=replace(base, calibration=CalibrationErrors(SIGMA, SIGMA, SIGMA, SIGMA))),
        "robot": dict(cell=replace(base, robot=RobotErrors(SIGMA, SIGMA, 0.03, 1e-3, SIGMA))),
        "material": dict(cell=base, effects=MaterialEffects(speckle=SIGMA, subsurface_bias=SIGMA)),
    }
    every = dict(
        cell=replace(
            base, calibration=sources["calibration"]["cell"].calibration, robot=sources["robot"]["cell"].robot
        ),
        effects=sources["material"]["effects"],
    )
    each = sum(_terms(**kw)[0] - alone for kw in sources.values()) + alone
    assert _terms(**every)[0] == pytest.approx(each, rel=1e-4)


@pytest.fixture(scope="module")
def part_b():
    return load_part("part_b")


def test_the_ideal_cell_is_todays_surrogate_exactly(part_b):
    turns = protocol_turns(load_objective("paper").in_cell("ideal"))
    today = Surrogate(part_b, turns=turns)
    ideal = Surrogate(part_b, turns=turns, cell=CellSetup.of(IDEAL, part_b))
    assert ideal.cell is None
    poses = part_b.layouts["hand"].poses
    a, b = [today.info(T) for T in poses], [ideal.info(T) for T in poses]
    for x, y in zip(a, b):
        assert y.cell is None
        assert all(np.array_equal(getattr(x, f), getattr(y, f)) for f in ("H", "A", "G"))
    p, q = predicted_stats(a), predicted_stats(b)
    assert np.array_equal(p.median_deg, q.median_deg) and np.array_equal(p.p75_deg, q.p75_deg) and p.score == q.score


def test_the_search_problem_scores_under_its_objectives_cell(part_b):
    from optipose.search.config import SearchConfig
    from optipose.search.problem import SurrogateProblem

    paper = load_objective("paper").in_cell("ideal")
    ideal, real = (
        SurrogateProblem(part_b, paper, SearchConfig()),
        SurrogateProblem(part_b, paper.in_cell("ur10e"), SearchConfig()),
    )
    assert ideal.surrogate.cell is None and real.surrogate.cell is not None
    hand = np.concatenate([ideal.space.from_pose(T) for T in part_b.layouts["hand"].poses])
    # the cell's errors are orders of magnitude above the ideal cell's (docs/cell.md)
    assert real.score(hand, constrained=False).value > 10 * ideal.score(hand, constrained=False).value


def test_a_zeroed_cell_takes_off_what_a_fixed_source_does_at_the_nominal_orientation():
    # the one turn is the nominal orientation again: a rigid calibration error zeroed there leaves nothing
    cell = replace(
        _cell(sensor_rotation=SIGMA, frame_rotation=SIGMA),
        calibration=CalibrationErrors(0.0, SIGMA, 0.0, SIGMA, zeroed=True),
    )
    var, _ = _terms(cell)
    assert np.abs(var).max() < 1e-6 * SIGMA**2
    assert (
        load_cell("ur10e").calibration.zeroed is False
    )  # the paper's cell is not zeroed: the term is the un-zeroed one


def test_the_form_fields_features_carry_its_rms_at_every_point():
    # cos² + sin² = 1 per frequency: the features' variance at a point is the process's form RMS², exactly,
    # and two points far apart in wavelengths are nearly uncorrelated
    import trimesh

    box = trimesh.creation.box((0.04, 0.04, 0.01))
    process = Process(name="milled", form_rms=3e-6, form_wavelengths=(0.01, 0.06))
    model = CellModel(
        CellSetup(_cell(), process, MaterialEffects()), box.vertices, box.faces, np.zeros(3), np.zeros(1), np.inf
    )
    x = np.array([[0.0, 0.0, 0.005], [0.0, 0.0, 0.005], [2.0, 0.0, 0.005]])
    form = model.part_columns(x, np.tile([0.0, 0.0, 1.0], (3, 1)))[:, :-4]  # the scale and warp columns are zero here
    assert (form**2).sum(axis=1) == pytest.approx(np.full(3, 3e-6**2))
    assert form[0] @ form[1] == pytest.approx(3e-6**2) and abs(form[0] @ form[2]) < 0.3 * 3e-6**2


_RANGES = (
    ("calibration.frame_rotation", 1e-4, 2e-3),
    ("calibration.frame_translation", 0.0, 4e-4),
    ("calibration.sensor_rotation", 2e-4, 3e-3),
    ("calibration.sensor_translation", 5e-5, 2e-4),
    ("process_scale", 0.5, 2.0),
    ("robot.orientation", 1e-5, 4e-5),
    ("robot.path", 1e-5, 3e-4),
    ("robot.path_rotation", 0.0, 1e-4),
    ("robot.step", 0.0, 2e-4),
)


def _variances(setup: CellSetup, R: np.ndarray) -> np.ndarray:
    """subset_terms' variance for two heads on the four-plane cloud, at the nominal orientation and turned by R."""
    import trimesh

    box = trimesh.creation.box((0.04, 0.04, 0.01))
    model = CellModel(setup, box.vertices, box.faces, np.zeros(3), np.linspace(-0.02, 0.02, 41), np.inf)
    v, n = _cloud()
    face = np.arange(len(v)) % len(box.faces)
    turns = [(v, n, face, np.eye(3)), (v, n, face, R)]
    return subset_terms([sensor_maps(model, turns, T, 4.0) for T in (T_DOWN, T_DOWN @ _shifted(0.03))])[0]


@pytest.mark.parametrize("zeroed", [False, True])
def test_each_magnitude_instance_of_a_ranged_cell_scores_as_that_point_cell(zeroed):
    """A cell of ranges is scored on its spread (optipose.cell.ranges.spread) by rescaling each source's variance
    from the maps built at the middles: each instance's variance is the one of the point cell of its magnitudes,
    whose maps are built anew."""
    from optipose.cell.config import load_process
    from optipose.cell.ranges import middle, spread
    from optipose.search.cell_terms import _INSTANCES

    mids = {name: middle(lo, hi) for name, lo, hi in _RANGES}
    robot = RobotErrors(path_correlation=0.02, **{k[6:]: v for k, v in mids.items() if k.startswith("robot.")})
    calibration = CalibrationErrors(
        zeroed=zeroed, **{k[12:]: v for k, v in mids.items() if k.startswith("calibration.")}
    )
    cell = Cell(
        name="ranged",
        robot=robot,
        calibration=calibration,
        as_made=True,
        process_scale=mids["process_scale"],
        ranges=_RANGES,
    )
    milled = load_process("milled")
    c, s = np.cos(np.deg2rad(2.0)), np.sin(np.deg2rad(2.0))
    R = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    ranged = _variances(CellSetup(cell, milled.scaled(cell.process_scale), MaterialEffects()), R)
    assert ranged.shape == (_INSTANCES, 1, 3)
    instances = spread(_RANGES, _INSTANCES)
    for got, magnitudes in zip(ranged, instances):
        point = cell._with(magnitudes)
        want = _variances(CellSetup(point, milled.scaled(point.process_scale), MaterialEffects()), R)
        np.testing.assert_allclose(got, want, rtol=1e-5)
    # the instances differ: a range is scored across, not at its middle
    assert np.ptp(ranged[:, 0, 0]) > 0.5 * ranged[:, 0, 0].min()


def test_a_ranges_spread_takes_each_stratum_once_and_ends_inside():
    from optipose.cell.ranges import quantile, spread

    instances = spread(_RANGES, 8)
    for name, low, high in _RANGES:
        values = sorted(inst[name] for inst in instances)
        want = [quantile(low, high, (i + 0.5) / 8) for i in range(8)]
        np.testing.assert_allclose(values, want, rtol=1e-12)
        assert low <= values[0] and values[-1] <= high
    assert spread(_RANGES, 8) == instances  # the same on every call
    # log-uniform: the middle stratum pair brackets the geometric mean
    assert quantile(1e-5, 3e-4, 0.5) == pytest.approx(np.sqrt(1e-5 * 3e-4))
