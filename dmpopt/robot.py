"""A robot model as the controller and the simulator need it, and where example-robot-data lives.

:class:`RobotModel` bundles a Pinocchio model with what a whole-body controller asks of a robot:
named joint groups, joint limits, the frames of feet and hands, a reference posture and the sole
corners used as contact points. It is robot-agnostic and covers the three bases dmpopt uses: a
fixed base, a planar base (x, z, pitch: one composite root joint, the biped) and a 3-D free
flyer (Talos). :meth:`RobotModel.from_urdf` builds one from a URDF (and optionally its SRDF)
in one call; ``robots/talos.py`` and ``robots/biped.py`` are two uses of it.
"""

from __future__ import annotations

import importlib.metadata
import re
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError, MissingDependency
from dmpopt.validation import real_array

__all__ = ["BASES", "RobotModel", "example_robot_data_dir"]

#: A sole lying farther than this from its foot frame's origin gets its own frame [m].
SOLE_OFFSET_TOLERANCE = 1e-3
#: Collision points within this height above the lowest one belong to the sole [m].
SOLE_BAND = 5e-3

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
        if self.base == "free_flyer":
            quaternion = self.reference_configuration[3:7]
            if not abs(np.linalg.norm(quaternion) - 1.0) <= 1e-6:
                raise InvalidInputError(
                    f"reference_configuration[3:7] is the base orientation quaternion (x, y, z, w) "
                    f"and must have norm 1, got {quaternion.tolist()} (norm "
                    f"{np.linalg.norm(quaternion):.3g}); pass [0, 0, 0, 1] for an upright base"
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

    @classmethod
    def from_urdf(
        cls,
        urdf: str | Path,
        srdf: str | Path | None = None,
        *,
        base: str | None = None,
        groups: Mapping[str, str | Sequence[str]] | None = None,
        feet: Mapping[str, object] | Sequence[str] = (),
        hands: Sequence[str] = (),
        reference: str | Mapping[str, float] | np.ndarray | None = None,
        torso: str = "",
        locked: str | Sequence[str] = (),
        armature: float | np.ndarray | None = None,
        name: str | None = None,
        package_dirs: Sequence[str | Path] | None = None,
    ) -> RobotModel:
        r"""Build a robot from its URDF (and optionally its SRDF) in one call.

        Parameters
        ----------
        urdf : str or Path
            The URDF file.
        srdf : str or Path, optional
            Its SRDF: named postures (``group_state``) and joint groups.
        base : {"fixed", "planar", "free_flyer"}, optional
            The root joint added under the URDF's root link. Default: ``"free_flyer"`` if
            ``feet`` are given, else ``"fixed"``. ``"planar"`` is translation along x and z
            and rotation about y (q = [x, z, pitch, joints...]).
        groups : mapping, optional
            Group name to joint names (kept in the given order) or to a regular expression
            matched in full against the actuated joints' names (model order). Default: the
            SRDF's groups of joints (nested groups expanded), else none.
        feet : mapping or sequence of str
            Foot frame to its sole, or a sequence of foot frames (soles from the geometry). A
            sole is ``None`` (the rectangle bounding the lowest collision points of the foot's
            link, see below) or corners ``(n, 2)`` or ``(n, 3)`` in the foot frame [m]: a
            rectangle's four corners, or ``[[0, 0, 0]]`` for a point foot. All feet share one
            sole shape. When the sole found in the geometry lies more than
            :data:`SOLE_OFFSET_TOLERANCE` below the frame's origin, a frame ``<frame>_sole`` is
            added on the sole (same orientation, origin under the frame's origin) and becomes
            the foot frame, since contacts need the origin on the sole.
        hands : sequence of str
            Hand (end-effector) frames.
        reference : str, mapping, array or None
            The reference posture: an SRDF state's name, a full configuration ``(nq,)`` (kept
            as given), or joint name to value [rad or m] with the others at zero and the base
            height placed so the lowest sole corner touches the floor (z = 0). Default: the
            SRDF's ``"half_sitting"`` state, else its only state, else all joints at zero
            (placed on the floor).
        torso : str
            The frame whose height tells a fall.
        locked : str or sequence of str
            Joints (names or regular expressions) locked at the reference posture and removed
            from the model; locking the free flyer's ``"root_joint"`` gives a fixed-base model
            whose frames keep their world placement (e.g. a humanoid's upper body).
        armature : float or array_like, optional
            Rotor inertia added to each actuated joint [kg m^2] (``model.armature``).
        name : str, optional
            Default: the URDF's robot name.
        package_dirs : sequence of str or Path, optional
            Where ``package://`` meshes are looked for (only read for soles taken from mesh
            geometry). Default: the folder holding example-robot-data and the URDF's folders.

        Returns
        -------
        RobotModel
            Limits from the URDF: position and velocity limits of the base and Pinocchio's
            float-max placeholders (|x| >= 1e300) become infinite; the base's effort limits are
            dropped, leaving one torque limit per actuated joint.

        Raises
        ------
        InvalidInputError
            If a file, frame, joint, group pattern, SRDF state or sole is wrong; the message
            says which and what was expected.

        Examples
        --------
        >>> panda = RobotModel.from_urdf(urdf, srdf)  # doctest: +SKIP
        >>> g1 = RobotModel.from_urdf(
        ...     urdf, feet=["left_ankle_roll_link", "right_ankle_roll_link"],
        ...     groups={"left_leg": "left_(hip|knee|ankle)_.*"},
        ...     reference={"left_knee_joint": 0.3, "right_knee_joint": 0.3},
        ... )  # doctest: +SKIP
        """
        return _from_urdf(
            cls, urdf, srdf, base, groups, feet, hands, reference, torso, locked, armature,
            name, package_dirs,
        )  # fmt: skip

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

    def frame_placement(self, frame: str, q: np.ndarray | None = None) -> pin.SE3:
        """World placement of ``frame`` in configuration ``q`` (default: the reference
        configuration); for setting up targets, not for a control loop (it allocates)."""
        if not (isinstance(frame, str) and self.model.existFrame(frame)):
            known = [f.name for f in self.model.frames]
            raise _unknown("frame", str(frame), known, self.name)
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, self._configuration(q))
        return data.oMf[self.model.getFrameId(frame)].copy()

    def center_of_mass(self, q: np.ndarray | None = None) -> np.ndarray:
        """Centre of mass [m] in configuration ``q`` (default: the reference configuration),
        shape (3,)."""
        return pin.centerOfMass(self.model, self.model.createData(), self._configuration(q))

    def sole_center(self, frame: str, q: np.ndarray | None = None) -> np.ndarray:
        """World position [m] of the centre of the sole rectangle of foot ``frame`` in
        configuration ``q`` (default: the reference configuration), shape (3,): where a CoM
        held over one foot keeps the centre of pressure farthest from the sole's edges."""
        if frame not in self.foot_frames:
            raise InvalidInputError(
                f"frame={frame!r} is not a foot frame of {self.name!r}; expected one of "
                f"{self.foot_frames}"
            )
        corners = np.asarray(self.sole_corners, dtype=float)
        middle = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
        return self.frame_placement(frame, q).act(middle)

    def reference_state(
        self, joints: str | Sequence[str] = (), positions=(), velocities=None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The reference configuration and zero velocity, with ``joints`` (a joint group or
        joint names) at ``positions`` [rad or m] and ``velocities`` [rad/s or m/s]: a start
        state, e.g. arms on a rhythmic DMP's limit cycle (``stepper.position``,
        ``stepper.velocity``).

        Returns
        -------
        (q, v) : ndarrays, shapes (nq,) and (nv,)
        """
        q, v = self.reference_configuration.copy(), np.zeros(self.model.nv)
        q_index, v_index = self.configuration_indices(joints), self.velocity_indices(joints)
        size, expected = (q_index.size,), f"one value per joint of {joints!r}"
        q[q_index] = real_array("positions", positions, shape=size, expected=expected)
        if velocities is not None:
            v[v_index] = real_array("velocities", velocities, shape=size, expected=expected)
        return q, v

    def _configuration(self, q) -> np.ndarray:
        if q is None:
            return self.reference_configuration
        expected = f"a configuration of {self.name}"
        return real_array("q", q, shape=(self.model.nq,), expected=expected)

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


def _finite_or_inf(values) -> np.ndarray:
    """Pinocchio's float-max placeholders (|x| >= 1e300) and non-finite limits as +-inf."""
    values = np.array(values, dtype=float)
    huge = ~(np.abs(values) < 1e300)
    values[huge] = np.copysign(np.inf, values[huge])
    return values


