"""The search: parameterisation, surrogate, NLopt driver and constraints."""

from __future__ import annotations

import re
import time
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from optipose.evaluate.objective import load_objective
from optipose.model.part import load_part
from optipose.search.space import PoseSpace, params_from_pose, pose_from_params
from optipose.model.sensor import load_sensor
from optipose.search.config import Preset, SearchConfig, SelectionConfig, SurrogateConfig
from optipose.search.driver import optimize
from optipose.search.problem import SurrogateProblem, Violation
from optipose.search.records import PENALTY, Found, LayoutScore
from optipose.search.study import SurrogateStudy
from optipose.search.surrogate_search import run_search
from optipose.search.surrogate import Surrogate, predicted_stats, rotation_sigma

PAPER_B = {  # docs/parts.md: z_S of the paper's S1, S2, S3 and their (alpha, beta, psi) in this parameterisation
    "S1": ((0, 0.707_106_8, -0.707_106_8), (0, -45, 0)),
    "S2": ((0, 0, -1), (0, -90, 0)),
    "S3": ((0, -0.707_106_8, -0.707_106_8), (0, -135, 0)),
}


@pytest.mark.parametrize("name", ["S1", "S2", "S3"])
def test_paper_poses_have_the_documented_parameters(name):
    T = load_part("part_b").layouts["hand"].sensors[int(name[1]) - 1].T_O_S
    _, alpha, beta, psi = params_from_pose(T)
    assert np.allclose(T[:3, 2], PAPER_B[name][0], atol=1e-6)
    assert np.allclose(np.rad2deg([alpha, beta, psi]), PAPER_B[name][1], atol=1e-3)


@settings(max_examples=150, deadline=None)
@given(
    st.floats(-1.0, 1.0),
    st.floats(-np.pi + 1e-6, np.pi - 1e-6),
    st.floats(-np.pi + 1e-6, np.pi - 1e-6),
    st.lists(st.floats(-0.1, 0.1), min_size=3, max_size=3),
)
def test_pose_parameters_round_trip(alpha, beta, psi, R):
    T = pose_from_params(np.array(R), alpha, beta, psi)
    assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12) and np.linalg.det(T[:3, :3]) > 0
    R2, a2, b2, p2 = params_from_pose(T)
    assert np.allclose(pose_from_params(R2, a2, b2, p2), T, atol=1e-9)
    assert abs(np.cross([1, 0, 0], T[:3, 2])).sum() > 0  # never looking along the scan axis


def test_psi_zero_puts_the_line_across_the_motion():
    T = pose_from_params(np.zeros(3), np.deg2rad(20), np.deg2rad(-60), 0.0)
    assert abs(T[:3, 0] @ [1, 0, 0]) < 1e-12  # x_S ⊥ x_O
    assert T[:3, 1] @ [1, 0, 0] > 0.9  # the receiver on the +x side, tilted by alpha


def test_pose_space_scaling_round_trip():
    space = PoseSpace.around(np.array([[0, -0.02, 0], [0.06, 0.02, 0.0176]]))
    u = np.array([0.1, 0.5, 0.9, 0.3, 0.25, 0.75])
    assert np.allclose(space.from_pose(space.to_pose(u)), u, atol=1e-9)


def test_pose_space_puts_the_turns_seams_where_nobody_mounts_a_sensor():
    space = PoseSpace.around(np.array([[0, -0.02, 0], [0.06, 0.02, 0.0176]]))
    centre = np.array([0.5, 0.5, 0.5, 0.5])
    at = lambda beta_u, psi_u: space.to_pose(np.r_[centre, beta_u, psi_u])  # noqa: E731
    # the middle of the box looks straight down; both faces of beta look straight up (the same pose)
    assert np.allclose(at(0.5, 0.25)[:3, 2], [0, 0, -1], atol=1e-12)
    assert np.allclose(at(0.0, 0.25)[:3, 2], [0, 0, 1], atol=1e-12) and np.allclose(
        at(0.0, 0.25), at(1.0, 0.25), atol=1e-12
    )
    # psi: a quarter is the paper's line across the motion with the receiver on +x, three quarters the
    # same line with the receiver on -x, and both faces put the line along the motion
    assert at(0.5, 0.25)[:3, 1] @ [1, 0, 0] > 0.999 and at(0.5, 0.75)[:3, 1] @ [1, 0, 0] < -0.999
    assert abs(at(0.5, 0.0)[:3, 0] @ [1, 0, 0]) > 0.999 and np.allclose(at(0.5, 0.0), at(0.5, 1.0), atol=1e-12)
    # the receiver-on--x poses near psi = 180 deg lie inside the box, on both sides of it
    for psi in (170.0, 180.0, -170.0):
        T = pose_from_params(np.full(3, 0.01), 0.1, np.deg2rad(-110), np.deg2rad(psi))
        u = space.from_pose(T)
        assert 0.7 < u[5] < 0.8 and np.allclose(space.to_pose(u), T, atol=1e-9)


