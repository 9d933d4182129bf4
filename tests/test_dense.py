"""Dense and large parts: collision, the scanner's set-up, the report's view and the scan budget stay bounded
in memory and time, against answers worked out by hand; the shipped parts' answers are those of the
full computations."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import trimesh

from optipose.model import convex, machine
from optipose.model.collision import BOUND_LOOSENESS, CollisionModel, ConvexSet
from optipose.model.convex import hull_arrays
from optipose.model.motion import ScanMotion
from optipose.model.part import Part, load_part
from optipose.report.views import drawn_mesh
from optipose.scan.hull import supporting_faces
from optipose.model.planes import shared_planes
from optipose.scan.scanner import SCAN_PROFILES, part_scanner, registered_motion

R = 0.03  # m, the sphere's radius
SHIPPED = ("part_a", "part_b", "part_c")


def sphere_part(subdivisions: int, length: float = 0.02) -> Part:
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=R)
    return Part(
        name="sphere",
        mesh=mesh,
        material="black-pla",
        sensor="keyence-lj-x8080",
        motion=ScanMotion(length),
        rotation_centre=np.zeros(3),
    )


def head_at(model: CollisionModel, corner_lo: np.ndarray) -> np.ndarray:
    """The pose (axes of O) that puts the head box's lowest corner at ``corner_lo``."""
    T = np.eye(4)
    T[:3, 3] = corner_lo - model.sensor.head_box_corners().min(axis=0)
    return T


def head_above(model: CollisionModel, z: float) -> np.ndarray:
    """The pose (axes of O) that puts the head box's bottom face at height ``z``, centred over O's origin."""
    corners = model.sensor.head_box_corners()
    return head_at(model, np.array([*(-0.5 * np.ptp(corners, axis=0)[:2]), z]))


@pytest.fixture(scope="module")
def dense_sphere():
    part = sphere_part(6)  # 81,920 faces, 40,962 vertices all on the hull
    hull_arrays(part.mesh)  # the hull (qhull), kept per mesh: not the collision model's own memory
    tracemalloc.start()
    model = CollisionModel(part)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return part, model, peak


def test_dense_sphere_collision_is_bounded_in_memory(dense_sphere):
    part, model, peak = dense_sphere
    assert not model.exact
    # the hull's vertices times its faces in float64 would be 27 GB; the model streams them
    assert peak < 64 * len(part.mesh.vertices) * 3 * 8


def test_dense_sphere_clearance_matches_the_hand_computed_gap(dense_sphere):
    """A sphere of radius R swept from x = a to x = b is a capsule: the gap to a head box whose bottom face
    is at height z over it is z - R; to a box whose corner points out of the capsule's end along a
    diagonal it is the corner's distance to (b, 0, 0) minus R. The tessellated sphere lies inside the
    round one (by far less than a micrometre here), and the bounding polytope stands out of it by at
    most BOUND_LOOSENESS × R."""
    part, model, _ = dense_sphere
    b = part.motion.offsets().max()
    tol = BOUND_LOOSENESS * R
    for gap in (0.5e-3, 2e-3, 10e-3):
        face = model.clearance(head_above(model, R + gap))
        assert face.obstacle == "part" and gap - tol <= face.distance <= gap + 1e-6
        u = np.ones(3) / np.sqrt(3.0)
        corner = model.clearance(head_at(model, np.array([b, 0.0, 0.0]) + (R + gap) * u))
        assert gap - tol <= corner.distance <= gap + 1e-6
    sunk = model.clearance(head_above(model, R - 3e-3))  # 3 mm into the top
    assert -3e-3 - tol <= sunk.distance <= -3e-3 + 1e-6


def test_shipped_parts_keep_their_exact_hulls():
    for name in SHIPPED:
        part = load_part(name)
        model = CollisionModel(part)
        offsets = part.motion.offsets()
        hull = np.asarray(part.mesh.convex_hull.vertices)
        swept = ConvexSet.hull_of(np.concatenate([hull + [offsets.min(), 0, 0], hull + [offsets.max(), 0, 0]]))
        assert model.exact
        for a, b in zip(model.obstacles[0][1].__dict__.values(), swept.__dict__.values()):
            assert np.array_equal(a, b)


def brute_force_supporting(mesh, normals, offsets, tol=1e-9):
    """Every hull vertex's height over every face's plane: the definition, quadratic."""
    hull = np.asarray(mesh.convex_hull.vertices)
    return ((hull @ normals.T - offsets).max(axis=0) <= tol) & (np.linalg.norm(normals, axis=1) > 0.5)


@pytest.mark.parametrize("which", ["sphere", "part_b 2 mm", *SHIPPED])
def test_supporting_faces_by_climbing_equal_the_definition(which):
    if which == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=4, radius=R)
    elif which == "part_b 2 mm":
        base = load_part("part_b").mesh
        mesh = trimesh.Trimesh(
            *trimesh.remesh.subdivide_to_size(base.vertices, base.faces, max_edge=2e-3), process=False
        )
    else:  # the scanner's own mesh: the part with its keep-outs
        scanner = part_scanner(load_part(which))
        mesh = trimesh.Trimesh(scanner.vertices, scanner.faces, process=False)
    _, normals, offsets, _, _ = shared_planes(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))
    got = supporting_faces(mesh, normals, offsets)
    assert np.array_equal(got, brute_force_supporting(mesh, normals, offsets))
    if which == "sphere":  # a convex mesh: every face is on its hull
        assert got.all()


