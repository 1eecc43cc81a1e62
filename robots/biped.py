r"""The dmpopt planar five-link biped: loader and a few physical facts about it.

The URDF ``robots/biped.urdf`` holds the parameters and their source (leg 0.6 m, 7.0 kg,
anthropometric mass distribution after Winter 2009, Table 4.1). The loader adds the planar
floating base as a composite root joint at the hip point: translation along x (forward),
translation along z (up) and rotation about y (pitch), so ``q = [x, z, pitch, joints...]`` and
``v`` has the same layout; the simulator treats these three coordinates as unactuated.

:func:`load_biped` returns a :class:`dmpopt_robots.model.RobotModel` with ``base="planar"``, point
feet ``("right_foot", "left_foot")`` and the joint group ``"gait"`` (:data:`GAIT_JOINTS`, the
gait's order, not the model's). The functions below give the facts a walking controller needs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError

from .model import RobotModel

__all__ = [
    "BIPED_URDF",
    "GAIT_JOINTS",
    "actuator_torques",
    "configuration",
    "foot_positions",
    "leg_length",
    "leg_lengths",
    "load_biped",
    "scaled_legs_urdf",
    "swing_leg_natural_frequency",
]

BIPED_URDF = Path(__file__).with_name("biped.urdf")

#: Actuated joints in the order used by the gait (right leg first), not the model order.
GAIT_JOINTS = ("right_hip", "right_knee", "left_hip", "left_knee")
#: Joint angles of the reference configuration, in :data:`GAIT_JOINTS` order [rad]: a stance
#: with the right foot 8.8 cm ahead of the hip and the left 8.8 cm behind, knees bent 0.4 rad
#: (bent knees keep the feet's Jacobian of full rank).
REFERENCE_JOINTS = (0.35, 0.4, 0.05, 0.4)


def _gait_indices(robot: RobotModel) -> np.ndarray:
    return robot.velocity_indices("gait")


def leg_lengths(robot: RobotModel) -> tuple[float, float]:
    """Thigh and shank length [m] (hip to knee, knee to foot)."""
    model = robot.model
    thigh = -model.jointPlacements[model.getJointId("right_knee")].translation[2]
    shank = -model.frames[model.getFrameId("right_foot")].placement.translation[2]
    return float(thigh), float(shank)


def leg_length(robot: RobotModel) -> float:
    """Hip-to-foot length of a straight leg [m]."""
    return sum(leg_lengths(robot))


def configuration(robot: RobotModel, base_x: float, base_z: float, pitch: float, joints):
    """``q`` from the base pose and the joint angles in :data:`GAIT_JOINTS` order.

    Parameters
    ----------
    robot : RobotModel
        From :func:`load_biped`.
    base_x, base_z : float
        Hip point position [m].
    pitch : float
        Torso pitch about y [rad] (positive leans forward).
    joints : array_like, shape (4,)
        Right hip, right knee, left hip, left knee [rad].
    """
    joints = np.asarray(joints, dtype=float).reshape(-1)
    if joints.shape != (4,):
        raise InvalidInputError(f"joints has shape {joints.shape}, expected (4,)")
    q = np.zeros(robot.nq)
    q[:3] = base_x, base_z, pitch
    q[_gait_indices(robot)] = joints
    return q


def actuator_torques(robot: RobotModel, gait_torques) -> np.ndarray:
    """Reorder torques from :data:`GAIT_JOINTS` order to the simulator's (model) order.

    Parameters
    ----------
    gait_torques : array_like, shape (4,)
        Right hip, right knee, left hip, left knee [N m].

    Returns
    -------
    ndarray, shape (4,)
        The same torques in the order of ``v[3:]``, as :meth:`Simulator.step` expects.
    """
    torques = np.empty(4)
    torques[_gait_indices(robot) - robot.n_base] = gait_torques
    return torques


def foot_positions(robot: RobotModel, q) -> np.ndarray:
    """World (x, z) of the right and left foot, shape (2, 2) [m]."""
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    return np.array([data.oMf[model.getFrameId(f)].translation[[0, 2]] for f in robot.foot_frames])


def swing_leg_natural_frequency(
    robot: RobotModel, knee_angle: float = 0.0, gravity: float = 9.81
) -> float:
    r"""Small-oscillation frequency of one leg swinging freely about a fixed hip [rad/s].

    The leg, with the knee locked at ``knee_angle``, is a compound pendulum:
    :math:`\omega = \sqrt{m g d / I}` with leg mass ``m``, hip-to-centre-of-mass distance
    ``d`` and moment of inertia ``I`` about the hip axis. This is the independent estimate
    of the legs' resonance frequency that the frequency adaptation of eq. (21) is
    compared against; a half oscillation (one swing) lasts :math:`\pi / \omega`.
    """
    model = robot.model
    thigh = model.inertias[model.getJointId("right_hip")]
    shank = model.inertias[model.getJointId("right_knee")]
    thigh_length, _ = leg_lengths(robot)
    # Positions in the hip frame (x forward, z up) with the knee flexed by knee_angle.
    knee = np.array([0.0, -thigh_length])
    direction = np.array([-np.sin(knee_angle), -np.cos(knee_angle)])
    thigh_com = np.array([0.0, thigh.lever[2]])
    shank_com = knee + direction * -shank.lever[2]
    mass = thigh.mass + shank.mass
    com = (thigh.mass * thigh_com + shank.mass * shank_com) / mass
    inertia = (
        thigh.inertia[1, 1]
        + thigh.mass * thigh_com @ thigh_com
        + shank.inertia[1, 1]
        + shank.mass * shank_com @ shank_com
    )
    return float(np.sqrt(mass * gravity * np.linalg.norm(com) / inertia))


LEG_LINKS = ("right_thigh", "right_shank", "left_thigh", "left_shank")
LEG_JOINTS = ("right_knee", "right_ankle_fixed", "left_knee", "left_ankle_fixed")


def scaled_legs_urdf(factor: float, path: str | Path) -> Path:
    r"""Write a copy of ``biped.urdf`` whose legs are ``factor`` times as long; return its path.

    Every length of the thighs and shanks (knee and foot offsets, centre-of-mass positions)
    is multiplied by ``factor`` and their inertias about the centre of mass by
    ``factor ** 2``; masses and the torso are unchanged. A leg swinging as a compound
    pendulum then has :math:`m g d \propto f` and :math:`I \propto f^2`, so its natural
    frequency :math:`\sqrt{m g d / I}` scales as :math:`1 / \sqrt{f}`.

    Parameters
    ----------
    factor : float
        Leg-length factor, > 0.
    path : str or Path
        Where to write the URDF (its folder must exist).
    """
    import xml.etree.ElementTree as ElementTree

    if isinstance(factor, bool) or not isinstance(factor, (int, float, np.floating)):
        raise InvalidInputError(f"factor must be a positive number, got {factor!r}")
    if not (np.isfinite(factor) and factor > 0):
        raise InvalidInputError(f"factor must be a positive finite number, got {factor!r}")
    tree = ElementTree.parse(BIPED_URDF)
    root = tree.getroot()

    def scale_xyz(origin) -> None:
        xyz = np.array(origin.get("xyz").split(), dtype=float) * factor
        origin.set("xyz", " ".join(f"{value:.9g}" for value in xyz))

    for link in root.iter("link"):
        if link.get("name") in LEG_LINKS:
            inertial = link.find("inertial")
            scale_xyz(inertial.find("origin"))
            inertia = inertial.find("inertia")
            for key, value in inertia.attrib.items():
                inertia.set(key, f"{float(value) * factor**2:.9g}")
    for joint in root.iter("joint"):
        if joint.get("name") in LEG_JOINTS:
            scale_xyz(joint.find("origin"))
    path = Path(path)
    tree.write(path, xml_declaration=True, encoding="utf-8")
    return path


def load_biped(urdf_path: str | Path = BIPED_URDF, gravity: float = 9.81) -> RobotModel:
    """Build the planar biped from its URDF with an (x, z, pitch) floating base.

    Parameters
    ----------
    urdf_path : str or Path
        Defaults to the packaged ``robots/biped.urdf`` (:func:`scaled_legs_urdf` writes
        leg-scaled copies).
    gravity : float
        Magnitude of the model's gravity, along -z [m/s^2].

    Returns
    -------
    RobotModel
        ``nq = nv = 7``: base x, z, pitch, then the four joints in model order; joint groups
        ``"gait"`` (:data:`GAIT_JOINTS`), ``"right_leg"``, ``"left_leg"``; point feet
        ``("right_foot", "left_foot")`` (right first); torso frame ``"torso"``; torque limits
        from the URDF, in model order.
    """
    path = Path(urdf_path)
    if not path.is_file():
        raise InvalidInputError(f"urdf_path {str(path)!r} does not exist")
    robot = RobotModel.from_urdf(
        path,
        base="planar",
        groups={
            "gait": GAIT_JOINTS,
            "right_leg": ("right_hip", "right_knee"),
            "left_leg": ("left_hip", "left_knee"),
        },
        feet={"right_foot": [[0.0, 0.0, 0.0]], "left_foot": [[0.0, 0.0, 0.0]]},
        reference=dict(zip(GAIT_JOINTS, REFERENCE_JOINTS)),
        torso="torso",
        name="planar_biped",
    )
    robot.model.name = "dmpopt_planar_biped"
    if isinstance(gravity, bool) or not isinstance(gravity, (int, float, np.floating)):
        raise InvalidInputError(f"gravity must be a positive number [m/s^2], got {gravity!r}")
    if not (np.isfinite(gravity) and gravity > 0):
        raise InvalidInputError(f"gravity must be positive and finite [m/s^2], got {gravity!r}")
    robot.model.gravity.linear = np.array([0.0, 0.0, -float(gravity)])
    return robot