def test_a_cache_saved_under_another_pose_map_is_not_reused(tmp_path):
    from optipose.io.search import load_cache, save_cache
    from optipose.search.space import SPACE_VERSION
    from optipose.search.surrogate import SensorInfo

    info = SensorInfo(np.eye(6), 2500, 900, np.eye(6), np.ones((2, 6)))
    cache = {tuple(np.full(6, 0.25)): info, tuple(np.full(6, 0.75)): Violation("clearance", 1.5)}
    save_cache(tmp_path, cache, SPACE_VERSION)
    loaded = load_cache(tmp_path, SPACE_VERSION)
    assert loaded[tuple(np.full(6, 0.75))] == ("clearance", 1.5) and np.array_equal(
        loaded[tuple(np.full(6, 0.25))].H, np.eye(6)
    )
    assert load_cache(tmp_path, SPACE_VERSION + 1) == {}  # its u keys name other poses
    data = dict(np.load(tmp_path / "cache.npz"))
    np.savez_compressed(
        tmp_path / "cache.npz", **{k: v for k, v in data.items() if k != "space"}
    )  # as saved before the map changed
    assert load_cache(tmp_path, SPACE_VERSION) == {}


def test_rotation_sigma_of_a_known_information_matrix():
    # H = diag(100, 400, 2500) on rotations (rad⁻²) and large on translations: σ = 0.1, 0.05, 0.02 rad,
    # less the weak 5° prior, which adds 1/(5°)² = 131 rad⁻² to each rotation's information.
    H = np.diag([100.0, 400.0, 2500.0, 1e12, 1e12, 1e12])
    prior = 1 / np.deg2rad(5.0) ** 2
    assert np.allclose(rotation_sigma(H), 1 / np.sqrt(np.array([100, 400, 2500]) + prior), rtol=1e-6)


def test_flat_plate_surrogate_says_yaw_is_unobservable(flat_plate):
    plate, down = flat_plate
    info = Surrogate(plate).info(down)
    roll, pitch, yaw = predicted_stats([info]).median_deg[0]
    # By hand: a voxel's point is the mean of the raw points in it, so on a plane the information is that
    # of all N = 80 profiles x 3200 columns raw points with σ = 2 µm (white, head-on: intensity ≈ 1).
    # Roll information is N·E[y²]/σ², y uniform over the line (half-width 17.36 mm at 1 mm beyond R);
    # pitch N·E[x²]/σ², x uniform over the 40 mm scan. The median |error| is 0.674 σ.
    n_points = 80 * 3200
    half = load_sensor("keyence-lj-x8080").half_width(0.001)
    assert info.n_points == pytest.approx(n_points, rel=0.01)
    assert roll == pytest.approx(np.rad2deg(0.6745 * 2e-6 / np.sqrt(n_points * half**2 / 3)), rel=0.05)
    assert pitch == pytest.approx(np.rad2deg(0.6745 * 2e-6 / np.sqrt(n_points * 0.040**2 / 12)), rel=0.05)
    assert yaw > 3.0  # a plane says nothing about yaw: only the 5° prior is left


@pytest.mark.parametrize("algorithm", ["GN_DIRECT_L", "GN_MLSL_LDS"])
def test_driver_finds_a_known_optimum(algorithm):
    # an egg-crate: a bowl with ~4 local minima per axis, global minimum 0 at an off-grid point
    target = np.array([0.2137, 0.7071, 0.4142, 0.8862, 0.1234, 0.5772])

    class Tracker:
        best, calls = (np.inf, None), 0

        def __call__(self, u, grad=None):
            self.calls += 1
            v = float(np.sum((u - target) ** 2) + 0.3 * np.sum(1 - np.cos(12 * (u - target))))
            if v < self.best[0]:
                self.best = (v, np.array(u))
            return v

    tracker = Tracker()
    optimize(tracker, algorithm, np.full(6, 0.5), 3000, seed=3)
    optimize(tracker, "LN_BOBYQA", tracker.best[1], 300, seed=3)
    assert np.allclose(tracker.best[1], target, atol=1e-4)
    assert tracker.best[0] < 1e-7
    assert tracker.calls <= 3300


class _Problem:
    """A stand-in for SurrogateProblem: a function, infeasible where it returns PENALTY + violation."""

    def __init__(self, f):
        self.f = f

    def score(self, u):
        v = float(self.f(np.asarray(u, dtype=float)))
        return LayoutScore(v, {}) if v < PENALTY else LayoutScore(float("nan"), None, v - PENALTY, "wall")


def _recorder(f):
    """A study of ``f`` and its sub-problem over one sensor (nothing placed yet)."""
    from optipose.search.driver import SubProblem

    return SubProblem(SurrogateStudy(_Problem(f)), np.zeros(0))


def test_screen_finds_the_basin_a_local_search_from_the_centre_misses():
    from optipose.search.screen import screen

    centre, target = np.full(6, 0.5), np.array([0.15, 0.8, 0.3, 0.7, 0.2, 0.6])

    def f(u):  # a wide shallow bowl at the centre, a deeper narrower one at the target, a wall at u0 > 0.9
        if u[0] > 0.9:
            return PENALTY + u[0]
        return min(1.0 + np.sum((u - centre) ** 2), 0.2 + 3.0 * np.sum((u - target) ** 2))

    local = _recorder(f)
    optimize(local, "LN_BOBYQA", centre, 200, seed=0)
    assert min(r.value for r in local.history) == pytest.approx(1.0)  # stuck in the centre's bowl

    cfg = SearchConfig(surrogate=SurrogateConfig(screen_samples=512, screen_starts=3, screen_evals=80))
    problem = _recorder(f)
    starts = screen(problem, cfg, 1, seed=4)
    stages = [r.stage for r in problem.history]
    assert stages.count("screen:k=1") == 512 and stages[:512] == ["screen:k=1"] * 512
    assert 1 <= len(starts) <= 3
    assert np.allclose(starts[0], target, atol=1e-3)  # best first, polished to the deeper basin's bottom
    assert all(f(u) < PENALTY for u in starts)  # an infeasible screen point is never a start
    again = _recorder(f)
    assert all(np.array_equal(a, b) for a, b in zip(screen(again, cfg, 1, seed=4), starts))  # seeded
    assert any(r.constraint == "wall" and not r.feasible for r in problem.history)  # the wall was met, and named


