"""Where the evaluator's work runs (executors) and how a worker scans (each sensor with its own model).

The part is a 30 x 25 x 2 mm plate seen from straight above: the Keyence LJ-X8080's 35 mm line overhangs
its 25 mm width, the LJ-X8060's 16 mm line lies wholly on it, so the two models return different counts
from the same pose.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import trimesh

from optipose.errors import ConfigError
from optipose.evaluate.evaluator import Evaluator, evaluate_many
from optipose.parallel.executors import (
    EXECUTORS,
    DaskExecutor,
    JoblibExecutor,
    SerialExecutor,
    make_executor,
    register_executor,
)
from optipose.evaluate.objective import objective_from_table
from optipose.evaluate.worker import sensor_groups
from optipose.seeds import group_seed
from optipose.model.layout import Layout, SensorPose
from optipose.model.motion import ScanMotion
from optipose.registration import voxel_down
from optipose.scan.scanner import PartPose, Scanner

DOWN = np.array([[0, 1, 0, 0.015], [1, 0, 0, 0.0], [0, 0, -1, 0.002], [0, 0, 0, 1.0]])  # R on the top face
TILTED = np.array([[0, 1, 0, 0.015], [0.8, 0, 0.6, -0.004], [0.6, 0, -0.8, 0.002], [0, 0, 0, 1.0]])


class _Part:
    """A minimal stand-in for optipose.model.part.Part: the plate, the LJ-X8080 by default."""

    def __init__(self):
        self.mesh = trimesh.creation.box([0.030, 0.025, 0.002])
        self.mesh.apply_translation([0.015, 0.0, 0.001])
        self.name, self.material, self.sensor = "plate", "white-diffuse", "keyence-lj-x8080"
        self.motion = ScanMotion(0.020)
        self.rotation_centre = np.array([0.015, 0.0, 0.001])
        self.layouts = {}


@pytest.fixture(scope="module")
def plate():
    return _Part()


@pytest.fixture(scope="module")
def objective():
    return objective_from_table(
        {"protocol": {"sequences": ["R", "P"], "start_deg": -1.0, "stop_deg": 1.0, "step_deg": 1.0}}
    )


def _layout(*sensors: str | None) -> Layout:
    poses = (DOWN, TILTED, DOWN)
    return Layout(tuple(SensorPose(f"S{i + 1}", poses[i], sensor) for i, sensor in enumerate(sensors)), name="test")


@pytest.fixture(scope="module")
def serial(plate, objective):
    with Evaluator(plate, objective, seed=2, executor=SerialExecutor()) as ev:
        return ev(_layout(None, None))


class _Recording(SerialExecutor):
    """Runs serially but says it has two workers, and keeps what it was given."""

    n_workers = 2

    def __init__(self):
        self.chunks, self.closed = [], False

    def map(self, fn, items):
        items = list(items)
        self.chunks += items
        return super().map(fn, items)

    def close(self):
        self.closed = True


# -- executors ------------------------------------------------------------------------------------------
def test_make_executor_picks_by_jobs_and_name(monkeypatch):
    assert isinstance(make_executor(1), SerialExecutor) and isinstance(make_executor(0), SerialExecutor)
    pool = make_executor(3)
    assert isinstance(pool, JoblibExecutor) and pool.n_workers == 3
    mine = SerialExecutor()
    assert make_executor(mine) is mine
    with pytest.raises(ConfigError, match="unknown executor 'spark'"):
        make_executor(2, "spark")
    monkeypatch.setitem(EXECUTORS, "spark", None)  # restored after the test
    register_executor("spark", lambda n: _Recording())
    assert isinstance(make_executor(2, "spark"), _Recording)


def test_serial_and_two_loky_workers_give_identical_tables(plate, objective, serial):
    with Evaluator(plate, objective, seed=2, executor=JoblibExecutor(2)) as ev:
        assert ev.jobs == 2 and ev.setup.threads == 1
        parallel = ev(_layout(None, None))
        again = ev(_layout(None, None))  # the pool is reused
    pd.testing.assert_frame_equal(parallel.per_scan, serial.per_scan, check_exact=True)
    pd.testing.assert_frame_equal(parallel.points, serial.points, check_exact=True)
    pd.testing.assert_frame_equal(again.per_scan, serial.per_scan, check_exact=True)


def test_several_evaluators_and_layouts_in_one_map_give_each_its_own_evaluation(plate, objective, serial):
    """A verdict's draws: two seeds, two layouts, one with a subset of its sensors, all in one map of the
    workers, each result the one its own call gives."""
    executor = JoblibExecutor(2)
    with (
        Evaluator(plate, objective, seed=2, executor=executor) as two,
        Evaluator(plate, objective, seed=3, executor=executor) as three,
    ):
        items = [(two, _layout(None, None), None), (three, _layout(None, None), [(1,)]), (two, _layout(None), None)]
        together = evaluate_many(items)
        alone = [evaluator(layout, subsets=subsets) for evaluator, layout, subsets in items]
    executor.close()
    pd.testing.assert_frame_equal(together[0].per_scan, serial.per_scan, check_exact=True)
    for one, other in zip(together, alone):
        pd.testing.assert_frame_equal(one.per_scan, other.per_scan, check_exact=True)
        pd.testing.assert_frame_equal(one.points, other.points, check_exact=True)
        assert one.seed == other.seed and one.layout.names == other.layout.names
    assert set(together[1].per_scan["subset"]) == {"S2"}  # the seed-3 draw registered only the subset asked for
    s2 = together[0].per_scan[together[0].per_scan["subset"] == "S2"]
    assert not np.array_equal(s2["roll_est"].to_numpy(), together[1].per_scan["roll_est"].to_numpy())  # another draw


def test_two_dask_workers_give_identical_tables(plate, objective, serial):
    executor = make_executor(2, "dask")  # a local cluster of two worker processes on 127.0.0.1
    try:
        assert isinstance(executor, DaskExecutor) and executor.n_workers == 2
        with Evaluator(plate, objective, seed=2, executor=executor) as ev:
            parallel = ev(_layout(None, None))
    finally:
        executor.close()
    pd.testing.assert_frame_equal(parallel.per_scan, serial.per_scan, check_exact=True)
    pd.testing.assert_frame_equal(parallel.points, serial.points, check_exact=True)


def test_a_given_executor_is_used_and_left_open(plate, objective, serial):
    executor = _Recording()
    with Evaluator(plate, objective, seed=2, executor=executor) as ev:
        result = ev(_layout(None, None))
        tasks = ev.tasks()
    assert [[t[0] for t in item[3]] for item in executor.chunks] == [
        [0, 4],
        [1, 5],
        [2],
        [3],
    ]  # 2 per worker, interleaved
    assert [t[0] for t in tasks] == [0, 1, 2, 3, 4, 5]
    assert not executor.closed  # the caller's to close
    pd.testing.assert_frame_equal(result.per_scan, serial.per_scan, check_exact=True)


def test_jobs_still_builds_the_executor(plate, objective):
    with Evaluator(plate, objective, jobs=2, quiet=True) as ev:
        assert isinstance(ev.executor, JoblibExecutor) and ev.jobs == 2
    with Evaluator(plate, objective) as ev:
        assert isinstance(ev.executor, SerialExecutor) and ev.jobs == 1 and ev.setup.threads is None


# -- each sensor with its own model ----------------------------------------------------------------------
def test_sensors_are_grouped_by_model_the_parts_first():
    assert sensor_groups([None, "b", "a", "b"], "a") == [(None, [0, 2]), ("b", [1, 3])]
    assert sensor_groups(["b"], "a") == [(None, []), ("b", [0])]
    assert group_seed(7, 0) == 7 and group_seed(7, 1) not in (7, group_seed(7, 2))


def test_naming_the_parts_own_model_changes_nothing(plate, objective, serial):
    with Evaluator(plate, objective, seed=2) as ev:
        named = ev(_layout("keyence-lj-x8080", None))
    pd.testing.assert_frame_equal(named.per_scan, serial.per_scan, check_exact=True)
    pd.testing.assert_frame_equal(named.points, serial.points, check_exact=True)


def test_a_sensor_naming_another_model_is_scanned_with_it(plate, objective, serial):
    with Evaluator(plate, objective, seed=2) as ev:
        mixed = ev(_layout(None, None, "keyence-lj-x8060"))
        tasks = ev.tasks()
    counts = mixed.points.pivot(index="scan", columns="sensor", values="n_points")
    assert (counts["S1"] != counts["S3"]).all()  # same pose, other model
    assert (counts["S3"] == 40 * 3200).all()  # the LJ-X8060's whole line on the plate, in each of 40 profiles
    # S1 and S2 are scanned as without S3; S3 as if alone with its model, under its group's seed
    pd.testing.assert_frame_equal(mixed.points[mixed.points["sensor_index"] < 2].reset_index(drop=True), serial.points)
    alone = Scanner(plate.mesh, "keyence-lj-x8060", plate.material)
    for i, rpy, offset, seed, _ in tasks:
        scan = alone.scan(DOWN, plate.motion, PartPose(rpy, plate.rotation_centre, offset), rng=group_seed(seed, 1))
        row = mixed.points[(mixed.points["scan"] == i) & (mixed.points["sensor"] == "S3")].iloc[0]
        assert row["n_points"] == len(scan.points)
        assert row["n_points_down"] == len(voxel_down(scan.points, ev.objective.registration.voxel_size))


def _dies_once(item):
    """Square ``value``; the first call that finds no ``marker`` file creates it and kills its own process."""
    import os
    import signal
    from pathlib import Path

    value, marker, always = item
    if always or (value == 3 and not Path(marker).exists()):
        Path(marker).touch()
        os.kill(os.getpid(), signal.SIGKILL)
    return value * value


def test_a_worker_that_dies_is_replaced_and_its_work_run_again(tmp_path, caplog):
    """A worker process killed mid-map (SIGKILL: the OOM killer, a user) costs a re-run, not the evaluation:
    the map's results are those of a map where nothing died, and the death is logged."""
    marker = tmp_path / "died"
    executor = JoblibExecutor(2)
    try:
        with caplog.at_level("WARNING", logger="optipose.parallel.executors"):
            out = executor.map(_dies_once, [(v, str(marker), False) for v in range(8)])
    finally:
        executor.close()
    assert marker.exists()  # a worker did die
    assert out == [v * v for v in range(8)]
    assert "a worker process died" in caplog.text


