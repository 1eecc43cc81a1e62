"""Independent runs (seeds, trials, folds, sweep points): in series or in local processes.

A study hands its independent runs to :func:`map_runs` as one module-level function and a
list of inputs; the :class:`Runner` it is given decides where they run. Results come back in
the order of the inputs, whatever the order they finish in, so a run with workers gives the
same numbers as the serial run with the same seeds.

>>> from dmpopt.parallel import Runner, map_runs
>>> map_runs(abs, [-1, 2, -3], Runner())
[1, 2, 3]
"""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

from .exceptions import InvalidInputError


@dataclass
class Runner:
    """Where independent runs execute.

    Parameters
    ----------
    workers : int
        1 runs them in series in this process; N > 1 in N local processes.
    """

    workers: int = 1
    wall_seconds: float = field(default=0.0, init=False)
    runs: int = field(default=0, init=False)

    def __post_init__(self):
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1:
            raise InvalidInputError(
                f"workers must be an integer >= 1, got {self.workers!r}; use 1 to run in series"
            )

    @property
    def backend(self) -> str:
        return "serial" if self.workers == 1 else "processes"

    def record(self) -> dict:
        """What a study writes under ``parallel`` in its metrics."""
        return {
            "backend": self.backend,
            "workers": self.workers,
            "runs": self.runs,
            "wall_seconds": self.wall_seconds,
        }


def map_runs(function, inputs, runner: Runner | None = None) -> list:
    """``[function(x) for x in inputs]``, run where ``runner`` says.

    ``function`` must be importable by name (a module-level function) when ``runner`` has
    several workers; each run gets its own process, so it must not rely on state set up in
    this one.
    """
    runner = runner or Runner()
    inputs = list(inputs)
    start = time.perf_counter()
    if runner.workers == 1 or len(inputs) < 2:
        results = [function(x) for x in inputs]
    else:
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(min(runner.workers, len(inputs)), mp_context=context) as pool:
            results = list(pool.map(function, inputs))
    runner.wall_seconds += time.perf_counter() - start
    runner.runs += len(inputs)
    return results