@pytest.fixture(scope="module")
def part_b_problem():
    cfg = SearchConfig(
        sensors=(1, 2),
        surrogate=SurrogateConfig(
            global_evals=40,
            local_evals=15,
            joint_evals=20,
            max_time=120,
            random_starts=2,
            screen_samples=64,
            screen_starts=2,
            screen_evals=8,
        ),
    )
    return load_part("part_b"), load_objective("paper").in_cell("ideal"), cfg


def test_same_seed_same_layout(part_b_problem):
    part, objective, cfg = part_b_problem
    a = run_search(part, objective, cfg, seed=5)
    b = run_search(part, objective, cfg, seed=5)
    for k in (1, 2):
        assert np.array_equal(a.found[k].u, b.found[k].u)
    assert [r.value for r in a.history] == [r.value for r in b.history]


def test_quick_in_a_real_cell_runs_every_stage_to_its_evaluations_and_a_slowed_clock_gives_its_layouts(monkeypatch):
    # a budget is work, not seconds: quick's surrogate stages in a real cell end by their evaluations and no budget
    # sets a clock, so every stage of every k is reached, none runs past its count, and the same seed on a machine
    # sixty times as slow (every clock the search reads running sixty times as fast) gives the same layouts and history
    from collections import Counter

    from optipose.search.budgets import config_from_budget

    part, objective = load_part("part_c"), load_objective("paper")
    assert not objective.cell.ideal
    cfg = config_from_budget("quick", (1, 2, 3), cell=True)
    assert cfg.surrogate.max_time == 0 and cfg.time_limit == 0  # no clock
    a = run_search(part, objective, cfg, seed=4)
    stages = Counter(r.stage for r in a.history)
    for k in (1, 2, 3):
        assert stages[f"screen:k={k}"] == cfg.surrogate.screen_samples
        assert 0 < stages[f"screen-polish:k={k}"] <= cfg.surrogate.screen_starts * cfg.surrogate.screen_evals
        assert 0 < stages[f"greedy:k={k}"] <= cfg.surrogate.global_evals
        assert 0 < stages[f"greedy-polish:k={k}"] <= cfg.surrogate.local_evals + cfg.surrogate.local_evals // 2
    real, start = time.monotonic, time.monotonic()
    monkeypatch.setattr(time, "monotonic", lambda: start + 60.0 * (real() - start))
    began = real()
    b = run_search(part, objective, cfg, seed=4)
    assert b.seconds > 30.0 * (real() - began)  # the slowed clock was the one the search read
    assert all(np.array_equal(a.found[k].u, b.found[k].u) for k in (1, 2, 3))
    assert [r.value for r in a.history] == [r.value for r in b.history]
    assert a.clock_cut == b.clock_cut == ()  # no clock ended a stage


def test_a_clock_that_ends_a_stage_is_recorded_and_said(caplog):
    # a clock that ends the surrogate's stages before their evaluations makes the layouts the machine's as well as the
    # seed's: the outcome names the stages it cut, in order, and the search says so in a warning
    from optipose.search.budgets import config_from_budget

    part, objective = load_part("part_c"), load_objective("paper")
    cfg = Preset(surrogate={"max_time": 0.3}).apply(config_from_budget("quick", (1, 2, 3), cell=True))
    with caplog.at_level("WARNING", logger="optipose.search.surrogate_search"):
        out = run_search(part, objective, cfg, seed=4)
    assert out.clock_cut and out.clock_cut[0].endswith("k=1")  # the first k's share is the first to end
    assert len(set(out.clock_cut)) == len(out.clock_cut)
    assert all(
        re.fullmatch(r"(screen|screen-polish|greedy|greedy-polish|joint):k=[123]", stage) for stage in out.clock_cut
    )
    counts = {
        "screen": cfg.surrogate.screen_samples,
        "screen-polish": cfg.surrogate.screen_starts * cfg.surrogate.screen_evals,
        "greedy": cfg.surrogate.global_evals,
        "greedy-polish": cfg.surrogate.local_evals + cfg.surrogate.local_evals // 2,
        "joint": cfg.surrogate.joint_evals,
    }
    first = out.clock_cut[0]
    assert sum(r.stage == first for r in out.history) < counts[first.split(":")[0]]  # cut before its evaluations
    assert any(
        "the clock ended the surrogate's" in r.getMessage() and out.clock_cut[0] in r.getMessage()
        for r in caplog.records
    )


def test_a_clock_that_stops_the_search_before_any_layout_says_so_once(caplog):
    # a clock too short for any layout: one warning names what is missing and the stage the clock ended, not two
    from optipose.search.budgets import config_from_budget

    part, objective = load_part("part_c"), load_objective("paper")
    cfg = Preset(surrogate={"max_time": 1e-6}).apply(config_from_budget("quick", (1, 2, 3), cell=True))
    with caplog.at_level("WARNING", logger="optipose.search.surrogate_search"):
        out = run_search(part, objective, cfg, seed=4)
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert not out.found and out.clock_cut
    assert len(said) == 1, said
    assert (
        "no layout of [1, 2, 3] sensor(s) yet" in said[0]
        and out.clock_cut[0] in said[0]
        and "a larger --max-time, or none" in said[0]
    )


