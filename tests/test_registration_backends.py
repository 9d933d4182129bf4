"""Contract tests every registration back-end passes (in the spirit of optuna's ``BasicSamplerTestCase``),
and the cross-checks between back-ends.

The part is a step block made by hand: a 40 x 30 x 10 mm base with a 20 x 30 x 10 mm step on its
x < 20 mm half (an L-shaped profile in x-z, extruded 30 mm along y). Sampled on every face it pins all six
motions, and its answers are known: a cloud on the surface registers to identity, and a cloud turned by
1° about each axis registers to the inverse of that turn.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
import trimesh
from meshes import centroid_split, distance_to_every_face

from optipose.errors import ConfigError
from optipose.evaluate.objective import load_objective
from optipose.registration import BACKENDS, Matches, Registration, backend_for, get_backend, register, register_backend
from optipose.registration.reference import SurfaceReference
from optipose.registration.sampled import SampledReference, sample_surface
from optipose.transforms import invert_T, matrix_to_rpy, part_motion, transform_points

DEG = np.pi / 180
CENTRE = np.array([0.020, 0.015, 0.010])  # m: the turns are about the block's middle
RPY = np.array([1.0, 1.0, 1.0]) * DEG
CASES = [(name, method) for name in BACKENDS for method in get_backend(name).methods]


def _config(name: str, method: str, **changes):
    # a step of 1e-5° whatever the paper objective says: point-to-point ICP crawls (each step ~0.8 of the
    # last), and 1e-4° (ample for point-to-plane's Gauss-Newton steps) stopped it 2.8e-4° short of the turn
    cfg = replace(
        load_objective("paper").in_cell("ideal").registration,
        backend=name,
        method=method,
        max_iterations=500,
        tolerance_rotation=np.deg2rad(1e-5),
        tolerance_translation=1e-8,
    )
    return replace(cfg, **changes)


@pytest.fixture(scope="module")
def block() -> trimesh.Trimesh:
    profile = np.array([[0, 0], [40, 0], [40, 10], [20, 10], [20, 20], [0, 20]]) * 1e-3  # (x, z), counter-clockwise
    vertices = np.array([[x, y, z] for y in (0.0, 0.030) for x, z in profile])
    caps = [(0, 1, 2), (0, 2, 3), (0, 3, 5), (3, 4, 5)]  # the L in four triangles, facing -y at y = 0
    faces = caps + [(a + 6, c + 6, b + 6) for a, b, c in caps]
    for i in range(6):
        j = (i + 1) % 6
        faces += [(i, j + 6, j), (i, i + 6, j + 6)]  # outward: the profile runs counter-clockwise in x-z
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert (
        mesh.is_watertight
        and mesh.is_winding_consistent
        and mesh.volume > 0
        and mesh.area == pytest.approx(2 * 600e-6 + 120e-3 * 30e-3)
    )
    return mesh


@pytest.fixture(scope="module")
def surface(block) -> SurfaceReference:
    return SurfaceReference(block.vertices, block.faces)


@pytest.fixture(scope="module")
def cloud(block) -> tuple[np.ndarray, np.ndarray]:
    """About one point per mm² of the block (4,800 points) and their face normals."""
    return sample_surface(block.vertices, block.faces, 1e-3, seed=2)


@pytest.fixture(scope="module")
def turned(cloud) -> np.ndarray:
    """The block's cloud turned by 1° about each axis (about CENTRE), as a scan of the turned part in O."""
    return transform_points(part_motion(RPY, CENTRE), cloud[0])


@pytest.fixture(scope="module")
def recovered(surface, turned) -> dict:
    """Every back-end and method once on the turned cloud (Open3D against a 0.25 mm sample)."""
    return {
        (name, method): register(turned, surface, _config(name, method, reference_spacing=0.25e-3))
        for name, method in CASES
    }


# -- the contract -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("name, method", CASES)
def test_a_cloud_on_the_reference_stays_at_identity(cloud, name, method):
    points, normals = cloud
    reg = register(points, SampledReference(points, normals), _config(name, method))
    assert reg.ok, reg.failure
    np.testing.assert_allclose(reg.T_target_source, np.eye(4), rtol=0, atol=1e-12)
    assert reg.fitness == 1.0 and reg.rmse < 1e-12


