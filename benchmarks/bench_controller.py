"""Time per 1 kHz tick of the QP inverse-dynamics controller on Talos.

Each case runs the humanoid study's own closed loop (:mod:`studies.humanoid`: the same
controller, tasks, contacts, simulator and DMP plans) for ``--seconds`` of simulated time and
times only ``InverseDynamicsController.compute_torques`` (model terms, QP assembly, solve):

- drumming: the 12 arm joints follow the learned rhythmic DMPs (posture tasks), the paper's
  task; standing, with a CoM task, a pelvis orientation task and two sole contacts;
- figure-8: the right hand follows a task-space DMP (hand position task), the other arm and
  the rest of the body hold their posture; standing as above;

on the full Talos (nv = 50) and the reduced one (nv = 38, no grippers or head), standing on a
floating base, and on their fixed-base upper bodies (nv = 32 and 20, no contacts).

Columns: CPU time of the thread (thread_time, which excludes waiting for a core on a loaded
machine) and wall time per tick, median and p99; the share of ticks solved without proxsuite
(no friction, CoP or torque row active); solver health; whether the robot fell.

Reference (TSID 1.7, C++, from Python, on this kind of machine): ~160-170 us/tick reduced,
250-340 us full, ~20 us fixed-base upper body.
Run: ``python benchmarks/bench_controller.py [--seconds 2]``.
"""

import argparse
import time

import numpy as np
import pinocchio as pin

from robots import load_talos
from studies import humanoid


def calibration():
    """computeAllTerms on the full Talos [us]: a marker of this machine's speed."""
    robot = load_talos("full")
    data = robot.create_data()
    q, v = robot.reference_configuration, np.zeros(robot.nv)
    samples = []
    for _ in range(2000):
        begin = time.perf_counter_ns()
        pin.computeAllTerms(robot.model, data, q, v)
        samples.append(time.perf_counter_ns() - begin)
    return np.median(samples) / 1e3


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated time per case [s]")
    args = parser.parse_args()
    dmps = humanoid.learn_drumming(humanoid.demonstrate_drumming())
    robots = [
        ("full, floating base", load_talos("full")),
        ("reduced, floating base", load_talos("reduced")),
        ("full upper body, fixed base", load_talos("full", fixed_base=True)),
        ("reduced upper body, fixed base", load_talos("reduced", fixed_base=True)),
    ]
    tasks = {
        "drumming": lambda robot: humanoid.run_drumming(robot, dmps, args.seconds),
        "figure-8": lambda robot: humanoid.run_figure8(robot, args.seconds)[0],
    }
    print(f"computeAllTerms on full Talos (machine marker): {calibration():.1f} us")
    print(
        f"{'robot':31s} {'task':9s} {'nv':>3s} {'cpu med':>8s} {'p99':>6s} {'wall med':>8s}"
        f" {'p99':>6s} {'direct':>7s}"
    )
    for robot_name, robot in robots:
        for task_name, run in tasks.items():
            log = run(robot)
            cpu, wall = log.tick_cpu_us, log.tick_wall_us
            print(
                f"{robot_name:31s} {task_name:9s} {robot.nv:3d} {np.median(cpu):8.1f} "
                f"{np.percentile(cpu, 99):6.1f} {np.median(wall):8.1f} "
                f"{np.percentile(wall, 99):6.1f} {log.n_direct / log.times.size:7.1%}  "
                f"cold restarts {log.n_cold_restarts}, fallbacks {log.n_fallbacks}"
                f"{', FELL' if log.fell else ''}"
            )


if __name__ == "__main__":
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # tiny matrices: threads only cost
        main()
