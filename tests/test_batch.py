"""Batch studies (``optipose batch``): trials on every back-end give the same rows, a failing trial is
recorded and the rest go on, a killed study resumes without redoing or duplicating trials, bad input is
one line.

The study is part C's hand layout evaluated on studies/tiny-protocol.toml (6 scans, about a second per
trial once a worker is warm), plus a part whose mesh is garbage: its trials must fail, the others not.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from optipose.batch.index import read_index
from optipose.batch.pools import DaskPool, LokyPool, SerialPool, make_pool
from optipose.batch.spec import load_study_spec, study_from_table
from optipose.batch.study import run_study
from optipose.batch.summary import summary_frame
from optipose.batch.threads import THREAD_VARIABLES, current_caps, plan
from optipose.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]
TINY = REPO / "studies" / "tiny-protocol.toml"
RESULTS = ["sensors_used", "score_deg"] + [
    f"{a}_{s}" for a in ("roll", "pitch", "yaw") for s in ("median_deg", "p75_deg", "subset")
]


def _study_file(folder: Path, parts: list[str], sensors=(1, 2), seeds=(0, 1)) -> Path:
    (folder / "broken.stl").write_text("this is not an stl file\n")
    path = folder / "study.toml"
    path.write_text(
        f'name = "t"\n[grid]\nparts = {parts!r}\ntasks = ["evaluate"]\nobjectives = ["{TINY}"]\n'
        f"sensors = {list(sensors)!r}\nseeds = {list(seeds)!r}\n".replace("'", '"')
    )
    return path


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    return load_study_spec(_study_file(tmp_path_factory.mktemp("study"), ["part_c", "broken.stl"]))


# -- the study file ---------------------------------------------------------------------------------------
def test_a_grid_is_every_combination_and_budgets_belong_to_searches(tmp_path):
    spec = study_from_table(
        {
            "grid": {
                "parts": ["part_a", "part_b"],
                "tasks": ["search", "evaluate"],
                "sensors": [1, 3],
                "budgets": ["quick", "default"],
                "seeds": [0, 7],
            }
        }
    )
    # 2 parts x 2 k x 2 seeds x (2 budgets for search + 1 for evaluate)
    assert len(spec.trials) == 2 * 2 * 2 * 3
    assert {t.budget for t in spec.trials if t.task == "evaluate"} == {""}
    assert {t.objective for t in spec.trials} == {"paper"}
    assert len({t.key for t in spec.trials}) == len(spec.trials)
    with pytest.raises(ConfigError, match="task 'robustness' was retired with the band of conditions"):
        study_from_table({"trials": [{"part": "part_c", "task": "robustness", "sensors": 2}]})


@pytest.mark.parametrize(
    "table, fragment",
    [
        ({"grid": {"parts": ["part_a"], "seed": [1]}}, "unknown key(s) seed"),
        ({"grid": {"parts": ["part_a"]}, "budget": "quick"}, "unknown key(s) budget"),
        ({"grid": {"parts": ["part_a"], "sensors": ["two"]}}, "grid.sensors: expected an integer, got 'two'"),
        ({"grid": {"parts": ["part_a"], "seeds": []}}, "grid.seeds is empty"),
        ({"grid": {"parts": []}}, "grid.parts is empty"),
        ({}, "no trials"),
        ({"grid": {"parts": ["part_z"]}}, "unknown part 'part_z'"),
        ({"grid": {"parts": ["*.nothing"]}}, "matches no file"),
        ({"grid": {"parts": ["part_a"], "budgets": ["huge"]}}, "unknown budget 'huge'"),
        ({"grid": {"parts": ["part_a"], "tasks": ["dance"]}}, "unknown task 'dance'"),
        ({"grid": {"parts": ["part_a"], "objectives": ["nope"]}}, "unknown objective 'nope'"),
        ({"trials": [{"task": "search"}]}, "needs 'part'"),
    ],
)
def test_a_bad_study_file_names_the_problem(tmp_path, table, fragment):
    with pytest.raises(ConfigError, match=None) as err:
        study_from_table(table, where="s.toml", base=tmp_path)
    assert fragment in str(err.value)


# -- where the cores go -----------------------------------------------------------------------------------
def test_the_cores_are_split_between_the_workers():
    assert plan(1, cores=2) == plan(1, cores=2, trial_jobs=2) and plan(1, cores=2).trial_jobs == 2
    assert (plan(2, cores=2).trial_jobs, plan(2, cores=2).threads) == (1, 1)
    assert plan(3, cores=2).threads == 1 and plan(2, cores=16).threads == 8
    assert plan(2, cores=2, trial_jobs=3).trial_jobs == 3


def test_joblib_workers_start_with_their_threads_capped():
    pool = LokyPool(2, trial_jobs=1)
    try:
        seen = pool.result(pool.submit(current_caps))
    finally:
        pool.close()
    assert seen == dict.fromkeys(THREAD_VARIABLES, "1")


# -- the same rows on every back-end; failing trials recorded --------------------------------------------
@pytest.fixture(scope="module")
def serial(study, tmp_path_factory):
    folder = tmp_path_factory.mktemp("serial") / "t"
    return folder, run_study(study, folder, SerialPool()).frame()


@pytest.fixture(scope="module")
def serial_index(serial):
    return serial[1]


def test_failing_trials_are_recorded_and_the_others_complete(serial, study):
    folder, index = serial
    rows = index.set_index("key")
    assert len(rows) == len(study.trials) == 8
    broken = rows[rows.part.str.endswith("broken.stl")]
    assert list(broken.state) == ["failed"] * 4 and broken.error.str.startswith("MeshError").all()
    assert broken.folder.eq("").all() and broken.score_deg.isna().all()
    done = rows[rows.part == "part_c"]
    assert list(done.state) == ["complete"] * 4 and done.error.eq("").all()
    on_disk = sorted(p.name for p in (folder / "trials").iterdir())
    assert on_disk == sorted(done.index)  # a folder per complete trial, none for a failed one, no leftovers
    assert all((folder / f / "per_scan.parquet").is_file() for f in done.folder)


def test_complete_rows_are_the_evaluators_own_answer(serial_index):
    # an independent path: the one-call evaluate() on the same part, objective and seed
    from optipose.evaluate.evaluator import evaluate
    from optipose.model.part import load_part

    result = evaluate(load_part("part_c"), objective=str(TINY), seed=1, jobs=1)
    for k in (1, 2):
        row = serial_index[
            (serial_index.part == "part_c") & (serial_index.sensors == k) & (serial_index.seed == 1)
        ].iloc[0]
        choice = result.table[k - 1]
        assert row.sensors_used == choice.name
        assert row.score_deg == pytest.approx(np.rad2deg(choice.score), rel=1e-12)
        assert row.roll_median_deg == pytest.approx(np.rad2deg(choice.axes[0].median), rel=1e-12)


@pytest.mark.parametrize("backend", ["joblib", "dask"])
def test_two_workers_give_the_rows_of_one(serial_index, study, tmp_path, backend):
    pool = make_pool(2, backend)
    assert isinstance(pool, LokyPool if backend == "joblib" else DaskPool) and pool.plan.trial_jobs == 1
    try:
        assert pool.result(pool.submit(current_caps)) == dict.fromkeys(THREAD_VARIABLES, "1")  # no oversubscription
        index = run_study(study, tmp_path / "t", pool).frame()
        workers = set(index.loc[index.state == "complete", "worker"])
    finally:
        pool.close()
    pd.testing.assert_frame_equal(index[["key", "state", *RESULTS]], serial_index[["key", "state", *RESULTS]])
    assert os.getpid() not in {int(w.split(":")[1]) for w in workers}  # ran in worker processes
    # index.csv says what index.parquet says
    csv = pd.read_csv(tmp_path / "t" / "index.csv", keep_default_na=False)
    assert list(csv.key) == list(index.key) and list(csv.state) == list(index.state)


def test_the_summary_groups_trials_per_part_and_setting(serial_index):
    summary = summary_frame(serial_index).set_index(["part", "sensors"])
    assert summary.loc[("part_c", 1), "complete"] == 2 and summary.loc[("part_c", 1), "failed"] == 0
    assert summary.loc[("broken", 2), "failed"] == 2 and summary.loc[("broken", 2), "complete"] == 0
    scores = serial_index[(serial_index.part == "part_c") & (serial_index.sensors == 2)].score_deg
    assert summary.loc[("part_c", 2), "score_median_deg"] == pytest.approx(scores.median())
    assert summary.loc[("part_c", 2), "score_worst_deg"] == pytest.approx(scores.max())


def test_the_study_command_prints_the_table_and_refuses_other_folders(serial, tmp_path):
    folder, index = serial
    shown = subprocess.run(
        [sys.executable, "-m", "optipose", "study", folder],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "COLUMNS": "120"},
    )
    assert shown.returncode == 0, shown.stderr
    rows = [line.split() for line in shown.stdout.splitlines() if line.strip().startswith(("part_c", "broken"))]
    assert [(r[0], r[3], r[4]) for r in rows] == [
        ("part_c", "1", "2/2"),
        ("part_c", "2", "2/2"),
        ("broken", "1", "0/2"),
        ("broken", "2", "0/2"),
    ]
    score = index[(index.part == "part_c") & (index.sensors == 1)].score_deg.median()
    assert rows[0][5] == f"{1e3 * score:.2f}"  # mdeg, the median over the seeds
    page = (Path(folder) / "study.html").read_text()  # the study report: the table above, then one row per trial
    trials = page[page.index('id="trials"') :]
    trials = trials[: trials.index("</table>")]
    assert page.index("Per part and setting") < page.index('id="trials"') and f">{1e3 * score:.2f}<" in page
    assert trials.count("<tr") == len(index) + 1 and all(f'href="#trial-{key}"' in trials for key in index.key)
    assert all(f'<details id="trial-{key}">' in page for key in index.key)  # each with all of its columns
    other = subprocess.run(
        [sys.executable, "-m", "optipose", "study", tmp_path], capture_output=True, text=True, timeout=120
    )
    assert (
        other.returncode == 2
        and other.stderr.startswith("optipose: error:")
        and "not an optipose study" in other.stderr
    )
    # `optipose report` on a study folder writes the same study report
    (Path(folder) / "study.html").unlink()
    made = subprocess.run(
        [sys.executable, "-m", "optipose", "report", folder], capture_output=True, text=True, timeout=120
    )
    assert made.returncode == 0, made.stderr
    assert (Path(folder) / "study.html").read_text() == page and (Path(folder) / "study.md").is_file()


class _DyingPool(SerialPool):
    """Runs trials here, but reports the worker of ``deaths[key]`` trials dead that many times (and, as a
    dead worker would, leaves no folder)."""

    def __init__(self, folder: Path, deaths: dict):
        super().__init__()
        self.folder, self.deaths, self.runs = folder, dict(deaths), {}

    def result(self, future):
        record = super().result(future)
        self.runs[record.key] = self.runs.get(record.key, 0) + 1
        if self.deaths.get(record.key, 0) > 0:
            self.deaths[record.key] -= 1
            shutil.rmtree(self.folder / record.folder)
            raise BrokenProcessPool("A process in the process pool was terminated abruptly")
        return record


def test_a_dead_worker_costs_its_trial_one_retry_then_it_fails(tmp_path):
    spec = study_from_table(
        {
            "grid": {
                "parts": ["part_c"],
                "tasks": ["evaluate"],
                "objectives": [str(TINY)],
                "sensors": [1],
                "seeds": [0, 1, 2],
            }
        }
    )
    once, twice, fine = (t.key for t in spec.trials)
    pool = _DyingPool(tmp_path / "t", {once: 1, twice: 2})
    index = run_study(spec, tmp_path / "t", pool).frame().set_index("key")
    assert pool.runs == {once: 2, twice: 2, fine: 1}
    assert (index.loc[once, "state"], index.loc[fine, "state"]) == ("complete", "complete")
    assert index.loc[twice, "state"] == "failed" and index.loc[twice, "error"].startswith(
        "worker died: BrokenProcessPool"
    )
    assert sorted(p.name for p in (tmp_path / "t" / "trials").iterdir()) == sorted([once, fine])


# -- killed, interrupted and resumed ----------------------------------------------------------------------
def _sigint_as_in_a_terminal() -> None:
    """A shell starts background jobs with SIGINT ignored, and Python keeps an ignored SIGINT ignored: a
    test suite run as one (``pytest &``, ``nohup``) would hand that to the study and its Ctrl-C would do
    nothing (the study ran to the end with exit 0). The study gets SIGINT as a terminal gives it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _batch(*args, **kw):
    return subprocess.Popen(
        [sys.executable, "-m", "optipose", "batch", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=_sigint_as_in_a_terminal,
        **kw,
    )


def _wait_for_complete(folder: Path, proc, n: int, timeout: float = 240.0) -> pd.DataFrame:
    """The index once ``n`` trials are complete (read as any reader would, while the study runs)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if (folder / "index.parquet").is_file():
            index = read_index(folder)
            if (index.state == "complete").sum() >= n:
                return index
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    raise AssertionError("the study did not get going")


def _finished_trials(folder: Path) -> dict:
    """key -> (trial.toml as written, its mtime): what a re-run would change."""
    out = {}
    for path in (folder / "trials").glob("*/trial.toml"):
        out[path.parent.name] = (tomllib.loads(path.read_text()), path.stat().st_mtime_ns)
    return out


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_a_killed_study_resumes_without_redoing_or_duplicating_trials(tmp_path, sig):
    study_file = _study_file(tmp_path, ["part_c"], sensors=(1, 2, 3), seeds=(0, 1))  # 6 trials
    folder = tmp_path / "out"
    proc = _batch(study_file, "--out", folder, "--jobs", 1)
    _wait_for_complete(folder, proc, 1)
    os.killpg(proc.pid, sig) if sig == signal.SIGKILL else os.kill(proc.pid, sig)
    _, err = proc.communicate(timeout=60)
    if sig == signal.SIGINT:
        assert proc.returncode == 130 and "--resume" in err and "Traceback" not in err
    index = read_index(folder)  # whole, never half-written
    assert len(index) == 6 and index.key.is_unique
    if sig == signal.SIGINT:
        assert set(index.state) <= {"complete", "pending"}  # nothing left 'running' after Ctrl-C
    before = _finished_trials(folder)
    assert 1 <= len(before) < 6, "the study should have been stopped part-way"

    resumed = subprocess.run(
        [sys.executable, "-m", "optipose", "batch", study_file, "--out", folder, "--resume", "--jobs", "1"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert resumed.returncode == 0, resumed.stderr
    index = read_index(folder)
    assert len(index) == 6 and index.key.is_unique and (index.state == "complete").all()
    after = _finished_trials(folder)
    assert set(after) == set(index.key)
    for key, (saved, mtime) in before.items():  # finished before the kill: not run again
        assert after[key] == (saved, mtime)
        row = index[index.key == key].iloc[0]
        assert (row.started, row.worker) == (saved["started"], saved["worker"])
    assert not list((folder / "trials").glob(".tmp-*"))


# -- bad input on the command line: one line, exit 2, nothing written -------------------------------------
@pytest.mark.parametrize(
    "text, args, fragment",
    [
        ('name = "t"\n[grid]\nparts = ["part_c"]\ncolour = "red"\n', [], "unknown key(s) colour"),
        ('name = "t"\n[grid]\nparts = ["part_c"]\nseeds = "zero"\n', [], "expected an integer, got 'zero'"),
        ('name = "t"\n[grid]\nparts = ["part_c"]\nsensors = []\n', [], "grid.sensors is empty"),
        ('name = "t"\n[grid]\nparts = ["part_q"]\n', [], "unknown part 'part_q'"),
        ('name = "t"\n[grid\n', [], "study file"),
        (
            'name = "t"\n[grid]\nparts = ["part_c"]\n',
            ["--backend", "dask", "--scheduler", "tcp://127.0.0.1:9"],
            "cannot reach the Dask scheduler",
        ),
        ('name = "t"\n[grid]\nparts = ["part_c"]\n', ["--backend", "spark"], "unknown back-end 'spark'"),
        (
            'name = "t"\n[grid]\nparts = ["part_c"]\n',
            ["--scheduler", "tcp://127.0.0.1:9"],
            "--scheduler needs --backend dask",
        ),
    ],
)
def test_bad_input_is_one_line_and_nothing_is_written(tmp_path, text, args, fragment):
    (tmp_path / "s.toml").write_text(text)
    result = subprocess.run(
        [sys.executable, "-m", "optipose", "batch", "s.toml", "--out", "out", *args],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith("optipose: error:") and fragment in lines[0], lines[0]
    assert not (tmp_path / "out").exists() and not (tmp_path / "results").exists()


def test_an_existing_study_is_not_overwritten_without_resume(tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "index.parquet").write_bytes(b"old")
    (tmp_path / "s.toml").write_text('name = "t"\n[grid]\nparts = ["part_c"]\n')
    result = subprocess.run(
        [sys.executable, "-m", "optipose", "batch", "s.toml", "--out", "out"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert result.returncode == 2 and "--resume" in result.stderr and "Traceback" not in result.stderr
    assert (tmp_path / "out" / "index.parquet").read_bytes() == b"old"
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["index.parquet"]


def test_the_shipped_studies_load():
    reference = load_study_spec(REPO / "studies" / "reference.toml")
    assert {(t.part, t.sensors, t.budget, t.task) for t in reference.trials} == {
        (p, k, "default", "search") for p in ("part_a", "part_b", "part_c") for k in (1, 2, 3)
    }
    assert len(load_study_spec(REPO / "studies" / "tiny.toml").trials) == 4


# -- the other tasks: each row is what its folder says ----------------------------------------------------
def test_search_trials_report_their_folders(tmp_path):
    from optipose.io import load_result

    spec = study_from_table(
        {"trials": [{"part": "part_c", "task": "search", "sensors": 1, "budget": "quick", "seed": 3}]},
        base=tmp_path,
    )
    index = run_study(spec, tmp_path / "t", SerialPool()).frame().set_index("task")
    assert (index.state == "complete").all(), index.error

    search = index.loc["search"]
    verdict = {v.k: v for v in load_result(tmp_path / "t" / search.folder).verdicts()}[1]
    assert search.score_deg == pytest.approx(np.rad2deg(verdict.found.score), rel=1e-12)
    assert search.hand_score_deg == pytest.approx(np.rad2deg(verdict.reference.score), rel=1e-12)
    assert search.ratio == pytest.approx(verdict.ratio) and search.no_worse == verdict.no_worse
    assert search.sensors_used == "F1"


def test_no_report_leaves_the_study_without_its_report(tmp_path):
    study_file = _study_file(tmp_path, ["part_c"], sensors=(1,), seeds=(0,))
    done = subprocess.run(
        [sys.executable, "-m", "optipose", "batch", study_file, "--out", tmp_path / "out", "--no-report"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "out" / "index.parquet").is_file() and not (tmp_path / "out" / "study.html").exists()


@pytest.mark.parametrize("how", ["numba", "search"])
def test_a_ctrl_c_a_trial_kept_to_itself_still_stops_the_study(tmp_path, monkeypatch, how):
    """Ctrl-C while compiled code runs arrives as a SystemError (numba), and a search ends its own stage on it
    and returns: either way the trial is not a failure to record and go past, the study stops."""
    from types import SimpleNamespace

    from optipose.batch import trial as trial_module
    from optipose.batch.spec import TrialSpec
    from optipose.batch.threads import Plan

    def interrupted(*_):
        if how == "numba":
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt as exc:
                raise SystemError("returned a result with an exception set") from exc
        return SimpleNamespace(outcome=SimpleNamespace(interrupted=True), validated=False)

    monkeypatch.setattr(
        trial_module, "cap_threads", lambda threads: None
    )  # this process's thread caps stay as they are
    if how == "numba":
        monkeypatch.setitem(trial_module.TASK_RUNNERS, "evaluate", interrupted)
    else:
        import optipose.search.pipeline as pipeline

        monkeypatch.setattr(pipeline, "run", interrupted)
    spec = TrialSpec(
        "part_c", "evaluate" if how == "numba" else "search", "paper", 1, "" if how == "numba" else "quick", 0
    )
    with pytest.raises(KeyboardInterrupt):
        trial_module.run_trial(spec, str(tmp_path), Plan(workers=1, trial_jobs=1, threads=1))
    assert not any((tmp_path / "trials").iterdir())  # nothing half-written stays behind


def test_a_ctrl_c_a_trial_swallowed_whole_still_stops_the_study(tmp_path, monkeypatch):
    """A Ctrl-C that something in a trial catches and goes past (no exception reaches the study) is noted by the
    study's handler: the trial is not recorded complete, and the study stops."""
    from optipose import errors
    from optipose.batch import trial as trial_module

    def swallowing(*_):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)  # the handler runs here
        except KeyboardInterrupt:
            pass

    monkeypatch.setattr(trial_module, "cap_threads", lambda threads: None)
    monkeypatch.setitem(trial_module.TASK_RUNNERS, "evaluate", swallowing)
    monkeypatch.setattr(errors, "_INTERRUPTS", [])
    before = signal.getsignal(signal.SIGINT)
    try:
        # as in a terminal: a run in the background of a shell starts with SIGINT ignored, which note_interrupts keeps
        signal.signal(signal.SIGINT, signal.default_int_handler)
        errors.note_interrupts()
        with pytest.raises(KeyboardInterrupt):
            run_study(
                load_study_spec(_study_file(tmp_path, ["part_c"], sensors=(1,), seeds=(0, 1))),
                tmp_path / "out",
                SerialPool(),
            )
    finally:
        signal.signal(signal.SIGINT, before)
    index = read_index(tmp_path / "out")
    assert (index.state == "pending").all() and not list((tmp_path / "out" / "trials").iterdir())
