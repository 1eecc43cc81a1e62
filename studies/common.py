"""Helpers shared by the studies: output folders, metrics files, figures, timing."""

from __future__ import annotations

import json
import os
import platform
import time
from importlib import metadata
from pathlib import Path

import numpy as np

from dmpopt.folders import FolderInUse, locked_folder, staged_output  # noqa: F401 (moved there)

PACKAGES = ("dmpopt", "numpy", "scipy", "casadi", "pin", "proxsuite", "toppra", "matplotlib")
TIME_BUDGET = 3600.0
"""CPU seconds per controller tick in the studies' simulations: far more than any tick takes,
so that no simulated tick's answer depends on the machine's speed or load. The controller's
time budget (default 5 ms) cuts its solver short on a slow tick, which is what a real-time
loop needs and what a study must not do: the same tick then got the hold answer in one run
and not in the next, and a push at the edge of a fall flipped between runs. With this budget
the solver stops on its iteration counts alone (``max_iterations``), the same on every
machine and in every process. The studies report their ticks' CPU time against the 5 ms
real-time budget (``ticks_over_budget``) instead."""


def output_dir(out_dir) -> Path:
    """Create (if needed) and return the study's output folder."""
    path = Path(out_dir)
    path.mkdir(parents=True, exist_ok=True)
    return path


def write_text_atomic(path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file: readers see the old or new file."""
    path = Path(path)
    partial = path.with_name(f".{path.name}.partial")
    try:
        partial.write_text(text)
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)
    return path


def versions() -> dict:
    """Installed versions of the packages a result depends on."""
    found = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found


def _plain(value):
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_metrics(out_dir, study: str, metrics: dict, parameters: dict, seed: int, quick: bool):
    """Write ``metrics.json`` with the seed, parameters and package versions; return it."""
    record = {
        "study": study,
        "quick": quick,
        "seed": seed,
        "parameters": parameters,
        "versions": versions(),
        **metrics,
    }
    record = _plain(record)
    path = output_dir(out_dir) / "metrics.json"
    path.write_text(json.dumps(record, indent=2) + "\n")
    return record


def pyplot():
    """matplotlib's pyplot on the non-interactive Agg backend (clear error if missing)."""
    try:
        import matplotlib
    except ImportError as error:
        from dmpopt.exceptions import MissingDependency

        raise MissingDependency(
            "the studies draw figures with matplotlib: pip install 'dmpopt[plot]'"
        ) from error
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and of its ended, waited-for children."""
    import resource

    return sum(
        usage.ru_utime + usage.ru_stime
        for usage in map(resource.getrusage, (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    )


class Progress:
    """Prints a study's stage, the elapsed time and the CPU time of this process so far:
    ``progress("fitting")`` (the CPU time tells a stage's cost on a loaded machine too; a
    worker's time counts once its pool has ended).

    >>> progress = Progress("rl")            # doctest: +SKIP
    >>> progress("eNAC, seed 3 of 10")       # doctest: +SKIP
    [rl     12.3 s, CPU    11.9 s] eNAC, seed 3 of 10
    """

    def __init__(self, study: str):
        self.study = study
        self.start = time.perf_counter()
        self.cpu = cpu_seconds()

    def __call__(self, message: str) -> None:
        elapsed, cpu = time.perf_counter() - self.start, cpu_seconds() - self.cpu
        print(f"[{self.study} {elapsed:6.1f} s, CPU {cpu:7.1f} s] {message}", flush=True)


def median_time(function, repeats: int = 20) -> float:
    """Median wall time of ``function()`` over ``repeats`` calls [s]."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def command_line(run, description: str, argv=None) -> dict:
    """A study's own command, ``python -m dmpopt_studies.NAME OUT_DIR [--quick] [--seed N]``:
    ``run(folder, quick=, seed=)`` into a staged ``OUT_DIR`` (replaced only when the run is
    done, as ``dmpopt study run`` does); returns the metrics for the caller to print."""
    import argparse

    parser = argparse.ArgumentParser(description=description.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    arguments = parser.parse_args(argv)
    with staged_output(arguments.out_dir) as folder:
        return run(folder, quick=arguments.quick, seed=arguments.seed)