def test_a_worker_that_dies_again_is_one_clear_error(tmp_path):
    from optipose.errors import WorkerError

    executor = JoblibExecutor(2)
    try:
        with pytest.raises(WorkerError, match="died twice"):
            executor.map(_dies_once, [(v, str(tmp_path / "died"), True) for v in range(4)])
    finally:
        executor.close()


def _pid(_) -> int:
    import os

    return os.getpid()


def test_stop_workers_ends_the_idle_workers_and_a_later_map_starts_new_ones():
    """What the ``optipose`` command calls at its end: the loky workers are gone at once (not left to the
    interpreter's exit), and a map after it still runs, on new workers."""
    import os

    from optipose.parallel.executors import stop_workers

    executor = JoblibExecutor(2)
    before = set(executor.map(_pid, range(8)))
    stop_workers()
    for pid in before:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    after = set(executor.map(_pid, range(8)))
    executor.close()
    assert after and not after & before and os.getpid() not in after
    stop_workers()  # none left to stop twice: no error


# -- one call in a process of its own ---------------------------------------------------------------------
def test_a_background_call_answers_from_another_process_with_its_threads_capped():
    import os

    from optipose.parallel.background import Background

    with Background(os.getenv, "NUMBA_NUM_THREADS") as call:
        assert call.result() == "1"
    with Background(os.getpid) as call:
        assert call.result() != os.getpid()
    with Background(os.nice, 0, nice=5) as call:  # os.nice(0) answers the process's niceness
        assert call.result() == os.nice(0) + 5


