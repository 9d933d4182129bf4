"""Faults: a killed evaluation, a full disk and a result folder that cannot be resumed. Every file a
result folder holds is whole (written to a temporary file and renamed, :mod:`optipose.files`); a write
that fails leaves what was written before as it was; ``--resume`` of anything but a search folder this
version wrote is one line, exit 2."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cli_checks import SMALL_SEARCH, assert_one_line_error, run
from optipose.files import atomic_path, is_temporary

SHORT = '[protocol]\nsequences = ["R"]\nstep_deg = 4.0\n'  # two scans: an evaluation in seconds

# `optipose …` with DataFrame.to_csv failing for one file name, as a full disk does: part of the file
# reaches the disk, then ENOSPC
FULL_DISK = """
import errno, sys
import pandas as pd
real = pd.DataFrame.to_csv
def full(self, path=None, *args, **kwargs):
    if path is not None and sys.argv[1] in str(path):
        real(self.head(1), path, *args, **kwargs)
        raise OSError(errno.ENOSPC, "No space left on device", str(path))
    return real(self, path, *args, **kwargs)
pd.DataFrame.to_csv = full
from optipose.cli.app import app
app(sys.argv[2:], prog_name="optipose")
"""


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("faults")
    (d / "short.toml").write_text(SHORT)
    (d / "full_disk.py").write_text(FULL_DISK)
    return d


@pytest.fixture(scope="module")
def complete(files):
    """An uninterrupted evaluation of part B's hand layout, seed 5: what every interrupted one is held to."""
    out = files / "complete"
    result = run("evaluate", "part_b", "--objective", str(files / "short.toml"), "--seed", "5", "--out", str(out))
    assert result.returncode == 0, result.stderr
    return out


def _check_whole(folder: Path, complete: Path) -> list[str]:
    """Every file in ``folder`` but a writer's temporary one is whole: the data files as the uninterrupted
    run wrote them, config.toml parses to the same settings, the report's pages end and its figures load.
    Returns the names checked."""
    from PIL import Image

    checked = []
    for path in sorted(p for p in folder.rglob("*") if p.is_file() and not is_temporary(p)):
        name = str(path.relative_to(folder))
        twin = complete / name
        if path.suffix == ".csv":
            assert path.read_bytes() == twin.read_bytes(), name
        elif path.suffix == ".parquet":
            pd.testing.assert_frame_equal(pd.read_parquet(path), pd.read_parquet(twin))
        elif path.name == "config.toml":
            mine, theirs = tomllib.loads(path.read_text()), tomllib.loads(twin.read_text())
            for table in (mine, theirs):
                table.pop("timings_s")
            assert mine == theirs
        elif path.suffix == ".html":
            assert path.read_text().rstrip().endswith("</html>"), name
        elif path.suffix == ".md":
            assert path.read_text().splitlines()[-1] == twin.read_text().splitlines()[-1], name
        elif path.suffix == ".png":
            Image.open(path).load()
        else:
            raise AssertionError(f"an unexpected file {name}")
        checked.append(name)
    return checked


