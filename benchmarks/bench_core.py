"""Timings of the DMP core (issue targets in brackets). Run: python benchmarks/bench_core.py

BLAS is limited to one thread: the matrices are small, and on a loaded 2-core machine
multithreaded BLAS turns a 0.5 ms product into tens of milliseconds.
"""

import dataclasses
import os
import time

import numpy as np
from threadpoolctl import threadpool_limits

from dmpopt import DiscreteDMP, fit_discrete
from dmpopt import dmp as dmp_module
from dmpopt.basis import discrete_basis


def median_us(function, repeats):
    """Median CPU time of the thread per call [us] (a busy machine's waiting is not counted)."""
    times = []
    for _ in range(repeats):
        start = time.thread_time()
        function()
        times.append(time.thread_time() - start)
    return 1e6 * float(np.median(times))


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
    fresh = iter([DiscreteDMP(**fields) for _ in range(6)])  # built afresh: nothing memoised

    def first_rollout():
        dmp_module._response.cache_clear()  # as for a DMP whose response matrices are new
        return next(fresh).rollout()

    n_steps = first_rollout().n_steps
    first = median_us(first_rollout, 5)
    print(
        f"first rollout of a new DMP (the LASA demo's, {n_steps} steps, its default duration): "
        f"{first / 1e3:.1f} ms median  [<= 10 ms]"
    )
    fit_discrete(demo, 50)
    fit = median_us(lambda: fit_discrete(demo, 50), 200)
    print(
        f"fit of one LASA demo, 2 DOFs, 1000 samples, 50 bases: {fit / 1e3:.3f} ms median  "
        "[<= 2 ms]"
    )


if __name__ == "__main__":
    with threadpool_limits(limits=1, user_api="blas"):
        main()