def test_a_background_call_that_raises_or_dies_says_so_instead_of_waiting():
    import os
    import signal
    import time

    from optipose.errors import WorkerError
    from optipose.parallel.background import Background

    with pytest.raises(WorkerError, match="ValueError"):
        Background(int, "not a number").result()
    call = Background(time.sleep, 60)
    os.kill(call._process.pid, signal.SIGKILL)  # killed, as by the kernel's out-of-memory killer
    t0 = time.monotonic()
    with pytest.raises(WorkerError, match="ended without an answer"):
        call.result()
    assert time.monotonic() - t0 < 10
    stopped = Background(time.sleep, 60)
    stopped.close()
    with pytest.raises(WorkerError, match="stopped"):
        stopped.result()


def test_the_heap_thresholds_reach_this_process_and_the_ones_it_starts_unless_the_user_set_them():
    # a fresh interpreter each time: mallopt cannot be undone in this one. glibc takes both thresholds and
    # leaves them in the environment a worker inherits; a threshold the user set wins, and nothing is changed
    import json
    import os
    import platform
    import subprocess
    import sys

    from optipose.heap import HEAP_VARIABLES

    code = (
        "import json, os; from optipose.heap import keep_freed_memory; "
        "print(json.dumps([keep_freed_memory(), {k: os.environ.get(k) for k in %r}]))" % list(HEAP_VARIABLES)
    )
    plain = {k: v for k, v in os.environ.items() if k not in HEAP_VARIABLES}

    def run(env):
        return json.loads(
            subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
        )

    glibc = platform.libc_ver()[0] == "glibc"  # elsewhere it does nothing
    took, seen = run(plain)
    assert took is glibc and seen == {k: str(v) if glibc else None for k, v in HEAP_VARIABLES.items()}
    took, seen = run(plain | {"MALLOC_TRIM_THRESHOLD_": "1000"})
    assert took is False and seen == {"MALLOC_MMAP_THRESHOLD_": None, "MALLOC_TRIM_THRESHOLD_": "1000"}