def test_results_never_violate_the_constraints(part_b_problem):
    part, objective, cfg = part_b_problem
    problem = SurrogateProblem(part, objective, cfg)
    out = run_search(part, objective, cfg, seed=2, study=SurrogateStudy(problem))
    assert any(not r.feasible for r in out.history)  # the search did meet infeasible layouts
    assert {r.constraint for r in out.history if not r.feasible} <= {"line_skew", "clearance", "min_points", "head_gap"}
    for found in out.found.values():
        assert found.score < PENALTY
        for T in found.poses:
            assert problem.collision.clearance(T).distance >= cfg.constraints.clearance
            assert problem.surrogate.info(T).n_points >= cfg.constraints.min_points
            assert (
                abs(T[0, 0]) <= np.sin(np.deg2rad(cfg.constraints.line_skew_max_deg)) + 1e-9
            )  # the line's turn toward the motion


@pytest.mark.parametrize("head_gap", [-0.003, 0.0, 0.004, 0.03])
def test_the_head_gap_shortcut_gives_the_exact_tests_verdict(part_b_problem, head_gap):
    # pairs of heads near each other and far apart: the bounding-sphere shortcut never changes the violation
    from optipose.model.collision import heads_clearance

    part, objective, cfg = part_b_problem
    problem = SurrogateProblem(part, objective, replace(cfg, constraints=replace(cfg.constraints, head_gap=head_gap)))
    rng = np.random.default_rng(7)
    base = rng.random((400, 6))
    near = np.clip(base + rng.normal(0.0, 0.04, base.shape), 0.0, 1.0)  # a second head close to the first
    skipped = 0
    for u in np.hstack([base, np.where(rng.random((400, 1)) < 0.5, near, rng.random((400, 6)))]):
        a, b = problem.space.to_poses(u)
        gap = heads_clearance(problem.collision.sensor, a, problem.collision.sensor, b)
        exact = 1.0 + min(head_gap - gap, 0.1) * 10 if gap < head_gap else 0.0
        assert problem._head_gaps(u, 0.0) == exact
        skipped += gap >= head_gap
    assert 50 < skipped < 400  # both kinds of pairs were met


def test_a_laser_line_turned_toward_the_motion_is_infeasible(part_b_problem):
    part, objective, cfg = part_b_problem
    problem = SurrogateProblem(part, objective, cfg)
    loose = SurrogateProblem(
        part,
        objective,
        replace(cfg, constraints=replace(cfg.constraints, line_skew_max_deg=90.0)),
        surrogate=problem.surrogate,
    )
    R, alpha, beta, _ = params_from_pose(part.layouts["hand"].poses[0])
    for psi, allowed in ((0.0, True), (55.0, True), (-65.0, False), (180.0 + 59.0, True), (180.0 - 70.0, False)):
        T = pose_from_params(R, alpha, beta, np.deg2rad(psi))
        # S1 looks straight across the scan axis (alpha = 0), so the line's angle from across the motion is psi's
        assert np.rad2deg(np.arcsin(abs(T[0, 0]))) == pytest.approx(min(abs(psi), abs(180 - psi)), abs=1e-6)
        u = problem.space.from_pose(T)
        strict, free = problem.sensor(u), loose.sensor(u)
        if allowed:  # the constraint adds nothing: same information, or the same other violation
            assert type(strict) is type(free), psi
            assert strict == free if isinstance(free, Violation) else np.array_equal(strict.H, free.H), psi
        else:
            assert (
                isinstance(strict, Violation)
                and strict.constraint == "line_skew"
                and strict.amount >= 1.0
                and strict != free
            ), psi


def test_icp_polish_returns_only_feasible_layouts_and_says_whether_they_beat_the_hand_layout():
    from optipose.evaluate.evaluator import Evaluator
    from optipose.evaluate.objective import load_objective as load
    from optipose.verdict.compare import dominates as _dominates
    from optipose.verdict.compare import excess as _excess
    from optipose.search.polish import polish

    part = load_part("part_b")
    objective = load("paper").in_cell("ideal")
    short = objective.__class__(
        **{
            **objective.__dict__,
            "protocol": objective.protocol.__class__(
                **{
                    **objective.protocol.__dict__,
                    "sequences": ("R", "Y"),
                    "step": objective.protocol.stop - objective.protocol.start,
                }
            ),
        }
    )
    cfg = SearchConfig(selection=SelectionConfig(polish_evals=8, polish_time=120.0, polish_step=0.2))
    problem = SurrogateProblem(part, objective, cfg)
    with Evaluator(part, short, seed=5) as evaluator:
        reference = evaluator(part.layouts["hand"]).table[0]
        u = problem.space.from_pose(part.layouts["hand"].poses[1])  # S2: its yaw is far worse than the best single's
        start = Found(1, "start", u, problem.space.to_poses(u), 0.0)
        found, choice, rows = polish(problem, evaluator, start, reference, cfg, 8, 120.0)
    assert 1 <= len(rows) <= 8
    assert found is not None and problem.score(found.u).feasible  # constraints hold
    assert all(r.protocol == "reduced" for r in rows)
    winners = [np.rad2deg(r.choice.score) for r in rows if r.dominates]
    if winners:  # the best of the layouts no worse than the hand layout on every axis is kept
        assert _dominates(choice, reference) and np.rad2deg(choice.score) == pytest.approx(min(winners))
    assert _dominates(choice, reference) == (_excess(choice, reference, 1.0) == 0.0)
    assert _excess(reference, reference, 1.0) == 0.0 and _excess(reference, reference, 0.5) > 0.0


