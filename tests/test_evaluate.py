"""The evaluator: registration signs and axes, observability, assignment, reproducibility, CLI."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import trimesh

from optipose.evaluate.assignment import all_subsets, best_choices, subset_name
from optipose.errors import ConfigError
from optipose.evaluate.evaluator import Evaluator
from optipose.model.layout import Layout, SensorPose
from optipose.evaluate.objective import StatisticConfig, load_objective, objective_from_table
from optipose.evaluate.protocol import perturbations
from optipose.registration.reference import SurfaceReference
from optipose.registration.sampled import sample_surface
from optipose.registration import information_matrix, voxel_down
from optipose.model.motion import ScanMotion
from optipose.evaluate.statistics import unobservable_axes
from optipose.transforms import part_motion, transform_points

DEG = np.pi / 180


def _objective(sequences=("R",), start=-1.0, stop=1.0, step=1.0, **registration):
    table = {
        "protocol": {"sequences": list(sequences), "start_deg": start, "stop_deg": stop, "step_deg": step},
        "registration": registration,
    }
    return objective_from_table(table)


class _Part:
    """A minimal stand-in for optipose.model.part.Part."""

    def __init__(self, mesh, layout, material="black-pla", length=None, centre=None):
        self.name, self.mesh, self.material, self.sensor = "synthetic", mesh, material, "keyence-lj-x8080"
        self.motion = ScanMotion(length or mesh.extents[0])
        self.rotation_centre = np.asarray(mesh.bounds.mean(axis=0) if centre is None else centre)
        self.layouts = {"hand": layout}


def _top_sensor(x, y, z, name="S2"):
    """Looking straight down (z_S = -z_O), laser line along y_O, R at (x, y, z)."""
    T = np.array([[0, 1, 0, x], [1, 0, 0, y], [0, 0, -1, z], [0, 0, 0, 1.0]])
    return SensorPose(name, T)


@pytest.fixture(scope="module")
def block():
    """Part B's envelope with a pocket: 60 x 41 x 17.6 mm, pocket 30 x 20 x 5 mm off-centre."""
    body = trimesh.creation.box([0.060, 0.041, 0.0176])
    pocket = trimesh.creation.box([0.030, 0.020, 0.010])
    pocket.apply_translation([0.005, 0.003, 0.0088])
    mesh = body.difference(pocket)
    mesh.apply_translation([0.030, 0.0, 0.0088])
    s = np.sqrt(0.5)
    poses = [
        SensorPose("S1", np.array([[0, 1, 0, 0.030], [s, 0, s, -0.023], [s, 0, -s, 0.015], [0, 0, 0, 1.0]])),
        _top_sensor(0.030, 0.0, 0.0175),
        SensorPose("S3", np.array([[0, 1, 0, 0.030], [s, 0, -s, 0.014], [-s, 0, -s, 0.015], [0, 0, 0, 1.0]])),
    ]
    return _Part(mesh, Layout(tuple(poses), name="hand"))


@pytest.fixture(scope="module")
def block_result(block):
    with Evaluator(block, _objective(("R", "P", "Y"), 1.0, 1.0), seed=3) as ev:
        return ev(block.layouts["hand"])


# -- objective and protocol -------------------------------------------------------------------------------
def test_paper_objective_is_the_papers_protocol():
    obj = load_objective("paper").in_cell("ideal")
    p = perturbations(obj.protocol, seed=0)
    assert len(p) == 77
    assert list(dict.fromkeys(p.label)) == ["R", "P", "Y", "RP", "PY", "YR", "RPY"]
    np.testing.assert_allclose(np.rad2deg(p.rpy[:11, 0]), np.linspace(-2, 2, 11), atol=1e-12)
    assert np.all(p.rpy[:11, 1:] == 0) and p.rpy[5, 0] == 0.0
    rp = p.rpy[p.label == "RP"]
    assert np.all(rp[:, 0] == rp[:, 1]) and np.all(rp[:, 2] == 0)
    assert len(set(p.seeds.tolist())) == 77
    np.testing.assert_array_equal(perturbations(obj.protocol, 0).seeds, p.seeds)


def test_random_protocol_and_offsets():
    obj = objective_from_table(
        {"protocol": {"kind": "random", "count": 5, "range_deg": [1, 0, 0], "offsets_mm": [[0, 0, 0], [1, 0, 0]]}}
    )
    p = perturbations(obj.protocol, seed=1)
    assert len(p) == 10 and np.all(np.abs(p.rpy[:, 0]) <= 1 * DEG) and np.all(p.rpy[:, 1:] == 0)
    np.testing.assert_allclose(p.offset[1] - p.offset[0], [1e-3, 0, 0])


