"""Reports (``optipose report``) on real result folders, opened in headless Chromium; the conventional
placement of a bare STL; the search's terminal output in 80 columns."""

from __future__ import annotations

import html
import itertools
import os
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import pytest

from optipose.io import load_result
from optipose.model.baseline import conventional_layout
from optipose.model.collision import DEFAULT_MARGIN, clearance, heads_clearance
from optipose.model.part import PARTS_DIR, load_part
from optipose.verdict.words import confident_line

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
SMALL = """[search]
global_evals = 25
local_evals = 8
joint_evals = 10
random_starts = 2
select_candidates = 0
screen_samples = 0
"""
SHORT = """name = "short"
[protocol]
sequences = ["R", "P", "Y"]
start_deg = -2.0
stop_deg = 2.0
step_deg = 4.0
"""


def run(*args, columns: int = 80):
    env = {**os.environ, "COLUMNS": str(columns)}
    return subprocess.run(
        [sys.executable, "-m", "optipose", *map(str, args)], capture_output=True, text=True, timeout=900, env=env
    )


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A search on a bare STL (its baseline: the conventional placement), a robustness run of its found
    pair against part B's hand layout in instances of the cobot cell, and an evaluation: each writes its report."""
    d = tmp_path_factory.mktemp("report")
    for name, text in (("small.toml", SMALL), ("short.toml", SHORT)):
        (d / name).write_text(text)
    shutil.copy(PARTS_DIR / "part_b" / "part_b.stl", d / "block.stl")
    search = run(
        "search",
        d / "block.stl",
        "--sensors",
        "1,2",
        "--budget",
        "quick",
        "--search-config",
        d / "small.toml",
        "--objective",
        d / "short.toml",
        "--seed",
        1,
        "--out",
        d / "search",
    )
    assert search.returncode == 0, search.stderr
    robust = run(
        "robustness",
        "part_b",
        "--layout",
        d / "search" / "layouts" / "found_k2.toml",
        "--objective",
        d / "short.toml",
        "--cell",
        "cobot",
        "--draws",
        1,
        "--out",
        d / "robustness",
    )  # one held-out draw of the cobot's ranges, and its ranges' low and high ends
    assert robust.returncode == 0, robust.stderr
    evaluation = run("evaluate", "part_b", "--objective", d / "short.toml", "--out", d / "evaluate")
    assert evaluation.returncode == 0, evaluation.stderr
    return {"search": d / "search", "robustness": d / "robustness", "evaluate": d / "evaluate", "stdout": search.stdout}


# --- the terminal ------------------------------------------------------------------------------------
def test_search_output_fits_80_columns_and_says_the_verdict_first(results):
    lines = results["stdout"].splitlines()
    assert max(len(line) for line in lines) <= 80
    result = load_result(results["search"])
    verdicts = result.verdicts()
    # the verdict with confidence first, one line per k, then the predicted errors with their intervals
    # (an UNDECIDED one followed by what keeps it open, indented)
    heads = [i for i, line in enumerate(lines) if line.startswith("k=")][: len(verdicts)]
    assert heads[0] == 0 and [lines[i] for i in heads] == [confident_line(result.confident.by_k[v.k]) for v in verdicts]
    for i, v in zip(heads, verdicts):
        opened = result.confident.by_k[v.k].decision == "UNDECIDED"
        assert lines[i + 1].startswith(f"  k={v.k} open: ") == opened
    lines = [lines[i] for i in heads] + lines[heads[-1] + 1 :]  # the verdict lines, then the rest
    assert all(any(f"{w} conventional" in line for w in ("vs", "than", "KEEP")) for line in lines[:2])
    assert "predicted median |error| in one cell" in " ".join(results["stdout"].split())  # a title rich may wrap
    assert "these verdicts hold in the ideal cell" in results["stdout"]  # the search ran in the ideal cell: it says so
    assert [line[:4] for line in lines[:2]] == ["k=1:", "k=2:"]
    table_row = next(i for i, line in enumerate(lines) if line.lstrip().startswith("1  found"))
    assert table_row > len(verdicts)  # the details come after


# --- the baseline of a bare STL ------------------------------------------------------------------------
def test_a_bare_stl_search_is_compared_with_the_conventional_placement(results):
    result = load_result(results["search"])
    assert result.baseline is not None and result.baseline.description.startswith("conventional placement")
    assert sorted(result.validation.baseline) == [1, 2] and len(result.verdicts()) == 2
    assert all("than conventional" in line for line in result.verdict_lines()[:2])


