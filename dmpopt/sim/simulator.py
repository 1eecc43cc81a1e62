r"""Deterministic rigid-body simulation with Pinocchio forward dynamics and compliant contact.

One step (semi-implicit Euler on the configuration manifold):

.. math::

    \dot v = \mathrm{ABA}(q, v, \tau + \textstyle\sum_i J_i^\top f_i), \qquad
    v \leftarrow v + \Delta t\, \dot v, \qquad q \leftarrow q \oplus \Delta t\, v,

where :math:`f_i` are the ground forces of :mod:`dmpopt.sim.contact` and any
pushes, applied as generalised forces :math:`J^\top f` through the world-aligned point
Jacobians, and :math:`\oplus` is ``pinocchio.integrate``. Per step the simulator makes one
``computeJointJacobians`` call and one ``aba`` call; contact forces are computed for all points
at once with NumPy.

After each step a floating-base robot is checked for a fall (:mod:`dmpopt.sim.falls`): the
first fall stops the simulation, ``state.fall`` says when and why, and :meth:`Simulator.step`
refuses to go on until :meth:`Simulator.reset`. A state that is non-finite or faster than
``max_speed`` raises :class:`~dmpopt.exceptions.SimulationDiverged` naming the coordinate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError, SimulationDiverged
from dmpopt.sim.contact import GroundContact, ground_forces
from dmpopt.sim.falls import (
    Fall,
    FallDetector,
    base_tilt,
    fall_checks,
    refuse_floating_without_contacts,
)
from dmpopt.sim.plant import IDEAL, PlantParameters, PlantRuntime, base_joint_kind
from dmpopt.validation import real, real_array, unit_rotation_blocks

__all__ = ["Backend", "SimState", "Simulator", "TouchdownEvent"]

_BASE_DOFS = {"JointModelFreeFlyer": 6, "JointModelPlanar": 3}
UNIT_NORM_TOLERANCE = 1e-3  # quaternions this close to unit norm are renormalised at reset


@dataclass(frozen=True)
class TouchdownEvent:
    """A contact point touched the ground.

    Attributes
    ----------
    time : float
        Simulation time at the end of the step in which contact began [s].
    point : int
        Index of the point in ``contact_points``.
    frame : str
        Frame the point is attached to.
    position : ndarray, shape (3,)
        World position of the point at touchdown [m].
    """

    time: float
    point: int
    frame: str
    position: np.ndarray


@dataclass(frozen=True, eq=False)
class SimState:
    """Snapshot of the simulation after a step.

    Attributes
    ----------
    t : float
        Time [s].
    q : ndarray, shape (nq,)
    v : ndarray, shape (nv,)
    contact_forces : ndarray, shape (n_points, 3)
        Ground force on each contact point, world frame [N] (computed at the start of the step).
    in_contact : ndarray of bool, shape (n_points,)
    contact_positions : ndarray, shape (n_points, 3)
        World positions of the contact points at the start of the step [m].
    touchdowns : tuple of TouchdownEvent
        Touchdowns that happened during this step.
    fall : Fall or None
        The fall that ended the simulation (time, cause, reason), None while standing.
    q_measured, v_measured : ndarray, shape (nq,) and (nv,)
        What the robot's sensors read: ``q`` and ``v`` plus the plant's measurement noise
        (:class:`dmpopt.sim.SensorNoise`); equal to ``q`` and ``v`` without noise. Feed these
        to a controller, measure with ``q`` and ``v``.
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    contact_forces: np.ndarray
    in_contact: np.ndarray
    contact_positions: np.ndarray
    touchdowns: tuple
    fall: Fall | None
    q_measured: np.ndarray | None = None
    v_measured: np.ndarray | None = None

    def __post_init__(self):
        if self.q_measured is None:
            object.__setattr__(self, "q_measured", self.q)
        if self.v_measured is None:
            object.__setattr__(self, "v_measured", self.v)

    @property
    def fallen(self) -> bool:
        """True once the robot has fallen (``fall is not None``)."""
        return self.fall is not None


@dataclass
class _Push:
    anchor: int  # the backend's index of the body the point moves with
    point: np.ndarray  # in that body's frame [m]
    force: np.ndarray  # world frame [N]
    end_time: float