@pytest.mark.parametrize(
    "table, words",
    [
        ({"protocol": {"step_deg": 0}}, "step_deg"),
        ({"protocol": {"sequences": ["RX"]}}, "sequences"),
        ({"registration": {"method": "magic"}}, "method"),
        ({"registration": {"voxel_size": 0.5}}, "unknown key"),
        ({"statistic": {"weights": {"roll": -1}}}, "weights"),
    ],
)
def test_bad_objectives_say_what_is_wrong(table, words):
    with pytest.raises(ConfigError, match=words):
        objective_from_table(table)


def test_unknown_objective_name():
    with pytest.raises(ConfigError, match="unknown objective"):
        load_objective("no-such-objective")


# -- registration ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def surface(block):
    return SurfaceReference(block.mesh.vertices, block.mesh.faces)


def test_voxel_down_keeps_one_centroid_per_voxel():
    p = np.array([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.5, 0.2, 0.2]]) * 1e-3
    np.testing.assert_allclose(voxel_down(p, 1e-3), [[0.2e-3] * 3, [1.5e-3, 0.2e-3, 0.2e-3]])


def test_voxel_down_is_the_unique_and_bincount_centroid_bit_for_bit():
    points = np.random.default_rng(3).normal(scale=0.01, size=(20000, 3))
    cell = np.floor(points / 0.5e-3).astype(np.int64)
    cell -= cell.min(axis=0)
    dims = cell.max(axis=0) + 1
    _, inverse, counts = np.unique(
        (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2], return_inverse=True, return_counts=True
    )
    sums = np.stack([np.bincount(inverse, points[:, j], len(counts)) for j in range(3)], axis=1)
    np.testing.assert_array_equal(voxel_down(points, 0.5e-3), sums / counts[:, None])


def _tilted_scan(block, rpy_deg, spacing=0.7e-3, noise=5e-6):
    points, _ = sample_surface(block.mesh.vertices, block.mesh.faces, spacing, seed=4)
    points = points + np.random.default_rng(5).normal(scale=noise, size=points.shape)
    return transform_points(part_motion(np.asarray(rpy_deg) * DEG, block.rotation_centre), points)


@pytest.mark.parametrize("guess", ["none", "previous step"])
def test_nearest_answers_what_closest_does(block, surface, guess):
    scan = _tilted_scan(block, [0.6, -0.4, 0.8])
    if guess == "previous step":
        _, _, ids = surface.closest(
            transform_points(part_motion(np.array([0.3, 0.2, -0.5]) * DEG, block.rotation_centre), scan)
        )
    else:
        ids = None
    q, n, ids = surface.nearest(scan, ids)
    q0, n0, ids0 = surface.closest(scan)
    np.testing.assert_array_equal(q, q0)
    np.testing.assert_array_equal(n, n0)
    assert (ids == ids0).mean() > 0.999  # a point on an edge may name either face; its q and n agree


# -- observability --------------------------------------------------------------------------------------
def test_a_plate_leaves_yaw_and_in_plane_translation_unobservable():
    xy = np.random.default_rng(0).uniform(-0.02, 0.02, (500, 2))
    points = np.column_stack([xy, np.zeros(500)])
    normals = np.tile([0.0, 0.0, 1.0], (500, 1))
    blind = unobservable_axes(information_matrix(points, normals), 0.02)
    assert blind.tolist() == [False, False, True, True, True, False]


def test_a_box_corner_observes_everything():
    rng = np.random.default_rng(1)
    faces = [
        (np.column_stack([rng.uniform(0, 0.02, 300), rng.uniform(0, 0.02, 300), np.zeros(300)]), [0, 0, 1.0]),
        (np.column_stack([np.zeros(300), rng.uniform(0, 0.02, 300), rng.uniform(0, 0.02, 300)]), [1.0, 0, 0]),
        (np.column_stack([rng.uniform(0, 0.02, 300), np.zeros(300), rng.uniform(0, 0.02, 300)]), [0, 1.0, 0]),
    ]
    points = np.vstack([f[0] for f in faces])
    normals = np.vstack([np.tile(f[1], (300, 1)) for f in faces])
    assert not unobservable_axes(information_matrix(points, normals), 0.02).any()


