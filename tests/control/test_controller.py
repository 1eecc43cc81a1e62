"""Tests of dmpopt.control: QP inverse dynamics, its tasks and contacts, computed torque."""

import dataclasses
import math
import os
import warnings

import numpy as np
import pinocchio as pin
import proxsuite
import pytest
from dmpopt_robots import load_talos

from dmpopt.control import (
    ComputedTorqueController,
    ComTask,
    FrameTask,
    InverseDynamicsController,
    PostureTask,
    SoleContact,
    kernels,
)
from dmpopt.exceptions import InvalidInputError, NoSolutionFound, ShapeError


@pytest.fixture(scope="module")
def upper_body():
    return load_talos("reduced", fixed_base=True)


def saturating_posture(robot):
    """A posture task asking 500 rad/s^2 of every joint of a fixed base at rest: the torque
    limits bind. Returns the controller and the state (q, v)."""
    posture = PostureTask(robot, weight=1.0, stiffness=0.0, damping=0.0)
    controller = InverseDynamicsController(robot, [posture], joint_limit_horizon=None,
                                           time_budget=1.0)  # fmt: skip
    q, v = robot.reference_configuration, np.zeros(robot.nv)
    posture.set_reference(q, v, np.full(robot.nv, 500.0))
    return controller, q, v


@pytest.fixture
def proxsuite_only(monkeypatch):
    """As if DAQP failed on every QP (cycled, say): each solve goes on to proxsuite, the
    fallback the tests that take this fixture exercise."""
    from dmpopt.control import qp_stages

    monkeypatch.setattr(qp_stages.StageSolver, "_daqp", lambda self, stage, stats, accept: None)


def random_state(robot, rng, spread=0.2, speed=0.5):
    q = pin.integrate(
        robot.model, robot.reference_configuration, spread * rng.normal(size=robot.nv)
    )
    q = np.clip(q, robot.position_lower, robot.position_upper)
    return q, speed * rng.normal(size=robot.nv)


def standing_controller(robot, friction=0.7, **options):
    """Posture, CoM, base orientation, both soles. A 1 s time budget: a busy machine must not
    turn a tick into the hold answer (the 5 ms default's timing is bench_qp_stress.py's)."""
    options.setdefault("time_budget", 1.0)
    posture = PostureTask(robot, weight=0.1, stiffness=10.0)
    com = ComTask(robot, weight=10.0, stiffness=50.0)
    base = FrameTask(robot, "base_link", weight=1.0, stiffness=50.0, components="orientation")
    contacts = [SoleContact(robot, f, friction_coefficient=friction) for f in robot.foot_frames]
    controller = InverseDynamicsController(robot, [posture, com, base], contacts, **options)
    return controller, com


# ---------------------------------------------------------------- fixed base, no contacts
def test_torques_reproduce_rnea_fixed_base(upper_body):
    """Unconstrained fixed base: tau = RNEA(q, v, qdd_ref) and qdd = qdd_ref (pure feed-forward)."""
    rng = np.random.default_rng(0)
    posture = PostureTask(upper_body, weight=1.0, stiffness=0.0, damping=0.0)
    controller = InverseDynamicsController(
        upper_body,
        [posture],
        acceleration_regularization=1e-12,
        tolerance=1e-10,
        joint_limit_horizon=None,  # random states sit at limits; this checks the formula
    )
    data = upper_body.create_data()
    for _ in range(5):
        q, v = random_state(upper_body, rng)
        acceleration = rng.normal(size=upper_body.nv)
        posture.set_reference(q, v, acceleration)
        tau = controller.compute_torques(q, v)
        np.testing.assert_allclose(controller.joint_accelerations, acceleration, atol=1e-8)
        np.testing.assert_allclose(
            tau, pin.rnea(upper_body.model, data, q, v, acceleration), atol=1e-7
        )
    assert controller.stats.n_fallbacks == 0 and controller.stats.n_cold_restarts == 0


def test_posture_pd_law(upper_body):
    """qdd = qdd_ref + Kp (q_ref - q) + Kd (qd_ref - qd) on the joints of the posture task."""
    rng = np.random.default_rng(1)
    kp, kd = 25.0, 7.0
    posture = PostureTask(upper_body, weight=1.0, stiffness=kp, damping=kd)
    controller = InverseDynamicsController(
        upper_body,
        [posture],
        acceleration_regularization=1e-12,
        tolerance=1e-10,
        joint_limit_horizon=None,  # random states sit at limits; this checks the formula
    )
    q, v = random_state(upper_body, rng)
    q_ref, v_ref, a_ref = random_state(upper_body, rng) + (rng.normal(size=upper_body.nv),)
    posture.set_reference(q_ref, v_ref, a_ref)
    controller.compute_torques(q, v)
    expected = a_ref + kp * (q_ref - q) + kd * (v_ref - v)
    np.testing.assert_allclose(controller.joint_accelerations, expected, atol=1e-8)


def test_overlapping_posture_tasks_blend_by_weight(upper_body):
    """Two posture tasks on the same joints give the weighted mean of their PD laws; gains
    and references assigned after the controller is built take effect."""
    rng = np.random.default_rng(4)
    whole = PostureTask(upper_body, weight=0.5, stiffness=10.0)
    arm = PostureTask(upper_body, "right_arm", weight=2.0, stiffness=30.0)
    controller = InverseDynamicsController(
        upper_body, [whole, arm], acceleration_regularization=1e-12
    )
    arm.stiffness = 40.0  # a scalar broadcasts over the arm's joints
    arm.damping = np.linspace(1.0, 7.0, len(arm.velocity_indices))
    whole.reference_acceleration = rng.normal(size=upper_body.nv)
    q, v = random_state(upper_body, rng)
    arm_reference = q[arm.configuration_indices] + 0.1 * rng.normal(size=7)
    arm.set_reference(arm_reference, rng.normal(size=7), rng.normal(size=7))
    controller.compute_torques(q, v)
    law_whole = whole.reference_acceleration + 10.0 * (whole.reference_position - q)
    law_whole += 2.0 * np.sqrt(10.0) * (whole.reference_velocity - v)
    joints = arm.velocity_indices
    law_arm = arm.reference_acceleration + 40.0 * (arm_reference - q[joints])
    law_arm += arm.damping * (arm.reference_velocity - v[joints])
    expected = law_whole.copy()
    expected[joints] = (0.5 * law_whole[joints] + 2.0 * law_arm) / 2.5
    np.testing.assert_allclose(controller.joint_accelerations, expected, rtol=1e-9, atol=1e-9)
    arm.update(q, v, None)  # the task's own law (the controller evaluates it in its copy)
    np.testing.assert_allclose(arm.target, law_arm, rtol=1e-12)
    with pytest.raises(InvalidInputError, match="stiffness"):
        arm.stiffness = -1.0
    with pytest.raises(ShapeError, match="damping"):
        arm.damping = np.ones(3)


def test_posture_task_rows_check_what_is_assigned(upper_body):
    """Assigning a row of a posture task writes that row only; gains must be finite and
    >= 0 (named), a position reference outside the limits warns, other rows do not."""
    arm = PostureTask(upper_body, "right_arm", stiffness=30.0)
    upper = np.asarray(upper_body.position_upper)[arm.configuration_indices]
    rows = ("reference_position", "reference_velocity", "reference_acceleration", "stiffness",
            "damping", "target")  # fmt: skip
    for index, name in enumerate(rows):
        before = arm.state.copy()
        value = 0.5 * upper + index  # inside the limits for the position
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # inside the limits, or not a position: no warning
            setattr(arm, name, value if index else 0.5 * upper)
        expected = before.copy()
        expected[index] = value if index else 0.5 * upper
        np.testing.assert_array_equal(arm.state, expected)
        np.testing.assert_array_equal(getattr(arm, name), expected[index])
        assert getattr(PostureTask, name).name == name  # the class holds the descriptor
    for name in ("stiffness", "damping"):
        with pytest.raises(InvalidInputError, match=f"^{name} must be finite and >= 0"):
            setattr(arm, name, -1e-12)
        with pytest.raises(InvalidInputError, match=f"^{name} must be finite"):
            setattr(arm, name, np.inf)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        arm.reference_velocity = arm.reference_acceleration = arm.target = -1e3  # any value
    with pytest.warns(UserWarning, match="outside its position limits"):
        arm.reference_position = upper + 0.5


def test_frame_task_acceleration_by_finite_differences(upper_body):
    """A dominant hand task reaches its desired acceleration, checked by differentiating the
    hand velocity numerically (Jacobian, drift and frame conventions together)."""
    rng = np.random.default_rng(2)
    model, data = upper_body.model, upper_body.create_data()
    hand = FrameTask(upper_body, "gripper_left_base_link", weight=1e2, stiffness=10.0)
    others = [
        j
        for g in ("right_arm", "head", "left_gripper", "right_gripper")
        for j in upper_body.joint_groups[g]
    ]  # joints that cannot move the left hand
    posture = PostureTask(upper_body, others, weight=1.0, stiffness=1.0)
    controller = InverseDynamicsController(upper_body, [hand, posture], tolerance=1e-8)
    q, v = random_state(upper_body, rng, spread=0.05, speed=0.1)
    pin.framesForwardKinematics(model, data, q)
    target = data.oMf[hand.frame_id] * pin.exp6(0.02 * rng.normal(size=6))
    target_velocity, target_acceleration = 0.1 * rng.normal(size=6), 0.3 * rng.normal(size=6)
    hand.set_target(target, velocity=target_velocity, acceleration=target_acceleration)
    tau = controller.compute_torques(q, v)
    assert np.all(np.abs(tau) < 0.9 * upper_body.torque_limit)  # no limit active
    qdd = controller.joint_accelerations

    def hand_velocity(dt):
        q_t = pin.integrate(model, q, v * dt + 0.5 * qdd * dt**2)
        pin.computeJointJacobians(model, data, q_t)
        pin.updateFramePlacements(model, data)
        jacobian = pin.getFrameJacobian(model, data, hand.frame_id, pin.LOCAL_WORLD_ALIGNED)
        return jacobian @ (v + qdd * dt)

    step = 1e-6
    measured = (hand_velocity(step) - hand_velocity(-step)) / (2 * step)
    velocity, current = hand_velocity(0.0), data.oMf[hand.frame_id]  # at q
    error = np.r_[
        target.translation - current.translation,
        pin.log3(target.rotation @ current.rotation.T),
    ]
    np.testing.assert_allclose(hand.error(), error, atol=1e-12)
    desired = target_acceleration + 10.0 * error  # Kp = 10, Kd = 2 sqrt(Kp) by default
    desired += 2.0 * np.sqrt(10.0) * (target_velocity - velocity)
    assert controller.stats.last_status == "CHOLESKY_SOLVED"
    np.testing.assert_allclose(measured, desired, atol=1e-5)