def _choice(per_axis_mdeg, k=1):
    """A Choice with (median, p75) per axis given in millidegrees; score = their sum (the paper objective)."""
    from optipose.evaluate.assignment import AxisChoice, Choice

    axes = tuple(
        AxisChoice(a, (0,), "F1", np.deg2rad(m * 1e-3), np.deg2rad(p * 1e-3))
        for a, (m, p) in zip(("roll", "pitch", "yaw"), per_axis_mdeg)
    )
    return Choice(k, tuple(range(k)), "F1", axes, float(np.deg2rad(sum(m + p for m, p in per_axis_mdeg) * 1e-3)))


def test_a_narrow_win_is_not_clear_and_needs_confirmation():
    from optipose.search.select import clear_win as _clear

    cfg = SearchConfig(selection=SelectionConfig(polish_margin=0.9, clear_ratio=0.4))
    hand = _choice([(3.0, 5.0), (0.1, 0.2), (0.1, 0.2)])  # sum 8.6
    assert _clear(_choice([(1.0, 1.5), (0.05, 0.1), (0.05, 0.1)]), hand, cfg)  # every axis <= 0.9x, sum 2.85 <= 3.44
    assert not _clear(_choice([(1.0, 1.5), (0.05, 0.1), (0.095, 0.1)]), hand, cfg)  # yaw median 0.95x the hand's
    assert not _clear(_choice([(3.0, 4.4), (0.05, 0.1), (0.05, 0.1)]), hand, cfg)  # every axis fine, sum 7.7 > 3.44
    assert not _clear(hand, hand, cfg)


def test_the_polish_also_starts_from_the_candidate_closest_to_beating_the_hand_layout():
    from optipose.search.select import nearest as _nearest

    hand = _choice([(3.0, 5.0), (0.1, 0.2), (0.1, 0.2)])
    low_sum = Found(1, "low sum", np.zeros(6), [], 0.0)  # roll great, yaw 0.3 mdeg over the hand's
    near = Found(1, "near", np.ones(6), [], 0.0)  # only the pitch median 0.01 mdeg over
    far = Found(1, "far", np.full(6, 0.5), [], 0.0)
    pool = [
        ((True, 1.0), low_sum, _choice([(0.2, 0.3), (0.05, 0.1), (0.25, 0.35)])),
        ((True, 5.0), near, _choice([(2.0, 2.5), (0.11, 0.2), (0.1, 0.2)])),
        ((True, 9.0), far, _choice([(9.0, 9.0), (1.0, 2.0), (1.0, 2.0)])),
    ]
    assert _nearest(pool, hand, low_sum) == [near]
    assert _nearest(pool, hand, near) == []  # the finalist itself is already the nearest


def test_distinct_keeps_the_best_of_each_neighbourhood_by_the_given_key():
    from optipose.search.candidates import distinct as _distinct

    a, b, c = (
        Found(1, n, u, [], s)
        for n, u, s in (("a", np.zeros(6), 3.0), ("b", np.full(6, 0.01), 1.0), ("c", np.ones(6), 2.0))
    )
    assert [f.strategy for f in _distinct([a, b, c], 0.02)] == ["b", "c"]  # a lies within 0.02 of the better b
    rank = {"a": 0, "b": 2, "c": 1}
    assert [f.strategy for f in _distinct([a, b, c], 0.02, key=lambda f: rank[f.strategy])] == ["a", "c"]


def test_a_confirmed_finalist_gives_way_to_the_better_k_subset_of_a_larger_finalist():
    from types import SimpleNamespace

    from optipose.evaluate.assignment import Choice
    from optipose.search.confirm import Confirmer as _Confirmer

    def as_sensor(choice, index):
        return Choice(1, (index,), f"S{index + 1}", choice.axes, choice.score)

    hand = SimpleNamespace(table=[_choice([(3.0, 5.0), (0.1, 0.2), (0.1, 0.2)])])
    single = as_sensor(_choice([(1.0, 2.0), (0.05, 0.1), (0.05, 0.1)]), 1)  # the pair's second sensor beats the hand
    pair_result = SimpleNamespace(table=[single], layout=SimpleNamespace(names=["S1", "S2"]))
    confirmer = _Confirmer.__new__(_Confirmer)  # no evaluator: the full-protocol results are given
    confirmer._baseline, confirmer._results, confirmer.chosen = hand, {}, {1: (True, np.deg2rad(5e-3))}
    confirmer.evaluate = lambda layout: pair_result
    problem = SimpleNamespace(
        score=lambda u: LayoutScore(0.25, {"score": 0.25}), space=SimpleNamespace(to_poses=lambda u: ["pose"])
    )
    pair = Found(2, "joint", np.concatenate([np.zeros(6), np.full(6, 0.5)]), [], 0.0)
    finalists, rows = {1: Found(1, "polish", np.ones(6), [], 0.0), 2: pair}, []
    confirmer.adopt_subsets(problem, finalists, rows)
    assert finalists[1].strategy == "best 1 of the k=2 finalist"
    assert np.array_equal(finalists[1].u, np.full(6, 0.5))  # the second sensor's six numbers
    assert confirmer.chosen[1] == (False, single.score) and rows[-1].dominates

    pair_result.table = [as_sensor(_choice([(9.0, 9.0), (0.05, 0.1), (0.05, 0.1)]), 0)]  # worse than the finalist
    kept = finalists[1]
    confirmer.adopt_subsets(problem, finalists, rows)
    assert finalists[1] is kept and not rows[-1].dominates


