"""dmpopt.parallel: the same results in series, in local processes and on Ray."""

import numpy as np
import pytest

from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.parallel import Runner, map_runs
from studies.recognition import _nearest_accuracy


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
    pytest.importorskip("ray")
    jobs = _jobs()
    serial = map_runs(_nearest_accuracy, jobs, Runner(progress=False))
    with Runner(workers=2, ray="local", progress=False) as runner:
        assert map_runs(_nearest_accuracy, jobs, runner) == serial
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

    from robots.biped import load_biped

    biped = load_biped()
    copy = pickle.loads(pickle.dumps(biped))
    assert dict(copy.joint_groups) == dict(biped.joint_groups)
    assert copy.model.nq == biped.model.nq == 7
    masses = [inertia.mass for inertia in biped.model.inertias]
    assert [inertia.mass for inertia in copy.model.inertias] == masses
    np.testing.assert_array_equal(copy.torque_limit, biped.torque_limit)
    assert copy.foot_frames == biped.foot_frames and copy.base == "planar"