@pytest.mark.parametrize("components", ["all", "position"])
def test_fixed_base_woodbury_solve_matches_the_cholesky_solve(upper_body, components):
    """Posture on every joint plus a hand task on a fixed base is solved without the mass
    matrix (Woodbury identity, torques by RNEA); it must equal the Cholesky solve of the
    same least-squares problem with the mass matrix."""
    rng = np.random.default_rng(3)

    def controller():
        posture = PostureTask(upper_body, weight=1e-2, stiffness=10.0)
        arm = PostureTask(upper_body, "left_arm", weight=1.0, stiffness=100.0)
        hand = FrameTask(
            upper_body,
            "gripper_right_base_link",
            weight=1.0,
            stiffness=100.0,
            components=components,
        )
        controller = InverseDynamicsController(
            upper_body, [posture, arm, hand], joint_limit_horizon=None
        )
        return controller, hand

    woodbury, hand_w = controller()
    cholesky, hand_c = controller()
    assert woodbury._current.assembly.joint_space
    # the general path: computeAllTerms, Cholesky, M qdd + h
    cholesky._current.assembly.joint_space = False
    model, data = upper_body.model, upper_body.create_data()
    for _ in range(5):
        q, v = random_state(upper_body, rng, spread=0.05, speed=0.05)
        pin.framesForwardKinematics(model, data, q)
        target = data.oMf[hand_w.frame_id] * pin.exp6(0.01 * rng.normal(size=6))
        velocity = 0.02 * rng.normal(size=6)
        for hand in (hand_w, hand_c):
            hand.set_target(target, velocity=velocity)
        tau_w, tau_c = woodbury.compute_torques(q, v), cholesky.compute_torques(q, v)
        assert woodbury.stats.last_status == cholesky.stats.last_status == "CHOLESKY_SOLVED"
        np.testing.assert_allclose(
            woodbury.joint_accelerations, cholesky.joint_accelerations, rtol=1e-9, atol=1e-9
        )
        np.testing.assert_allclose(tau_w, tau_c, rtol=1e-9, atol=1e-8)
    assert woodbury.stats.n_direct == 5


def test_torque_limits_hold(upper_body):
    """An aggressive reference saturates some joints; no torque leaves its limit."""
    rng = np.random.default_rng(3)
    posture = PostureTask(upper_body, weight=1.0, stiffness=0.0, damping=0.0)
    controller = InverseDynamicsController(
        upper_body, [posture], tolerance=1e-9, joint_limit_horizon=None
    )
    q, v = random_state(upper_body, rng)
    posture.set_reference(q, v, 500.0 * rng.normal(size=upper_body.nv))
    tau = controller.compute_torques(q, v)
    limit = upper_body.torque_limit
    assert np.all(np.abs(tau) <= limit + 1e-9)
    assert np.any(np.abs(tau) >= limit - 1e-6)
    data = upper_body.create_data()
    np.testing.assert_allclose(
        tau, pin.rnea(upper_body.model, data, q, v, controller.joint_accelerations), atol=1e-6
    )
    assert controller.stats.n_torque_limited == 1 and controller.stats.n_direct == 0
    # A gentle reference releases the limits: from the next tick on, closed form again.
    posture.set_reference(q, v, np.zeros(upper_body.nv))
    for _ in range(2):
        tau = controller.compute_torques(q, v)
    assert controller.stats.n_direct == 1 and controller.stats.last_status == "CHOLESKY_SOLVED"
    np.testing.assert_allclose(tau, pin.rnea(upper_body.model, data, q, v, 0 * v), atol=1e-6)


# ---------------------------------------------------------------- floating base with contacts
def test_contact_wrenches_satisfy_friction_cones(talos):
    """With a low friction coefficient and a CoM pushed sideways, every wrench stays in its
    cone (||f_t|| <= mu f_z), its CoP in the sole and f_z >= f_min; some row is active."""
    rng = np.random.default_rng(4)
    mu = 0.2
    controller, com = standing_controller(  # random states sit at joint limits
        talos, friction=mu, tolerance=1e-9, joint_limit_horizon=None
    )
    active = False
    for _ in range(4):
        q, v = random_state(talos, rng, spread=0.02, speed=0.1)
        q[:3] = talos.reference_configuration[:3]
        com.set_target(com.target_position, acceleration=[6.0, -4.0, 0.0])
        controller.reset()
        controller.compute_torques(q, v)
        assert controller.stats.last_status == "DAQP_SOLVED"
        for contact, wrench in zip(controller.contacts, controller.contact_wrenches):
            force, torque = wrench[:3], wrench[3:]
            assert np.hypot(force[0], force[1]) <= mu * force[2] + 1e-6
            assert force[2] >= 1.0 - 1e-6
            cop = np.array([-torque[1], torque[0]]) / force[2]
            assert contact.x_min - 1e-8 <= cop[0] <= contact.x_max + 1e-8
            assert contact.y_min - 1e-8 <= cop[1] <= contact.y_max + 1e-8
            margin = contact.cone_margin(wrench)
            assert margin.min() >= -1e-6
            active |= margin[:4].min() < 1e-6
    assert active, "the test should make a friction row active"
    # Standing still, every cone row is slack: the next tick leaves the QP with cone rows,
    # the one after is solved without them again (one Cholesky solve).
    com.set_target(com.target_position)
    q, v = talos.reference_configuration, np.zeros(talos.nv)
    answers = [(controller.compute_torques(q, v), controller.stats.last_answer)[1] for _ in "ab"]
    assert answers == ["solved", "direct"]


def test_com_task_pd_law(talos):
    """The CoM task's target is c_ref'' + Kp (c_ref - c) + Kd (c_ref' - c') minus the drift,
    with c' and the drift from Pinocchio's centre-of-mass kinematics."""
    rng = np.random.default_rng(7)
    model, data = talos.model, talos.create_data()
    com = ComTask(talos, stiffness=np.array([20.0, 30.0, 40.0]))
    com.set_target(
        com.target_position + 0.01, velocity=rng.normal(size=3), acceleration=rng.normal(size=3)
    )
    q, v = random_state(talos, rng, spread=0.05, speed=0.3)
    pin.computeAllTerms(model, data, q, v)
    com.update(q, v, data)
    check = talos.create_data()
    pin.centerOfMass(model, check, q, v, np.zeros(talos.nv))
    expected = (
        com.target_acceleration
        + com.stiffness * (com.target_position - check.com[0])
        + com.damping * (com.target_velocity - check.vcom[0])
        - check.acom[0]
    )
    np.testing.assert_allclose(com.target, expected, atol=1e-12)
    np.testing.assert_allclose(com.jacobian, pin.jacobianCenterOfMass(model, check, q), atol=1e-12)


def test_sole_contact_gains_are_validated(talos):
    contact = SoleContact(talos, "left_sole_link", stiffness=4.0)
    assert contact.damping == pytest.approx(4.0)  # critical by default
    contact.stiffness, contact.damping = 9.0, 1.0
    assert (contact.stiffness, contact.damping) == (9.0, 1.0)
    with pytest.raises(InvalidInputError, match="stiffness must be a finite number >= 0"):
        contact.stiffness = -1.0
    with pytest.raises(InvalidInputError, match="got 'stiff'"):
        contact.stiffness = "stiff"
    with pytest.raises(InvalidInputError, match="damping"):
        contact.damping = float("nan")


def test_construction_compiles_the_kernels_of_a_tick(talos, upper_body):
    """A new controller's first ticks (with the writable state of a control loop) compile
    nothing, standing or on a fixed base whose posture reference is far from the reference
    configuration (the construction's own ticks then hit the torque limits); contact
    references set before construction are kept."""
    sole = SoleContact(talos, "left_sole_link")
    sole.reference_placement = pin.SE3(np.eye(3), np.array([0.0, 0.1, 0.0]))
    standing = InverseDynamicsController(
        talos, [PostureTask(talos, weight=0.1), ComTask(talos)],
        [sole, SoleContact(talos, "right_sole_link")],
    )  # fmt: skip
    assert standing.stats.n_ticks == 0
    assert sole.reference_placement.translation[1] == 0.1
    arm = PostureTask(upper_body, "left_arm", stiffness=400.0)
    arm.set_reference(arm.reference_position + 1.0)
    fixed = InverseDynamicsController(
        upper_body, [PostureTask(upper_body), arm], joint_limit_horizon=0.05
    )
    names = [name for name in kernels.__all__ if hasattr(getattr(kernels, name), "signatures")]
    compiled = {name: len(getattr(kernels, name).signatures) for name in names}
    rng = np.random.default_rng(3)
    for controller, robot in ((standing, talos), (fixed, upper_body)):
        q, v = random_state(robot, rng, spread=0.02, speed=0.1)
        for _ in range(3):
            controller.compute_torques(q, v)
    assert {name: len(getattr(kernels, name).signatures) for name in names} == compiled


def test_solution_satisfies_equations_of_motion(talos):
    """Forward dynamics of (tau, contact wrenches) gives back the QP's qdd, and the soles
    accelerate as the contact constraint asks."""
    rng = np.random.default_rng(5)
    controller, _ = standing_controller(talos, tolerance=1e-10)
    q, v = random_state(talos, rng, spread=0.02, speed=0.2)
    tau = controller.compute_torques(q, v)
    model, data = talos.model, talos.create_data()
    jacobians = [
        pin.computeFrameJacobian(model, data, q, c.frame_id, pin.LOCAL) for c in controller.contacts
    ]
    generalized = np.concatenate([np.zeros(6), tau])
    generalized += np.vstack(jacobians).T @ controller.contact_wrenches.ravel()
    qdd = pin.aba(model, data, q, v, generalized)
    np.testing.assert_allclose(qdd, controller.joint_accelerations, atol=1e-7)
    pin.forwardKinematics(model, data, q, v, qdd)
    for contact in controller.contacts:
        reference = contact.reference_placement
        pin.updateFramePlacements(model, data)
        deviation = pin.log6(reference.actInv(data.oMf[contact.frame_id])).vector
        velocity = pin.getFrameVelocity(model, data, contact.frame_id, pin.LOCAL).vector
        acceleration = pin.getFrameAcceleration(model, data, contact.frame_id, pin.LOCAL).vector
        expected = -contact.stiffness * deviation - contact.damping * velocity
        np.testing.assert_allclose(acceleration, expected, atol=1e-6)


def test_weight_is_carried_by_the_feet(talos):
    """Standing still in half-sitting, the normal forces sum to the robot's weight."""
    controller, _ = standing_controller(talos, tolerance=1e-10)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    controller.compute_torques(q, v)
    mass = pin.computeTotalMass(talos.model)
    total = controller.contact_wrenches[:, 2].sum()
    assert total == pytest.approx(mass * 9.81, rel=1e-5)


# ---------------------------------------------------------------- failures
def test_failed_solve_falls_back_without_nan(talos, monkeypatch, proxsuite_only):
    """A proxsuite solve that cannot finish (after a DAQP failure) is retried cold, then the
    last torque is returned, counted.

    Low friction and a sideways CoM acceleration make the friction rows active, so that the
    ticks need a solver (the cone-free optimum is solved directly and cannot fail this way).
    No active-set rounds follow proxsuite's unfinished solves (else they go on from the last
    tick's set and can certify the optimum without it)."""
    from dmpopt.control import qp_stages

    controller, com = standing_controller(talos, friction=0.2)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    com.set_target(com.target_position, acceleration=[6.0, -4.0, 0.0])
    first = controller.compute_torques(q, v)
    assert controller.stats.last_status == "PROXQP_SOLVED"
    assert controller.stats.last_iterations >= 1 and controller.stats.n_solved == 1
    controller.qp.settings.max_iter = 1
    monkeypatch.setattr(qp_stages, "_REFINEMENT_ROUNDS", 0)
    com.set_target(com.target_position + [0.05, 0.02, -0.05], acceleration=[-6.0, 4.0, 0.0])
    second = controller.compute_torques(q, v)
    assert np.all(np.isfinite(second))
    np.testing.assert_array_equal(second, first)
    assert controller.stats.n_cold_restarts == 1 and controller.stats.n_fallbacks == 1
    assert controller.stats.last_status == "PROXQP_MAX_ITER_REACHED"
    controller.qp.settings.max_iter = 1000
    controller.compute_torques(q, v)
    assert controller.stats.last_status == "PROXQP_SOLVED"


