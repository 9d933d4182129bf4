"""The virtual scanner against answers worked out by hand (docs/sensor.md)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from optipose.model.material import load_material
from optipose.scan.profiles import EMPTY, profiles_to_points, read_profiles, write_profiles
from optipose.model.motion import ScanMotion
from optipose.scan.scanner import PartPose, Scanner
from optipose.model.sensor import load_sensor
from optipose.transforms import invert_T, part_motion, transform_points

MM = 1e-3
SENSOR = load_sensor("keyence-lj-x8080")
# Looking straight down -z_O with the line along y_O: the paper's S2 (eq. 2) with R at the origin.
T_DOWN = np.array([[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1.0]])


def box(lo_mm, hi_mm) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo_mm) * MM, np.asarray(hi_mm) * MM
    m = trimesh.creation.box(hi - lo)
    m.apply_translation((lo + hi) / 2)
    return m


def plate(top_mm: float = 0.0) -> trimesh.Trimesh:
    """A 60 × 60 × 2 mm plate whose top face is at z = top_mm, wider than the laser line."""
    return box([-30, -30, top_mm - 2], [30, 30, top_mm])


def max_sigma(material: str) -> float:
    """Largest noise σ (m) a point of this material can get: σ0 / sqrt(threshold)."""
    return SENSOR.noise_sigma / np.sqrt(SENSOR.detection_threshold)


def test_fan_matches_datasheet_widths_at_both_ends():
    o, d = SENSOR.laser_rays()
    for z, width in ((SENSOR.z_near, 30 * MM), (SENSOR.z_far, 39 * MM)):
        x = o[:, 0] + (z - o[:, 2]) / d[:, 2] * d[:, 0]
        assert x.min() == pytest.approx(-width / 2, abs=1e-12)
        assert x.max() == pytest.approx(width / 2, abs=1e-12)
    assert np.allclose(o[:, 2], -73 * MM)  # rays start on the emitter window


def test_flat_plate_head_on_returns_every_point_at_the_exact_height():
    scanner = Scanner(plate(0.0), SENSOR, "white-diffuse")
    motion = ScanMotion(10 * MM)
    scan = scanner.scan(T_DOWN, motion, rng=1)
    assert len(scan) == motion.n_profiles * 3200  # 20 profiles, all 3200 columns
    assert np.all(scan.raw > EMPTY)
    # Height: 0 within noise (σ = 2 µm at full intensity, cos(6.3°) at the line's ends) and quantisation.
    assert np.abs(scan.points[:, 2]).max() < 6 * 2e-6 / np.sqrt(0.99) + SENSOR.z_resolution
    assert np.std(scan.points[:, 2]) == pytest.approx(2e-6, rel=0.1)
    # Line width at R: the straight fan through 30 mm (near) and 39 mm (far) is 34.5 mm wide at Z = 0.
    assert scan.points[:, 1].min() == pytest.approx(-17.25 * MM, abs=2e-6)
    assert scan.points[:, 1].max() == pytest.approx(17.25 * MM, abs=2e-6)
    # The motion is undone: profile k sits at x = -offset_k.
    assert np.allclose(np.unique(scan.points[:, 0]), np.sort(-motion.offsets()))


@pytest.mark.parametrize("top_mm", [-21.0, 21.0, -40.0])
def test_plate_outside_the_z_range_returns_nothing(top_mm):
    scanner = Scanner(plate(top_mm), SENSOR, "white-diffuse")
    scan = scanner.scan(T_DOWN, ScanMotion(5 * MM))
    assert len(scan) == 0
    assert np.all(scan.raw == EMPTY)


@pytest.mark.parametrize("top_mm", [-20.0, 20.0])
def test_plate_just_inside_the_z_range_is_seen(top_mm):
    scan = Scanner(plate(top_mm), SENSOR, "white-diffuse").scan(T_DOWN, ScanMotion(1 * MM), noise=False)
    assert len(scan) == 2 * 3200
    assert np.allclose(scan.points[:, 2], top_mm * MM, atol=1e-12)


def test_step_casts_a_triangulation_shadow_of_the_predicted_width():
    # Low floor at z = 0, a 10 mm high block from x = 2 mm on. The receiver sits 30 mm along +x_O
    # (y_S = x_O) and 73 mm above the floor, so floor points closer to the step than h·b/d are hidden.
    h, x0 = 10.0, 2.0
    mesh = trimesh.util.concatenate([box([-20, -30, -5], [20, 30, 0]), box([x0, -30, 0], [20, 30, h])])
    step = 0.02 * MM
    scan = Scanner(mesh, SENSOR, "white-diffuse").scan(T_DOWN, ScanMotion(16 * MM, step), noise=False)
    floor = scan.points[np.abs(scan.points[:, 2]) < 1e-9]
    top = scan.points[np.abs(scan.points[:, 2] - h * MM) < 1e-9]
    shadow_edge = x0 * MM - h * MM * SENSOR.baseline / SENSOR.reference_distance  # 2 - 4.11 mm
    assert floor[:, 0].max() == pytest.approx(shadow_edge, abs=step)
    assert top[:, 0].min() == pytest.approx(x0 * MM, abs=step)  # the laser itself reaches the step
    # nothing was measured inside the shadow band
    band = (scan.points[:, 0] > shadow_edge + step) & (scan.points[:, 0] < x0 * MM - step)
    assert not band.any()


def test_step_facing_away_from_the_receiver_casts_no_shadow():
    # Mirror the step: the block is on the -x side, the receiver on +x looks away from it.
    mesh = trimesh.util.concatenate([box([-20, -30, -5], [20, 30, 0]), box([-20, -30, 0], [-2, 30, 10])])
    step = 0.05 * MM
    scan = Scanner(mesh, SENSOR, "white-diffuse").scan(T_DOWN, ScanMotion(16 * MM, step), noise=False)
    floor = scan.points[np.abs(scan.points[:, 2]) < 1e-9]
    assert floor[:, 0].min() == pytest.approx(-2 * MM, abs=step)


def test_tilted_plate_past_the_materials_aoi_limit_returns_nothing():
    material = load_material("smooth-aluminium-ra0.8")
    limit = np.rad2deg(material.max_aoi(SENSOR.detection_threshold))  # ≈ 47.5°
    mesh = plate(0.0)
    motion = ScanMotion(2 * MM)
    # Pitch the plate about y_O through R: the laser meets it at AoI ≈ pitch (the fan's own spread is
    # in the y-z plane and adds at most 6.3°, in quadrature).
    past = Scanner(mesh, SENSOR, material).scan(T_DOWN, motion, PartPose(np.deg2rad([0, limit + 3, 0])))
    assert len(past) == 0
    # The same geometry is measured when the material allows it, so it is the material that drops out.
    assert len(Scanner(mesh, SENSOR, "white-diffuse").scan(T_DOWN, motion, PartPose(np.deg2rad([0, limit + 3, 0])))) > 0
    within = Scanner(mesh, SENSOR, material).scan(T_DOWN, motion, PartPose(np.deg2rad([0, limit - 10, 0])))
    assert len(within) > 0.9 * motion.n_profiles * 3200


BRACKET_BOXES_MM = [
    ([0, -20, 0], [40, -5, 15]),
    ([0, 5, 0], [40, 20, 15]),
    ([0, -5, 0], [40, 5, 5]),
    ([15, -2, 5], [25, 2, 25]),
]


@pytest.fixture(scope="module")
def bracket():
    """A non-convex part: a block with a slot and a post, so shadows and occlusions happen."""
    return trimesh.util.concatenate([box(lo, hi) for lo, hi in BRACKET_BOXES_MM])


def distance_to_bracket(points: np.ndarray) -> np.ndarray:
    """Exact float64 distance (n,) from points to the nearest face of the bracket's boxes."""
    best = np.full(len(points), np.inf)
    for lo, hi in BRACKET_BOXES_MM:
        lo, hi = np.asarray(lo) * MM, np.asarray(hi) * MM
        q = np.abs(points - (lo + hi) / 2) - (hi - lo) / 2  # box signed distance, component-wise
        sdf = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
        best = np.minimum(best, np.abs(sdf))
    return best


