"""Failed registrations in Table 1 and in the score: an axis left without a subset because its
registrations failed says so (not ``unobservable``), and a layout whose registrations fail cannot win on
its few good successes."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cli_checks import run
from optipose.evaluate.assignment import FAILED, UNOBSERVABLE, best_choices
from optipose.evaluate.objective import AXES, StatisticConfig
from optipose.evaluate.statistics import FAILED_ERROR, summarize

# part B's hand layout at ±10° (R, P, Y, RPY: 8 scans) with the ICP capped at 8 steps: measured, 33 of 56
# registrations fail and every subset fails in over a tenth of its scans (test_stress_registration.py)
CAPPED = """name = "capped"
[protocol]
sequences = ["R", "P", "Y", "RPY"]
start_deg = -10.0
stop_deg = 10.0
step_deg = 20.0
[registration]
max_iterations = 8
"""


def _per_scan(errors_urad: np.ndarray, failed: set[int]) -> pd.DataFrame:
    """A one-sensor layout's per-scan table: scan i's error (µrad) on every axis, ``failed`` scans not ok."""
    rows = []
    for i, e in enumerate(errors_urad):
        ok = i not in failed
        rows.append(
            {
                "scan": i,
                "subset": "S1",
                "ok": ok,
                **{f"err_{a}": (1e-6 * e if ok else np.nan) for a in AXES},
                **{f"unobservable_{a}": False for a in AXES},
            }
        )
    return pd.DataFrame(rows)


def test_a_layout_whose_registrations_fail_loses_to_an_equal_one_that_does_not():
    # 20 scans with the same errors 1 … 20 µrad, but in one layout the scans of 12 and 14 µrad fail (2 of
    # 20, at the 10 % cut: still eligible). Left out, they would make its score smaller: it would win.
    errors = np.arange(1.0, 21.0)
    cfg = StatisticConfig()
    sound = best_choices(summarize(_per_scan(errors, set())), ["S1"], cfg, 20)[0]
    failing_stats = summarize(_per_scan(errors, {11, 13}))
    failing = best_choices(failing_stats, ["S1"], cfg, 20)[0]
    survivors = np.delete(errors, [11, 13])
    old_rule = 3 * (np.median(survivors) + np.percentile(survivors, 75)) * 1e-6  # 3 × (9.5 + 15.75) µrad
    assert old_rule < sound.score
    # by hand: the failures rank last, the order statistics are those of 1-11, 13, 15-20, 10°, 10°:
    # the median (ranks 9, 10) stays (10 + 11) / 2; the p75 (rank 14.25) goes from 15.25 to 17.25 µrad
    roll = failing_stats.set_index("axis").loc["roll"]
    assert roll["median"] == pytest.approx(10.5e-6) and roll["p75"] == pytest.approx(17.25e-6)
    assert roll["mean"] == pytest.approx(survivors.mean() * 1e-6) and roll["max"] == pytest.approx(
        20e-6
    )  # the converged ones
    assert roll.n_failed == 2 and all(a.observable for a in failing.axes)  # eligible, and
    assert failing.score > sound.score  # it loses: 3 × (10.5 + 17.25) µrad against 3 × (10.5 + 15.25)
    assert failing.score == pytest.approx(3 * (10.5 + 17.25) * 1e-6) and sound.score == pytest.approx(
        3 * (10.5 + 15.25) * 1e-6
    )


def test_with_no_failure_the_order_statistics_are_the_measured_ones():
    errors = np.random.default_rng(3).exponential(5.0, 77)
    stats = summarize(_per_scan(errors, set())).set_index("axis")
    for axis in AXES:
        assert stats.loc[axis, "median"] == np.median(errors * 1e-6) and stats.loc[axis, "p75"] == np.percentile(
            errors * 1e-6, 75
        )


def test_an_axis_without_a_subset_says_why():
    cfg = StatisticConfig()
    failing = summarize(_per_scan(np.arange(1.0, 11.0), {0, 1, 2}))  # 30 % failed, every axis observable
    assert [a.reason for a in best_choices(failing, ["S1"], cfg, 10)[0].axes] == [FAILED] * 3
    blind = _per_scan(np.arange(1.0, 11.0), {0, 1, 2})
    blind["unobservable_yaw"] = True  # yaw is not seen at all: that is the reason, failures or not
    choice = best_choices(summarize(blind), ["S1"], cfg, 10)[0]
    assert [a.label for a in choice.axes] == ["registrations failed", "registrations failed", "unobservable"]
    assert choice.axes[2].reason == UNOBSERVABLE and choice.score == pytest.approx(3 * 2 * FAILED_ERROR)
    assert "yaw=unobservable" in repr(choice) and "roll=registrations failed" in repr(choice)


def test_the_cli_table_the_saved_result_and_the_report_say_registrations_failed(tmp_path):
    from optipose.io import load_result
    from optipose.report.build import build_blocks
    from optipose.report.document import render_markdown

    (tmp_path / "capped.toml").write_text(CAPPED)
    out = tmp_path / "capped"
    result = run(
        "evaluate",
        "part_b",
        "--objective",
        str(tmp_path / "capped.toml"),
        "--seed",
        "2",
        "--out",
        str(out),
        "--no-report",
    )
    assert result.returncode == 0, result.stderr
    # a cell of 3 k × 3 axes each (an 80-column table wraps the words)
    assert (
        result.stdout.count("registrations") == 9
        and result.stdout.count("failed") == 9
        and "unobservable" not in result.stdout
    )
    loaded = load_result(out)
    assert all(a.reason == FAILED for c in loaded.table for a in c.axes)
    assert (
        pd.read_csv(out / "table1.csv")["roll_subset"].isna()
    ).all()  # no subset in the CSV; the reason comes from stats.csv
    markdown = render_markdown(*build_blocks(out, views=False), "figures")
    assert "registrations failed" in markdown and "unobservable" not in markdown