def test_failed_solve_can_raise(talos, monkeypatch, proxsuite_only):
    """With raise_on_failure, a double failure raises NoSolutionFound carrying the stats."""
    from dmpopt.control import qp_stages

    controller, com = standing_controller(talos, friction=0.2, raise_on_failure=True)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    com.set_target(com.target_position, acceleration=[6.0, -4.0, 0.0])
    controller.compute_torques(q, v)
    controller.qp.settings.max_iter = 1
    monkeypatch.setattr(qp_stages, "_REFINEMENT_ROUNDS", 0)  # as in the test above
    com.set_target(com.target_position + [0.05, 0.02, -0.05], acceleration=[-6.0, 4.0, 0.0])
    with pytest.raises(NoSolutionFound) as error:
        controller.compute_torques(q, v)
    assert error.value.stats.n_fallbacks == 1


def test_states_are_checked_as_the_simulators_check_them(talos):
    """A zero base quaternion is refused (once it was read as upright, with normal torques);
    q and v as lists give the torques of arrays; a transition time must be a number."""
    controller, _ = standing_controller(talos)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    expected = controller.compute_torques(q, v)
    np.testing.assert_array_equal(controller.compute_torques(list(q), list(v)), expected)
    q[3:7] = 0.0
    with pytest.raises(InvalidInputError) as error:
        controller.compute_torques(q, v)
    assert str(error.value) == (
        "q[3:7] of joint 'root_joint' has norm 0, expected a unit quaternion (x, y, z, w): pass "
        "e.g. (0, 0, 0, 1) for no rotation, or pinocchio.normalize(model, q) if the orientation "
        "is right but not scaled"
    )
    with pytest.raises(InvalidInputError) as error:
        controller.remove_contact(talos.foot_frames[0], "0.2")
    assert str(error.value) == (
        "transition_time must be a finite number of seconds, got '0.2' (a str: pass a number)"
    )
    with pytest.raises(InvalidInputError) as error:
        PostureTask(talos, "tail")
    assert str(error.value).startswith("joints='tail' is not a joint group of 'talos_full'")