T_DIAG = np.array(  # the paper's S1 (eq. 1), R moved onto the bracket
    [[0, 1, 0, 0.020], [0.707_106_8, 0, 0.707_106_8, -0.012], [0.707_106_8, 0, -0.707_106_8, 0.012], [0, 0, 0, 1]]
)


@pytest.mark.parametrize("rpy_deg", [(0, 0, 0), (1.2, -2.0, 0.8)])
def test_zero_noise_gives_exact_surface_points(bracket, rpy_deg):
    scanner = Scanner(bracket, SENSOR, "white-diffuse")
    rpy = np.deg2rad(rpy_deg)
    centre = np.array([0.02, 0.0, 0.01])
    scan = scanner.scan(T_DIAG, ScanMotion(40 * MM), PartPose(rpy, centre), noise=False)
    assert len(scan) > 10_000
    # back into the part's own frame, every point must lie on the CAD surface
    local = transform_points(invert_T(part_motion(rpy, centre)), scan.points)
    assert distance_to_bracket(local).max() < 1e-12


def test_the_part_pose_is_one_record(bracket):
    # where the part stands (orientation about a centre, then an offset) travels as one PartPose: the scan
    # carries its pose, and the old loose (rpy, centre, offset) arguments are refused, not misread as a seed
    rpy, centre, offset = np.deg2rad([0.5, -1.0, 0.3]), np.array([0.02, 0.0, 0.01]), np.array([1e-3, 0.0, -0.5e-3])
    pose = PartPose(rpy, centre, offset)
    assert np.array_equal(pose.T_O_P, part_motion(rpy, centre, offset))
    assert np.array_equal(PartPose().T_O_P, np.eye(4))
    scanner = Scanner(bracket, SENSOR, "white-diffuse")
    scan = scanner.scan(T_DIAG, ScanMotion(10 * MM), pose, noise=False)
    assert np.array_equal(scan.T_O_P, pose.T_O_P) and np.array_equal(scan.rpy, rpy)
    with pytest.raises(TypeError, match="PartPose"):
        scanner.scan(T_DIAG, ScanMotion(10 * MM), rpy)


