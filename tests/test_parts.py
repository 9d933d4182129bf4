"""The parts library: meshes, part files, loading, hand layouts and the head collision check."""

from __future__ import annotations

import importlib.util
import itertools
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from optipose.model.collision import ConvexSet, _sat_gap, clearance, collides, heads_clearance
from optipose.errors import ConfigError, MeshError
from optipose.model.part import PARTS_DIR, Keepout, Part, list_parts, load_part
from optipose.model.motion import ScanMotion
from optipose.scan.scanner import Scanner
from optipose.model.sensor import load_sensor

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ["part_a", "part_b", "part_c"]


def _make_parts_module():
    spec = importlib.util.spec_from_file_location("make_parts", ROOT / "scripts" / "make_parts.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


mp = _make_parts_module()


@pytest.fixture(scope="module")
def parts() -> dict[str, Part]:
    return {name: load_part(name) for name in SHIPPED}


# --- meshes ------------------------------------------------------------------------------------------
def test_shipped_parts_are_listed():
    assert list_parts() == SHIPPED


@pytest.mark.parametrize("name", SHIPPED)
def test_mesh_is_one_watertight_body_of_moderate_size(parts, name):
    mesh = parts[name].mesh
    assert mesh.is_watertight
    assert mesh.body_count == 1
    assert mesh.volume > 0  # outward normals
    assert len(mesh.faces) < 20_000


@pytest.mark.parametrize("name", SHIPPED)
def test_bounding_box_matches_the_paper_dimensions(parts, name):
    L, W, H = (v * 1e-3 for v in mp.expected_size_mm(name))
    expected = np.array([[0.0, -W / 2, 0.0], [L, W / 2, H]])  # x from 0 to L, y centred, z from 0 up
    np.testing.assert_allclose(parts[name].mesh.bounds, expected, atol=1e-4)


@pytest.mark.parametrize("name", SHIPPED)
def test_volume_equals_the_polygonal_hand_formula(parts, name):
    # The STL holds float32 metres: ~6e-8 relative rounding per coordinate, so 1e-6 is ample.
    assert parts[name].mesh.volume * 1e9 == pytest.approx(mp.expected_volume_mm3(name), rel=1e-6)


def _ideal_volume_mm3(name: str) -> float:
    """Volumes with true circles (π), from the paper-level description, independent of make_parts' formulas."""
    if name == "part_a":
        section = 45 * 32 - 10 * 10 - (8**2 - np.pi * 8**2 / 4)
        return section * 54 - 2 * np.pi * 4**2 * 12
    if name == "part_b":
        return 60 * 41 * 17.6 - 36 * 24 * 4 - 24 * 12 * 5 - 4 * np.pi * 2.75**2 * 17.6
    base = 42.5 * (55 - 2 * 4) * 2
    lugs = 12 * 2 * (np.pi / 4 * (4**2 - 2**2) + (32.5 - 4) * 2)
    return base + lugs - np.pi * 4**2 * 2


@pytest.mark.parametrize("name", SHIPPED)
def test_volume_is_close_to_the_true_circular_shape(name):
    # Chords cut each circle's area by (θ²/6) relative, θ = 2π/96 or π/64: ≤ 7e-4 of the small curved
    # volumes, under 1e-4 of each part's volume.
    assert mp.expected_volume_mm3(name) == pytest.approx(_ideal_volume_mm3(name), rel=1e-4)


def test_generator_is_deterministic(tmp_path):
    for name in SHIPPED:
        mp.write_part(name, tmp_path)
        assert (tmp_path / name / f"{name}.stl").read_bytes() == (PARTS_DIR / name / f"{name}.stl").read_bytes()


# --- part files and hand layouts ---------------------------------------------------------------------
PAPER_B = {  # eqs. (1)-(3), 0.175 read as 0.0175
    "S1": [[0, 1, 0, 0.03], [0.7071, 0, 0.7071, -0.023], [0.7071, 0, -0.7071, 0.015], [0, 0, 0, 1]],
    "S2": [[0, 1, 0, 0.03], [1, 0, 0, 0], [0, 0, -1, 0.0175], [0, 0, 0, 1]],
    "S3": [[0, 1, 0, 0.03], [0.7071, 0, -0.7071, 0.014], [-0.7071, 0, -0.7071, 0.015], [0, 0, 0, 1]],
}


def test_part_b_hand_layout_is_the_papers(parts):
    layout = parts["part_b"].layouts["hand"]
    assert layout.names == ["S1", "S2", "S3"]
    for pose in layout.sensors:
        np.testing.assert_allclose(pose.T_O_S, PAPER_B[pose.name], atol=1e-4)


def test_part_settings(parts):
    b = parts["part_b"]
    assert (b.material, b.sensor) == ("black-pla", "keyence-lj-x8080")
    assert b.motion == ScanMotion(0.060, 0.0005)
    np.testing.assert_allclose(b.rotation_centre, [0.030, 0.0, 0.0088])
    assert parts["part_a"].material == "milled-aluminium-ra1.6"
    assert parts["part_c"].material == "smooth-aluminium-ra0.8"
    assert parts["part_c"].motion.length == pytest.approx(0.012)
    for part in parts.values():
        assert [k.name for k in part.keepouts] == ["flange"]
        assert part.keepouts[0].hi[2] <= part.mesh.bounds[0, 2]  # under the bottom face


@pytest.mark.parametrize("name", SHIPPED)
def test_hand_sensors_see_the_part_and_clear_it(parts, name):
    part = parts[name]
    scanner = Scanner(part.mesh, part.sensor, part.material)
    profiles = part.motion.n_profiles
    for pose in part.layouts["hand"].sensors:
        scan = scanner.scan(pose.T_O_S, part.motion, noise=False)
        assert len(scan) > 500 * profiles, f"{name} {pose.name}: {len(scan)} points"
        sample = scan.points[:: max(1, len(scan) // 2000)]
        assert _distance_to_surface(part.mesh, sample).max() < 1e-5  # exact hits, quantised to 1.6 µm
        assert not collides(part, None, pose.T_O_S), f"{name} {pose.name} hits {clearance(part, None, pose.T_O_S)}"


def _distance_to_surface(mesh, points: np.ndarray, tol: float = 1e-5) -> np.ndarray:
    """(n,) distance of each point to the nearest face plane among the faces whose bounding box (grown by
    ``tol``) holds the point; inf when no face is near. Enough to tell points on the surface from stray ones."""
    tri = mesh.triangles  # (f, 3, 3)
    lo, hi = tri.min(axis=1) - tol, tri.max(axis=1) + tol
    near = np.all((points[:, None, :] >= lo) & (points[:, None, :] <= hi), axis=2)  # (n, f)
    plane = np.abs(
        np.einsum("nk,fk->nf", points, mesh.face_normals) - np.einsum("fk,fk->f", tri[:, 0], mesh.face_normals)
    )
    return np.where(near, plane, np.inf).min(axis=1)


@pytest.mark.parametrize("name", ["part_a", "part_c"])
def test_designed_layouts_keep_heads_apart(parts, name):
    part = parts[name]
    for a, b in itertools.combinations(part.layouts["hand"].sensors, 2):
        assert heads_clearance(part.sensor, a.T_O_S, part.sensor, b.T_O_S) > 2e-3, (a.name, b.name)


# --- loading -----------------------------------------------------------------------------------------
def test_bare_stl_gets_the_defaults(tmp_path):
    stl = tmp_path / "bracket.stl"
    shutil.copy(PARTS_DIR / "part_b" / "part_b.stl", stl)
    part = load_part(stl)
    assert part.name == "bracket"
    assert (part.material, part.sensor) == ("milled-aluminium-ra1.6", "keyence-lj-x8080")
    assert part.motion.length == pytest.approx(0.060, abs=1e-6)  # the extent along x
    assert part.motion.step == pytest.approx(0.0005)
    np.testing.assert_allclose(part.rotation_centre, [0.030, 0.0, 0.0088], atol=1e-6)
    assert part.keepouts == [] and list(part.layouts) == ["conventional"]  # the baseline of a bare mesh
    assert part.source == stl


def test_millimetre_stl_is_scaled(tmp_path):
    box = trimesh.creation.box(extents=(40.0, 20.0, 10.0))
    box.export(tmp_path / "block.stl")
    part = load_part(tmp_path / "block.stl")  # diagonal 46 > 2: taken as mm
    np.testing.assert_allclose(part.size, [0.040, 0.020, 0.010], atol=1e-9)
    with pytest.raises(MeshError, match="wrong --units"):  # 46 m across: a forced wrong unit is caught
        load_part(tmp_path / "block.stl", units="m")


def test_part_file_beside_an_stl_is_used(tmp_path):
    shutil.copy(PARTS_DIR / "part_b" / "part_b.stl", tmp_path / "b.stl")
    (tmp_path / "b.toml").write_text('[part]\nmaterial = "black-pla"\nscan_length_mm = 20.0\n')
    part = load_part(tmp_path / "b.stl")
    assert part.material == "black-pla"
    assert part.motion.length == pytest.approx(0.020)


def test_unknown_part_name_lists_the_shipped_ones():
    with pytest.raises(ConfigError, match="part_a, part_b, part_c"):
        load_part("part_z")


def test_empty_stl_is_a_mesh_error(tmp_path):
    (tmp_path / "empty.stl").write_bytes(b"")
    with pytest.raises(MeshError, match="empty"):
        load_part(tmp_path / "empty.stl")


@pytest.mark.parametrize(
    "text, message",
    [
        ("[part\nmesh = 'x.stl'", "part file"),  # not TOML
        ("[part]\nmaterial = 'black-pla'\n", "needs mesh"),
        ("[part]\nmesh = 'part_b.stl'\ncolour = 'red'\n", "unknown key"),
        ("[part]\nmesh = 'part_b.stl'\nmaterial = 'unobtainium'\n", "unknown material"),
        ("[part]\nmesh = 'part_b.stl'\nrotation_centre_mm = [1, 2]\n", "3 numbers"),
        (
            "[part]\nmesh = 'part_b.stl'\n[[keepout]]\nname = 'f'\nmin_mm = [0, 0, 0]\nmax_mm = [1, -1, 1]\n",
            "min < max",
        ),
        (
            "[part]\nmesh = 'part_b.stl'\n[layouts.hand]\n[[layouts.hand.sensors]]\nname = 'S1'\n"
            "T_O_S = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]]\n",
            "reflection",
        ),
    ],
)
def test_broken_part_files_are_config_errors(tmp_path, text, message):
    shutil.copy(PARTS_DIR / "part_b" / "part_b.stl", tmp_path / "part_b.stl")
    (tmp_path / "part.toml").write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_part(tmp_path / "part.toml")


def test_part_file_naming_a_missing_mesh_is_a_mesh_error(tmp_path):
    (tmp_path / "part.toml").write_text("[part]\nmesh = 'gone.stl'\n")
    with pytest.raises(MeshError, match="not found"):
        load_part(tmp_path / "part.toml")


# --- collision ---------------------------------------------------------------------------------------
LOOK_DOWN = np.array([[0.0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]])  # z_S = -z_O, y_S = x_O


def _block_part(length: float = 0.060, keepouts=()) -> Part:
    """A 60 x 40 x 20 mm block, x 0..60 mm, y ±20 mm, z 0..20 mm, scanned over ``length``."""
    mesh = trimesh.creation.box(bounds=[[0.0, -0.020, 0.0], [0.060, 0.020, 0.020]])
    return Part(
        "block",
        mesh,
        "white-diffuse",
        "keyence-lj-x8080",
        ScanMotion(length, 0.0005),
        np.array([0.03, 0.0, 0.01]),
        list(keepouts),
    )


def _looking_down_at(x: float, y: float, z: float) -> np.ndarray:
    T = LOOK_DOWN.copy()
    T[:3, 3] = (x, y, z)
    return T


def test_head_far_above_clears_by_the_exact_gap():
    part = _block_part()
    T = _looking_down_at(0.030, 0.0, 0.025)  # R 5 mm above the top: the window 73 mm above R
    gap = clearance(part, None, T)
    assert gap.obstacle == "part"
    assert gap.distance == pytest.approx(0.025 + 0.073 - 0.020, abs=1e-12)  # window face to top face
    assert not collides(part, None, T)


def test_head_inside_the_part_collides():
    part = _block_part()
    T = _looking_down_at(0.030, 0.0, -0.063)  # window at z = 10 mm: the head box's bottom 10 mm inside
    gap = clearance(part, None, T)
    assert gap.distance == pytest.approx(-0.010, abs=1e-12)
    assert collides(part, None, T)


def test_the_part_is_swept_along_the_scan():
    # A head 1 mm past the part's +x end, below the top: clear of the part at rest, but the part travels
    # ±30 mm along x during a 60 mm scan and runs into it.
    T = _looking_down_at(0.061 + 0.045, 0.0, -0.063)  # head box x (= x_S) 61..151 mm, z 10..80 mm
    T[:3, :3] = [[1, 0, 0], [0, -1, 0], [0, 0, -1]]  # x_S = x_O so the 90 mm side lies along x
    assert clearance(_block_part(length=0.001), None, T).distance == pytest.approx(0.001 - 0.0005 / 2, abs=1e-9)
    # Swept over 60 mm the overlap is 28.75 mm along x but only 10 mm along z: the depth is the smaller.
    assert clearance(_block_part(length=0.060), None, T).distance == pytest.approx(-0.010, abs=1e-12)


def test_a_head_only_in_a_keepout_collides():
    flange = Keepout("flange", np.array([-0.010, -0.040, -0.300]), np.array([0.070, 0.040, 0.0]))
    part = _block_part(keepouts=[flange])
    T = _looking_down_at(0.030, 0.0, -0.200)  # head box z -127..-57 mm: far below the part, in the flange
    gap = clearance(part, None, T)
    assert gap.obstacle == "flange" and gap.distance < -0.05
    assert collides(part, None, T)
    assert clearance(_block_part(), None, T).distance == pytest.approx(0.057)  # no keep-out: clear


def test_sat_agrees_with_a_linear_program_on_random_poses(parts):
    """Cross-check against an independent test: the head box and the hull intersect iff the LP
    'a convex combination of hull vertices equals a point of the box' is feasible."""
    from scipy.optimize import linprog
    from scipy.spatial.transform import Rotation

    hull = ConvexSet.hull_of(np.asarray(parts["part_c"].mesh.convex_hull.vertices))
    half = np.array(load_sensor("keyence-lj-x8080").head_box) / 2
    rng = np.random.default_rng(7)
    for _ in range(60):
        R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
        centre = rng.uniform([-0.06, -0.09, -0.06], [0.10, 0.09, 0.10])
        nv = len(hull.vertices)
        A = np.zeros((4, nv + 3))
        A[:3, :nv], A[:3, nv:], A[3, :nv] = hull.vertices.T, -R, 1.0
        lp = linprog(
            np.zeros(nv + 3),
            A_eq=A,
            b_eq=np.r_[centre, 1.0],
            bounds=[(0, None)] * nv + [(-h, h) for h in half],
            method="highs",
        )
        assert (lp.status == 0) == (_sat_gap(hull, centre, R, half) < 0)


# --- commands ----------------------------------------------------------------------------------------
def test_show_writes_a_png_and_counts_match_a_scan(tmp_path, parts):
    from optipose.cli.parts import counts_table, show_command

    out = show_command("part_c", tmp_path / "c.png", "auto")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = counts_table(["part_c"])
    part = parts["part_c"]
    scanner = Scanner(part.mesh, part.sensor, part.material)
    expected = [len(scanner.scan(p.T_O_S, part.motion)) for p in part.layouts["hand"].sensors]
    assert [r["points"] for r in rows] == expected


@pytest.mark.parametrize(
    "name, size_mm", [("bushing", (50.0, 50.0, 32.0)), ("angle", (60.0, 50.0, 35.0)), ("housing", (70.0, 45.0, 24.0))]
)
def test_the_study_parts_are_built_as_their_files_say(tmp_path, name, size_mm):
    """The verdict study's parts (scripts/make_study_parts.py): rebuilt byte for byte as shipped in studies/parts,
    one watertight body of the stated size, a process and a material the cell knows, the conventional baseline."""
    spec = importlib.util.spec_from_file_location("make_study_parts", ROOT / "scripts" / "make_study_parts.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main([str(tmp_path)])
    shipped = ROOT / "studies" / "parts" / name
    for file in (f"{name}.stl", "part.toml"):
        assert (tmp_path / name / file).read_bytes() == (shipped / file).read_bytes()
    part = load_part(shipped / "part.toml")
    assert part.mesh.is_watertight and part.mesh.body_count == 1
    assert np.allclose(part.mesh.extents * 1e3, size_mm, atol=1e-6)
    assert set(part.layouts) == {"conventional"} and part.process in ("milled", "fdm", "bent-sheet")