class Backend:
    """What both simulation backends share: the state snapshot, falls and the push rules.

    A backend sets ``t``, ``dt``, ``fall``, ``_forces``, ``_in_contact``, ``_positions``,
    ``_last_touchdowns``, ``_pushes`` and ``plant`` (a :class:`PlantRuntime`: it passes each
    command through :meth:`PlantRuntime.actuate`, calls :meth:`PlantRuntime.draw` after each
    step and reset), and implements ``_q_v()`` (Pinocchio's q, v) and ``_locate(frame_name,
    offset)`` (the body a frame's point moves with, and the point in it).
    """

    @property
    def state(self) -> SimState:
        """The current :class:`SimState` (arrays are copies)."""
        q, v = self._q_v()
        q_measured, v_measured = self.plant.measure(q, v)
        return SimState(
            t=self.t,
            q=q,
            v=v,
            contact_forces=self._forces.copy(),
            in_contact=self._in_contact.copy(),
            contact_positions=self._positions.copy(),
            touchdowns=self._last_touchdowns,
            fall=self.fall,
            q_measured=q_measured,
            v_measured=v_measured,
        )

    @property
    def fallen(self) -> bool:
        """True once the robot has fallen (see :attr:`fall`)."""
        return self.fall is not None

    def push(self, frame_name: str, force, duration: float, offset=(0.0, 0.0, 0.0)) -> None:
        """Apply a constant world-frame ``force`` [N] at a point of a frame from now on.

        The push acts during the next ``round(duration / dt)`` steps; several pushes add up.

        Parameters
        ----------
        frame_name : str
            Frame of the model the point is attached to.
        force : array_like, shape (3,)
            World-frame force [N].
        duration : float
            [s], at least ``dt / 2`` (one step).
        offset : array_like, shape (3,)
            Point in the frame [m].
        """
        force = real_array("force", force, shape=(3,), expected="a world-frame force [N]")
        n_steps = self._push_steps(duration)
        anchor, point = self._locate(frame_name, offset)
        self._pushes.append(_Push(anchor, point, force, self.t + (n_steps - 0.5) * self.dt))

    def push_impulse(self, frame_name: str, impulse, duration: float = 0.05, offset=(0, 0, 0)):
        """Apply a world-frame ``impulse`` [N s], spread evenly over ``duration`` [s].

        The force is ``impulse / (n dt)`` over ``n = round(duration / dt)`` steps, so the
        impulse is exact whatever ``duration``.
        """
        impulse = real_array("impulse", impulse, shape=(3,), expected="a world-frame impulse [N s]")
        n_steps = self._push_steps(duration)
        self.push(frame_name, impulse / (n_steps * self.dt), n_steps * self.dt, offset)

    def _push_steps(self, duration) -> int:
        duration = real(
            "duration",
            duration,
            minimum=0.0,
            open_minimum=True,
            expected="a positive finite time [s]",
        )
        n_steps = round(duration / self.dt)
        if n_steps < 1:
            raise InvalidInputError(
                f"duration = {duration:.3g} s is shorter than half the time step dt = "
                f"{self.dt:.3g} s, so the push would never act; pass duration >= dt"
            )
        return n_steps


