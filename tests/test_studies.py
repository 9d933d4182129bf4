"""Long studies (``pytest -m slow``): the claims docs/results.md makes about the search, re-measured."""

from __future__ import annotations

import pytest

from optipose.evaluate.objective import load_objective
from optipose.model.part import load_part
from optipose.search.budgets import config_from_budget
from optipose.io.search import SearchFolder
from optipose.search.pipeline import run


@pytest.mark.slow
@pytest.mark.parametrize(
    "part, better, no_worse",
    [
        ("part_a", (1, 2, 3), (2, 3)),
        ("part_b", (1, 2, 3), (2, 3)),
        ("part_c", (2, 3), (1, 2, 3)),
    ],  # run times: benchmarks/README.md, 'Whole commands'
)
def test_default_search_beats_the_hand_placed_layout(tmp_path, part, better, no_worse):
    # docs/results.md, "The main command": these found layouts are >= 2x better in sum than the hand-placed
    # sensors, and no worse on any axis, on the held-out validation seed. C k = 1 is no worse on any axis but
    # only 1.2x better in sum (the tie with the hand S3); A k = 1 and B k = 1 are 5-8x better in sum but a
    # hundredth of a millidegree worse on one pitch statistic than the hand sensor, a difference no real cell resolves.
    report = run(
        load_part(part),
        load_objective("paper").in_cell("ideal"),
        config_from_budget("default", (1, 2, 3)),
        0,
        SearchFolder(tmp_path),
        jobs=2,
    )
    verdicts = {v.k: v for v in report.validation.verdicts()}
    for k in better:
        assert verdicts[k].ratio >= 2
    for k in no_worse:
        assert verdicts[k].no_worse
