"""The surrogate's voxel-bias model (the error it predicts exists, has the right size, and adds up) and the
first-order map of a sensor off its believed pose (what the cell term builds on)."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from optipose.evaluate.objective import load_objective
from optipose.model.part import load_part
from optipose.registration.reference import SurfaceReference
from optipose.registration import register, voxel_down
from optipose.scan.scanner import PartPose, part_scanner
from optipose.search.surrogate import Surrogate, SensorInfo, bias_rotation, predicted_stats
from optipose.transforms import invert_T, matrix_to_rpy

# orientations of the part (deg): the protocol's ends and a few in between
TURNS = [(2, 0, 0), (-1.2, 0, 0), (0, 2, 0), (0, -1.2, 0), (0, 0, 2), (0, 0, -1.2), (1.2, 1.2, 1.2), (-2, -2, -2)]


@pytest.fixture(scope="module")
def part_b():
    part = load_part("part_b")
    return (
        part,
        load_objective("paper").in_cell("ideal").registration,
        SurfaceReference(part.mesh.vertices, part.mesh.faces),
    )


def _roll_errors_mdeg(part, cfg, reference, T, voxel: float, noise: bool) -> np.ndarray:
    scanner = part_scanner(part)
    out = []
    for i, rpy in enumerate(np.deg2rad(np.array(TURNS, dtype=float))):
        scan = scanner.scan(T, part.motion, PartPose(rpy, part.rotation_centre), rng=i + 1, noise=noise)
        cloud = voxel_down(scan.points, voxel) if voxel > 0 else scan.points[::4]
        T_est = invert_T(register(cloud, reference, cfg).T_target_source)
        out.append(matrix_to_rpy(T_est[:3, :3])[0] - rpy[0])
    return np.abs(np.rad2deg(out)) * 1e3


def test_voxel_centroids_not_noise_limit_part_b_roll(part_b):
    # Why the surrogate models the voxel bias: with exact (noise-free) points, ICP on the raw points returns
    # the set roll to 1e-6 mdeg, while on 0.5 mm voxel centroids it ends mdeg off, far above what the
    # 2 µm noise costs on the raw points.
    part, cfg, reference = part_b
    S1 = part.layouts["hand"].poses[0]
    exact_raw = _roll_errors_mdeg(part, cfg, reference, S1, 0.0, noise=False)
    exact_voxels = _roll_errors_mdeg(part, cfg, reference, S1, cfg.voxel_size, noise=False)
    noisy_raw = _roll_errors_mdeg(part, cfg, reference, S1, 0.0, noise=True)
    assert exact_raw.max() < 1e-3
    assert np.median(exact_voxels) > 1.0
    assert np.median(exact_voxels) > 10 * np.median(noisy_raw)


def test_surrogate_predicts_the_size_of_the_voxel_bias(part_b):
    # the surrogate's roll prediction for B's hand S1 and S2 (noise-free, bias only) against ICP on voxel
    # centroids at eight orientations: same order of magnitude, and S2 (which looks straight down and sees
    # no edge along the scan from two faces) far below S1
    part, cfg, reference = part_b
    surrogate = Surrogate(part, voxel=cfg.voxel_size)
    predicted, measured = [], []
    for T in part.layouts["hand"].poses[:2]:
        info = surrogate.info(T)
        predicted.append(np.median(np.abs(np.rad2deg(bias_rotation(info.A, info.G)[:, 0]))) * 1e3)
        measured.append(np.median(_roll_errors_mdeg(part, cfg, reference, T, cfg.voxel_size, noise=False)))
    assert 1 / 3 < predicted[0] / measured[0] < 3
    assert predicted[1] < predicted[0] / 10 and measured[1] < measured[0] / 10


def test_bias_step_is_the_gauss_newton_step():
    # A = diag(4, 1, 2, 1, 1, 1), g = (1, 2, 3, 4, 5, 6)·1e-3 gives δ = −A⁻¹g: rotations −(0.25, 2, 1.5)·1e-3
    # rad; a direction without information (A singular there) gets no step; a step beyond the weak
    # prior's 5° is cut there
    A = np.diag([4.0, 1.0, 2.0, 1.0, 1.0, 1.0])
    G = np.array([[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]]) * 1e-3
    assert np.allclose(bias_rotation(A, G), [[-0.25e-3, -2.0e-3, -1.5e-3]])
    A[2, 2] = 0.0
    assert np.allclose(bias_rotation(A, G), [[-0.25e-3, -2.0e-3, 0.0]])
    assert np.allclose(bias_rotation(A, G * 1e2), [[-0.025, -np.deg2rad(5), 0.0]])  # 0.2 rad cut to 5°


def test_bias_of_a_subset_is_the_step_of_its_summed_equations():
    rng = np.random.default_rng(0)
    infos = []
    for _ in range(2):
        J = rng.normal(size=(50, 6))
        r = rng.normal(size=(3, 50))
        infos.append(SensorInfo(np.eye(6) * 1e12, 10_000, 100, J.T @ J, r @ J))
    stats = predicted_stats(infos)
    both = stats.subsets.index((0, 1))
    delta = bias_rotation(infos[0].A + infos[1].A, infos[0].G + infos[1].G)
    # with σ ≈ 0 (huge H), the median |error| is the median of |δ| over the three phases
    assert np.allclose(stats.median_deg[both], np.rad2deg(np.median(np.abs(delta), axis=0)), rtol=1e-3)


def test_plane_seen_head_on_has_no_voxel_bias(flat_plate):
    # the centroid of points on a plane lies on the plane: no residual, no bias, whatever the turn
    plate, down = flat_plate
    info = Surrogate(plate).info(down)
    assert np.abs(info.G).max() < 1e-12 * np.abs(info.A).max()


# --- a sensor off its believed pose ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def hand_b_infos(part_b):
    from optipose.search.surrogate import protocol_turns

    part, cfg, _ = part_b
    surrogate = Surrogate(part, voxel=cfg.voxel_size, turns=protocol_turns(load_objective("paper").in_cell("ideal")))
    return [surrogate.info(T) for T in part.layouts["hand"].poses]


def test_the_prediction_record_is_consistent(hand_b_infos):
    # the fields of one Prediction agree with each other: the per-axis best subsets are the paper's
    # assignment (lowest median, ties by p75), the axis scores are theirs, and the score is their weighted sum
    weights, median_weight, p75_weight = (1.0, 2.0, 0.5), 1.0, 0.5
    p = predicted_stats(hand_b_infos, weights, median_weight, p75_weight)
    n = len(hand_b_infos)
    assert p.subsets == tuple(c for r in range(1, n + 1) for c in itertools.combinations(range(n), r))
    assert p.median_deg.shape == p.p75_deg.shape == (2**n - 1, 3) and p.axis_score.shape == (3,)
    assert p.level_axis_score.shape == (1, 3) and p.level_axis_stats.shape == (1, 3, 2)
    for a, best in enumerate(p.best_subset):
        row = p.subsets.index(best)
        assert min(zip(p.median_deg[:, a], p.p75_deg[:, a])) == (p.median_deg[row, a], p.p75_deg[row, a])
        assert p.axis_score[a] == median_weight * p.median_deg[row, a] + p75_weight * p.p75_deg[row, a]
    assert p.score == float(np.dot(weights, p.axis_score))
    # the one level's statistics are the axes' own
    assert np.array_equal(p.level_axis_score[0], p.axis_score)
    assert np.array_equal(
        p.level_axis_score, median_weight * p.level_axis_stats[..., 0] + p75_weight * p.level_axis_stats[..., 1]
    )
    with pytest.raises(AttributeError):
        p.score = 0.0  # frozen


def test_displacement_map_is_the_rebuilt_scan_to_first_order(part_b):
    # independent reference: the scanner's own rebuild of a cloud whose sensor stood off its drawn pose
    from optipose.scan.cloud import rebuilt_with
    from optipose.search.mounting import displacement
    from optipose.transforms import make_T, rpy_to_matrix

    part, _, _ = part_b
    T = part.layouts["hand"].poses[0]
    scan = part_scanner(part).scan(T, part.motion, PartPose(centre=part.rotation_centre), noise=False)
    xi = np.array([3e-5, -2e-5, 4e-5, 2e-6, -3e-6, 1e-6])  # small: the rebuild is linear in it to ~1e-5
    true = replace(scan, T_O_S=T @ make_T(rpy_to_matrix(xi[:3]), xi[3:]))
    moved = rebuilt_with(true, T, part.motion.offsets()).points - scan.points
    predicted = displacement(scan.points, T) @ xi
    assert np.abs(moved).max() > 1e-6  # the rotation's shear along the scan is in it, up to ~2 µm
    assert np.abs(predicted - moved).max() < 1e-3 * np.abs(moved).max()


def test_the_prediction_is_the_formula_written_out(hand_b_infos):
    # the bias step over the summed equations, noise σ from H
    from optipose.search.prediction import axis_stats as _axis_stats
    from optipose.search.surrogate import rotation_sigma

    stats = predicted_stats(hand_b_infos)
    for s, c in enumerate(stats.subsets):
        delta = bias_rotation(sum(hand_b_infos[i].A for i in c), sum(hand_b_infos[i].G for i in c))
        m, q = _axis_stats(rotation_sigma(sum(hand_b_infos[i].H for i in c)), delta)
        assert np.array_equal(stats.median_deg[s], np.rad2deg(m)) and np.array_equal(stats.p75_deg[s], np.rad2deg(q))


def test_prefetching_poses_on_threads_fills_the_cache_as_scoring_them_one_by_one(part_b):
    """The screen scores its poses on every core first (``SurrogateProblem.prefetch``): each pose's
    information (or its violation) is the one a plain call computes, bit for bit, whatever the threads."""
    from scipy.stats import qmc

    from optipose.search.budgets import config_from_budget
    from optipose.search.problem import SurrogateProblem

    part, objective, config = part_b[0], load_objective("paper").in_cell("ideal"), config_from_budget("default", (1,))
    points = qmc.Sobol(6, scramble=True, seed=3).random(24)
    threaded, plain = SurrogateProblem(part, objective, config), SurrogateProblem(part, objective, config)
    threaded.prefetch(points, threads=3)
    assert len(threaded.cache) == 24
    feasible = 0
    for u in points:
        a, b = threaded.sensor(u), plain.sensor(u)
        assert type(a) is type(b)
        if isinstance(a, SensorInfo):
            feasible += 1
            np.testing.assert_array_equal(a.H, b.H)
            np.testing.assert_array_equal(a.G, b.G)
        else:
            assert (a.constraint, a.amount) == (b.constraint, b.amount)
    assert feasible >= 5


def test_a_screen_cut_short_by_the_clock_records_what_it_computed(part_b):
    """In the paper's cell a pose costs several nominal ones, and the screen's 4,096 do not fit in a sensor count's
    share of the clock: the screen computes its poses ahead in chunks and records each chunk, so when the
    clock ends it, what was computed is in the history (a first version computed them all ahead and
    recorded none: "no feasible layout in 0 evaluations")."""
    from optipose.search.budgets import config_from_budget
    from optipose.search.driver import SubProblem
    from optipose.search.problem import SurrogateProblem
    from optipose.search.screen import screen
    from optipose.search.study import Stop, SurrogateStudy

    config = config_from_budget("default", (1,))
    study = SurrogateStudy(SurrogateProblem(part_b[0], load_objective("paper"), config))
    study.start_clock(4.0)
    with pytest.raises(Stop):
        screen(SubProblem(study, np.zeros(0)), config, 1, seed=0)
    assert 16 <= len(study.history) < config.surrogate.screen_samples
    assert any(e.state.name == "FEASIBLE" for e in study.history)


def test_a_subset_met_before_is_looked_up_with_the_same_numbers():
    # the memo keyed by the sensors' keys, in order: a screen re-scores the placed sensors' subsets thousands
    # of times; what it returns must be what computing them gives, bit for bit
    part = load_part("part_b")
    objective = load_objective("paper").in_cell("ideal")
    surrogate = Surrogate(part, voxel=objective.registration.voxel_size, turns=np.deg2rad(np.array(TURNS[:3], float)))
    infos = [surrogate.info(T) for T in part.layouts["hand"].poses]
    kw: dict = {}
    memo: dict = {}
    for order in ([0, 1], [0, 2], [0, 1, 2], [2, 0], [1]):
        chosen = [infos[i] for i in order]
        looked_up = predicted_stats(chosen, memo=memo, keys=[f"S{i + 1}" for i in order], **kw)
        computed = predicted_stats(chosen, **kw)
        for name in ("median_deg", "p75_deg", "axis_score", "level_axis_score"):
            assert np.array_equal(getattr(looked_up, name), getattr(computed, name)), (order, name)
        assert looked_up.score == computed.score and looked_up.best_subset == computed.best_subset
    assert len(memo) == 3 + 2 + 2 + 1 + 0  # S1 S2 S1S2; S3 S1S3; S2S3 S1S2S3; S3S1 (another order); S2 met already
