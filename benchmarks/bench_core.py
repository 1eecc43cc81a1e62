"""Timings of the DMP core (issue targets in brackets). Run: python benchmarks/bench_core.py

BLAS is limited to one thread: the matrices are small, and on a loaded 2-core machine
multithreaded BLAS turns a 0.5 ms product into tens of milliseconds.
"""

import dataclasses
import os
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
        first = median_us(first_rollout, 5)
        dmp = new_dmp()
        dmp.rollout()
        again = median_us(dmp.rollout, 50)
        print(
            f"{form} form, 2 DOFs, 50 bases, {n_steps} steps: first rollout {first / 1e3:.1f} ms, "
            f"repeated {again / 1e3:.3f} ms (medians)"
        )


if __name__ == "__main__":
    with threadpool_limits(limits=1, user_api="blas"):
        main()
