"""Independent runs (seeds, trials, folds, sweep points): in series, in local processes or on Ray.

A study hands its independent runs to :func:`map_runs` as one module-level function and a
list of inputs; the :class:`Runner` it is given decides where they run. Results come back in
the order of the inputs, whatever the order they finish in, so a run with workers or on Ray
gives the same numbers as the serial run with the same seeds. A progress bar counts the runs
as they finish.

>>> from dmpopt.parallel import Runner, map_runs
>>> map_runs(abs, [-1, 2, -3], Runner())
[1, 2, 3]

On a Ray cluster (``pip install 'dmpopt[ray]'``; docs/cluster.md)::

    with Runner(ray="auto") as runner:      # or ray="local", or ray="10.0.0.1:6379"
        results = map_runs(simulate_trial, seeds, runner)
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import socket
import time
import warnings
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field

from .exceptions import InvalidInputError, MissingDependency


@dataclass
class Runner:
    """Where independent runs execute.

    Parameters
    ----------
    workers : int
        Without ``ray``: 1 runs in series in this process, N > 1 in N local processes. With
        ``ray="local"``: the number of CPUs the local Ray may use (1: all of this machine's).
        More than this machine's cores (:func:`available_cores`) are cut to them, with a
        warning; a :func:`map_runs` also starts no more processes than it has runs.
    ray : str, optional
        ``"local"`` starts a Ray instance on this machine for the runner's lifetime; ``"auto"``
        joins the cluster this machine belongs to (``ray start``); ``"HOST:PORT"`` joins the
        cluster whose head is there. None (default): no Ray.
    progress : bool
        Show a progress bar (on stderr) as runs finish.
    """

    workers: int = 1
    ray: str | None = None
    progress: bool = True
    wall_seconds: float = field(default=0.0, init=False)
    runs: int = field(default=0, init=False)
    _ray_started: bool = field(default=False, init=False, repr=False)
    _pool: ProcessPoolExecutor | None = field(default=None, init=False, repr=False)
    _pool_size: int = field(default=0, init=False, repr=False)

    def __post_init__(self):
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1:
            raise InvalidInputError(
                f"workers must be an integer >= 1, got {self.workers!r}; use 1 to run in series"
            )
        if self.ray is not None and (not isinstance(self.ray, str) or not self.ray.strip()):
            raise InvalidInputError(
                f"ray must be 'local', 'auto' or a head address 'HOST:PORT', got {self.ray!r}"
            )
        cores = available_cores()
        if self.ray in (None, "local") and self.workers > cores:
            warnings.warn(
                f"workers={self.workers} is more than this machine's {cores} cores; using "
                f"{cores} (more processes than cores only share them)",
                stacklevel=3,
            )
            self.workers = cores

    @property
    def backend(self) -> str:
        if self.ray is not None:
            return "ray"
        return "serial" if self.workers == 1 else "processes"

    def record(self) -> dict:
        """What a study writes under ``parallel`` in its metrics."""
        record = {
            "backend": self.backend,
            "workers": self.workers,
            "runs": self.runs,
            "wall_seconds": self.wall_seconds,
        }
        if self.ray is not None:
            record["ray_address"] = self.ray
            record["ray_cpus"] = self._ray_cpus()
        return record

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        """Stop the worker processes and the local Ray this runner started.

        A cluster it joined keeps running. A runner is used again after ``close()`` by
        starting them anew.
        """
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        if self._ray_started:
            import ray

            ray.shutdown()
            self._ray_started = False

    def connect(self) -> None:
        """Start or join Ray now (otherwise at the first :func:`map_runs`)."""
        self._ray()

    def _ray(self):
        try:
            import ray
        except ImportError as error:
            raise MissingDependency(
                "ray is not installed: pip install 'dmpopt[ray]', or run without ray "
                "(workers=N for local processes)"
            ) from error
        if not ray.is_initialized():
            options = {"include_dashboard": False, "log_to_driver": False}
            if self.ray not in ("local", "auto"):
                _check_reachable(self.ray)
            try:
                if self.ray == "local":
                    ray.init(num_cpus=self.workers if self.workers > 1 else None, **options)
                else:
                    ray.init(address=self.ray, **options)
            except Exception as error:  # noqa: BLE001 - a startup timeout is a bare Exception
                raise InvalidInputError(
                    f"cannot start or join Ray at {self.ray!r} ({error}); start a cluster "
                    "with 'ray start --head' or use ray='local' (a local Ray can time out "
                    "starting on an overloaded machine: try again, or run without ray)"
                ) from error
            self._ray_started = True
        return ray

    def _ray_cpus(self):
        try:
            import ray
        except ImportError:
            return None
        return ray.cluster_resources().get("CPU") if ray.is_initialized() else None


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the system tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """Fail in seconds on a head that is not there (Ray itself retries for minutes)."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise InvalidInputError(
            f"ray address must be 'local', 'auto' or 'HOST:PORT', got {address!r}"
        )
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as error:
        raise InvalidInputError(
            f"no Ray head answers at {address} ({error.strerror or error}); start one with "
            "'ray start --head --port PORT' on that machine, or use ray='local'"
        ) from None


