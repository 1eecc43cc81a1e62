r"""MuJoCo backend of :mod:`dmpopt.sim`: the same robot, from the same URDF, under MuJoCo physics.

:class:`MujocoSimulator` has the interface of :class:`dmpopt.sim.Simulator` (``reset(q, v)``,
``state``, ``step(tau)``, ``push``, ``push_impulse``, touchdown events, falls; besides,
``snapshot()`` and ``restore(snapshot)`` to continue a run from a saved point) and speaks
Pinocchio's coordinates, so a controller written against the Pinocchio model drives either.

Model
    MuJoCo reads the URDF the Pinocchio model was built from (``package://`` mesh paths resolved
    against ``package_dirs``; static links kept as bodies). The Pinocchio root joint is added to
    the URDF root link: a free joint for a free flyer, slide/hinge joints for a composite of
    one-axis joints (the planar biped), nothing for a fixed base. Joints are matched by name and
    the total masses must agree. URDF ``<mimic>`` couplings are dropped, as Pinocchio's URDF
    reader drops them (the Talos gripper joints move independently in both).
Contact
    MuJoCo's soft-constraint contact (default ``solref`` = (0.02 s, 1), ``solimp`` = (0.9, 0.95,
    0.001 m)), elliptic friction cones with ``condim`` 3 (sliding friction only), with a flat
    floor at z = 0. The ``(frame, offset)`` contact points are the feet: a frame with three or
    more points on its x-y plane (a sole's corners) gets a box, the rectangle they span and
    ``SOLE_THICKNESS`` thick above it, so a sole rests flat, rolls on its edges and catches on
    steps as the real one; a frame with fewer points gets a sphere of ``contact_radius`` per
    point whose lowest point is the contact point (point feet). The rest of the body collides
    with the floor through the URDF's collision geometry (links without any: capsules along
    their sticks), so a fallen robot lies on the ground; the links that carry contact points
    (and the static links fixed to them) collide only through their soles. Self-collision is
    off. ``SimState.contact_forces`` are the solver's contact forces (``efc_force``) rotated to
    the world frame, per point: a sole's contacts (at the box's corners on a flat floor) go to
    the nearest corner.
Integration
    Time step ``dt`` (1 ms by default), ``implicitfast`` integrator (damping implicit), Newton
    solver. Torques enter as ``qfrc_applied``, through the plant's saturation and delay.
Joints
    The plant (:class:`dmpopt.sim.PlantParameters`) sets each actuated joint's ``armature``,
    ``damping`` and ``frictionloss``; the default :data:`dmpopt.sim.IDEAL` leaves them 0, so
    the simulated robot is exactly the rigid-body model the controllers use. The URDF's
    ``<dynamics>`` values are not read (pass them through the plant). URDF position limits are
    MuJoCo limit constraints (the native simulator has none).

State conversion (the part where bugs hide): MuJoCo's free joint stores the quaternion as
(w, x, y, z) and its velocity as (linear velocity of the body origin in the **world** frame,
angular velocity in the **local** frame); Pinocchio's free flyer stores (x, y, z, w) and
(linear, angular) both in the **local** frame. With :math:`R` the base orientation,
:math:`\dot q_{mj} = T \dot q_{pin}`, :math:`T = \mathrm{diag}(R, I, P)` with :math:`P` the
name-matched joint permutation; generalised forces map with :math:`T^{-\top}`. As :math:`T`
depends on :math:`q`, MuJoCo's base linear acceleration is Pinocchio's plus
:math:`R\,(\omega \times v_{lin})` (:math:`v_{lin}` the local linear velocity), and its bias
forces are :math:`T^{-\top}` of Pinocchio's minus :math:`M_{mj} \dot T v`.

Loose objects: ``free_bodies`` adds :class:`FreeBox` bodies (a free joint each, not part of
the robot's state ``q, v``); they collide with the floor and with the robot's collision
geometry (so ``body_collisions`` must stay on to hold one), start at their given pose at every
``reset``, and :attr:`MujocoSimulator.free_body_qpos` reads their poses.

Falls: the options ``falls``, ``fall_frame`` and ``fall_height`` of :class:`dmpopt.sim.Simulator`
give the same thresholds (:func:`dmpopt.sim.falls.fall_checks`, standing height above the lowest
contact point in the neutral configuration) and the same checks after each step; the first
fall sets ``state.fall`` and ``step`` refuses to go on until ``reset``. The compiled read-out
after each step (:func:`dmpopt.sim.kernels.settle`) screens the four measures; a step where
one reaches its threshold or comes within 1e-9 (relative) of it is decided by
:meth:`~dmpopt.sim.falls.FallDetector.check` on the watched frame's measures, as before (a
``FallDetector`` subclass is asked every step).

Speed: a step is one compiled call, :func:`dmpopt.sim.kernels_mujoco.advance` (torques,
MuJoCo's C ``mj_step``, the read-out above, the returned state's arrays)
(``benchmarks/bench_mujoco.py --overhead`` measures the ratio to ``mj_step``). Steps while a
push acts (``mj_step1``, the push, ``mj_step2``), and every step when the compiled call is not
available (``native_step_unavailable`` says why: e.g. a ``mujoco`` without ``_address``), go
through the Python bindings and :func:`dmpopt.sim.kernels.settle`: the same numbers, bit for
bit.

Returned states: each step returns a :class:`SimState` of its own, whose arrays no later step
changes while anyone holds the state, one of its arrays or a view of one. Making those objects
anew at each step cost more than a quarter of the biped's ``mj_step``, so the simulator
recycles them: steps take turns between two slots, each a ``SimState`` whose arrays are views
of one block, and the compiled call copies the step's state into the slot of two steps ago
only if nobody else holds any of its objects (their reference counts are as when the slot was
made: :func:`dmpopt.sim.kernels_mujoco.publish`); else the slot gets new objects, as the
caller who keeps a state (``log.append(state.q)``) expects. The usual loop
(``state = sim.step(tau)``) holds the previous state during a step, so its states are recycled.
Where an object's first word is not its reference count (a free-threaded Python,
:func:`dmpopt.sim.kernels_mujoco.counts_references`), every step makes new objects.

The ``mujoco`` package is imported on first use (extra ``dmpopt[mujoco]``); ``MUJOCO_GL``
defaults to ``egl`` (headless rendering) when unset at that moment.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
import pinocchio as pin

from dmpopt.exceptions import (
    FileFormatError,
    InvalidInputError,
    MissingDependency,
    ResourceLimitError,
    ShapeError,
    SimulationDiverged,
)
from dmpopt.sim import kernels, kernels_mujoco
from dmpopt.sim.falls import (
    Fall,
    FallDetector,
    fall_checks,
    refuse_floating_without_contacts,
)
from dmpopt.sim.kernels import (
    STATE_OK,
    STATE_UNSTABLE,
    apply_torques,
    pinocchio_state,
    read_contacts,
    settle,
    to_pinocchio,
)
from dmpopt.sim.kernels_mujoco import STATE_BAD_INPUT, STATE_SLOTS, advance, publish
from dmpopt.sim.plant import IDEAL, PlantParameters, PlantRuntime, base_joint_kind
from dmpopt.sim.simulator import Backend, SimState, TouchdownEvent, _Push
from dmpopt.validation import real, real_array

__all__ = ["SOLE_THICKNESS", "FreeBox", "MujocoSimulator", "MujocoSnapshot", "render_animation"]

SOLE_THICKNESS = 0.01  # [m] of the box that stands for a sole
_FLOOR_BIT, _BODY_BIT = 1, 2  # contype bits: contact geometry of the feet, the rest of the body

_PACKAGE_URI = re.compile(r"package://+([^/\"']+)/([^\"']+)")
_ROBOT_TAG = re.compile(r"<robot\b[^>]*>")
_FLOOR_RGBA = (0.82, 0.84, 0.86, 1.0)
# MuJoCo's warnings BADQPOS, BADQVEL, BADQACC: it reset the data
_UNSTABLE = slice(
    kernels_mujoco.FIRST_UNSTABLE, kernels_mujoco.FIRST_UNSTABLE + kernels_mujoco.UNSTABLE_WARNINGS
)
_NONE = np.zeros(0, dtype=np.int32)
_NO_FORCE = np.zeros(0)
_FLOAT = np.dtype(float)
_ONE_FLOAT = (_FLOAT.itemsize,)  # the strides of a contiguous 1-D float array
_ARRAY = np.ndarray
_new = object.__new__


@dataclass(frozen=True)
class FreeBox:
    """A loose box in the MuJoCo scene (a free body), e.g. an object the robot carries.

    Attributes
    ----------
    name : str
        Body name in the MuJoCo model.
    half_sizes : tuple of float
        Half widths along the box's x, y, z axes [m].
    mass : float
        [kg], spread uniformly.
    position : tuple of float
        Initial centre, world frame [m].
    orientation : tuple of float
        Initial orientation, unit quaternion ``(w, x, y, z)``.
    friction : float
        Coulomb coefficient of its contacts (MuJoCo takes the larger of the two geoms').
    torsional_friction : float
        Friction against spinning about the contact normal [m] (MuJoCo's ``condim`` 4).
    """

    name: str
    half_sizes: tuple
    mass: float
    position: tuple
    orientation: tuple = (1.0, 0.0, 0.0, 0.0)
    friction: float = 1.0
    torsional_friction: float = 0.01


def _import_mujoco():
    """The ``mujoco`` module, or :class:`MissingDependency` naming the extra."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    try:
        import mujoco
    except ImportError as error:
        raise MissingDependency(
            f"the MuJoCo backend needs the `mujoco` package ({error}); "
            "install it with `pip install 'dmpopt[mujoco]'`"
        ) from None
    return mujoco


def _positive(name: str, value, allow_none=False, allow_zero=False) -> float | None:
    """A finite number > 0 (>= 0 with ``allow_zero``; None kept with ``allow_none``)."""
    if value is None and allow_none:
        return None
    bound = ">= 0" if allow_zero else "> 0"
    extra = " or None (keep the URDF value)" if allow_none else ""
    return real(
        name,
        value,
        minimum=0.0,
        open_minimum=not allow_zero,
        expected=f"a finite number {bound}{extra}",
    )


def _vector(name: str, value, size: int) -> np.ndarray:
    if (
        type(value) is np.ndarray
        and value.dtype == np.float64
        and value.shape == (size,)
        and math.isfinite(value.sum())
    ):
        return value  # the common case in a loop, checked in a few operations
    return real_array(name, value, shape=(size,))


def _pairs(contact_points) -> list[tuple[str, object]]:
    """``contact_points`` as a list of ``(frame_name, offset)`` pairs."""
    try:
        pairs = list(contact_points)
    except TypeError:
        raise InvalidInputError(
            f"contact_points must be a sequence of (frame_name, offset_xyz) pairs, got "
            f"{contact_points!r}; pass () for no contact"
        ) from None
    for item in pairs:
        if not (isinstance(item, (tuple, list)) and len(item) == 2):
            raise InvalidInputError(
                f"contact_points must hold (frame_name, offset_xyz) pairs, got {item!r}"
            )
    return pairs


def _urdf_for_mujoco(urdf: Path, package_dirs) -> str:
    """URDF text with ``package://`` paths made absolute and MuJoCo compiler options added."""
    text = urdf.read_text()
    directories = [Path(d) for d in package_dirs]

    def resolve(match: re.Match) -> str:
        package, rest = match.groups()
        for directory in directories:
            candidate = directory / package / rest
            if candidate.is_file():
                return str(candidate)
        raise FileFormatError(
            f"{urdf.name}: mesh {match.group(0)!r} was not found in any of package_dirs "
            f"{[str(d) for d in directories]}; pass package_dirs= with the directory that holds "
            f"the package {package!r}"
        )

    text = _PACKAGE_URI.sub(resolve, text)
    if not _ROBOT_TAG.search(text):
        raise FileFormatError(f"urdf {str(urdf)!r} has no <robot> element; expected a URDF file")
    compiler = (
        '<mujoco><compiler fusestatic="false" strippath="false" discardvisual="true" '
        f'meshdir="{urdf.parent}"/></mujoco>'
    )
    return _ROBOT_TAG.sub(lambda m: m.group(0) + compiler, text, count=1)


@dataclass(frozen=True, eq=False)
class MujocoSnapshot:
    """A :meth:`MujocoSimulator.snapshot`: pass it to :meth:`MujocoSimulator.restore`."""

    data: object  # mujoco.MjData
    arrays: tuple
    pushes: tuple
    touchdown_events: tuple
    last_touchdowns: tuple
    fall: Fall | None
    rng_state: dict


class MujocoSimulator(Backend):
    """A Pinocchio-described robot simulated by MuJoCo from the same URDF.

    Parameters
    ----------
    model : pinocchio.Model
        The robot as the controller sees it, built from ``urdf``; its root joint (free flyer,
        composite of one-axis joints, or none) is the unactuated base. ``q`` and ``v`` are in
        its coordinates.
    urdf : str or Path
        The URDF file ``model`` was built from.
    dt : float
        Time step [s].
    contact_points : sequence of (str, array_like)
        ``(frame_name, offset_xyz)`` pairs, offset in the frame [m]; one floor-contact sphere each.
    friction : float
        Coulomb friction coefficient between the contact spheres and the floor [-].
    contact_radius : float
        Radius of the contact spheres [m].
    plant : PlantParameters
        Joint armature, damping and friction, torque saturation, delay and sensor noise (see
        :mod:`dmpopt.sim.plant`); default :data:`~dmpopt.sim.IDEAL`, the controller's model.
    body_collisions : bool
        Whether the links other than the feet collide with the floor (see Contact above).
    package_dirs : sequence of path, optional
        Where ``package://NAME/...`` is looked up as ``DIR/NAME/...``; defaults to the URDF's
        parent directories.
    fall_frame, fall_height, falls
        Fall checks, as in :class:`dmpopt.sim.Simulator` (same thresholds for the same robot
        and contact points): ``fall_frame`` is the watched frame of the base body,
        ``fall_height`` replaces the derived ``min_height`` [m above the floor], ``falls`` is
        True (derived thresholds), False (no checks) or a :class:`FallDetector`.
    max_speed : float
        Any ``|v_i|`` above this raises :class:`SimulationDiverged` [m/s or rad/s].
    free_bodies : sequence of FreeBox
        Loose boxes in the scene (module docstring, Loose objects); none by default.
    boxes : sequence of (array_like, array_like[, float])
        Fixed boxes on the floor, as uneven ground: ``(centre, half_sizes)`` in the world
        frame [m], shape (3,) each, and optionally a pitch [rad] (rotation about y: a slope
        along x, descending towards +x when positive). They touch what the floor touches,
        with the floor's friction.

    Attributes
    ----------
    model : pinocchio.Model
    mj_model, mj_data : mujoco.MjModel, mujoco.MjData
        After a step, ``mj_data`` is as ``mj_step`` leaves it: ``qpos`` and ``qvel`` of the new
        state, body poses and contacts of the start of the step (``mj_kinematics`` updates
        the poses).
    n_base_dofs, n_actuated : int
    contact_frames : list of str
    touchdown_events : list of TouchdownEvent
    fall_detector : FallDetector or None
        The thresholds in use (None: no fall checks).
    fall : Fall or None
        The fall that stopped the simulation, if any.
    native_step_unavailable : str or None
        Why the steps go through MuJoCo's Python bindings instead of the compiled call with
        MuJoCo's ``mj_step`` inside (module docstring, Speed); None while they do not.
    """

    def __init__(
        self,
        model: pin.Model,
        urdf,
        dt: float = 1e-3,
        contact_points=(),
        friction: float = 1.0,
        contact_radius: float = 0.005,
        plant: PlantParameters = IDEAL,
        body_collisions: bool = True,
        package_dirs=None,
        fall_frame: str | None = None,
        fall_height: float | None = None,
        falls: bool | FallDetector = True,
        max_speed: float = 1e3,
        free_bodies=(),
        boxes=(),
    ):
        mujoco = _import_mujoco()
        self._mj = mujoco
        if not isinstance(model, pin.Model):
            raise InvalidInputError(
                f"model must be a pinocchio.Model, got {type(model).__name__}; pass e.g. "
                "robot.model with urdf=robot.source"
            )
        self.dt = _positive("dt", dt)
        self._max_speed = _positive("max_speed", max_speed)
        friction = _positive("friction", friction, allow_zero=True)
        contact_radius = _positive("contact_radius", contact_radius)
        if not isinstance(body_collisions, (bool, np.bool_)):
            raise InvalidInputError(
                f"body_collisions must be True or False, got {body_collisions!r}"
            )
        urdf = Path(urdf)
        if not urdf.is_file():
            raise InvalidInputError(f"urdf {str(urdf)!r} is not a file; pass the robot's URDF path")
        if package_dirs is None:
            package_dirs = urdf.resolve().parents
        elif isinstance(package_dirs, (str, Path)):
            package_dirs = [package_dirs]
        self.model = model
        self._base = base_joint_kind(model)
        self.n_base_dofs = 0 if self._base is None else model.joints[1].nv
        self.n_actuated = model.nv - self.n_base_dofs
        self._torque_shape, self._base_shape = (self.n_actuated,), (self.n_base_dofs,)
        first = 1 if self._base is None else 2
        self.plant = PlantRuntime(plant, model, self._base, model.names[first:])

        spec = self._spec(urdf, package_dirs)
        self._check_joints(spec, urdf)
        self._set_joint_dynamics(spec)
        self._add_floor(spec, friction)
        self._add_boxes(spec, boxes, friction)
        contact_points = _pairs(contact_points)
        self.contact_frames = [name for name, _ in contact_points]
        feet = self._add_feet(spec, contact_points, contact_radius)
        if body_collisions:
            self._collide_body(spec, feet)
        self._add_free_bodies(spec, free_bodies)
        self.fall_detector, self._watched = fall_checks(
            model, self.n_base_dofs, contact_points, falls, fall_frame, fall_height
        )
        refuse_floating_without_contacts(
            model, self.n_base_dofs, contact_points, falls, fall_height
        )
        try:
            self.mj_model = spec.compile()
        except ValueError as error:
            raise FileFormatError(f"MuJoCo could not compile {urdf.name}: {error}") from None
        self.mj_data = mujoco.MjData(self.mj_model)
        warning = mujoco.mjtWarning
        if (_UNSTABLE.start, _UNSTABLE.stop) != (
            int(warning.mjWARN_BADQPOS),
            int(warning.mjWARN_BADQACC) + 1,
        ):
            raise MissingDependency(  # pragma: no cover - a MuJoCo that renumbered them
                f"this mujoco {mujoco.__version__} numbers its warnings differently; "
                "install the version pinned by dmpopt[mujoco]"
            )
        self._map_coordinates()
        self._free_qpos = np.array(
            [
                self.mj_model.joint(f"{name}_free").qposadr[0] + k
                for name in self.free_bodies
                for k in range(7)
            ],
            dtype=int,
        )
        self._check_mass(urdf)
        self._n_points = len(contact_points)
        self._index_contact_geoms(contact_points)
        self._pack_step_arrays()
        self._compile_step()
        self._compile_advance()
        self.reset(pin.neutral(model), np.zeros(model.nv))
        if self.fall_detector is not None:  # and the fall check's, before any timed step
            self._watched.height_tilt_spin(self._q, self._v)

    # ------------------------------------------------------------------ model building
    def _spec(self, urdf: Path, package_dirs):
        """MjSpec of the URDF with the Pinocchio base joint added to the root link."""
        mujoco = self._mj
        text = _urdf_for_mujoco(urdf, package_dirs)
        try:
            spec = mujoco.MjSpec.from_string(text)
        except ValueError as error:
            raise FileFormatError(f"MuJoCo could not read {urdf.name}: {error}") from None
        spec.option.timestep = self.dt
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        spec.option.solver = mujoco.mjtSolver.mjSOL_NEWTON
        root = spec.worldbody.first_body()
        if self._base == "free":
            root.add_freejoint(name=self.model.names[1])
        elif self._base is not None:
            for k, (kind, axis) in enumerate(self._base):
                joint_type = (
                    mujoco.mjtJoint.mjJNT_SLIDE if kind == "P" else mujoco.mjtJoint.mjJNT_HINGE
                )
                root.add_joint(name=f"{self.model.names[1]}_{k}", type=joint_type, axis=axis)
        for equality in list(spec.equalities):  # URDF <mimic>: Pinocchio's joints are free
            spec.delete(equality)
        spec.compiler.discardvisual = False  # keep the non-colliding geometry below
        for geom in spec.geoms:  # URDF collision geometry: see _collide_body
            geom.contype = geom.conaffinity = 0
        for body in spec.bodies[1:]:  # links without geometry (the planar biped): sticks
            if body.geoms or not body.explicitinertial:  # no mass from geometry
                continue
            for child in body.bodies:
                if np.linalg.norm(child.pos) > 1e-6:
                    body.add_geom(
                        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                        fromto=[0.0, 0.0, 0.0, *child.pos],
                        size=[0.02, 0.0, 0.0],
                        contype=0,
                        conaffinity=0,
                        rgba=[0.45, 0.5, 0.6, 1.0],
                    )
        return spec

    def _set_joint_dynamics(self, spec) -> None:
        """The plant's armature, damping and friction on every actuated joint."""
        plant = self.plant
        for k, name in enumerate(plant.joint_names):
            joint = spec.joint(name)
            joint.armature = plant.armature[k]
            joint.damping = [plant.damping[k], 0.0, 0.0]
            joint.frictionloss = plant.friction[k]

    def _add_floor(self, spec, friction: float) -> None:
        mujoco = self._mj
        spec.worldbody.add_light(pos=[0, 0, 4], dir=[0, 0, -1], diffuse=[0.8, 0.8, 0.8])
        spec.worldbody.add_geom(
            name="floor",
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[0, 0, 0.05],
            rgba=_FLOOR_RGBA,
            friction=[friction, 0.005, 0.0001],
            condim=3,
            contype=_FLOOR_BIT,
            conaffinity=_FLOOR_BIT | _BODY_BIT,
        )

    def _add_free_bodies(self, spec, free_bodies) -> None:
        """A body with a free joint and one box geom per :class:`FreeBox`."""
        mujoco = self._mj
        boxes = tuple(free_bodies)
        for box in boxes:
            if not isinstance(box, FreeBox):
                raise InvalidInputError(
                    f"free_bodies must hold FreeBox values, got {type(box).__name__}"
                )
        names = [box.name for box in boxes]
        taken = {body.name for body in spec.bodies}
        clashes = sorted(set(names) & taken) + sorted({n for n in names if names.count(n) > 1})
        if clashes:
            raise InvalidInputError(
                f"free body names {clashes} repeat or are links of the robot; rename them"
            )
        for box in boxes:
            half = _vector(f"half_sizes of {box.name!r}", box.half_sizes, 3)
            orientation = _vector(f"orientation of {box.name!r}", box.orientation, 4)
            body = spec.worldbody.add_body(
                name=box.name,
                pos=_vector(f"position of {box.name!r}", box.position, 3),
                quat=orientation / np.linalg.norm(orientation),
            )
            body.add_freejoint(name=f"{box.name}_free")
            body.add_geom(
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=half,
                mass=_positive(f"mass of {box.name!r}", box.mass),
                friction=[_positive("friction", box.friction), box.torsional_friction, 1e-4],
                condim=4,
                contype=_BODY_BIT,  # touches the floor (its conaffinity) and the robot's links
                conaffinity=_BODY_BIT,
                rgba=[0.75, 0.55, 0.3, 1.0],
            )
        self.free_bodies = tuple(names)

    @property
    def free_body_qpos(self) -> np.ndarray:
        """Poses of the free bodies: per body position [m] and quaternion ``(w, x, y, z)``,
        shape (7 * n_free_bodies,)."""
        return self.mj_data.qpos[self._free_qpos].copy()

    def _add_boxes(self, spec, boxes, friction: float) -> None:
        for k, box in enumerate(boxes):
            if not isinstance(box, (tuple, list)) or len(box) not in (2, 3):
                raise InvalidInputError(
                    f"boxes[{k}] must be (centre, half_sizes) or (centre, half_sizes, pitch), "
                    f"got {box!r}"
                )
            centre = real_array(f"boxes[{k}] centre", box[0], shape=(3,))
            half = real_array(f"boxes[{k}] half_sizes", box[1], shape=(3,))
            if (half <= 0).any():
                raise InvalidInputError(f"boxes[{k}] half_sizes must be > 0 [m], got {half}")
            pitch = real(f"boxes[{k}] pitch", box[2]) if len(box) == 3 else 0.0
            spec.worldbody.add_geom(
                name=f"box_{k}",
                type=self._mj.mjtGeom.mjGEOM_BOX,
                pos=centre,
                size=half,
                quat=[np.cos(pitch / 2), 0.0, np.sin(pitch / 2), 0.0],
                rgba=[0.6, 0.62, 0.66, 1.0],
                friction=[friction, 0.005, 0.0001],
                condim=3,
                contype=_FLOOR_BIT,
                conaffinity=_FLOOR_BIT | _BODY_BIT,
            )

    def _base_joint_names(self) -> list[str]:
        """Names of the MuJoCo joints that stand for the Pinocchio root joint."""
        if self._base is None:
            return []
        if self._base == "free":
            return [self.model.names[1]]
        return [f"{self.model.names[1]}_{k}" for k in range(len(self._base))]

    def _spec_body(self, spec, joint_id: int):
        """The MjSpec body moved by Pinocchio joint ``joint_id`` (the world for 0)."""
        if joint_id == 0:
            return spec.worldbody
        if joint_id == 1 and self._base is not None:
            return spec.worldbody.first_body()
        return spec.joint(self.model.names[joint_id]).parent

    def _frame(self, name: str) -> pin.Frame:
        if not isinstance(name, str) or not self.model.existFrame(name):
            raise InvalidInputError(
                f"frame {name!r} is not in the model {self.model.name!r}; "
                "use a frame name of the Pinocchio model"
            )
        return self.model.frames[self.model.getFrameId(name)]

    def _add_feet(self, spec, contact_points, radius: float) -> set:
        """A site at every contact point; a box per sole, a sphere per point foot.

        Returns the names of the MjSpec bodies that carry contact geometry.
        """
        by_frame: dict[str, list[int]] = {}
        points = []
        for index, (name, offset) in enumerate(contact_points):
            frame = self._frame(name)
            offset = _vector(f"offset of contact point {name!r}", offset, 3)
            points.append(offset)
            by_frame.setdefault(name, []).append(index)
            body = self._spec_body(spec, frame.parentJoint)
            body.add_site(name=f"contact_point_{index}", pos=frame.placement.act(offset))
        self._soles = {}
        bodies = set()
        friction = [spec.geom("floor").friction[0], 0.005, 0.0001]
        for name, indices in by_frame.items():
            frame = self._frame(name)
            body = self._spec_body(spec, frame.parentJoint)
            bodies.add(body.name)
            local = np.array([points[i] for i in indices])
            up = frame.placement.rotation[:, 2]
            if len(indices) >= 3 and np.ptp(local[:, 2]) < 1e-9:
                low, high = local[:, :2].min(axis=0), local[:, :2].max(axis=0)
                centre = np.r_[(low + high) / 2, local[0, 2] + SOLE_THICKNESS / 2]
                quaternion = np.empty(4)
                self._mj.mju_mat2Quat(quaternion, frame.placement.rotation.reshape(-1))
                body.add_geom(
                    name=f"sole_{len(self._soles)}",
                    type=self._mj.mjtGeom.mjGEOM_BOX,
                    size=[*((high - low) / 2), SOLE_THICKNESS / 2],
                    pos=frame.placement.act(centre),
                    quat=quaternion,
                    contype=_FLOOR_BIT,
                    conaffinity=0,
                    condim=3,
                    friction=friction,
                    rgba=[0.9, 0.3, 0.2, 1.0],
                )
                self._soles[f"sole_{len(self._soles)}"] = indices
                continue
            for index in indices:
                body.add_geom(
                    name=f"contact_point_{index}",
                    type=self._mj.mjtGeom.mjGEOM_SPHERE,
                    size=[radius, 0, 0],
                    pos=frame.placement.act(points[index]) + radius * up,
                    contype=_FLOOR_BIT,
                    conaffinity=0,
                    condim=3,
                    friction=friction,
                    rgba=[0.9, 0.3, 0.2, 1.0],
                )
        return bodies

    def _collide_body(self, spec, feet: set) -> None:
        """The links' collision geometry touches the floor, except on the feet's links (and the
        static links fixed to them); links drawn as sticks get capsules that collide."""

        def welded(body) -> list:
            return [body] + [b for child in body.bodies if not child.joints for b in welded(child)]

        skipped = {b.name for body in spec.bodies if body.name in feet for b in welded(body)}
        for body in spec.bodies[1:]:
            if body.name in skipped:
                continue
            for geom in body.geoms:
                if geom.name.startswith(("sole_", "contact_point_")):
                    continue
                geom.contype, geom.conaffinity = _BODY_BIT, 0

    def _index_contact_geoms(self, contact_points) -> None:
        """``_foot_code`` per MuJoCo geom: 0 for a geom of no foot, else ``1 + k`` with row
        ``k`` of ``_foot_points`` the contact points of that geom (a sphere's one point, a
        sole's corners; rows padded by repeating their points)."""
        model = self.mj_model
        names = [f"contact_point_{i}" for i in range(self._n_points)]
        self._point_sites = np.array([model.site(n).id for n in names], dtype=int)
        self._foot_code = np.zeros(model.ngeom, dtype=int)
        feet = []
        for index in range(self._n_points):
            geom = self._mj.mj_name2id(model, self._mj.mjtObj.mjOBJ_GEOM, f"contact_point_{index}")
            if geom >= 0:
                feet.append((geom, [index]))
        feet += [(model.geom(name).id, indices) for name, indices in self._soles.items()]
        width = max((len(indices) for _, indices in feet), default=1)
        self._foot_points = np.zeros((len(feet), width), dtype=int)
        for k, (geom, indices) in enumerate(feet):
            self._foot_code[geom] = 1 + k
            self._foot_points[k] = np.resize(indices, width)  # repeats fill a short row

    def _check_joints(self, spec, urdf: Path) -> None:
        """The model's joints are the URDF's, by name, and all have one axis."""
        model = self.model
        first = 1 if self._base is None else 2
        pin_names = list(model.names[first:])
        mj_names = {j.name for j in spec.joints} - set(self._base_joint_names())
        missing = [n for n in pin_names if n not in mj_names]
        extra = sorted(mj_names - set(pin_names))
        if missing or extra:
            raise InvalidInputError(
                f"model and urdf {urdf.name} disagree on joints: in the model only {missing}, "
                f"in the URDF only {extra}; build model from this URDF (locked joints are not "
                "supported)"
            )
        for joint_id, name in enumerate(pin_names, start=first):
            joint = model.joints[joint_id]
            if joint.nq != 1 or joint.nv != 1:
                raise InvalidInputError(
                    f"joint {name!r} is a {joint.shortname()} (nq={joint.nq}, nv={joint.nv}); "
                    "only one-axis revolute or prismatic joints are supported"
                )

    def _check_mass(self, urdf: Path) -> None:
        """Same mass on the moving bodies (a fixed base's root link belongs to the world)."""
        robot = self.mj_model.body_rootid == self.mj_model.body_rootid[1]  # not free bodies
        moving = (self.mj_model.body_weldid != 0) & robot
        mass, mj_mass = (
            pin.computeTotalMass(self.model),
            float(self.mj_model.body_mass[moving].sum()),
        )
        if not np.isclose(mass, mj_mass, rtol=1e-6):
            raise InvalidInputError(
                f"model ({mass:.6g} kg) and urdf {urdf.name} ({mj_mass:.6g} kg) are not the same "
                "robot; pass the URDF the model was built from"
            )

    def _map_coordinates(self) -> None:
        """Index maps between Pinocchio (q, v) and MuJoCo (qpos, qvel), by joint name."""
        model, mj_model = self.model, self.mj_model
        first = 1 if self._base is None else 2
        qpos, dofs = np.empty(model.nq, dtype=int), np.empty(model.nv, dtype=int)
        for joint_id in range(first, model.njoints):
            joint, name = model.joints[joint_id], model.names[joint_id]
            qpos[joint.idx_q] = mj_model.joint(name).qposadr[0]
            dofs[joint.idx_v] = mj_model.joint(name).dofadr[0]
        if self._base == "free":
            root = mj_model.joint(model.names[1])
            qpos[:7] = root.qposadr[0] + np.array([0, 1, 2, 4, 5, 6, 3])  # x y z | qx qy qz qw
            dofs[:6] = root.dofadr[0] + np.arange(6)
        elif self._base is not None:
            for k in range(len(self._base)):
                joint = mj_model.joint(f"{model.names[1]}_{k}")
                qpos[k], dofs[k] = joint.qposadr[0], joint.dofadr[0]
        self._qpos_index, self._dof_index = qpos, dofs
        self._quaternion = None  # MuJoCo's (w, x, y, z) of a free base in qpos
        self._quaternion_start = -1
        if self._base == "free":
            self._quaternion_start = int(qpos[6])
            self._quaternion = slice(int(qpos[6]), int(qpos[6]) + 4)
        self._rotation = np.empty(9)  # buffers of the base rotation

    def _pack_step_arrays(self) -> None:
        """The arrays :func:`dmpopt.sim.kernels.settle` reads and writes after each step
        (layouts there), the views of them the simulator reads, and MuJoCo's arrays that
        stay in place (views into ``mj_data``, valid while it lives)."""
        model, data = self.model, self.mj_data
        nq, nv, n_points = model.nq, model.nv, self._n_points
        watched, axes, parts = self._watched, [], []
        placements = [np.zeros(12)] * 2
        if watched is not None:
            placements = [_flat(watched._placement), _flat(watched._offset)]
            if self._base != "free":
                composite = model.joints[1].extract()
                for (kind, axis), placement in zip(self._base, composite.jointPlacements):
                    axes.append(int(np.argmax(axis)) + (3 if kind == "R" else 0))
                    parts.append(_flat(placement))
        header = np.zeros(kernels.TABLES_HEADER, dtype=np.int64)
        header[kernels.N_Q], header[kernels.N_V], header[kernels.N_POINTS] = nq, nv, n_points
        header[kernels.N_GEOMS] = self._foot_code.size
        header[kernels.N_FEET], header[kernels.WIDTH] = self._foot_points.shape
        header[kernels.N_PARTS] = len(axes)
        header[kernels.QUATERNION_START] = self._quaternion_start
        header[kernels.NOISY] = self.plant.noisy
        header[kernels.N_BASE_DOFS] = self.n_base_dofs
        self._tables = np.concatenate(
            [
                header,
                self._qpos_index,
                self._dof_index,
                self._point_sites,
                self._foot_code,
                self._foot_points.ravel(),
                np.array(axes, dtype=np.int64),
            ]
        ).astype(np.int64)
        self._constants = np.concatenate([np.zeros(5), *placements, *parts])
        self.max_speed = self._max_speed  # into the constants
        self._pack_fall_checks()
        self._work = np.zeros(2 * (nq + nv) + 6 * n_points)
        self._q, self._v = self._work[:nq], self._work[nq : nq + nv]
        at = nq + nv
        self._forces = self._work[at : at + 3 * n_points].reshape(n_points, 3)
        self._positions = self._work[at + 3 * n_points : at + 6 * n_points].reshape(n_points, 3)
        at += 6 * n_points
        self._q_measured = self._work[at : at + nq]
        self._v_measured = self._work[at + nq :]
        self._flags = np.zeros(2 * n_points, dtype=bool)
        self._contact_time = np.full(1, math.nan)  # end of the last step with a contact [s]
        self._noisy = self.plant.noisy
        self._in_contact, self._started = self._flags[:n_points], self._flags[n_points:]
        self._qpos, self._qvel, self._qfrc_applied = data.qpos, data.qvel, data.qfrc_applied
        self._site_xpos, self._warnings = data.site_xpos, data.warning.number[_UNSTABLE]

    def _compile_step(self) -> None:
        """Compile (or load from numba's cache) the step's kernels before any timed step: for
        MuJoCo's contact arrays as they come with contacts (strided views) and without (empty,
        contiguous). Writes the step buffers: ``reset`` follows."""
        n = self.n_actuated
        apply_torques(
            np.zeros(n), _NO_FORCE, self.plant.torque_limit, np.zeros((1, n)),
            np.zeros(2, dtype=np.int64), np.zeros(self.model.nv), self._dof_index,
            self.n_base_dofs,
        )  # fmt: skip
        strided = (  # two contacts skipped (no constraint rows), in strided arrays
            np.zeros((2, 4), dtype=np.int32)[:, :2],
            np.full(4, -1, dtype=np.int32)[::2],
            np.zeros((2, 18))[:, :9],
            np.zeros((2, 6))[:, :3],
        )
        empty = tuple(np.ascontiguousarray(a[:0]) for a in strided)
        for geom, efc_address, frame, position in (strided, empty):
            settle(
                self._qpos, self._qvel, self._warnings, geom, efc_address, frame, position,
                np.zeros(0), self._site_xpos, self._tables, self._constants, self._work,
                self._flags, self.plant.noise, 0.0, math.nan,
            )  # fmt: skip

    def _compile_advance(self) -> None:
        """Set up the compiled step with MuJoCo's ``mj_step`` inside
        (:mod:`dmpopt.sim.kernels_mujoco`) and compile it (or load it from numba's cache), or
        keep in ``native_step_unavailable`` why the steps go through the Python bindings; and
        the state slots both paths fill (module docstring, Returned states)."""
        self._advance = None
        self.native_step_unavailable = None
        try:
            kernels_mujoco.load_library(self._mj)
            layout = kernels_mujoco.native_layout(self._mj, self.mj_model, self.mj_data)
        except MissingDependency as error:
            self.native_step_unavailable = str(error)
            layout = np.zeros(kernels_mujoco.LAYOUT_SIZE, dtype=np.int64)  # never stepped
        plant = self.plant
        self._clock = np.zeros(2)  # advance's mj_step timer (benchmarks): on, reading [s]
        self._native_arrays = {  # kept alive here: advance reads them by address
            "torque_limit": plant.torque_limit, "line": plant.line, "ring": plant.ring,
            "layout": layout, "clock": self._clock, "qpos": self._qpos, "qvel": self._qvel,
            "qfrc_applied": self._qfrc_applied, "site_xpos": self._site_xpos,
            "tables": self._tables, "constants": self._constants, "work": self._work,
            "flags": self._flags, "noise": plant.noise, "normals": plant.normals,
            "next_row": plant.next_row, "contact_time": self._contact_time,
        }  # fmt: skip
        self._advance_arrays = kernels_mujoco.array_table(self._native_arrays)
        self._slots = [None] * STATE_SLOTS
        self._turn = 0  # the slot of the next step's state
        self._recycles = kernels_mujoco.counts_references()
        for slot in range(STATE_SLOTS):
            self._fresh_slot(slot)
        if self.native_step_unavailable is not None:
            return
        self._table_address = self._advance_arrays.ctypes.data
        vector = numba.typeof(np.zeros(4)[::2])  # a float vector, contiguous or not
        signature = (vector, vector, numba.typeof(self._table_address), numba.typeof(0))
        advance.compile(signature)
        # the compiled function's own entry point: no dispatch on the argument types (step
        # passes only float64 vectors and two integers, the types compiled for; numba's
        # unboxing does not check a dtype nor the number of dimensions)
        self._advance = getattr(advance.overloads[signature], "entry_point", advance)

    def _leave_native(self, reason: str) -> None:
        """Step through the Python bindings from now on, for ``reason``."""
        self._advance = None
        self.native_step_unavailable = reason

    def _fresh_slot(self, slot: int) -> None:
        """New objects for state slot ``slot`` (:meth:`_slot_objects`), entered in the table
        with their reference words while nobody else holds them (module docstring, Speed)."""
        self._slots[slot] = self._slot_objects(slot)
        if self._recycles:
            kernels_mujoco.hold_words(self._advance_arrays, slot)

    def _slot_objects(self, slot: int) -> list:
        """``[state, block, q, v, contact_forces, in_contact, contact_positions(, q_measured,
        v_measured)]``: a new block laid out as ``work`` then the contact flags
        (:func:`dmpopt.sim.kernels_mujoco.publish`), the state's arrays as views of it, and a
        :class:`SimState` holding them; entered in the table."""
        nq, nv, n_points = self.model.nq, self.model.nv, self._n_points
        size = self._work.size
        block = np.zeros(size + -(-n_points // 8))  # the flags' bytes in whole words
        at = nq + nv
        q, v = block[:nq], block[nq:at]
        forces = block[at : at + 3 * n_points].reshape(n_points, 3)
        positions = block[at + 3 * n_points : at + 6 * n_points].reshape(n_points, 3)
        at += 6 * n_points
        in_contact = block[size:].view(np.bool_)[:n_points]
        objects = [None, block, q, v, forces, in_contact, positions]
        q_measured, v_measured = q, v
        if self._noisy:
            q_measured, v_measured = block[at : at + nq], block[at + nq : size]
            objects += [q_measured, v_measured]
        state = _new(SimState)
        state.__dict__.update(
            t=0.0, q=q, v=v, contact_forces=forces, in_contact=in_contact,
            contact_positions=positions, touchdowns=(), fall=None, q_measured=q_measured,
            v_measured=v_measured,
        )  # fmt: skip
        objects[0] = state
        kernels_mujoco.enter_slot(self._advance_arrays, slot, block, objects)
        return objects

    def _pack_fall_checks(self) -> None:
        """The fall thresholds and base kind in the packed arrays, for the detector in
        ``fall_detector`` (``step`` re-packs when it is replaced)."""
        detector = self.fall_detector
        if detector is not None and self._watched is None:
            raise InvalidInputError(
                "fall_detector set on a simulator built without fall checks; build it with "
                "falls=FallDetector(...) instead"
            )
        # a FallDetector subclass may check differently: then every step checks in Python
        self._screened = detector is None or type(detector) is FallDetector
        base = kernels.BASE_UNCHECKED
        if detector is not None and self._screened:
            base = kernels.BASE_FREE if self._base == "free" else kernels.BASE_COMPOSITE
            self._constants[1:5] = (
                detector.min_height,
                detector.max_tilt,
                detector.max_flight_time,
                detector.max_spin,
            )
        self._tables[kernels.BASE] = base
        self._packed_detector = detector

    @property
    def max_speed(self) -> float:
        """Any ``|v_i|`` above this raises :class:`SimulationDiverged` [m/s or rad/s]."""
        return self._max_speed

    @max_speed.setter
    def max_speed(self, value) -> None:
        self._max_speed = _positive("max_speed", value)
        if hasattr(self, "_constants"):
            self._constants[0] = self._max_speed

    def _locate(self, frame_name: str, offset) -> tuple[int, np.ndarray]:
        """MuJoCo body of a frame and the point's position in that body's frame."""
        frame = self._frame(frame_name)
        offset = _vector("offset", offset, 3)
        joint_id = frame.parentJoint
        if joint_id == 0:
            body = 0
        elif joint_id == 1 and self._base is not None:
            body = int(self.mj_model.joint(self._base_joint_names()[0]).bodyid[0])
        else:
            body = int(self.mj_model.joint(self.model.names[joint_id]).bodyid[0])
        return body, frame.placement.act(offset)

    # ------------------------------------------------------------------ state conversion
    def _base_rotation(self, qpos: np.ndarray) -> np.ndarray:
        """The free base's rotation matrix (3, 3), in a buffer reused by the next call."""
        self._mj.mju_quat2Mat(self._rotation, qpos[self._quaternion])
        return self._rotation.reshape(3, 3)

    def to_mujoco(self, q, v) -> tuple[np.ndarray, np.ndarray]:
        """MuJoCo ``(qpos, qvel)`` of Pinocchio ``(q, v)``.

        Parameters
        ----------
        q : array_like, shape (nq,)
        v : array_like, shape (nv,)
        """
        q = _vector("q", q, self.model.nq)
        v = _vector("v", v, self.model.nv)
        qpos, qvel = self.mj_model.qpos0.copy(), np.zeros(self.mj_model.nv)  # free bodies: start
        if self._base == "free":
            norm = np.linalg.norm(q[3:7])
            if not norm > 1e-9:
                raise InvalidInputError(
                    f"q[3:7] is the base quaternion (x, y, z, w) and must be non-zero, got {q[3:7]}"
                )
            q = q.copy()
            q[3:7] /= norm
            v = v.copy()
            v[:3] = pin.Quaternion(q[3:7]).toRotationMatrix() @ v[:3]  # local -> world
        qpos[self._qpos_index] = q
        qvel[self._dof_index] = v
        return qpos, qvel

    def from_mujoco(self, qpos, qvel) -> tuple[np.ndarray, np.ndarray]:
        """Pinocchio ``(q, v)`` of MuJoCo ``(qpos, qvel)`` (new arrays)."""
        qpos = np.ascontiguousarray(qpos, dtype=float)
        qvel = np.ascontiguousarray(qvel, dtype=float)
        return pinocchio_state(
            qpos, qvel, self._qpos_index, self._dof_index, self._quaternion_start, np.inf, _NONE
        )[:2]

    def _base_force(self, force) -> np.ndarray:
        """MuJoCo's generalised force on the base dofs of Pinocchio's ``force``
        (n_base_dofs,), power-preserving: a free base's linear part rotated to the world frame
        (a contiguous float array; non-finite entries are left to the caller)."""
        if not (
            type(force) is np.ndarray
            and force.dtype is _FLOAT
            and force.shape == self._base_shape
            and force.strides == _ONE_FLOAT
        ):
            force = np.ascontiguousarray(_vector("base_force", force, self.n_base_dofs))
        if self._quaternion is not None:
            force = force.copy()
            force[:3] = self._base_rotation(self.mj_data.qpos) @ force[:3]
        return force

    # ------------------------------------------------------------------ state
    def reset(self, q, v=None, t: float = 0.0) -> SimState:
        """Set the configuration ``q`` (nq,), velocity ``v`` (nv,) and time; clear contacts."""
        mujoco, data = self._mj, self.mj_data
        v = np.zeros(self.model.nv) if v is None else v
        qpos, qvel = self.to_mujoco(q, v)
        t = _positive("t", t, allow_zero=True)
        mujoco.mj_resetData(self.mj_model, data)
        data.qpos[:], data.qvel[:], data.time = qpos, qvel, t
        mujoco.mj_forward(self.mj_model, data)
        quaternion_start = self._quaternion_start
        to_pinocchio(
            data.qpos, data.qvel, self._qpos_index, self._dof_index, quaternion_start, self._q,
            self._v,
        )  # fmt: skip
        self._pushes: list[_Push] = []
        self.touchdown_events: list[TouchdownEvent] = []
        self._last_touchdowns: tuple = ()
        self.fall: Fall | None = None
        self.plant.reset()
        self.plant.draw()
        self._read_contacts()
        self._contact_time[0] = t if self._in_contact.any() else math.nan  # NaN: none yet
        return self.state

    def snapshot(self) -> MujocoSnapshot:
        """What the next steps depend on, to continue from here later with :meth:`restore`
        (e.g. several continuations of one approach phase, each as a run from the start
        would give it, bit for bit): MuJoCo's data, the last step's read-out, the plant's
        delay line and noise, the pushes, touchdowns and fall. The model (``mj_model``:
        masses, gravity) is not part of it: changes to it stay."""
        data = self._mj.MjData(self.mj_model)
        self._mj.mj_copyData(data, self.mj_model, self.mj_data)
        return MujocoSnapshot(
            data=data,
            arrays=tuple(array.copy() for array in self._buffers()),
            pushes=tuple(self._pushes),
            touchdown_events=tuple(self.touchdown_events),
            last_touchdowns=self._last_touchdowns,
            fall=self.fall,
            rng_state=self.plant._rng.bit_generator.state,
        )

    def restore(self, snapshot: MujocoSnapshot) -> SimState:
        """Set the simulation back to a :meth:`snapshot` of this simulator; returns its state.

        The buffers stay in place (the compiled step holds their addresses): their contents
        are copied back."""
        if not isinstance(snapshot, MujocoSnapshot) or snapshot.data.qpos.size != self.mj_model.nq:
            raise InvalidInputError(
                f"restore takes a snapshot() of this simulator, got {type(snapshot).__name__}"
            )
        self._mj.mj_copyData(self.mj_data, self.mj_model, snapshot.data)
        for array, saved in zip(self._buffers(), snapshot.arrays):
            array[...] = saved
        self._pushes = list(snapshot.pushes)
        self.touchdown_events = list(snapshot.touchdown_events)
        self._last_touchdowns, self.fall = snapshot.last_touchdowns, snapshot.fall
        self.plant._rng.bit_generator.state = snapshot.rng_state
        return self.state

    def _buffers(self) -> tuple:
        """The arrays a step updates in place besides MuJoCo's data (:meth:`snapshot`)."""
        plant = self.plant
        return (
            self._work, self._flags, self._contact_time, plant.line, plant.ring, plant._applied,
            plant.noise, plant.normals, plant.next_row,
        )  # fmt: skip

    @property
    def t(self) -> float:
        """Simulation time [s]."""
        return float(self.mj_data.time)

    @property
    def q(self) -> np.ndarray:
        """Configuration in Pinocchio coordinates, shape (nq,)."""
        return self.from_mujoco(self.mj_data.qpos, self.mj_data.qvel)[0]

    @property
    def v(self) -> np.ndarray:
        """Velocity in Pinocchio coordinates, shape (nv,)."""
        return self.from_mujoco(self.mj_data.qpos, self.mj_data.qvel)[1]

    def _q_v(self) -> tuple[np.ndarray, np.ndarray]:
        """Pinocchio's (q, v) of the state after the last step or reset (copies)."""
        return self._q.copy(), self._v.copy()

    # ------------------------------------------------------------------ pushes
    def _apply_pushes(self) -> None:
        """Add the active pushes to ``qfrc_applied``; needs the current kinematics."""
        self._pushes = [p for p in self._pushes if p.end_time > self.t]
        data = self.mj_data
        for p in self._pushes:
            point = data.xpos[p.anchor] + data.xmat[p.anchor].reshape(3, 3) @ p.point
            self._mj.mj_applyFT(
                self.mj_model, data, p.force, np.zeros(3), point, p.anchor, data.qfrc_applied
            )

    # ------------------------------------------------------------------ dynamics
    def step(self, torques, base_force=None) -> SimState:
        """Advance one time step under actuated joint torques ``torques``.

        Parameters
        ----------
        torques : array_like, shape (n_actuated,)
            Torques/forces of the actuated joints, in the order of ``v[n_base_dofs:]``.
        base_force : array_like, shape (n_base_dofs,), optional
            Generalised force on the base coordinates (Pinocchio's, e.g. a boom).

        Returns
        -------
        SimState
            With ``fall`` set if the robot fell during this step; the simulation stops there.
            Its arrays are not changed by later steps while anyone holds the state or one of
            them (module docstring, Returned states).

        Raises
        ------
        InvalidInputError
            For non-finite torques, and when called after a fall (``reset`` first).
        SimulationDiverged
            When MuJoCo reports an unstable acceleration or the state exceeds ``max_speed``.
        """
        if self.fall is not None:
            raise InvalidInputError(
                f"step() after the robot fell at t = {self.fall.time:.3f} s ({self.fall.reason});"
                " the simulation stopped there: check state.fall after each step, or reset()"
            )
        tau = torques
        # a float vector goes as it is: the compiled step checks its length and entries
        if not (type(tau) is _ARRAY and tau.dtype is _FLOAT and tau.ndim == 1):
            tau = _actuated(torques, self.n_actuated, self.n_base_dofs, self.model.nv)
        force = base_force
        if force is None:
            force = _NO_FORCE
        elif not (  # a planar or fixed base takes the force as it is, as the torques
            self._quaternion is None
            and type(force) is _ARRAY
            and force.dtype is _FLOAT
            and force.ndim == 1
        ):
            force = self._base_force(force)
        if self.fall_detector is not self._packed_detector:
            self._pack_fall_checks()
        slot = self._turn
        self._turn = slot ^ 1  # STATE_SLOTS = 2
        if self._advance is not None and not self._pushes:
            status, time, events = self._advance(tau, force, self._table_address, slot)
        else:
            status, time, events = self._step_bindings(tau, force, slot)
        if status != STATE_OK:
            self._raise_for(status, tau, base_force)
        self._last_touchdowns = ()
        if events or not self._screened:
            self._after_step(events, slot)
        state = self._slots[slot][0]  # its arrays hold this step's state
        fields = state.__dict__  # a frozen dataclass: its fields set in its dict
        fields["t"], fields["touchdowns"], fields["fall"] = time, self._last_touchdowns, self.fall
        return state

    def _step_bindings(self, tau, force, slot: int) -> tuple:
        """:func:`dmpopt.sim.kernels_mujoco.advance` through the Python bindings: the step's
        torques, ``mj_step`` (``mj_step1``, the pushes, ``mj_step2`` while a push acts),
        :func:`dmpopt.sim.kernels.settle` and the copy into state slot ``slot``, the same
        numbers and results."""
        plant, data = self.plant, self.mj_data
        if tau.size != self.n_actuated or force.size not in (0, self.n_base_dofs):
            return STATE_BAD_INPUT, 0.0, 0
        if not apply_torques(
            np.ascontiguousarray(tau), np.ascontiguousarray(force), plant.torque_limit,
            plant.line, plant.ring, self._qfrc_applied, self._dof_index, self.n_base_dofs,
        ):  # fmt: skip
            return STATE_BAD_INPUT, 0.0, 0
        if self._pushes:
            self._mj.mj_step1(self.mj_model, data)  # kinematics and collisions at the start
            self._apply_pushes()
            self._mj.mj_step2(self.mj_model, data)
        else:
            self._mj.mj_step(self.mj_model, data)
        contact = data.contact  # contacts found and solved at the start of the step
        time = data.time
        status, any_contact, n_started, check_fall = settle(
            self._qpos, self._qvel, self._warnings, contact.geom, contact.efc_address,
            contact.frame, contact.pos, data.efc_force, self._site_xpos, self._tables,
            self._constants, self._work, self._flags, plant.noise, time,
            self._contact_time[0],
        )  # fmt: skip
        if status != STATE_OK:
            return status, time, 0
        if any_contact:
            self._contact_time[0] = time  # end of a step with contact
        events = (
            (kernels_mujoco.TOUCHDOWN if n_started else 0)
            | (kernels_mujoco.CHECK_FALL if check_fall else 0)
            | (kernels_mujoco.DRAW if self._noisy else 0)
        )
        if not publish(self._advance_arrays, slot):
            events |= kernels_mujoco.SLOT_HELD
        return status, time, events

    def _after_step(self, events: int, slot: int) -> None:
        """What a step's ``events`` (:func:`dmpopt.sim.kernels_mujoco.advance`) ask for, in
        order: new objects for state slot ``slot`` when someone holds a part of it, record
        touchdowns, draw the next tick's normals, check for a fall; and leave the compiled
        step when MuJoCo's memory fills (a MuJoCo error there would end the process)."""
        if events & kernels_mujoco.SLOT_HELD:
            self._fresh_slot(slot)
            kernels_mujoco.fill(self._advance_arrays, slot)
        if events & kernels_mujoco.MEMORY_FULL:
            self._leave_native("MuJoCo's stack and arena use passed half its arena")
        if events & kernels_mujoco.TOUCHDOWN:
            self._record_touchdowns()
        if events & kernels_mujoco.DRAW:
            self.plant.draw_next()
        if events & kernels_mujoco.CHECK_FALL or not self._screened:
            self._check_fall()

    def _raise_for(self, status: int, tau, base_force) -> None:
        """Raise for a step that did not end in ``STATE_OK``."""
        if status == STATE_BAD_INPUT:  # a non-finite torque or base force: nothing done
            _actuated(tau, self.n_actuated, self.n_base_dofs, self.model.nv)  # raises
            _vector("base_force", base_force, self.n_base_dofs)  # raises
            raise InvalidInputError(f"base_force {base_force} turned to the world overflows")
        if status == STATE_UNSTABLE:  # MuJoCo reset the data: never go on silently
            self._raise_unstable()
        self._raise_too_fast()

    def _record_touchdowns(self) -> None:
        self._last_touchdowns = tuple(
            TouchdownEvent(self.t, int(i), self.contact_frames[i], self._positions[i].copy())
            for i in np.flatnonzero(self._started)
        )
        self.touchdown_events.extend(self._last_touchdowns)

    def _read_contacts(self) -> None:
        """Forces, positions and contact flags of the contact points (start of the last step):
        each MuJoCo contact of a foot geom goes to the nearest of that geom's contact points (a
        sphere's own point, a sole's corners), its force rotated from the contact frame to the
        world (:func:`dmpopt.sim.kernels.read_contacts`; ``step`` reads them in
        :func:`dmpopt.sim.kernels.settle`)."""
        data = self.mj_data
        self._positions[:] = data.site_xpos[self._point_sites]
        contacts = data.contact
        read_contacts(
            contacts.geom,
            contacts.efc_address,
            contacts.frame,
            contacts.pos,
            data.efc_force,
            self._foot_code,
            self._foot_points,
            self._positions,
            self._forces,
            self._in_contact,
        )

    def _raise_unstable(self) -> None:
        numbers = self.mj_data.warning.number[_UNSTABLE]
        kind = self._mj.mjtWarning(_UNSTABLE.start + int(np.argmax(numbers > 0)))
        raise SimulationDiverged(
            f"MuJoCo reported {kind.name} at t = {self.t:.4f} s (it resets the state); "
            "reduce dt or check the torques"
        )

    def _raise_too_fast(self) -> None:
        fastest = np.abs(self.mj_data.qvel).max(initial=0.0)
        raise SimulationDiverged(
            f"|v| reached {fastest:.3g} > max_speed = {self.max_speed:.3g} at "
            f"t = {self.t:.4f} s; reduce dt or check the torques"
        )

    # ------------------------------------------------------------------ falls
    def _check_fall(self) -> None:
        """Measure the base (:mod:`dmpopt.sim.falls`) and record the first fall."""
        height, tilt, spin = self._watched.height_tilt_spin(self._q, self._v)
        last = float(self._contact_time[0])
        t = self.mj_data.time
        self.fall = self.fall_detector.check(
            t, height, tilt, 0.0 if math.isnan(last) else t - last, spin
        )


def _flat(placement: pin.SE3) -> np.ndarray:
    """A placement as 12 numbers: its rotation row by row, then its translation."""
    return np.r_[placement.rotation.ravel(), placement.translation]


def _actuated(tau, n_actuated: int, n_base: int, nv: int) -> np.ndarray:
    if (
        type(tau) is np.ndarray
        and tau.dtype == np.float64
        and tau.shape == (n_actuated,)
        and tau.flags.c_contiguous
        and math.isfinite(tau.sum())  # a NaN or inf entry makes the sum NaN or inf
    ):
        return tau  # the common case, checked in a few operations
    try:
        array = np.ascontiguousarray(np.asarray(tau, dtype=float).reshape(-1))
    except (TypeError, ValueError):
        raise InvalidInputError(f"torques must be numbers, got {tau!r}") from None
    if array.shape != (n_actuated,):
        raise ShapeError(
            f"torques has shape {np.shape(tau)}, expected ({n_actuated},): one torque per actuated "
            f"joint (model.nv = {nv} minus {n_base} base dofs)"
        )
    if not np.isfinite(array).all():
        raise InvalidInputError(
            f"torques must be finite; entries {np.flatnonzero(~np.isfinite(array)).tolist()} "
            "are not"
        )
    return array


# ---------------------------------------------------------------------------------- rendering
def render_animation(
    simulator: MujocoSimulator,
    configurations,
    path,
    fps: float = 25.0,
    width: int = 480,
    height: int = 360,
    distance: float = 3.0,
    max_bytes: int = 5_000_000,
    target=None,
    azimuth: float = 135.0,
    elevation: float = -15.0,
    free_body_qpos=None,
    shadows: bool = True,
) -> Path:
    """Render configurations offscreen and write an animated WebP or GIF.

    The camera looks at ``target`` (default: the root body) from ``distance`` at ``azimuth``
    and ``elevation``, following the target frame by frame. If the file is larger than
    ``max_bytes``, every other frame is dropped (each shown twice as long) until it fits.

    Parameters
    ----------
    simulator : MujocoSimulator
        Provides the model; its simulation state is not changed.
    configurations : array_like, shape (n_frames, nq)
        Pinocchio configurations, e.g. ``state.q`` every ``1 / (fps dt)`` steps.
    path : str or Path
        Output file, ``.webp`` or ``.gif``.
    fps : float
        Frames per second of the animation.
    width, height : int
        Image size [pixels].
    distance : float
        Camera distance to the target [m].
    max_bytes : int
        Size bound of the file.
    target : str or array_like, shape (3,), optional
        A frame of the Pinocchio model (a link, a hand, a sole) the camera follows, or a fixed
        world point [m]. Default: the root body.
    azimuth, elevation : float
        Camera direction [deg]: azimuth about the vertical (MuJoCo's convention, 90 looks
        along +y), elevation below the horizon negative.
    free_body_qpos : array_like, shape (n_frames, 7 * n_free_bodies), optional
        Poses of the simulator's free bodies per frame (its :attr:`MujocoSimulator.free_body_qpos`
        at each frame); default their start poses.
    shadows : bool
        Cast shadows (they show where a foot meets the ground), from a shadow map sized to
        the frame (:func:`shadow_map_size`). Without them a frame renders about twice as fast
        on a software OpenGL (Talos at 320 x 240 with EGL on the CPU: 80-100 against 41-44 ms
        of CPU per frame; 160-190 with MuJoCo's default map).

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    MissingDependency
        Without an OpenGL context (the message says why: set ``MUJOCO_GL`` to ``egl`` or
        ``osmesa``) or without Pillow.
    ResourceLimitError
        If even a single frame exceeds ``max_bytes``.
    """
    configurations = _check_render(simulator, configurations, width, height)
    if free_body_qpos is not None:
        free_body_qpos = real_array(
            "free_body_qpos",
            free_body_qpos,
            shape=(len(configurations), simulator._free_qpos.size),
            expected="one row of free-body poses per configuration",
        )
    path = _output_path(path, (".webp", ".gif"))
    fps = _positive("fps", fps)
    _check_shadows(shadows)
    camera = _camera(simulator, target, distance, azimuth, elevation)
    max_bytes = _positive("max_bytes", max_bytes)
    image_class = _pillow()
    frames = [
        image_class.fromarray(f)
        for f in _render_frames(
            simulator, configurations, width, height, camera, free_body_qpos, shadows
        )
    ]
    duration = 1000.0 / fps  # [ms] per frame
    while True:
        frames[0].save(
            path, save_all=True, append_images=frames[1:], duration=round(duration), loop=0
        )
        size = path.stat().st_size
        if size <= max_bytes:
            return path
        if len(frames) == 1:
            raise ResourceLimitError(
                f"one frame of {width}x{height} already takes {size} bytes > max_bytes = "
                f"{max_bytes}; reduce width and height"
            )
        frames, duration = frames[::2], 2 * duration


def render_frame(
    simulator: MujocoSimulator,
    q,
    path,
    width: int = 640,
    height: int = 480,
    target=None,
    distance: float = 3.0,
    azimuth: float = 135.0,
    elevation: float = -15.0,
    shadows: bool = True,
) -> Path:
    """Render one configuration offscreen and write it as a PNG still.

    Parameters
    ----------
    simulator : MujocoSimulator
        Provides the model; its simulation state is not changed.
    q : array_like, shape (nq,)
        A Pinocchio configuration.
    path : str or Path
        Output file, ``.png``.
    width, height : int
        Image size [pixels].
    target, distance, azimuth, elevation
        The camera, as in :func:`render_animation`.
    shadows : bool
        Cast shadows, as in :func:`render_animation`.

    Returns
    -------
    Path
        The file written.
    """
    configurations = _check_render(simulator, [q], width, height, name="q")
    path = _output_path(path, (".png",))
    _check_shadows(shadows)
    camera = _camera(simulator, target, distance, azimuth, elevation)
    image_class = _pillow()
    (image,) = _render_frames(simulator, configurations, width, height, camera, None, shadows)
    image_class.fromarray(image).save(path)
    return path


def _check_shadows(shadows) -> None:
    if not isinstance(shadows, (bool, np.bool_)):
        raise InvalidInputError(f"shadows must be True or False, got {shadows!r}")


def _check_render(simulator, configurations, width, height, name="configurations"):
    if not isinstance(simulator, MujocoSimulator):
        raise InvalidInputError(
            f"simulator must be a MujocoSimulator, got {type(simulator).__name__}"
        )
    configurations = np.array(configurations, dtype=float, ndmin=2)
    nq = simulator.model.nq
    if configurations.ndim != 2 or configurations.shape[1] != nq or not len(configurations):
        shape = configurations.shape if name == "configurations" else configurations.shape[1:]
        expected = f"(n_frames, {nq})" if name == "configurations" else f"({nq},)"
        raise ShapeError(f"{name} has shape {shape}, expected {expected}")
    if not np.isfinite(configurations).all():
        rows = np.flatnonzero(~np.isfinite(configurations).all(axis=1)).tolist()
        raise InvalidInputError(f"{name} must be finite; rows {rows} are not")
    for label, value in (("width", width), ("height", height)):
        if not (isinstance(value, (int, np.integer)) and 16 <= value <= 4096):
            raise InvalidInputError(
                f"{label} must be an integer in [16, 4096] pixels, got {value!r}"
            )
    return configurations


def _output_path(path, suffixes) -> Path:
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise InvalidInputError(f"path {str(path)!r} must end in {' or '.join(suffixes)}")
    if not path.parent.is_dir():
        raise InvalidInputError(
            f"path {str(path)!r}: directory {str(path.parent)!r} does not exist"
        )
    return path


def _pillow():
    try:
        from PIL import Image
    except ImportError:
        raise MissingDependency(
            "writing images needs Pillow; install it with `pip install 'dmpopt[plot]'`"
        ) from None
    return Image


def _camera(simulator, target, distance, azimuth, elevation) -> dict:
    """Checked camera options: target (None, a frame id or a world point) and angles."""
    model = simulator.model
    if target is None or isinstance(target, str):
        if target is not None and not model.existFrame(target):
            raise InvalidInputError(
                f"target={target!r} is not a frame of the model; pass a link or frame name "
                "(e.g. a hand frame), a world point (x, y, z), or None for the root body"
            )
        target = None if target is None else model.getFrameId(target)
    else:
        target = real_array("target", target, shape=(3,), expected="a world point [m]")
    return {
        "target": target,
        "distance": _positive("distance", distance),
        "azimuth": real("azimuth", azimuth, expected="an angle [deg]"),
        "elevation": real("elevation", elevation, expected="an angle [deg]"),
    }


def shadow_map_size(width: int, height: int) -> int:
    """Side [texels] of the shadow map for frames of ``width`` x ``height`` pixels: twice the
    longer side, rounded up to a power of two (1024 for 320 x 240 or 480 x 360).

    MuJoCo's default map (4096) costs most of a frame on a software OpenGL (Talos at 320 x
    240 with EGL on the CPU: 160-190 ms a frame against 80-100 with 1024 and 41-44 without
    shadows), and its shadows look the same at these sizes."""
    return 1 << max(0, math.ceil(math.log2(2 * max(width, height))))


def _render_frames(
    simulator, configurations, width, height, camera, free_body_qpos=None, shadows=True
) -> list[np.ndarray]:
    """RGB images, shape (height, width, 3) each, of Pinocchio configurations."""
    mujoco = simulator._mj
    model = simulator.mj_model
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    quality = model.vis.quality
    shadow_size = quality.shadowsize  # the context's shadow map is made with it
    quality.shadowsize = min(shadow_size, shadow_map_size(width, height))
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as error:  # noqa: BLE001 - each GL back end fails in its own way
        raise MissingDependency(
            f"no OpenGL context for offscreen rendering (MUJOCO_GL="
            f"{os.environ.get('MUJOCO_GL', '')!r}): {error}; set MUJOCO_GL=egl (GPU) or "
            "MUJOCO_GL=osmesa (software) before importing mujoco"
        ) from None
    finally:
        quality.shadowsize = shadow_size
    data = mujoco.MjData(model)
    view = mujoco.MjvCamera()
    view.distance, view.azimuth, view.elevation = (
        camera["distance"], camera["azimuth"], camera["elevation"]
    )  # fmt: skip
    target = camera["target"]
    frames = simulator.model.createData() if isinstance(target, (int, np.integer)) else None
    images = []
    with renderer:
        for k, q in enumerate(configurations):
            data.qpos[:] = simulator.to_mujoco(q, np.zeros(simulator.model.nv))[0]
            if free_body_qpos is not None:
                data.qpos[simulator._free_qpos] = free_body_qpos[k]
            mujoco.mj_forward(model, data)
            if target is None:
                view.lookat[:] = data.xpos[1]  # the URDF root link
            elif frames is not None:
                pin.framesForwardKinematics(simulator.model, frames, q)
                view.lookat[:] = frames.oMf[target].translation
            else:
                view.lookat[:] = target
            renderer.update_scene(data, view)
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
            images.append(renderer.render().copy())
    return images
