"""The same surface in other triangles gives the same closest points and normals (docs/method.md, "The evaluator")."""

import numpy as np
import trimesh

from meshes import centroid_split, distance_to_every_face
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

    from optipose.parallel import shared
    from optipose.model.part import load_part
    from optipose.registration.reference import load_reference

    mesh = load_part("part_b").mesh
    built = SurfaceReference(mesh.vertices, mesh.faces)
    key, folder = shared.acquire(mesh.vertices, mesh.faces)
    again, same = shared.acquire(mesh.vertices, mesh.faces)  # a second evaluator of the mesh: the same folder
    assert (again, same) == (key, folder)
    assert os.path.basename(folder).startswith(
        f"{shared.PREFIX}{shared._owner(os.getpid())}-"
    )  # named by its process, for sweep()
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


def test_a_killed_process_reference_folder_is_swept_and_the_others_are_left(tmp_path):
    """What a process killed before its exit left (its pid no longer runs) is removed; a live process's folder,
    one of another pid namespace (a container sharing the folder), an older version's (no pid in its name) and
    anything else are not."""
    import os
    import subprocess
    import sys

    from optipose.parallel import shared

    gone = int(
        subprocess.run(
            [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True, check=True
        ).stdout
    )
    dead = tmp_path / f"{shared.PREFIX}{shared._owner(gone)}-ab12"
    elsewhere = f"{shared._namespace() + 1}.{gone}"  # the same pid in another namespace: not ours to judge
    kept = [
        tmp_path / f"{shared.PREFIX}{shared._owner(os.getpid())}-cd34",
        tmp_path / f"{shared.PREFIX}{elsewhere}-ef56",
        tmp_path / f"{shared.PREFIX}gh56",
        tmp_path / f"{shared.PREFIX}ij-78",
        tmp_path / "other-1-2",
    ]
    for folder in [dead, *kept]:
        folder.mkdir()
        (folder / "tri.npy").write_bytes(b"x")
    assert shared.sweep(str(tmp_path)) == [str(dead)]
    assert not dead.exists() and all(folder.is_dir() for folder in kept)
    assert shared.sweep(str(tmp_path)) == []


def test_the_grid_lists_each_face_a_few_times_whatever_the_density():
    """Part B at 2 mm edges (the grid's cells are 0.5 mm): a face is listed only in the cells it crosses."""
    from optipose.model.part import load_part

    mesh = load_part("part_b").mesh
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=2e-3)
    reference = SurfaceReference(v, f)
    assert len(reference._grid_faces) < 10 * len(f)
    assert reference._grid_faces.dtype == np.int32 and reference._adjacent.dtype == np.int32


MM = 1e-3


def _strip(xz_mm) -> tuple[np.ndarray, np.ndarray]:
    """An open strip: the profile ``xz_mm`` (k, 2) extruded along y over ±5 mm, each quad two triangles."""
    k = len(xz_mm)
    vertices = np.array([[x, y, z] for y in (-5.0, 5.0) for x, z in xz_mm]) * MM
    faces = [f for i in range(k - 1) for f in ([i, i + 1, k + i + 1], [i, k + i + 1, k + i])]
    return vertices, np.array(faces)


def _assert_exact(vertices, faces, points, hints) -> None:
    reference = SurfaceReference(vertices, faces)
    truth = np.array([distance_to_every_face(vertices[faces], p).min() for p in points])
    for guess in (None, np.asarray(hints, dtype=np.int64)):
        q = reference.nearest(points, guess)[0]
        np.testing.assert_allclose(np.linalg.norm(points - q, axis=1), truth, rtol=0, atol=1e-12)


