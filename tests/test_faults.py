"""Faults a user meets outside the happy path, each one line ``optipose: error: …`` on stderr, exit 2, and
nothing computed lost: a Dask scheduler address that is malformed, where nothing listens, where a silent
or foreign service (a web server: a Dask dashboard) answers, a cluster that loses every worker; an output
folder that cannot be written (refused before the work); a damaged result file; and the leftovers of dead
workers removed when a study ends. A mesh in inches keeps its units in the result folder (the report's
views load it again), and a verdict built on failed registrations says so instead of ranking."""

from __future__ import annotations

import http.server
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cli_checks import assert_one_line_error

SHORT = '[protocol]\nsequences = ["R"]\nstep_deg = 4.0\n'  # two scans: an evaluation in seconds
FAST_CHECK = {"OPTIPOSE_SCHEDULER_TIMEOUT": "2"}  # the check's default is 10 s a step; 2 s is plenty on loopback


def run(*args, env: dict | None = None, timeout: float = 120):
    return subprocess.run(
        [sys.executable, "-m", "optipose", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **(env or {})},
    )


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("faults")
    (d / "short.toml").write_text(SHORT)
    (d / "study.toml").write_text(
        'name = "f"\n[grid]\nparts = ["part_b"]\ntasks = ["evaluate"]\nobjectives = ["short.toml"]\n'
        "sensors = [1]\nseeds = [0, 1, 2]\n"
    )
    return d


# -- the scheduler address ----------------------------------------------------------------------------------
@pytest.fixture
def silent_port():
    """A port that accepts connections and never says a word."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held = []
    thread = threading.Thread(target=lambda: [held.append(server.accept()) for _ in iter(int, 1)], daemon=True)
    thread.start()
    yield server.getsockname()[1]
    server.close()
    for conn, _ in held:
        conn.close()


@pytest.fixture
def http_port():
    """A web server on loopback (what a Dask dashboard is)."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield server.server_address[1]
    server.shutdown()
    server.server_close()


@pytest.fixture
def banner_port():
    """A foreign service that speaks first (an SSH server's banner): Dask read such an answer as a frame's length."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")
            conn.close()

    threading.Thread(target=serve, daemon=True).start()
    yield server.getsockname()[1]
    server.close()


def _closed_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


@pytest.mark.parametrize(
    "address, fragment",
    [
        ("bogus://x", "unknown scheme 'bogus'"),
        (":notaport", "'notaport' is not a port number"),
        ("tcp://127.0.0.1:99999", "'99999' is not a port number"),
        ("tcp://:8786", "no host"),
        ("closed", "(Connection refused)"),
        ("silent", "said nothing in 2 s"),
        ("http", "said nothing in 2 s"),
        ("banner", "it answered 'SSH-2.0-'"),
        ("tls", "cannot reach the Dask scheduler at tls://127.0.0.1:"),  # no TLS settings in Dask's config here
    ],
)
def test_a_scheduler_that_is_not_one_is_one_line_before_the_study_folder(files, request, address, fragment):
    ports = {"silent": "silent_port", "http": "http_port", "banner": "banner_port"}
    if address == "tls":
        address = f"tls://127.0.0.1:{request.getfixturevalue('silent_port')}"
    elif address in ports:
        address = f"tcp://127.0.0.1:{request.getfixturevalue(ports[address])}"
    elif address == "closed":
        address = f"tcp://127.0.0.1:{_closed_port()}"
    out = files / f"never-{abs(hash(address))}"
    t0 = time.monotonic()
    result = run(
        "batch",
        str(files / "study.toml"),
        "--backend",
        "dask",
        "--scheduler",
        address,
        "--out",
        str(out),
        env=FAST_CHECK,
    )
    seconds = time.monotonic() - t0
    assert_one_line_error(result, fragment)
    assert not out.exists()  # refused before the study folder is made
    assert seconds < 60  # bounded by the check's own waits, not Dask's (which waited for ever on a silent port)


def test_the_check_accepts_a_real_scheduler_and_says_what_a_dashboard_is():
    from distributed import LocalCluster

    from optipose.batch.scheduler import check_scheduler, split_address
    from optipose.errors import ConfigError

    with LocalCluster(
        n_workers=0, processes=False, protocol="tcp://", host="127.0.0.1", dashboard_address=":0"
    ) as cluster:
        address = cluster.scheduler_address
        assert check_scheduler(address, timeout=5) == address
        assert check_scheduler(address.removeprefix("tcp://"), timeout=5) == address  # HOST:PORT is tcp://
    assert split_address("tls://[::1]:8786") == ("tls", "::1", 8786)
    with pytest.raises(ConfigError, match="8787 is its dashboard"):
        server = socket.socket()
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        with server:
            check_scheduler(f"127.0.0.1:{server.getsockname()[1]}", timeout=0.5)


# -- a cluster that loses its workers -------------------------------------------------------------------------
def _dask(*args: str, log: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_" + args[0], *args[1:]],
        stdout=subprocess.DEVNULL,
        stderr=log.open("w"),
        start_new_session=True,
    )


def _stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGKILL)
    process.wait(timeout=30)


def _complete(study: Path) -> bool:
    """Whether the study's index has a complete trial (the index is replaced whole: never read half-written)."""
    try:
        return (pd.read_csv(study / "index.csv").state == "complete").any()
    except (FileNotFoundError, pd.errors.EmptyDataError):
        return False


