"""Time per 1 kHz tick of the QP inverse-dynamics controller on Talos (drumming hands).

Each case runs the controller in closed loop with the simulator for ``--seconds`` of simulated
time while both hands drum (alternating vertical sine waves) and times only
``InverseDynamicsController.compute_torques`` (model terms, QP assembly, warm-started solve):

- full floating-base Talos (nv = 50) standing on two sole contacts,
- reduced floating-base Talos (nv = 38) standing on two sole contacts,
- fixed-base upper body of the reduced and the full model (nv = 20 and 32), no contacts.

Each case is run twice: once plain, for the wall and CPU time per tick (median and p99), and
once with the controller's assembly and solve methods wrapped in timers, for the breakdown.
On a shared machine compare CPU times (thread_time), and compare variants in one process.

Reference (TSID 1.7, C++): ~160-170 us/tick reduced, 250-340 us full, ~20 us upper body.
Run: ``/work/venv/bin/python benchmarks/bench_controller.py [--seconds 2]``.
"""

import argparse
import time

import numpy as np
import pinocchio as pin

from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    PostureTask,
    SoleContact,
)
from dmpopt.sim import GroundContact, Simulator
from robots import load_talos

DT = 1e-3  # [s] control and simulation period
DRUM_AMPLITUDE = 0.04  # [m]
DRUM_FREQUENCY = 2.0  # [Hz]
GROUND_STIFFNESS = 2e4  # [N/m] per sole corner


def build(robot):
    """Controller with posture, hand, (CoM, pelvis orientation and sole contacts if standing)."""
    tasks = [PostureTask(robot, weight=0.1, stiffness=10.0)]
    hands = [
        FrameTask(robot, f, weight=1.0, stiffness=100.0, components="position")
        for f in robot.hand_frames
    ]
    tasks += hands
    contacts = []
    if robot.floating_base:
        tasks += [
            ComTask(robot, weight=10.0, stiffness=50.0),
            FrameTask(robot, "base_link", weight=1.0, stiffness=50.0, components="orientation"),
        ]
        contacts = [SoleContact(robot, f) for f in robot.foot_frames]
    return InverseDynamicsController(robot, tasks, contacts), hands


def simulator_for(robot):
    if not robot.floating_base:
        return Simulator(robot.model, DT), robot.reference_configuration.copy()
    points = [(f, c) for f in robot.foot_frames for c in robot.sole_corners]
    simulator = Simulator(
        robot.model,
        DT,
        contact_points=points,
        ground=GroundContact(stiffness=GROUND_STIFFNESS, damping=300.0, friction=1.0),
        fall_frame="base_link",
        fall_height=0.7,
    )
    q0 = robot.reference_configuration.copy()
    q0[2] -= pin.computeTotalMass(robot.model) * 9.81 / len(points) / GROUND_STIFFNESS
    return simulator, q0


def _timed(function, samples):
    """Wrap a bound method to append its CPU time [ns] per call to ``samples``."""

    def wrapper(*args, **kwargs):
        begin = time.thread_time_ns()
        result = function(*args, **kwargs)
        samples.append(time.thread_time_ns() - begin)
        return result

    return wrapper


