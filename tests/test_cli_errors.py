"""Bad input gets one line on stderr and a non-zero exit, never a traceback."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from cli_checks import PAPER_S2, assert_one_line_error, run


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("bad")
    (d / "empty.stl").write_bytes(b"")
    (d / "garbage.stl").write_text("this is not an stl file\n")
    box = trimesh.creation.box((0.01, 0.01, 0.01))
    v = box.vertices.copy()
    v[0, 0] = np.nan
    (d / "nan.stl").write_bytes(trimesh.Trimesh(v, box.faces, process=False).export(file_type="stl"))
    (d / "layout.toml").write_text('[[sensors]]\nname = "S1"\nT_O_S = [[1, 0, 0], [0, 1, 0]]\n')
    return d


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["scan", "{d}/missing.stl"], "not found"),
        (["scan", "{d}/empty.stl"], "empty"),
        (["scan", "{d}/garbage.stl"], "no triangles"),
        (["scan", "{d}/nan.stl"], "NaN"),
        (["scan", "part_b", "--material", "unobtainium"], "unknown material"),
        (["scan", "part_b", "--sensor", "lj-x9999"], "unknown sensor"),
        (["scan", "part_b", "-p", "1,0,0,0, 0,1,0,0, 0,0,-1,0.1, 0,0,0,1"], "reflection"),
        (["scan", "part_b", "-p", "1,2,3"], "16 numbers"),
        (["scan", "part_b", "--layout", "{d}/layout.toml"], "4x4"),
        (["scan", "part_b", "--units", "furlong"], "units"),
        (["scan", "no_such_part"], "unknown part"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(bad_files, args, fragment):
    assert_one_line_error(run(*[a.format(d=bad_files) for a in args]), fragment)


def test_wrong_units_are_caught(tmp_path):
    # a 60 mm part declared in metres is 60 m across: refused as a units mistake
    trimesh.creation.box((60.0, 41.0, 17.6)).export(tmp_path / "big.stl")
    assert_one_line_error(run("scan", str(tmp_path / "big.stl"), "--units", "m", "-p", PAPER_S2), "units")


def test_scan_writes_cloud_and_raw_profiles(tmp_path):
    result = run("scan", "part_b", "-p", PAPER_S2, "--out", str(tmp_path / "b.npy"), "--raw", str(tmp_path / "raw"))
    assert result.returncode == 0, result.stderr
    points = np.load(tmp_path / "b.npy")
    raw = np.loadtxt(tmp_path / "raw" / "S1.csv", delimiter=",")
    assert raw.shape == (120, 3200)
    assert len(points) == int((raw > -9999).sum()) > 100_000
    # S2 looks straight down at the top face (z = 17.6 mm)
    assert np.median(points[:, 2]) == pytest.approx(0.0176, abs=1e-5)