class Simulator(Backend):
    """Fixed- or floating-base robot on a compliant ground.

    Parameters
    ----------
    model : pinocchio.Model
        The robot. A free-flyer, planar or composite root joint is treated as the unactuated
        base (``n_base_dofs`` overrides the detection).
    dt : float
        Integration step [s]; 1e-3 or smaller for stiff contacts.
    contact_points : sequence of (str, array_like)
        ``(frame_name, offset_xyz)`` pairs; the offset is expressed in the frame [m].
    ground : GroundContact, optional
        Ground model; required when there are contact points.
    n_base_dofs : int, optional
        Number of unactuated base velocity coordinates (the first ones of ``v``).
    fall_frame : str, optional
        Frame of the base body whose pose the fall checks watch; default: the root joint's
        frame.
    fall_height : float, optional
        Shortcut for the ``min_height`` of the fall checks [m above the ground]; the other
        thresholds stay derived from the robot.
    max_speed : float
        Any ``|v_i|`` above this raises :class:`SimulationDiverged` [m/s or rad/s].
    falls : bool or FallDetector
        ``True`` (default): a floating-base robot with contact points gets the thresholds of
        :meth:`FallDetector.for_standing_height`, with the height of the base above the
        lowest contact point in the neutral configuration (straight legs) as standing height;
        without contact points only ``fall_height``, if given, is checked; a fixed base never
        falls. A :class:`FallDetector` sets the thresholds; ``False`` switches the checks off.
    plant : PlantParameters
        Joint armature, damping and Coulomb friction, torque saturation, delay and sensor noise
        (:mod:`dmpopt.sim.plant`); default :data:`~dmpopt.sim.IDEAL`, the model itself. Coulomb
        friction is regularised (see :meth:`_set_plant`) and damping explicit: a damping too
        stiff for ``dt`` is refused.

    Attributes
    ----------
    plant : PlantRuntime
        The plant's delay line and noise generator.
    fall_detector : FallDetector or None
        The thresholds in use (None: no fall checks).
    fall : Fall or None
        The fall that stopped the simulation, if any.
    """

    def __init__(
        self,
        model: pin.Model,
        dt: float,
        contact_points=(),
        ground: GroundContact | None = None,
        n_base_dofs: int | None = None,
        fall_frame: str | None = None,
        fall_height: float | None = None,
        max_speed: float = 1e3,
        falls: bool | FallDetector = True,
        plant: PlantParameters = IDEAL,
    ):
        if not isinstance(model, pin.Model):
            raise InvalidInputError(
                f"model must be a pinocchio.Model, got {type(model).__name__}; pass robot.model"
            )
        self.model = model
        self.dt = real(
            "dt",
            dt,
            minimum=0.0,
            open_minimum=True,
            expected="a positive finite time step [s], e.g. 1e-3",
        )
        self.max_speed = real(
            "max_speed",
            max_speed,
            minimum=0.0,
            open_minimum=True,
            expected="a positive finite bound [m/s, rad/s], e.g. 1e3",
        )
        self.n_base_dofs = self._check_base_dofs(n_base_dofs)
        self.n_actuated = model.nv - self.n_base_dofs
        self._set_plant(plant)
        self.data = self.model.createData()
        self._name_coordinates()
        contact_points = self._check_contact_points(contact_points)
        if contact_points and not isinstance(ground, GroundContact):
            raise InvalidInputError(
                f"ground must be a GroundContact when contact_points are given, got {ground!r}; "
                "pass ground=GroundContact(stiffness=..., damping=..., friction=...)"
            )
        self.ground = ground
        self.contact_frames = [name for name, _ in contact_points]
        located = [
            self._locate(name, offset, f"contact_points[{i}]", f"contact_points[{i}] offset")
            for i, (name, offset) in enumerate(contact_points)
        ]
        self._point_list = [int(j) for j, _ in located]
        self._n_points = len(located)
        self._point_placements = [pin.SE3(np.eye(3), p) for _, p in located]
        normal = (0.0, 0.0, 1.0) if ground is None else ground.normal
        self.fall_detector, self._watched = fall_checks(
            model, self.n_base_dofs, contact_points, falls, fall_frame, fall_height, normal
        )
        refuse_floating_without_contacts(
            model, self.n_base_dofs, contact_points, falls, fall_height
        )
        self._tau = np.zeros(model.nv)
        self.touchdown_events: list[TouchdownEvent] = []
        self.reset(pin.neutral(model), np.zeros(model.nv))

    # ------------------------------------------------------------------ set-up helpers
    def _set_plant(self, plant: PlantParameters) -> None:
        r"""The plant's runtime; armature into a copy of the model; friction's regularisation.

        Coulomb friction is :math:`f_c \, \mathrm{clip}(\dot q / v_s, -1, 1)` with
        :math:`v_s = \Delta t f_c / m` per joint (:math:`m` its inertia with armature in the
        neutral posture), the narrowest band explicit Euler integrates without chattering.
        """
        model = self.model
        names = [
            model.names[j]
            for j in range(1, model.njoints)
            for _ in range(model.joints[j].nv)
            if model.joints[j].idx_v >= self.n_base_dofs
        ]
        try:
            base = base_joint_kind(model) if self.n_base_dofs else None
        except InvalidInputError:  # a root the noise model does not know (e.g. planar)
            base = None
        self.plant = PlantRuntime(plant, model, base, names)
        if self.plant.armature.any():
            armature = np.zeros(model.nv)
            armature[self.n_base_dofs :] = self.plant.armature
            self.model = model = pin.Model(model)
            model.armature = armature
        inertia = np.diag(pin.crba(model, model.createData(), pin.neutral(model)))
        inertia = inertia[self.n_base_dofs :]
        stiff = self.dt * self.plant.damping / inertia
        if (stiff >= 1.0).any():
            joint = names[int(np.argmax(stiff))]
            raise InvalidInputError(
                f"damping of {joint!r} ({self.plant.damping.max():.3g} N m s/rad) is too stiff "
                f"for explicit integration at dt = {self.dt:.3g} s (dt b / m >= 1); add armature, "
                "reduce dt, or use MujocoSimulator (implicit damping)"
            )
        self._friction_band = np.maximum(self.dt * self.plant.friction / inertia, 1e-9)

    def _joint_torques(self, tau: np.ndarray) -> np.ndarray:
        """The plant's torque on the actuated joints: motors minus damping and friction."""
        applied = self.plant.actuate(tau)
        plant = self.plant
        if plant.damping.any() or plant.friction.any():
            speed = self.v[self.n_base_dofs :]
            slip = np.clip(speed / self._friction_band, -1.0, 1.0)
            applied = applied - plant.damping * speed - plant.friction * slip
        return applied

    def _check_base_dofs(self, n_base_dofs) -> int:
        if n_base_dofs is None:
            return _detect_base_dofs(self.model)
        if (
            isinstance(n_base_dofs, (bool, np.bool_))
            or not isinstance(n_base_dofs, (int, np.integer))
            or not 0 <= n_base_dofs <= self.model.nv
        ):
            raise InvalidInputError(
                f"n_base_dofs must be an integer in [0, {self.model.nv}] (model.nv), got "
                f"{n_base_dofs!r}; omit it to detect the base from the root joint"
            )
        return int(n_base_dofs)

    def _name_coordinates(self) -> None:
        """Readable names of the entries of q and v, e.g. ``root_joint[3]``, for messages."""
        model = self.model
        self._q_names, self._v_names = [], []
        for joint_id in range(1, model.njoints):
            joint, name = model.joints[joint_id], model.names[joint_id]
            for names, size in ((self._q_names, joint.nq), (self._v_names, joint.nv)):
                names.extend(
                    [f"joint {name!r}"] if size == 1 else [f"{name}[{k}]" for k in range(size)]
                )
        self._tau_names = self._v_names[self.n_base_dofs :]
        self._tau_expected = (
            f"one torque [N m] or force [N] per actuated joint (model.nv = {model.nv} minus "
            f"{self.n_base_dofs} base dofs)"
        )

    def _check_contact_points(self, contact_points) -> list:
        try:
            points = list(contact_points)
        except TypeError:
            raise InvalidInputError(
                f"contact_points must be a sequence of (frame_name, offset_xyz) pairs, got "
                f"{contact_points!r}"
            ) from None
        for i, point in enumerate(points):
            if not (isinstance(point, (tuple, list)) and len(point) == 2):
                raise InvalidInputError(
                    f"contact_points[{i}] must be a (frame_name, offset_xyz) pair, got {point!r}"
                )
        return points

    def _frame_id(self, name, argument: str) -> int:
        if not isinstance(name, str) or not self.model.existFrame(name):
            raise InvalidInputError(
                f"{argument}: frame {name!r} is not in the model {self.model.name!r}; pass one of "
                f"the names in [f.name for f in model.frames]"
            )
        return self.model.getFrameId(name)

    def _locate(self, frame_name, offset, frame_argument="frame_name", offset_argument="offset"):
        """Parent joint of a frame and the point's position in that joint's frame."""
        offset = real_array(
            offset_argument, offset, shape=(3,), expected="x, y, z in the frame [m]"
        )
        frame = self.model.frames[self._frame_id(frame_name, frame_argument)]
        return frame.parentJoint, frame.placement.act(offset)

    # ------------------------------------------------------------------ state
    def reset(self, q, v=None, t: float = 0.0) -> SimState:
        """Set the configuration, velocity and time; clear contacts, pushes and any fall.

        Parameters
        ----------
        q : array_like, shape (nq,)
            Configuration. Quaternions (free-flyer, spherical joints, order x, y, z, w) and
            unit complex numbers must have unit norm; a norm within ``1e-3`` of 1 is
            renormalised, anything else is refused.
        v : array_like, shape (nv,), optional
            Velocity; zero by default.
        t : float
            Time [s].
        """
        q = self._check_configuration(q)
        v = np.zeros(self.model.nv) if v is None else v
        v = real_array(
            "v",
            v,
            shape=(self.model.nv,),
            expected="velocity: base twist then joint speeds",
            labels=self._v_names,
        )
        t = real("t", t, expected="a finite time [s]")
        self.q, self.v, self.t = q, v, t
        n_points = self._n_points
        self._anchors = np.zeros((n_points, 2))
        self._in_contact = np.zeros(n_points, dtype=bool)
        self._forces = np.zeros((n_points, 3))
        self._positions = np.zeros((n_points, 3))
        self._pushes: list[_Push] = []
        self.touchdown_events = []
        self._last_touchdowns: tuple = ()
        self.fall: Fall | None = None
        self._last_contact_time: float | None = None
        self.plant.reset()
        self.plant.draw()
        if n_points:
            pin.computeJointJacobians(self.model, self.data, self.q)
            self._positions, _ = self._point_jacobians(self._point_list, self._point_placements)
            self._in_contact = self.ground.penetration(self._positions) > 0
            self._anchors = (self._positions @ self.ground.frame.T)[:, :2]
            if self._in_contact.any():
                self._last_contact_time = t
        return self.state

    def _check_configuration(self, q) -> np.ndarray:
        """``q`` as a finite array with unit quaternions (renormalised within tolerance)."""
        model = self.model
        q = real_array(
            "q",
            q,
            shape=(model.nq,),
            expected="configuration: base pose then joint positions",
            labels=self._q_names,
        )
        for block in unit_rotation_blocks(model, q, UNIT_NORM_TOLERANCE):
            q[block] /= np.linalg.norm(q[block])
        if not pin.isNormalized(model, q, UNIT_NORM_TOLERANCE):
            raise InvalidInputError(
                "q has a non-unit quaternion or complex number inside a composite joint; pass a "
                "normalised configuration (pinocchio.normalize(model, q))"
            )
        return q

    def _q_v(self) -> tuple[np.ndarray, np.ndarray]:
        return self.q.copy(), self.v.copy()

    # ------------------------------------------------------------------ dynamics
    def _point_jacobians(self, joints, placements) -> tuple[np.ndarray, np.ndarray]:
        """World positions (n, 3) and world-aligned linear Jacobians (n, 3, nv) of points.

        ``placements`` are ``pin.SE3`` of the points in their joints' frames; needs
        ``computeJointJacobians`` on the current ``q``.
        """
        model, data = self.model, self.data
        positions = np.empty((len(joints), 3))
        jacobians = np.empty((len(joints), 3, model.nv))
        for i, (joint, placement) in enumerate(zip(joints, placements)):
            positions[i] = data.oMi[joint].act(placement.translation)
            jacobians[i] = pin.getFrameJacobian(
                model, data, joint, placement, pin.LOCAL_WORLD_ALIGNED
            )[:3]
        return positions, jacobians

    def step(self, torques, base_force=None) -> SimState:
        r"""Advance one time step under actuated joint torques ``torques``.

        Ground and push forces enter as generalised forces :math:`J^\top f` of the point
        Jacobians, so a step is one ``computeJointJacobians`` and one ``aba`` call plus a
        few vectorised NumPy operations.

        Parameters
        ----------
        torques : array_like, shape (n_actuated,)
            Torques/forces of the actuated joints (``model.nv - n_base_dofs``).
        base_force : array_like, shape (n_base_dofs,), optional
            Generalised force on the base coordinates, e.g. a boom or harness.

        Returns
        -------
        SimState
            With ``fall`` set if the robot fell during this step; the simulation stops there.

        Raises
        ------
        InvalidInputError
            For non-finite torques, and when called after a fall (``reset`` first).
        SimulationDiverged
            When the state would become non-finite or exceed ``max_speed``; the simulator
            keeps the last finite state.
        """
        if self.fall is not None:
            raise InvalidInputError(
                f"step() after the robot fell at t = {self.fall.time:.3f} s ({self.fall.reason});"
                " the simulation stopped there: check state.fall after each step, or reset()"
            )
        tau_full = self._tau
        self._set_forces(tau_full, torques, base_force)
        tau_full[self.n_base_dofs :] = self._joint_torques(tau_full[self.n_base_dofs :])
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, self.q)
        generalized = tau_full
        touchdowns = ()
        if self._n_points:
            positions, jacobians = self._point_jacobians(self._point_list, self._point_placements)
            velocities = jacobians @ self.v
            forces, self._anchors, touching = ground_forces(
                self.ground, positions, velocities, self._anchors, self._in_contact
            )
            started = np.flatnonzero(touching & ~self._in_contact)
            self._in_contact, self._forces, self._positions = touching, forces, positions
            if touching.any():
                generalized = tau_full + np.einsum("pkn,pk->n", jacobians, forces)
                self._last_contact_time = self.t + self.dt  # end of a step with contact
            if started.size:
                touchdowns = tuple(
                    TouchdownEvent(self.t + self.dt, int(i), self.contact_frames[i], positions[i])
                    for i in started
                )
        if self._pushes:
            generalized = generalized + self._push_forces()
        acceleration = pin.aba(model, data, self.q, self.v, generalized)
        v = self.v + self.dt * acceleration
        q = pin.integrate(model, self.q, self.dt * v)
        self._check_finite(v, self.t + self.dt)
        self.q, self.v, self.t = q, v, self.t + self.dt
        self._last_touchdowns = touchdowns
        if touchdowns:
            self.touchdown_events.extend(touchdowns)
        self.plant.draw()
        if self.fall_detector is not None:
            self._check_fall()
        return self.state

    def _set_forces(self, tau_full: np.ndarray, tau, base_force) -> None:
        """Copy ``base_force`` and ``tau`` into ``tau_full``; errors name the bad entry."""
        n_base = self.n_base_dofs
        try:
            valid = np.shape(tau) == (self.n_actuated,) and (
                base_force is None or np.shape(base_force) == (n_base,)
            )
            if valid:
                tau_full[n_base:] = tau
                tau_full[:n_base] = 0.0 if base_force is None else base_force
        except (TypeError, ValueError):  # entries that are not numbers
            valid = False
        if valid and np.isfinite(tau_full).all():
            return
        real_array(
            "torques",
            tau,
            shape=(self.n_actuated,),
            expected=self._tau_expected,
            labels=self._tau_names,
        )
        real_array(
            "base_force",
            base_force,
            shape=(n_base,),
            expected="generalised force on the base dofs",
        )

    def _push_forces(self) -> np.ndarray:
        """Generalised force of the active pushes; drops the finished ones."""
        self._pushes = [p for p in self._pushes if p.end_time > self.t]
        if not self._pushes:
            return np.zeros(self.model.nv)
        joints = [p.anchor for p in self._pushes]
        points = [pin.SE3(np.eye(3), p.point) for p in self._pushes]
        _, jacobians = self._point_jacobians(joints, points)
        forces = np.array([p.force for p in self._pushes])
        return np.einsum("pkn,pk->n", jacobians, forces)

    def _check_finite(self, v: np.ndarray, t: float) -> None:
        """Raise SimulationDiverged naming the first non-finite or too fast speed.

        ``q`` needs no check: integrating finite speeds from a finite ``q`` keeps it finite.
        """
        speeds = np.abs(v)
        if v.size == 0 or speeds.max() <= self.max_speed:  # False for NaN
            return
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise SimulationDiverged(
                f"v[{bad[0]}] ({self._v_names[bad[0]]}) became non-finite at t = {t:.4f} s; "
                "reduce dt or the contact stiffness"
            )
        fastest = int(np.argmax(speeds))
        raise SimulationDiverged(
            f"|v[{fastest}]| ({self._v_names[fastest]}) reached {speeds[fastest]:.3g} > "
            f"max_speed = {self.max_speed:.3g} at t = {t:.4f} s; reduce dt or the contact "
            "stiffness, or look for torques that spin the joint up"
        )

    def _check_fall(self) -> None:
        """Measure the base (:mod:`dmpopt.sim.falls`) and record the first fall."""
        base, spin = self._watched.measure(self.q, self.v)
        if self._n_points:
            height = float(base.translation @ self.ground.normal) - self.ground.height
        else:
            height = float(base.translation[2])
        flight_time = 0.0 if self._last_contact_time is None else self.t - self._last_contact_time
        self.fall = self.fall_detector.check(
            self.t, height, base_tilt(base.rotation), flight_time, spin
        )


def _detect_base_dofs(model: pin.Model) -> int:
    """Velocity size of an unactuated root joint (free-flyer, planar, composite), else 0."""
    if model.njoints < 2:
        return 0
    root = model.joints[1]
    name = root.shortname()
    if name in _BASE_DOFS:
        return _BASE_DOFS[name]
    if name == "JointModelComposite":
        return root.nv
    return 0