@pytest.mark.parametrize("name, method", CASES)
def test_a_one_degree_turn_about_each_axis_comes_back(recovered, name, method):
    """To 0.03° and 10 µm: the loosest back-end, Open3D point-to-point against a 0.25 mm sample, stops
    about 0.015° short (its matches are sample points); the exact-surface ones are checked tighter below."""
    reg = recovered[(name, method)]
    assert reg.ok, reg.failure
    T_est = invert_T(reg.T_target_source)  # the part's estimated motion
    np.testing.assert_allclose(np.rad2deg(matrix_to_rpy(T_est[:3, :3])), np.rad2deg(RPY), rtol=0, atol=0.03)
    np.testing.assert_allclose(T_est[:3, 3], part_motion(RPY, CENTRE)[:3, 3], rtol=0, atol=10e-6)


@pytest.mark.parametrize("name, method", CASES)
def test_the_result_is_well_formed(recovered, turned, name, method):
    reg = recovered[(name, method)]
    T = reg.T_target_source
    assert isinstance(reg, Registration) and T.shape == (4, 4)
    np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), rtol=0, atol=1e-12)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0, abs=1e-12) and T[3].tolist() == [0, 0, 0, 1]
    assert 0.0 <= reg.fitness <= 1.0 and 0.0 <= reg.rmse < 1e-3
    assert reg.n_points == len(turned) and reg.iterations <= 500 and reg.converged and reg.failure == ""
    H = reg.information
    assert H.shape == (6, 6)
    np.testing.assert_allclose(H, H.T, rtol=1e-12, atol=1e-12 * np.abs(H).max())
    assert np.linalg.eigvalsh(H).min() > -1e-9 * np.abs(H).max()


@pytest.mark.parametrize("name, method", CASES)
def test_too_few_points_fail_with_a_reason(surface, cloud, name, method):
    reg = register(cloud[0][:5], surface, _config(name, method))
    assert not reg.ok and reg.failure == "only 5 points" and reg.n_points == 5


@pytest.mark.parametrize("name, method", CASES)
def test_a_cloud_out_of_reach_fails_with_a_reason(surface, cloud, name, method):
    far = cloud[0][:200] + [1.0, 0.0, 0.0]  # 1 m off: no point within the 5 mm correspondence distance
    reg = get_backend(name).register(far, surface, _config(name, method))
    assert not reg.ok and reg.failure and reg.fitness == 0.0


# -- cross-checks between back-ends --------------------------------------------------------------------------
@pytest.mark.parametrize("method, degrees", [("point_to_plane", 3e-3), ("point_to_point", 0.03)])
def test_fast_and_open3d_agree(recovered, method, degrees):
    fast, o3d = (
        matrix_to_rpy(invert_T(recovered[(name, method)].T_target_source)[:3, :3]) for name in ("fast", "open3d")
    )
    np.testing.assert_allclose(np.rad2deg(fast), np.rad2deg(RPY), rtol=0, atol=1e-4)  # the exact surface
    np.testing.assert_allclose(np.rad2deg(o3d), np.rad2deg(fast), rtol=0, atol=degrees)


@pytest.mark.parametrize("method", ["point_to_plane", "point_to_point"])
def test_compiled_icp_agrees_with_the_plain_numpy_reference(surface, cloud, method):
    """The compiled fast path and the plain one run the same iterations to the same pose (summation order only)."""
    noisy = cloud[0] + np.random.default_rng(5).normal(scale=5e-6, size=cloud[0].shape)
    scan = transform_points(part_motion(np.array([0.9, -0.7, 1.1]) * DEG, CENTRE), noisy)
    cfg = _config("fast", method, max_iterations=300)
    start = Matches(*surface.closest(scan))
    fast, plain = register(scan, surface, cfg, start), get_backend("plain").register(scan, surface, cfg, start)
    assert fast.ok and plain.ok and fast.iterations == plain.iterations
    np.testing.assert_allclose(fast.T_target_source, plain.T_target_source, rtol=0, atol=1e-12)
    assert fast.fitness == plain.fitness and abs(fast.rmse - plain.rmse) < 1e-12
    # a point off an edge takes the direction to its closest point as its normal, which the two paths round
    # differently when it is close to the edge: a few 1e-10 of the information's small entries
    np.testing.assert_allclose(fast.information, plain.information, rtol=1e-8, atol=1e-12)