def test_input_errors(talos, upper_body):
    """Wrong shapes and non-finite states are rejected with the expected sizes."""
    controller, _ = standing_controller(talos)
    with pytest.raises(ShapeError) as error:
        controller.compute_torques(np.zeros(50), np.zeros(50))
    assert str(error.value) == "q has shape (50,), expected (51,) (the configuration of talos_full)"
    q = talos.reference_configuration.copy()
    q[10] = np.nan
    with pytest.raises(InvalidInputError):
        controller.compute_torques(q, np.zeros(50))
    arm = PostureTask(upper_body, "left_arm")
    with pytest.raises(ShapeError) as error:
        arm.set_reference(np.zeros(6))
    assert str(error.value).startswith("positions has shape (6,), expected (7,) for the joints")
    with pytest.raises(InvalidInputError):
        SoleContact(upper_body, "left_sole_link")
    with pytest.raises(InvalidInputError):
        InverseDynamicsController(upper_body, [])
    with pytest.raises(InvalidInputError, match="velocities must be finite"):
        arm.set_reference(np.zeros(7), np.full(7, np.inf))
    hand = FrameTask(upper_body, "gripper_left_base_link")
    with pytest.raises(InvalidInputError, match="placement must be finite"):
        hand.set_target(np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(InvalidInputError, match="acceleration must be finite"):
        hand.set_target(np.zeros(3), acceleration=np.full(6, np.nan))


def test_a_task_vector_is_checked_and_copied_on_either_path():
    """A target vector: a float64 array of its length (the compiled check), a list or an
    int or float32 array (numpy's) give a new float array of the same numbers; NaN or inf
    anywhere is refused on either path; a number is repeated; a wrong length or what is not
    numbers is named."""
    from dmpopt.control import tasks

    for value in (np.array([1.0, -2.0, 3.0]), [1.0, -2.0, 3.0], np.array([1, -2, 3]),
                  np.array([1.0, -2.0, 3.0], dtype=np.float32)):  # fmt: skip
        got = tasks._vector(value, 3, "x")
        assert got.dtype == np.float64 and got.tolist() == [1.0, -2.0, 3.0]
        assert not np.shares_memory(got, np.asarray(value))
    for bad in (np.inf, -np.inf, np.nan):
        for at in range(3):
            value = np.zeros(3)
            value[at] = bad
            for form in (value, value.tolist()):
                with pytest.raises(InvalidInputError, match="x must be finite"):
                    tasks._vector(form, 3, "x")
    assert tasks._vector(2, 4, "x").tolist() == [2.0] * 4
    with pytest.raises(InvalidInputError, match="^x must be numbers"):
        tasks._vector(["a", "b", "c"], 3, "x")
    with pytest.raises(ShapeError, match=r"x has shape \(2,\), expected \(\) or \(3,\)"):
        tasks._vector(np.zeros(2), 3, "x")


@pytest.mark.parametrize("with_hand", [False, True])
def test_nan_written_into_a_task_never_reaches_the_torques(upper_body, with_hand):
    """A NaN that bypasses validation (written into a task's array) fails the tick's checks:
    the controller falls back to finite torques and counts it, on the closed-form and the
    Woodbury path alike."""
    posture = PostureTask(upper_body)
    tasks = [posture] + [FrameTask(upper_body, "gripper_left_base_link")] * with_hand
    controller = InverseDynamicsController(upper_body, tasks, max_iterations=50)
    q, v = upper_body.reference_configuration, np.zeros(upper_body.nv)
    good = controller.compute_torques(q, v)
    posture.reference_position[3] = np.nan
    tau = controller.compute_torques(q, v)
    assert np.isfinite(tau).all() and controller.stats.n_fallbacks == 1
    np.testing.assert_array_equal(tau, good)  # the last valid torque
    stats = controller.stats  # refused before proxsuite, which can call such a QP solved
    assert (stats.last_status, stats.last_iterations) == ("NON_FINITE_PROBLEM", 0)


# ---------------------------------------------------------------- computed torque
def test_computed_torque_formula(upper_body):
    """u = M qdd_d + h + Kp (q_d - q) + Kd (qd_d - qd), checked against crba and nle."""
    rng = np.random.default_rng(6)
    controller = ComputedTorqueController(
        upper_body, stiffness=50.0, damping=5.0, clip_to_limits=False
    )
    q, v = random_state(upper_body, rng)
    q_ref, v_ref = random_state(upper_body, rng)
    a_ref = rng.normal(size=upper_body.nv)
    data = upper_body.create_data()
    mass = pin.crba(upper_body.model, data, q)
    bias = pin.nonLinearEffects(upper_body.model, data, q, v)
    expected = mass @ a_ref + bias + 50.0 * (q_ref - q) + 5.0 * (v_ref - v)
    np.testing.assert_allclose(
        controller.compute_torques(q, v, q_ref, v_ref, a_ref), expected, atol=1e-9
    )


def test_computed_torque_needs_fixed_base(talos):
    """A floating-base robot is refused with the remedy."""
    with pytest.raises(InvalidInputError, match="computed torque needs a fixed base"):
        ComputedTorqueController(talos)


# ---------------------------------------------------------------- closed loop
def test_talos_stands_in_simulation(talos):
    """Talos stands 1.5 s on compliant ground under the QP controller: no fall, no fallback,
    base and CoM within a few millimetres, feet not sliding."""
    from dmpopt.sim import GroundContact, Simulator

    stiffness = 2e4  # [N/m] per sole corner
    points = [(foot, corner) for foot in talos.foot_frames for corner in talos.sole_corners]
    simulator = Simulator(
        talos.model,
        1e-3,
        contact_points=points,
        ground=GroundContact(stiffness=stiffness, damping=300.0, friction=1.0),
        fall_frame="base_link",
        fall_height=0.7,
    )
    q0 = talos.reference_configuration.copy()
    q0[2] -= pin.computeTotalMass(talos.model) * 9.81 / len(points) / stiffness
    state = simulator.reset(q0)
    controller, com = standing_controller(talos)
    com.set_target(pin.centerOfMass(talos.model, talos.create_data(), q0))
    for _ in range(1500):
        state = simulator.step(controller.compute_torques(state.q, state.v))
    assert not state.fallen
    assert controller.stats.n_fallbacks == 0
    np.testing.assert_allclose(state.q[:3], q0[:3], atol=3e-3)
    final_com = pin.centerOfMass(talos.model, talos.create_data(), state.q)
    np.testing.assert_allclose(final_com, com.target_position, atol=3e-3)
    assert np.abs(state.v).max() < 1e-2
    sole_positions = state.contact_positions
    start = simulator.reset(q0).contact_positions
    np.testing.assert_allclose(sole_positions[:, :2], start[:, :2], atol=1e-3)


@pytest.mark.parametrize("horizon", [None, 0.05])
def test_joint_limits_hold_in_simulation(upper_body, horizon):
    """A posture reference 0.3 rad past the left elbow's upper limit, and a head reference
    that stiff gains would reach at 3 rad/s (limit 1 rad/s): with joint limits the simulated
    elbow stops at its limit and the head at its speed limit; without, both pass them."""
    from dmpopt.sim import Simulator

    names = list(upper_body.actuated_joint_names)
    elbow, head = names.index("arm_left_4_joint"), names.index("head_1_joint")
    q_elbow, q_head = upper_body.configuration_indices(["arm_left_4_joint", "head_1_joint"])
    v_head = upper_body.velocity_indices(["head_1_joint"])[0]
    elbow_limit, head_speed = upper_body.position_upper[q_elbow], upper_body.velocity_limit[v_head]
    posture = PostureTask(upper_body, weight=1.0, stiffness=400.0)
    reference = posture.reference_position.copy()
    reference[elbow], reference[head] = elbow_limit + 0.3, 0.7
    posture.set_reference(reference)
    controller = InverseDynamicsController(
        upper_body, [posture], joint_limit_horizon=horizon, time_budget=1.0
    )
    simulator = Simulator(upper_body.model, 1e-3)
    state = simulator.reset(upper_body.reference_configuration)
    elbow_peak = head_peak = -np.inf
    for _ in range(1000):
        state = simulator.step(controller.compute_torques(state.q, state.v))
        elbow_peak = max(elbow_peak, state.q[q_elbow])
        head_peak = max(head_peak, state.v[v_head])
    assert controller.stats.n_fallbacks == 0
    if horizon is None:
        assert elbow_peak > elbow_limit + 0.2 and head_peak > 2.5 * head_speed
    else:
        assert elbow_limit - 0.01 < elbow_peak <= elbow_limit + 1e-3  # reaches it, stays out
        assert 0.95 * head_speed < head_peak <= head_speed + 1e-3
        assert abs(state.q[q_head] - 0.7) < 1e-3  # the head still gets there


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_joint_limits_standing(talos, side):
    """Standing Talos with an arm moving fast toward its upper (side 1) or lower (side -1)
    limit: the accelerations of the tick (through the eliminated QP, then the QP with bound
    rows) respect the bound formula."""
    controller, _ = standing_controller(talos, joint_limit_horizon=0.05)
    arm = PostureTask(talos, "left_arm", weight=10.0, stiffness=400.0)
    controller = InverseDynamicsController(
        talos, [*controller.tasks, arm], controller.contacts, joint_limit_horizon=0.05,
        time_budget=1.0,  # a busy machine (or mutation testing) must not end the exact QP
    )  # fmt: skip
    joint = "arm_left_4_joint"
    i_q, i_v = talos.configuration_indices([joint])[0], talos.velocity_indices([joint])[0]
    limit = talos.position_upper[i_q] if side > 0 else talos.position_lower[i_q]
    reference = arm.reference_position.copy()
    reference[3] = limit + side * 0.5
    arm.set_reference(reference)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    q[i_q], v[i_v] = limit - side * 0.05, side * 1.5
    controller.compute_torques(q, v)
    h, margin = 0.05, 1e-3  # the bounds aim 1e-3 rad past the limit (JOINT_LIMIT_TOLERANCE)
    # side * qdd <= min((|limit + margin - q|) / h^2 - 2 side v / h, (v_max - side v) / h)
    bound = side * min(
        side * (limit + side * margin - q[i_q]) / h**2 - 2 * side * v[i_v] / h,
        (talos.velocity_limit[i_v] - side * v[i_v]) / h,
    )
    assert controller.stats.n_torque_limited == 1 and controller.stats.n_fallbacks == 0
    assert controller.joint_accelerations[i_v] == pytest.approx(bound, abs=1e-4)  # brakes
    # At rest with the arm's reference inside its limits the bound rows are slack: the next
    # tick still starts with them and releases them, the one after starts without them.
    arm.set_reference(talos.reference_configuration[arm.configuration_indices])
    rest = talos.reference_configuration, np.zeros(talos.nv)
    for _ in range(3):
        controller.compute_torques(*rest)
    assert controller.stats.n_torque_limited == 2 and controller.stats.last_answer == "direct"


def test_active_set_iterations_add_the_most_violated_row_each_round():
    """min |x - t|^2 / 2 in the box [-1, 1]^4 with t = (3, 2.5, 2, 0.5), from no active row:
    each round adds the most violated bound (rows 0, 1, 2), the fourth solve is certified,
    x = clip(t, -1, 1); with three rounds allowed, no answer after three solves."""
    from dmpopt.control.qp_stages import _active_set

    target = np.array([3.0, 2.5, 2.0, 0.5])
    problem = (np.eye(4), -target, None, None, np.eye(4), -np.ones(4), np.ones(4))
    for rounds, expected in ((4, (np.clip(target, -1, 1), 4)), (3, (None, 3)), (2, (None, 2))):
        at_upper, at_lower = np.zeros(4, bool), np.zeros(4, bool)
        x, solves = _active_set(problem, at_upper, at_lower, 1e-9, rounds)
        assert solves == expected[1]
        if expected[0] is None:
            assert x is None
        else:
            np.testing.assert_allclose(x, expected[0], rtol=0, atol=1e-12)
            np.testing.assert_array_equal(at_upper, [True, True, True, False])
            assert not at_lower.any()


def test_acceleration_bounds_formula(upper_body):
    h = 0.1
    lower, upper = np.zeros(3), np.zeros(3)
    bounds = kernels.JointBounds(
        np.arange(3), np.arange(3), np.array([-1.0, -np.inf, -1.0]), np.array([1.0, np.inf, 1.0]),
        np.array([2.0, np.inf, 0.5]), h, lower, upper,
    )  # fmt: skip
    kernels.acceleration_bounds(bounds, np.array([0.5, 0.0, 1.5]), np.array([0.1, 0.0, 3.0]))
    # joint 0: position (1 - 0.5)/h^2 - 2 (0.1)/h = 48 vs velocity (2 - 0.1)/h = 19
    assert upper[0] == pytest.approx(19.0) and lower[0] == pytest.approx(-21.0)
    assert (lower[1], upper[1]) == (-np.inf, np.inf)  # no limits
    # joint 2 is past its limit and too fast: the bounds cross and meet at their mean
    assert lower[2] == upper[2] == pytest.approx(0.5 * ((-0.5 - 3.0) / h + (1 - 1.5) / h**2 - 60.0))
    posture = PostureTask(upper_body)
    with pytest.raises(InvalidInputError, match="joint_limit_horizon must be finite and > 0"):
        InverseDynamicsController(upper_body, [posture], joint_limit_horizon=0.0)
    with pytest.raises(InvalidInputError, match="limited_joints is given without"):
        InverseDynamicsController(
            upper_body, [posture], joint_limit_horizon=None, limited_joints="left_arm"
        )
    with pytest.raises(InvalidInputError, match="limited_joints: joint 'elbow'"):
        InverseDynamicsController(
            upper_body, [posture], joint_limit_horizon=0.05, limited_joints=["elbow"]
        )


def test_construction_checks_name_the_argument(upper_body, talos):
    """Each positive setting refuses 0, a negative, inf, a bool and a string by name; tasks
    and contacts refuse a bare item, the wrong kind (naming both) and another robot's."""
    posture = PostureTask(upper_body)
    for name in ("acceleration_regularization", "force_regularization", "tolerance",
                 "time_budget", "torque_limit_scale"):  # fmt: skip
        for bad in (0.0, -1.0, np.inf, True, "fast"):
            with pytest.raises(InvalidInputError, match=f"^{name} must be a finite number > 0"):
                InverseDynamicsController(upper_body, [posture], **{name: bad})
    for bad in (0, True, 2.5, "ten"):
        with pytest.raises(InvalidInputError, match="^max_iterations must be an integer >= 1"):
            InverseDynamicsController(upper_body, [posture], max_iterations=bad)
    with pytest.raises(InvalidInputError, match="^tasks and contacts must be sequences"):
        InverseDynamicsController(upper_body, posture)
    sole = SoleContact(talos, talos.foot_frames[0])
    with pytest.raises(InvalidInputError,
                       match="^tasks holds SoleContact, expected Task objects$"):  # fmt: skip
        InverseDynamicsController(talos, [sole])
    with pytest.raises(
        InvalidInputError,
        match=r"^contacts holds PostureTask, expected Contact \(SoleContact, PointContact, "
        r"\.\.\.\) objects$",
    ):
        InverseDynamicsController(talos, [PostureTask(talos)], [PostureTask(talos)])
    with pytest.raises(ShapeError, match="^tasks: a PostureTask was built for another robot"):
        InverseDynamicsController(upper_body, [PostureTask(talos)])
    with pytest.raises(ShapeError, match="^contacts: a SoleContact was built for another robot"):
        InverseDynamicsController(upper_body, [posture], [sole])
    unlimited = upper_body.torque_limit.copy()
    unlimited[2] = 0.0  # a model without the effort limit of one joint
    robot = dataclasses.replace(upper_body, torque_limit=unlimited)
    with pytest.raises(InvalidInputError, match=r"^robot.torque_limit must be > 0 for every"):
        InverseDynamicsController(robot, [PostureTask(robot)])


def test_the_certificate_starts_from_daqps_active_set_then_from_the_last_one(
    upper_body, monkeypatch
):
    """Torque limits binding on a fixed base: the first tick's QP goes to DAQP, whose
    multipliers seed the active set that one KKT solve then certifies; the next tick at the
    same state starts from that set (one KKT solve, no solver call). proxsuite, run on the
    same QP as it is after a DAQP failure, certifies the same way."""
    from dmpopt.control import qp_stages

    real, calls = qp_stages._active_set, []

    def recorded(problem, at_upper, at_lower, tolerance, rounds, duals=None, workspace=None):
        seeded = int(at_upper.sum() + at_lower.sum())
        solution, solves = real(problem, at_upper, at_lower, tolerance, rounds, duals, workspace)
        calls.append((rounds, seeded, solution is not None, solves))
        return solution, solves

    monkeypatch.setattr(qp_stages, "_active_set", recorded)
    controller, q, v = saturating_posture(upper_body)
    first = controller.compute_torques(q, v)
    binding = int(np.sum(np.abs(first) >= controller.torque_limit * (1 - 1e-9)))
    assert binding >= 3 and controller.stats.last_status == "DAQP_SOLVED"
    assert calls == [(qp_stages._REFINEMENT_ROUNDS, binding, True, 1)]
    second = controller.compute_torques(q, v)
    assert calls[1:] == [(qp_stages._WARM_ROUNDS, binding, True, 1)]
    assert (controller.stats.last_status, controller.stats.last_iterations) == (
        "ACTIVE_SET_SOLVED", 1)  # fmt: skip
    np.testing.assert_allclose(second, first, rtol=0, atol=1e-9)
    # proxsuite on that QP (as after a DAQP failure): cold, its answer seeds the same set
    # (one KKT solve, the same torques); warm from the certified optimum, it needs fewer
    # iterations, counted as proxsuite counts
    qp, stage = controller._current, controller._current.tick.limited
    run = qp.tick.solver._run  # one proxsuite solve and its refinement, as a tick makes it
    stage.qp.init(*stage.init_arguments)
    assert run(stage, True, math.inf, qp.stats, qp.tick._take)
    assert controller.stats.last_status == "PROXQP_SOLVED" and calls[-1][1:] == (binding, True, 1)
    np.testing.assert_allclose(qp.assembly.candidate, qp.assembly.solution, rtol=0, atol=1e-9)
    cold = controller.stats.last_iterations
    assert run(stage, False, math.inf, qp.stats, qp.tick._take)
    warm = controller.stats.last_iterations
    assert warm < cold and warm == stage.qp.results.info.iter  # one call: proxsuite's count


def test_solver_defaults(upper_body):
    """The documented defaults: eps_abs = duality-gap tolerance = 1e-6 (no relative one), 50
    outer iterations of at most 10 inner ones, stopping on the duality gap too, a 5 ms budget,
    proxsuite's PrimalDualLDLT factorisation."""
    controller = InverseDynamicsController(upper_body, [PostureTask(upper_body)])
    settings = controller.qp.settings
    assert (settings.eps_abs, settings.eps_rel, settings.eps_duality_gap_abs) == (1e-6, 0.0, 1e-6)
    assert (settings.max_iter, settings.max_iter_in, settings.check_duality_gap) == (50, 10, True)
    assert controller.time_budget == 5e-3
    backend = proxsuite.proxqp.dense.DenseBackend.PrimalDualLDLT
    assert controller.qp.which_dense_backend() == backend


def test_default_limited_joints_have_both_position_limits(upper_body):
    """By default only joints with two finite position limits get acceleration bounds: an
    elbow without a lower limit takes a -200 rad/s^2 reference at rest (bounded, it would
    stop at -v_max / h = -20 v_max); limited_joints names a group as well."""
    names = list(upper_body.actuated_joint_names)
    elbow = names.index("arm_left_4_joint")
    i_q = upper_body.configuration_indices(["arm_left_4_joint"])[0]
    lower = np.array(upper_body.position_lower, dtype=float)
    lower[i_q] = -np.inf
    robot = dataclasses.replace(upper_body, position_lower=lower)
    posture = PostureTask(robot, stiffness=0.0, damping=0.0)
    acceleration = np.zeros(robot.nv)
    acceleration[elbow] = -200.0
    posture.set_reference(robot.reference_configuration, None, acceleration)
    controller = InverseDynamicsController(
        robot, [posture], time_budget=1.0, torque_limit_scale=100.0
    )
    controller.compute_torques(robot.reference_configuration, np.zeros(robot.nv))
    assert -200.0 < -20.0 * robot.velocity_limit[elbow]  # the bound would bind
    assert controller.joint_accelerations[elbow] == pytest.approx(-200.0, rel=1e-6)
    arm = InverseDynamicsController(
        upper_body, [posture], limited_joints="left_arm", torque_limit_scale=100.0
    )
    arm.compute_torques(upper_body.reference_configuration, np.zeros(upper_body.nv))
    assert arm.joint_accelerations[elbow] == pytest.approx(-20.0 * robot.velocity_limit[elbow])


# ---------------------------------------------------------------- the reduced QPs
def reference_solution(controller, q, v, acceleration_regularization, force_regularization):
    """The QP of the module docstring, assembled naively: x = (qdd, f) with the base and
    contact rows as equalities and the torque and cone rows as inequalities, from the tasks as
    the controller's last tick updated them. Returns (qdd, wrenches, tau)."""
    import proxsuite

    robot, model = controller.robot, controller.model
    data = model.createData()
    pin.computeAllTerms(model, data, q, v)
    mass, bias = data.M, data.nle
    nv, n_act = robot.nv, robot.n_actuated
    n_base, n_force = nv - n_act, 6 * len(controller.contacts)
    n = nv + n_force
    hessian = np.diag(np.r_[np.full(nv, acceleration_regularization), np.full(n_force, 0.0)])
    hessian[nv:, nv:] += force_regularization * np.eye(n_force)
    gradient = np.zeros(n)
    for task in controller.tasks:
        if isinstance(task, PostureTask):
            task.update(q, v, None)  # its PD law (the controller evaluates it in its copy)
            indices = task.velocity_indices
            hessian[indices, indices] += task.weight
            gradient[indices] -= task.weight * task.target
        else:
            hessian[:nv, :nv] += task.weight * task.jacobian.T @ task.jacobian
            gradient[:nv] -= task.weight * task.jacobian.T @ task.target
    contact_jacobian = np.vstack([c.jacobian for c in controller.contacts])
    contact_target = np.concatenate([c.target for c in controller.contacts])
    equality = np.zeros((n_base + n_force, n))
    equality[:n_base, :nv] = mass[:n_base]
    equality[:n_base, nv:] = -contact_jacobian[:, :n_base].T
    equality[n_base:, :nv] = contact_jacobian
    equality_target = np.r_[-bias[:n_base], contact_target]
    n_cone = 12 * len(controller.contacts)
    inequality = np.zeros((n_act + n_cone, n))
    inequality[:n_act, :nv] = mass[n_base:]
    inequality[:n_act, nv:] = -contact_jacobian[:, n_base:].T
    lower = np.r_[-robot.torque_limit - bias[n_base:], np.full(n_cone, -1e20)]
    upper = np.r_[robot.torque_limit - bias[n_base:], np.zeros(n_cone)]
    for k, contact in enumerate(controller.contacts):
        rows = slice(n_act + 12 * k, n_act + 12 * (k + 1))
        inequality[rows, nv + 6 * k : nv + 6 * (k + 1)] = contact.wrench_matrix
        upper[rows] = contact.wrench_upper
    qp = proxsuite.proxqp.dense.QP(n, n_base + n_force, n_act + n_cone)
    qp.settings.eps_abs, qp.settings.eps_rel, qp.settings.max_iter = 1e-10, 0.0, 100000
    qp.settings.eps_primal_inf = qp.settings.eps_dual_inf = 1e-14  # it is feasible
    qp.init(hessian, gradient, equality, equality_target, inequality, lower, upper)
    qp.solve()
    assert qp.results.info.status.name == "PROXQP_SOLVED"
    x = qp.results.x
    tau = mass[n_base:] @ x[:nv] + bias[n_base:] - contact_jacobian[:, n_base:].T @ x[nv:]
    return x[:nv], x[nv:].reshape(-1, 6), tau


@pytest.mark.parametrize("case", ["free", "cones", "torque_limits", "contact_rows_kept"])
def test_reduced_qp_matches_the_full_qp(talos, case, monkeypatch):
    """The controller's eliminations (base and contact rows solved for the basic
    accelerations, scaled wrenches, inequality rows added on demand) give the solution of the
    QP as stated, when no inequality is active and when cone or torque rows are; DAQP and
    the active-set certificate answer, proxsuite is never called, and DAQP's active set (over
    the full variables, with the contact rows as equalities, on a contact set's first QPs) is
    the optimal one: its certificate takes one KKT solve."""
    import dataclasses

    import dmpopt.control.assembly as assembly
    from dmpopt.control import qp_stages

    real, refinements = qp_stages._active_set, []

    def recorded(problem, at_upper, at_lower, tolerance, rounds, duals=None, workspace=None):
        solution, solves = real(problem, at_upper, at_lower, tolerance, rounds, duals, workspace)
        if rounds == qp_stages._REFINEMENT_ROUNDS:  # after DAQP
            refinements.append((problem[2] is not None, solves))
        return solution, solves

    monkeypatch.setattr(qp_stages, "_active_set", recorded)

    rng = np.random.default_rng(7)
    robot, friction, com_acceleration, speed = talos, 0.7, [0.0, 0.0, 0.0], 0.2
    if case == "free":  # slow enough for the sole wrenches to stay inside their cones
        speed = 0.02
    if case == "cones":
        friction, com_acceleration = 0.2, [6.0, -4.0, 0.0]
    if case == "torque_limits":  # knees (leg joints 4) and hip pitch (3) far below gravity
        limit = talos.torque_limit.copy()
        limit[[2, 3, 8, 9]] = 20.0
        robot = dataclasses.replace(talos, torque_limit=limit)
    if case == "contact_rows_kept":  # every tick takes the ill-conditioned fallback
        monkeypatch.setattr(assembly, "_MIN_PIVOT_RATIO", 2.0)
    regularization = {"acceleration_regularization": 1e-6, "force_regularization": 1e-6}
    controller, com = standing_controller(
        robot, friction=friction, tolerance=1e-10, joint_limit_horizon=None,
        max_iterations=10_000, time_budget=1.0, **regularization,
    )  # fmt: skip
    com.set_target(com.target_position, acceleration=com_acceleration)
    for stage in controller._current.tick.stages:
        stage.qp = _Forbidden()
    statuses = []
    for _ in range(3):
        q, v = random_state(robot, rng, spread=0.02, speed=speed)
        q[:3] = robot.reference_configuration[:3]
        tau = controller.compute_torques(q, v)
        statuses.append(controller.stats.last_status)
        qdd, wrenches, tau_ref = reference_solution(controller, q, v, **regularization)
        np.testing.assert_allclose(controller.joint_accelerations, qdd, atol=1e-6)
        np.testing.assert_allclose(controller.contact_wrenches, wrenches, atol=1e-4)
        tau_ref = np.clip(tau_ref, -robot.torque_limit, robot.torque_limit)
        np.testing.assert_allclose(tau, tau_ref, atol=1e-4)
    stats = controller.stats
    assert stats.n_fallbacks == 0 and stats.n_cold_restarts == 0
    # Without active inequalities the tick is solved by Cholesky, with them by DAQP on the
    # first tick, then by DAQP or active-set iterations from the last active set.
    if case == "free":
        assert statuses == ["CHOLESKY_SOLVED"] * 3
    else:
        assert statuses[0] == "DAQP_SOLVED"
        assert set(statuses) <= {"DAQP_SOLVED", "ACTIVE_SET_SOLVED"}
    if case in ("torque_limits", "contact_rows_kept"):  # QPs with equality rows went to DAQP
        assert (True, 1) in refinements
    assert all(solves == 1 for _, solves in refinements), refinements
    if case == "cones":
        margins = [c.cone_margin(w) for c, w in zip(controller.contacts, wrenches)]
        assert min(m.min() for m in margins) < 1e-6, "a cone row should be active"
    if case == "torque_limits":
        assert stats.n_torque_limited > 0
        assert np.any(np.abs(tau) >= robot.torque_limit - 1e-6)
        assert np.all(np.abs(tau) <= robot.torque_limit + 1e-9)
    else:
        assert stats.n_torque_limited == 0


def test_tasks_shared_by_two_controllers(upper_body):
    """Tasks write into their controller's rows; a second controller built on the same tasks
    takes them over, and the first still gets correct values."""
    rng = np.random.default_rng(8)

    def build():
        posture = PostureTask(upper_body, weight=0.1, stiffness=10.0)
        hand = FrameTask(upper_body, "gripper_left_base_link", weight=1.0, stiffness=50.0)
        return [posture, hand]

    shared = build()
    first = InverseDynamicsController(upper_body, shared)
    second = InverseDynamicsController(upper_body, shared)
    alone = InverseDynamicsController(upper_body, build())
    for _ in range(3):
        q, v = random_state(upper_body, rng)
        expected = alone.compute_torques(q, v)
        np.testing.assert_allclose(first.compute_torques(q, v), expected, atol=1e-8)
        np.testing.assert_allclose(second.compute_torques(q, v), expected, atol=1e-8)
        np.testing.assert_allclose(shared[1].jacobian, alone.tasks[1].jacobian, atol=1e-12)


# ---------------------------------------------------------------- answer keys of the arguments
def test_computed_torque_defaults_clip_and_argument_names(upper_body):
    """Defaults Kp = 100, Kd = 20, omitted references zero and the torques clipped to the
    limits on both sides (the law written out, then clipped); integer arrays and zero gains
    are accepted; each bad argument is named."""
    rng = np.random.default_rng(8)
    model, nv = upper_body.model, upper_body.nv
    q, v = random_state(upper_body, rng)
    q_ref = q + 3.0 * np.sign(rng.normal(size=nv))  # saturates joints both ways
    data = upper_body.create_data()
    unclipped = pin.rnea(model, data, q, v, np.zeros(nv)) + 100.0 * (q_ref - q) - 20.0 * v
    limit = upper_body.torque_limit
    assert (unclipped > limit).any() and (unclipped < -limit).any()
    tau = ComputedTorqueController(upper_body).compute_torques(q, v, q_ref)
    np.testing.assert_allclose(tau, np.clip(unclipped, -limit, limit), rtol=1e-12, atol=1e-9)
    free = ComputedTorqueController(upper_body, clip_to_limits=False)
    np.testing.assert_allclose(free.compute_torques(q, v, q_ref), unclipped, atol=1e-9)
    zero_gains = ComputedTorqueController(upper_body, stiffness=0, damping=[0.5] * nv)
    integers = np.zeros(nv, dtype=int)
    expected = pin.rnea(model, data, np.zeros(nv), np.zeros(nv), np.ones(nv))
    tau = zero_gains.compute_torques(integers, integers, integers, integers, np.ones(nv, int))
    np.testing.assert_allclose(tau, np.clip(expected, -limit, limit), atol=1e-9)
    for options, error, message in [
        (dict(stiffness="stiff"), InvalidInputError, "stiffness must be numbers"),
        (dict(stiffness=-1.0), InvalidInputError, "stiffness must be finite and >= 0"),
        (dict(damping=np.ones(3)), ShapeError, r"damping has shape \(3,\)"),
        (dict(damping=np.nan), InvalidInputError, "damping must be finite and >= 0"),
    ]:
        with pytest.raises(error, match=message):
            ComputedTorqueController(upper_body, **options)
    with pytest.raises(InvalidInputError, match="reference_velocity must be numbers"):
        free.compute_torques(q, v, q_ref, "fast")


def test_posture_reference_arguments(upper_body):
    """set_reference: an omitted velocity is zero and the acceleration after it still set;
    large finite values are accepted; the bad one is named; only positions outside the
    joint limits warn."""
    arm = PostureTask(upper_body, "left_arm")
    positions = arm.reference_position.copy()
    arm.set_reference(positions, None, np.arange(7.0))
    np.testing.assert_array_equal(arm.reference_velocity, np.zeros(7))
    np.testing.assert_array_equal(arm.reference_acceleration, np.arange(7.0))
    with np.errstate(over="ignore"):  # their sum overflows, each is finite
        arm.set_reference(positions, np.full(7, 1e308))
    np.testing.assert_array_equal(arm.reference_velocity, np.full(7, 1e308))
    with pytest.raises(ShapeError, match=r"^accelerations has shape \(3,\)"):
        arm.set_reference(positions, None, np.zeros(3))
    with pytest.raises(InvalidInputError, match="^accelerations must be numbers"):
        arm.set_reference(positions, None, "fast")
    outside = np.asarray(upper_body.position_upper)[arm.configuration_indices] + 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        arm.set_reference(positions, outside, outside)
    with pytest.warns(UserWarning, match="outside its position limits"):
        arm.set_reference(outside)
    # a NaN is named whatever the array's layout or type (strided view, list, read-only)
    strided = np.repeat(positions, 2)[::2]
    strided[4] = np.nan
    frozen = positions.copy()
    frozen[0] = np.nan
    frozen.flags.writeable = False
    for bad in (strided, list(strided), frozen):
        with pytest.raises(InvalidInputError, match="^positions must be finite"):
            arm.set_reference(bad)
    with pytest.raises(InvalidInputError, match="^accelerations must be finite"):
        arm.set_reference(positions, None, np.repeat([0.0, -np.inf], 7)[::2][::-1])


def test_placements_must_be_finite_rigid_motions(upper_body):
    """A frame target with a NaN translation, or a rotation 0.1 % off orthonormal, is
    refused (one off by round-off, 1e-7, is accepted); so are a position that is not
    numbers and a velocity of the wrong size, by name."""
    hand = FrameTask(upper_body, "gripper_left_base_link")
    for bad in (
        pin.SE3(np.eye(3), np.array([np.nan, 0.0, 0.0])),
        pin.SE3(1.001 * np.eye(3), np.zeros(3)),
    ):
        with pytest.raises(InvalidInputError, match="placement must be finite with a rotation"):
            hand.set_target(bad)
    hand.set_target(pin.SE3(np.eye(3) + np.diag([1e-7, 1e-7], 1), np.zeros(3)))  # round-off
    with pytest.raises(InvalidInputError, match="^placement must be numbers"):
        hand.set_target("up")
    with pytest.raises(ShapeError, match=r"^velocity has shape \(2,\)"):
        hand.set_target(np.zeros(3), velocity=np.ones(2))
    # a 3-vector velocity or acceleration (a position DMP's) is the linear part, angular 0
    hand.set_target(np.zeros(3), [1.0, 2.0, 3.0], [4.0, 5.0, 6.0])
    np.testing.assert_array_equal(hand.target_velocity, [1, 2, 3, 0, 0, 0])
    np.testing.assert_array_equal(hand.target_acceleration, [4, 5, 6, 0, 0, 0])
    hand.set_target(np.zeros(3), 0.5)  # a scalar: every component; acceleration omitted: 0
    np.testing.assert_array_equal(hand.target_velocity, np.full(6, 0.5))
    np.testing.assert_array_equal(hand.target_acceleration, np.zeros(6))
    # target_placement is a copy; assigning it sets the placement only, checked
    turn = pin.SE3(pin.exp3(np.array([0.0, 0.0, 0.3])), np.array([0.1, 0.2, 0.3]))
    hand.target_placement = turn
    copy = hand.target_placement
    copy.translation = np.full(3, 9.0)  # a copy: the task keeps its target
    assert hand.target_placement.isApprox(turn, 0.0)
    np.testing.assert_array_equal(hand.target_velocity, np.full(6, 0.5))
    with pytest.raises(InvalidInputError, match="^placement must be finite;"):
        hand.target_placement = np.array([0.0, np.inf, 0.0])
    assert hand.target_placement.isApprox(turn, 0.0)


def test_removed_task_no_longer_counts(upper_body):
    """After remove_task of the hand task the tick is the posture PD law alone (written
    out); the only task left cannot be removed."""
    rng = np.random.default_rng(9)
    posture = PostureTask(upper_body, weight=1.0, stiffness=25.0, damping=7.0)
    hand = FrameTask(upper_body, "gripper_left_base_link", weight=1e2, stiffness=10.0)
    controller = InverseDynamicsController(
        upper_body, [posture, hand], acceleration_regularization=1e-12, tolerance=1e-10,
        joint_limit_horizon=None,
    )  # fmt: skip
    q, v = random_state(upper_body, rng)
    q_ref, v_ref = random_state(upper_body, rng)
    posture.set_reference(q_ref, v_ref)
    controller.compute_torques(q, v)
    law = 25.0 * (q_ref - q) + 7.0 * (v_ref - v)
    assert np.abs(controller.joint_accelerations - law).max() > 1e-3  # the hand counts
    controller.remove_task(hand)
    assert controller.tasks == (posture,)
    controller.compute_torques(q, v)
    np.testing.assert_allclose(controller.joint_accelerations, law, atol=1e-8)
    with pytest.raises(InvalidInputError, match="remove_task would leave no task"):
        controller.remove_task(posture)


def test_settings_reach_every_contact_set_qp(talos, monkeypatch, proxsuite_only):
    """time_budget and raise_on_failure set on the controller hold in the QP in use and in
    the QPs built later; after reset the counters start again from the next tick."""
    from dmpopt.control import qp_stages

    controller, com = standing_controller(talos, friction=0.2)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    controller.compute_torques(q, v)
    controller.time_budget = 0.25
    controller.raise_on_failure = True
    assert controller.time_budget == 0.25 and controller.raise_on_failure is True
    controller.remove_contact("right_sole_link")
    controller.compute_torques(q, v)
    assert controller.active_contacts == ("left_sole_link",)
    assert controller.time_budget == 0.25 and controller.raise_on_failure is True
    controller.reset()
    controller.compute_torques(q, v)
    assert controller.stats.n_ticks == 1
    com.set_target(com.target_position, acceleration=[6.0, -4.0, 0.0])
    controller.compute_torques(q, v)
    controller.qp.settings.max_iter = 1
    monkeypatch.setattr(qp_stages, "_REFINEMENT_ROUNDS", 0)  # see the fall-back test
    com.set_target(com.target_position + [0.05, 0.02, -0.05], acceleration=[-6.0, 4.0, 0.0])
    with pytest.raises(NoSolutionFound):
        controller.compute_torques(q, v)


def test_hold_answer_of_a_first_tick_is_the_clipped_bias_torque(talos, upper_body):
    """A tick that fails before any valid one holds h_a(q, v) (pin.nonLinearEffects)
    clipped to the limits, counted each time as "hold"; the next good tick starts again
    without inequality rows (a direct answer)."""
    posture = PostureTask(upper_body)
    controller = InverseDynamicsController(upper_body, [posture])
    q = upper_body.reference_configuration
    v = np.full(upper_body.nv, 20.0)  # Coriolis terms beyond some torque limits
    bias = pin.nonLinearEffects(upper_body.model, upper_body.create_data(), q, v)
    limit = upper_body.torque_limit
    assert (bias > limit).any() and (bias < -limit).any()
    posture.reference_position[3] = np.nan  # bypasses validation
    for count in (1, 2):
        tau = controller.compute_torques(q, v)
        np.testing.assert_allclose(tau, np.clip(bias, -limit, limit), rtol=1e-12)
        assert controller.stats.n_fallbacks == count and controller.stats.last_answer == "hold"
    standing, com = standing_controller(talos)
    q, v = talos.reference_configuration, np.zeros(talos.nv)
    standing.compute_torques(q, v)
    target = com.target_position.copy()
    com.target_position[0] = np.nan
    standing.compute_torques(q, v)
    assert standing.stats.last_answer == "hold"
    com.target_position[:] = target
    standing.compute_torques(q, v)
    assert standing.stats.last_answer == "direct" and standing.stats.last_iterations == 0


HAND = "gripper_left_base_link"


def test_task_defaults_checks_and_names(upper_body):
    """Defaults of the three tasks (weight 1; K_p 50 CoM, 100 frame, 10 posture; K_d 2 sqrt K_p
    unless given), each argument's name, the frame rows allowed, the group of a posture task,
    and its warning: once per joint, not at the limit itself, from the caller's line."""
    com, frame, posture = ComTask(upper_body), FrameTask(upper_body, HAND), PostureTask(upper_body)
    for task, kp in ((com, 50.0), (frame, 100.0), (posture, 10.0)):
        assert task.weight == 1.0
        np.testing.assert_array_equal(task.stiffness, kp)
        np.testing.assert_allclose(task.damping, 2.0 * np.sqrt(kp), rtol=1e-15)
    np.testing.assert_array_equal(ComTask(upper_body, damping=3.0).damping, 3.0)
    np.testing.assert_array_equal(FrameTask(upper_body, HAND, damping=4.0).damping, 4.0)
    for bad, message in ((0.0, "^weight must be a finite number > 0"),
                         (np.inf, "^weight must be a finite number > 0"),
                         ([1.0, 2.0], "^weight must be a finite number > 0"),
                         ("heavy", "^weight must be numbers")):  # fmt: skip
        with pytest.raises(InvalidInputError, match=message):
            ComTask(upper_body, weight=bad)
    for name in ("stiffness", "damping"):
        with pytest.raises(ShapeError, match=f"^{name} has shape"):
            ComTask(upper_body, **{name: [1.0, 2.0]})
    with pytest.raises(InvalidInputError, match="^stiffness and damping must be finite and >= 0"):
        ComTask(upper_body, stiffness=1.0, damping=-1.0)
    with pytest.raises(InvalidInputError, match="^stiffness and damping must be finite and >= 0"):
        ComTask(upper_body, stiffness=-1.0, damping=1.0)
    com.set_target([0.1, 0.2, 0.3], velocity=[1.0, 2.0, 3.0], acceleration=[4.0, 5.0, 6.0])
    np.testing.assert_array_equal(com.target_velocity, [1.0, 2.0, 3.0])
    for name in ("position", "velocity", "acceleration"):
        values = {"position": [0.0, 0.0, 0.0], name: [1.0, 2.0]}
        with pytest.raises(ShapeError, match=f"^{name} has shape"):
            com.set_target(**values)
    for rows in ([5], [0], [0, 5]):
        assert FrameTask(upper_body, HAND, components=rows).rows.tolist() == rows
    for rows in ([], [-1], [6]):
        with pytest.raises(InvalidInputError, match="expected indices in 0..5"):
            FrameTask(upper_body, HAND, components=rows)
    arm = PostureTask(upper_body, "left_arm")
    assert arm.joint_names == tuple(upper_body.joint_groups["left_arm"])
    upper = np.asarray(upper_body.position_upper)[arm.configuration_indices]
    lower = np.asarray(upper_body.position_lower)[arm.configuration_indices]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        arm.set_reference(upper)  # at the limits: no warning
        arm.set_reference(lower)
    outside = upper.copy()
    outside[3] += 0.5
    name = arm.joint_names[3]
    with pytest.warns(UserWarning) as caught:
        arm.set_reference(outside)
        arm.set_reference(outside)  # once per joint
    assert len(caught) == 1
    if not os.environ.get("MUTANT_UNDER_TEST"):  # mutmut's trampoline adds a frame
        assert caught[0].filename == __file__  # the warning points at the caller
    assert str(caught[0].message) == (
        f"PostureTask: reference {outside[3]:.4g} rad of {name!r} is outside its position "
        f"limits [{lower[3]:.4g}, {upper[3]:.4g}]; the joint stops at its limit (clip the "
        "reference to silence this)"
    )


def test_answer_counters_add_up_over_ticks(upper_body):
    """Two infeasible ticks (an elbow 5 mm before its limit at 4 rad/s, torques at 2 %) are
    two relaxed, torque-limited ticks; two ticks asking 500 rad/s^2 of every joint are two
    solved, torque-limited ones; every counter counts each tick once."""
    posture = PostureTask(upper_body, weight=1.0, stiffness=10.0)
    weak = InverseDynamicsController(
        upper_body, [posture], torque_limit_scale=0.02, time_budget=1.0
    )
    i_q, i_v = (f(["arm_left_4_joint"])[0] for f in (upper_body.configuration_indices,
                                                     upper_body.velocity_indices))  # fmt: skip
    q, v = upper_body.reference_configuration.copy(), np.zeros(upper_body.nv)
    q[i_q], v[i_v] = upper_body.position_upper[i_q] - 0.005, 4.0
    for _ in range(2):
        weak.compute_torques(q, v)
    stats = weak.stats
    assert (stats.n_ticks, stats.n_relaxed, stats.n_torque_limited) == (2, 2, 2)
    assert (stats.n_solved, stats.n_direct, stats.n_fallbacks) == (0, 0, 0)
    strong = InverseDynamicsController(upper_body, [posture], time_budget=1.0)
    q = upper_body.reference_configuration
    posture.set_reference(q, None, np.full(upper_body.nv, 500.0))
    for _ in range(2):
        strong.compute_torques(q, np.zeros(upper_body.nv))
    stats = strong.stats
    assert (stats.n_ticks, stats.n_solved, stats.n_torque_limited) == (2, 2, 2)
    assert (stats.n_relaxed, stats.n_direct, stats.n_fallbacks) == (0, 0, 0)
    assert stats.last_answer == "solved"


def test_sole_contact_without_corners_and_unknown_posture_group(upper_body):
    """No silent traps: a SoleContact on a robot without sole corners and a PostureTask on a
    misspelt group say what is wrong and how to fix it (not numpy's empty-reduction error or
    a bare KeyError)."""
    no_soles = dataclasses.replace(upper_body, foot_frames=("gripper_left_base_link",))
    with pytest.raises(InvalidInputError, match=r"has no sole_corners.*RobotModel.from_urdf"):
        SoleContact(no_soles, "gripper_left_base_link")
    with pytest.raises(InvalidInputError) as error:
        PostureTask(upper_body, "left_armm")
    assert str(error.value).startswith(
        "joints='left_armm' is not a joint group of 'talos_reduced_upper_body'; expected one of "
        "['head', 'left_arm', 'left_gripper', 'right_arm', 'right_gripper', 'torso']"
    )


def test_no_garbage_collection_starts_inside_a_tick(talos, monkeypatch):
    """With the collector's threshold at one allocation, collections start around the ticks
    but none inside one (compute_torques pauses the collector), and it is on again after;
    ticks that ramp a contact down and switch to another contact set's QP (built then, not
    prepared) included."""
    import gc

    from dmpopt.control.controller import InverseDynamicsController

    controller, _ = standing_controller(talos)
    inside, collections = [False], []
    tick = InverseDynamicsController._compute_torques

    def watched(self, q, v, t):
        inside[0] = True
        try:
            return tick(self, q, v, t)
        finally:
            inside[0] = False

    def watch(phase, info):
        if phase == "start":
            collections.append(inside[0])

    monkeypatch.setattr(InverseDynamicsController, "_compute_torques", watched)
    threshold = gc.get_threshold()
    gc.callbacks.append(watch)
    gc.set_threshold(1)
    try:
        q, v = talos.reference_configuration, np.zeros(talos.nv)
        for k in range(6):
            if k == 2:
                controller.remove_contact(talos.foot_frames[1], transition_time=0.002)
            controller.compute_torques(q, v, 0.001 * k)
            [[] for _ in range(3)]  # garbage between ticks: collections must start here
    finally:
        gc.set_threshold(*threshold)
        gc.callbacks.remove(watch)
    assert controller.active_contacts == (talos.foot_frames[0],)  # switched
    assert collections and not any(collections)
    assert gc.isenabled()


def test_control_loop_freezes_the_objects_made_before_it():
    """Inside control_loop the objects alive at its start are in the permanent generation
    (gc.get_freeze_count counts them) and none after it; an error inside unfreezes too."""
    import gc

    from dmpopt.control import control_loop

    before = gc.get_freeze_count()
    with control_loop():
        assert gc.get_freeze_count() > before
    assert gc.get_freeze_count() == before
    with pytest.raises(ZeroDivisionError), control_loop():
        1 / 0
    assert gc.get_freeze_count() == before


def test_control_loop_collects_only_the_youngest_generation():
    """Entering control_loop starts one collection, of generation 0 (a full one scanned every
    object of the process at each loop); none starts inside an empty loop's body."""
    import gc

    from dmpopt.control import control_loop

    generations = []

    def watch(phase, info):
        if phase == "start":
            generations.append(info["generation"])

    gc.callbacks.append(watch)
    try:
        with control_loop():
            entered = list(generations)
    finally:
        gc.callbacks.remove(watch)
    assert entered == [0]


def test_proxsuite_starts_from_the_last_certified_optimum_not_from_its_own_iterates(
    upper_body, proxsuite_only
):
    """Torque limits binding on a fixed base: a warm proxsuite solve starts from the last
    certified optimum and its multipliers, so its iterations and answer are the same whatever
    proxsuite computed in between (its own iterates differ in their last bits between
    processes; started from them, the solves of two processes drift apart)."""
    controller, q, v = saturating_posture(upper_body)
    controller.compute_torques(q, v)
    qp, stage = controller._current, controller._current.tick.limited
    assert stage.certified

    def warm_solve():
        assert qp.tick.solver._run(stage, False, math.inf, qp.stats, qp.tick._take)
        return controller.stats.last_iterations, qp.assembly.candidate.copy()

    iterations, answer = warm_solve()
    settings = stage.qp.settings
    settings.max_iter, settings.initial_guess = 1, proxsuite.proxqp.InitialGuess.NO_INITIAL_GUESS
    stage.qp.solve()  # proxsuite's last result is now a first iterate from scratch
    settings.max_iter = 50
    again, same = warm_solve()
    assert again == iterations and again > 0
    np.testing.assert_array_equal(same, answer)


class _Forbidden:
    """A stage's proxsuite QP that must not be used: any call raises."""

    def __getattr__(self, name):
        raise AssertionError(f"proxsuite's {name} was used")


class _NoisyProxsuite:
    """A stage's proxsuite QP whose answers (x and z) get a random error of ``size`` times
    their largest entry (at least 1) after every solve: far more than the ~1e-12 by which
    proxsuite's answers to the same QP differ between processes."""

    def __init__(self, qp, rng, size):
        self._qp, self._rng, self._size = qp, rng, size

    def __getattr__(self, name):
        return getattr(self._qp, name)

    def solve(self, *arguments):
        self._qp.solve(*arguments)
        results = self._qp.results
        for values in (results.x, results.z):  # views of proxsuite's own arrays
            scale = max(1.0, float(np.abs(values).max(initial=0.0)))
            values += self._size * scale * self._rng.uniform(-1.0, 1.0, values.size)


def test_an_unconverged_proxsuite_answer_does_not_decide_the_torques(
    upper_body, monkeypatch, proxsuite_only
):
    """Torque limits binding on a fixed base, proxsuite allowed one outer iteration (it stops
    out of iterations on every call) and no warm active-set rounds: a controller whose
    proxsuite answers carry an error of 1e-3 of their scale gives bitwise the torques of one
    without, tick by tick. (Seeding the active set from such an answer puts nearly every row
    into it, with random signs: certified or not, the answers part. Such iterates differ
    between processes: on a near-infeasible QP by far more than their last bits.)"""
    from dmpopt.control import qp_stages

    monkeypatch.setattr(qp_stages, "_WARM_ROUNDS", 0)  # proxsuite on every QP tick
    robot, n_ticks = upper_body, 12
    rng = np.random.default_rng(11)
    states = []
    for _ in range(n_ticks):
        q = robot.reference_configuration + 0.2 * rng.uniform(-1.0, 1.0, robot.nq)
        q = np.clip(q, robot.position_lower, robot.position_upper)
        states.append((q, 0.5 * rng.normal(size=robot.nv)))
    targets = [60.0 * rng.normal(size=robot.nv) for _ in range(n_ticks)]
    runs, statuses = [], []
    for noise in (0.0, 1e-3):
        posture = PostureTask(robot, weight=1.0, stiffness=0.0, damping=0.0)
        controller = InverseDynamicsController(robot, [posture], time_budget=1.0, max_iterations=1)
        for stage in controller._current.tick.stages:
            stage.qp = _NoisyProxsuite(stage.qp, np.random.default_rng(5), noise)
        torques = []
        for k in range(n_ticks):
            posture.set_reference(*states[k], targets[k])
            torques.append(controller.compute_torques(*states[k]))
            statuses.append(controller.stats.last_status)
        assert controller.stats.n_solved >= n_ticks // 2, controller.stats
        runs.append(np.array(torques))
    assert "PROXQP_MAX_ITER_REACHED" in statuses
    np.testing.assert_array_equal(runs[1], runs[0])


@pytest.mark.parametrize("case", ["torque rows", "cone rows"])
def test_torques_do_not_depend_on_proxsuites_last_bits(
    upper_body, talos, case, monkeypatch, proxsuite_only
):
    """Every tick through proxsuite (no warm active-set rounds): two controllers, the second
    built after other heap allocations and with proxsuite's answers perturbed by 1e-11 of
    their scale, give bitwise the same torques on the same states, because the answer is the
    KKT solution of an active set chosen with a margin from proxsuite's multipliers. (A
    threshold at proxsuite's own noise, 1e-12 of the largest multiplier, lets the error move
    rows into the set.)"""
    from dmpopt.control import qp_stages

    monkeypatch.setattr(qp_stages, "_WARM_ROUNDS", 0)  # proxsuite on every QP tick
    rng = np.random.default_rng(7)
    if case == "torque rows":
        robot, n_ticks = upper_body, 12
        states = [random_state(robot, rng) for _ in range(n_ticks)]
        targets = [400.0 * rng.normal(size=robot.nv) for _ in range(n_ticks)]

        def build():
            posture = PostureTask(robot, weight=1.0, stiffness=0.0, damping=0.0)
            controller = InverseDynamicsController(robot, [posture], time_budget=1.0)
            return controller, lambda k: posture.set_reference(*states[k], targets[k])
    else:
        robot, n_ticks = talos, 8
        states = [random_state(robot, rng, spread=0.02, speed=0.3) for _ in range(n_ticks)]
        com0 = pin.centerOfMass(robot.model, robot.create_data(), robot.reference_configuration)
        targets = [com0 + [0.0, 0.05 * (-1) ** k, -0.03] for k in range(n_ticks)]

        def build():
            controller, com = standing_controller(robot, friction=0.1)
            return controller, lambda k: com.set_target(targets[k])

    runs = []
    kept = [np.empty(int(n)) for n in rng.integers(1, 5000, size=20)]  # another heap state
    for noise in (0.0, 1e-11):
        controller, set_target = build()
        for stage in controller._current.tick.stages:
            stage.qp = _NoisyProxsuite(stage.qp, rng, noise)
        torques = []
        for k in range(n_ticks):
            set_target(k)
            torques.append(controller.compute_torques(*states[k]))
        stats = controller.stats
        assert stats.n_solved >= n_ticks // 2 and stats.n_fallbacks == 0, stats
        runs.append(np.array(torques))
    del kept
    np.testing.assert_array_equal(runs[1], runs[0])


@pytest.mark.parametrize("angle", [0.3, np.pi - 1e-4])
def test_frame_and_sole_rows_from_known_errors(upper_body, talos, angle):
    """A FrameTask's rows b = a_ref + K_p e + K_d (v_ref - J v) - drift (J, drift from
    Pinocchio) with the error e = (p_ref - p, w) of a target R_ref = exp([w]) R (a half turn
    included, where the task falls back to Pinocchio's log3), with gains assigned after a first
    update; a SoleContact's error log6(M^-1 M_ref) = nu for M_ref = M exp6(nu)."""
    rng = np.random.default_rng(3)
    for robot in (upper_body, talos):
        q, v = random_state(robot, rng)
        model, data = robot.model, robot.model.createData()
        pin.computeAllTerms(model, data, q, v)
        task = FrameTask(robot, HAND if robot is upper_body else "left_sole_link")
        current = pin.updateFramePlacement(model, data, task.frame_id).copy()
        w = angle * np.array([0.6, 0.0, 0.8])
        velocity, acceleration = rng.normal(size=6), rng.normal(size=6)
        task.set_target(
            pin.SE3(pin.exp3(w) @ current.rotation, current.translation + [0.1, 0.0, -0.2]),
            velocity, acceleration,
        )  # fmt: skip
        task.update(q, v, data)
        task.stiffness, task.damping = np.full(6, 20.0), np.arange(6.0)  # new arrays
        task.update(q, v, data)
        error = np.r_[0.1, 0.0, -0.2, w]
        # near a half turn the axis comes from R's diagonal: error ~ eps / (pi - theta) ~ 1e-12
        np.testing.assert_allclose(task.error(), error, rtol=0, atol=1e-9)
        jacobian = pin.getFrameJacobian(model, data, task.frame_id, pin.LOCAL_WORLD_ALIGNED)
        drift = pin.getFrameClassicalAcceleration(
            model, data, task.frame_id, pin.LOCAL_WORLD_ALIGNED
        ).vector
        expected = acceleration + 20.0 * error + np.arange(6.0) * (velocity - jacobian @ v) - drift
        np.testing.assert_allclose(task.target, expected, rtol=1e-9, atol=1e-8)
        np.testing.assert_allclose(task.jacobian, jacobian, rtol=0, atol=1e-13)
    sole = SoleContact(talos, "left_sole_link")
    nu = np.r_[0.01, -0.02, 0.003, w / angle * min(angle, 0.1)]
    placement = pin.updateFramePlacement(talos.model, data, sole.frame_id)
    sole.reference_placement = placement * pin.exp6(pin.Motion(nu))
    sole.update(q, v, data)
    np.testing.assert_allclose(sole._error, nu, rtol=0, atol=1e-12)
    local = pin.getFrameJacobian(talos.model, data, sole.frame_id, pin.LOCAL)
    np.testing.assert_allclose(sole.jacobian, local, rtol=0, atol=1e-13)


def test_daqps_answer_does_not_depend_on_where_the_arrays_lie(upper_body):
    """Torque limits binding on a fixed base: the QP of the stage with every inequality row,
    copied into buffers at four byte offsets (as another process's heap would place it),
    gives bitwise the same DAQP status, iterations and certified optimum at each (proxsuite's
    vectorised kernels do not: its last bits follow the offsets)."""
    from dmpopt.control.qp_stages import ControllerStats, StageSolver, _arguments, _Stage

    controller, q, v = saturating_posture(upper_body)
    controller.compute_torques(q, v)
    hessian, gradient, _, _, in_matrix, lower, upper = controller._current.tick.limited.problem
    answers = []
    for offset in (0, 1, 2, 3):  # in float64 entries: 0, 8, 16 and 24 bytes

        def placed(array, offset=offset):
            buffer = np.empty(array.size + 4)
            view = buffer[offset : offset + array.size].reshape(array.shape)
            view[...] = array
            return view

        arguments = _arguments(
            placed(hessian), placed(gradient), None,
            (placed(in_matrix), placed(lower), placed(upper)),
        )  # fmt: skip
        backend = proxsuite.proxqp.dense.DenseBackend.Automatic
        stage = _Stage(hessian.shape[0], 0, in_matrix.shape[0], backend, arguments, arguments)
        stage.qp = _Forbidden()
        stats = ControllerStats()
        assert StageSolver(controller.qp)._daqp(stage, stats, lambda stage, x: True)
        answers.append((stats.last_status, stats.last_iterations, stage.warm[0].tobytes(),
                        stage.at_upper.tobytes(), stage.at_lower.tobytes()))  # fmt: skip
    assert answers[0][0] == "DAQP_SOLVED" and answers[0][1] >= 3
    assert answers[1:] == answers[:1] * 3


def test_tick_rows_are_pinocchios(talos):
    """The QP's task and contact rows after a tick (frame tasks, sole contacts and the CoM
    task computed together in one compiled call, another task by its own update) are those
    written from Pinocchio's frame Jacobians and accelerations: J and b = a_ref + K_p e +
    K_d (v_ref - J v) - drift, with e = (p_ref - p, log3(R_ref R^T)) and the classical
    acceleration in world axes for a frame task, e = log6(M^-1 M_ref) and the spatial
    acceleration in sole axes for a sole; a sole's reference placement changed in place or
    replaced is the one used next tick."""

    class Lean(FrameTask):  # a subclass with its own update: rows from that update
        def update(self, q, v, data):
            super().update(q, v, data)
            self.target[:] = 0.5

    rng = np.random.default_rng(11)
    model, data = talos.model, talos.create_data()
    hand = FrameTask(talos, "gripper_left_base_link", weight=2.0, stiffness=30.0)
    lean = Lean(talos, "torso_2_link", components="orientation")
    controller, com = standing_controller(talos)
    controller.add_task(hand)
    controller.add_task(lean)
    q, v = random_state(talos, rng, spread=0.05, speed=0.3)
    pin.framesForwardKinematics(model, data, q)
    placement = data.oMf[hand.frame_id].copy()
    hand.set_target(
        placement * pin.exp6(pin.Motion(0.1 * rng.normal(size=6))),
        rng.normal(size=6), rng.normal(size=6),
    )  # fmt: skip
    com.set_target(com.target_position + [0.01, -0.02, 0.0], rng.normal(size=3))
    left, right = controller.contacts
    for step in ("first", "in place", "replaced"):
        if step == "in place":
            left.reference_placement.rotation = pin.exp3(rng.normal(size=3) * 0.01) @ (
                left.reference_placement.rotation
            )
        elif step == "replaced":
            right.reference_placement = right.reference_placement * pin.exp6(
                pin.Motion(0.01 * rng.normal(size=6))
            )
        controller.compute_torques(q, v)
        formulation = controller._current
        rows, layout = formulation.assembly._rows, formulation.layout
        pin.computeAllTerms(model, data, q, v)
        pin.updateFramePlacements(model, data)
        expected = {}
        for task in (hand, controller.tasks[2]):
            placement, frame = data.oMf[task.frame_id], task.frame_id
            reference = task.target_placement
            error = np.r_[
                reference.translation - placement.translation,
                pin.log3(reference.rotation @ placement.rotation.T),
            ]
            jacobian = pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
            drift = pin.getFrameClassicalAcceleration(
                model, data, frame, pin.LOCAL_WORLD_ALIGNED
            ).vector
            target = (
                task.target_acceleration + task.stiffness * error
                + task.damping * (task.target_velocity - jacobian @ v) - drift
            )  # fmt: skip
            expected[task] = jacobian[task.rows], target[task.rows]
        com_jacobian = pin.jacobianCenterOfMass(model, data, q)
        position = pin.centerOfMass(model, data, q, v, np.zeros(talos.nv)).copy()
        expected[com] = com_jacobian, (
            com.target_acceleration + com.stiffness * (com.target_position - position)
            + com.damping * (com.target_velocity - data.vcom[0]) - data.acom[0]
        )  # fmt: skip
        expected[lean] = (
            pin.getFrameJacobian(model, data, lean.frame_id, pin.LOCAL_WORLD_ALIGNED)[3:],
            np.full(3, 0.5),
        )
        stacked = [t for t in controller.tasks if not isinstance(t, PostureTask)]
        for task, block in zip(stacked, layout.task_rows):
            jacobian, target = expected[task]
            np.testing.assert_allclose(rows[block, : talos.nv], jacobian, rtol=0, atol=1e-12)
            np.testing.assert_allclose(rows[block, -1], target, rtol=1e-12, atol=1e-10)
        pin.computeAllTerms(model, data, q, v)
        pin.updateFramePlacements(model, data)
        for contact, forces in zip(controller.contacts, layout.force_slices):
            frame = contact.frame_id
            jacobian = pin.getFrameJacobian(model, data, frame, pin.LOCAL)
            error = pin.log6(data.oMf[frame].actInv(contact.reference_placement)).vector
            drift = pin.getFrameAcceleration(model, data, frame, pin.LOCAL).vector
            target = contact.stiffness * error - contact.damping * (jacobian @ v) - drift
            block = slice(layout.n_cost + forces.start, layout.n_cost + forces.stop)
            np.testing.assert_allclose(rows[block, : talos.nv], jacobian, rtol=0, atol=1e-12)
            np.testing.assert_allclose(rows[block, -1], target, rtol=1e-12, atol=1e-10)
