"""A robot model as the controller and the simulator need it, and where example-robot-data lives.

:class:`RobotModel` bundles a Pinocchio model with what a whole-body controller asks of a robot:
named joint groups, joint limits, the frames of feet and hands, a reference posture and the sole
corners used as contact points. It is robot-agnostic and covers the three bases dmpopt uses: a
fixed base, a planar base (x, z, pitch: one composite root joint, the biped) and a 3-D free
flyer (Talos). ``robots/talos.py`` and ``robots/biped.py`` fill it.
"""

from __future__ import annotations

import importlib.metadata
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError, MissingDependency

__all__ = ["BASES", "RobotModel", "example_robot_data_dir"]

#: Base kinds and their number of unactuated velocity coordinates (those of the root joint).
BASES = MappingProxyType({"fixed": 0, "planar": 3, "free_flyer": 6})


def example_robot_data_dir() -> Path:
    """Directory ``robots/`` of the installed example-robot-data package (the cmeel wheel).

    Returns
    -------
    Path
        ``<site-packages>/cmeel.prefix/share/example-robot-data/robots``.

    Raises
    ------
    MissingDependency
        If the package ``example-robot-data`` is not installed or holds no robot files.
    """
    remedy = "install it with `pip install example-robot-data` or `pip install 'dmpopt[robots]'`"
    try:
        distribution = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise MissingDependency(
            f"the robot data package example-robot-data is not installed; {remedy}"
        ) from None
    directory = Path(distribution.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    if not directory.is_dir():
        raise MissingDependency(
            f"example-robot-data is installed but {directory} does not exist; re-{remedy}"
        )
    return directory


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float)
    array.setflags(write=False)
    return array


def _rebuild_robot_model(fields: dict) -> RobotModel:
    """A pickled :class:`RobotModel` back (worker processes of :mod:`dmpopt.parallel`)."""
    return RobotModel(**fields)


