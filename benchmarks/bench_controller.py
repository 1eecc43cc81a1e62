"""Time per 1 kHz tick of the QP inverse-dynamics controller on Talos.

Each case runs the humanoid study's own closed loop (:mod:`dmpopt_studies.humanoid`: the same
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
position and velocity limits (never active in these runs); TSID's has no such rows. TSID's
wheels crash with pin 4 (binary mismatch), so it runs in its own venv with a combination that
runs, TSID 1.7.1 on pin 3.4.0::

    python3.11 -m venv .venv-tsid
    .venv-tsid/bin/pip install -c benchmarks/tsid-constraints.txt -e ".[test]" tsid
    .venv-tsid/bin/python benchmarks/bench_controller.py

``--walking`` times instead a Talos tick with one foot in the air: the full Talos in
:class:`dmpopt.sim.Simulator` moves its CoM over the left sole, removes the right contact
(0.25 s transition) and lifts the right sole 5 cm with a swing FrameTask (CoM, pelvis
orientation and posture tasks, left sole contact); the ticks with the right foot in the air are
timed. TSID (:class:`tsid_baseline.TsidWalking`, the same tasks, weights and gains) is timed on
the same recorded states and targets.

Run: ``python benchmarks/bench_controller.py [--seconds 2] [--no-tsid] [--walking]``.
"""

import argparse
import time

import numpy as np
import pinocchio as pin
from dmpopt_robots import load_talos
from dmpopt_studies import humanoid

try:
    from tsid_baseline import TsidWalking, build_tsid
except ImportError as error:  # TSID is optional: only the reference column needs it
    build_tsid, tsid_missing = None, str(error)

RIGHT, LEFT = "right_sole_link", "left_sole_link"


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


def _placement(robot, q, frame) -> pin.SE3:
    data = robot.create_data()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(frame)].copy()


def walking_ticks():
    """dmpopt's one-foot ticks in closed loop: (CPU us per tick, states and targets)."""
    from dmpopt.control import (
        ComTask,
        FrameTask,
        InverseDynamicsController,
        PostureTask,
        SoleContact,
    )
    from dmpopt.sim import GroundContact, Simulator

    robot = load_talos("full")
    stiffness = 2e4
    ground = GroundContact(stiffness=stiffness, damping=300.0, friction=1.0)
    simulator = Simulator(robot.model, 1e-3, robot.contact_points, ground)
    q0 = robot.reference_configuration.copy()
    q0[2] -= robot.mass * 9.81 / len(robot.contact_points) / stiffness
    state = simulator.reset(q0)
    com = ComTask(robot, weight=10.0, stiffness=50.0)
    tasks = [
        PostureTask(robot, weight=0.1, stiffness=10.0),
        com,
        FrameTask(robot, "base_link", weight=1.0, stiffness=50.0, components="orientation"),
    ]
    contacts = [
        SoleContact(robot, f, max_normal_force=1500.0, cop_fraction=0.7) for f in robot.foot_frames
    ]
    controller = InverseDynamicsController(robot, tasks, contacts)
    swing = FrameTask(robot, RIGHT, weight=10.0, stiffness=400.0)
    c0 = pin.centerOfMass(robot.model, robot.create_data(), q0)
    left, right0 = _placement(robot, q0, LEFT).translation, _placement(robot, q0, RIGHT)
    cpu, records = [], []
    for k in range(2600):
        t = 1e-3 * k
        s = min(t, 1.0)
        target = np.r_[c0[:2] + s * s * (3 - 2 * s) * (left[:2] - c0[:2]), c0[2]]
        com.set_target(target)
        if k == 1100:
            controller.remove_contact(RIGHT, transition_time=0.25)
        if k == 1400:
            controller.add_task(swing)
        if k >= 1400:
            lift = 0.05 * np.sin(np.pi * min((t - 1.4) / 1.2, 1.0)) ** 2
            swing.set_target(pin.SE3(right0.rotation, right0.translation + [0, 0, lift]))
        begin = time.thread_time_ns()
        tau = controller.compute_torques(state.q, state.v, t)
        if k >= 1450:  # the swing task's contact set is built and warm
            cpu.append((time.thread_time_ns() - begin) / 1e3)
            records.append((state.q.copy(), state.v.copy(), t, target, swing.target_placement))
        state = simulator.step(tau)
        assert not state.fallen, f"fell at t = {t:.3f} s"
    return robot, np.array(cpu), records, controller.stats


def walking(with_tsid: bool) -> None:
    robot, cpu, records, stats = walking_ticks()
    print(f"pinocchio {pin.__version__}; computeAllTerms on full Talos: {calibration():.1f} us")
    print(f"one-foot Talos tick, {cpu.size} ticks [CPU us]:")
    print(
        f"  dmpopt  median {np.median(cpu):6.1f}  p99 {np.percentile(cpu, 99):6.1f}  "
        f"(fallbacks {stats.n_fallbacks}, direct {stats.n_direct}/{stats.n_ticks} ticks)"
    )
    if not with_tsid:
        return
    if build_tsid is None:
        print(f"  TSID skipped: {tsid_missing}")
        return
    tsid_controller = TsidWalking(robot, records[0][0], 10.0, 400.0, 0.7)
    tsid_controller.add_swing()
    times = []
    for q, v, t, com_target, swing_target in records:
        begin = time.thread_time_ns()
        tsid_controller.compute_torques(q, v, t, com_target, swing_target)
        times.append((time.thread_time_ns() - begin) / 1e3)
    print(
        f"  TSID    median {np.median(times):6.1f}  p99 {np.percentile(times, 99):6.1f}  "
        f"(failed solves {tsid_controller.failures})"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated time per case [s]")
    parser.add_argument("--no-tsid", action="store_true", help="skip the TSID reference runs")
    parser.add_argument("--walking", action="store_true", help="time a one-foot tick instead")
    args = parser.parse_args()
    if args.walking:
        walking(not args.no_tsid)
        return
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
