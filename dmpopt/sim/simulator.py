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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError, ShapeError, SimulationDiverged
from dmpopt.sim.contact import GroundContact, ground_forces

__all__ = ["SimState", "Simulator", "TouchdownEvent"]

_BASE_DOFS = {"JointModelFreeFlyer": 6, "JointModelPlanar": 3}


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
    fallen : bool
        True once the fall frame has gone below the fall height (stays True).
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    contact_forces: np.ndarray
    in_contact: np.ndarray
    contact_positions: np.ndarray
    touchdowns: tuple
    fallen: bool


@dataclass
class _Push:
    joint: int
    point_in_joint: np.ndarray
    force: np.ndarray
    end_time: float


class Simulator:
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
        Frame whose origin height is watched for falls.
    fall_height : float, optional
        The robot has fallen when ``fall_frame`` is below this world height [m].
    max_speed : float
        Any ``|v_i|`` above this raises :class:`SimulationDiverged` [m/s or rad/s].
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
    ):
        if not (np.isfinite(dt) and dt > 0):
            raise InvalidInputError(f"dt must be a positive finite time step [s], got {dt!r}")
        self.model = model
        self.data = model.createData()
        self.dt = float(dt)
        self.max_speed = float(max_speed)
        if n_base_dofs is None:
            n_base_dofs = _detect_base_dofs(model)
        if not 0 <= n_base_dofs <= model.nv:
            raise InvalidInputError(f"n_base_dofs must be in [0, {model.nv}], got {n_base_dofs}")
        self.n_base_dofs = int(n_base_dofs)
        self.n_actuated = model.nv - self.n_base_dofs
        contact_points = list(contact_points)
        if contact_points and ground is None:
            raise InvalidInputError("ground is None but contact_points were given; pass ground=")
        self.ground = ground
        self.contact_frames = [name for name, _ in contact_points]
        located = [self._locate(name, offset) for name, offset in contact_points]
        self._point_list = [int(j) for j, _ in located]
        self._n_points = len(located)
        self._point_placements = [pin.SE3(np.eye(3), p) for _, p in located]
        self._fall_frame = None if fall_frame is None else self._frame_id(fall_frame)
        if (fall_frame is None) != (fall_height is None):
            raise InvalidInputError("fall_frame and fall_height must be given together")
        self._fall_height = fall_height
        self._tau = np.zeros(model.nv)
        self.touchdown_events: list[TouchdownEvent] = []
        self.reset(pin.neutral(model), np.zeros(model.nv))

    # ------------------------------------------------------------------ set-up helpers
    def _frame_id(self, name: str) -> int:
        if not self.model.existFrame(name):
            raise InvalidInputError(f"frame {name!r} is not in the model {self.model.name!r}")
        return self.model.getFrameId(name)

    def _locate(self, frame_name: str, offset) -> tuple[int, np.ndarray]:
        """Parent joint of a frame and the point's position in that joint's frame."""
        offset = np.asarray(offset, dtype=float).reshape(-1)
        if offset.shape != (3,):
            raise ShapeError(f"offset of {frame_name!r} has shape {offset.shape}, expected (3,)")
        frame = self.model.frames[self._frame_id(frame_name)]
        return frame.parentJoint, frame.placement.act(offset)

    # ------------------------------------------------------------------ state
    def reset(self, q, v=None, t: float = 0.0) -> SimState:
        """Set the configuration ``q`` (nq,), velocity ``v`` (nv,) and time; clear contacts."""
        q = np.array(q, dtype=float).reshape(-1)
        v = np.zeros(self.model.nv) if v is None else np.array(v, dtype=float).reshape(-1)
        if q.shape != (self.model.nq,):
            raise ShapeError(f"q has shape {q.shape}, expected ({self.model.nq},)")
        if v.shape != (self.model.nv,):
            raise ShapeError(f"v has shape {v.shape}, expected ({self.model.nv},)")
        self.q, self.v, self.t = q, v, float(t)
        n_points = self._n_points
        self._anchors = np.zeros((n_points, 2))
        self._in_contact = np.zeros(n_points, dtype=bool)
        self._forces = np.zeros((n_points, 3))
        self._positions = np.zeros((n_points, 3))
        self._pushes: list[_Push] = []
        self.touchdown_events = []
        self._last_touchdowns: tuple = ()
        self.fallen = False
        if n_points:
            pin.computeJointJacobians(self.model, self.data, self.q)
            self._positions, _ = self._point_jacobians(self._point_list, self._point_placements)
            self._in_contact = self.ground.penetration(self._positions) > 0
            self._anchors = (self._positions @ self.ground.frame.T)[:, :2]
        return self.state

    @property
    def state(self) -> SimState:
        """The current :class:`SimState` (arrays are copies)."""
        return SimState(
            t=self.t,
            q=self.q.copy(),
            v=self.v.copy(),
            contact_forces=self._forces.copy(),
            in_contact=self._in_contact.copy(),
            contact_positions=self._positions.copy(),
            touchdowns=self._last_touchdowns,
            fallen=self.fallen,
        )

    # ------------------------------------------------------------------ pushes
    def push(self, frame_name: str, force, duration: float, offset=(0.0, 0.0, 0.0)) -> None:
        """Apply a constant world-frame ``force`` [N] at a point of a frame for ``duration`` [s].

        The push starts now; several pushes add up.
        """
        force = np.asarray(force, dtype=float).reshape(-1)
        if force.shape != (3,):
            raise ShapeError(f"force has shape {force.shape}, expected (3,)")
        if not duration > 0:
            raise InvalidInputError(f"duration must be > 0 [s], got {duration!r}")
        joint, point = self._locate(frame_name, offset)
        self._pushes.append(_Push(joint, point, force, self.t + duration - 0.5 * self.dt))

    def push_impulse(self, frame_name: str, impulse, duration: float = 0.05, offset=(0, 0, 0)):
        """Apply a world-frame ``impulse`` [N s] spread evenly over ``duration`` [s]."""
        self.push(frame_name, np.asarray(impulse, dtype=float) / duration, duration, offset)

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

    def step(self, tau, base_force=None) -> SimState:
        r"""Advance one time step under actuated joint torques ``tau``.

        Ground and push forces enter as generalised forces :math:`J^\top f` of the point
        Jacobians, so a step is one ``computeJointJacobians`` and one ``aba`` call plus a
        few vectorised NumPy operations.

        Parameters
        ----------
        tau : array_like, shape (n_actuated,)
            Torques/forces of the actuated joints (``model.nv - n_base_dofs``).
        base_force : array_like, shape (n_base_dofs,), optional
            Generalised force on the base coordinates, e.g. a boom or harness.

        Returns
        -------
        SimState

        Raises
        ------
        SimulationDiverged
            When the state becomes non-finite or exceeds ``max_speed``.
        """
        tau_full = self._tau
        try:
            tau_full[self.n_base_dofs :] = tau
        except ValueError:
            raise ShapeError(
                f"tau has shape {np.shape(tau)}, expected ({self.n_actuated},): one torque per "
                f"actuated joint (model.nv = {self.model.nv} minus {self.n_base_dofs} base dofs)"
            ) from None
        if base_force is None:
            tau_full[: self.n_base_dofs] = 0.0
        else:
            tau_full[: self.n_base_dofs] = base_force
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
            if started.size:
                touchdowns = tuple(
                    TouchdownEvent(self.t + self.dt, int(i), self.contact_frames[i], positions[i])
                    for i in started
                )
        if self._pushes:
            generalized = generalized + self._push_forces()
        acceleration = pin.aba(model, data, self.q, self.v, generalized)
        self.v = self.v + self.dt * acceleration
        self.q = pin.integrate(model, self.q, self.dt * self.v)
        self.t += self.dt
        self._check_finite()
        self._last_touchdowns = touchdowns
        if touchdowns:
            self.touchdown_events.extend(touchdowns)
        if self._fall_frame is not None and not self.fallen:
            pin.updateFramePlacement(model, data, self._fall_frame)
            self.fallen = bool(data.oMf[self._fall_frame].translation[2] < self._fall_height)
        return self.state

    def _push_forces(self) -> np.ndarray:
        """Generalised force of the active pushes; drops the finished ones."""
        self._pushes = [p for p in self._pushes if p.end_time > self.t]
        if not self._pushes:
            return np.zeros(self.model.nv)
        joints = [p.joint for p in self._pushes]
        points = [pin.SE3(np.eye(3), p.point_in_joint) for p in self._pushes]
        _, jacobians = self._point_jacobians(joints, points)
        forces = np.array([p.force for p in self._pushes])
        return np.einsum("pkn,pk->n", jacobians, forces)

    def _check_finite(self) -> None:
        fastest = np.abs(self.v).max(initial=0.0)
        if not np.isfinite(fastest + self.q.sum()):
            raise SimulationDiverged(
                f"state became non-finite at t = {self.t:.4f} s; reduce dt or the contact stiffness"
            )
        if fastest > self.max_speed:
            raise SimulationDiverged(
                f"|v| reached {fastest:.3g} > max_speed = {self.max_speed:.3g} at "
                f"t = {self.t:.4f} s; reduce dt or the contact stiffness"
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
