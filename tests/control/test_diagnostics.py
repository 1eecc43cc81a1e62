"""Diagnostics of the controller: the rows at their bounds, named, and why an answer relaxed."""

import numpy as np
import pinocchio as pin
import pytest
from dmpopt_robots import load_talos
from dmpopt_robots.talos import TALOS_SOLE_CORNERS

from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    PostureTask,
    SoleContact,
    active_constraints,
    explain,
)


@pytest.fixture(scope="module")
def talos():
    return load_talos("reduced")


def standing(robot, **options):
    posture = PostureTask(robot, weight=0.1, stiffness=10.0)
    com = ComTask(robot, weight=10.0, stiffness=50.0)
    pelvis = FrameTask(robot, "base_link", weight=1.0, stiffness=50.0, components="orientation")
    soles = [SoleContact(robot, f, cop_fraction=0.7) for f in robot.foot_frames]
    controller = InverseDynamicsController(
        robot, [posture, com, pelvis], soles, time_budget=1.0, **options
    )
    return controller, com


@pytest.mark.parametrize("shift, edge", [(0.05, "heel"), (-0.05, "toe")])
def test_centre_of_pressure_edge_is_named(talos, shift, edge):
    """A CoM target 5 cm ahead of the standing CoM asks for a forward CoM acceleration, so the
    ground must push from behind the CoM: each sole's CoP (-tau_y / f_z, from the wrenches)
    sits on its heel edge at 0.7 x 0.11 m (TALOS_SOLE_CORNERS, cop_fraction 0.7); backwards, on
    its toe edge at 0.7 x 0.10 m. Exactly those edges are named."""
    controller, com = standing(talos)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    com.set_target(pin.centerOfMass(talos.model, talos.create_data(), q) + [shift, 0.0, 0.0])
    controller.compute_torques(q, v)
    wrenches = controller.contact_wrenches
    cop = -wrenches[:, 4] / wrenches[:, 2]
    expected_x = 0.7 * (
        TALOS_SOLE_CORNERS[:, 0].min() if edge == "heel" else TALOS_SOLE_CORNERS[:, 0].max()
    )
    np.testing.assert_allclose(cop, expected_x, atol=1e-6)  # the QP's tolerance, scaled
    names = active_constraints(controller)
    cop_names = sorted(n.split(" (")[0] for n in names if n.startswith("CoP"))
    assert cop_names == [f"CoP of {foot} at its {edge} edge" for foot in sorted(talos.foot_frames)]
    # on the edge: 0.0 mm from it (the wrenches' CoP above is within 1e-6 m of it)
    assert all(n.endswith("edge (0.0 mm)") for n in names if n.startswith("CoP"))
    assert explain(controller).startswith("solved; at their bounds: ")


def test_torque_limits_are_named_with_their_side(talos):
    """With 5 % of the motors the torques saturate: every joint with |tau| at its limit (read
    from the torques and limits here) is named, "upper" for a positive torque."""
    controller, _ = standing(talos, torque_limit_scale=0.05)
    controller.compute_torques(talos.reference_configuration.copy(), np.zeros(talos.nv))
    tau, limit = controller.torques, controller.torque_limit
    saturated = np.flatnonzero(np.isclose(np.abs(tau), limit, rtol=1e-3))
    assert saturated.size >= 3
    expected = sorted(
        f"torque limit of {talos.actuated_joint_names[i]} ({'upper' if tau[i] > 0 else 'lower'})"
        for i in saturated
    )
    assert sorted(n for n in active_constraints(controller) if n.startswith("torque")) == expected


def test_relaxed_answer_says_why(talos):
    """With 0.1 % of the motors no answer holds the robot: the relaxed answer names the exact
    QP's infeasibility."""
    controller, _ = standing(talos, torque_limit_scale=0.001)
    controller.compute_torques(talos.reference_configuration.copy(), np.zeros(talos.nv))
    assert controller.stats.last_answer == "relaxed"
    binding = active_constraints(controller)
    assert len(binding) >= 2
    assert explain(controller) == (
        "relaxed: the QP with its inequality rows was not solved (DAQP_INFEASIBLE: "
        "infeasible: no accelerations and wrenches meet every row at once); the contact rows "
        "and joint-limit bounds were relaxed, torque and cone rows kept. At their bounds: "
        + "; ".join(binding)
    )


@pytest.mark.parametrize("side", ["upper", "lower"])
def test_a_joint_at_its_limit_is_named_with_its_side(talos, side):
    """The left elbow 1 mrad inside its upper (lower) position limit, moving into it at 1
    rad/s: its acceleration bound stops it, and it is the one row named, with its side."""
    controller, _ = standing(talos)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    joint = talos.model.joints[talos.model.getJointId("arm_left_4_joint")]
    lower = talos.model.lowerPositionLimit[joint.idx_q]
    upper = talos.model.upperPositionLimit[joint.idx_q]
    q[joint.idx_q] = upper - 1e-3 if side == "upper" else lower + 1e-3
    v[joint.idx_v] = 1.0 if side == "upper" else -1.0
    controller.compute_torques(q, v)
    assert active_constraints(controller) == [
        f"joint limit of arm_left_4_joint ({side} acceleration bound)"
    ]
    assert explain(controller) == (
        f"solved; at their bounds: joint limit of arm_left_4_joint ({side} acceleration bound)"
    )
    # it decelerates: the acceleration opposes the velocity
    assert controller.joint_accelerations[joint.idx_v] * v[joint.idx_v] < 0


def test_a_tick_that_needs_no_inequality_row_says_so(talos):
    """Standing still at the reference posture, nothing binds: a direct answer, no row named."""
    controller, _ = standing(talos)
    controller.compute_torques(talos.reference_configuration.copy(), np.zeros(talos.nv))
    assert controller.stats.last_answer == "direct"
    assert active_constraints(controller) == []
    assert explain(controller) == "direct: no inequality row was needed"


def test_friction_cone_rows_are_named_with_their_direction(talos):
    """On a floor of friction 0.02 with the base moving sideways at 0.3 m/s, the feet push
    sideways as far as the friction pyramid lets them: f_y = -mu / sqrt(2) f_z (the pyramid
    inscribed in the cone, read from the wrenches here), and exactly those rows are named,
    "-y", with no centre-of-pressure distance."""
    posture = PostureTask(talos, weight=0.1, stiffness=10.0)
    com = ComTask(talos, weight=10.0, stiffness=50.0)
    pelvis = FrameTask(talos, "base_link", weight=1.0, stiffness=50.0, components="orientation")
    soles = [SoleContact(talos, f, friction_coefficient=0.02) for f in talos.foot_frames]
    controller = InverseDynamicsController(talos, [posture, com, pelvis], soles, time_budget=1.0)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    com.set_target(pin.centerOfMass(talos.model, talos.create_data(), q))
    v[1] = 0.3
    controller.compute_torques(q, v)
    wrenches = controller.contact_wrenches
    np.testing.assert_allclose(wrenches[:, 1], -0.02 / np.sqrt(2) * wrenches[:, 2], rtol=1e-6)
    names = [n for n in active_constraints(controller) if n.startswith("friction cone")]
    assert names == [f"friction cone of {foot} (-y)" for foot in controller.active_contacts]