def test_noisy_points_lie_on_the_surface_within_the_noise(bracket):
    scanner = Scanner(bracket, SENSOR, "black-pla")
    scan = scanner.scan(T_DIAG, ScanMotion(40 * MM), rng=7)
    exact = scanner.scan(T_DIAG, ScanMotion(40 * MM), noise=False)
    assert np.array_equal(scan.column, exact.column)  # noise moves points along their rays, never drops them
    along_ray = np.linalg.norm(scan.points - exact.points, axis=1)
    sigma = SENSOR.noise_sigma / np.sqrt(np.clip(scan.intensity, SENSOR.detection_threshold, 1))
    assert np.median(along_ray / sigma) == pytest.approx(0.674, rel=0.05)  # median of |N(0, 1)|
    # the distance to the surface is the along-ray error projected on the normal: never more
    assert np.all(distance_to_bracket(scan.points) <= along_ray + 1e-12)
    assert np.all(along_ray <= 6 * sigma + SENSOR.z_resolution)


def test_same_seed_same_cloud_other_seed_other_cloud_any_thread_count(bracket):
    motion = ScanMotion(20 * MM)
    one = Scanner(bracket, SENSOR, "black-pla", threads=1).scan(T_DIAG, motion, rng=3)
    two = Scanner(bracket, SENSOR, "black-pla", threads=2).scan(T_DIAG, motion, rng=3)
    other = Scanner(bracket, SENSOR, "black-pla", threads=2).scan(T_DIAG, motion, rng=4)
    assert np.array_equal(one.points, two.points)
    assert np.array_equal(one.raw, two.raw)
    assert len(other) == len(one) and not np.array_equal(one.points, other.points)