def test_evaluator_flags_a_plate_seen_from_above(tmp_path):
    # wider than the laser fan (35 mm) and longer than the scan, so only the top face is seen
    plate = trimesh.creation.box([0.060, 0.060, 0.002])
    plate.apply_translation([0.030, 0.0, 0.001])
    part = _Part(plate, Layout((_top_sensor(0.030, 0.0, 0.002),), name="top"), length=0.030)
    with Evaluator(part, _objective(("R", "Y"), -1.0, 1.0, 2.0), seed=0) as ev:
        result = ev(part.layouts["hand"])
    stats = result.stats.set_index("axis")
    assert (
        stats.loc["yaw", "unobservable"]
        and not stats.loc["roll", "unobservable"]
        and not stats.loc["pitch", "unobservable"]
    )
    assert not result.table[0].axes[2].observable and result.table[0].axes[0].observable
    assert result.per_scan["unobservable_x"].all() and result.per_scan["unobservable_y"].all()
    from optipose.cli.evaluate import table1

    from rich.console import Console

    console = Console(record=True, width=200)
    console.print(table1(result))
    assert "unobservable" in console.export_text()


# -- the pipeline ---------------------------------------------------------------------------------------
def test_scanned_rotations_come_back_per_axis(block_result):
    per_scan = block_result.per_scan
    # S2 alone looks straight down: its yaw hangs on the pocket walls and may crawl past 100 ICP steps
    assert len(per_scan) == 3 * 7 and per_scan.loc[per_scan["subset"] != "S2", "ok"].all()
    full = per_scan[per_scan["subset"] == "S1S2S3"].set_index("label")
    for axis, label in zip(("roll", "pitch", "yaw"), "RPY"):
        assert full.loc[label, f"{axis}_set"] == pytest.approx(1 * DEG)
        assert np.rad2deg(full.loc[label, f"{axis}_est"]) == pytest.approx(1.0, abs=0.01)
    assert np.rad2deg(np.abs(full[["err_roll", "err_pitch", "err_yaw"]].to_numpy())).max() < 0.01
    # x_O is the scan direction: faces across it are edge-on to the laser plane, so x is the weak one
    assert np.abs(full[["err_y", "err_z"]].to_numpy()).max() < 20e-6 and np.abs(full["err_x"]).max() < 0.5e-3
    counts = block_result.points
    assert (
        len(counts) == 9
        and (counts["n_points"] > counts["n_points_down"]).all()
        and (counts["n_points_down"] > 100).all()
    )


def test_every_subset_is_registered_and_table1_has_one_row_per_k(block_result):
    assert list(dict.fromkeys(block_result.per_scan["subset"])) == ["S1", "S2", "S3", "S1S2", "S1S3", "S2S3", "S1S2S3"]
    assert [c.k for c in block_result.table] == [1, 2, 3]
    assert "S1S2S3" in repr(block_result) and "Choice(k=3" in repr(block_result)


def test_seeded_runs_repeat_exactly(block, block_result):
    with Evaluator(block, _objective(("R", "P", "Y"), 1.0, 1.0), seed=3) as ev:
        again = ev(block.layouts["hand"])
    pd.testing.assert_frame_equal(again.per_scan, block_result.per_scan)
    with Evaluator(block, _objective(("R", "P", "Y"), 1.0, 1.0), seed=4) as ev:
        other = ev(block.layouts["hand"])
    assert not np.array_equal(other.per_scan["err_roll"], block_result.per_scan["err_roll"])


def test_one_and_two_jobs_give_identical_results(block, block_result):
    with Evaluator(block, _objective(("R", "P", "Y"), 1.0, 1.0), seed=3, jobs=2) as ev:
        parallel = ev(block.layouts["hand"])
    pd.testing.assert_frame_equal(parallel.per_scan, block_result.per_scan)
    pd.testing.assert_frame_equal(parallel.points, block_result.points)