def test_confirmation_also_re_runs_the_candidate_closest_to_beating_the_hand_layout():
    from types import SimpleNamespace

    from optipose.search.confirm import Confirmer as _Confirmer

    hand = SimpleNamespace(table=[_choice([(3.0, 5.0), (0.1, 0.2), (0.1, 0.2)])])
    # on the full protocol the two leaders of the reduced ranking trade pitch for roll; the fourth is no worse anywhere
    full = {
        0.0: _choice([(0.2, 0.3), (0.15, 0.3), (0.05, 0.1)]),
        0.2: _choice([(0.3, 0.4), (0.12, 0.25), (0.05, 0.1)]),
        0.4: _choice([(5.0, 6.0), (0.1, 0.2), (0.1, 0.2)]),
        0.6: _choice([(0.5, 0.8), (0.08, 0.15), (0.04, 0.07)]),
    }
    cands = [Found(1, f"c{i}", np.full(6, u), [], 0.0) for i, u in enumerate(sorted(full))]
    pool = [((True, float(i)), c) for i, c in enumerate(cands)]
    evaluated = []

    def evaluate(layout):
        evaluated.append(layout.strategy)
        return SimpleNamespace(table=[full[float(layout.u[0])]])

    confirmer = _Confirmer.__new__(_Confirmer)  # no evaluator: the full-protocol results are given
    confirmer._baseline, confirmer._results, confirmer.chosen, confirmer.evaluate = hand, {}, {}, evaluate
    assert confirmer.pick(1, pool, 2, []).strategy == "c0"  # the leaders alone: the lower sum, pitch worse
    assert evaluated == ["c0", "c1"]
    evaluated.clear()
    assert confirmer.pick(1, pool, 2, [], near=cands[3]).strategy == "c3"
    assert evaluated == ["c0", "c1", "c3"] and confirmer.chosen[1][0] is False  # no worse on every axis
    evaluated.clear()
    confirmer.pick(1, pool, 2, [], near=cands[0])  # already a leader: not run twice
    assert evaluated == ["c0", "c1"]


def test_a_tight_time_budget_still_places_every_sensor_count():
    """Evaluations enough for minutes and 8 s on the clock: each k gets its share of the clock instead of
    k = 1 using all of it, so k = 1, 2 and 3 all have a feasible layout, and the search keeps to its clock."""
    cfg = SearchConfig(
        sensors=(1, 2, 3),
        surrogate=SurrogateConfig(
            global_evals=5000, local_evals=2000, joint_evals=2000, max_time=8.0, random_starts=2, screen_samples=0
        ),
    )
    out = run_search(load_part("part_b"), load_objective("paper").in_cell("ideal"), cfg, seed=1)
    assert sorted(out.found) == [1, 2, 3]
    assert all(f.score < PENALTY and len(f.poses) == k for k, f in out.found.items())
    stages = {r.stage.split(":")[0] + f":{r.k}" for r in out.history}
    assert {"greedy:1", "greedy:2", "greedy:3"} <= stages


# -- the hand layout's validation beside the search -------------------------------------------------------
def _short(objective):
    """Sequences R and Y at -2°, 0°, +2°... in 1° steps: 5 orientations each, 10 in all."""
    return replace(objective, protocol=replace(objective.protocol, sequences=("R", "Y"), step=np.deg2rad(1.0)))


def test_the_hand_layout_evaluated_beside_the_search_is_the_one_validate_would_compute():
    from optipose.evaluate.evaluator import Evaluator
    from optipose.search.validate import BaselineRun, validate
    from optipose.seeds import validation_seed

    part, objective = load_part("part_b"), _short(load_objective("paper").in_cell("ideal"))
    with BaselineRun(part, objective, seed=3) as run:
        beside = run.result()
    with Evaluator(part, objective, seed=validation_seed(3), jobs=1) as evaluator:
        here = evaluator(part.layouts["hand"])
    assert beside is not None and len(beside.per_scan) == len(here.per_scan) == 10 * 7
    cols = ["err_roll", "err_pitch", "err_yaw", "iterations", "rmse"]
    np.testing.assert_array_equal(beside.per_scan[cols].to_numpy(), here.per_scan[cols].to_numpy())
    # validate takes it as the hand layout's evaluation, and says so to whoever saves the evaluations
    seen = {}
    hand = part.layouts["hand"]
    found = {1: replace(hand, name="one", sensors=hand.sensors[:1])}
    with BaselineRun(part, objective, seed=3) as run:
        validation = validate(part, objective, found, 3, 1, "full", lambda name, r: seen.setdefault(name, r), run)
    np.testing.assert_array_equal(seen["hand"].per_scan[cols].to_numpy(), here.per_scan[cols].to_numpy())
    assert validation.baseline[1].score == here.table[0].score


