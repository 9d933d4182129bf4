"""Degenerate geometry seen by one sensor looking straight down: what the part cannot show must come out
``unobservable`` (per scan and in Table 1), never as a confident small error."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from cli_checks import SMALL_SEARCH, run
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective, reduced_objective
from optipose.io import load_result
from optipose.model.baseline import CONVENTIONAL
from optipose.model.part import load_part

ROTATIONS = ("roll", "pitch", "yaw")
ALONG_X = trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0])


def _short():
    objective = load_objective("paper").in_cell("ideal")
    return replace(objective, protocol=replace(reduced_objective(objective).protocol, sequences=("R", "P", "Y")))


def _seen_from_above(mesh, tmp_path, name, sidecar=False):
    """The mesh as a bare STL loaded as a user would, scanned by one sensor looking straight down at the
    middle of its top (the conventional S2's view): (per-scan table, Table 1's k = 1 choice).

    sidecar : give that sensor in a part file beside the STL as its hand layout, so no conventional
        placement is computed (it takes ~26 s on a 2048-facet cylinder: the heads' clearance to its hull).
    """
    (x0, y0, _), (x1, y1, z1) = mesh.bounds
    down = np.array([[0, 1, 0, (x0 + x1) / 2], [1, 0, 0, (y0 + y1) / 2], [0, 0, -1, z1], [0, 0, 0, 1.0]])
    mesh.export(tmp_path / f"{name}.stl")
    if sidecar:
        rows = ", ".join(str(list(row)) for row in down.tolist())
        (tmp_path / f"{name}.toml").write_text(
            f'[part]\nunits = "m"\n[[layouts.hand.sensors]]\nname = "S2"\nT_O_S = [{rows}]\n'
        )
    part = load_part(tmp_path / f"{name}.stl", units="m")
    assert ("hand" if sidecar else CONVENTIONAL) in part.layouts  # every bare STL gets a baseline, flat ones included
    with Evaluator(part, _short(), seed=1) as evaluator:
        result = evaluator([down])
    assert len(result.per_scan) == 6 and result.per_scan["ok"].all()
    return result.per_scan, result.table[0]


def _blind(per_scan, axes) -> bool:
    return all(per_scan[f"unobservable_{a}"].all() for a in axes)


def _max_deg(per_scan, axis) -> float:
    return float(np.rad2deg(per_scan[f"err_{axis}"].abs().max()))


FLAT = {
    # two triangles of zero thickness (its convex hull is flat: loading it crashed in trimesh before)
    "plane": lambda: trimesh.Trimesh(
        [[-15e-3, -15e-3, 0], [15e-3, -15e-3, 0], [15e-3, 15e-3, 0], [-15e-3, 15e-3, 0]], [[0, 1, 2], [0, 2, 3]]
    ),
    # 300 mm across the 35 mm laser line: the line never reaches an edge
    "plate_300mm": lambda: trimesh.creation.box((0.04, 0.3, 0.005)),
}


@pytest.mark.parametrize("name", FLAT)
def test_a_flat_face_shows_its_tilt_and_nothing_else(name, tmp_path):
    per_scan, choice = _seen_from_above(FLAT[name](), tmp_path, name)
    # a plane's normal fixes roll, pitch and z; turning about z and sliding in x, y change nothing
    assert _blind(per_scan, ("yaw", "x", "y"))
    assert not per_scan[["unobservable_roll", "unobservable_pitch", "unobservable_z"]].any().any()
    assert _max_deg(per_scan, "roll") < 0.005 and _max_deg(per_scan, "pitch") < 0.005
    yawed = per_scan["label"] == "Y"
    assert np.allclose(np.rad2deg(per_scan.loc[yawed, "err_yaw"]), [2.0, -2.0], atol=1e-3)  # yaw stays at the start
    assert not choice.axes[2].observable and choice.axes[0].observable and choice.axes[1].observable


def test_a_smooth_cylinder_along_the_motion_hides_its_roll(tmp_path):
    # 2048 facets: turning about its own axis (the rotation centre's x line) changes nothing the scan sees
    per_scan, choice = _seen_from_above(
        trimesh.creation.cylinder(0.01, 0.04, sections=2048, transform=ALONG_X), tmp_path, "cyl", sidecar=True
    )
    assert _blind(per_scan, ("roll",))
    assert not per_scan[["unobservable_pitch", "unobservable_yaw"]].any().any()
    assert _max_deg(per_scan, "pitch") < 0.001 and _max_deg(per_scan, "yaw") < 0.001
    assert not choice.axes[0].observable and choice.axes[1].observable and choice.axes[2].observable


def test_a_faceted_cylinder_does_not_report_its_roll_as_a_small_error(tmp_path):
    # 128 facets (2.8° each) make roll weakly observable (H's roll eigenvalue ~1e-4 of the largest, over the
    # 1e-6 tolerance), and the ICP can lock onto a neighbouring facet: the roll it reports must show that
    per_scan, choice = _seen_from_above(
        trimesh.creation.cylinder(0.01, 0.04, sections=128, transform=ALONG_X), tmp_path, "cyl128"
    )
    roll = choice.axes[0]
    assert not roll.observable or np.rad2deg(roll.p75) > 0.5
    assert _max_deg(per_scan, "pitch") < 0.001 and _max_deg(per_scan, "yaw") < 0.001


def test_a_thin_sheet_turned_past_its_thickness_registers_wrong_and_says_so(tmp_path):
    # 0.5 mm thick, 40 mm long: 2° about its middle lifts its ends 0.7 mm, past the thickness, so their
    # closest points are on the other face and ICP settles about 1° off. It is not dropped: the error is
    # in the statistics, and its RMSE is tens of times the good registrations'
    per_scan, choice = _seen_from_above(trimesh.creation.box((0.04, 0.04, 0.0005)), tmp_path, "sheet")
    tilted = per_scan["label"].isin(["R", "P"]).to_numpy()
    worst = np.maximum(per_scan["err_roll"].abs(), per_scan["err_pitch"].abs()).to_numpy()
    assert np.all(np.rad2deg(worst[tilted]) > 0.5)
    assert per_scan.loc[tilted, "rmse"].min() > 20 * per_scan.loc[~tilted, "rmse"].max()
    assert _blind(per_scan, ("yaw", "x", "y"))
    assert np.rad2deg(choice.axes[0].p75) > 0.5 and np.rad2deg(choice.axes[1].p75) > 0.5


def test_a_faceted_sphere_pins_its_centre(tmp_path):
    # 5120 facets: the centre is fixed by the surface (translations to a few µm); rotations about it are
    # seen only through the facets, and whatever is reported for them stays within a facet's reach
    per_scan, _ = _seen_from_above(
        trimesh.creation.icosphere(subdivisions=4, radius=0.015), tmp_path, "sphere", sidecar=True
    )
    assert not per_scan[["unobservable_x", "unobservable_y", "unobservable_z"]].any().any()
    assert per_scan[["err_x", "err_y", "err_z"]].abs().max().max() < 5e-6
    for axis in ROTATIONS:
        assert per_scan[f"unobservable_{axis}"].all() or _max_deg(per_scan, axis) < 0.05


# -- the search on a part no sensor can fully observe -------------------------------------------------------
SHORT = '[protocol]\nsequences = ["R", "P", "Y"]\nstep_deg = 4.0\n'


def test_the_search_says_when_no_layout_of_k_sensors_observes_an_axis(tmp_path):
    # a plane: from any view its yaw (a turn about its normal) is unobservable. Measured: a 160-evaluation
    # search of one sensor in 17 s; found and conventional both read yaw `unobs.`, scores 20 000 mdeg
    # (the 10° charge twice), and one line says no layout of one sensor the search found observes yaw
    FLAT["plane"]().export(tmp_path / "plane.stl")
    (tmp_path / "small.toml").write_text(SMALL_SEARCH)
    (tmp_path / "short.toml").write_text(SHORT)
    out = tmp_path / "searched"
    result = run(
        "search",
        str(tmp_path / "plane.stl"),
        "--units",
        "m",
        "--sensors",
        "1",
        "--search-config",
        str(tmp_path / "small.toml"),
        "--objective",
        str(tmp_path / "short.toml"),
        "--seed",
        "4",
        "--out",
        str(out),
        "--no-report",
    )
    assert result.returncode == 0, result.stderr
    said = " ".join(result.stdout.split())  # the terminal's 80 columns fold the line
    assert (
        "k=1: yaw unobservable: no layout of 1 sensor the search found observes it; conventional S2 does not either"
        in said
    )
    found = load_result(out).validation.found[1]
    assert [a.label for a in found.axes] == ["F1", "F1", "unobservable"] and np.isnan(found.axes[2].median)
    assert any(
        line.startswith("k=1: yaw unobservable") for line in load_result(out).verdict_lines()
    )  # the report's lines too


def test_an_unmeasured_axis_compares_as_the_penalty_not_as_nan():
    from optipose.evaluate.assignment import FAILED, UNOBSERVABLE, AxisChoice, Choice
    from optipose.verdict.compare import Verdict, dominates, excess
    from optipose.verdict.words import unmeasured_line

    def choice(name, yaw_reason=""):
        yaw = (
            AxisChoice("yaw", (), "", float("nan"), float("nan"), yaw_reason)
            if yaw_reason
            else AxisChoice("yaw", (0,), name, 2e-6, 3e-6)
        )
        axes = (AxisChoice("roll", (0,), name, 1e-6, 2e-6), AxisChoice("pitch", (0,), name, 1e-6, 2e-6), yaw)
        return Choice(1, (0,), name, axes, 0.0)

    blind, seeing, failing = choice("F1", UNOBSERVABLE), choice("S2"), choice("F1", FAILED)
    # NaN compared as "not worse" before: a found layout blind to yaw passed as no worse than one that sees it
    assert not dominates(blind, seeing) and dominates(seeing, blind) and dominates(blind, choice("S2", UNOBSERVABLE))
    assert excess(blind, seeing) == pytest.approx(2 * np.deg2rad(10.0) - 5e-6)
    assert [(g.axis, g.statistic) for g in Verdict(1, blind, seeing).worse] == [("yaw", "median"), ("yaw", "p75")]
    assert unmeasured_line(1, seeing, blind) == ""
    assert unmeasured_line(1, blind, seeing) == (
        "k=1: yaw unobservable: no layout of 1 sensor the search found observes it; "
        "hand S2 measures yaw (the error is unknown, not small)"
    )
    assert unmeasured_line(2, failing, None).startswith(
        "k=2: yaw not measured: the registrations of found F1 that observe it failed"
    )
