"""Dynamics-feasible fits (dmpopt.fitting.dynamics): torques, balance rows, SQP, certificate.

Answer keys: the pendulum's torque written plainly, ``tau = m l^2 qdd + m g l sin q``; finite
differences of the exact rows for the chain rule; the centre of mass's ground projection for the
static CoP.
"""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from dmpopt import Trajectory, fit_discrete
from dmpopt.exceptions import InfeasibleProblem, InvalidInputError
from dmpopt.fitting import Balance, TorqueLimits, build_dynamics_problem, solve_dynamics_problem
from dmpopt.fitting.dynamics import (
    BALANCE_LENGTH,
    _evaluate,
    _linearised_rows,
    certify,
    robot_dynamics,
)
from dmpopt.robot import RobotModel

MASS, LENGTH, GRAVITY = 1.5, 0.8, 9.81


def pendulum(torque_limit: float = 30.0) -> RobotModel:
    """A point mass on a massless rod hanging from a joint about y (q = 0 hangs down)."""
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRY(), pin.SE3.Identity(), "swing")
    inertia = pin.Inertia(MASS, np.array([0.0, 0.0, -LENGTH]), np.zeros((3, 3)))
    model.appendBodyToJoint(joint, inertia, pin.SE3.Identity())
    model.gravity.linear = np.array([0.0, 0.0, -GRAVITY])
    return RobotModel(
        name="pendulum",
        model=model,
        joint_groups={"arm": ("swing",)},
        reference_configuration=np.zeros(1),
        position_lower=np.array([-np.pi]),
        position_upper=np.array([np.pi]),
        velocity_limit=np.array([100.0]),
        torque_limit=np.array([torque_limit]),
        base="fixed",
    )


def plain_torque(trajectory: Trajectory) -> np.ndarray:
    """The answer key: ``m l^2 qdd + m g l sin q``."""
    q, qdd = trajectory.positions[:, 0], trajectory.accelerations[:, 0]
    return MASS * LENGTH**2 * qdd + MASS * GRAVITY * LENGTH * np.sin(q)


def swing_demo(duration: float = 0.5, goal: float = 1.5) -> Trajectory:
    """From hanging to ``goal`` [rad], minimum jerk, at 1 kHz."""
    times = np.linspace(0.0, duration, int(round(duration / 1e-3)) + 1)
    s = times / duration
    return Trajectory.from_positions(times, (goal * s**3 * (10 - 15 * s + 6 * s**2))[:, None])


@settings(max_examples=25, deadline=None)
@given(
    arrays(np.float64, (3, 5), elements=st.floats(-10.0, 10.0, allow_nan=False)),
)
def test_pendulum_torque_is_the_plain_formula(states):
    """RNEA of the reduced model equals m l^2 qdd + m g l sin q at any state (rounding of
    terms below 1e3 N m: 1e-9 N m)."""
    dynamics = robot_dynamics(pendulum(), ["swing"], torque_limits=TorqueLimits())
    q, v, a = (row[:, None] for row in states)
    trajectory = Trajectory(np.arange(5.0), q, v, a)
    assert np.allclose(dynamics.outputs(trajectory)[:, 0], plain_torque(trajectory), atol=1e-9)


@pytest.mark.parametrize("goal", [1.5, -1.5])
def test_fit_holds_the_torque_limit_where_the_plain_dmp_does_not(goal):
    """The plain DMP needs more than the limit (positive torques to 1.5 rad, negative ones to
    -1.5 rad); the fit's plan, at the same duration, stays within it on a 0.25 ms grid by the
    plain formula (the margin 1e-3 of the limit covers the linearisation; the certificate's
    tolerance is 1e-9 of the limit)."""
    limit = 30.0
    demo = swing_demo(goal=goal)
    plain = fit_discrete(demo, 10).rollout(demo.duration, 2.5e-4)
    assert np.abs(plain_torque(plain)).max() > 1.2 * limit
    problem = build_dynamics_problem(
        demo, pendulum(limit), ["swing"], 10, torque_limits=TorqueLimits(), n_samples=110
    )
    dmp, report = solve_dynamics_problem(problem)
    fine = dmp.rollout(demo.duration, 2.5e-4, start_velocity=problem.kinematic.start_velocity)
    assert np.abs(plain_torque(fine)).max() <= limit * (1 + 1e-9)
    assert report.certificate.feasible and report.status == "converged"
    assert abs(fine.positions[-1, 0] - goal) < 1e-6  # the goal, held at the end as by default


