"""Property tests of the frames: RPY ↔ matrix (up to pitch ±90°), poses ↔ the search's six numbers,
inverse and composition identities."""

from __future__ import annotations

import warnings

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from optipose.search.space import PoseSpace, params_from_pose, pose_from_params
from optipose.transforms import (
    invert_T,
    make_T,
    matrix_to_rpy,
    mean_pose,
    part_motion,
    rpy_to_matrix,
    transform_points,
    validate_pose,
)

HALF_PI = np.pi / 2
turn = st.floats(-np.pi, np.pi)
near_gimbal = st.floats(HALF_PI - 1e-3, HALF_PI)  # pitch within 0.06° of 90°, 90° itself included
unit = st.floats(0.0, 1.0)
metres = st.floats(-10.0, 10.0)
SPACE = PoseSpace(np.array([-0.005, -0.025, -0.005]), np.array([0.065, 0.025, 0.023]))  # part B's box + 5 mm


def rigid(r, p, y, t) -> np.ndarray:
    return make_T(rpy_to_matrix([r, p, y]), t)


def rpy_quietly(R: np.ndarray) -> np.ndarray:
    with warnings.catch_warnings():  # scipy warns at gimbal lock and sets yaw to 0; the matrix is what counts
        warnings.simplefilter("ignore", UserWarning)
        return matrix_to_rpy(R)


@settings(max_examples=300, deadline=None)
@given(turn, near_gimbal, turn, st.sampled_from([1.0, -1.0]))
@example(
    0.0, 1.570_796_304_159_418, 1.0, 1.0
)  # 2.3e-8 rad short of 90°: scipy's gimbal branch gave R back to 2e-8 only
def test_matrix_round_trip_at_pitch_90(r, p, y, sign):
    R = rpy_to_matrix([r, sign * p, y])
    rpy = rpy_quietly(R)
    # roll and yaw are not unique at ±90° pitch, the rotation is: the angles must give R back
    assert np.allclose(rpy_to_matrix(rpy), R, atol=1e-9)
    assert abs(rpy[1]) <= HALF_PI + 1e-12 and np.sign(rpy[1]) == sign


@settings(max_examples=300, deadline=None)
@given(turn, st.floats(-HALF_PI + 1e-3, HALF_PI - 1e-3), turn)
def test_rpy_round_trip_over_the_whole_range(r, p, y):
    # 17 µrad is 0.001°: the round trip must be far below it everywhere 0.06° away from gimbal lock
    # compared as angles: -π and π are one yaw (the difference wrapped into (-π, π])
    diff = np.asarray(matrix_to_rpy(rpy_to_matrix([r, p, y]))) - [r, p, y]
    assert np.allclose(np.angle(np.exp(1j * diff)), 0.0, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(turn, turn, turn, turn, turn, turn, st.lists(metres, min_size=6, max_size=6))
def test_inverse_and_composition(r1, p1, y1, r2, p2, y2, t):
    A, B = rigid(r1, p1, y1, t[:3]), rigid(r2, p2, y2, t[3:])
    assert np.allclose(invert_T(A @ B), invert_T(B) @ invert_T(A), atol=1e-12)
    assert np.allclose(invert_T(invert_T(A)), A, atol=1e-12)
    assert np.allclose(A @ invert_T(A), np.eye(4), atol=1e-12)
    points = np.array([[0.0, 0.0, 0.0], [0.06, 0.041, 0.0176], [-0.01, 0.02, 0.03]])
    assert np.allclose(transform_points(A @ B, points), transform_points(A, transform_points(B, points)), atol=1e-12)
    # a proper rigid transform passes validation unchanged, however far its origin is
    assert np.allclose(validate_pose(A), A, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05), st.floats(-0.05, 0.05), st.lists(metres, min_size=3, max_size=3))
def test_part_motion_turns_about_its_centre(r, p, y, centre):
    c = np.array(centre)
    T = part_motion([r, p, y], c)
    assert np.allclose(transform_points(T, c[None]), c[None], atol=1e-12)
    assert np.allclose(T[:3, :3], rpy_to_matrix([r, p, y]), atol=1e-15)
    assert np.allclose(mean_pose([T, T, T]), T, atol=1e-12)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(1e-3, 1 - 1e-3), min_size=6, max_size=6))
def test_pose_space_round_trip(u):
    T = SPACE.to_pose(np.array(u))
    R = T[:3, :3]
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) > 0
    assert np.all(T[:3, 3] >= SPACE.lo - 1e-15) and np.all(T[:3, 3] <= SPACE.hi + 1e-15)
    assert np.allclose(SPACE.from_pose(T), u, atol=1e-9)
    assert np.allclose(SPACE.to_pose(SPACE.from_pose(T)), T, atol=1e-12)


@settings(max_examples=300, deadline=None)
@given(st.floats(-np.deg2rad(60), np.deg2rad(60)), turn, turn)
def test_params_round_trip_and_psi_zero_is_across_the_motion(alpha, beta, psi):
    T = pose_from_params(np.array([0.03, 0.0, 0.0176]), alpha, beta, psi)
    z = T[:3, 2]
    assert np.allclose(z, [np.sin(alpha), np.cos(alpha) * np.cos(beta), np.cos(alpha) * np.sin(beta)], atol=1e-15)
    R, a, b, s = params_from_pose(T)
    assert np.allclose(pose_from_params(R, a, b, s), T, atol=1e-12)
    assert abs(a - alpha) < 1e-9
    # β and ψ come back modulo a full turn (β is lost only when looking along the motion, outside the bounds)
    wrap = lambda x: (x + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
    assert abs(wrap(b - beta)) < 1e-9 and abs(wrap(s - psi)) < 1e-9
    x0 = pose_from_params(R, alpha, beta, 0.0)[:3, 0]
    across = np.cross([1.0, 0.0, 0.0], z)
    assert np.allclose(x0, across / np.linalg.norm(across), atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(1e-3, 1 - 1e-3), min_size=6, max_size=6), st.lists(metres, min_size=3, max_size=3))
def test_the_searched_angles_do_not_depend_on_where_the_box_is(u, t):
    # a space moved by t (a part far from O) maps the same six numbers to the same angles, the aim moved by t
    moved = PoseSpace(SPACE.lo + np.array(t), SPACE.hi + np.array(t))
    A, B = SPACE.to_pose(np.array(u)), moved.to_pose(np.array(u))
    assert np.allclose(B[:3, :3], A[:3, :3], atol=1e-15) and np.allclose(B[:3, 3], A[:3, 3] + t, atol=1e-12)
    assert np.allclose(moved.from_pose(B), u, atol=1e-9)