def test_a_point_beside_a_groove_at_the_parts_edge_finds_the_wall_beyond_it():
    """A top face ends at an edge that turns away (a groove 0.1 mm wide, 1 mm deep), and the far side of the
    groove rises 1 mm above the top: a point 0.2 mm above the top, 0.05 mm from its edge, is 0.15 mm from the
    wall, nearer than its projection on the top it was guessed on. The face across the edge turns away from it,
    but the edge lies within the point's distance: the faces beyond must be searched."""
    vertices, faces = _strip([(-5, 0), (0, 0), (0, -1), (0.1, -1), (0.1, 1), (5, 1)])
    point = np.array([[-0.05, 0.0, 0.2]]) * MM
    _assert_exact(vertices, faces, point, [0])
    assert np.isclose(
        np.linalg.norm(point - SurfaceReference(vertices, faces).nearest(point, np.array([0]))[0]), 0.15 * MM
    )


def test_a_face_in_the_plane_to_rounding_does_not_hide_the_wall_behind_it():
    """At a top face's edge, a sliver (zero area, its normal rounding) or a face of the same plane wound the other
    way lies between the top and a wall rising 1 mm: neither turns away from a point 0.2 mm above the top near
    that edge, whatever rotation puts the rounding on either side; the wall 0.05-0.06 mm away answers."""
    rng = np.random.default_rng(1)
    sliver_v = (
        np.array([[-5, -5, 0], [0, -5, 0], [0, 5, 0], [-5, 5, 0], [0, 0, 0], [0, -5, 1], [0, 0, 1], [0, 5, 1]]) * MM
    )
    sliver_f = np.array([[0, 1, 2], [0, 2, 3], [2, 1, 4], [1, 5, 6], [1, 6, 4], [4, 6, 7], [4, 7, 2]])
    flip_v = np.array([[x, y, 0] for x in (-5, -0.01, 0) for y in (-5, 5)] + [[0, -5, 1], [0, 5, 1]]) * MM
    flip_f = np.array([[0, 2, 3], [0, 3, 1], [2, 3, 4], [3, 5, 4], [4, 6, 7], [4, 7, 5]])
    for vertices, faces, point in ((sliver_v, sliver_f, [-0.05, 1.0, 0.2]), (flip_v, flip_f, [-0.06, 0.3, 0.2])):
        for _ in range(20):
            rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
            shift = rng.normal(size=3) * 0.05
            _assert_exact(vertices @ rotation.T + shift, faces, (np.array(point) * MM @ rotation.T + shift)[None], [0])


def test_a_point_over_an_edge_inside_a_plane_gets_one_answer_whatever_its_guess():
    """A 10 mm box split twice at its centroids and turned: points over edges between two faces of one plane
    (0.2-0.8 along the edge, up to 0.2 mm off the plane) get the same face, point and normal with either face
    as the guess as without one."""
    rng = np.random.default_rng(7)
    box = trimesh.creation.box((10 * MM, 10 * MM, 10 * MM))
    mesh = centroid_split(centroid_split(box))
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    mesh = trimesh.Trimesh(mesh.vertices @ rotation.T + 0.03, mesh.faces, process=False)
    reference = SurfaceReference(mesh.vertices, mesh.faces)
    adjacent, plane = reference.arrays()["adjacent"], reference.arrays()["plane_id"]
    points, own, across = [], [], []
    for f in rng.choice(len(mesh.faces), 200):
        for k in range(3):
            g = adjacent[f, k]
            if g >= 0 and plane[g] == plane[f]:
                a, b = mesh.vertices[mesh.faces[f, k]], mesh.vertices[mesh.faces[f, (k + 1) % 3]]
                points.append(a + rng.uniform(0.2, 0.8) * (b - a) + mesh.face_normals[f] * rng.uniform(-0.2, 0.2) * MM)
                own.append(f)
                across.append(g)
    points = np.array(points)
    q0, n0, ids0 = reference.nearest(points)
    for guess in (own, across):
        q, n, ids = reference.nearest(points, np.array(guess, dtype=np.int64))
        np.testing.assert_array_equal(ids, ids0)
        np.testing.assert_array_equal(q, q0)
        np.testing.assert_array_equal(n, n0)
