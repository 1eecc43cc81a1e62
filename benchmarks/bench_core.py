"""Timings of the DMP core (issue targets in brackets). Run: python benchmarks/bench_core.py

First rollouts (a new DMP: its response matrices computed) are reported as medians of the
thread's and the process's CPU time and of the wall time, and of the thread's system time
(within its CPU time: the page faults of the new response's memory); the rest as thread CPU
time.

BLAS is limited to one thread: the matrices are small, and on a loaded 2-core machine
multithreaded BLAS turns a 0.5 ms product into tens of milliseconds.
"""

import argparse
import dataclasses
import os
import resource
import time

import numpy as np
from threadpoolctl import threadpool_limits

from dmpopt import DiscreteDMP, RhythmicDMP, fit_discrete
from dmpopt import dmp as dmp_module
from dmpopt.basis import discrete_basis, rhythmic_basis


def median_us(function, repeats):
    """Median CPU time of the thread per call [us] (a busy machine's waiting is not counted)."""
    times = []
    for _ in range(repeats):
        start = time.thread_time()
        function()
        times.append(time.thread_time() - start)
    return 1e6 * float(np.median(times))


def medians_ms(function, repeats):
    """Medians per call [ms] of the thread's CPU time, the process's CPU time and the wall
    time (which counts a busy machine's waiting), and of the thread's system time within its
    CPU time (where Linux reports it: mostly page faults of new memory), as one string."""
    clocks = (time.thread_time, time.process_time, time.perf_counter, _thread_system_time)
    times = np.empty((repeats, 4))
    for i in range(repeats):
        start = [clock() for clock in clocks]
        function()
        times[i] = [clock() - begun for clock, begun in zip(clocks, start)]
    thread, process, wall, system = 1e3 * np.median(times, axis=0)
    return (
        f"{thread:.1f} ms thread CPU ({system:.1f} ms of it system), {process:.1f} ms process "
        f"CPU, {wall:.1f} ms wall"
    )


def _thread_system_time():
    """The calling thread's system CPU time [s] (Linux), else 0."""
    if not hasattr(resource, "RUSAGE_THREAD"):
        return 0.0
    return resource.getrusage(resource.RUSAGE_THREAD).ru_stime


FIRST_REPEATS = 15
"""First rollouts timed per line (each a new DMP whose response matrices are computed)."""


def main():
    print(f"load average {os.getloadavg()[0]:.2f}")
    rng = np.random.default_rng(0)
    centres, widths = discrete_basis(50, (25.0, 6.25, 25.0, 6.25))
    dmp = DiscreteDMP(
        100 * rng.normal(size=(30, 50)),
        np.zeros(30),
        np.ones(30),
        0.5,
        centres,
        widths,
        form="acceleration",
        goal_scaling="translation",
    )
    dmp.rollout(0.999, 0.001)  # builds and caches the response matrices
    rollout = median_us(lambda: dmp.rollout(0.999, 0.001), 200)
    print(f"rollout, 30 DOFs, 50 bases, 1000 steps: {rollout / 1e3:.3f} ms median  [<= 1 ms]")
    for compile_ in (False, True):
        stepper = dmp.stepper(0.001, compile=compile_)
        step = median_us(stepper.step, 5000)
        label = "compiled C" if compile_ else "casadi VM"
        print(f"online step, 30 DOFs, 50 bases ({label}): {step:.1f} us median  [<= 20 us]")
    from dmpopt_studies import lasa

    demo = lasa.demonstrations("Angle")[0]
    lasa_dmp = fit_discrete(demo, 50)
    lasa_dmp.rollout(0.999, 0.001)
    rollout = median_us(lambda: lasa_dmp.rollout(0.999, 0.001), 500)
    print(
        f"rollout of the LASA demo's DMP, 2 DOFs, 1000 steps: {rollout / 1e3:.3f} ms median  "
        "[<= 0.1 ms]"
    )
    # a new DMP value each time (a loop over goals): its response is in the process's cache,
    # its goal map, inputs and plan are not
    moved = iter([lasa_dmp.with_goal(lasa_dmp.goal + 0.01 * k) for k in range(500)])
    rollout = median_us(lambda: next(moved).rollout(0.999, 0.001), 500)
    print(
        f"rollout of a new goal of the LASA demo's DMP, 2 DOFs, 1000 steps: "
        f"{rollout / 1e3:.3f} ms median"
    )

    fields = {field.name: getattr(lasa_dmp, field.name) for field in dataclasses.fields(lasa_dmp)}
    fields.pop("kernel")  # not an argument
    fresh = iter([DiscreteDMP(**fields) for _ in range(FIRST_REPEATS + 1)])  # nothing memoised

    def first_rollout():
        dmp_module._response.cache_clear()  # as for a DMP whose response matrices are new
        return next(fresh).rollout()

    n_steps = first_rollout().n_steps
    first = medians_ms(first_rollout, FIRST_REPEATS)
    print(
        f"first rollout of a new DMP (the LASA demo's, {n_steps} steps, its default duration): "
        f"{first} (medians)  [<= 10 ms]"
    )
    lasa_dmp.rollout()
    again = median_us(lasa_dmp.rollout, 200)
    print(f"repeated rollout of the LASA demo's DMP, its default duration: {again / 1e3:.3f} ms")
    first_rollouts()
    fit_discrete(demo, 50)
    fit = median_us(lambda: fit_discrete(demo, 50), 200)
    print(
        f"fit of one LASA demo, 2 DOFs, 1000 samples, 50 bases: {fit / 1e3:.3f} ms median  "
        "[<= 2 ms]"
    )


def first_rollouts():
    """First and repeated rollouts of a new DMP of each form: 2 DOFs, 50 bases, tau = 5 s
    (discrete) or 0.5 s (rhythmic), its default duration at dt = 1 ms (the settling time of
    the discrete forms, three periods of the rhythmic ones)."""
    rng = np.random.default_rng(1)
    centres, widths = discrete_basis(50, (25.0, 6.25, 25.0, 6.25))
    rhythmic = rhythmic_basis(50, "von_mises")
    for form in ("velocity", "acceleration", "phase", "energy"):
        weights = 100 * rng.normal(
            size=(2, 50) if form in ("velocity", "acceleration") else (2, 50, 2)
        )

        def new_dmp():
            if form in ("velocity", "acceleration"):
                return DiscreteDMP(weights, np.zeros(2), np.ones(2), 5.0, centres, widths,
                                   form=form, goal_scaling="translation")  # fmt: skip
            return RhythmicDMP(weights, np.zeros(2), 0.5, *rhythmic, form=form)

        def first_rollout():
            dmp_module._response.cache_clear()  # as for a DMP whose response matrices are new
            return new_dmp().rollout()

        n_steps = first_rollout().n_steps
        first = medians_ms(first_rollout, FIRST_REPEATS)
        dmp = new_dmp()
        dmp.rollout()
        again = median_us(dmp.rollout, 50)
        print(
            f"{form} form, 2 DOFs, 50 bases, {n_steps} steps: first rollout {first}; "
            f"repeated {again / 1e3:.3f} ms thread CPU (medians)"
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.parse_args()  # --help: the text above
    with threadpool_limits(limits=1, user_api="blas"):
        main()
