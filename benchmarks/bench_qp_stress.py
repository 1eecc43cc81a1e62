"""Stress runs of the QP inverse-dynamics controller: optimality of every tick and tick time.

Closed loops on Talos (the humanoid study's controller, simulator and compliant ground) in
which inequality rows bind:

- ``wave``: full Talos standing, torque limits scaled to 0.3, both arms waving 0.05 rad at
  3 Hz (posture tasks with feed-forward);
- ``com-step``: full Talos standing, friction coefficient 0.1, the CoM target stepping 3 cm
  sideways and 2 cm down after 0.1 s;
- ``fixed``: the full upper body on a fixed base, torque limits scaled to 0.3, the same wave;
- ``infeasible``: fixed upper body with torque limits scaled to 0.02 (too weak to hold the
  arms against gravity), the same wave.

After each tick the whole QP of that tick (all cone, torque and acceleration-bound rows, base
rows eliminated) is rebuilt from the controller's arrays and solved by Clarabel (an interior
point solver, through qpsolvers) to 1e-10; the objective gap of the controller's answer is
``(F - F*) / F*`` with F the full least-squares cost (constant included, so F* > 0), over
the ticks that gave the ``direct`` or ``solved`` answer. The other columns: median / p99 /
max CPU time of the thread in ``compute_torques`` [us] (thread_time: the machine may be
busy), its max wall time, and how many ticks gave each answer of
:class:`~dmpopt.control.ControllerStats`.

Run from the repository root: ``PYTHONPATH=. python benchmarks/bench_qp_stress.py
[--seconds 1.5] [--no-reference] [--scenarios wave fixed]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
import pinocchio as pin
import proxsuite
import qpsolvers
import scipy.sparse
from dmpopt_robots import load_talos
from dmpopt_studies import humanoid

from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    PostureTask,
    SoleContact,
)
from dmpopt.exceptions import SimulationDiverged

WAVE_FREQUENCY, WAVE_AMPLITUDE = 3.0, 0.05  # [Hz], [rad]


def scaled(robot, scale: float):
    """The robot with its torque limits multiplied by ``scale``."""
    return dataclasses.replace(robot, torque_limit=scale * np.asarray(robot.torque_limit))


def wave_controller(robot):
    """The humanoid study's controller with both arms driven by a posture task."""
    q_start = humanoid.drumming_posture(robot)
    controller, arms = humanoid.build_controller(robot, q_start)
    centre = q_start[robot.configuration_indices(list(humanoid.DRUM_JOINTS))]

    def reference(t):
        omega = 2 * np.pi * WAVE_FREQUENCY
        s, c = np.sin(omega * t), np.cos(omega * t)
        a = WAVE_AMPLITUDE * np.ones(centre.size)
        arms.set_reference(centre + a * s, a * omega * c, -a * omega**2 * s)

    return controller, q_start, reference


def com_step_controller(robot):
    """Standing on friction 0.1 with a CoM step of (0, 3, -2) cm at 0.1 s."""
    q_start = humanoid.drumming_posture(robot)
    posture = PostureTask(robot, weight=humanoid.POSTURE_WEIGHT, stiffness=10.0)
    com = ComTask(robot, weight=humanoid.COM_WEIGHT, stiffness=50.0)
    start = pin.centerOfMass(robot.model, robot.create_data(), q_start)
    start = start - [0, 0, humanoid._sink(robot)]
    base = FrameTask(robot, "base_link", weight=1.0, stiffness=50.0, components="orientation")
    contacts = [SoleContact(robot, f, friction_coefficient=0.1) for f in robot.foot_frames]
    posture.set_reference(q_start[7:])
    controller = InverseDynamicsController(robot, [posture, com, base], contacts)

    def reference(t):
        com.set_target(start + ([0.0, 0.03, -0.02] if t >= 0.1 else 0.0))

    return controller, q_start, reference


SCENARIOS = {
    "wave": lambda: wave_controller(scaled(load_talos("full"), 0.3)),
    "com-step": lambda: com_step_controller(load_talos("full")),
    "fixed": lambda: wave_controller(scaled(load_talos("full", fixed_base=True), 0.3)),
    "infeasible": lambda: wave_controller(scaled(load_talos("full", fixed_base=True), 0.02)),
}


def full_qp(public, q, v):
    """The tick's QP over y = (qdd_a, f / weight) with every inequality row, and the constant
    that makes its objective the full least-squares cost: (H, g, A, b, C, l, u, constant)."""
    qp = public.assembled_qp(q, v)
    return (
        qp.hessian, qp.gradient, qp.equality_matrix, qp.equality_vector, qp.inequality_matrix,
        qp.lower, qp.upper, qp.constant,
    )  # fmt: skip