def test_a_sampled_reference_finds_the_kd_trees_nearest_points(block):
    """The grid search of a CAD sample answers the KD-tree's nearest points, near the sample and far from
    it, with the previous step's matches as hints or without."""
    reference = SampledReference(*sample_surface(block.vertices, block.faces, 0.25e-3, seed=1))
    rng = np.random.default_rng(3)
    base = reference.points[rng.choice(len(reference.points), 4000)]
    for scale in (1e-6, 5e-5, 3e-4, 3e-3, 3e-2):
        p = base + rng.normal(scale=scale, size=base.shape)
        truth = reference.closest(p)[2]
        hint = reference.closest(p + rng.normal(scale=2e-5, size=p.shape))[2]
        np.testing.assert_array_equal(reference.nearest(p)[2], truth)
        np.testing.assert_array_equal(reference.nearest(p, hint)[2], truth)


def test_a_sampled_references_tracker_answers_the_kd_trees_nearest_points_at_every_step(block):
    """An ICP's tracker searches again only the points that moved as far as half the gap to their second-
    nearest sample: along a path of steps from a millimetre down to a nanometre (and back up), started
    from the matches where the path starts or from nothing, every step's matches are the KD-tree's."""
    reference = SampledReference(*sample_surface(block.vertices, block.faces, 0.25e-3, seed=1))
    rng = np.random.default_rng(4)
    cloud = reference.points[rng.choice(len(reference.points), 3000)] + rng.normal(scale=3e-5, size=(3000, 3))
    steps = [2e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 1e-7, 1e-9, 0.0, 1e-9, 1e-6, 1e-4, 2e-3]
    for track in (reference.tracker(initial=reference.matches(cloud)), reference.tracker()):
        T = np.eye(4)
        for i, size in enumerate(steps):
            p = transform_points(T, cloud)
            q, n, ids = track(p)
            truth = reference.closest(p)
            np.testing.assert_array_equal(ids, truth[2])
            np.testing.assert_array_equal(q, truth[0])
            np.testing.assert_array_equal(n, truth[1])
            if i and steps[i - 1] <= 1e-7:  # settled: nearly every point keeps a margin, which lets steps skip it
                assert (track.margin > 0).mean() > 0.9
            step = part_motion(
                rng.normal(scale=size / 0.02, size=3), CENTRE, rng.normal(scale=size, size=3)
            )  # ~size at the block
            T = step @ T


def test_a_sampled_references_tracker_takes_any_hint_and_ignores_one_that_is_not_its_point(block):
    """Hints only start the search: wrong ones (another point's, or ids past the reference's points, as a
    surface's face ids would be) still give the KD-tree's nearest points."""
    reference = SampledReference(*sample_surface(block.vertices, block.faces, 0.5e-3, seed=1))
    rng = np.random.default_rng(6)
    p = reference.points[rng.choice(len(reference.points), 2000)] + rng.normal(scale=1e-4, size=(2000, 3))
    hints = rng.integers(0, 3 * len(reference.points), size=len(p))
    np.testing.assert_array_equal(reference.tracker(hints)(p)[2], reference.closest(p)[2])


def test_a_samples_neighbour_list_holds_every_sample_closer_than_its_radius(block):
    """The walk's certificate rests on this: each sample's list is its KD-tree nearest, in order, up to its
    radius, and no sample left off the list is closer than the radius."""
    reference = SampledReference(*sample_surface(block.vertices, block.faces, 0.25e-3, seed=1))
    near, rho = reference._neighbours()
    pick = np.random.default_rng(5).choice(len(reference.points), 500, replace=False)
    for i in pick:
        d = np.linalg.norm(reference.points - reference.points[i], axis=1)
        d[i] = np.inf
        listed = near[i][near[i] >= 0]
        assert np.all(np.diff(d[listed]) >= 0) and rho[i] > 0
        closer = np.flatnonzero(d < rho[i])
        assert set(closer) <= set(listed)


