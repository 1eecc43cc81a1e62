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

With TSID importable, each case also runs TSID on the same loop with the same tasks
(:mod:`tsid_baseline`) and prints dmpopt's median CPU time as a fraction of TSID's; the target
is at most 0.5. dmpopt's controller also bounds the driven joints' accelerations for their
position and velocity limits (never active in these runs); TSID's has no such rows. TSID's wheels crash with pin 4 (binary mismatch), so it runs in its own venv
with a combination that runs, TSID 1.7.1 on pin 3.4.0::

    python3.11 -m venv .venv-tsid
    .venv-tsid/bin/pip install -c benchmarks/tsid-constraints.txt -e ".[test]" tsid
    .venv-tsid/bin/python benchmarks/bench_controller.py

Run: ``python benchmarks/bench_controller.py [--seconds 2] [--no-tsid]``.
"""

import argparse
import time

import numpy as np
import pinocchio as pin

from robots import load_talos
from studies import humanoid

try:
    from tsid_baseline import build_tsid
except ImportError as error:  # TSID is optional: only the reference column needs it
    build_tsid, tsid_missing = None, str(error)


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
    parser.add_argument("--no-tsid", action="store_true", help="skip the TSID reference runs")
    args = parser.parse_args()
    builders = [("dmpopt", humanoid.build_controller)]
    if build_tsid is not None and not args.no_tsid:
        builders.append(("TSID", build_tsid))
    elif not args.no_tsid:
        print(f"TSID reference skipped: {tsid_missing}")
    dmps = humanoid.learn_drumming(humanoid.demonstrate_drumming())
    robots = [
        ("full, floating base", load_talos("full")),
        ("reduced, floating base", load_talos("reduced")),
        ("full upper body, fixed base", load_talos("full", fixed_base=True)),
        ("reduced upper body, fixed base", load_talos("reduced", fixed_base=True)),
    ]
    tasks = {
        "drumming": lambda robot, build: humanoid.run_drumming(
            robot, dmps, args.seconds, build=build
        ),
        "figure-8": lambda robot, build: humanoid.run_figure8(robot, args.seconds, build=build)[0],
    }
    print(f"pinocchio {pin.__version__}; computeAllTerms on full Talos: {calibration():.1f} us")
    print(
        f"{'robot':31s} {'task':9s} {'nv':>3s} {'ctrl':6s} {'cpu med':>8s} {'p99':>6s}"
        f" {'wall med':>8s} {'p99':>6s} {'direct':>7s} {'rms':>8s}"
    )
    for robot_name, robot in robots:
        for task_name, run in tasks.items():
            medians = {}
            for controller_name, build in builders:
                log = run(robot, build)
                cpu, wall = log.tick_cpu_us, log.tick_wall_us
                medians[controller_name] = np.median(cpu)
                rms = np.sqrt(np.mean(np.square(log.desired - log.actual)))
                print(
                    f"{robot_name:31s} {task_name:9s} {robot.nv:3d} {controller_name:6s} "
                    f"{np.median(cpu):8.1f} {np.percentile(cpu, 99):6.1f} {np.median(wall):8.1f} "
                    f"{np.percentile(wall, 99):6.1f} {log.n_direct / log.times.size:7.1%} "
                    f"{rms:8.2e}  cold restarts {log.n_cold_restarts}, fallbacks "
                    f"{log.n_fallbacks}{', FELL' if log.fell else ''}"
                )
            if "TSID" in medians:
                print(f"{'':44s} dmpopt / TSID = {medians['dmpopt'] / medians['TSID']:.2f}")


if __name__ == "__main__":
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # tiny matrices: threads only cost
        main()