def test_a_cluster_without_workers_stops_the_study_in_one_line_and_keeps_what_finished(files, tmp_path):
    # a scheduler and one single-threaded worker; the worker is killed once the index has a complete trial,
    # and the study (--no-workers-after 4) ends in one line with that trial still complete, its folder there
    port = _closed_port()
    scheduler = _dask(
        "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard", log=tmp_path / "scheduler.log"
    )
    worker = None
    try:
        address = f"tcp://127.0.0.1:{port}"
        worker = _dask(
            "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard", log=tmp_path / "worker.log"
        )
        out = tmp_path / "study"
        batch = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "optipose",
                "batch",
                str(files / "study.toml"),
                "--backend",
                "dask",
                "--scheduler",
                address,
                "--out",
                str(out),
                "--no-workers-after",
                "4",
                "--no-report",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, **FAST_CHECK},
        )
        deadline = time.monotonic() + 120
        while not _complete(out) and batch.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        _stop(worker)
        killed = time.monotonic()
        _, stderr = batch.communicate(timeout=120)
        seconds = time.monotonic() - killed
    finally:
        for process in (worker, scheduler):
            if process is not None:
                _stop(process)
    assert_one_line_error(subprocess.CompletedProcess([], batch.returncode, "", stderr), "no Dask worker at")
    assert "for 4 s: the study stopped" in stderr and "--resume" in stderr
    assert seconds < 4 + 30
    index = pd.read_parquet(out / "index.parquet")
    done = index[index.state == "complete"]
    assert len(done) >= 1 and set(index.state) <= {"complete", "pending"}, index.state  # none left "running"
    for folder in done.folder:
        assert (out / folder / "trial.toml").is_file() and (out / folder / "per_scan.parquet").is_file()


def test_a_scheduler_without_workers_is_one_line_before_the_study_folder(files):
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=0, processes=False, protocol="tcp://", host="127.0.0.1", dashboard_address=":0"
    ) as cluster:
        out = files / "no-workers"
        result = run(
            "batch",
            str(files / "study.toml"),
            "--backend",
            "dask",
            "--scheduler",
            cluster.scheduler_address,
            "--out",
            str(out),
            "--no-workers-after",
            "2",
        )
    assert_one_line_error(
        result, f"no Dask worker at {cluster.scheduler_address} for 2 s: the study stopped (start workers with"
    )
    assert not out.exists()


