"""Frames and the orientation convention (docs/conventions.md), checked by hand and by property."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from optipose.errors import PoseError
from optipose.transforms import (
    invert_T,
    make_T,
    matrix_to_rpy,
    part_motion,
    rpy_to_matrix,
    transform_points,
    validate_pose,
)

angles = st.floats(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3)


def test_roll_pitch_yaw_are_extrinsic_xyz():
    d = np.deg2rad(90)
    # roll about x_O takes y to z; pitch about y_O takes z to x; yaw about z_O takes x to y
    assert np.allclose(rpy_to_matrix([d, 0, 0]) @ [0, 1, 0], [0, 0, 1])
    assert np.allclose(rpy_to_matrix([0, d, 0]) @ [0, 0, 1], [1, 0, 0])
    assert np.allclose(rpy_to_matrix([0, 0, d]) @ [1, 0, 0], [0, 1, 0])
    # R = Rz(yaw) Ry(pitch) Rx(roll): roll acts first
    r, p, y = np.deg2rad([10, 20, 30])
    expected = rpy_to_matrix([0, 0, y]) @ rpy_to_matrix([0, p, 0]) @ rpy_to_matrix([r, 0, 0])
    assert np.allclose(rpy_to_matrix([r, p, y]), expected)


@settings(max_examples=200, deadline=None)
@given(angles, angles, angles)
def test_rpy_round_trip(r, p, y):
    assert np.allclose(matrix_to_rpy(rpy_to_matrix([r, p, y])), [r, p, y], atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(angles, angles, angles, st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_invert_T_is_the_inverse(r, p, y, t):
    T = make_T(rpy_to_matrix([r, p, y]), t)
    assert np.allclose(invert_T(T) @ T, np.eye(4), atol=1e-12)


def test_part_motion_keeps_the_rotation_centre_fixed():
    centre = np.array([0.03, 0.0, 0.0088])
    T = part_motion(np.deg2rad([2, -2, 2]), centre)
    assert np.allclose(transform_points(T, centre[None]), centre)


def test_paper_pose_is_snapped_to_a_rotation():
    T = np.array([[0, 1, 0, 0.03], [0.7071, 0, 0.7071, -0.023], [0.7071, 0, -0.7071, 0.015], [0, 0, 0, 1]])
    out = validate_pose(T)
    assert np.allclose(out[:3, :3].T @ out[:3, :3], np.eye(3), atol=1e-12)
    assert np.allclose(out, T, atol=1e-4)


@pytest.mark.parametrize(
    "T, message",
    [
        (np.diag([1.0, 1.0, -1.0, 1.0]), "reflection"),
        (np.diag([2.0, 1.0, 1.0, 1.0]), "orthonormal"),
        (np.eye(3), "4x4"),
        (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]]), "last row"),
        (np.full((4, 4), np.nan), "NaN"),
    ],
)
def test_bad_poses_are_refused(T, message):
    with pytest.raises(PoseError, match=message):
        validate_pose(T)