def test_a_robustness_folder_keeps_every_figure_of_its_check(results):
    result = load_result(results["robustness"])
    assert result.verdicts() == [] and list(result.layouts) == ["hand", "found_k2"]
    rows = result.rows
    instances = [("cobot", "draw 1"), ("cobot", "low ends"), ("cobot", "high ends")]
    assert list(dict.fromkeys(zip(rows.cell, rows.instance))) == instances
    assert len(rows) == len(instances) * 2 * 3  # found_k2 at k = 1 and 2, three axes each
    ratios = result.ratios()
    assert (ratios.ratio == ratios.groupby(["k", "cell", "instance"]).ratio.transform("first")).all()
    assert (ratios.holds == (ratios.ratio >= 1)).all()
    held = result.holds()
    assert held.instances.tolist() == [3, 3] and (held.held <= 3).all()
    config = tomllib.loads((results["robustness"] / "config.toml").read_text())
    assert [(i["cell"], i["instance"]) for i in config["instances"]] == instances


@pytest.mark.parametrize("spec", ["part_b", "bare part_a.stl"])
def test_conventional_placement_clears_the_part_and_sees_it(spec, tmp_path):
    if spec.startswith("bare"):
        shutil.copy(PARTS_DIR / "part_a" / "part_a.stl", tmp_path / "a.stl")
        part = load_part(tmp_path / "a.stl", units="m")
        layout = part.layouts["conventional"]
    else:
        part = load_part(spec)
        layout = conventional_layout(part)  # a shipped part keeps its hand layout; the placement still exists
    from optipose.scan.scanner import part_scanner

    scanner = part_scanner(part)
    x_O = np.array([1.0, 0.0, 0.0])
    for pose in layout.sensors:
        T = pose.T_O_S
        assert clearance(part, None, T).distance >= DEFAULT_MARGIN
        assert abs(T[:3, 0] @ x_O) < 1e-9 and abs(abs(T[:3, 1] @ x_O) - 1) < 1e-9  # the line across the motion
        assert len(scanner.scan(T, part.motion)) >= 2000  # it sees the part (the search's min_points)
    tilt = [np.rad2deg(np.arccos(-pose.T_O_S[2, 2])) for pose in layout.sensors]
    np.testing.assert_allclose(tilt, [45.0, 0.0, 45.0], atol=1e-6)  # S1, S3 at 45 deg, S2 straight down
    assert layout.sensors[0].T_O_S[1, 2] > 0 > layout.sensors[2].T_O_S[1, 2]  # S1 from -y, S3 from +y
    for a, b in itertools.combinations(layout.poses, 2):
        assert heads_clearance(part.sensor, a, part.sensor, b) >= 0


# --- what the report says ------------------------------------------------------------------------------
def test_the_report_says_the_verdicts_of_the_result(results):
    result = load_result(results["search"])
    text = (results["search"] / "report.html").read_text()
    md = (results["search"] / "report.md").read_text()
    by_k = result.confident.by_k
    assert by_k  # a search with a baseline races its verdict on draws: its lines, not the first draw's hedges, decide
    for line in [confident_line(v) for v in by_k.values()]:
        assert html.escape(line) in text and line in md
    assert text.index("Verdict") < text.index("Table 1") < text.index("Where the sensors go")
    robust = (results["robustness"] / "report.md").read_text()
    assert "found_k2 k=2: " in robust and "in every cell instance" in robust and "cobot, high ends" in robust


def _rz_ry_rx(rpy_deg):
    r, p, y = np.deg2rad(rpy_deg)
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def test_the_xyz_rpy_shown_rebuilds_each_sensors_T_O_S(results):
    """docs/conventions.md: R = Rz(yaw)·Ry(pitch)·Rx(roll), built here by hand from the numbers the report prints."""
    result = load_result(results["search"])
    md = (results["search"] / "report.md").read_text()
    shown = re.findall(r"# (\w+): X Y Z \(mm\), roll pitch yaw \(deg, extrinsic xyz\)\n([-0-9., ]+)", md)
    layouts = [*(lay for _, lay in sorted(result.layouts.items())), result.baseline]
    expected = [(s.name, s.T_O_S) for lay in layouts for s in lay.sensors]
    assert [name for name, _ in shown] == [name for name, _ in expected]
    for (_, numbers), (_, T) in zip(shown, expected):
        values = np.array([float(v) for v in numbers.split(",")])
        np.testing.assert_allclose(values[:3], T[:3, 3] * 1e3, atol=1e-3)
        np.testing.assert_allclose(_rz_ry_rx(values[3:]), T[:3, :3], atol=2e-6)