def test_no_workers_for_a_while_stops_or_waits_as_the_user_chose():
    from optipose.batch.scheduler import NoWorkers, WorkerWatch
    from optipose.errors import ConfigError

    now, said = [0.0], []
    clock = lambda: now[0]  # noqa: E731
    for policy in ("stop", "wait"):
        watch = WorkerWatch("tcp://h:1", policy, 60, said.append, clock)
        watch.check(2)
        for t in (100.0, 159.0):  # the first count without a worker starts the minute
            now[0] = t
            watch.check(0)
        assert said == []
        now[0] = 160.0
        if policy == "stop":
            with pytest.raises(
                NoWorkers,
                match=r"^no Dask worker at tcp://h:1 for 60 s: the study stopped \(start workers with `dask worker tcp://h:1`\)$",
            ):
                watch.check(0)
            continue
        watch.check(0)
        now[0] = 500.0
        watch.check(0)  # said once, not at every count
        watch.check(1)
        assert said == [
            "no Dask worker at tcp://h:1 for 60 s: waiting for workers (--no-workers wait; Ctrl-C stops, --resume continues)",
            "the Dask cluster at tcp://h:1 has 1 worker(s) again: the study goes on",
        ]
    with pytest.raises(ConfigError, match="--no-workers maybe: use stop or wait"):
        WorkerWatch("", "maybe")


class _DyingOnce:
    """A serial pool whose first trial's worker 'dies' after writing half of its temporary folder."""

    workers = 1

    def __init__(self, folder: Path):
        from optipose.batch.pools import SerialPool

        self.serial, self.folder, self.died = SerialPool(), folder, False
        self.plan = self.serial.plan

    def submit(self, fn, *args):
        if not self.died:
            self.died = True
            (self.folder / "trials" / ".tmp-dead-worker").mkdir(parents=True)
            (self.folder / "trials" / ".tmp-dead-worker" / "per_scan.csv").write_text("scan\n0\n")
            return "dead"
        return self.serial.submit(fn, *args)

    def wait_any(self, futures) -> set:
        return set(futures)

    def result(self, future):
        if future == "dead":
            raise RuntimeError("worker died")
        return self.serial.result(future)

    def close(self, cancel: bool = False) -> None:
        pass


def test_leftovers_of_a_dead_worker_are_removed_when_the_study_succeeds(files, tmp_path):
    from optipose.batch.spec import load_study_spec
    from optipose.batch.study import run_study

    spec = load_study_spec(files / "study.toml")
    spec = replace(spec, trials=spec.trials[:1])
    out = tmp_path / "study"
    index = run_study(spec, out, _DyingOnce(out))
    assert [r.state.value for r in index.records.values()] == ["complete"]  # run again after its worker died
    assert sorted(p.name for p in (out / "trials").iterdir()) == [spec.trials[0].key]  # no .tmp-* left


# -- output folders, checked first ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "args",
    [
        ["evaluate", "part_b", "--objective", "{d}/short.toml", "--no-report", "--out", "{out}"],
        ["robustness", "part_b", "--objective", "{d}/short.toml", "--no-report", "--out", "{out}"],
        ["search", "part_b", "--budget", "quick", "--sensors", "1", "--no-report", "--out", "{out}"],
        ["scan", "part_b", "--out", "{out}/cloud.npy"],
        ["show", "part_b", "--out", "{out}/part.png"],
        ["batch", "{d}/study.toml", "--out", "{out}"],
        ["report", "/sys"],
    ],
)
def test_an_output_that_cannot_be_written_is_refused_before_the_work(files, args):
    # /sys is read-only even for root (whom a chmod-ed folder would not stop)
    t0 = time.monotonic()
    result = run(*[a.format(d=files, out="/sys/optipose-out") for a in args])
    assert_one_line_error(result, "cannot write in /sys")
    assert time.monotonic() - t0 < 20  # refused at once: an evaluation, a search or a study would take longer


# -- damaged result files -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def evaluation(files):
    out = files / "evaluation"
    result = run(
        "evaluate", "part_b", "--objective", str(files / "short.toml"), "--seed", "5", "--out", str(out), "--no-report"
    )
    assert result.returncode == 0, result.stderr
    return out