def run_case(robot, seconds, breakdown=False):
    """Closed-loop run; per-tick wall and CPU time [us] of ``compute_torques``.

    With ``breakdown``, the controller's assembly (the ``_assemble*`` methods: model terms,
    tasks, constraint elimination, QP matrices) and solve (``_solve``: proxsuite update and
    solve, solution and torque readout) are timed too (CPU, summed per tick), at the cost of a
    little wrapper overhead.
    """
    controller, hands = build(robot)
    assembly, solve = [], []
    if breakdown:
        for name in ("_assemble", "_assemble_eliminated", "_assemble_y", "_assemble_torque_rows"):
            if hasattr(controller, name):
                setattr(controller, name, _timed(getattr(controller, name), assembly))
        controller._solve = _timed(controller._solve, solve)
    simulator, q0 = simulator_for(robot)
    state = simulator.reset(q0)
    starts = [hand.target_placement.translation.copy() for hand in hands]
    omega = 2 * np.pi * DRUM_FREQUENCY
    n_ticks = int(round(seconds / DT))
    times, cpu_times, iterations = np.empty(n_ticks), np.empty(n_ticks), np.empty(n_ticks)
    phases = np.zeros((n_ticks, 2))
    for k in range(n_ticks):
        t = k * DT
        for sign, hand, start in zip((1.0, -1.0), hands, starts):
            height = sign * DRUM_AMPLITUDE * np.sin(omega * t)
            speed = sign * DRUM_AMPLITUDE * omega * np.cos(omega * t)
            accel = -(omega**2) * height
            hand.set_target(
                start + [0.0, 0.0, height],
                velocity=[0, 0, speed, 0, 0, 0],
                acceleration=[0, 0, accel, 0, 0, 0],
            )
        assembly.clear()
        solve.clear()
        begin, cpu_begin = time.perf_counter_ns(), time.thread_time_ns()
        tau = controller.compute_torques(state.q, state.v)
        cpu_times[k] = time.thread_time_ns() - cpu_begin
        times[k] = time.perf_counter_ns() - begin
        phases[k] = sum(assembly), sum(solve)
        iterations[k] = controller.stats.last_iterations
        state = simulator.step(tau)
    return {
        "wall": times / 1e3,
        "cpu": cpu_times / 1e3,
        "assembly": phases[:, 0] / 1e3,
        "solve": phases[:, 1] / 1e3,
        "iterations": iterations,
        "stats": controller.stats,
        "fallen": state.fallen,
    }


def calibration():
    """Machine speed markers, to compare with the TSID reference machine."""
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
    cases = [
        ("full Talos, floating base, 2 sole contacts", load_talos("full")),
        ("reduced Talos, floating base, 2 sole contacts", load_talos("reduced")),
        ("reduced Talos upper body, fixed base", load_talos("reduced", fixed_base=True)),
        ("full Talos upper body, fixed base", load_talos("full", fixed_base=True)),
    ]
    print(f"computeAllTerms on full Talos (machine marker): {calibration():.1f} us")
    print(
        "per tick [us]: median / p99 of wall clock (perf_counter) and of the thread's CPU time\n"
        "(thread_time: excludes waiting for a core on a loaded machine, not cache misses);\n"
        "breakdown (CPU medians, separate instrumented run): assembly = model terms, tasks and\n"
        "QP matrices; solve = proxsuite update + solve and the torque readout; iterations\n"
        "median/max; solver health"
    )
    header = (
        f"{'case':46s} {'nv':>3s} {'wall med':>8s} {'p99':>7s} {'cpu med':>8s} {'p99':>7s}"
        f" {'assembly':>8s} {'solve':>7s} {'iters':>6s}"
    )
    print(header)
    for name, robot in cases:
        run = run_case(robot, args.seconds)
        parts = run_case(robot, args.seconds, breakdown=True)
        stats = run["stats"]
        wall, cpu, iterations = run["wall"], run["cpu"], run["iterations"]
        print(
            f"{name:46s} {robot.nv:3d} {np.median(wall):8.1f} {np.percentile(wall, 99):7.1f} "
            f"{np.median(cpu):8.1f} {np.percentile(cpu, 99):7.1f} "
            f"{np.median(parts['assembly']):8.1f} {np.median(parts['solve']):7.1f} "
            f"{np.median(iterations):2.0f}/{iterations.max():<3.0f}  cold restarts "
            f"{stats.n_cold_restarts}, fallbacks {stats.n_fallbacks}, torque-limited ticks "
            f"{stats.n_torque_limited}{' FELL' if run['fallen'] else ''}"
        )


if __name__ == "__main__":
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # tiny matrices: threads only cost
        main()
