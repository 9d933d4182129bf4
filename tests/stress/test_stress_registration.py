"""Registration under stress: start offsets up to ±10°, ICPs cut short, a wrong reference. A failure
must be flagged and counted in the result (per scan, in the statistics, out of Table 1), never dropped."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from optipose.evaluate.assignment import FAILED, MAX_FAILED_FRACTION
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective
from optipose.model.part import load_part
from optipose.registration import register, voxel_down
from optipose.registration.reference import SurfaceReference
from optipose.scan.scanner import PartPose, part_scanner

AXES = ["err_roll", "err_pitch", "err_yaw"]


@pytest.fixture(scope="module")
def part_b():
    return load_part("part_b")


def _at(offset_deg: float, max_iterations: int = 100):
    """The paper objective at ±offset_deg only (R, P, Y, RPY: 8 scans), ICP capped at max_iterations."""
    objective = load_objective("paper").in_cell("ideal")
    start, stop = -np.deg2rad(offset_deg), np.deg2rad(offset_deg)
    protocol = replace(objective.protocol, sequences=("R", "P", "Y", "RPY"), start=start, stop=stop, step=stop - start)
    return replace(
        objective, protocol=protocol, registration=replace(objective.registration, max_iterations=max_iterations)
    )


def test_ten_degree_offsets_are_recovered(part_b):
    with Evaluator(part_b, _at(10.0), seed=2) as evaluator:
        result = evaluator(part_b.layouts["hand"])
    per_scan = result.per_scan
    assert len(per_scan) == 8 * 7 and result.n_failed == 0
    assert np.allclose(np.rad2deg(per_scan.loc[per_scan["label"] == "R", "roll_set"]).unique(), [-10, 10])
    error = np.rad2deg(per_scan[AXES].abs().to_numpy())
    several = per_scan["subset"].str.count("S").to_numpy() > 1
    # S2 alone sees yaw only through B's side walls at grazing angles (docs/method.md, "The evaluator"):
    # measured 0.082° there at 10° of pitch; every other axis and subset stays under 0.008°
    assert error.max() < 0.1
    assert np.delete(error, np.flatnonzero(per_scan["subset"] == "S2"), axis=0).max() < 0.01
    assert error[several].max() < 0.005  # measured 0.0028°
    assert (per_scan["fitness"] == 1.0).all() and per_scan["rmse"].max() < 20e-6


def test_registrations_cut_short_are_counted_not_dropped(part_b):
    with Evaluator(part_b, _at(10.0, max_iterations=8), seed=2, quiet=True) as evaluator:
        result = evaluator(part_b.layouts["hand"])
    per_scan, stats = result.per_scan, result.stats
    failed = ~per_scan["ok"]
    assert len(per_scan) == 8 * 7 and 0 < failed.sum() < len(per_scan) and result.n_failed == failed.sum()
    assert (per_scan.loc[failed, "failure"] == "no convergence in 8 iterations").all()
    assert not per_scan.loc[failed, "converged"].any()
    for (subset, axis), row in stats.set_index(["subset", "axis"]).iterrows():
        rows = per_scan[per_scan["subset"] == subset]
        assert row.n_ok + row.n_failed == 8 and row.n_failed == (~rows["ok"]).sum()
        ok = rows.loc[rows["ok"], f"err_{axis}"].abs()
        ranked = np.concatenate([ok, np.full(row.n_failed, np.deg2rad(10.0))])  # a failure: a 10° error
        assert row["median"] == pytest.approx(np.median(ranked), rel=1e-12) and row["p75"] == pytest.approx(
            np.percentile(ranked, 75), rel=1e-12
        )
        assert (np.isnan(row["max"]) and ok.empty) or row["max"] == ok.max()  # mean and max: the converged ones
    # Table 1 takes no subset that failed in more than a tenth of the scans, and says that is why
    too_many = set(stats.loc[stats["n_failed"] > MAX_FAILED_FRACTION * 8, "subset"])
    assert too_many
    for choice in result.table:
        assert not {a.name for a in choice.axes if a.observable} & too_many
    assert not stats["unobservable"].any()  # every subset observes every axis: the failures are why
    assert all(a.reason == FAILED and a.label == "registrations failed" for c in result.table for a in c.axes)


@pytest.fixture(scope="module")
def s1_cloud(part_b):
    """Part B turned 2° in roll, seen by the hand layout's S1, down-sampled as the evaluator does."""
    cfg = load_objective("paper").in_cell("ideal").registration
    scan = part_scanner(part_b).scan(
        part_b.layouts["hand"].poses[0], part_b.motion, PartPose(np.deg2rad([2, 0, 0]), part_b.rotation_centre)
    )
    return voxel_down(scan.points, cfg.voxel_size), cfg