@pytest.mark.parametrize(
    "name, damage",
    [
        ("per_scan.parquet", "truncate"),
        ("stats.csv", "truncate"),
        ("points.csv", "garbage"),
        ("config.toml", "garbage"),
    ],
)
def test_a_damaged_result_file_is_one_line_naming_it(files, evaluation, tmp_path, name, damage):
    import shutil

    folder = tmp_path / "damaged"
    shutil.copytree(evaluation, folder)
    data = (folder / name).read_bytes()
    (folder / name).write_bytes(data[: len(data) // 2] if damage == "truncate" else np.random.default_rng(3).bytes(400))
    result = run("report", str(folder), "--no-views")
    assert_one_line_error(result, f"{folder}/{name}")
    assert (folder / "per_scan.csv").read_bytes() == (evaluation / "per_scan.csv").read_bytes()  # the rest untouched


def test_a_damaged_study_index_and_search_cache_are_one_line(files, tmp_path):
    from optipose.batch.index import read_index
    from optipose.errors import ConfigError
    from optipose.io.search import load_cache

    (tmp_path / "index.parquet").write_bytes(b"PAR1" + bytes(100))
    with pytest.raises(ConfigError, match="index.parquet: damaged"):
        read_index(tmp_path)
    (tmp_path / "cache.npz").write_bytes(b"PK\x03\x04" + bytes(50))
    with pytest.raises(ConfigError, match="cache.npz: damaged"):
        load_cache(tmp_path, 2)


def test_search_resume_with_a_damaged_cache_is_one_line_and_keeps_it(tmp_path):
    from optipose.evaluate.objective import load_objective
    from optipose.io.search import SearchFolder
    from optipose.model.part import load_part
    from optipose.search.budgets import config_from_budget

    SearchFolder(tmp_path).start(
        load_part("part_b"), load_objective("paper").in_cell("ideal"), config_from_budget("quick", (1,)), "quick", 0, 1
    )
    garbage = b"PK\x03\x04" + np.random.default_rng(4).bytes(200)
    (tmp_path / "cache.npz").write_bytes(garbage)
    assert_one_line_error(run("search", "--resume", str(tmp_path), "--no-report"), f"{tmp_path}/cache.npz: damaged")
    assert (tmp_path / "cache.npz").read_bytes() == garbage  # left as it was, for the user to look at


def test_a_search_into_a_used_folder_leaves_none_of_the_earlier_runs_results_but_its_cache(tmp_path):
    """A search started in a folder an earlier search wrote (its config says so; its 40 draws, kinds, report) leaves
    there only what it writes itself: a folder never shows another run's draws or kinds beside this run's config.
    The history, the cache and the layouts stay (a resumed search starts from the cache; the layouts are an
    interrupted run's best so far, until this run writes its own). A folder no search wrote keeps everything."""
    from optipose.evaluate.objective import load_objective
    from optipose.io.search import SearchFolder
    from optipose.model.part import load_part
    from optipose.search.budgets import config_from_budget

    earlier = ["verdict/draw-40/hand/per_scan.csv", "validation/hand/per_scan.csv", "kinds.csv", "verdict.csv"]
    earlier += ["report.md", "report_figures/a.png", "selection.csv"]
    kept = ["layouts/hand.toml", "layouts/found_k3.toml", "history.csv", "cache.npz"]
    for folder, command in ((tmp_path / "search", "search"), (tmp_path / "other", "evaluate")):
        for name in [*earlier, *kept]:
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            (folder / name).write_text("earlier")
        (folder / "config.toml").write_text(f'command = "{command}"\n')
        SearchFolder(folder).start(
            load_part("part_b"),
            load_objective("paper").in_cell("ideal"),
            config_from_budget("quick", (1,)),
            "quick",
            0,
            1,
        )
        assert all((folder / name).read_text() == "earlier" for name in kept)
        assert 'command = "search"' in (folder / "config.toml").read_text()
    assert not any((tmp_path / "search" / name).exists() for name in earlier)
    assert not (tmp_path / "search" / "verdict").exists() and not (tmp_path / "search" / "report_figures").exists()
    assert all((tmp_path / "other" / name).read_text() == "earlier" for name in earlier)  # not a search's folder


# -- a mesh in inches, a mesh that is not a solid -------------------------------------------------------------
def test_a_part_in_inches_is_loaded_with_its_units_for_the_report_views(files, tmp_path):
    import trimesh

    block = trimesh.creation.box((0.06, 0.041, 0.0176))
    block.apply_translation([0.03, 0.0, 0.0088])  # part B's box, in metres
    block.apply_scale(1 / 0.0254)
    block.export(tmp_path / "inches.stl")
    out = tmp_path / "result"
    result = run(
        "evaluate",
        str(tmp_path / "inches.stl"),
        "--units",
        "in",
        "--objective",
        str(files / "short.toml"),
        "--out",
        str(out),
    )
    assert result.returncode == 0, result.stderr
    from optipose.io.folders import read_config

    assert read_config(out).part_units == "in"
    report = (out / "report.md").read_text()
    assert "no 3D views" not in report and "--units in" in report  # drawn, and the command line says how it was loaded
    assert "does not load" not in result.stderr


def test_a_verdict_on_failed_registrations_says_so_instead_of_ranking():
    from optipose.evaluate.assignment import FAILED, AxisChoice, Choice
    from optipose.verdict.compare import Verdict, bought
    from optipose.verdict.words import failed_line, verdict_headline, verdict_line

    def choice(name, failed=()):
        axes = tuple(
            AxisChoice(a, (), "", float("nan"), float("nan"), FAILED)
            if a in failed
            else AxisChoice(a, (0,), name, 1e-6, 2e-6)
            for a in ("roll", "pitch", "yaw")
        )
        return Choice(1, (0,), name, axes, 3e-6)

    found_failed = Verdict(1, choice("F1", ("roll", "pitch")), choice("S1"))
    assert found_failed.failed == (("roll", "pitch"), ())
    assert verdict_line(found_failed).startswith(
        "k=1: no verdict: the registrations of found F1 failed on roll, pitch in over a tenth"
    )
    assert verdict_line(found_failed).endswith("keep S1 until they succeed") and not bought(found_failed)
    hand_failed = Verdict(1, choice("F1"), choice("S1", ("yaw",)))
    assert "those of hand S1 on yaw" in verdict_line(hand_failed) and "keep" not in verdict_line(hand_failed)
    assert failed_line(Verdict(1, choice("F1"), choice("S1"))) == ""  # nothing failed: ranked as before

    assert verdict_headline(found_failed) == "k=1: NO VERDICT: registrations of found F1 failed (roll, pitch)"
    assert verdict_headline(hand_failed) == "k=1: NO VERDICT: registrations of hand S1 failed (yaw)"


def test_a_mesh_that_is_not_a_solid_is_warned_in_one_line(tmp_path, caplog):
    import trimesh

    from optipose.model.mesh import load_mesh

    box = trimesh.creation.box((0.06, 0.04, 0.02))
    flipped = box.faces.copy()
    flipped[::2] = flipped[::2, ::-1]
    trimesh.Trimesh(box.vertices, flipped, process=False).export(tmp_path / "flipped.stl")
    trimesh.Trimesh(box.vertices, box.faces[2:], process=False).export(tmp_path / "open.stl")
    with caplog.at_level("WARNING"):
        load_mesh(tmp_path / "flipped.stl", "m")
        load_mesh(tmp_path / "open.stl", "m")
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and all(
        "not a closed solid" in line and "export the part as a closed solid" in line for line in lines
    )
    assert "faces not consistently oriented" in lines[0] and "open: some edges have one face" in lines[1]


def test_after_a_ctrl_c_a_dying_helper_thread_prints_no_traceback(monkeypatch, capsys):
    """A pool's thread that dies while a Ctrl-C unwinds (its workers' pipes closed) adds no traceback to the one
    line an interrupted command prints; before any Ctrl-C a thread's error is printed as Python prints it."""
    import signal
    import threading

    from optipose import errors

    monkeypatch.setattr(threading, "excepthook", threading.__excepthook__)
    monkeypatch.setattr(errors, "_INTERRUPTS", [])
    previous = signal.getsignal(signal.SIGINT)
    try:
        errors.note_interrupts()

        def die():
            raise BrokenPipeError("the worker's pipe is closed")

        def run() -> str:
            t = threading.Thread(target=die, name="QueueManagerThread")
            t.start()
            t.join()
            return capsys.readouterr().err

        before = run()
        assert "Traceback" in before and "QueueManagerThread" in before
        errors._INTERRUPTS.append(signal.SIGINT)
        assert run() == ""
    finally:
        signal.signal(signal.SIGINT, previous)