def test_the_hand_layout_shared_out_over_processes_by_its_scans_is_the_evaluators():
    # one condition, two processes: each evaluates every other scan, and together they make the one result
    from optipose.evaluate.evaluator import Evaluator
    from optipose.search.validate import BaselineRun
    from optipose.seeds import validation_seed

    part, objective = load_part("part_b"), _short(load_objective("paper").in_cell("ideal"))
    with BaselineRun(part, objective, seed=3, processes=2) as run:
        assert len(run._calls) == 2  # every other scan each
        beside = run.result()
    with Evaluator(part, objective, seed=validation_seed(3), jobs=1) as evaluator:
        here = evaluator(part.layouts["hand"])
    assert beside.per_scan.equals(here.per_scan) and beside.points.equals(here.points)
    assert beside.stats.equals(here.stats) and beside.table == here.table


def test_a_validation_of_a_share_of_the_scans_evaluates_found_and_hand_on_the_same_drawn_scans():
    # validation.scans = 4 of the short protocol's 10: the hand layout beside the search (two processes) and the
    # found one in the validation evaluate the same 4 scans, those the held-out seed draws, and the hand's rows are
    # the evaluator's own on that share
    from optipose.evaluate.evaluator import Evaluator
    from optipose.search.validate import BaselineRun, validate
    from optipose.seeds import validation_seed

    part, objective = load_part("part_b"), _short(load_objective("paper").in_cell("ideal"))
    hand = part.layouts["hand"]
    found = {1: replace(hand, name="one", sensors=hand.sensors[1:2])}
    seen = {}
    with BaselineRun(part, objective, seed=3, processes=2, scans=4) as run:
        validate(part, objective, found, 3, 1, "full", lambda name, r: seen.setdefault(name, r), run, scans=4)
    with Evaluator(part, objective, seed=validation_seed(3), jobs=1, scans=4) as evaluator:
        here = evaluator(hand)
    drawn = set(here.per_scan["scan"])
    assert len(drawn) == 4 and set(seen["hand"].per_scan["scan"]) == set(seen["found_k1"].per_scan["scan"]) == drawn
    assert seen["hand"].per_scan.equals(here.per_scan)


def test_a_found_pair_inside_the_triple_in_another_order_shares_its_evaluation():
    # hand-anchored layouts keep the hand poses exactly, so a found pair can be the triple's sensors in
    # another order: validation evaluates the triple once and takes the pair's choice from it (sorted indices)
    from optipose.search.validate import nested_groups, validate

    part, objective = load_part("part_b"), _short(load_objective("paper").in_cell("ideal"))
    hand = part.layouts["hand"]
    layouts = {3: hand, 2: replace(hand, name="pair", sensors=(hand.sensors[2], hand.sensors[1]))}
    assert nested_groups(layouts) == [[3, 2]]
    validation = validate(part, objective, layouts, 2, 1)
    assert validation.found[2].sensors == (1, 2) and validation.found[2].name == "S2S3"
    assert validation.found[3].score == validation.baseline[3].score  # the hand triple itself


def test_a_stopped_hand_evaluation_is_evaluated_again_by_validate():
    from optipose.search.validate import BaselineRun, validate

    part, objective = load_part("part_b"), _short(load_objective("paper").in_cell("ideal"))
    run = BaselineRun(part, objective, seed=5)
    run.close()  # stopped before it could finish: no result, and validate evaluates the hand layout itself
    assert run.result() is None
    hand = part.layouts["hand"]
    found = {1: replace(hand, name="one", sensors=hand.sensors[1:2])}
    validation = validate(part, objective, found, 5, 1, "full", None, run)
    assert validation.baseline[1].score > 0 and np.isfinite(validation.baseline[1].score)


def test_the_whole_pipeline_with_a_selection_and_the_hand_layout_beside_it(tmp_path):
    """Every stage in order on two cores (the hand layout's validation in its own process, a selection by
    ICP, the validation): each k gets a layout, and the hand layout's validation is the one a plain
    evaluation on the held-out seed gives."""
    from optipose.evaluate.evaluator import Evaluator
    from optipose.io.search import SearchFolder
    from optipose.search.pipeline import run
    from optipose.seeds import validation_seed

    part, objective = load_part("part_b"), _short(load_objective("paper").in_cell("ideal"))
    config = SearchConfig(
        sensors=(1, 2),
        surrogate=SurrogateConfig(global_evals=20, local_evals=6, joint_evals=8, random_starts=2),
        selection=SelectionConfig(candidates=1, time=60.0),
    )
    stages = []
    report = run(part, objective, config, 2, SearchFolder(tmp_path), jobs=2, on_stage=stages.append)
    assert set(report.layouts) == {1, 2} and report.validated
    assert any("selecting" in s for s in stages) and any("hand layout" in s for s in stages)
    with Evaluator(part, objective, seed=validation_seed(2), jobs=1) as evaluator:
        here = evaluator(part.layouts["hand"])
    assert report.validation.baseline[2].score == here.table[1].score
    assert (tmp_path / "validation" / "hand" / "per_scan.csv").is_file() and (tmp_path / "selection.csv").is_file()


def test_ctrl_c_inside_a_compiled_kernel_stops_the_search_like_any_ctrl_c():
    # numba raises SystemError ("returned a result with an exception set") when the interrupt arrives while
    # it runs; the study must treat it as the interrupt it is, and let any other SystemError through
    from optipose.errors import is_interrupt
    from optipose.search.study import Stop

    def compiled_call_interrupted():  # as numba chains it: the interrupt, under two SystemErrors
        try:
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt as exc:
                raise SystemError("<function _numba_unpickle> returned a result with an exception set") from exc
        except SystemError as exc:
            raise SystemError("CPUDispatcher(<function nearest>) returned a result with an exception set") from exc

    class Interrupted:
        def score(self, u):
            compiled_call_interrupted()

    study = SurrogateStudy(Interrupted())
    with pytest.raises(Stop, match="interrupted"):
        study(np.full(6, 0.5))
    assert study.interrupted
    assert not is_interrupt(SystemError("something else"))