def test_chain_rule_matches_finite_differences():
    """d c / d x of the torque and balance rows (Talos, free flyer, two arm joints) equals
    central differences of the exact rows; step 1e-5 in x: error O(h^2) ~ 1e-9 relative."""
    from dmpopt_robots import load_talos

    robot = load_talos("reduced")
    joints = ["arm_right_1_joint", "arm_right_4_joint"]
    q_index = robot.configuration_indices(joints)
    start = robot.reference_configuration[q_index]
    times = np.linspace(0.0, 0.4, 41)
    s = times / times[-1]
    positions = start + np.outer(s**3 * (10 - 15 * s + 6 * s**2), [-0.6, -0.8])
    demo = Trajectory.from_positions(times, positions)
    problem = build_dynamics_problem(
        demo, robot, joints, 6, torque_limits=TorqueLimits(), balance=Balance(), n_samples=15
    )
    hessian, gradient = problem.kinematic.full_qp()[:2]
    x = np.random.default_rng(0).normal(size=gradient.size)
    iterate = _evaluate(problem, x, hessian, gradient)
    matrix = _linearised_rows(problem, iterate, problem.response())
    h = 1e-5
    for column in range(0, gradient.size, 5):
        step = np.zeros(gradient.size)
        step[column] = h
        upper = _evaluate(problem, x + step, hessian, gradient).values.ravel()
        lower = _evaluate(problem, x - step, hessian, gradient).values.ravel()
        difference = (upper - lower) / (2 * h)
        scale = 1.0 + np.abs(difference).max()
        assert np.abs(matrix[:, column] - difference).max() <= 1e-6 * scale


def test_static_cop_is_the_centre_of_mass_projection():
    """Standing still, the CoP is the CoM's ground projection (Newton-Euler: the ground's
    moment about the CoM is zero); to rounding, 1e-9 m."""
    from dmpopt_robots import load_talos

    robot = load_talos("reduced")
    joints = ["arm_left_2_joint"]
    dynamics = robot_dynamics(robot, joints, balance=Balance())
    q = robot.reference_configuration[robot.configuration_indices(joints)]
    still = Trajectory(np.arange(3.0), np.vstack([q, q, q]), np.zeros((3, 1)), np.zeros((3, 1)))
    cop = dynamics.cop(dynamics.outputs(still))
    com = pin.centerOfMass(robot.model, robot.create_data(), robot.reference_configuration)
    assert np.allclose(cop, com[:2], atol=1e-9)
    # the CoP rows: (a.p - b) / BALANCE_LENGTH when f_z = m g (no margin asked)
    cop_rows = [i for i, name in enumerate(dynamics.row_names) if name == "cop"]
    values = dynamics.constraint_values(dynamics.outputs(still))[0, cop_rows]
    a, b = dynamics.polygon[:, :2], dynamics.polygon[:, 2]
    assert np.allclose(values, (a @ com[:2] - b) / BALANCE_LENGTH, atol=1e-9)


def test_certificate_catches_a_violation_between_samples():
    """With the limit just above the torques at 11 samples, the samples pass and the 1 ms grid
    does not; the plain formula on that grid agrees (answer key)."""
    demo = swing_demo()
    dmp = fit_discrete(demo, 10)
    probe = build_dynamics_problem(
        demo, pendulum(), ["swing"], reference=dmp, torque_limits=TorqueLimits(), n_samples=11
    )
    on_samples = np.abs(plain_torque(probe.kinematic.rollout(dmp))).max()
    fine = dmp.rollout(demo.duration, 1e-3, start_velocity=probe.kinematic.start_velocity)
    assert np.abs(plain_torque(fine)).max() > 1.05 * on_samples  # the case is a real one
    problem = build_dynamics_problem(
        demo,
        pendulum(on_samples * 1.001),
        ["swing"],
        reference=dmp,
        torque_limits=TorqueLimits(),
        n_samples=11,
    )
    certificate = certify(problem, dmp)
    assert certificate.samples.worst <= 0.0 < certificate.fine.worst
    assert not certificate.feasible


def test_infeasible_request_names_the_joint():
    """Holding 1.5 rad needs m g l sin(1.5) = 11.7 N m: a 5 N m limit cannot hold the goal."""
    problem = build_dynamics_problem(
        swing_demo(), pendulum(5.0), ["swing"], 10, torque_limits=TorqueLimits(), n_samples=40
    )
    with pytest.raises(InfeasibleProblem, match=r"swing at \d+\.\d % of its torque limit") as error:
        solve_dynamics_problem(problem)
    assert error.value.stats["violation"] > 0.0
    assert not error.value.stats["fit"].report.certificate.feasible