@pytest.mark.parametrize("kill_when", ["per_scan.csv", "config.toml", "report_figures"])
def test_an_evaluation_killed_part_way_leaves_only_whole_files(files, complete, kill_when):
    # SIGKILL the moment `kill_when` appears: writing the tables, starting the report, writing its figures
    out = files / f"killed-{kill_when}"
    args = [
        "-m",
        "optipose",
        "evaluate",
        "part_b",
        "--objective",
        str(files / "short.toml"),
        "--seed",
        "5",
        "--out",
        str(out),
    ]
    process = subprocess.Popen([sys.executable, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not (out / kill_when).exists() and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.0005)
        os.kill(process.pid, signal.SIGKILL)
    finally:
        process.wait(timeout=30)
    assert process.returncode == -signal.SIGKILL  # killed, not finished
    checked = _check_whole(out, complete)
    assert kill_when in checked or any(c.startswith(kill_when) for c in checked) or kill_when == "report_figures"
    if (out / "config.toml").exists():  # written last: everything else of the evaluation is there
        from optipose.io import load_result

        assert load_result(out).table == load_result(complete).table


def test_a_full_disk_is_one_line_and_keeps_what_was_written(files, complete):
    out = files / "full"
    result = subprocess.run(
        [
            sys.executable,
            str(files / "full_disk.py"),
            "table1.csv",
            "evaluate",
            "part_b",
            "--objective",
            str(files / "short.toml"),
            "--seed",
            "5",
            "--out",
            str(out),
            "--no-report",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert_one_line_error(result, f"No space left on device: {out / 'table1.csv'}")
    present = sorted(p.name for p in out.iterdir())
    assert present == [
        "per_scan.csv",
        "per_scan.parquet",
        "points.csv",
        "stats.csv",
    ]  # no half table1.csv, no temporary file
    _check_whole(out, complete)


def test_a_failed_write_keeps_the_file_it_would_have_replaced(tmp_path, monkeypatch):
    from optipose.io.search import SearchFolder, load_cache
    from optipose.search.problem import Violation
    from optipose.search.records import EvalState, Evaluation

    folder = SearchFolder(tmp_path)
    history = [
        Evaluation(i, "greedy k=1", 1, (0.5,) * 6, EvalState.FEASIBLE, 1.0 / (i + 1), 1.0 / (i + 1)) for i in range(3)
    ]
    cache = {(0.5,) * 6: Violation("clearance", 0.25)}
    folder.flush(history, cache, 2)
    before = {name: (tmp_path / name).read_bytes() for name in ("history.csv", "cache.npz")}
    real = pd.DataFrame.to_csv

    def full(self, path=None, *args, **kwargs):
        real(self.head(1), path, *args, **kwargs)
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(pd.DataFrame, "to_csv", full)
    with pytest.raises(OSError, match="No space left") as caught:
        folder.flush(history * 2, {**cache, (0.25,) * 6: Violation("points", 1.0)}, 2)
    assert caught.value.filename == str(tmp_path / "history.csv")  # the file the user knows, not the temporary one
    assert {name: (tmp_path / name).read_bytes() for name in before} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache.npz", "history.csv"]
    assert list(load_cache(tmp_path, 2)) == [(0.5,) * 6]
    with pytest.raises(ValueError), atomic_path(tmp_path / "history.csv") as tmp:  # any error: the same
        tmp.write_text("half")
        raise ValueError("stop")
    assert (tmp_path / "history.csv").read_bytes() == before["history.csv"]


# -- --resume ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def search_config(tmp_path_factory) -> dict:
    """A search folder's config.toml as this version writes it (part B, the paper objective)."""
    from optipose.evaluate.objective import load_objective
    from optipose.io.search import SearchFolder
    from optipose.model.part import load_part
    from optipose.search.budgets import config_from_budget

    folder = tmp_path_factory.mktemp("search_config")
    SearchFolder(folder).start(
        load_part("part_b"), load_objective("paper").in_cell("ideal"), config_from_budget("quick", (1,)), "quick", 0, 1
    )
    return tomllib.loads((folder / "config.toml").read_text())


def _search_folder(root: Path, name: str, table: dict | None = None, text: str | bytes | None = None) -> Path:
    import tomli_w

    folder = root / name
    folder.mkdir()
    if table is not None:
        text = tomli_w.dumps(table)
    if text is not None:
        (folder / "config.toml").write_bytes(text if isinstance(text, bytes) else text.encode())
    return folder


def test_a_search_folder_of_this_version_is_resumable(search_config, tmp_path):
    from optipose.cli.search import _resumed_settings
    from optipose.io.folders import RESULT_FORMAT

    assert search_config["format"] == RESULT_FORMAT and search_config["command"] == "search"
    part, config, budget, seed, objective, units = _resumed_settings(_search_folder(tmp_path, "ok", search_config))
    assert part.endswith("part_b/part.toml") and (config.sensors, budget, seed, objective.name) == (
        (1,),
        "quick",
        0,
        "paper",
    )
    assert units is None  # loaded without --units


def _older(table: dict, **changes) -> dict:
    """The table as an older optipose wrote it: no format, and ``changes`` (None: the key removed)."""
    out = {k: v for k, v in table.items() if k != "format"}
    for key, value in changes.items():
        if value is None:
            out.pop(key)
        else:
            out[key] = value
    return out


@pytest.mark.parametrize(
    "case, fragment",
    [
        ("a_file", "not a folder"),
        ("empty", "no config.toml there (not a search result folder)"),
        ("garbage", "its config.toml is damaged"),
        ("broken_toml", "its config.toml is damaged"),
        ("evaluation", "holds a 'evaluate' result, not a search"),
        ("newer", "written by another optipose (optipose 0.1.0, result format 99)"),
        ("older_unknown_key", "cannot be resumed by this version: unknown search setting(s) retired_knob"),
        ("older_no_objective", "cannot be resumed by this version: no 'objective_file' in it"),
        (
            "older_bad_objective",
            "cannot be resumed by this version: objective [registration]: max_iterations must be a number",
        ),
    ],
)
def test_resume_of_a_folder_it_cannot_take_is_one_line(search_config, tmp_path, case, fragment):
    cases = {
        "empty": {},
        "garbage": {"text": np.random.default_rng(1).bytes(300)},
        "broken_toml": {"text": 'command = "search"\n[search\n'},
        "evaluation": {"table": {**search_config, "command": "evaluate"}},
        "newer": {"table": {**search_config, "format": 99}},
        "older_unknown_key": {"table": _older(search_config, search={**search_config["search"], "retired_knob": 3})},
        "older_no_objective": {"table": _older(search_config, objective_file=None)},
        "older_bad_objective": {
            "table": _older(search_config, objective_file='[registration]\nmax_iterations = "many"\n')
        },
    }
    if case == "a_file":
        target = tmp_path / "a_file"
        target.write_text("not a folder\n")
    else:
        target = _search_folder(tmp_path, case, **cases[case])
    assert_one_line_error(run("search", "--resume", str(target)), fragment)


# -- a killed search --------------------------------------------------------------------------------------
def _search(files: Path, out: Path, *more: str) -> list[str]:
    return [
        "-m",
        "optipose",
        "search",
        "part_b",
        "--sensors",
        "1",
        "--search-config",
        str(files / "small_search.toml"),
        "--objective",
        str(files / "short.toml"),
        "--seed",
        "4",
        "--out",
        str(out),
        "--no-report",
        *more,
    ]


@pytest.mark.slow
def test_a_search_killed_part_way_resumes_to_the_uninterrupted_result(files):
    # measured: 13 s uninterrupted; killed at the first flush of its history (100 evaluations of ~160 when
    # it flushed every 100; now no sooner than 10 s apart, so here at the end of the surrogate
    # stage, before the ICP validation), then resumed; 23-30 s in all at nice 19 on the shared machine
    (files / "small_search.toml").write_text(SMALL_SEARCH)
    whole, killed = files / "search_whole", files / "search_killed"
    done = subprocess.run([sys.executable, *_search(files, whole)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    process = subprocess.Popen(
        [sys.executable, *_search(files, killed)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        while not (killed / "history.csv").exists() and process.poll() is None:
            time.sleep(0.001)
        os.kill(process.pid, signal.SIGKILL)
    finally:
        process.wait(timeout=30)
    assert process.returncode == -signal.SIGKILL and not (killed / "comparison.csv").exists()  # killed part-way
    # the first flush, whole (every 100 evaluations and at most every 10 s, or at the end of the surrogate stage)
    assert 100 <= len(pd.read_csv(killed / "history.csv")) <= len(pd.read_csv(whole / "history.csv"))
    resumed = run("search", "--resume", str(killed), "--no-report")
    assert resumed.returncode == 0, resumed.stderr
    for name in ("history.csv", "comparison.csv", "surrogate_scores.csv", "layouts/found_k1.toml", "layouts/hand.toml"):
        assert (killed / name).read_bytes() == (whole / name).read_bytes(), name
