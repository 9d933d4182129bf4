"""The same surface in other triangles gives the same closest points and normals (docs/method.md, "The evaluator")."""

import numpy as np
import trimesh

from meshes import centroid_split
from optipose.registration.reference import SurfaceReference


def test_a_point_off_an_edge_gets_the_direction_to_the_edge_whatever_the_triangles():
    """Off the edge x = y = 0 of a 40 × 30 × 20 mm box, the closest point is on the edge and the normal
    is the direction from it to the point, on the box's 12 triangles and on its split and subdivided ones
    (before, the normal was that of whichever tied face had the lowest id)."""
    box = trimesh.creation.box([0.04, 0.03, 0.02])
    box.apply_translation([0.02, 0.015, 0.01])
    rng = np.random.default_rng(3)
    z = rng.uniform(0.002, 0.018, 50)
    angle = rng.uniform(np.pi, 1.5 * np.pi, 50)  # in the quadrant outside both faces that meet there
    r = rng.uniform(1e-5, 5e-4, 50)
    points = np.stack([r * np.cos(angle), r * np.sin(angle), z], axis=1)
    expected_q = np.stack([np.zeros(50), np.zeros(50), z], axis=1)
    expected_n = np.stack([np.cos(angle), np.sin(angle), np.zeros(50)], axis=1)
    for mesh in (box, centroid_split(box), box.subdivide().subdivide()):
        reference = SurfaceReference(mesh.vertices, mesh.faces)
        for hints in (None, reference.nearest(points + 1e-4)[2]):
            q, n, _ = reference.nearest(points, hints)
            np.testing.assert_allclose(q, expected_q, rtol=0, atol=1e-15)
            np.testing.assert_allclose(n, expected_n, rtol=0, atol=1e-9)


def test_far_from_the_surface_the_normal_off_an_edge_is_the_direction_to_it_too():
    """Farther than the grid reaches (Open3D's answer), a point off a corner gets the direction to it."""
    box = trimesh.creation.box([0.04, 0.03, 0.02])
    reference = SurfaceReference(box.vertices, box.faces)
    corner = np.array([0.02, 0.015, 0.01])
    points = corner + np.array([[0.003, 0.004, 0.0], [0.002, 0.002, 0.001]])
    q, n, _ = reference.nearest(points)
    expected = (points - corner * np.array([[1, 1, 1], [1, 1, 1]])) / np.linalg.norm(points - corner, axis=1)[:, None]
    np.testing.assert_allclose(q, np.broadcast_to(corner, (2, 3)), rtol=0, atol=1e-8)  # float32 BVH
    np.testing.assert_allclose(n, expected, rtol=0, atol=1e-5)


def test_a_reference_mapped_from_its_files_answers_as_the_one_built():
    """save_reference / load_reference: the same closest points, normals and faces, from read-only maps."""
    import os

    from optipose.evaluate import shared
    from optipose.model.part import load_part
    from optipose.registration.reference import load_reference

    mesh = load_part("part_b").mesh
    built = SurfaceReference(mesh.vertices, mesh.faces)
    key, folder = shared.acquire(mesh.vertices, mesh.faces)
    again, same = shared.acquire(mesh.vertices, mesh.faces)  # a second evaluator of the mesh: the same folder
    assert (again, same) == (key, folder)
    mapped = load_reference(folder)
    assert not mapped._tri.flags.writeable
    assert not shared.surface(mesh.vertices, mesh.faces)._tri.flags.writeable  # held here: the surrogate maps it too
    points = trimesh.sample.sample_surface(mesh, 500, seed=1)[0] + np.random.default_rng(1).normal(size=(500, 3)) * 4e-4
    for a, b in zip(built.nearest(points), mapped.nearest(points)):
        np.testing.assert_array_equal(a, b)
    shared.release(key)
    assert os.path.isdir(folder)  # one user left
    shared.release(key)
    assert not os.path.exists(folder)
    assert shared.surface(mesh.vertices, mesh.faces)._tri.flags.writeable  # held by no one: built


def test_the_grid_lists_each_face_a_few_times_whatever_the_density():
    """Part B at 2 mm edges (the grid's cells are 0.5 mm): a face is listed only in the cells it crosses."""
    from optipose.model.part import load_part

    mesh = load_part("part_b").mesh
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=2e-3)
    reference = SurfaceReference(v, f)
    assert len(reference._grid_faces) < 10 * len(f)
    assert reference._grid_faces.dtype == np.int32 and reference._adjacent.dtype == np.int32