@dataclass(frozen=True, eq=False)
class RobotModel:
    """A Pinocchio model with joint groups, limits, contact and hand frames.

    Parameters
    ----------
    name : str
        Human-readable name, e.g. ``"talos_full"``.
    model : pinocchio.Model
        The kinematic and dynamic model. Unless ``base`` is ``"fixed"``, its first joint is
        the unactuated base: a free flyer (7 configuration and 6 velocity coordinates) or the
        planar base (x, z, pitch about y; 3 and 3).
    joint_groups : Mapping[str, tuple of str]
        Group name (``"left_arm"``, ``"torso"``, ...) to the names of its joints, in model order.
    reference_configuration : ndarray, shape (nq,)
        A nominal posture (half-sitting for Talos).
    position_lower, position_upper : ndarray, shape (nq,)
        Joint position limits [rad or m]; infinite for the base.
    velocity_limit : ndarray, shape (nv,)
        Symmetric joint velocity limits [rad/s]; infinite for the base.
    torque_limit : ndarray, shape (n_actuated,)
        Symmetric torque limits of the actuated joints, in model order [N m].
    base : {"fixed", "planar", "free_flyer"}
        The base (see :data:`BASES`).
    foot_frames : tuple of str
        Foot frames: soles (z axis normal to the sole, origin on the sole surface) or point
        feet. Empty if no feet.
    hand_frames : tuple of str
        End-effector frames of the hands.
    sole_corners : ndarray, shape (n_corners, 3)
        Corners of each sole expressed in its foot frame [m]; contact points for the simulator
        and the centre-of-pressure bounds of the controller. One corner at the origin for
        point feet.
    torso_frame : str
        The frame whose height tells a fall (``""`` if none).
    source : str
        The file the model was built from.
    """

    name: str
    model: pin.Model
    joint_groups: Mapping[str, tuple[str, ...]]
    reference_configuration: np.ndarray
    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity_limit: np.ndarray
    torque_limit: np.ndarray
    base: str
    foot_frames: tuple[str, ...] = ()
    hand_frames: tuple[str, ...] = ()
    sole_corners: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    torso_frame: str = ""
    source: str = ""

    def __reduce__(self):
        # the read-only mapping of joint groups does not pickle: rebuild from a plain dict
        fields = {name: getattr(self, name) for name in self.__dataclass_fields__}
        fields["joint_groups"] = dict(self.joint_groups)
        return (_rebuild_robot_model, (fields,))

    def __post_init__(self):
        self._check_base()
        groups = {name: tuple(joints) for name, joints in self.joint_groups.items()}
        object.__setattr__(self, "joint_groups", MappingProxyType(groups))
        for name in (
            "reference_configuration",
            "position_lower",
            "position_upper",
            "velocity_limit",
            "torque_limit",
            "sole_corners",
        ):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        expected = {
            "reference_configuration": (self.nq,),
            "position_lower": (self.nq,),
            "position_upper": (self.nq,),
            "velocity_limit": (self.nv,),
            "torque_limit": (self.n_actuated,),
        }
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise InvalidInputError(
                    f"{name} has shape {getattr(self, name).shape}, expected {shape} "
                    f"to match the Pinocchio model (nq={self.nq}, nv={self.nv})"
                )
        frames = (
            self.foot_frames + self.hand_frames + ((self.torso_frame,) if self.torso_frame else ())
        )
        for frame in frames:
            if not self.model.existFrame(frame):
                raise InvalidInputError(f"frame {frame!r} is not in the model {self.name!r}")
        for joints in groups.values():
            for joint in joints:
                if not self.model.existJointName(joint):
                    raise InvalidInputError(f"joint {joint!r} is not in the model {self.name!r}")

    def _check_base(self) -> None:
        if self.base not in BASES:
            raise InvalidInputError(
                f"base={self.base!r} is not a base kind; expected one of {sorted(BASES)}"
            )
        n_base = BASES[self.base]
        root_nv = self.model.joints[1].nv if self.model.njoints > 1 else 0
        free = self.base != "free_flyer" or self.model.joints[1].nq == 7
        if n_base and (root_nv != n_base or not free):
            raise InvalidInputError(
                f"base={self.base!r} needs a root joint with {n_base} velocity coordinates, but "
                f"the root joint of {self.name!r} has {root_nv}; build the model with that root "
                "joint or pick the matching base"
            )

    @property
    def floating_base(self) -> bool:
        """Whether the root joint is an unactuated base (planar or free flyer)."""
        return self.base != "fixed"

    @property
    def n_base(self) -> int:
        """Unactuated velocity coordinates of the base: 0, 3 (planar) or 6 (free flyer)."""
        return BASES[self.base]

    @property
    def mass(self) -> float:
        """Total mass [kg]."""
        return float(pin.computeTotalMass(self.model))

    @property
    def contact_points(self) -> list[tuple[str, tuple[float, float, float]]]:
        """``(frame, offset)`` of every sole corner of every foot, for :class:`dmpopt.sim.Simulator`
        (feet in :attr:`foot_frames` order)."""
        return [
            (f, tuple(float(x) for x in c)) for f in self.foot_frames for c in self.sole_corners
        ]

    @property
    def nq(self) -> int:
        """Size of the configuration vector."""
        return self.model.nq

    @property
    def nv(self) -> int:
        """Size of the velocity (and acceleration) vector."""
        return self.model.nv

    @property
    def n_actuated(self) -> int:
        """Number of actuated velocity coordinates (``nv - n_base``)."""
        return self.model.nv - self.n_base

    @property
    def actuated_joint_names(self) -> tuple[str, ...]:
        """Names of the actuated joints, in model order."""
        first = 2 if self.floating_base else 1
        return tuple(self.model.names[first:])

    def create_data(self) -> pin.Data:
        """Create a :class:`pinocchio.Data` workspace for this model (one per thread or user)."""
        return self.model.createData()

    def velocity_indices(self, joints: str | tuple[str, ...] | list[str]) -> np.ndarray:
        """Return the indices into the velocity vector of a joint group or of 1-DOF joints.

        Parameters
        ----------
        joints : str or sequence of str
            A key of :attr:`joint_groups`, or joint names.

        Returns
        -------
        ndarray of int, shape (n_joints,)
        """
        return np.array([self.model.joints[j].idx_v for j in self._joint_ids(joints)], dtype=int)

    def configuration_indices(self, joints: str | tuple[str, ...] | list[str]) -> np.ndarray:
        """Return the indices into the configuration vector of a joint group or of 1-DOF joints."""
        return np.array([self.model.joints[j].idx_q for j in self._joint_ids(joints)], dtype=int)

    def _joint_ids(self, joints: str | tuple[str, ...] | list[str]) -> list[int]:
        if isinstance(joints, str):
            if joints not in self.joint_groups:
                raise InvalidInputError(
                    f"joints={joints!r} is not a joint group of {self.name!r}; "
                    f"expected one of {sorted(self.joint_groups)}"
                )
            joints = self.joint_groups[joints]
        ids = []
        for joint in joints:
            if not self.model.existJointName(joint):
                raise InvalidInputError(f"joint {joint!r} is not in the model {self.name!r}")
            joint_id = self.model.getJointId(joint)
            if self.model.joints[joint_id].nv != 1:
                raise InvalidInputError(
                    f"joint {joint!r} has {self.model.joints[joint_id].nv} velocity coordinates; "
                    "expected a 1-DOF joint (use the free flyer through a frame task instead)"
                )
            ids.append(joint_id)
        return ids