def test_an_evaluation_of_some_subsets_gives_their_rows_of_the_whole_one(block, block_result):
    """A verdict's draw registers only the subsets its choices use: the same rows, bit for bit, their index
    among every subset kept, and the table chooses among them alone."""
    with Evaluator(block, _objective(("R", "P", "Y"), 1.0, 1.0), seed=3) as ev:
        some = ev(block.layouts["hand"], subsets=[(0, 2), (1,)])
    whole = block_result.per_scan
    pd.testing.assert_frame_equal(some.per_scan, whole[whole["subset"].isin(["S2", "S1S3"])].reset_index(drop=True))
    assert sorted(some.per_scan["subset_index"].unique()) == [1, 4]
    used = {a.name for c in some.table for a in c.axes if a.observable}
    assert used <= {"S2", "S1S3"} and [c.k for c in some.table] == [1, 2, 3]
    # a subset that starts from its sensors' own registrations gets them registered too: the same start
    combined = _objective(("R", "P"), 1.0, 1.0, subset_start="combined")
    with Evaluator(block, combined, seed=3) as ev:
        whole, some = ev(block.layouts["hand"]).per_scan, ev(block.layouts["hand"], subsets=[(2, 0)]).per_scan
    assert list(dict.fromkeys(some["subset"])) == ["S1", "S3", "S1S3"]
    pd.testing.assert_frame_equal(some, whole[whole["subset"].isin(["S1", "S3", "S1S3"])].reset_index(drop=True))
    with Evaluator(block, combined, seed=3) as ev:
        for bad in ([], [()], [(0, 3)]):
            with pytest.raises(ValueError, match="subsets"):
                ev(block.layouts["hand"], subsets=bad)


def test_failed_registrations_are_counted_not_averaged(block):
    obj = _objective(("R",), 1.0, 1.0, max_iterations=1)
    with Evaluator(block, obj, seed=0) as ev:
        result = ev(block.layouts["hand"])
    assert result.n_failed == 7 and (result.stats["n_failed"] == 1).all() and result.stats["max"].isna().all()
    assert (result.stats["median"] == np.deg2rad(10.0)).all()  # a failure enters the order statistics as 10°
    assert all(not a.observable and a.reason == "registrations failed" for c in result.table for a in c.axes)


# -- assignment -----------------------------------------------------------------------------------------
def _stats(values: dict) -> pd.DataFrame:
    rows = []
    for subset, per_axis in values.items():
        for axis, (median, p75) in zip(("roll", "pitch", "yaw"), per_axis):
            rows.append(
                {
                    "subset": subset,
                    "axis": axis,
                    "median": median,
                    "p75": p75,
                    "mean": median,
                    "max": p75,
                    "n_ok": 77,
                    "n_failed": 0,
                    "unobservable": np.isnan(median),
                }
            )
    return pd.DataFrame(rows)


def test_assignment_picks_each_axis_its_subset_like_table1():
    names = ["S1", "S2", "S3"]
    assert [subset_name(s, names) for s in all_subsets(3)] == ["S1", "S2", "S3", "S1S2", "S1S3", "S2S3", "S1S2S3"]
    nan = float("nan")
    stats = _stats(
        {
            "S1": [(3, 4), (5, 6), (1, 2)],
            "S2": [(9, 9), (9, 9), (nan, nan)],
            "S3": [(4, 5), (2, 3), (8, 9)],
            "S1S2": [(2, 3), (4, 5), (3, 4)],
            "S1S3": [(2, 9), (3, 4), (2, 3)],
            "S2S3": [(5, 6), (1, 1), (7, 8)],
            "S1S2S3": [(1, 2), (2, 3), (2, 3)],
        }
    )
    one, two, three = best_choices(stats, names, StatisticConfig(), 77)
    assert (one.name, [a.name for a in one.axes]) == ("S1", ["S1", "S1", "S1"])
    assert (one.sensors, [a.subset for a in one.axes]) == ((0,), [(0,), (0,), (0,)])  # by index
    # by hand: {S1,S2} scores (2+3)+(4+5)+(1+2) = 17, {S1,S3} (2+9)+(2+3)+(1+2) = 19, {S2,S3} 26
    assert (two.name, [a.name for a in two.axes]) == ("S1S2", ["S1S2", "S1S2", "S1"])
    assert (two.sensors, [a.subset for a in two.axes]) == ((0, 1), [(0, 1), (0, 1), (0,)])
    assert two.score == pytest.approx(17.0)
    assert [a.name for a in three.axes] == ["S1S2S3", "S2S3", "S1"]
    assert [a.subset for a in three.axes] == [(0, 1, 2), (1, 2), (0,)]
    assert three.score <= two.score <= one.score


def test_assignment_breaks_median_ties_by_p75():
    stats = _stats({"S1": [(1, 5), (1, 1), (1, 1)], "S2": [(1, 2), (1, 1), (1, 1)], "S1S2": [(1, 3), (1, 1), (1, 1)]})
    _, both = best_choices(stats, ["S1", "S2"], StatisticConfig(), 77)
    assert both.axes[0].name == "S2" and both.axes[0].subset == (1,)


