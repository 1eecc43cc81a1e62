"""Constrained QP fit: 2 DOFs, 1,000 samples, 50 basis functions, bounds at every sample.

Prints the median solve time (solver calls only, problem building excluded) per QP backend:
cold (a fresh problem, no previous working set) and warm (the next problem, goal moved by
1 % of the motion, warm-started from the previous fit's working sets). Run with
``python benchmarks/bench_constrained.py``.
"""

from __future__ import annotations

import numpy as np

from dmpopt.exceptions import DmpoptError
from dmpopt.fitting.constrained import Bounds, build_fitting_problem, solve_fitting_problem
from dmpopt.fitting.imitation import fit_discrete
from dmpopt.trajectory import Trajectory


def demonstration(n_samples: int = 1000) -> Trajectory:
    """A 2-DOF S-shaped reach of 1 s (a smooth stand-in for a LASA shape)."""
    times = np.linspace(0.0, 1.0, n_samples)
    s = 10 * times**3 - 15 * times**4 + 6 * times**5
    positions = np.column_stack([s, 0.3 * np.sin(2 * np.pi * s) + 0.5 * s])
    return Trajectory.from_positions(times, positions)


def main(repeats: int = 11) -> None:
    demo = demonstration()
    reference = fit_discrete(demo, 50)
    plan = reference.rollout(
        demo.duration, demo.duration / (demo.n_steps - 1), start_velocity=demo.velocities[0]
    )
    bounds = Bounds(
        velocity=0.8 * np.abs(plan.velocities).max(0),
        acceleration=0.6 * np.abs(plan.accelerations).max(0),
    )
    goal = demo.positions[-1]
    for solver in ("daqp", "qpoases", "proxsuite"):
        repeats_here = repeats if solver != "proxsuite" else 3
        cold, warm, failures = [], [], 0
        for k in range(repeats_here):
            shift = 0.002 * k * np.array([1.0, -1.0])
            problem = build_fitting_problem(
                demo, reference=reference, bounds=bounds, goal=goal + shift, solver=solver
            )
            follow = build_fitting_problem(
                demo, reference=reference, bounds=bounds, goal=goal + shift + 0.002, solver=solver
            )
            try:
                _, first = solve_fitting_problem(problem)
                _, second = solve_fitting_problem(follow, warm_start=first)
            except DmpoptError as error:
                failures += 1
                last_error = f"{type(error).__name__}: {str(error)[:120]}"
                continue
            cold.append(first.solve_time)
            warm.append(second.solve_time)
        if cold:
            print(
                f"{solver:10s} cold median {1e3 * np.median(cold):7.2f} ms   "
                f"warm median {1e3 * np.median(warm):7.2f} ms   "
                f"({len(cold)} runs, {failures} failed)"
            )
        else:
            print(f"{solver:10s} failed on all {failures} runs: {last_error}")


if __name__ == "__main__":
    main()
