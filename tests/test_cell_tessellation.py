"""The real cell draws from the seed and the surface, never from the triangles (docs/cell.md, "The cell and
the tessellation"): part B's mesh, split at its centroids, subdivided, its faces and vertices permuted, or
subdivided and written as a float32 STL, gives the same part as made, the same plane faces, the same
material draws and the same multipath edges at the same surface points. (The whole evaluation on
re-tessellated parts: tests/stress/test_stress_tessellation.py.)"""

from __future__ import annotations

import dataclasses
import io

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from meshes import centroid_split, distance_to_every_face
from optipose.cell.asmade import AsMade
from optipose.cell.config import load_cell, load_process
from optipose.cell.kernels import lattice_normals
from optipose.cell.scans import CellSetup, ConcaveEdges, LiveCell
from optipose.model.material import MaterialEffects, load_material
from optipose.model.part import load_part
from optipose.model.planes import surface_planes
from optipose.scan.scanner import Scan

ROUNDING = 1e-13  # m: float64 meshes of one surface give the same offsets to this
FLOAT32 = 2e-8  # m: a float32 STL's vertices are off the surface by ~4 nm, its 2 mm faces' normals by ~1e-5 rad


def _permuted(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The same triangles, listed in another order, each starting at another corner, its vertices renumbered."""
    rng = np.random.default_rng(5)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    order, renumber = rng.permutation(len(f)), rng.permutation(len(v))
    f = np.roll(f[order], 1, axis=1)
    inverse = np.empty_like(renumber)
    inverse[renumber] = np.arange(len(v))
    return trimesh.Trimesh(v[renumber], inverse[f], process=False)


def _subdivided(mesh: trimesh.Trimesh, size: float = 0.006) -> trimesh.Trimesh:
    return trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, size), process=False)


def _stl(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh written as a binary STL (float32) and read back as optipose reads a mesh file."""
    return trimesh.load(io.BytesIO(mesh.export(file_type="stl")), file_type="stl")


VARIANTS = {
    "centroid split": (centroid_split, ROUNDING),
    "subdivided": (_subdivided, ROUNDING),
    "permuted": (_permuted, ROUNDING),
    "subdivided, float32 STL": (lambda m: _stl(_subdivided(m, 0.002)), FLOAT32),
}


@pytest.fixture(scope="module")
def part_b():
    """Part B's mesh and 400 points on its surface with their faces."""
    mesh = load_part("part_b").mesh
    x, face = trimesh.sample.sample_surface(mesh, 400, seed=1)
    return mesh, x, face


@pytest.fixture(scope="module", params=list(VARIANTS))
def variant(request, part_b):
    """(name, the re-tessellated mesh, the face of it each point lies on, the tolerance)."""
    mesh, x, _ = part_b
    make, tolerance = VARIANTS[request.param]
    other = make(mesh)
    tri = np.asarray(other.triangles)
    lo, hi = tri.min(axis=1) - 1e-7, tri.max(axis=1) + 1e-7
    face = np.empty(len(x), np.int64)
    for i, p in enumerate(x):  # the exact nearest face among those whose box holds the point
        around = np.flatnonzero(np.all((lo <= p) & (p <= hi), axis=1))
        face[i] = around[np.argmin(distance_to_every_face(tri[around], p))]
    return request.param, other, face, tolerance


def _arrays(mesh):
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces)


def test_the_plane_faces_are_the_surfaces(part_b, variant):
    mesh, _, face = part_b
    _, other, other_face, tolerance = variant
    ours, theirs = surface_planes(*_arrays(mesh)), surface_planes(*_arrays(other))
    assert len(ours.area) == len(theirs.area) == 400 and np.all(theirs.plane >= 0)
    a, b = ours.plane[face], theirs.plane[other_face]
    np.testing.assert_allclose(theirs.centroid[b], ours.centroid[a], rtol=0, atol=tolerance)
    np.testing.assert_allclose(theirs.normal[b], ours.normal[a], rtol=0, atol=1e-12)
    np.testing.assert_allclose(theirs.area[b], ours.area[a], rtol=1e-6 if tolerance == FLOAT32 else 1e-12)


def test_the_part_as_made_is_the_surfaces(part_b, variant):
    """Every term of the FDM process (form, faces, scale, warp, layers) at the same points, for two seeds."""
    mesh, x, face = part_b
    _, other, other_face, tolerance = variant
    process = load_process("fdm")
    assert process.face_offset and process.face_tilt and process.scale and process.warp and process.layer_amplitude
    for seed in (3, 8):
        ours = AsMade(process, *_arrays(mesh), seed).offset(x, mesh.face_normals[face], face)
        theirs = AsMade(process, *_arrays(other), seed).offset(x, other.face_normals[other_face], other_face)
        assert ours.std() > 2e-5
        np.testing.assert_allclose(theirs, ours, rtol=0, atol=tolerance)