def test_requests_refuse_bad_values():
    """Messages name the argument and what was expected."""
    with pytest.raises(InvalidInputError, match="cop_margin must be a finite number >= 0"):
        Balance(cop_margin=-0.01)
    with pytest.raises(InvalidInputError, match="fraction must be a finite number > 0"):
        TorqueLimits(fraction=0.0)
    with pytest.raises(InvalidInputError, match="Balance needs a standing robot"):
        robot_dynamics(pendulum(), ["swing"], balance=Balance())
    with pytest.raises(InvalidInputError, match="'elbow', which is not a joint of 'pendulum'"):
        robot_dynamics(pendulum(), ["elbow"], torque_limits=TorqueLimits())


@pytest.mark.slow
def test_study_quick_meets_the_issue(tmp_path):
    """The feasible study (quick): the plain DMP exceeds the limits, the dynamics-feasible DMP
    holds them and the CoP margin at the demonstrated duration."""
    from dmpopt_studies import feasible

    metrics = feasible.run(tmp_path, quick=True)
    methods = metrics["methods"]
    assert methods["plain_dmp"]["torque_use_max"] > 1.0
    fit = methods["dynamics_feasible"]
    assert fit["torque_use_max"] <= 1.0 and fit["cop_margin_min_mm"] >= 0.0
    assert fit["duration_s"] == pytest.approx(metrics["demo_duration_s"])
    assert (tmp_path / "feasible.png").exists()


def centroidal_cop(robot, posture, joints, trajectory, height):
    """CoP from Pinocchio's centroidal momentum rate on the full model (answer key): the
    ground's wrench is ``(dl/dt - m g, dk_G/dt)`` at the CoM ``c``, moved to the origin."""
    model, data = robot.model, robot.create_data()
    q_index, v_index = robot.configuration_indices(joints), robot.velocity_indices(joints)
    mass = pin.computeTotalMass(model)
    cops = []
    for q_j, v_j, a_j in zip(trajectory.positions, trajectory.velocities, trajectory.accelerations):
        q, v, a = posture.copy(), np.zeros(model.nv), np.zeros(model.nv)
        q[q_index], v[v_index], a[v_index] = q_j, v_j, a_j
        rate = pin.computeCentroidalMomentumTimeVariation(model, data, q, v, a)
        force = rate.linear - mass * model.gravity.linear
        moment = rate.angular + np.cross(data.com[0], force)
        cops.append(
            [(height * force[0] - moment[1]) / force[2], (height * force[1] + moment[0]) / force[2]]
        )
    return np.array(cops)


def test_balance_fit_keeps_the_cop_inside_by_centroidal_dynamics():
    """A fast two-joint arm swing whose plain plan brings the CoP nearer the edge than asked:
    the fit's CoP, computed by centroidal dynamics on the full model, keeps the margin (the
    samples' 1e-3 margin covers the linearisation) and equals the fit's own CoP to 1e-9 m."""
    from dmpopt_robots import load_talos

    robot = load_talos("reduced")
    joints = ["arm_right_1_joint", "arm_right_4_joint"]
    posture = np.array(robot.reference_configuration)
    start = posture[robot.configuration_indices(joints)]
    times = np.linspace(0.0, 0.35, 351)
    s = times / times[-1]
    positions = start + np.outer(s**3 * (10 - 15 * s + 6 * s**2), [-1.2, -1.0])
    demo = Trajectory.from_positions(times, positions)
    plain = fit_discrete(demo, 10).rollout(demo.duration, 1e-3)
    loose = robot_dynamics(robot, joints, posture, balance=Balance())
    plain_margin = loose.cop_margin(loose.outputs(plain)).min()
    asked = plain_margin + 0.01  # more than the plain plan keeps
    assert 0.0 < asked < 0.1
    problem = build_dynamics_problem(
        demo, robot, joints, 10, posture=posture, balance=Balance(cop_margin=asked), n_samples=40
    )
    dmp, report = solve_dynamics_problem(problem)
    fine = problem.fine_plan.trajectory(dmp.forcing_weights())
    cop = centroidal_cop(robot, posture, joints, fine, loose.sole_height)
    assert np.allclose(cop, loose.cop(loose.outputs(fine)), atol=1e-9)
    margin = np.min(loose.polygon[:, 2] - cop @ loose.polygon[:, :2].T, axis=1)
    assert margin.min() >= asked - 1e-9 and report.certificate.feasible
