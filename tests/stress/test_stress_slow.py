"""The long stress cases (``pytest -m slow tests/stress``): the paper's whole protocol on a cell 17 m from
O, and ±10° offsets on part A."""

from __future__ import annotations

import numpy as np
import pytest

from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective
from optipose.model.part import load_part
from optipose.transforms import make_T

from .test_stress_invariance import AXES, _moved
from .test_stress_registration import _at

pytestmark = pytest.mark.slow


def test_the_paper_protocol_on_a_cell_far_from_O():
    # 77 scans × 7 subsets of part B's hand layout, then the whole cell moved by (10, -10, 10) m.
    # Measured: every subset of two or three sensors within 1e-4°, S1 and S3 alone within 2.9e-4° and
    # 1.3e-4° (the size of what a nanometre does to them near O too); the median change over all scans 1e-6°
    # or less but S2's. S2 alone slides along its flat valley (see test_stress_invariance): where both runs'
    # registrations end at the same fit (RMSE within 2x) within 0.065°, but in 2 of its 77 scans a µm of
    # difference in the scan sends one run's ICP to another basin (scan 40 near O: RMSE 1.0 mm against
    # 1.6 µm far, pitch 3.85° off; 2026-11-27), a property of ICP on one sensor's valley, not of the frame
    part = load_part("part_b")
    with Evaluator(part, load_objective("paper").in_cell("ideal"), seed=0) as evaluator:
        near = evaluator(part.layouts["hand"])
    far_part = _moved(part, make_T(t=[10.0, -10.0, 10.0]))
    with Evaluator(far_part, load_objective("paper").in_cell("ideal"), seed=0) as evaluator:
        far = evaluator(far_part.layouts["hand"])
    assert near.per_scan["ok"].equals(far.per_scan["ok"])
    subsets = near.per_scan["subset"].to_numpy()
    change = np.rad2deg(np.abs(far.per_scan[AXES].to_numpy() - near.per_scan[AXES].to_numpy()))
    several = np.array([s.count("S") > 1 for s in subsets])
    assert change[several].max() < 1e-4
    assert change[np.isin(subsets, ["S1", "S3"])].max() < 1e-3
    rmse = near.per_scan["rmse"].to_numpy(), far.per_scan["rmse"].to_numpy()
    other_basin = np.maximum(rmse[0] / rmse[1], rmse[1] / rmse[0]) > 10
    assert not other_basin[subsets != "S2"].any() and other_basin.sum() <= 3
    assert change[(subsets == "S2") & ~other_basin].max() < 0.5
    assert np.median(change[~(subsets == "S2")]) < 1e-5
    for a, b in zip(near.table, far.table):  # Table 1: the same subsets, medians within 1e-4°
        assert [x.name for x in a.axes] == [x.name for x in b.axes]
        assert np.allclose(np.rad2deg([x.median for x in a.axes]), np.rad2deg([x.median for x in b.axes]), atol=1e-4)


def test_ten_degree_offsets_on_part_a():
    # measured: all 56 converge; the worst observed error 0.021° (S2 alone's yaw), 0.0035° for the others
    part = load_part("part_a")
    with Evaluator(part, _at(10.0), seed=2) as evaluator:
        per_scan = evaluator(part.layouts["hand"]).per_scan
    assert per_scan["ok"].all() and len(per_scan) == 56
    blind = per_scan[["unobservable_roll", "unobservable_pitch", "unobservable_yaw"]].to_numpy()
    error = np.where(blind, 0.0, np.rad2deg(per_scan[AXES].abs().to_numpy()))
    assert error.max() < 0.05
    assert error[per_scan["subset"].to_numpy() != "S2"].max() < 0.005
