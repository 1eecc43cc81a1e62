"""dmpopt.parallel: the same results in series, in local processes and on Ray."""

import sys

import numpy as np
import pytest
from dmpopt_studies.recognition import _nearest_accuracy

from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.parallel import Runner, map_runs


def _jobs():
    """k-NN leave-one-out runs of different sizes, so they finish out of order."""
    rng = np.random.default_rng(7)
    jobs = []
    for n in (60, 12, 40, 8, 24):
        labels = np.repeat(np.array(["a", "b", "c"]), n // 3 + 1)[:n]
        rows = rng.normal(size=(n, 4)) + (labels == "b")[:, None] * 1.5
        jobs.append((rows, labels, 1 + n % 3))
    return jobs


def _plain_loo_accuracy(rows, labels, k):
    """The answer key: leave-one-out k-NN written out (Euclidean, ties to the lowest label)."""
    hits = 0
    for i in range(len(rows)):
        distances = np.linalg.norm(rows - rows[i], axis=1)
        distances[i] = np.inf
        nearest = labels[np.argsort(distances, kind="stable")[:k]]
        values, counts = np.unique(nearest, return_counts=True)
        hits += values[np.argmax(counts)] == labels[i]
    return hits / len(rows)


def test_serial_runs_match_the_plain_computation():
    jobs = _jobs()
    expected = [_plain_loo_accuracy(*job) for job in jobs]
    runner = Runner(progress=False)
    assert map_runs(_nearest_accuracy, jobs, runner) == pytest.approx(expected, abs=0)
    assert runner.record()["runs"] == len(jobs)
    assert runner.record()["backend"] == "serial"


def test_processes_give_the_serial_results_in_input_order():
    jobs = _jobs()
    serial = map_runs(_nearest_accuracy, jobs, Runner(progress=False))
    with Runner(workers=2, progress=False) as runner:
        assert map_runs(_nearest_accuracy, jobs, runner) == serial
        assert map_runs(_nearest_accuracy, jobs[:1], runner) == serial[:1]  # the same pool
    assert runner.record()["backend"] == "processes"
    assert runner.record()["runs"] == len(jobs) + 1


def _blas_threads(_) -> int:
    from threadpoolctl import threadpool_info

    return max(pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas")


def test_every_run_uses_one_blas_thread_wherever_it_runs():
    """The same rounding in series and in processes: a biped walk run in series (the
    default BLAS threads) and in a worker (one thread) ended 2e-6 m apart, enough to flip
    a trial at the edge of a fall."""
    assert map_runs(_blas_threads, [0, 1], Runner(progress=False)) == [1, 1]
    with Runner(workers=2, progress=False) as runner:
        assert map_runs(_blas_threads, [0, 1], runner) == [1, 1]


def test_ray_gives_the_serial_results_in_input_order():
    ray = pytest.importorskip("ray")
    jobs = _jobs()
    serial = map_runs(_nearest_accuracy, jobs, Runner(progress=False))
    with Runner(workers=2, ray="local", progress=False) as runner:
        assert map_runs(_nearest_accuracy, jobs, runner) == serial
        # one BLAS thread there too (a Ray worker cannot import this file: send it by value)
        here = sys.modules[__name__]
        ray.cloudpickle.register_pickle_by_value(here)
        try:
            assert map_runs(_blas_threads, [0, 1], runner) == [1, 1]
        finally:
            ray.cloudpickle.unregister_pickle_by_value(here)
        record = runner.record()
        with pytest.raises(ShapeError, match="labels"):
            map_runs(_nearest_accuracy, [(np.zeros((3, 2)), ["a"], 1)], runner)
    assert record["backend"] == "ray" and record["ray_cpus"] == 2


def test_an_error_in_a_run_reaches_the_caller():
    bad = [(np.zeros((3, 2)), ["a"], 1)]  # one label for three rows
    with pytest.raises(ShapeError, match="labels"):
        map_runs(_nearest_accuracy, bad, Runner(progress=False))
    with Runner(workers=2, progress=False) as runner, pytest.raises(ShapeError, match="labels"):
        map_runs(_nearest_accuracy, bad * 2, runner)


@pytest.mark.parametrize(
    "options, match",
    [
        ({"workers": 0}, "workers"),
        ({"workers": 1.5}, "workers"),
        ({"workers": True}, "workers"),
        ({"ray": ""}, "ray"),
        ({"ray": 3}, "ray"),
    ],
)
def test_bad_runner_options_name_the_argument(options, match):
    with pytest.raises(InvalidInputError, match=match):
        Runner(**options)


def test_an_absent_ray_head_fails_in_seconds_with_the_fix():
    pytest.importorskip("ray")
    with pytest.raises(InvalidInputError, match="ray start --head"):
        Runner(ray="127.0.0.1:1").connect()
    with pytest.raises(InvalidInputError, match="HOST:PORT"):
        Runner(ray="no-port").connect()


def test_robot_models_survive_the_trip_to_a_worker():
    """A RobotModel pickles (worker processes get the model of the caller, not a reload)."""
    import pickle

    from dmpopt_robots.biped import load_biped

    biped = load_biped()
    copy = pickle.loads(pickle.dumps(biped))
    assert dict(copy.joint_groups) == dict(biped.joint_groups)
    assert copy.model.nq == biped.model.nq == 7
    masses = [inertia.mass for inertia in biped.model.inertias]
    assert [inertia.mass for inertia in copy.model.inertias] == masses
    np.testing.assert_array_equal(copy.torque_limit, biped.torque_limit)
    assert copy.foot_frames == biped.foot_frames and copy.base == "planar"


def test_workers_beyond_the_cores_are_cut_to_them_with_a_warning():
    """Runner(workers=10**6) once started one process per queued run."""
    import os

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    with pytest.warns(UserWarning) as record:
        runner = Runner(workers=10**6, progress=False)
    assert [str(w.message) for w in record] == [
        f"workers=1000000 is more than this machine's {cores} cores; using {cores} (more "
        "processes than cores only share them)"
    ]
    assert runner.workers == cores


def _pid(_) -> int:
    import os

    return os.getpid()


def test_a_pool_starts_no_more_processes_than_runs():
    import multiprocessing

    with Runner(workers=2, progress=False) as runner:
        if runner.workers < 2:
            pytest.skip("one core: no pool")
        assert len(set(map_runs(_pid, [0], runner))) == 1
        assert len(multiprocessing.active_children()) == 1
        map_runs(_pid, [0, 1, 2, 3], runner)  # more runs: the pool grows to the workers
        assert len(multiprocessing.active_children()) == 2


_CHANGED_HERE = []  # appended to by the test below, in the calling process only


def _parent_and_state(_) -> tuple:
    import os

    return os.getppid(), len(_CHANGED_HERE)


def test_worker_processes_start_from_freshly_imported_modules():
    """process_context: the workers come from a fork server (their parent is not the caller)
    and see the modules as imported, not the caller's state: a list the caller appended to
    is empty there (a plain fork would copy it, so runs would depend on what ran before)."""
    import multiprocessing
    import os

    _CHANGED_HERE.append(1)
    try:
        with Runner(workers=2, progress=False) as runner:
            if runner.workers < 2:
                pytest.skip("one core: no pool")
            results = map_runs(_parent_and_state, [0, 1], runner)
    finally:
        _CHANGED_HERE.clear()
    assert [state for _, state in results] == [0, 0]
    if "forkserver" in multiprocessing.get_all_start_methods():
        assert all(parent != os.getpid() for parent, _ in results)


class _Holder:
    def __init__(self):
        import threading

        self.lock = threading.Lock()

    def __call__(self, x):
        return x


def test_what_cannot_reach_a_worker_is_refused_before_any_run():
    """A lambda, a nested function, a lock: once multiprocessing's pickle traceback mid-run."""
    import threading

    def nested(x):
        return x

    runner = Runner(workers=2, progress=False)
    if runner.workers < 2:
        pytest.skip("one core: runs stay in this process")
    where = "worker processes (workers=2)"
    here = "test_what_cannot_reach_a_worker_is_refused_before_any_run"
    fix = (
        "define it with def at the top level of a module (not a lambda or a nested function, "
        "and holding no lock or open file), or run in series with Runner(workers=1)"
    )
    cases = [
        (lambda x: x, f"{here}.<locals>.<lambda>", "Can't pickle local object"),
        (nested, f"{here}.<locals>.nested", "Can't pickle local object"),
        (_Holder(), "_Holder", "cannot pickle '_thread.lock' object"),
    ]
    for function, name, reason in cases:
        with pytest.raises(InvalidInputError) as error:
            map_runs(function, [1, 2], runner)
        message = str(error.value)
        assert message.startswith(f"function {name} cannot be sent to {where} (")
        assert reason in message and message.endswith(f"); {fix}")
    with pytest.raises(InvalidInputError) as error:
        map_runs(_pid, [1, threading.Lock()], runner)
    assert str(error.value) == (
        f"inputs[1] cannot be sent to {where} (TypeError: cannot pickle '_thread.lock' object); "
        "pass plain data (numbers, arrays, strings, dataclasses of them), or run in series "
        "with Runner(workers=1)"
    )
    assert runner._pool is None  # refused before a process started


def _sleep_then_mark(path):
    import time
    from pathlib import Path

    time.sleep(0.3)
    Path(path).touch()


def test_ctrl_c_cancels_the_queued_runs_and_stops_the_running_ones(tmp_path):
    """KeyboardInterrupt once a first run has finished: no run finishes afterwards (once,
    every queued run ran first, 90 s)."""
    import _thread
    import signal
    import threading
    import time

    runner = Runner(workers=2, progress=False)
    if runner.workers < 2:
        pytest.skip("one core: runs stay in this process")
    marks = [tmp_path / f"{k}.done" for k in range(40)]

    def interrupt_after_a_first_run():
        while not any(mark.exists() for mark in marks):
            time.sleep(0.01)
        _thread.interrupt_main()

    # A shell starts a background job with SIGINT ignored, and Python then leaves it ignored:
    # Ctrl-C is simulated with Python's own handler in place, whatever started the suite.
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)
    threading.Thread(target=interrupt_after_a_first_run, daemon=True).start()
    try:
        with pytest.raises(KeyboardInterrupt):
            map_runs(_sleep_then_mark, [str(mark) for mark in marks], runner)
    finally:
        signal.signal(signal.SIGINT, handler)
    finished = sorted(tmp_path.iterdir())
    assert runner._pool is None
    time.sleep(1.0)  # over three runs' length: a run still going or queued would finish now
    assert sorted(tmp_path.iterdir()) == finished and len(finished) < 10