def test_a_wrong_reference_shows_in_fitness_and_rmse(part_b, s1_cloud):
    cloud, cfg = s1_cloud
    right = register(cloud, SurfaceReference(part_b.mesh.vertices, part_b.mesh.faces), cfg)
    assert right.ok and right.fitness == 1.0 and right.rmse < 20e-6
    for other in ("part_a", "part_c"):
        mesh = load_part(other).mesh
        wrong = register(cloud, SurfaceReference(mesh.vertices, mesh.faces), cfg)
        # measured: RMSE 1.4 and 1.6 mm against 7.7 µm, fitness 0.99 and 0.85; the ICP still calls it
        # converged (see docs/testing.md, "Stress tests": no RMSE threshold fails it)
        assert wrong.rmse > 100 * right.rmse and wrong.fitness < 1.0


def test_a_reference_out_of_reach_fails_the_registration(part_b, s1_cloud):
    cloud, cfg = s1_cloud
    mesh = part_b.mesh.copy()
    mesh.apply_translation([0.0, 0.0, 0.1])  # 100 mm away: no point within the 5 mm correspondence distance
    reg = register(cloud, SurfaceReference(mesh.vertices, mesh.faces), cfg)
    assert not reg.ok and not reg.converged and "within the correspondence distance" in reg.failure
    assert reg.fitness == 0.0 and np.isnan(reg.rmse)


def test_wrong_basins_at_ten_degrees_stay_in_the_statistics_and_show_in_the_rmse():
    # part C (a U bracket) at ±10°: measured 25 of 56 registrations converge off by 0.1-33° on axes they
    # observe; they are not failures to the ICP, but they are in the statistics, and their RMSE (64 µm
    # and up) is over ten times the worst of the good ones (4.6 µm)
    part_c = load_part("part_c")
    with Evaluator(part_c, _at(10.0), seed=2, quiet=True) as evaluator:
        result = evaluator(part_c.layouts["hand"])
    per_scan, stats = result.per_scan, result.stats
    assert len(per_scan) == 8 * 7
    seen = ~per_scan[["unobservable_roll", "unobservable_pitch", "unobservable_yaw"]].any(axis=1)
    error = np.rad2deg(per_scan[AXES].abs().max(axis=1))
    wrong, right = per_scan["ok"] & seen & (error > 0.05), per_scan["ok"] & seen & (error < 0.02)
    assert wrong.sum() >= 10 and right.sum() >= 10
    assert per_scan.loc[wrong, "rmse"].min() > 10 * per_scan.loc[right, "rmse"].max()
    for (subset, axis), row in stats.set_index(["subset", "axis"]).iterrows():
        ok = per_scan.loc[(per_scan["subset"] == subset) & per_scan["ok"], f"err_{axis}"].abs()
        assert row["max"] == ok.max() and row.n_ok + row.n_failed == 8  # the worst is in, none dropped


def test_max_rmse_fails_the_wrong_basins_and_the_wrong_reference(part_b, s1_cloud):
    objective = _at(10.0)
    objective = replace(objective, registration=replace(objective.registration, max_rmse=0.03e-3))
    part_c = load_part("part_c")
    with Evaluator(part_c, objective, seed=2, quiet=True) as evaluator:
        per_scan = evaluator(part_c.layouts["hand"]).per_scan
    seen = ~per_scan[["unobservable_roll", "unobservable_pitch", "unobservable_yaw"]].any(axis=1)
    error = np.rad2deg(per_scan[AXES].abs().max(axis=1))
    by_rmse = per_scan["failure"].str.startswith("rmse ")
    assert by_rmse.sum() >= 10 and not per_scan.loc[by_rmse, "ok"].any()
    assert not (per_scan["ok"] & seen & (error > 0.05)).any()  # no wrong basin left among the successes
    assert (per_scan.loc[seen & (error < 0.02), "ok"]).all()  # and no good registration lost
    cloud, cfg = s1_cloud
    cfg = replace(cfg, max_rmse=0.05e-3)
    assert register(cloud, SurfaceReference(part_b.mesh.vertices, part_b.mesh.faces), cfg).ok
    mesh = load_part("part_a").mesh
    wrong = register(cloud, SurfaceReference(mesh.vertices, mesh.faces), cfg)
    assert not wrong.ok and wrong.converged and wrong.failure.startswith("rmse 1.4")


def test_max_rmse_in_an_objective_file():
    from optipose.errors import ConfigError
    from optipose.evaluate.objective import objective_from_table

    assert objective_from_table({"registration": {"max_rmse_mm": 0.1}}).registration.max_rmse == pytest.approx(1e-4)
    assert load_objective("paper").in_cell("ideal").registration.max_rmse == 0.0  # off unless set
    with pytest.raises(ConfigError, match="max_rmse"):
        objective_from_table({"registration": {"max_rmse_mm": -1}})
