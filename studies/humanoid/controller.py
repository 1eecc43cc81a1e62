"""Controller and simulator set-up: tasks, contacts, the two plants and model variants."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin

from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    JointImpedance,
    PostureTask,
    SoleContact,
)
from dmpopt.sim import IDEAL, GroundContact, Simulator, with_armature

from ..common import TIME_BUDGET
from .demos import DRUM_JOINTS
from .parameters import (
    ARM_STIFFNESS,
    BASE_WEIGHT,
    COM_WEIGHT,
    CONTROLLER_FRICTION,
    DT,
    FALL_HEIGHT,
    GROUND_STIFFNESS,
    HAND_STIFFNESS,
    JOINT_LIMIT_HORIZON,
    MUJOCO_FRICTION,
    POSTURE_WEIGHT,
)

COPING = ("armature", "feedforward", "impedance")  # the parts of the control design


# ------------------------------------------------------------------------ closed loop
def build_controller(
    robot,
    q_start: np.ndarray,
    arm_joints=DRUM_JOINTS,
    hand=None,
    base_task: bool = True,
    com_sink: float | None = None,
    friction: float = CONTROLLER_FRICTION,
    nominal_plant=None,
    coping=COPING,
):
    """Inverse-dynamics controller holding ``q_start``; returns it and the DMP-driven task.

    The driven task is a :class:`PostureTask` on ``arm_joints`` (drumming) or, with ``hand``
    a frame name, a position :class:`FrameTask` on that hand (figure-8). ``base_task=False``
    leaves out the pelvis orientation task (to show why it is needed). The driven joints (the
    hand's arm for the figure-8) are kept within their position and velocity limits.
    ``com_sink`` [m] lowers the CoM target (default: the compliant ground's static
    compression, :func:`_sink`); ``friction`` is the soles' friction coefficient.
    ``nominal_plant`` (a :class:`dmpopt.sim.PlantParameters`) is what the controller believes
    of the joints: its model carries the plant's armature and a :class:`JointImpedance` closes
    the joint loop around the QP's motion (None: the rigid-body model, no joint loop);
    ``coping`` names the parts used, for ablations: ``"armature"`` in the model, friction
    ``"feedforward"``, the joint ``"impedance"``.
    """
    impedance = None
    if nominal_plant is not None:
        if "armature" in coping:
            robot = with_armature(robot, nominal_plant)
        if "feedforward" in coping or "impedance" in coping:
            impedance = JointImpedance.for_plant(
                robot,
                DT,
                nominal_plant,
                feedback="impedance" in coping,
                feedforward="feedforward" in coping,
            )
    actuated = np.sort(
        np.concatenate([robot.configuration_indices([n]) for n in robot.actuated_joint_names])
    )
    posture = PostureTask(robot, weight=POSTURE_WEIGHT, stiffness=10.0)
    posture.set_reference(q_start[actuated])
    if hand is None:
        driven = PostureTask(robot, list(arm_joints), weight=1.0, stiffness=ARM_STIFFNESS)
        driven.set_reference(q_start[robot.configuration_indices(list(arm_joints))])
    else:
        driven = FrameTask(robot, hand, weight=1.0, stiffness=HAND_STIFFNESS, components="position")
        data = robot.create_data()
        pin.framesForwardKinematics(robot.model, data, q_start)
        driven.set_target(data.oMf[robot.model.getFrameId(hand)].translation.copy())
    tasks = [posture, driven]
    limited = list(arm_joints)  # the joints the plan moves
    if hand is not None:  # hold the other arm (the CoM task would otherwise swing it)
        limited, other = ("right_arm", "left_arm") if "right" in hand else ("left_arm", "right_arm")
        hold = PostureTask(robot, other, weight=1.0, stiffness=ARM_STIFFNESS)
        hold.set_reference(q_start[robot.configuration_indices(other)])
        tasks.append(hold)
    contacts = []
    if robot.floating_base:
        com = ComTask(robot, weight=COM_WEIGHT, stiffness=50.0)
        # The simulation starts with the soles pressed into the compliant ground.
        sink = _sink(robot) if com_sink is None else com_sink
        com.set_target(pin.centerOfMass(robot.model, robot.create_data(), q_start) - [0, 0, sink])
        base = FrameTask(
            robot, "base_link", weight=BASE_WEIGHT, stiffness=50.0, components="orientation"
        )
        tasks += [com, base] if base_task else [com]
        contacts = [SoleContact(robot, f, friction_coefficient=friction) for f in robot.foot_frames]
    controller = InverseDynamicsController(
        robot,
        tasks,
        contacts,
        joint_limit_horizon=JOINT_LIMIT_HORIZON,
        limited_joints=limited,
        time_budget=TIME_BUDGET,
        joint_impedance=impedance,
    )
    return controller, driven


def make_simulator(robot, q_start: np.ndarray):
    """Simulator (compliant ground under the sole corners if standing) and its start state."""
    if not robot.floating_base:
        return Simulator(robot.model, DT), q_start.copy()
    points = [(f, c) for f in robot.foot_frames for c in robot.sole_corners]
    simulator = Simulator(
        robot.model,
        DT,
        contact_points=points,
        ground=GroundContact(stiffness=GROUND_STIFFNESS, damping=300.0, friction=1.0),
        fall_frame="base_link",
        fall_height=FALL_HEIGHT,
    )
    q0 = q_start.copy()
    q0[2] -= _sink(robot)
    return simulator, q0


def _sink(robot) -> float:
    """Static compression of the ground under the standing robot [m]."""
    n_points = len(robot.foot_frames) * len(robot.sole_corners)
    return pin.computeTotalMass(robot.model) * 9.81 / n_points / GROUND_STIFFNESS


def mujoco_plant(friction: float = MUJOCO_FRICTION, parameters=IDEAL):
    """A ``plant(robot, q_start) -> (simulator, q0)`` simulating in MuJoCo.

    MuJoCo's floor touches a 5 mm sphere at each sole corner (the URDF collision meshes touch
    nothing), with Coulomb ``friction``; the same fall options as :func:`make_simulator`, so
    the same thresholds (:mod:`dmpopt.sim.falls`). The robot starts with the soles on the
    floor: MuJoCo's contacts sink by about a millimetre. ``parameters`` is the plant
    (:class:`dmpopt.sim.PlantParameters`: joints, actuators, sensors).
    """
    from dmpopt.sim import MujocoSimulator

    def plant(robot, q_start):
        if not robot.floating_base:
            simulator = MujocoSimulator(robot.model, robot.source, DT, plant=parameters)
            return simulator, q_start.copy()
        points = [(f, c) for f in robot.foot_frames for c in robot.sole_corners]
        simulator = MujocoSimulator(
            robot.model,
            robot.source,
            DT,
            points,
            friction,
            fall_frame="base_link",
            fall_height=FALL_HEIGHT,
            plant=parameters,
        )
        return simulator, q_start.copy()

    return plant


def with_scaled_torque_limits(robot, scale: float):
    """A copy of ``robot`` whose torque limits are multiplied by ``scale``."""
    limit = np.asarray(robot.torque_limit, dtype=float) * scale
    return dataclasses.replace(robot, torque_limit=limit, name=f"{robot.name}_torque_x{scale:.3g}")


def with_mass_error(robot, scale: float, groups=("left_arm", "right_arm")):
    """A copy of ``robot`` whose links moved by ``groups`` (and all links after them: the
    hands and grippers) have mass and inertia multiplied by ``scale``."""
    model = pin.Model(robot.model)
    first = [model.getJointId(j) for g in groups for j in robot.joint_groups[g]]
    for joint_id in range(1, model.njoints):
        ancestors = set(model.supports[joint_id])
        if ancestors & set(first):
            inertia = model.inertias[joint_id]
            model.inertias[joint_id] = pin.Inertia(
                inertia.mass * scale, inertia.lever, inertia.inertia * scale
            )
    return dataclasses.replace(robot, model=model, name=f"{robot.name}_mass_x{scale:g}")