def objective(problem, y):
    hessian, gradient, *_, constant = problem
    return 0.5 * y @ hessian @ y + gradient @ y + constant


def reference_solution(problem):
    """Clarabel's solution of the QP to 1e-9; proxsuite from scratch to 1e-10 with the
    duality gap checked if Clarabel stops short (it may on the worst-scaled ticks)."""
    hessian, gradient, a, b, c, lower, upper, _ = problem
    has_lower, has_upper = lower > -1e19, upper < 1e19
    g = np.vstack([c[has_upper], -c[has_lower]])
    h = np.concatenate([upper[has_upper], -lower[has_lower]])
    sparse = scipy.sparse.csc_matrix
    problem = qpsolvers.Problem(
        sparse(hessian), gradient, sparse(g), h, sparse(a) if a.size else None,
        b if b.size else None,
    )  # fmt: skip
    solution = qpsolvers.solve_problem(
        problem, solver="clarabel", tol_gap_abs=1e-9, tol_gap_rel=1e-9, tol_feas=1e-9
    )
    if solution.found:
        return solution.x
    qp = proxsuite.proxqp.dense.QP(hessian.shape[0], b.size, lower.size)
    qp.settings.eps_abs, qp.settings.eps_rel = 1e-10, 0.0
    qp.settings.check_duality_gap, qp.settings.eps_duality_gap_abs = True, 1e-10
    qp.init(hessian, gradient, a, b, c, lower, upper)
    qp.solve()
    return qp.results.x


def controller_y(public):
    """The controller's last answer over y (wrenches divided by the robot's weight)."""
    layout = public._current.layout
    wrenches = public.contact_wrenches.ravel() / layout.force_scale
    return np.concatenate([public.joint_accelerations[layout.n_base :], wrenches])


def run(name, seconds, check):
    controller, q_start, reference = SCENARIOS[name]()
    robot = controller.robot
    simulator, q0 = humanoid.make_simulator(robot, q_start)
    state = simulator.reset(q0, np.zeros(robot.nv))
    n = int(round(seconds / humanoid.DT))
    walls, cpus, gaps, answers = np.empty(n), np.empty(n), [], []
    for k in range(n):
        reference(k * humanoid.DT)
        before = dataclasses.replace(controller.stats)
        begin, cpu_begin = time.perf_counter_ns(), time.thread_time_ns()
        tau = controller.compute_torques(state.q, state.v)
        cpus[k] = (time.thread_time_ns() - cpu_begin) / 1e3
        walls[k] = (time.perf_counter_ns() - begin) / 1e3
        answers.append(_answer(before, controller.stats))
        if check and answers[-1] in ("solved", "direct", "limits", "cones"):
            problem = full_qp(controller, state.q, state.v)
            solution = reference_solution(problem)
            best = objective(problem, solution)
            gaps.append((objective(problem, controller_y(controller)) - best) / best)
        try:
            state = simulator.step(tau)
        except SimulationDiverged:  # the infeasible case: the arms fall and spin
            break
    return cpus[: len(answers)], walls[: len(answers)], np.array(gaps), answers, state


def _answer(before, after) -> str:
    """Which answer the tick gave, from the change of the counters."""
    for field in ("n_hold", "n_fallbacks", "n_relaxed", "n_direct"):
        if getattr(after, field, 0) > getattr(before, field, 0):
            return {"n_fallbacks": "hold", "n_hold": "hold"}.get(field, field[2:])
    return "solved"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.5, help="simulated time [s]")
    parser.add_argument("--no-reference", action="store_true", help="skip the Clarabel solves")
    parser.add_argument("--scenarios", nargs="*", default=list(SCENARIOS))
    args = parser.parse_args()
    print(
        f"{'scenario':11s} {'gap max':>9s} {'cpu med':>7s} {'p99':>7s} {'max':>8s} "
        f"{'wall max':>8s}  answers"
    )
    for name in args.scenarios:
        cpus, walls, gaps, answers, state = run(name, args.seconds, not args.no_reference)
        counts = {a: answers.count(a) for a in sorted(set(answers))}
        gap = f"{gaps.max():9.2e}" if gaps.size else f"{'-':>9s}"
        print(
            f"{name:11s} {gap} {np.median(cpus):7.0f} {np.percentile(cpus, 99):7.0f} "
            f"{cpus.max():8.0f} {walls.max():8.0f}  {counts}{'  FELL' if state.fallen else ''}"
        )


if __name__ == "__main__":
    import warnings

    from threadpoolctl import threadpool_limits

    warnings.simplefilter("ignore")  # qpsolvers' notes on dense matrices and inexact solves

    with threadpool_limits(limits=1, user_api="blas"):
        main()
