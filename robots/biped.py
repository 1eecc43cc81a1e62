r"""The dmpopt planar five-link biped: loader and a few physical facts about it.

The URDF ``robots/biped.urdf`` holds the parameters and their source (leg 0.6 m, 7.0 kg,
anthropometric mass distribution after Winter 2009, Table 4.1). The loader adds the planar
floating base as a composite root joint at the hip point: translation along x (forward),
translation along z (up) and rotation about y (pitch), so ``q = [x, z, pitch, joints...]`` and
``v`` has the same layout; the simulator treats these three coordinates as unactuated.

:class:`robots.model.RobotModel` assumes a 6-DOF free flyer, so the biped keeps its own small
description, :class:`Biped`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError

__all__ = ["BIPED_URDF", "Biped", "load_biped"]

BIPED_URDF = Path(__file__).with_name("biped.urdf")

#: Actuated joints in the order used by the gait (right leg first), not the model order.
GAIT_JOINTS = ("right_hip", "right_knee", "left_hip", "left_knee")


@dataclass(frozen=True, eq=False)
class Biped:
    """A planar biped model with the facts a walking controller needs.

    Attributes
    ----------
    model : pinocchio.Model
        ``nq = nv = 7``: base x, z, pitch, then the four joints in model order.
    joint_names : tuple of str
        :data:`GAIT_JOINTS`: right hip, right knee, left hip, left knee.
    joint_velocity_indices : ndarray of int, shape (4,)
        Index in ``v`` (and ``q``) of each of ``joint_names``.
    foot_frames : tuple of str
        ``("right_foot", "left_foot")``: point feet at the tips of the shanks.
    torso_frame : str
    thigh_length, shank_length : float
        [m]
    torque_limit : ndarray, shape (4,)
        Effort limits of ``joint_names`` from the URDF [N m].
    """

    model: pin.Model
    joint_names: tuple[str, ...]
    joint_velocity_indices: np.ndarray
    foot_frames: tuple[str, ...]
    torso_frame: str
    thigh_length: float
    shank_length: float
    torque_limit: np.ndarray

    n_base_dofs = 3

    @property
    def mass(self) -> float:
        """Total mass [kg]."""
        return float(sum(inertia.mass for inertia in self.model.inertias))

    @property
    def leg_length(self) -> float:
        """Hip-to-foot length of a straight leg [m]."""
        return self.thigh_length + self.shank_length

    @property
    def contact_points(self) -> list[tuple[str, tuple[float, float, float]]]:
        """``(frame, offset)`` pairs for :class:`dmpopt.sim.Simulator`, right foot first."""
        return [(frame, (0.0, 0.0, 0.0)) for frame in self.foot_frames]

    def configuration(self, base_x: float, base_z: float, pitch: float, joints) -> np.ndarray:
        """``q`` from the base pose and the joint angles in :attr:`joint_names` order.

        Parameters
        ----------
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
        q = np.zeros(self.model.nq)
        q[:3] = base_x, base_z, pitch
        q[self.joint_velocity_indices] = joints
        return q

    def actuator_torques(self, gait_torques) -> np.ndarray:
        """Reorder torques from :attr:`joint_names` order to the simulator's (model) order.

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
        torques[self.joint_velocity_indices - self.n_base_dofs] = gait_torques
        return torques

    def foot_positions(self, q) -> np.ndarray:
        """World (x, z) of the right and left foot, shape (2, 2) [m]."""
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, np.asarray(q, dtype=float))
        return np.array(
            [data.oMf[self.model.getFrameId(f)].translation[[0, 2]] for f in self.foot_frames]
        )

    def swing_leg_natural_frequency(self, knee_angle: float = 0.0, gravity: float = 9.81):
        r"""Small-oscillation frequency of one leg swinging freely about a fixed hip [rad/s].

        The leg, with the knee locked at ``knee_angle``, is a compound pendulum:
        :math:`\omega = \sqrt{m g d / I}` with leg mass ``m``, hip-to-centre-of-mass distance
        ``d`` and moment of inertia ``I`` about the hip axis. This is the independent estimate
        of the legs' resonance frequency that the frequency adaptation of eq. (21) is
        compared against; a half oscillation (one swing) lasts :math:`\pi / \omega`.
        """
        model = self.model
        thigh = model.inertias[model.getJointId("right_hip")]
        shank = model.inertias[model.getJointId("right_knee")]
        # Positions in the hip frame (x forward, z up) with the knee flexed by knee_angle.
        knee = np.array([0.0, -self.thigh_length])
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


def load_biped(urdf_path: str | Path = BIPED_URDF) -> Biped:
    """Build the planar biped from its URDF with an (x, z, pitch) floating base.

    Parameters
    ----------
    urdf_path : str or Path
        Defaults to the packaged ``robots/biped.urdf``.

    Returns
    -------
    Biped
    """
    path = Path(urdf_path)
    if not path.is_file():
        raise InvalidInputError(f"urdf_path {str(path)!r} does not exist")
    base = pin.JointModelComposite()
    base.addJoint(pin.JointModelPX())
    base.addJoint(pin.JointModelPZ())
    base.addJoint(pin.JointModelRY())
    model = pin.buildModelFromUrdf(str(path), base)
    model.name = "dmpopt_planar_biped"
    ids = [model.getJointId(name) for name in GAIT_JOINTS]
    indices = np.array([model.joints[j].idx_v for j in ids], dtype=int)
    placement = model.jointPlacements
    return Biped(
        model=model,
        joint_names=GAIT_JOINTS,
        joint_velocity_indices=indices,
        foot_frames=("right_foot", "left_foot"),
        torso_frame="torso",
        thigh_length=float(-placement[model.getJointId("right_knee")].translation[2]),
        shank_length=float(-model.frames[model.getFrameId("right_foot")].placement.translation[2]),
        torque_limit=np.array([model.effortLimit[i] for i in indices]),
    )