def test_scan_many_equals_separate_scans(bracket):
    scanner = Scanner(bracket, SENSOR, "white-diffuse")
    motion = ScanMotion(10 * MM)
    T2 = T_DOWN.copy()
    T2[:3, 3] = [0.02, 0.0, 0.015]
    both = scanner.scan_many([T_DIAG, T2], motion, noise=False)
    assert np.array_equal(both[1].points, scanner.scan(T2, motion, noise=False).points)
    assert np.array_equal(both[0].points, scanner.scan(T_DIAG, motion, noise=False).points)


@pytest.mark.parametrize("backend", ["embreex", "open3d"])
def test_backends_agree(bracket, backend):
    motion = ScanMotion(10 * MM)
    ref = Scanner(bracket, SENSOR, "white-diffuse", backend="embreex").scan(T_DIAG, motion, noise=False)
    other = Scanner(bracket, SENSOR, "white-diffuse", backend=backend).scan(T_DIAG, motion, noise=False)
    assert abs(len(other) - len(ref)) <= 0.001 * len(ref)  # float32 edge cases may differ on a few rays


@pytest.mark.parametrize("suffix", [".csv", ".npy"])
def test_raw_profiles_round_trip_to_the_same_cloud(bracket, tmp_path, suffix):
    motion = ScanMotion(10 * MM)
    scan = Scanner(bracket, SENSOR, "black-pla").scan(T_DIAG, motion, rng=2)
    assert scan.raw.shape == (motion.n_profiles, 3200)
    path = write_profiles(tmp_path / f"s1{suffix}", scan.raw)
    raw = read_profiles(path, 3200)
    points, profile, column = profiles_to_points(raw, SENSOR, T_DIAG, motion.offsets())
    assert np.array_equal(profile, scan.profile) and np.array_equal(column, scan.column)
    assert np.abs(points - scan.points).max() < 1e-9  # %.4f mm keeps the 1.6 µm grid exactly


def test_empty_points_use_the_device_marker(tmp_path):
    scan = Scanner(plate(-40), SENSOR, "white-diffuse").scan(T_DOWN, ScanMotion(1 * MM))
    path = write_profiles(tmp_path / "empty.csv", scan.raw)
    first = path.read_text().splitlines()[-1].split(",")
    assert len(first) == 3200 and set(first) == {"-9999.9999"}


def test_normals_follow_the_rotated_part():
    scanner = Scanner(plate(0.0), SENSOR, "white-diffuse")
    rpy = np.deg2rad([1.5, -2.0, 0.5])
    scan = scanner.scan(T_DOWN, ScanMotion(2 * MM), PartPose(rpy), noise=False)
    normals = scanner.normals(scan)
    expected = part_motion(rpy, np.zeros(3))[:3, 2]  # the plate's +z, rotated
    assert len(scan) > 0 and np.allclose(normals, expected, atol=1e-12)


def test_an_occluder_hides_what_it_covers_and_returns_no_points():
    # A plate at z = 0 seen from below through a box (the flange) that covers its middle third in x.
    T_UP = np.array([[0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 1, -0.002], [0, 0, 0, 1.0]])  # z_S = +z_O, R under the plate
    motion = ScanMotion(30 * MM)
    free = Scanner(plate(0.0), SENSOR, "white-diffuse").scan(T_UP, motion, noise=False)
    flange = (np.array([-5, -40, -15]) * MM, np.array([5, 40, -2.5]) * MM)  # 10 mm wide in x, below the plate
    hidden = Scanner(plate(0.0), SENSOR, "white-diffuse", occluders=[flange]).scan(T_UP, motion, noise=False)
    assert len(free) == motion.n_profiles * 3200
    assert np.allclose(hidden.points[:, 2], -2 * MM, atol=1e-12)  # only the plate's bottom face, never the box
    x = hidden.points[:, 0]
    assert not np.any((x > -5 * MM) & (x < 5 * MM))  # nothing behind the box
    assert np.any(x < -8 * MM) and np.any(x > 8 * MM)