def test_each_stage_objective_is_derived_in_one_place():
    # the table of optipose.search.objectives: the surrogate and the confirmation as given; selection and polish
    # on the reduced protocol; validation on the full one, or the reduced one
    from optipose.evaluate.objective import reduced_objective
    from optipose.search.objectives import STAGES, stage_objective

    for objective in (load_objective("paper").in_cell("ideal"), load_objective("paper")):
        stage = {name: stage_objective(objective, name) for name in STAGES}
        assert stage["surrogate"] is objective and stage["validation"] is objective
        assert stage["confirmation"] is objective
        assert repr(stage["selection"]) == repr(stage["polish"]) == repr(reduced_objective(objective))
        assert repr(stage_objective(objective, "validation", "reduced")) == repr(reduced_objective(objective))
    assert STAGES == ("surrogate", "selection", "polish", "confirmation", "validation")
    with pytest.raises(ValueError, match="no stage"):
        stage_objective(load_objective("paper"), "band")


def test_an_answer_checked_in_the_ideal_cell_only_is_not_a_buy():
    from optipose.verdict.compare import Verdict
    from optipose.io.config import run_config
    from optipose.io.results import SearchResult
    from optipose.report.verdict import verdict_table
    from optipose.search.records import Validation

    nominal = Verdict(1, _choice([(1, 2), (1, 2), (1, 2)]), _choice([(3, 4), (3, 4), (3, 4)]))
    assert verdict_table([nominal], "hand").rows[0][-1] == "buy the found sensors"
    assert (
        verdict_table([nominal], "hand", unchecked=True)
        .rows[0][-1]
        .startswith("better in the ideal cell; check it in a real cell")
    )
    ideal = {"objective": {"cell": {"name": "ideal"}}}
    in_a_cell = {"objective": {"cell": {"name": "cobot"}}}
    validation = Validation("full", 1, {}, {})

    def result(config):
        return SearchResult(None, "part_b", 0, "quick", run_config(config), validation=validation)

    assert result(ideal).unchecked  # a search in the ideal cell: its better holds there only
    assert not result(in_a_cell).unchecked  # a search in a cell: its verdict is the cell's


@pytest.mark.parametrize("algorithm", ["GN_DIRECT_L", "LN_BOBYQA", "GN_CRS2_LM"])
def test_a_stop_raised_in_the_objective_comes_out_of_nlopt_as_itself(algorithm):
    """DIRECT-L called the objective again with a raised Share still set, and the search died of a
    SystemError at its next call into numpy (part A's default search in the cell): the driver keeps the
    exception, stops NLopt and raises it after."""
    from optipose.search.driver import optimize
    from optipose.search.study import Share

    calls = []

    def objective(u, grad=None):
        calls.append(np.concatenate([u, u]))  # a call into numpy, as the sub-problem makes
        if len(calls) == 7:
            raise Share("its share of the time used up")
        return float(np.sum((u - 0.3) ** 2))

    with pytest.raises(Share, match="share"):
        optimize(objective, algorithm, np.full(4, 0.5), 200, seed=1)
    assert len(calls) == 7  # not called again once it raised


def test_a_nested_candidate_that_is_already_a_candidate_is_not_evaluated_twice():
    """The k−1 finalist plus one sensor can be a layout already in (the subset of a larger layout, its sensors in
    the same order): it is one ICP evaluation, not two. A nested layout that differs is still added."""
    from types import SimpleNamespace

    from optipose.search.candidates import candidates
    from optipose.search.records import Found, SearchOutcome

    a, b, c = np.full(6, 0.1), np.full(6, 0.5), np.full(6, 0.9)
    # the surrogate of this toy: a layout scores the sum of its numbers, so the pair (a, b) beats (a, c); two
    # sensors in one place collide
    problem = SimpleNamespace(
        score=lambda u: SimpleNamespace(
            feasible=len({tuple(s) for s in np.reshape(u, (-1, 6))}) == len(u) // 6,
            value=float(np.sum(u)),
            stats={"toy": 1},
        ),
        space=SimpleNamespace(to_poses=lambda u: [np.eye(4)] * (len(u) // 6)),
    )
    found = lambda k, strategy, *sensors: Found(
        k, strategy, np.concatenate(sensors), [], float(np.sum(sensors)), {"t": 1}
    )  # noqa: E731
    triple = found(3, "greedy", a, b, c)
    outcome = SearchOutcome({3: triple}, {3: triple}, {}, {}, [])
    pairs = candidates(problem, [], outcome, 2, 1, {1: found(1, "greedy", a)})
    layouts = [tuple(p.u) for p in pairs]
    assert len(layouts) == len(set(layouts)) and tuple(np.concatenate([a, b])) in layouts
    assert "k=1 finalist + 1" not in [p.strategy for p in pairs]  # (a, b): the triple's best pair, already in
    pairs = candidates(problem, [], outcome, 2, 1, {1: found(1, "greedy", c)})
    assert "k=1 finalist + 1" in [p.strategy for p in pairs]  # (c, a): no candidate yet
