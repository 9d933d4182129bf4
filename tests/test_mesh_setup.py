"""A mesh's set-up in time linear in it: loading, merging, the closed-solid check, the hull and the face planes
give trimesh's and numpy's answers exactly, found by hashing, counting and one pass over the faces."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from optipose.model import convex, grouping, machine
from optipose.model.convex import hull_arrays
from optipose.model.grouping import closed_and_wound, unique_rows
from optipose.model.mesh import load_mesh
from optipose.model.part import load_part
from optipose.scan import hull
from optipose.model.planes import edge_planes, face_planes, shared_planes

SHIPPED = ("part_a", "part_b", "part_c")


def test_unique_rows_are_trimeshs_in_order_of_first_occurrence():
    keys = np.random.default_rng(0).integers(-3, 3, size=(5000, 3))
    first, inverse = unique_rows(keys)
    want_first, want_inverse = trimesh.grouping.unique_rows(keys, keep_order=True)
    assert np.array_equal(first, want_first) and np.array_equal(inverse, want_inverse)
    assert np.array_equal(keys[first][inverse], keys)


def test_unique_rows_fall_back_to_sorting_when_two_rows_hash_alike(monkeypatch):
    import pandas as pd

    keys = np.random.default_rng(1).integers(0, 4, size=(400, 2))
    want = trimesh.grouping.unique_rows(keys, keep_order=True)
    monkeypatch.setattr(
        pd.util, "hash_array", lambda column: np.zeros(len(column), dtype=np.uint64)
    )  # every row collides
    first, inverse = unique_rows(keys)
    assert np.array_equal(first, want[0]) and np.array_equal(inverse, want[1])


def _fin() -> trimesh.Trimesh:
    """A box with a fin: one edge in three faces."""
    box = trimesh.creation.box()
    a, b = box.faces[0][:2]
    return trimesh.Trimesh(
        np.vstack([box.vertices, [[2.0, 2.0, 2.0]]]), np.vstack([box.faces, [[a, b, 8]]]), process=False
    )


def _flipped() -> trimesh.Trimesh:
    sphere = trimesh.creation.icosphere(2)
    faces = sphere.faces.copy()
    faces[0] = faces[0][::-1]
    return trimesh.Trimesh(sphere.vertices, faces, process=False)


@pytest.mark.parametrize("which", ["sphere", "box", "open", "flipped face", "fin", "two bodies", *SHIPPED])
def test_closed_and_wound_are_trimeshs(which):
    mesh = {
        "sphere": lambda: trimesh.creation.icosphere(3),
        "box": trimesh.creation.box,
        "open": lambda: trimesh.Trimesh(
            trimesh.creation.icosphere(2).vertices, trimesh.creation.icosphere(2).faces[1:]
        ),
        "flipped face": _flipped,
        "fin": _fin,
        "two bodies": lambda: trimesh.util.concatenate(
            [trimesh.creation.box(), trimesh.creation.box().apply_translation([3, 0, 0])]
        ),
    }.get(which, lambda: load_part(which).mesh)()
    fresh = trimesh.Trimesh(
        mesh.vertices.copy(), mesh.faces.copy(), process=False
    )  # trimesh's own answer, not a cached one
    assert closed_and_wound(mesh.faces, len(mesh.vertices)) == (fresh.is_watertight, fresh.is_winding_consistent)


def test_a_face_naming_a_vertex_twice_is_left_to_trimesh():
    assert closed_and_wound(np.array([[0, 1, 1], [0, 1, 2]]), 3) is None


@pytest.mark.parametrize("which", ["dense sphere", *SHIPPED])
def test_loading_is_trimeshs_load_and_merge(which, tmp_path):
    if which == "dense sphere":
        path = tmp_path / "sphere.stl"
        trimesh.creation.icosphere(subdivisions=5, radius=30.0).export(path)  # in mm, 20,480 faces
    else:
        path = next((Path(__file__).parents[1] / "parts" / which).glob("*.stl"))
    got = load_mesh(path)
    want = trimesh.load(path, force="mesh", process=False)
    want.process(validate=False)
    want.apply_scale(got.extents[0] / want.extents[0])
    assert np.array_equal(got.vertices, want.vertices) and np.array_equal(got.faces, want.faces)
    assert np.array_equal(got.face_normals, want.face_normals)
    assert got.is_watertight == want.is_watertight and got.is_winding_consistent == want.is_winding_consistent


def _supports(points: np.ndarray, directions: np.ndarray) -> np.ndarray:
    return (points @ directions.T).max(axis=0)


def test_a_dense_convex_mesh_is_its_own_hull(monkeypatch):
    monkeypatch.setattr(machine, "SHARED_FACES", 0)
    monkeypatch.setattr(machine, "per_machine", lambda kind, content, compute, names: compute())
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.03)
    monkeypatch.setattr(trimesh.convex, "convex_hull", lambda *a, **k: pytest.fail("qhull ran"))
    vertices, faces = hull_arrays(mesh)
    assert np.array_equal(vertices, mesh.vertices) and np.array_equal(faces, mesh.faces)


def test_a_dense_non_convex_mesh_gives_qhull_only_its_corners(monkeypatch):
    monkeypatch.setattr(machine, "SHARED_FACES", 0)
    monkeypatch.setattr(machine, "per_machine", lambda kind, content, compute, names: compute())
    base = load_part("part_b").mesh
    mesh = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(base.vertices, base.faces, max_edge=2e-3), process=False)
    mesh.merge_vertices()
    given = []
    qhull = trimesh.convex.convex_hull
    monkeypatch.setattr(
        trimesh.convex, "convex_hull", lambda points, **k: given.append(len(points)) or qhull(points, **k)
    )
    vertices, _ = hull_arrays(mesh)
    want = np.asarray(qhull(np.asarray(mesh.vertices), repair=False).vertices)
    assert given[0] < 0.2 * len(mesh.vertices)  # the flat patches' vertices are not given to qhull
    assert np.array_equal(vertices, want)


def _locally_convex(mesh) -> bool:
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    around = grouping.vertex_faces(faces, len(mesh.vertices))
    return convex._locally_convex(
        np.asarray(mesh.vertices, float), faces, np.ascontiguousarray(mesh.face_normals), *around, convex._TOL
    )


def test_a_dent_makes_a_mesh_not_convex():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.03)
    assert _locally_convex(sphere)
    dented = sphere.vertices.copy()
    dented[0] *= 0.98  # 0.6 mm in, past the facets' 0.24 mm sagitta: its neighbours stand in front of its faces
    assert not _locally_convex(trimesh.Trimesh(dented, sphere.faces, process=False))
    bulged = sphere.vertices.copy()
    bulged[0] *= 1.02  # 0.6 mm out: it stands in front of the faces beyond its ring
    assert not _locally_convex(trimesh.Trimesh(bulged, sphere.faces, process=False))


def test_supporting_faces_on_a_finer_cube_map_equal_the_definition(monkeypatch):
    monkeypatch.setattr(hull, "_PER_CELL", 1)  # 2,562 hull vertices: a map of 20 cells a side
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.03)
    bumped = mesh.vertices * (
        1 + 0.05 * np.sin(9 * mesh.vertices[:, :1] / 0.03) * np.sin(9 * mesh.vertices[:, 1:2] / 0.03)
    )  # not convex: some faces are off the hull
    mesh = trimesh.Trimesh(bumped, mesh.faces, process=False)
    _, normals, offsets, _, _ = shared_planes(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))
    got = hull.supporting_faces(mesh, normals, offsets)
    h = np.asarray(mesh.convex_hull.vertices)
    want = ((h @ normals.T - offsets).max(axis=0) <= 1e-9) & (np.linalg.norm(normals, axis=1) > 0.5)
    assert np.array_equal(got, want) and 0 < got.sum() < len(got)


@pytest.mark.parametrize("which", ["random", *SHIPPED])
def test_face_and_edge_planes_are_numpys_to_the_bit(which):
    if which == "random":
        rng = np.random.default_rng(2)
        vertices, faces = rng.normal(size=(300, 3)), rng.integers(0, 300, size=(1000, 3))
        faces[0] = [5, 5, 7]  # a degenerate face: a zero normal
    else:
        mesh = load_part(which).mesh
        vertices, faces = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    tris = vertices[faces]
    normal = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal /= np.where(length > 0, length, 1.0)
    got_n, got_c = face_planes(vertices, faces)
    assert np.array_equal(got_n, normal) and np.array_equal(got_c, np.einsum("ij,ij->i", normal, tris[:, 0]))
    edge_n = np.cross(normal[:, None, :], np.roll(tris, -1, axis=1) - tris)
    edge_n /= np.maximum(np.linalg.norm(edge_n, axis=2, keepdims=True), 1e-300)
    got_en, got_ec = edge_planes(tris, normal)
    assert np.array_equal(got_en, edge_n) and np.array_equal(got_ec, np.einsum("fkj,fkj->fk", edge_n, tris))


@pytest.mark.parametrize("which", ["sphere", *SHIPPED])
def test_inside_is_trimeshs_contains(which):
    from optipose.model.collision import contains

    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.03) if which == "sphere" else load_part(which).mesh
    rng = np.random.default_rng(3)
    points = mesh.bounds[0] + rng.uniform(-0.1, 1.1, size=(400, 3)) * mesh.extents
    want = mesh.contains(points)
    assert np.array_equal(contains(mesh, points), want) and 0 < want.sum() < len(want)


@pytest.mark.parametrize("which", ["sphere", "two bodies and a loose vertex", *SHIPPED])
def test_bodies_are_trimeshs_body_count(which):
    from optipose.model.grouping import bodies

    if which == "sphere":
        mesh = trimesh.creation.icosphere(2)
    elif which == "two bodies and a loose vertex":
        two = trimesh.util.concatenate([trimesh.creation.box(), trimesh.creation.box().apply_translation([3, 0, 0])])
        mesh = trimesh.Trimesh(np.vstack([two.vertices, [[9.0, 9.0, 9.0]]]), two.faces, process=False)
    else:
        mesh = load_part(which).mesh
    assert (
        bodies(mesh.faces, len(mesh.vertices)) == trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).body_count
    )


def test_the_hull_graph_is_every_edge_once_each_way():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    faces = np.asarray(mesh.faces, np.int64)
    indptr, neighbours = hull._neighbours(faces, *grouping.vertex_faces(faces, len(mesh.vertices)))
    got = {(v, int(w)) for v in range(len(mesh.vertices)) for w in neighbours[indptr[v] : indptr[v + 1]]}
    want = {(int(a), int(b)) for a, b in mesh.edges_unique} | {(int(b), int(a)) for a, b in mesh.edges_unique}
    assert got == want and all(
        np.all(np.diff(neighbours[indptr[v] : indptr[v + 1]]) > 0) for v in range(len(mesh.vertices))
    )