def test_the_fitness_stop_runs_open3ds_point_to_point_icp(block, turned):
    """stop = "fitness" in the compiled back-end takes Open3D's steps and stops where Open3D stops (inlier
    fraction and RMSE unchanged, or the iteration cap): the same pose as Open3D's ICP against the same sample."""
    reference = SampledReference(*sample_surface(block.vertices, block.faces, 0.5e-3, seed=1))
    for cap in (8, 60):
        cfg = replace(
            _config("fast", "point_to_point", reference="cad-sample", reference_spacing=0.5e-3),
            stop="fitness",
            max_iterations=cap,
        )
        fast, o3d = register(turned, reference, cfg), register(turned, reference, replace(cfg, backend="open3d"))
        assert fast.ok and o3d.ok and (fast.iterations == cap) == (cap == 8)
        np.testing.assert_allclose(fast.T_target_source, o3d.T_target_source, rtol=0, atol=1e-9)


# -- the registry ----------------------------------------------------------------------------------------
def test_generalized_icp_goes_to_open3d_whatever_the_backend():
    cfg = load_objective("paper").in_cell("ideal").registration
    assert backend_for(replace(cfg, backend="fast", method="generalized")) is get_backend("open3d")
    assert backend_for(replace(cfg, backend="fast", method="point_to_plane")) is get_backend("fast")


def test_an_unknown_backend_is_a_one_line_config_error():
    with pytest.raises(ConfigError, match="unknown registration backend 'magic' \\(registered: fast, ") as err:
        get_backend("magic")
    assert "\n" not in str(err.value)


def test_a_registered_backend_is_used_and_accepted_by_objectives(monkeypatch, surface, cloud):
    class Identity:
        methods, takes_initial, calls = ("point_to_plane",), False, []

        def register(self, source, reference, cfg, initial=None):
            self.calls.append(len(source))
            return Registration(np.eye(4), True, 0, 1.0, 0.0, len(source), np.zeros((6, 6)))

    monkeypatch.setitem(BACKENDS, "identity", None)  # restored after the test
    register_backend("identity", Identity())
    reg = register(cloud[0], surface, _config("identity", "point_to_plane"))
    assert reg.ok and Identity.calls == [len(cloud[0])]
    from optipose.evaluate.objective import objective_from_table

    assert objective_from_table({"registration": {"backend": "identity"}}).registration.backend == "identity"
    with pytest.raises(TypeError, match="needs methods"):
        register_backend("broken", object())


def test_importing_registration_loads_no_heavy_dependency():
    code = "import sys, optipose.registration; print(sorted({'open3d', 'numba', 'scipy'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_an_icp_caught_in_a_cycle_settles_on_the_cycles_mean():
    from optipose.registration.config import RegistrationConfig
    from optipose.registration.fast import Cycle
    from optipose.transforms import make_T, rpy_to_matrix

    cfg = RegistrationConfig()
    a, b, c = (make_T(rpy_to_matrix(np.deg2rad([x, 0, 0]) * 1e-3), np.array([0, x * 1e-6, 0])) for x in (1.0, 1.6, 1.3))
    cycle = Cycle(cfg)
    # a period-3 cycle, each step 0.3 to 0.6 mdeg (far above the 1e-5 deg tolerance): settles on the 4th pose
    assert [cycle(T) for T in (a, b, c)] == [None, None, None]
    middle = cycle(a.copy())
    assert middle is not None
    assert np.rad2deg(np.arccos(middle[1, 1])) * 1e3 == pytest.approx((1.0 + 1.6 + 1.3) / 3, rel=1e-6)
    assert middle[1, 3] == pytest.approx((1.0 + 1.6 + 1.3) / 3 * 1e-6)
    # a steadily converging ICP (each step 0.8 of the last, until the tolerance would stop it) is no cycle
    steady, T = Cycle(cfg), np.eye(4)
    for n in range(30):
        T = make_T(rpy_to_matrix(np.deg2rad([0.8**n, 0, 0]) * 1e-2), np.zeros(3)) @ T
        assert steady(T) is None
    # a pose that jitters about one place without repeating settles within two windows, on about that place
    rng, jitter, settled = np.random.default_rng(3), Cycle(cfg), None
    for n in range(24):
        out = jitter(make_T(rpy_to_matrix(np.deg2rad([5 + rng.normal(0, 0.3), 0, 0]) * 1e-3), np.zeros(3)))
        settled = out if settled is None else settled
    assert settled is not None and np.rad2deg(np.arccos(settled[1, 1])) * 1e3 == pytest.approx(5.0, abs=0.5)