def test_a_subset_registered_before_is_looked_up_to_the_bit(plate, objective, monkeypatch):
    """An evaluator that registered a sensor at a place takes that sensor's rows for the next layout with the
    same sensor at the same place (a hand-anchored candidate, a finalist plus one): the next layout's tables are
    a fresh evaluator's, float for float, with one registration and one sensor's scan fewer per scan (the known
    sensor's down-sampled cloud is registered with the new one's); the same sensor at another place
    has other draws (its index keys its noise and brackets) and is registered again."""
    import optipose.evaluate.subset_errors as subset_errors

    moved = TILTED.copy()
    moved[0, 3] += 0.002
    first = _layout(None, None)
    anchored = Layout((first.sensors[0], SensorPose("S2", moved)), name="anchored")
    swapped = Layout((SensorPose("S1", moved), SensorPose("S2", DOWN)), name="swapped")
    fresh = {}
    for layout in (anchored, swapped):
        with Evaluator(plate, objective, seed=2, executor=SerialExecutor()) as ev:
            fresh[layout.name] = ev(layout)
    registered, original = [], subset_errors.register_subset
    monkeypatch.setattr(subset_errors, "register_subset", lambda *a, **k: registered.append(a[2]) or original(*a, **k))
    scanned, clouds = [], subset_errors.scan_clouds
    monkeypatch.setattr(
        subset_errors, "scan_clouds", lambda cfg, scans, seed: scanned.append(len(scans)) or clouds(cfg, scans, seed)
    )
    with Evaluator(plate, objective, seed=2, executor=SerialExecutor()) as ev:
        ev(first)
        scans, counts = len(ev.tasks()), {}
        for layout in (anchored, swapped):
            before = len(registered)
            result = ev(layout)
            counts[layout.name] = len(registered) - before
            pd.testing.assert_frame_equal(result.per_scan, fresh[layout.name].per_scan, check_exact=True)
            pd.testing.assert_frame_equal(result.points, fresh[layout.name].points, check_exact=True)
        again = ev(anchored)  # wholly known: nothing scanned or registered
    assert counts == {"anchored": 2 * scans, "swapped": 3 * scans}
    assert sum(scanned) == 2 * scans + 1 * scans + 2 * scans  # the anchored layout's first sensor is not scanned again
    assert len(registered) == 3 * scans + 2 * scans + 3 * scans
    pd.testing.assert_frame_equal(again.per_scan, fresh["anchored"].per_scan, check_exact=True)
    pd.testing.assert_frame_equal(again.points, fresh["anchored"].points, check_exact=True)
