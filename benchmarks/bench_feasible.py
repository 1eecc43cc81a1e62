"""Dynamics-feasible fit: 6 joints, 1.25 s demonstrated at 1 kHz, on standing Talos.

The humanoid study's forehand (six right-arm joints, 1.25 s, 1,251 samples) fitted at its
demonstrated duration (30 basis functions per joint, rows at 200 samples, certificate on the
1 kHz grid) under torque limits at ``TORQUE_FRACTION`` of Talos's (so that they bind: the
demonstration uses at most 34 % of them), then also with balance (CoP ``COP_MARGIN`` inside
the feet, which binds too). Prints the median wall time of the fit (problem building included,
and apart), its CPU time (less sensitive to a loaded machine) and the SQP iterations, against
the target of 0.5 s. BLAS runs on one thread, as ``dmpopt study run`` sets it (small
matrices: more threads only wait for each other on a loaded machine). Run with
``python benchmarks/bench_feasible.py``.
"""

from __future__ import annotations

import os
import time

import numpy as np

from dmpopt.fitting import Balance, TorqueLimits, build_dynamics_problem, solve_dynamics_problem

TORQUE_FRACTION = 0.3
COP_MARGIN = 0.03  # [m]
TARGET = 0.5  # [s]


def main(repeats: int = 3) -> None:
    from dmpopt_robots import load_talos
    from dmpopt_studies.humanoid.demos import drumming_posture
    from dmpopt_studies.humanoid.swing import SWING_JOINTS, demonstrate_swing

    robot = load_talos("full")
    posture = drumming_posture(robot)
    demo = demonstrate_swing(robot, dt=1e-3)
    print(f"demo: {demo.n_dofs} joints, {demo.duration:g} s, {demo.n_steps} samples")
    cases = {
        "torque limits": {"torque_limits": TorqueLimits(fraction=TORQUE_FRACTION)},
        "torque limits + balance": {
            "torque_limits": TorqueLimits(fraction=TORQUE_FRACTION),
            "balance": Balance(cop_margin=COP_MARGIN),
        },
    }
    for name, requests in cases.items():
        total, cpu, solve, iterations = [], [], [], []
        for _ in range(repeats):
            begin, cpu_begin = time.perf_counter(), time.process_time()
            problem = build_dynamics_problem(demo, robot, SWING_JOINTS, posture=posture, **requests)
            _, report = solve_dynamics_problem(problem)
            total.append(time.perf_counter() - begin)
            cpu.append(time.process_time() - cpu_begin)
            solve.append(report.solve_time)
            iterations.append(report.iterations)
        print(
            f"{name:24s} fit {np.median(total):6.2f} s wall, {np.median(cpu):5.2f} s CPU (solve "
            f"{np.median(solve):5.2f} s wall), {int(np.median(iterations))} SQP iterations, "
            f"certificate {report.certificate.feasible}; target {TARGET} s: wall "
            f"{'met' if np.median(total) <= TARGET else 'missed'}, CPU "
            f"{'met' if np.median(cpu) <= TARGET else 'missed'} (load average "
            f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)"
        )


if __name__ == "__main__":
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # as the CLI runs the studies
        main()