def test_combined_start_adds_the_clouds_quadratic_models():
    """Cloud 1 sees only roll (and translation) and sits at roll a; cloud 2 sees only pitch and yaw and
    sits at pitch b. Their models add: the combined pose has roll a and pitch b (to second order), and
    yaw stays where both left it. One cloud alone starts where it stands, whatever its centroid."""
    from scipy.spatial.transform import Rotation

    from optipose.registration.backends import combined_start

    a, b = 1.5e-3, -2.0e-3
    T1, T2 = np.eye(4), np.eye(4)
    T1[:3, :3] = Rotation.from_rotvec([a, 0, 0]).as_matrix()
    T2[:3, :3] = Rotation.from_rotvec([0, b, 0]).as_matrix()
    H1, H2 = np.diag([4.0, 0, 0, 1, 1, 1]), np.diag([0, 3.0, 2.0, 1, 1, 1])
    T = combined_start([(T1, H1, np.zeros(3)), (T2, H2, np.zeros(3))])
    rotvec = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    np.testing.assert_allclose(rotvec, [a, b, 0.0], atol=1e-5)
    np.testing.assert_allclose(T[:3, 3], 0.0, atol=1e-9)
    T3 = part_motion(np.array([0.3, -0.2, 0.5]) * DEG, CENTRE)
    np.testing.assert_allclose(
        combined_start([(T3, np.diag([1.0, 2, 3, 4, 5, 6]), np.array([0.05, -0.02, 0.01]))]), T3, atol=1e-12
    )


