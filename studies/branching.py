"""Runs that part: one simulation up to a branch point, then one continuation per arm.

Runs that differ only after some point (a biped's phase-reset switches after its warm-up, a
push's impulse at the push) are the same run up to it: :class:`Branch` simulates that part
once and forks the process there, one child per further arm. A child is a copy of the whole
run at that point (simulator, controller, logs), so it continues exactly as a run with its
arm's settings from the start would: the same bits (the runs are deterministic). Used by
:func:`dmpopt_studies.biped.walker.walk` and the pushed Talos walks
(:mod:`dmpopt_studies.talos_walk_recovery`).
"""

from __future__ import annotations

import copy
import os
import pickle
import time


class BranchFailed(RuntimeError):
    """The arms of a run could not part (no process forked) or an arm's process ended
    without its result."""


class Branch:
    """Where the ``n_arms`` arms of a run part: at the first call of :meth:`arm`, the run's
    process forks one child per further arm (one at a time, each run to its end before the
    next starts, so that a run uses one core), and goes on with arm 0, the last to run.

    A child returns from :meth:`arm` with its arm's index and continues the caller's code;
    at the end every process calls :meth:`logs` with its result: a child hands it back
    through a pipe and ends (``os._exit``), the parent gets every arm's result. While it
    continues, :attr:`children` holds the results of the arms that ran before it (arms 1 up
    to its own; all of them for arm 0), so that an arm may choose its settings from them (a
    bisection). A child's CPU time is its own (a forked process starts its count at 0) plus
    an equal share of the run's before the branch, as is the parent's (:meth:`cpu_time`).
    """

    def __init__(self, n_arms: int):
        self.n_arms = n_arms
        self.index = None  # the arm this process runs, once parted
        self.pipe = None  # a child's write end
        self.forked_cpu = None  # process CPU time at the branch [s]
        self.children = {}  # arm -> result of the arms run so far

    def arm(self) -> int:
        """The arm this process runs; forks the children on the first call."""
        if self.index is None:
            self.index, self.forked_cpu = 0, time.process_time()
            for index in range(1, self.n_arms):
                read, write = os.pipe()
                try:
                    pid = os.fork()
                except OSError as error:
                    os.close(read), os.close(write)
                    raise BranchFailed(f"could not fork the walk of arm {index}: {error}") from None
                if pid == 0:  # the child: runs arm ``index`` to its end
                    os.close(read)
                    self.index, self.pipe = index, write
                    break
                os.close(write)
                with os.fdopen(read, "rb") as pipe:
                    data = pipe.read()
                _, status = os.waitpid(pid, 0)
                if status != 0 or not data:
                    raise BranchFailed(f"the walk of arm {index} ended without a log")
                self.children[index] = pickle.loads(data)
        return self.index

    def cpu_time(self, cpu_start: float) -> float:
        """This process's CPU time in the run [s] (``cpu_start``: ``time.process_time()``
        at its start): its own continuation and its share of the run before the branch (an
        equal share of the whole run if it did not part: the arms ran alike)."""
        end = time.process_time()
        if self.forked_cpu is None:
            return (end - cpu_start) / self.n_arms
        shared = (self.forked_cpu - cpu_start) / self.n_arms
        return shared + (end if self.pipe is not None else end - self.forked_cpu)

    def logs(self, log) -> list:
        """Every arm's result, in the order of the arms, from this process's ``log`` (a
        child sends it and ends; a run that ended before the branch gives copies of it: its
        arms ran alike)."""
        if self.pipe is not None:
            try:
                data = pickle.dumps(log, protocol=pickle.HIGHEST_PROTOCOL)
                with os.fdopen(self.pipe, "wb") as pipe:
                    pipe.write(data)
            finally:
                os._exit(0)  # the child must not return into its parent's code
        if self.index is None:
            return [log] + [copy.deepcopy(log) for _ in range(1, self.n_arms)]
        return [log] + [self.children[index] for index in range(1, self.n_arms)]

    def abandon(self) -> None:
        """End a child's process without a result (its parent reports the arm's failure)."""
        if self.pipe is not None:
            os._exit(1)
