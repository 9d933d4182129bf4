"""Bad input as a new user gives it, through the command line: one line `optipose: error: …`, exit 2, no
traceback (what tests/test_cli_errors.py does not already cover)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from cli_checks import PAPER_S2, assert_one_line_error, run

SHORT = '[protocol]\nsequences = ["R"]\nstep_deg = 4.0\n'  # two scans: an evaluation in seconds


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("stress_cli")
    block = trimesh.creation.box((0.06, 0.041, 0.0176))
    block.apply_translation([0.03, 0.0, 0.0088])  # part B's box, in metres
    data = block.export(file_type="stl")
    (d / "truncated.stl").write_bytes(data[: len(data) // 2])
    (d / "binary_garbage.stl").write_bytes(b"\0" * 80 + np.random.default_rng(0).bytes(5000))
    v = block.vertices.copy()
    v[3, 2] = np.inf
    with np.errstate(invalid="ignore"):  # the STL's face normals of the inf vertex
        (d / "inf.stl").write_bytes(trimesh.Trimesh(v, block.faces, process=False).export(file_type="stl"))
    line = np.array([[0.0, 0, 0], [0.01, 0, 0], [0.02, 0, 0]])  # every triangle collapsed onto a line
    (d / "degenerate.stl").write_bytes(
        trimesh.Trimesh(line, [[0, 1, 2], [0, 2, 1]], process=False).export(file_type="stl")
    )
    other = block.copy()
    other.apply_translation([0.0, 0.1, 0.0])
    trimesh.util.concatenate([block, other]).export(d / "two_bodies.stl")
    inches = block.copy()
    inches.apply_scale(1 / 0.0254)
    inches.export(d / "inches.stl")
    flat = trimesh.Trimesh(
        [[0, -0.02, 0.0176], [0.06, -0.02, 0.0176], [0.06, 0.02, 0.0176], [0, 0.02, 0.0176]], [[0, 1, 2], [0, 2, 3]]
    )
    flat.export(d / "flat.stl")
    (d / "unknown_key.toml").write_text('[protocol]\nsequences = ["R"]\nstep_degrees = 1\n')
    (d / "wrong_type.toml").write_text('[registration]\nmax_iterations = "many"\n')
    (d / "wrong_type_list.toml").write_text("[registration]\nvoxel_size_mm = [0.5]\n")
    (d / "short.toml").write_text(SHORT)
    # S2 moved 68 mm down: its window (73 mm behind R) 5 mm above B's bottom, in the material
    (d / "inside.toml").write_text(
        '[[sensors]]\nname = "S1"\nT_O_S = [[0,1,0,0.03],[1,0,0,0],[0,0,-1,-0.068],[0,0,0,1]]\n'
    )
    (d / "a_file").write_text("not a folder\n")
    return d


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["scan", "{d}/truncated.stl", "-p", PAPER_S2], "no triangles"),
        (["scan", "{d}/binary_garbage.stl", "-p", PAPER_S2], "no triangles"),
        (["scan", "{d}/inf.stl", "-p", PAPER_S2], "NaN or infinite"),
        (["scan", "{d}/degenerate.stl", "-p", PAPER_S2], "zero surface area"),
        (["scan", "{d}/inches.stl", "-p", PAPER_S2], "mm or inches"),
        (["evaluate", "part_b", "--objective", "{d}/unknown_key.toml", "--no-report"], "unknown key(s) step_degrees"),
        (
            ["evaluate", "part_b", "--objective", "{d}/wrong_type.toml", "--no-report"],
            "max_iterations must be a number",
        ),
        (
            ["evaluate", "part_b", "--objective", "{d}/wrong_type_list.toml", "--no-report"],
            "voxel_size_mm must be a number",
        ),
        (["scan", "part_b", "--layout", "{d}/inside.toml"], "sensor S1: its window is inside the part"),
        (["evaluate", "part_b", "--layout", "{d}/inside.toml", "--no-report"], "inside the part"),
        (["robustness", "part_b", "--layout", "{d}/inside.toml", "--no-report"], "inside the part"),
        (["scan", "part_b", "-p", PAPER_S2, "--out", "{d}/a_file/cloud.npy"], "a_file"),
        (
            ["evaluate", "part_b", "--objective", "{d}/short.toml", "--no-report", "--out", "{d}/a_file/result"],
            "a_file",
        ),
    ],
)
def test_bad_input_is_one_line_and_exit_2(files, args, fragment):
    assert_one_line_error(run(*[a.format(d=files) for a in args]), fragment)


def test_an_output_folder_that_cannot_be_written(files):
    # /sys is read-only here even for root (whom a chmod-ed folder would not stop); elsewhere it is refused
    # all the same: either way one line, after the evaluation, not a traceback
    result = run(
        "evaluate", "part_b", "--objective", str(files / "short.toml"), "--no-report", "--out", "/sys/optipose-result"
    )
    assert_one_line_error(result, "/sys/optipose-result")


def test_a_part_in_inches_is_read_with_its_units(files, tmp_path):
    result = run("scan", str(files / "inches.stl"), "--units", "in", "-p", PAPER_S2, "--out", str(tmp_path / "c.npy"))
    assert result.returncode == 0, result.stderr
    assert np.median(np.load(tmp_path / "c.npy")[:, 2]) == pytest.approx(0.0176, abs=1e-5)  # the top, in metres


def test_a_mesh_of_two_bodies_is_scanned_with_a_warning(files, tmp_path):
    # legal (a part and its fixture move as one) but often an assembly exported by mistake: said, not refused
    result = run("scan", str(files / "two_bodies.stl"), "-p", PAPER_S2, "--out", str(tmp_path / "c.npy"))
    assert result.returncode == 0, result.stderr
    assert "2 separate bodies" in result.stderr and "Traceback" not in result.stderr
    assert len(np.load(tmp_path / "c.npy")) > 100_000


def test_a_flat_mesh_of_zero_thickness_scans(files, tmp_path):
    # its convex hull is flat: loading it (the conventional placement's clearances) crashed before
    result = run("scan", str(files / "flat.stl"), "--units", "m", "--out", str(tmp_path / "c.npy"))
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert np.allclose(np.load(tmp_path / "c.npy")[:, 2], 0.0176, atol=2e-5)