def test_a_study_table_links_each_trials_report(results, tmp_path):
    from optipose.report.study import study_report

    rows = [
        {"part": "block", "k": 2, "score_mdeg": 1.25, "state": "complete"},
        {"part": "part_b", "k": 3, "score_mdeg": 0.5, "state": "failed"},
    ]
    page, md = study_report(rows, [results["search"], None], tmp_path / "study")
    text = page.read_text()
    assert text.count("<tr>") == 3 and 'class="sortable"' in text
    link = os.path.relpath(results["search"] / "report.html", tmp_path / "study")
    assert f'href="{link}"' in text and f"]({link})" in md.read_text()


# --- the report in a browser ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.exists():
        pytest.fail("no /usr/bin/chromium: run scripts/setup.sh --tests")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p, tempfile.TemporaryDirectory() as profile:
        context = p.chromium.launch_persistent_context(
            profile, executable_path=str(CHROMIUM), args=FLAGS, headless=True, viewport={"width": 1280, "height": 900}
        )
        yield context
        context.close()


def _open(browser, path: Path):
    page = browser.new_page()
    errors, requests = [], []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("request", lambda r: requests.append(r.url))
    page.goto(path.as_uri())
    page.wait_for_load_state("load")
    return page, errors, requests


@pytest.mark.parametrize(
    "kind, tables",
    [
        (
            "search",
            [
                "Table 1",
                "R (the middle of the measuring range)",
                "points per scan",
                "search settings",
            ],
        ),
        ("robustness", ["the paper's score", "R (the middle of the measuring range)"]),
        ("evaluate", ["Table 1", "points per scan"]),
    ],
)
def test_the_report_opens_offline_in_chromium_and_shows_everything(results, browser, kind, tables, tmp_path):
    path = results[kind] / "report.html"
    source = path.read_text()
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", source)  # nothing to fetch
    page, errors, requests = _open(browser, path)
    assert errors == []
    assert requests == [path.as_uri()]  # the page itself, nothing else
    n_tables = page.evaluate("() => document.querySelectorAll('table').length")
    assert n_tables == source.count("<table") and n_tables >= len(tables)
    captions = page.evaluate("() => Array.from(document.querySelectorAll('table caption')).map(c => c.innerText)")
    for fragment in tables:
        assert any(fragment in c for c in captions), (fragment, captions)
    images = page.evaluate("() => Array.from(document.images).map(i => [i.complete, i.naturalWidth])")
    assert len(images) == source.count("<img") >= 3 and all(ok and width > 0 for ok, width in images)
    copies = page.evaluate("() => document.querySelectorAll('.code button').length")
    assert copies >= 2  # each sensor's pose, and the command
    shot = tmp_path / f"{kind}.png"
    page.screenshot(path=str(shot), full_page=True)
    page.close()
    from PIL import Image

    pixels = np.asarray(Image.open(shot).convert("L"), dtype=float)
    assert pixels.shape[0] > 2000 and pixels.std() > 10  # a long page with something on it, not blank


def test_a_study_table_sorts_in_the_browser(results, browser, tmp_path):
    from optipose.report.study import study_report

    rows = [{"trial": n, "score_mdeg": s} for n, s in (("a", 3.0), ("b", 1.0), ("c", 2.0))]
    page_path, _ = study_report(rows, [results["search"], None, None], tmp_path)
    page, errors, _ = _open(browser, page_path)
    column = lambda: page.evaluate(
        "() => Array.from(document.querySelectorAll('tbody tr')).map(r => r.cells[0].innerText)"
    )  # noqa: E731
    assert column() == ["a", "b", "c"]
    page.click("th:nth-child(2)")
    assert column() == ["b", "c", "a"]
    page.click("th:nth-child(2)")
    assert column() == ["a", "c", "b"]
    assert errors == []
    page.close()


def _index_rows() -> list[dict]:
    """Rows as a study index has them (every column it writes): part C evaluated and part B searched, k = 1
    and 2 over three seeds, and one trial that failed."""
    rows = []
    for task, k, seed in itertools.product(("evaluate", "search"), (1, 2), range(3)):
        budget = "thorough" if task == "search" else ""
        part = "part_b" if task == "search" else "/data/meshes/part_c.stl"
        row = {
            "key": f"{Path(part).stem}-{task}-paper-k{k}-{budget}-s{seed}".replace("--", "-"),
            "part": part,
            "task": task,
            "objective": "paper",
            "sensors": k,
            "budget": budget,
            "seed": seed,
            "state": "complete",
            "error": "",
            "started": "2026-11-24T23:09:01.155+00:00",
            "finished": "2026-11-24T23:19:01.155+00:00",
            "seconds": 600.2,
            "cpu_seconds": 1190.5,
            "worker": "node-17.cluster:123456",
            "sensors_used": "S1S2S3"[: 2 * k],
            "score_deg": 0.00123 * (seed + 1) / k,
        }
        for axis in ("roll", "pitch", "yaw"):
            row |= {f"{axis}_median_deg": 0.0002 * (seed + 1), f"{axis}_p75_deg": 0.0004, f"{axis}_subset": "S1"}
        if task == "search":
            row |= {
                "hand_score_deg": 0.002,
                "ratio": 1.5 + seed,
                "no_worse": seed != 1,
            }
        rows.append(row)
    rows[1] = {
        **{c: None for c in rows[1]},
        **{c: rows[1][c] for c in ("key", "part", "task", "objective", "sensors", "budget", "seed")},
        "state": "failed",
        "error": "MeshError: part_c.stl: mesh has no triangles",
    }
    return rows