def _existing_file(argument: str, path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(
            f"{argument} {str(path)!r} does not exist; pass the path of the file"
        )
    return path


def _unknown(kind: str, name: str, known: Sequence[str], robot: str) -> InvalidInputError:
    import difflib

    close = difflib.get_close_matches(name, list(known), n=3, cutoff=0.5)
    hint = f"; did you mean {' or '.join(map(repr, close))}?" if close else ""
    return InvalidInputError(f"{kind} {name!r} is not in the URDF of {robot!r}{hint}")


def _build_model(urdf: Path, base: str) -> pin.Model:
    if base == "fixed":
        return pin.buildModelFromUrdf(str(urdf))
    if base == "free_flyer":
        return pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    planar = pin.JointModelComposite()
    for joint in (pin.JointModelPX(), pin.JointModelPZ(), pin.JointModelRY()):
        planar.addJoint(joint)
    return pin.buildModelFromUrdf(str(urdf), planar)


def _srdf_groups(srdf: Path) -> dict[str, tuple[str, ...]]:
    """The SRDF's ``<group>`` elements as joint names, nested groups expanded."""
    elements = {g.get("name"): g for g in ElementTree.parse(srdf).getroot().findall("group")}

    def joints(name: str, seen: tuple[str, ...] = ()) -> tuple[str, ...]:
        if name in seen or name not in elements:
            return ()
        names = tuple(j.get("name") for j in elements[name].findall("joint"))
        for sub in elements[name].findall("group"):
            names += joints(sub.get("name"), seen + (name,))
        return names

    groups = {name: joints(name) for name in elements}
    return {name: names for name, names in groups.items() if names}


def _joint_groups(model, groups, actuated, robot) -> dict[str, tuple[str, ...]]:
    resolved = {}
    for group, joints in groups.items():
        if isinstance(joints, str):
            pattern = re.compile(joints)
            names = tuple(n for n in actuated if pattern.fullmatch(n))
            if not names:
                raise InvalidInputError(
                    f"groups[{group!r}] = {joints!r} matches no actuated joint of {robot!r}; "
                    f"its joints are {list(actuated)}"
                )
        else:
            names = tuple(joints)
            for joint in names:
                if not model.existJointName(joint):
                    raise _unknown(f"groups[{group!r}]: joint", joint, actuated, robot)
        resolved[group] = names
    return resolved


def _collision_points(geometry, model: pin.Model, frame: str) -> np.ndarray:
    """Points bounding the collision geometry of a frame's link, in that frame, shape (n, 3)."""
    import coal

    placement = model.frames[model.getFrameId(frame)].placement
    joint = model.frames[model.getFrameId(frame)].parentJoint
    points = []
    for item in geometry.geometryObjects:
        if item.parentJoint != joint:
            continue
        shape, local = item.geometry, placement.actInv(item.placement)
        if isinstance(shape, coal.Sphere):  # its lowest point, under its centre
            vertices = np.array([[0.0, 0.0, 0.0]])
            vertices = (local.rotation @ vertices.T).T + local.translation
            vertices[:, 2] -= shape.radius
            points.append(vertices)
            continue
        if isinstance(shape, coal.Box):
            signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
            vertices = signs * shape.halfSide
        elif isinstance(shape, coal.Cylinder):
            angles = np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
            ring = shape.radius * np.column_stack([np.cos(angles), np.sin(angles)])
            vertices = np.vstack(
                [
                    np.column_stack([ring, np.full(32, z)])
                    for z in (-shape.halfLength, shape.halfLength)
                ]
            )
        elif hasattr(shape, "vertices"):  # meshes
            vertices = np.asarray(shape.vertices(), dtype=float).reshape(-1, 3)
        else:
            raise InvalidInputError(
                f"feet[{frame!r}] = None: the collision shape {item.name!r} is a "
                f"{type(shape).__name__}, which dmpopt cannot bound; give the sole's corners in "
                f"the foot frame: feet={{{frame!r}: [[x, y], ...]}}"
            )
        points.append(vertices @ local.rotation.T + local.translation)
    if not points:
        raise InvalidInputError(
            f"feet[{frame!r}] = None, but the link of {frame!r} has no collision geometry; give "
            f"the sole's corners in the foot frame: feet={{{frame!r}: [[x, y], ...]}}"
        )
    return np.vstack(points)


def _sole_from_geometry(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Corners (4, 3) of the rectangle bounding the lowest points, and the sole's height."""
    height = points[:, 2].min()
    sole = points[points[:, 2] <= height + SOLE_BAND, :2]
    (x_min, y_min), (x_max, y_max) = sole.min(axis=0), sole.max(axis=0)
    corners = np.array([[x_max, y_max], [x_max, y_min], [x_min, y_max], [x_min, y_min]])
    return np.column_stack([corners, np.zeros(4)]), float(height)


def _given_sole(frame: str, corners) -> np.ndarray:
    from dmpopt.validation import real_array

    corners = real_array(f"feet[{frame!r}]", corners, ndim=2, expected="sole corners [m]")
    if corners.shape[1] not in (2, 3) or len(corners) == 0:
        raise InvalidInputError(
            f"feet[{frame!r}] has shape {corners.shape}, expected (n_corners, 2) or "
            "(n_corners, 3): the sole's corners in the foot frame [m], [[0, 0, 0]] for a point foot"
        )
    if corners.shape[1] == 2:
        corners = np.column_stack([corners, np.zeros(len(corners))])
    return corners


def _add_soles(model, urdf, feet, package_dirs, robot) -> tuple[tuple[str, ...], np.ndarray]:
    """Foot frames (sole frames added where needed) and the one sole shape they share."""
    geometry = None
    frames, soles = [], []
    for frame, sole in feet.items():
        if not model.existFrame(frame):
            raise _unknown("foot frame", frame, [f.name for f in model.frames], robot)
        if sole is not None:
            frames.append(frame)
            soles.append(_given_sole(frame, sole))
            continue
        if geometry is None:
            try:
                geometry = pin.buildGeomFromUrdf(
                    model, str(urdf), pin.COLLISION, package_dirs=[str(d) for d in package_dirs]
                )
            except (RuntimeError, ValueError) as error:
                raise InvalidInputError(
                    f"the collision geometry of {str(urdf)!r} could not be read ({error}); pass "
                    f"package_dirs, or give each sole's corners: feet={{{frame!r}: [[x, y], ...]}}"
                ) from error
        corners, height = _sole_from_geometry(_collision_points(geometry, model, frame))
        if abs(height) > SOLE_OFFSET_TOLERANCE:
            parent = model.frames[model.getFrameId(frame)]
            offset = pin.SE3(np.eye(3), np.array([0.0, 0.0, height]))
            model.addFrame(
                pin.Frame(
                    f"{frame}_sole",
                    parent.parentJoint,
                    model.getFrameId(frame),
                    parent.placement * offset,
                    pin.FrameType.OP_FRAME,
                )  # fmt: skip
            )
            frame = f"{frame}_sole"
        frames.append(frame)
        soles.append(corners)
    if not soles:
        return (), np.zeros((0, 3))
    if all(sole is None for sole in feet.values()):
        # soles from geometry: mirrored meshes differ by a fraction of a millimetre; keep the
        # rectangle inside all of them
        bounds = np.array(
            [[s[:, 0].max(), s[:, 1].max(), s[:, 0].min(), s[:, 1].min()] for s in soles]
        )
        if np.ptp(bounds, axis=0).max() <= SOLE_BAND:
            (x_max, y_max), (x_min, y_min) = bounds[:, :2].min(axis=0), bounds[:, 2:].max(axis=0)
            corners = np.array([[x_max, y_max], [x_max, y_min], [x_min, y_max], [x_min, y_min]])
            soles = [np.column_stack([corners, np.zeros(4)])] * len(soles)
    for frame, sole in zip(frames[1:], soles[1:]):
        if sole.shape != soles[0].shape or not np.allclose(sole, soles[0], atol=1e-6):
            raise InvalidInputError(
                f"the sole of {frame!r} ({np.round(sole, 4).tolist()}) differs from that of "
                f"{frames[0]!r} ({np.round(soles[0], 4).tolist()}); a RobotModel has one sole "
                "shape for all feet: give the same corners for every foot in feet={...}"
            )
    return tuple(frames), soles[0]


def _reference(model, srdf, reference, robot) -> tuple[np.ndarray, bool]:
    """The reference configuration, and whether its base still has to be put on the floor."""
    states = {}
    if srdf is not None:
        pin.loadReferenceConfigurations(model, str(srdf), False)
        configurations = model.referenceConfigurations
        states = {entry.key(): np.array(entry.data()) for entry in configurations}
    if reference is None:
        if "half_sitting" in states:
            return states["half_sitting"], False
        if len(states) == 1:
            return next(iter(states.values())), False
        if states:
            raise InvalidInputError(
                f"the SRDF of {robot!r} has the postures {sorted(states)}; pick the reference "
                "posture with reference=<name>"
            )
        return pin.neutral(model), True
    if isinstance(reference, str):
        if reference not in states:
            raise InvalidInputError(
                f"reference={reference!r} is not a posture of the SRDF; expected one of "
                f"{sorted(states)}" + ("" if srdf is not None else " (no srdf was given)")
            )
        return states[reference], False
    if isinstance(reference, Mapping):
        q = pin.neutral(model)
        for joint, value in reference.items():
            if not model.existJointName(joint):
                raise _unknown("reference: joint", joint, list(model.names), robot)
            index = model.joints[model.getJointId(joint)]
            if index.nq != 1:
                raise InvalidInputError(
                    f"reference[{joint!r}]: the joint has {index.nq} configuration coordinates; "
                    "give a full configuration array to set it"
                )
            q[index.idx_q] = float(value)
        return q, True
    from dmpopt.validation import real_array

    return real_array("reference", reference, shape=(model.nq,), expected="a configuration"), False


def _on_floor(model, q, base, feet, sole) -> np.ndarray:
    """``q`` with the base raised or lowered so that the lowest sole corner is at z = 0."""
    if base == "fixed" or not feet:
        return q
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    lowest = min(
        float((sole @ data.oMf[model.getFrameId(f)].rotation.T)[:, 2].min()
              + data.oMf[model.getFrameId(f)].translation[2])
        for f in feet
    )  # fmt: skip
    q = q.copy()
    q[2 if base == "free_flyer" else 1] -= lowest
    return q


def _lock(model, q, locked, robot) -> tuple[pin.Model, np.ndarray]:
    patterns = [locked] if isinstance(locked, str) else list(locked)
    names = [n for n in model.names[1:] if any(re.fullmatch(p, n) for p in patterns)]
    for pattern in patterns:
        if not any(re.fullmatch(pattern, n) for n in names):
            raise _unknown("locked: joint", pattern, list(model.names[1:]), robot)
    kept = [n for n in model.names[1:] if n not in names]
    reduced = pin.buildReducedModel(model, [model.getJointId(n) for n in names], q)
    parts = []
    for name in kept:
        joint = model.joints[model.getJointId(name)]
        parts.append(q[joint.idx_q : joint.idx_q + joint.nq])
    return reduced, np.concatenate(parts) if parts else np.zeros(0)


def _from_urdf(
    cls, urdf, srdf, base, groups, feet, hands, reference, torso, locked, armature, name,
    package_dirs,
) -> RobotModel:  # fmt: skip
    urdf = _existing_file("urdf", urdf)
    srdf = None if srdf is None else _existing_file("srdf", srdf)
    feet = dict(feet) if isinstance(feet, Mapping) else dict.fromkeys(feet)
    base = base if base is not None else ("free_flyer" if feet else "fixed")
    if base not in BASES:
        raise InvalidInputError(
            f"base={base!r} is not a base kind; expected one of {sorted(BASES)}"
        )
    model = _build_model(urdf, base)
    robot = name or model.name
    if package_dirs is None:
        package_dirs = [urdf.parent, *list(urdf.parents)[:4]]
        try:
            package_dirs.append(example_robot_data_dir().parents[1])
        except MissingDependency:
            pass
    foot_frames, sole = _add_soles(model, urdf, feet, package_dirs, robot)
    for frame in tuple(hands) + ((torso,) if torso else ()):
        if not model.existFrame(frame):
            raise _unknown("frame", frame, [f.name for f in model.frames], robot)
    q, place = _reference(model, srdf, reference, robot)
    if place:
        q = _on_floor(model, q, base, foot_frames, sole)
    first = 2 if base != "fixed" else 1
    if groups is None:
        groups = _srdf_groups(srdf) if srdf is not None else {}
    groups = _joint_groups(model, groups, tuple(model.names[first:]), robot)
    if locked:
        model, q = _lock(model, q, locked, robot)
        if not model.existJointName("root_joint"):
            base = "fixed"
        groups = {g: tuple(j for j in js if model.existJointName(j)) for g, js in groups.items()}
        groups = {g: js for g, js in groups.items() if js}
    n_base, n_base_q = BASES[base], (model.joints[1].nq if base != "fixed" else 0)
    lower, upper = (
        _finite_or_inf(model.lowerPositionLimit),
        _finite_or_inf(model.upperPositionLimit),
    )
    lower[:n_base_q], upper[:n_base_q] = -np.inf, np.inf
    velocity = _finite_or_inf(model.velocityLimit)
    velocity[:n_base] = np.inf
    if armature is not None:
        from dmpopt.validation import vector

        values = np.array(model.armature)
        values[n_base:] = vector("armature", armature, model.nv - n_base, "the actuated joints")
        model.armature = values
    return cls(
        name=robot,
        model=model,
        joint_groups=groups,
        reference_configuration=q,
        position_lower=lower,
        position_upper=upper,
        velocity_limit=velocity,
        torque_limit=_finite_or_inf(model.effortLimit)[n_base:],
        base=base,
        foot_frames=foot_frames,
        hand_frames=tuple(hands),
        sole_corners=sole,
        torso_frame=torso,
        source=str(urdf),
    )
