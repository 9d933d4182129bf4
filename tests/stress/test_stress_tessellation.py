"""The same surface in other triangles gives the same Table 1 (docs/method.md, "The evaluator").

Parts A, B and C re-tessellated without moving their surface — every triangle split in three at its
centroid (other triangles and other edges, the old ones kept) and split in four at its edges' midpoints
(trimesh's ``subdivide``) — are evaluated with their hand layouts: each k's choice takes the same sensors
and, per axis, the same subset, each statistic within 1 % of the shipped mesh's (or the axis
unobservable in both). The scans are the same points up to the scanner's column fill, and a point off a
crease gets the same normal whichever face answers for it; the whole protocol is slow (marked ``slow``),
a short one on part B runs by default. In the real cell (``ur10e``, the default) too: the part as made, the
calibration and the material draw from the seed and the surface (docs/cell.md, "The cell and the
tessellation"), also when the re-tessellated mesh is written as a float32 STL and read back.
"""

import io
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from meshes import centroid_split, midpoint_split

from optipose.evaluate.evaluator import evaluate
from optipose.evaluate.objective import load_objective, objective_from_table
from optipose.model.part import load_part

TOLERANCE = 0.01  # relative, per statistic of Table 1
REGISTRATION = (
    "in the real cell A's centroid split moves one median by more than 1 %: the cell moves its points alike"
    " (tests/test_cell_tessellation.py), the registration of clouds off the CAD does not (docs/cell.md)"
)


def _same_table(shipped, other) -> None:
    for a, b in zip(shipped.table, other.table):
        assert (a.k, a.sensors) == (b.k, b.sensors)
        for x, y in zip(a.axes, b.axes):
            assert (x.axis, x.subset, x.reason) == (y.axis, y.subset, y.reason)
            if x.observable:
                np.testing.assert_allclose([y.median, y.p75], [x.median, x.p75], rtol=TOLERANCE, atol=0)


def _evaluate(part, mesh, objective, jobs, seed=0):
    return evaluate(replace(part, mesh=mesh), None, objective, seed=seed, jobs=jobs)


def test_part_b_split_at_its_centroids_gives_the_same_table_on_a_short_protocol():
    """Part B, 1,596 triangles against 4,788 (the same surface), on 9 orientations of the paper's range."""
    objective = objective_from_table(
        {"protocol": {"sequences": ["RP", "PY", "RPY"], "start_deg": -2.0, "stop_deg": 2.0, "step_deg": 2.0}}
    )
    part = load_part("part_b")
    shipped = _evaluate(part, part.mesh, objective, 1)
    other = _evaluate(part, centroid_split(part.mesh), objective, 1)
    _same_table(shipped, other)
    assert other.n_failed == shipped.n_failed
    assert [c.score for c in other.table] == pytest.approx([c.score for c in shipped.table], rel=TOLERANCE)


@pytest.mark.slow
@pytest.mark.parametrize("cell", ["ideal", "ur10e"])
@pytest.mark.parametrize("name", ["part_a", "part_b", "part_c"])
@pytest.mark.parametrize("split", [centroid_split, midpoint_split], ids=["centroid", "midpoint"])
def test_a_retessellated_part_gives_the_same_table(name, split, cell, request):
    """The paper's whole protocol (77 orientations) on the shipped mesh and on the re-tessellated one."""
    if cell != "ideal" and name == "part_a" and split is centroid_split:
        request.applymarker(pytest.mark.xfail(reason=REGISTRATION, strict=False))
    part = load_part(name)
    shipped = _evaluate(part, part.mesh, load_objective("paper").in_cell(cell), 2)
    other = _evaluate(part, split(part.mesh), load_objective("paper").in_cell(cell), 2)
    _same_table(shipped, other)


@pytest.mark.slow
def test_part_b_subdivided_to_2_mm_and_written_as_an_stl_gives_the_same_table_in_the_real_cell():
    """The issue's case: part B at 2 mm edges (170,372 triangles, ``subdivide_to_size``), its vertices
    rounded to float32 as an STL holds them, ``optipose evaluate part_b --seed 3`` in the default cell."""
    part = load_part("part_b")
    v, f = trimesh.remesh.subdivide_to_size(part.mesh.vertices, part.mesh.faces, 0.002)
    stl = trimesh.Trimesh(v, f, process=False).export(file_type="stl")
    other = trimesh.load(io.BytesIO(stl), file_type="stl")
    objective = load_objective("paper")
    assert objective.cell.name == "ur10e"
    _same_table(_evaluate(part, part.mesh, objective, 2, seed=3), _evaluate(part, other, objective, 2, seed=3))