def _study_page(tmp_path, rows):
    import pandas as pd

    from optipose.batch.summary import summary_frame
    from optipose.report.study import study_report, summary_table

    (tmp_path / "t0").mkdir()
    (tmp_path / "t0" / "report.html").write_text("<html></html>")
    folders = [tmp_path / "t0"] + [None] * (len(rows) - 1)
    return study_report(rows, folders, tmp_path, "study s", summary_table(summary_frame(pd.DataFrame(rows))))


def test_a_study_page_shows_the_summary_first_then_one_short_row_per_trial_in_mdeg(tmp_path):
    from optipose.report.study import TRIAL_COLUMNS

    rows = _index_rows()
    page, md = _study_page(tmp_path, rows)
    text = page.read_text()
    assert text.index("Per part and setting") < text.index('id="trials"')  # the table the terminal prints, first
    summary = text[text.index("Per part and setting") : text.index('id="trials"')]
    assert (
        summary.count("<tr>") == 1 + 4 and ">1.23<" in summary and ">0/3 1F<" not in summary and ">2/3 1F<" in summary
    )
    trials = text[text.index('id="trials"') :]
    trials = trials[: trials.index("</table>")]
    assert re.findall(r"<th[^>]*>([^<]*)</th>", trials) == [h for h, _ in TRIAL_COLUMNS] + ["report"]
    assert trials.count("<tr>") == len(rows) + 1 and trials.count("<td") == (len(rows)) * (len(TRIAL_COLUMNS) + 1)
    assert f">{1e3 * rows[0]['score_deg']:.3g}<" in trials and ">part_c<" in trials  # mdeg; a mesh by its name
    assert 'href="t0/report.html"' in trials
    for row in rows:  # each trial's name unfolds all of its columns, angles in mdeg
        assert f'href="#trial-{row["key"]}"' in trials and f'<details id="trial-{row["key"]}">' in text
    details = text[text.index(f'<details id="trial-{rows[0]["key"]}">') :]
    details = details[: details.index("</details>")]
    assert (
        all(f">{c.replace('_deg', '_mdeg')}<" in details for c in rows[0])
        and f">{1e3 * rows[0]['score_deg']:.4g}<" in details
    )
    assert "MeshError: part_c.stl: mesh has no triangles" in text
    assert f"[{rows[0]['key']}](#trial-{rows[0]['key']})" in md.read_text()


def test_a_study_page_fits_1280_pixels_and_unfolds_a_trial(browser, tmp_path):
    rows = _index_rows()
    page_path, _ = _study_page(tmp_path, rows)
    page, errors, requests = _open(browser, page_path)
    assert requests == [page_path.as_uri()]
    widths = page.evaluate(
        "() => [document.documentElement.scrollWidth, document.querySelector('#trials').getBoundingClientRect().right]"
    )
    assert max(widths) <= 1280, widths  # no column out of sight
    key = rows[4]["key"]
    opened = f"() => document.getElementById('trial-{key}').open"
    assert page.evaluate(opened) is False
    page.click(f'#trials a[href="#trial-{key}"]')
    assert page.evaluate(opened) is True
    assert errors == []
    page.close()


def test_a_layouts_drawn_views_are_taken_only_when_no_older_than_its_file(tmp_path):
    import os

    from optipose.report.build import _drawn

    (tmp_path / "found_k1.toml").write_text("x")
    (tmp_path / "found_k1.png").write_bytes(b"png")
    toml = (tmp_path / "found_k1.toml").stat().st_mtime_ns
    os.utime(tmp_path / "found_k1.png", ns=(toml, toml + 1))
    assert _drawn(tmp_path, "found_k1") == b"png"
    os.utime(tmp_path / "found_k1.png", ns=(toml, toml - 10**9))  # drawn before the layout was written: stale
    assert _drawn(tmp_path, "found_k1") is None
    assert _drawn(tmp_path, "hand") is None and _drawn(None, "found_k1") is None