@pytest.mark.parametrize("which", ["sphere", *SHIPPED])
def test_hull_arrays_are_trimeshs_hull_unoriented(which):
    """The same vertices in the same order as trimesh's repaired hull, and every edge of it."""
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=R) if which == "sphere" else load_part(which).mesh
    vertices, faces = hull_arrays(mesh)
    full = mesh.convex_hull
    assert np.array_equal(vertices, full.vertices)
    edges = {tuple(e) for e in np.sort(trimesh.Trimesh(vertices, faces, process=False).edges, axis=1)}
    assert {tuple(e) for e in np.sort(full.edges, axis=1)} <= edges
    assert hull_arrays(mesh)[0] is vertices  # kept per mesh


def test_a_dense_meshs_hull_is_shared_through_a_file(tmp_path, monkeypatch):
    monkeypatch.setattr(machine, "SHARED_FACES", 0)
    monkeypatch.setattr(machine.tempfile, "gettempdir", lambda: str(tmp_path))
    monkeypatch.setattr(machine, "_WRITTEN", [])
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=R)
    vertices, faces = hull_arrays(mesh)
    (written,) = tmp_path.glob("optipose-hull-*.npz")
    assert machine._WRITTEN == [written]
    monkeypatch.setattr(convex, "_compute", lambda mesh: pytest.fail("computed again"))
    again = hull_arrays(
        trimesh.Trimesh(mesh.vertices.copy(), mesh.faces.copy(), process=False)
    )  # another process's mesh
    assert np.array_equal(again[0], vertices) and np.array_equal(again[1], faces)
    machine._remove_written()
    assert not written.exists()


def test_a_dense_meshs_scanner_arrays_are_shared_through_a_file(tmp_path, monkeypatch):
    from optipose.model import planes
    from optipose.scan.hull import face_arrays

    monkeypatch.setattr(machine, "SHARED_FACES", 0)
    monkeypatch.setattr(machine.tempfile, "gettempdir", lambda: str(tmp_path))
    monkeypatch.setattr(machine, "_WRITTEN", [])
    scanner = part_scanner(load_part("part_c"))  # the part with its keep-outs, written by the scanner
    assert len(list(tmp_path.glob("optipose-faces-*.npz"))) == 1
    monkeypatch.setattr(planes, "shared_planes", lambda *a: pytest.fail("computed again"))
    mesh = trimesh.Trimesh(scanner.vertices.copy(), scanner.faces.copy(), process=False)  # another process's
    read = face_arrays(mesh, scanner.vertices, scanner.faces)
    held = (scanner._plane, scanner._normals, scanner._offsets, scanner._edge_n, scanner._edge_c, scanner._on_hull)
    for a, b in zip(read, held):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    machine._remove_written()


def test_a_dense_part_is_drawn_with_a_bounded_number_of_triangles():
    mesh = trimesh.creation.icosphere(subdivisions=7, radius=R)  # 327,680 faces
    drawn = drawn_mesh(mesh, 50_000)
    assert 10_000 < len(drawn.faces) <= 50_000
    assert np.abs(drawn.bounds - mesh.bounds).max() < 2e-3  # the same sphere, to a cell or so
    radius = np.linalg.norm(drawn.vertices, axis=1)
    assert np.abs(radius - R).max() < 1e-3
    shipped = load_part("part_b").mesh
    assert drawn_mesh(shipped, 50_000) is shipped  # a shipped part is drawn whole


def test_a_long_part_is_scanned_in_bounded_profiles():
    metre = ScanMotion(1.0, 0.5e-3)  # 2000 profiles
    motion = registered_motion(metre)
    assert motion.length == metre.length and motion.n_profiles <= SCAN_PROFILES
    assert motion.step == pytest.approx(metre.step * np.ceil(metre.n_profiles / SCAN_PROFILES))
    for name in SHIPPED:  # their motions are the scans' own: nothing changes
        part = load_part(name)
        assert registered_motion(part.motion) is part.motion


def test_the_evaluation_of_a_metre_long_part_casts_bounded_rays(tmp_path):
    from optipose.evaluate.evaluator import Evaluator
    from optipose.evaluate.objective import load_objective, reduced_objective
    from optipose.evaluate.worker import run_chunk
    from optipose.search.surrogate import SURROGATE_RAYS, Surrogate

    bar = trimesh.creation.box(extents=[1.0, 0.05, 0.02])
    bar.apply_translation([0.5, 0.0, 0.01])
    path = tmp_path / "bar.stl"
    bar.export(path)
    part = load_part(path)  # a metre-long bar, with the conventional placement
    with Evaluator(part, reduced_objective(load_objective("paper").in_cell("ideal")), seed=0, jobs=1, quiet=True) as ev:
        assert ev.setup.motion.n_profiles <= SCAN_PROFILES
        _, points, _, _ = run_chunk(ev.setup, part.layouts["conventional"], ev.tasks()[:1])
    columns = 3200  # the keyence-lj-x8080's points per profile
    assert 0 < max(p["n_points"] for p in points) <= SCAN_PROFILES * columns
    surrogate = Surrogate(part, turns=np.zeros((0, 3)))
    assert surrogate.motion.n_profiles * surrogate.scanner.sensor.points_per_profile <= SURROGATE_RAYS


def test_shipped_parts_surrogate_scans_are_unchanged():
    from optipose.search.surrogate import Surrogate

    for name in SHIPPED:
        part = load_part(name)
        surrogate = Surrogate(part, turns=np.zeros((0, 3)))
        assert surrogate.motion == ScanMotion(part.motion.length, part.motion.step * 2.0)  # the default step_factor
