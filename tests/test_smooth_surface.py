"""The surface a CAD mesh stands for: smooth normals, and the motions a cloud on it cannot observe,
whatever the tessellation (a sphere's facets observe no rotation; a part's edges stay edges)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from optipose.evaluate.statistics import unobservable_axes
from optipose.registration import get_backend
from optipose.registration.config import RegistrationConfig
from optipose.registration.preprocess import information_matrix
from optipose.registration.reference import SurfaceReference
from optipose.registration.smooth import smooth_normals

R = 0.025


def _on_sphere(n: int, seed: int = 0, cap_deg: float = 40.0) -> np.ndarray:
    """Points on a cap of the true sphere of radius R (about +z), as a sensor would see them."""
    rng = np.random.default_rng(seed)
    theta = np.arccos(rng.uniform(np.cos(np.deg2rad(cap_deg)), 1.0, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    return R * np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def test_a_spheres_smooth_normals_are_ten_times_closer_to_radial_than_its_facets():
    errors = []
    for sub in (3, 5):
        mesh = trimesh.creation.icosphere(subdivisions=sub, radius=R)
        ref = SurfaceReference(mesh.vertices, mesh.faces)
        q, n, ids = ref.nearest(_on_sphere(4000))
        radial = q / np.linalg.norm(q, axis=1)[:, None]
        smooth = np.degrees(
            np.arccos(np.clip((smooth_normals(q, ids, ref._tri, ref._corners) * radial).sum(axis=1), -1, 1))
        ).max()
        faceted = np.degrees(np.arccos(np.clip((n * radial).sum(axis=1), -1, 1))).max()
        assert smooth < 0.1 * faceted  # the information a facet's turn adds goes as its square: 100x less
        errors.append(smooth)
    assert errors[1] < errors[0] / 3  # four times finer edges


def test_the_one_pass_information_is_the_information_of_the_smooth_normals():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=R)
    ref = SurfaceReference(mesh.vertices, mesh.faces)
    p = _on_sphere(2000) * 1.0001
    p[:50] *= 1.5  # out of reach: left out of both
    q, _, ids = ref.nearest(p)
    H, scale = ref.smooth_information(p, q, ids, (5e-3) ** 2)
    near = np.linalg.norm(p - q, axis=1) <= 5e-3
    np.testing.assert_allclose(
        H,
        information_matrix(p[near], smooth_normals(q[near], ids[near], ref._tri, ref._corners)),
        rtol=1e-9,
        atol=1e-15,
    )
    assert scale == pytest.approx(np.sqrt(((p[near] - p[near].mean(axis=0)) ** 2).sum(axis=1).mean()))


def test_a_boxs_smooth_normals_are_its_faces_normals():
    box = trimesh.creation.box([0.04, 0.03, 0.02])
    ref = SurfaceReference(box.vertices, box.faces)
    rng = np.random.default_rng(2)
    q, n, ids = ref.nearest(rng.uniform(-0.03, 0.03, (3000, 3)))
    # corners and edges are creases: each face keeps its own normal up to float32 storage
    inside = np.ones(len(q), bool)
    np.testing.assert_allclose(
        smooth_normals(q[inside], ids[inside], ref._tri, ref._corners), ref.normals[ids[inside]], atol=1e-7
    )


def test_the_rotations_of_a_sphere_are_unobservable_at_every_tessellation():
    for sub in (4, 6):  # 5 k and 82 k faces: the facets turn by 2.4 and 0.6 degrees
        mesh = trimesh.creation.icosphere(subdivisions=sub, radius=R)
        ref = SurfaceReference(mesh.vertices, mesh.faces)
        turned = _on_sphere(3000, seed=sub) @ Rotation.from_euler("xyz", [1.0, -0.5, 0.7], degrees=True).as_matrix().T
        reg = get_backend("fast").register(turned + [2e-4, -1e-4, 1e-4], ref, RegistrationConfig())
        assert reg.ok
        assert unobservable_axes(reg.information, R * 0.5).tolist()[:3] == [True, True, True]
        if sub == 4:  # 4·10⁻⁷ of the largest: unobservable, but near enough the tolerance that the ICP still steps
            continue
        assert reg.iterations <= 4  # 6·10⁻⁹: no wandering along the facets
        # what it can see, it finds: the centre (the translation, the rotation being none), to the gap between
        # the true sphere and the inscribed facets (their sagitta, edge² / 8R, of a mean edge; the faces vary)
        sagitta = mesh.edges_unique_length.mean() ** 2 / (8 * R)
        assert np.linalg.norm(reg.T_target_source[:3, 3] + [2e-4, -1e-4, 1e-4]) < 1.5 * sagitta
        # and it takes no step along the rotation it cannot see
        assert np.allclose(reg.T_target_source[:3, :3], np.eye(3), atol=1e-9)


def test_a_cylinder_observes_two_rotations_and_not_the_one_about_its_axis():
    mesh = trimesh.creation.cylinder(radius=R, height=0.08, sections=96)
    ref = SurfaceReference(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(4)
    phi, z = rng.uniform(-1.2, 1.2, 3000), rng.uniform(-0.03, 0.03, 3000)
    cloud = np.column_stack([R * np.cos(phi), R * np.sin(phi), z])  # the side seen from +x, away from the caps
    turn = Rotation.from_euler("xyz", [0.4, -0.3, 0.5], degrees=True).as_matrix()
    reg = get_backend("fast").register(cloud @ turn.T, ref, RegistrationConfig())
    assert reg.ok
    blind = unobservable_axes(reg.information, float(np.sqrt(((cloud - cloud.mean(0)) ** 2).sum(1).mean())))
    assert blind[:3].tolist() == [False, False, True]
    recovered = Rotation.from_matrix(reg.T_target_source[:3, :3] @ turn).as_euler("xyz", degrees=True)
    assert np.abs(recovered[:2]).max() < 1e-3  # roll and pitch come back; yaw is the cylinder's own


def test_the_rotation_test_leaves_the_translation_free():
    """A patch of a sphere with radial normals: about its centroid each rotation is observable with the
    translation held, and none with it free (a rotation about the centre is that rotation plus a shift)."""
    p = _on_sphere(2000, cap_deg=25.0)
    H = information_matrix(p, p / R)
    blind = unobservable_axes(H, 0.01)
    assert blind[:3].all()
    D = np.diag([1 / 0.01] * 3 + [1.0] * 3)
    w = np.linalg.eigvalsh((D @ H @ D)[:3, :3])
    assert w[1] > 1e-3 * w[-1]  # the rotation block alone: the two tilts of the patch about its centroid observable


@pytest.mark.parametrize("backend", ["fast", "plain"])
def test_a_block_registers_as_before_the_smooth_surface(backend):
    """A part of flat faces has no smooth-surface null: the same pose, bit for bit, as without the test."""
    block = trimesh.creation.box([0.04, 0.03, 0.02])
    ref = SurfaceReference(block.vertices, block.faces)
    cloud, _ = trimesh.sample.sample_surface(block, 3000, seed=5)
    turned = cloud @ Rotation.from_euler("xyz", [0.7, -0.4, 0.3], degrees=True).as_matrix().T
    on = get_backend(backend).register(turned, ref, RegistrationConfig())
    off = get_backend(backend).register(turned, ref, RegistrationConfig(null_tolerance=0.0))
    np.testing.assert_array_equal(on.T_target_source, off.T_target_source)
    np.testing.assert_array_equal(on.information, off.information)