@pytest.mark.parametrize("part_name", ["part_a", "part_b", "part_c"])
@pytest.mark.parametrize("stride", [16, 40])
def test_casting_only_anchor_columns_gives_the_same_points_as_casting_every_column(part_name, stride):
    """Columns between two anchors that hit one triangle are filled, not cast, and their shadow rays are
    skipped when both anchors see the receiver: the shipped parts' scans (edges, holes, shadows, the
    flange) come out bit-identical to casting every column, at a turned orientation too. Between anchors
    on two triangles of one plane (most of them: a CAD face is many triangles) the rays are filled too."""
    from optipose.model.part import load_part
    from optipose.scan.scanner import part_scanner

    part = load_part(part_name)
    poses = part.layouts["hand"].poses
    every, anchors = part_scanner(part, column_stride=1), part_scanner(part, column_stride=stride)
    for rpy_deg in ([0.0, 0.0, 0.0], [1.7, -1.3, 0.9]):
        rpy = np.deg2rad(rpy_deg)
        a = every.scan_many(poses, part.motion, PartPose(rpy, part.rotation_centre), rng=3)
        b = anchors.scan_many(poses, part.motion, PartPose(rpy, part.rotation_centre), rng=3)
        for x, y in zip(a, b):
            assert len(x) > 10_000
            np.testing.assert_array_equal(x.points, y.points)
            np.testing.assert_array_equal(x.raw, y.raw)


def test_a_step_shadow_is_the_same_with_anchor_columns():
    """The step of the shadow test turned 30° about z, so its shadow's boundary runs across the line's
    columns: the hits between anchors there are traced, and the cloud is the one of every column cast."""
    mesh = trimesh.util.concatenate([box([-20, -30, -5], [20, 30, 0]), box([2, -30, 0], [20, 30, 10])])
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(30.0), [0, 0, 1]))
    motion = ScanMotion(16 * MM, 0.05 * MM)
    every, anchors = (
        Scanner(mesh, SENSOR, "white-diffuse", column_stride=s).scan(T_DOWN, motion, noise=False) for s in (1, 16)
    )
    assert len(every) < 320 * 3200  # a shadow was cast
    np.testing.assert_array_equal(every.points, anchors.points)


def test_profiles_whose_fan_misses_the_parts_box_cast_no_ray_and_change_nothing():
    """Part B carried 300 mm past a sensor: most profiles' fans lie wholly outside the part's box and cast
    nothing, and the cloud is the one of a scanner that casts every profile."""
    from dataclasses import replace

    from optipose.model.part import load_part
    from optipose.scan.scanner import part_scanner

    part = load_part("part_b")
    part = replace(part, motion=ScanMotion(0.3, part.motion.step))
    pose = part.layouts["hand"].poses[1]
    scanners = {"box": part_scanner(part), "everything": part_scanner(part)}
    scanners["everything"]._bounds = (np.full(3, -np.inf), np.full(3, np.inf))
    cast = {}
    for name, scanner in scanners.items():
        first = scanner.caster.first_triangle
        cast[name] = 0

        def counted(origins, *args, _first=first, _name=name):
            cast[_name] += len(origins)
            return _first(origins, *args)

        scanner.caster.first_triangle = counted
    a, b = (
        s.scan(pose, part.motion, PartPose(np.deg2rad([0.7, -0.4, 1.1]), part.rotation_centre), rng=4)
        for s in scanners.values()
    )
    np.testing.assert_array_equal(a.points, b.points)
    assert (
        len(a) > 10_000 and cast["box"] < 0.5 * cast["everything"]
    )  # 4 of 5 profiles miss; anchors are most of the rest