# -- CLI ------------------------------------------------------------------------------------------------
def test_cli_evaluate_writes_results_and_rejects_bad_input(tmp_path, monkeypatch):
    import typer
    from typer.testing import CliRunner

    from optipose.cli.evaluate import register as register_evaluate

    app = typer.Typer()
    register_evaluate(app)
    app.command("noop")(lambda: None)  # a second command keeps "evaluate" as a sub-command
    objective = tmp_path / "tiny.toml"
    objective.write_text('name = "tiny"\n[protocol]\nsequences = ["R"]\nstart_deg = 0.5\nstop_deg = 0.5\n')
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    ok = runner.invoke(app, ["evaluate", "part_b", "--objective", str(objective), "--seed", "1"])
    assert ok.exit_code == 0, ok.output
    latest = tmp_path / "results" / "latest"
    assert latest.is_symlink()
    for name in ("per_scan.csv", "per_scan.parquet", "stats.csv", "table1.csv", "points.csv", "config.toml"):
        assert (latest / name).is_file(), name
    config = (latest / "config.toml").read_text()
    assert "seed = 1" in config and "tiny" in config and "numpy" in config
    bad = runner.invoke(app, ["evaluate", "part_b", "--objective", "nonexistent"])
    assert bad.exit_code == 2 and "unknown objective" in bad.output and "Traceback" not in bad.output


def test_subsets_started_from_their_sensors_registrations_end_where_identity_would(block):
    """Starting each subset of several sensors where its sensors' own registrations put it saves ICP
    steps but not accuracy: the estimates are those of a start at identity to well within the ICP's
    tolerance, and single sensors are untouched (no sensor borrows another's information)."""
    results = {}
    for start in ("identity", "combined"):
        with Evaluator(block, _objective(("R", "P", "Y", "RPY"), -1.5, 1.5, 1.5, subset_start=start), seed=4) as ev:
            results[start] = ev(block.layouts["hand"]).per_scan
    a, b = results["identity"], results["combined"]
    errors = ["err_roll", "err_pitch", "err_yaw"]
    single = a["subset"].str.len() == 2
    np.testing.assert_array_equal(a.loc[single, errors], b.loc[single, errors])
    diff = np.rad2deg(np.abs(a.loc[~single, errors].to_numpy() - b.loc[~single, errors].to_numpy()))
    assert np.median(diff) < 1e-6 and diff.max() < 1e-4  # degrees; the tolerance is 1e-5 deg per step
    assert b.loc[~single, "iterations"].mean() < a.loc[~single, "iterations"].mean() - 1.5


def test_one_sensor_registered_on_its_own_nominal_scan_comes_back(block):
    """A single sensor against its nominal scan (a sampled reference of its own, tracked step after step):
    the turn comes back."""
    layout = Layout((block.layouts["hand"].sensors[0],), name="S1")
    objective = _objective(("R", "Y"), 1.0, 1.0, reference="nominal-scan", reference_spacing_mm=0.5)
    with Evaluator(block, objective, seed=5) as ev:
        per_scan = ev(layout).per_scan
    assert per_scan["ok"].all()
    assert np.rad2deg(np.abs(per_scan[["err_roll", "err_yaw"]].to_numpy())).max() < 0.02


def test_a_zero_area_face_on_an_edge_never_answers_for_its_neighbours():
    # a box with a sliver triangle along one of its edges (collinear corners: no area, no normal); points
    # around that edge have their closest point on the edge, and must get a face with a normal
    box = trimesh.creation.box((0.03, 0.02, 0.01))
    v = np.asarray(box.vertices)
    lo, hi = v.min(axis=0), v.max(axis=0)
    a, b = np.array([lo[0], hi[1], hi[2]]), np.array([hi[0], hi[1], hi[2]])
    vertices = np.vstack([v, a, b, 0.5 * (a + b)])
    faces = np.vstack([[len(v), len(v) + 2, len(v) + 1], box.faces])  # first: it would win every exact tie
    surface = SurfaceReference(vertices, faces)
    rng = np.random.default_rng(3)
    t = rng.uniform(0.1, 0.9, 500)
    edge = a + t[:, None] * (b - a)
    points = edge + np.column_stack([np.zeros(500), rng.uniform(0, 3e-4, 500), rng.uniform(0, 3e-4, 500)])
    q, n, ids = surface.nearest(points)
    assert not np.any(ids == 0)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    np.testing.assert_allclose(q, np.clip(points, lo, hi), atol=1e-12)