def _bar(runner: Runner, total: int, label: str):
    from tqdm import tqdm

    return tqdm(total=total, desc=label, unit="run", disable=not runner.progress, leave=False)


def process_context(preload: list[str]):
    """The multiprocessing context for local processes: forked from a server process that
    has imported the modules ``preload`` once (``forkserver``), so that each new process
    starts without importing them again (a study's imports take 1.5-2 s of CPU), or spawned
    where the system cannot fork. Either way a process starts from freshly imported modules,
    so it computes the same numbers. The preload list is taken by the first process started
    from the server; later calls reuse that server."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(preload))
    return context


def _one_blas_thread() -> None:
    """A worker's BLAS on one thread: the workers already fill the cores (Ray does the same).
    threadpoolctl limits the libraries loaded so far: NumPy's and SciPy's are loaded first."""
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)


def _check_picklable(function, inputs, where: str) -> None:
    """Refuse, with the fix, a function or input that cannot be sent to another process
    (a lambda, a nested function, a lock): otherwise the pickle error surfaces mid-run."""
    name = getattr(function, "__qualname__", type(function).__name__)
    try:
        pickle.dumps(function)
    except Exception as error:  # pickle raises PicklingError, TypeError or AttributeError
        raise InvalidInputError(
            f"function {name} cannot be sent to {where} ({type(error).__name__}: {error}); "
            "define it with def at the top level of a module (not a lambda or a nested "
            "function, and holding no lock or open file), or run in series with "
            "Runner(workers=1)"
        ) from None
    for i, x in enumerate(inputs):
        try:
            pickle.dumps(x)
        except Exception as error:
            raise InvalidInputError(
                f"inputs[{i}] cannot be sent to {where} ({type(error).__name__}: {error}); "
                "pass plain data (numbers, arrays, strings, dataclasses of them), or run in "
                "series with Runner(workers=1)"
            ) from None


def _in_processes(function, inputs, runner, bar) -> list:
    size = min(runner.workers, len(inputs))
    if runner._pool is not None and runner._pool_size < size:
        runner._pool.shutdown()
        runner._pool = None
    if runner._pool is None:  # kept for the runner's next map_runs; close() ends it
        context = process_context([function.__module__])
        runner._pool = ProcessPoolExecutor(size, mp_context=context, initializer=_one_blas_thread)
        runner._pool_size = size
    results = [None] * len(inputs)
    futures = {runner._pool.submit(function, x): i for i, x in enumerate(inputs)}
    try:
        for future in as_completed(futures):
            results[futures[future]] = future.result()
            bar.update()
    except BaseException:  # Ctrl-C or a failed run: drop the queued runs, stop the workers
        _stop(runner)
        raise
    return results


def _stop(runner: Runner) -> None:
    """End the runner's pool at once: queued runs cancelled, running ones terminated."""
    pool, runner._pool = runner._pool, None
    processes = list((pool._processes or {}).values())  # the executor offers no public kill
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join()


def _call(function, x):
    """One run on a Ray worker, on one BLAS thread as everywhere else (a Ray worker may have
    loaded its libraries with more)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return function(x)


def _on_ray(function, inputs, runner, bar) -> list:
    ray = runner._ray()
    remote = ray.remote(_call)
    function_ref = ray.put(function)
    pending = [remote.remote(function_ref, x) for x in inputs]
    index = {ref: i for i, ref in enumerate(pending)}
    results = [None] * len(inputs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        results[index[done[0]]] = ray.get(done[0])
        bar.update()
    return results


def map_runs(function, inputs, runner: Runner | None = None, label: str = "runs") -> list:
    """``[function(x) for x in inputs]``, run where ``runner`` says, in the order of ``inputs``.

    Every run uses one BLAS thread, in series as in processes or on Ray: a matrix product
    split over threads rounds differently, and a chaotic run (a walk at the edge of a fall)
    would then end differently depending on where it ran.

    ``function`` must be importable by name (a module-level function) when the runs leave
    this process (workers > 1 or Ray); each run then executes in another process, so it must
    not rely on state set up in this one; a function or input that cannot be sent there is
    refused before any run starts. An exception in a run is raised here, and Ctrl-C (or the
    first failed run) cancels the queued runs and stops the running ones at once.
    """
    runner = runner or Runner()
    if not callable(function):
        raise InvalidInputError(f"function must be callable, got {type(function).__name__}")
    inputs = list(inputs)
    if runner.ray is not None or (runner.workers > 1 and len(inputs) > 0):
        where = "Ray" if runner.ray is not None else f"worker processes (workers={runner.workers})"
        _check_picklable(function, inputs, where)
    start = time.perf_counter()
    with _bar(runner, len(inputs), label) as bar:
        if runner.ray is not None:
            results = _on_ray(function, inputs, runner, bar)
        elif runner.workers == 1:
            from threadpoolctl import threadpool_limits

            results = []
            with threadpool_limits(limits=1):  # as in the workers: the same rounding
                for x in inputs:
                    results.append(function(x))
                    bar.update()
        else:
            results = _in_processes(function, inputs, runner, bar)
    runner.wall_seconds += time.perf_counter() - start
    runner.runs += len(inputs)
    return results