def test_combined_start_moves_each_model_to_a_common_origin():
    """Two clouds far apart (centroids 0.2 m on either side) that both sit at the same translated pose:
    their models, each about its own centroid, agree once moved to a common origin, so the start is
    that pose (adding them about the wrong origin would turn it)."""
    from optipose.registration.backends import combined_start

    T = part_motion(np.array([0.0, 0.0, 0.8]) * DEG, np.zeros(3))
    T[:3, 3] += [1e-4, -2e-4, 3e-4]
    H = np.diag([1.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    start = combined_start([(T, H, np.array([0.2, 0.0, 0.0])), (T, 2 * H, np.array([-0.2, 0.1, 0.0]))])
    np.testing.assert_allclose(start, T, atol=1e-12)


@pytest.mark.parametrize("off_mm", [0.3, 0.08])
@pytest.mark.parametrize("name", ["part_a", "part_b", "part_c", "part_b_split"])
def test_the_surface_search_answers_what_every_face_does(name, off_mm):
    """Closest points on A, B and C against the distance to every face: points within a millimetre
    of the surface, without a guess (the grid, its faces in order of their bound, the skips) and with the
    face of a point a few hundred µm away as the guess (the follow test and the walk across edges). At
    0.08 mm off, a cloud of the part as made: most points near an edge of the tessellation inside a plane
    keep their face and its neighbour there; part B split at its faces' centroids has three times as many."""
    from optipose.model.part import load_part

    mesh = load_part(name.removesuffix("_split")).mesh
    if name.endswith("_split"):
        mesh = centroid_split(mesh)
    reference = SurfaceReference(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(7)
    base, _ = trimesh.sample.sample_surface(mesh, 600 if off_mm > 0.1 else 2000, seed=7)
    points = base + rng.normal(size=(len(base), 3)) * off_mm * 1e-3
    truth = np.array([distance_to_every_face(mesh.triangles, p).min() for p in points])
    near = truth < 0.9e-3  # the grid's reach (farther, Open3D answers in float32)
    points, truth = points[near], truth[near]
    drifted = points + rng.normal(size=points.shape) * (2.0 / 3.0) * off_mm * 1e-3  # where the ICP's last step put them
    guess = reference.nearest(drifted)[2]
    for hints in (None, guess):
        q, n, ids = reference.nearest(points, hints)
        d = np.linalg.norm(points - q, axis=1)
        np.testing.assert_allclose(d, truth, rtol=0, atol=1e-12)
        own = np.array([distance_to_every_face(mesh.triangles[[f]], p)[0] for p, f in zip(points, ids)])
        np.testing.assert_allclose(own, d, rtol=0, atol=1e-12)  # the face named is one that near
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)


# -- the trust region of a point-to-plane step ---------------------------------------------------------------
def _gauss_newton(AtA, Atb, seen=None):
    """The undamped step (rotation vector, shift) as the solver takes it before any trust region."""
    if seen is None:
        return np.linalg.lstsq(AtA, Atb, rcond=1e-12)[0]
    return seen @ np.linalg.lstsq(seen.T @ AtA @ seen, seen.T @ Atb, rcond=1e-12)[0]


def test_a_step_within_the_trust_region_is_the_gauss_newton_step_bit_for_bit():
    """Every step of an ICP that moves as the protocols do (a few degrees, a fraction of the correspondence
    distance) is the Gauss-Newton step as it was solved before the trust region, to the last bit."""
    from scipy.spatial.transform import Rotation

    from optipose.registration.fast import MAX_TURN, _solve_point_to_plane

    rng = np.random.default_rng(11)
    seen = np.linalg.qr(rng.normal(size=(6, 5)))[0]  # one motion not stepped along
    for i in range(200):
        J = rng.normal(size=(300, 6)) * [0.01, 0.01, 0.01, 1, 1, 1]  # rows (p − c) × n, n for a cloud ~1 cm across
        AtA = J.T @ J
        x = rng.normal(size=6) * [0.01, 0.01, 0.01, 1e-3, 1e-3, 1e-3]  # ~1° and ~1 mm
        Atb, c = AtA @ x, rng.normal(size=3) * 0.02
        for s in (None, seen):
            step = _gauss_newton(AtA, Atb, s)
            assert np.linalg.norm(step[:3]) <= MAX_TURN and np.linalg.norm(step[3:]) <= 5e-3
            R = Rotation.from_rotvec(step[:3]).as_matrix()
            expected = np.eye(4)
            expected[:3, :3], expected[:3, 3] = R, c + step[3:] - R @ c
            np.testing.assert_array_equal(_solve_point_to_plane(AtA, Atb, c, s, reach=5e-3), expected)


def test_a_step_beyond_the_trust_region_holds_its_weakest_motion():
    """A motion seen ten orders below the rest whose share of Aᵀb asks for a turn of radians: the step holds it
    and gives the other five their Gauss-Newton step; a shift beyond the reach along a weak motion is held too."""
    from scipy.spatial.transform import Rotation

    from optipose.registration.fast import MAX_TURN, _damped, _solve_point_to_plane

    information = np.diag([3e-2, 2e-2, 1e-8, 300.0, 20.0, 1.0])  # the turn about z barely seen
    wanted = np.array([0.01, -0.02, 0.0, 1e-4, -2e-4, 3e-4])
    Atb = information @ wanted + [0, 0, 3e-8, 0, 0, 0]  # what the linearisation leaves out, on the weak motion
    assert np.linalg.norm(_gauss_newton(information, Atb)[:3]) > 1.0 > MAX_TURN  # 3 rad about z
    np.testing.assert_allclose(_damped(information, Atb, None, 5e-3), wanted, rtol=1e-12, atol=1e-18)
    T = _solve_point_to_plane(information, Atb, np.zeros(3), None, 5e-3)
    np.testing.assert_allclose(T[:3, :3], Rotation.from_rotvec(wanted[:3]).as_matrix(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(T[:3, 3], wanted[3:], rtol=1e-12, atol=0)

    shifting = np.diag([3e-2, 2e-2, 1e-3, 300.0, 20.0, 1e-6])  # now the shift along z barely seen
    Atb = shifting @ wanted + [0, 0, 0, 0, 0, 1e-6]  # asking for a metre
    assert _gauss_newton(shifting, Atb)[5] > 0.5
    np.testing.assert_allclose(_damped(shifting, Atb, None, 5e-3), [*wanted[:5], 0.0], rtol=1e-12, atol=1e-18)


@pytest.fixture(scope="module")
def bar() -> trimesh.Trimesh:
    """The step block drawn out to a 120 mm bar: the 20 mm high half on x < 60 mm, the 10 mm base beyond."""
    profile = np.array([[0, 0], [120, 0], [120, 10], [60, 10], [60, 20], [0, 20]]) * 1e-3
    vertices = np.array([[x, y, z] for y in (0.0, 0.030) for x, z in profile])
    caps = [(0, 1, 2), (0, 2, 3), (0, 3, 5), (3, 4, 5)]
    faces = caps + [(a + 6, c + 6, b + 6) for a, b, c in caps]
    for i in range(6):
        j = (i + 1) % 6
        faces += [(i, j + 6, j), (i, i + 6, j + 6)]
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    return mesh


def _band(step_face: bool) -> np.ndarray:
    """One line of a profile along the bar's top, down its step face (if ``step_face``) and along the base, every
    0.5 mm, at y = 15 mm."""
    s = np.arange(0.0, 59.0 + 10.0 + 59.0, 0.5) * 1e-3
    x = np.where(s < 59e-3, 1e-3 + s, np.where(s < 69e-3, 60e-3, 60e-3 + (s - 69e-3)))
    z = np.where(s < 59e-3, 20e-3, np.where(s < 69e-3, 20e-3 - (s - 59e-3), 10e-3))
    keep = step_face | (np.abs(x - 60e-3) > 1e-9)
    return np.column_stack([x, np.full_like(x, 15e-3), z])[keep]


@pytest.mark.parametrize("name", ["fast", "plain"])
def test_a_band_whose_gauss_newton_step_throws_it_off_the_part_registers(monkeypatch, bar, name):
    """Two lines 0.5 mm apart along a 120 mm bar, the step face in one line's shadow: the bar's yaw (the band's
    turn within its faces) is seen by that line's 20 points on the step face alone, 0.25 mm off the band's
    middle. Turned by 2° in roll and pitch about a centre 50 mm below, the points near the step's edges match
    the face beside theirs, and the first Gauss-Newton step puts that into the yaw: a turn of over 90°, after
    which the ICP ends far from the part's pose (no matches left, or a wrong one). With the trust region it
    holds the yaw until the rest is settled, and recovers the turn."""
    from optipose.registration import fast as icp
    from optipose.registration.normal_equations import normal_equations

    surface = SurfaceReference(bar.vertices, bar.faces)
    band = np.vstack([_band(True) - [0, 0.25e-3, 0], _band(False) + [0, 0.25e-3, 0]])
    rpy = np.deg2rad([2.0, 2.0, 0.0])
    scan = transform_points(part_motion(rpy, np.array([0.060, 0.015, -0.050])), band)
    cfg = _config(name, "point_to_plane", max_iterations=100)
    start = Matches(*surface.closest(scan))
    _, _, AtA, Atb, _ = normal_equations(scan, start.q, start.n, cfg.max_correspondence_distance**2)
    assert np.rad2deg(np.linalg.norm(_gauss_newton(AtA, Atb)[:3])) > 90.0

    reg = get_backend(name).register(scan, surface, cfg, start)
    assert reg.ok, reg.failure
    error = np.rad2deg(matrix_to_rpy(invert_T(reg.T_target_source)[:3, :3]) - rpy)
    assert np.all(np.abs(error) < [0.01, 0.01, 0.05]), error  # roll, pitch; the yaw seen by 20 points

    with monkeypatch.context() as m:  # the same ICP without the trust region
        m.setattr(icp, "_within", lambda x, reach: True)
        wild = get_backend(name).register(scan, surface, cfg, start)
    off = np.rad2deg(matrix_to_rpy(invert_T(wild.T_target_source)[:3, :3]) - rpy)
    assert not wild.ok or np.abs(off).max() > 10.0


def test_the_trust_regions_steps_agree_between_the_compiled_and_plain_icp(bar):
    """The band above through both back-ends: the same iterations to the same pose (summation order only)."""
    surface = SurfaceReference(bar.vertices, bar.faces)
    band = np.vstack([_band(True) - [0, 0.25e-3, 0], _band(False) + [0, 0.25e-3, 0]])
    scan = transform_points(part_motion(np.deg2rad([2.0, 2.0, 0.0]), np.array([0.060, 0.015, -0.050])), band)
    cfg = _config("fast", "point_to_plane", max_iterations=100)
    start = Matches(*surface.closest(scan))
    fast, plain = register(scan, surface, cfg, start), get_backend("plain").register(scan, surface, cfg, start)
    assert fast.ok and plain.ok and fast.iterations == plain.iterations
    np.testing.assert_allclose(fast.T_target_source, plain.T_target_source, rtol=0, atol=1e-10)