def _scan(x: np.ndarray, face: np.ndarray, pick: np.ndarray) -> Scan:
    """The points ``pick`` (in its order) as one sensor's scan, its parallel rays oblique to every face of
    the part (a face seen edge-on is capped at grazing incidence on the side its normal's rounding puts it),
    each point on a ray of its own."""
    ray = np.random.default_rng(2).choice(40 * 3200, len(x), replace=False)[pick]
    T_O_S = np.eye(4)
    T_O_S[:3, :3] = Rotation.from_rotvec([2.6, 0.5, 0.3]).as_matrix()
    T_O_S[:3, 3] = [0.03, 0.0, 0.1]
    return Scan(
        x[pick],
        (ray // 3200).astype(np.int32),
        (ray % 3200).astype(np.int32),
        np.ones(len(pick), np.float32),
        np.zeros((0, 3200)),
        T_O_S,
        face=face[pick].astype(np.int32),
        T_O_P=np.eye(4),
    )


def _moves(mesh, x, face, material, pick=None, seed=3):
    """What a live ur10e cell (part as made, material, robot path) adds to the points ``pick`` (default:
    all), in the order of ``pick``."""
    pick = np.arange(len(x)) if pick is None else pick
    part = dataclasses.replace(load_part("part_b"), material=material)
    live = LiveCell(CellSetup.of(load_cell("ur10e"), part), *_arrays(mesh), part.rotation_centre, seed)
    scan = _scan(x, face, pick)
    shifts = np.arange(40) * 0.5e-3
    moved = live.perturb([[scan]], [np.asarray(mesh.face_normals, float)], [np.inf], shifts, np.eye(4), 0.5e-3, 11)
    return moved[0][0].points - scan.points


@pytest.mark.parametrize("material", ["black-pla", "smooth-aluminium-ra0.8"])
def test_a_scan_in_the_cell_is_the_surfaces(part_b, variant, material):
    """The points moved by the part as made, the robot's path and the material (sub-surface, speckle,
    spurious returns, multipath near the pocket's concave edges) alike, point by point."""
    mesh, x, face = part_b
    _, other, other_face, tolerance = variant
    ours, theirs = _moves(mesh, x, face, material), _moves(other, x, other_face, material)
    assert np.sqrt(np.mean(ours**2)) > 2e-5
    np.testing.assert_allclose(theirs, ours, rtol=0, atol=tolerance)


def test_a_points_material_draw_is_its_rays_not_its_place_in_the_scan(part_b):
    """The scan's points in another order, or half of them dropped: each remaining point moves alike."""
    mesh, x, face = part_b
    effects = load_material("smooth-aluminium-ra0.8").effects
    assert effects.spurious_fraction and effects.concave_fraction and effects.speckle
    ours = _moves(mesh, x, face, "smooth-aluminium-ra0.8")
    shuffled = np.random.default_rng(4).permutation(len(x))
    np.testing.assert_array_equal(_moves(mesh, x, face, "smooth-aluminium-ra0.8", shuffled), ours[shuffled])
    half = np.arange(0, len(x), 2)
    np.testing.assert_array_equal(_moves(mesh, x, face, "smooth-aluminium-ra0.8", half), ours[half])


def test_the_concave_edges_are_segments_whatever_their_split():
    """Points around part B's concave edges, many within a sample's spacing of the distance: near or not
    as the exact distance to the segments says, on the shipped edges and on the subdivided mesh's."""
    mesh = load_part("part_b").mesh
    ours = ConcaveEdges.of(*_arrays(mesh))
    theirs = ConcaveEdges.of(*_arrays(_subdivided(mesh, 0.0013)))
    assert len(theirs.start) > 2 * len(ours.start)
    rng = np.random.default_rng(7)
    pick = rng.integers(len(ours.start), size=3000)
    along = ours.start[pick] + rng.uniform(0, 1, (3000, 1)) * (ours.end[pick] - ours.start[pick])
    direction = rng.normal(size=(3000, 3))
    distance = 2e-3 + rng.uniform(-1e-4, 1e-4, 3000)
    x = along + distance[:, None] * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    a, ab = ours.start, ours.end - ours.start
    u = np.clip(np.einsum("ijk,jk->ij", x[:, None] - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
    exact = np.linalg.norm(x[:, None] - (a + u[..., None] * ab), axis=2).min(axis=1) < 2e-3
    assert 100 < exact.sum() < len(x) - 100  # both sides of the distance
    np.testing.assert_array_equal(ours.near(x, 2e-3), exact)
    np.testing.assert_array_equal(theirs.near(x, 2e-3), exact)


def test_a_cell_without_a_material_or_a_process_draws_nothing_of_them(part_b):
    """The counter-based draws are off where their magnitudes are: an exact process, no effects."""
    mesh, x, face = part_b
    setup = CellSetup(load_cell("ideal"), load_process("cad"), MaterialEffects())
    live = LiveCell(setup, *_arrays(mesh), np.zeros(3), 3)
    assert live.as_made is None and live.edges is None
    scan = _scan(x, face, np.arange(len(x)))
    moved = live.perturb([[scan]], [np.asarray(mesh.face_normals, float)], [np.inf], np.zeros(40), np.eye(4), 5e-4, 1)
    np.testing.assert_array_equal(moved[0][0].points, scan.points)


def test_a_planes_draws_are_standard_normal_continuous_and_independent_two_cells_apart():
    """cell.kernels.lattice_normals: standard normal wherever the point lies in its cell, moved by about δ
    when the point moves by δ of a cell, and uncorrelated with the draws two cells away."""
    rng = np.random.default_rng(0)
    place = rng.uniform(-50, 50, (20000, 4))
    draws = lattice_normals(place, np.uint64(12345), 4)
    assert np.abs(draws.mean(axis=0)).max() < 0.05 and np.abs(draws.std(axis=0) - 1).max() < 0.03
    assert np.abs(np.corrcoef(draws.T) - np.eye(4)).max() < 0.05  # the four fields are independent
    moved = lattice_normals(place + 1e-9, np.uint64(12345), 4)
    assert np.abs(moved - draws).max() < 1e-6
    far = np.stack([lattice_normals(place[:1] + [2.0, 0, 0, 0], np.uint64(k), 1)[0] for k in range(1, 3001)])
    here = np.stack([lattice_normals(place[:1], np.uint64(k), 1)[0] for k in range(1, 3001)])
    assert abs(np.corrcoef(far[:, 0], here[:, 0])[0, 1]) < 0.08 and here.std() == pytest.approx(1.0, abs=0.05)
