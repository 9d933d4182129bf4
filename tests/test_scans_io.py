"""Scans out and scans in: ``scan --protocol --raw`` writes a scan folder as a cell's sensors report it,
``evaluate --scans`` reads it back to the simulation's Table 1 bit for bit, and a bad folder is one line."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import trimesh

from cli_checks import assert_one_line_error, run
from optipose.model.motion import ScanMotion
from optipose.model.sensor import load_sensor
from optipose.scan.folder import MANIFEST, ProfileWriter, part_fingerprint
from optipose.scan.profiles import EMPTY, profiles_to_points, read_profiles
from optipose.scan.scanner import Scanner

from meshes import TWO_SENSORS

ROOT = Path(__file__).resolve().parents[1]
MM = 1e-3


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A reduced protocol (R and P at -2, 0, 2 deg: 6 scans) of two of part B's sensors in the paper's cell,
    written by ``scan --protocol --raw`` and simulated by ``evaluate``, with the same seed."""
    d = tmp_path_factory.mktemp("scans")
    paper = (ROOT / "objectives" / "paper.toml").read_text()
    small = paper.replace('name = "paper"', 'name = "small"').replace("step_deg = 0.4", "step_deg = 2.0")
    small = small.replace('sequences = ["R", "P", "Y", "RP", "PY", "YR", "RPY"]', 'sequences = ["R", "P"]')
    (d / "small.toml").write_text(small)
    (d / "two.toml").write_text(TWO_SENSORS)
    common = ["--cell", "ur10e", "--layout", str(d / "two.toml"), "--seed", "1"]
    wrote = run("scan", "part_b", "--protocol", str(d / "small.toml"), *common, "--raw", str(d / "scans"), cwd=d)
    assert wrote.returncode == 0, wrote.stderr
    simulated = run(
        "evaluate",
        "part_b",
        "--objective",
        str(d / "small.toml"),
        *common,
        "--out",
        str(d / "simulated"),
        "--no-report",
        cwd=d,
    )
    assert simulated.returncode == 0, simulated.stderr
    return d


def test_a_protocol_written_in_a_cell_reads_back_to_its_simulation_bit_for_bit(written):
    d = written
    manifest = tomllib.loads((d / "scans" / MANIFEST).read_text())
    assert manifest["cell"] == "ur10e" and manifest["seed"] == 1 and len(manifest["scans"]) == 6
    assert [s["name"] for s in manifest["sensors"]] == ["S1", "S2"]
    raw = np.load(d / "scans" / manifest["scans"][0]["files"][1])
    assert raw.shape == (120, 3200) and raw.dtype == np.float64 and (raw == EMPTY).any()
    read = run("evaluate", "part_b", "--scans", str(d / "scans"), "--out", str(d / "read"), "--no-report", cwd=d)
    assert read.returncode == 0, read.stderr
    for table in ("table1.csv", "per_scan.csv", "stats.csv", "points.csv"):
        assert (d / "read" / table).read_bytes() == (d / "simulated" / table).read_bytes(), table


def _copy(src: Path, dst: Path) -> Path:
    """A scan folder whose profile files are links to ``src``'s and whose manifest is a copy."""
    dst.mkdir()
    for f in src.iterdir():
        (dst / f.name).write_text(f.read_text()) if f.name == MANIFEST else (dst / f.name).symlink_to(f)
    return dst


def _edit_manifest(folder: Path, edit) -> None:
    table = tomllib.loads((folder / MANIFEST).read_text())
    edit(table)
    (folder / MANIFEST).write_text(tomli_w.dumps(table))


def _replace_file(folder: Path, raw: np.ndarray) -> None:
    name = tomllib.loads((folder / MANIFEST).read_text())["scans"][2]["files"][0]
    (folder / name).unlink()
    np.save(folder / name, raw)


def _bad(kind: str, folder: Path) -> None:
    first = tomllib.loads((folder / MANIFEST).read_text())["scans"][3]["files"][1]
    if kind == "manifest":
        (folder / MANIFEST).unlink()
    elif kind == "length":
        _replace_file(folder, np.full((120, 3199), EMPTY))
    elif kind == "nan":
        raw = np.full((120, 3200), EMPTY)
        raw[7, 100] = np.nan
        _replace_file(folder, raw)
    elif kind == "orientation":
        _edit_manifest(folder, lambda t: t["scans"].pop(4))
    elif kind == "file":
        (folder / first).unlink()


@pytest.mark.parametrize(
    "kind, fragment",
    [
        ("manifest", "no manifest.toml"),
        ("length", "3200 values a profile"),
        ("nan", "profile 7 holds NaN"),
        ("orientation", "is not in the manifest"),
        ("file", "is missing"),
    ],
)
def test_a_bad_scan_folder_is_one_line(written, tmp_path, kind, fragment):
    folder = _copy(written / "scans", tmp_path / "bad")
    _bad(kind, folder)
    assert_one_line_error(run("evaluate", "part_b", "--scans", str(folder), "--out", str(tmp_path / "r")), fragment)


def test_another_parts_scans_are_refused(written, tmp_path):
    result = run("evaluate", "part_a", "--scans", str(written / "scans"), "--out", str(tmp_path / "r"))
    assert_one_line_error(result, "scans of part 'part_b'")


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["scan", "part_b", "--protocol", "paper"], "--protocol needs --raw"),
        (["scan", "part_b", "--cell", "ur10e"], "--cell needs --protocol"),
        (["scan", "part_b", "--protocol", "paper", "--raw", "{d}/x", "--format", "tiff"], "--format tiff"),
        (["evaluate", "part_b", "--scans", "{d}/nowhere"], "no such folder"),
        (["evaluate", "part_b", "--scans", "{d}", "--cell", "ideal"], "--cell is not for --scans"),
    ],
)
def test_scan_options_that_cannot_work_are_one_line(tmp_path, args, fragment):
    args = [a.replace("{d}", str(tmp_path)) for a in args]
    assert_one_line_error(run(*args), fragment)


def test_a_plate_at_a_known_distance_gives_the_known_height(tmp_path):
    # the top face 5 mm beyond R along the view (z_S): Z = -5 mm (positive toward the head) in every column
    plate = trimesh.creation.box((0.06, 0.06, 0.002))
    plate.apply_translation([0.0, 0.0, -0.006])  # top at z = -5 mm
    sensor = load_sensor("keyence-lj-x8080")
    T_down = np.array([[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1.0]])
    motion = ScanMotion(4 * MM)
    scan = Scanner(plate, sensor, "white-diffuse").scan(T_down, motion, noise=False)
    writer = ProfileWriter(tmp_path, ("R",), ("S1",))
    raw = read_profiles(tmp_path / writer(0, 0, scan.raw), sensor.points_per_profile)
    assert raw.shape == (8, 3200) and np.allclose(raw, -5.0, rtol=0, atol=1e-12)
    points, _, _ = profiles_to_points(raw, sensor, T_down, motion.offsets())
    assert np.allclose(points[:, 2], -0.005, rtol=0, atol=1e-15) and np.array_equal(points, scan.points)


def test_the_device_csv_reads_back_to_its_four_decimals(tmp_path):
    raw = np.full((3, 3200), EMPTY)
    raw[1, 10:20] = np.linspace(-1.23456, 2.5, 10)
    name = ProfileWriter(tmp_path, ("R",), ("S1",), "csv")(0, 0, raw)
    back = read_profiles(tmp_path / name, 3200)
    assert name.endswith(".csv") and np.allclose(back, raw, rtol=0, atol=0.51e-4)
    assert (back == EMPTY).sum() == (raw == EMPTY).sum()


def test_the_fingerprint_is_the_meshs_whatever_its_units_or_triangle_order():
    box = trimesh.creation.box((0.05, 0.04, 0.03))
    same = trimesh.Trimesh(box.vertices, box.faces[::-1], process=False)
    other = trimesh.creation.box((0.05, 0.04, 0.031))
    assert part_fingerprint(box.vertices) == part_fingerprint(same.vertices)
    assert part_fingerprint(box.vertices) != part_fingerprint(other.vertices)


def test_a_folder_without_its_objective_settings_uses_the_named_objective(written, tmp_path):
    folder = _copy(written / "scans", tmp_path / "named")
    _edit_manifest(folder, lambda t: (t.pop("objective_settings"), t.update(objective="paper")))
    # the paper's protocol has 77 scans; this folder 6: the first it lacks is named
    result = run("evaluate", "part_b", "--scans", str(folder), "--out", str(tmp_path / "r"))
    assert_one_line_error(result, "objective 'paper''s protocol")
