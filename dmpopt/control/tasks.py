r"""Acceleration tasks of the inverse-dynamics QP.

Every task turns the current state into a linear least-squares term on the joint accelerations
:math:`\ddot q`: a Jacobian :math:`J` and a desired acceleration :math:`a^*` such that the QP
minimises

.. math:: w \, \lVert J \ddot q + \dot J \dot q - a^* \rVert^2 ,
   \qquad a^* = a_{\mathrm{ref}} + K_p\, e + K_d\, (\dot x_{\mathrm{ref}} - \dot x),

the operational-space PD law of [Khatib1987]_ with the reference acceleration as feed-forward
(the form TSID uses [DelPrete2016]_). A task's :meth:`Task.update` fills ``jacobian`` :math:`J`
and ``target`` :math:`b = a^* - \dot J \dot q`; the controller adds :math:`w J^\top J` to the
Hessian and :math:`-w J^\top b` to the gradient. A :class:`PostureTask` selects joints, so its
Hessian term is the constant :math:`w` on their diagonal entries. The drift :math:`\dot J \dot q`
is read from the Pinocchio data, whose kinematics the controller runs with zero acceleration.
Weights are read once, when the controller is built.

The contacts (:mod:`dmpopt.control.contacts`) are not tasks but constraints.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import ClassVar, Sequence

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError, ShapeError

from . import kernels

__all__ = ["ComTask", "FrameTask", "PostureTask", "Task"]

_LWA = pin.LOCAL_WORLD_ALIGNED
_EMPTY = np.zeros(0)


def _array(value, name: str) -> np.ndarray:
    """``value`` as a float array, or the named error (not numpy's)."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name} must be numbers, got {value!r}") from None


def _vector(value, size: int, name: str) -> np.ndarray:
    """Broadcast a scalar or check a vector of length ``size``; all entries finite."""
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (size,):
        # a target set every tick: one compiled pass instead of numpy's isfinite and all
        if not kernels.all_finite(value, _EMPTY):
            raise InvalidInputError(f"{name} must be finite; it holds NaN or inf")
        return value.copy()
    array = _array(value, name)
    if array.ndim == 0:
        array = np.full(size, float(array))
    elif array.shape != (size,):
        raise ShapeError(f"{name} has shape {array.shape}, expected () or ({size},)")
    if not np.isfinite(array).all():
        raise InvalidInputError(f"{name} must be finite; it holds NaN or inf")
    return array.copy()


def _gains(stiffness, damping, size: int) -> tuple[np.ndarray, np.ndarray]:
    kp = _vector(stiffness, size, "stiffness")
    kd = 2.0 * np.sqrt(kp) if damping is None else _vector(damping, size, "damping")
    if np.any(kp < 0) or np.any(kd < 0):  # finite: _vector checked
        raise InvalidInputError("stiffness and damping must be finite and >= 0")
    return kp, kd


def _gain(value: float, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not (math.isfinite(number) and number >= 0):
        raise InvalidInputError(f"{name} must be a finite number >= 0, got {value!r}")
    return number


def _support_columns(model: pin.Model, frame_id: int) -> np.ndarray:
    """Velocity indices of the joints that move a frame (the only nonzero columns of its
    Jacobian)."""
    joints = model.supports[model.frames[frame_id].parentJoint]
    columns = [range(model.joints[j].idx_v, model.joints[j].idx_v + model.joints[j].nv)
               for j in joints if j > 0]  # fmt: skip
    return np.array([c for block in columns for c in block], dtype=np.int64)


def _frame_in_joint(model: pin.Model, frame_id: int) -> tuple[int, np.ndarray]:
    """A frame's parent joint and its placement in that joint as [R | p], shape (3, 4)."""
    frame = model.frames[frame_id]
    placement = np.zeros((3, 4))
    placement[:, :3], placement[:, 3] = frame.placement.rotation, frame.placement.translation
    return frame.parentJoint, placement


def joint_views(data: pin.Data, joint: int) -> tuple[np.ndarray, ...]:
    """Views of a joint's placement (rotation, translation), velocity and acceleration (joint
    axes, linear part first) in ``data``: arrays that see every later update of ``data``
    (Pinocchio returns views of its own storage, which it never reallocates); whoever keeps
    them keeps ``data`` alive."""
    placement = data.oMi[joint]
    return placement.rotation, placement.translation, data.v[joint].vector, data.a[joint].vector


def _check_weight(weight: float) -> float:
    number = _array(weight, "weight")
    if number.shape != () or not (np.isfinite(number) and number > 0):
        raise InvalidInputError(f"weight must be a finite number > 0, got {weight!r}")
    return float(number)


class Task:
    r"""Base class: a weighted least-squares term :math:`w\lVert J\ddot q - b\rVert^2`.

    Subclasses fill ``self.jacobian`` (shape (m, nv)) and ``self.target`` (:math:`b = a^* -
    \dot J \dot q`, shape (m,)) in :meth:`update`, in place (``self.jacobian[:] = ...``); a
    :class:`PostureTask` has ``velocity_indices`` instead of a Jacobian.

    Tasks are pure: :meth:`update` computes the rows from the state into the task's own
    arrays, which an :class:`~dmpopt.control.InverseDynamicsController` copies into its QP
    each tick; a controller never rebinds or rewrites a task, so one task can serve several
    controllers. A :class:`PostureTask`'s references and gains are copied instead and its PD
    law evaluated in the controller (for all posture tasks at once): its ``target`` and
    :meth:`error` are those of its own last :meth:`update`.
    """

    weight: float
    jacobian: np.ndarray
    target: np.ndarray

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        r"""Compute ``jacobian`` and ``target`` from the state and the Pinocchio data.

        ``data`` holds the joint kinematics of :math:`(q, \dot q, \ddot q = 0)` and the joint
        Jacobians (on a floating base, everything ``computeAllTerms`` fills). Frame
        placements (``data.oMf``) are not refreshed: a task that reads a frame computes its
        placement from its parent joint's (``data.oMi``), or updates its own
        (``pin.updateFramePlacement``).
        """
        raise NotImplementedError

    def error(self) -> np.ndarray:
        """Tracking error :math:`e` of the last :meth:`update`."""
        return self._error.copy()


@dataclass(frozen=True)
class _GainRow:
    """Row ``index`` of a task's packed ``_gains`` block (gains and references), as an
    attribute: reading gives a view of the row, assigning writes into it (checked). A
    descriptor, so that its code runs when the attribute is used, not when the class is
    built."""

    index: int
    name: str
    nonnegative: bool = False
    block: ClassVar[str] = "_gains"

    def __get__(self, task, owner=None):
        return self if task is None else getattr(task, self.block)[self.index]

    def __set__(self, task, value) -> None:
        rows = getattr(task, self.block)
        value = _vector(value, rows.shape[1], self.name)
        if self.nonnegative and (value < 0).any():  # finite: _vector checked
            raise InvalidInputError(f"{self.name} must be finite and >= 0")
        self._check(task, value)
        rows[self.index] = value

    def _check(self, task, value) -> None:
        """A further check of a value about to be written (none here)."""


class _PostureRow(_GainRow):
    """Row ``index`` of a PostureTask's ``_state`` block; a reference position outside the
    joint limits warns."""

    block: ClassVar[str] = "_state"

    def _check(self, task, value) -> None:
        if self.index == 0:
            task._warn_outside_limits(value)


class PostureTask(Task):
    r"""Joint-space tracking of a joint group: the task a DMP drives.

    .. math:: \ddot q_j^* = \ddot q_{\mathrm{ref}} + K_p (q_{\mathrm{ref}} - q_j)
              + K_d (\dot q_{\mathrm{ref}} - \dot q_j)

    With a DMP plan as reference, the plan's acceleration is the feed-forward and the PD gains
    stay low. Call :meth:`set_reference` every tick with the DMP's ``y, yd, ydd``.

    Parameters
    ----------
    robot : RobotModel
        The robot (see :mod:`robots`).
    joints : str or sequence of str
        A joint group of ``robot`` (``"left_arm"``) or 1-DOF joint names; ``None`` for all
        actuated joints.
    weight : float
        Task weight :math:`w`.
    stiffness : float or ndarray, shape (n_joints,)
        :math:`K_p` [1/s^2].
    damping : float or ndarray, shape (n_joints,), optional
        :math:`K_d` [1/s]; default :math:`2\sqrt{K_p}` (critical damping).

    Attributes
    ----------
    reference_position, reference_velocity, reference_acceleration : ndarray, shape (n_joints,)
        Desired joint positions [rad], velocities [rad/s] and accelerations [rad/s^2].
    stiffness, damping : ndarray, shape (n_joints,)
        :math:`K_p` [1/s^2] and :math:`K_d` [1/s]; assigning checks them (finite, >= 0).
    target : ndarray, shape (n_joints,)
        Desired joint accelerations of the last update.

    Notes
    -----
    The reference starts at ``robot.reference_configuration`` with zero velocity and
    acceleration.
    """

    # The task's arrays are the rows of one block, shape (7, n_joints), that a controller copies
    # each tick into one block for all its posture tasks (one compiled call for their gradient).
    reference_position = _PostureRow(0, "reference_position")
    reference_velocity = _PostureRow(1, "reference_velocity")
    reference_acceleration = _PostureRow(2, "reference_acceleration")
    stiffness = _PostureRow(3, "stiffness", nonnegative=True)
    damping = _PostureRow(4, "damping", nonnegative=True)
    target = _PostureRow(5, "target")
    _error = _PostureRow(6, "_error")

    def __init__(self, robot, joints=None, weight: float = 1.0, stiffness=10.0, damping=None):
        joints = robot.actuated_joint_names if joints is None else joints
        # first: it names an unknown group or joint (the group lookup below raised KeyError)
        self.velocity_indices = np.asarray(robot.velocity_indices(joints), dtype=np.int64)
        self.joint_names = (
            tuple(robot.joint_groups[joints]) if isinstance(joints, str) else (tuple(joints))
        )
        self.configuration_indices = np.asarray(robot.configuration_indices(joints), dtype=np.int64)
        size = len(self.velocity_indices)
        self.weight = _check_weight(weight)
        self._state = np.zeros((7, size))
        self.stiffness, self.damping = _gains(stiffness, damping, size)
        self.model = robot.model
        self._lower = np.asarray(robot.position_lower, float)[self.configuration_indices]
        self._upper = np.asarray(robot.position_upper, float)[self.configuration_indices]
        self._warned: set[str] = set()
        unbounded = (np.full(size, -np.inf), np.full(size, np.inf))
        self._limits = ((self._lower, self._upper), unbounded, unbounded)  # per reference row
        self._status_kernel = kernels.entry_point(
            kernels.reference_status, self._lower, self._lower, self._upper
        )
        self.reference_position = robot.reference_configuration[self.configuration_indices]

    @property
    def state(self) -> np.ndarray:
        """The task's block, shape (7, n_joints), rows: reference position, velocity and
        acceleration, stiffness, damping, target, error (a controller copies it each tick;
        the array itself is never replaced)."""
        return self._state

    def set_reference(self, positions, velocities=None, accelerations=None) -> None:
        """Set the joint reference for the coming ticks (e.g. one DMP step).

        Parameters
        ----------
        positions : ndarray, shape (n_joints,)
            Desired joint positions [rad].
        velocities, accelerations : ndarray, shape (n_joints,), optional
            Desired joint velocities [rad/s] and accelerations [rad/s^2]; zero if omitted.
        """
        state = self._state
        for row, (name, value) in enumerate(
            (("positions", positions), ("velocities", velocities),
             ("accelerations", accelerations))
        ):  # fmt: skip
            if value is None:
                state[row] = 0.0
                continue
            if not (type(value) is np.ndarray and value.dtype == np.float64):
                value = _array(value, name)
            if value.shape != state.shape[1:]:
                raise ShapeError(
                    f"{name} has shape {value.shape}, expected ({state.shape[1]},) for the joints "
                    f"{self.joint_names}"
                )
            # one compiled pass: finite, and the positions within their limits
            status = self._status(value, *self._limits[row])
            if status == 1:
                raise InvalidInputError(f"{name} must be finite; it holds NaN or inf")
            if status == 2 and row == 0:
                self._warn_outside_limits(value)
            state[row] = value

    def _status(self, value: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> int:
        """:func:`kernels.reference_status`, called without numba's type dispatch for a
        writable C-ordered float64 vector (the type it was bound to)."""
        flags = value.flags
        if flags.c_contiguous and flags.writeable:
            return self._status_kernel(value, lower, upper)
        return kernels.reference_status(value, lower, upper)

    def _warn_outside_limits(self, positions: np.ndarray) -> None:
        """Warn, once per joint, of a reference outside the joint's position limits: the
        controller's joint limits (on by default) stop the joint at its limit."""
        outside = (positions < self._lower) | (positions > self._upper)
        if not outside.any():
            return
        for j in np.flatnonzero(outside):
            name = self.joint_names[j]
            if name not in self._warned:
                self._warned.add(name)
                warnings.warn(
                    f"PostureTask: reference {positions[j]:.4g} rad of {name!r} is outside its "
                    f"position limits [{self._lower[j]:.4g}, {self._upper[j]:.4g}]; the joint "
                    "stops at its limit (clip the reference to silence this)",
                    stacklevel=3,
                )

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Compute the desired joint accelerations of the PD law above."""
        kernels.posture_law(self._state, self.configuration_indices, self.velocity_indices, q, v)


class FrameTask(Task):
    r"""Track a frame's placement (SE(3)), position or orientation, in world-aligned axes.

    Errors are expressed in the world frame at the frame origin
    (``LOCAL_WORLD_ALIGNED``): :math:`e = (p_{\mathrm{ref}} - p,\;
    \log_3(R_{\mathrm{ref}} R^\top))`, tracked with the classical frame acceleration.

    Parameters
    ----------
    robot : RobotModel
        The robot.
    frame : str
        Frame name, e.g. ``"gripper_left_base_link"`` or ``"base_link"`` (pelvis).
    weight : float
        Task weight.
    stiffness, damping : float or ndarray, shape (6,)
        PD gains on (linear, angular) components; damping defaults to critical.
    components : {"all", "position", "orientation"} or sequence of int
        Which of the 6 rows (x, y, z, roll, pitch, yaw axes) to track.

    Notes
    -----
    The target starts at the frame's placement in ``robot.reference_configuration``.
    """

    _COMPONENTS = {"all": range(6), "position": range(3), "orientation": range(3, 6)}

    def __init__(
        self,
        robot,
        frame: str,
        weight: float = 1.0,
        stiffness=100.0,
        damping=None,
        components: str | Sequence[int] = "all",
    ):
        if not robot.model.existFrame(frame):
            raise InvalidInputError(f"frame={frame!r} is not a frame of {robot.name!r}")
        if isinstance(components, str):
            if components not in self._COMPONENTS:
                raise InvalidInputError(
                    f"components={components!r}; expected one of {sorted(self._COMPONENTS)} "
                    "or a list of row indices in 0..5"
                )
            components = self._COMPONENTS[components]
        self.rows = np.array(sorted(set(int(c) for c in components)), dtype=int)
        if self.rows.size == 0 or self.rows.min() < 0 or self.rows.max() > 5:
            raise InvalidInputError(f"components={components!r}; expected indices in 0..5")
        self.model = robot.model
        self.frame = frame
        self.frame_id = robot.model.getFrameId(frame)
        self.weight = _check_weight(weight)
        # Packed once, so that a tick passes a few arrays to its compiled call
        # (kernels.frame_rows): gains rows Kp, Kd, v_ref, a_ref; reference [R_ref | p_ref]
        # (column-major: R_ref and p_ref are contiguous, as Pinocchio's); out (target, error);
        # jacobians (rows, frame Jacobian: its other columns stay zero); indices (tracked
        # rows, supporting columns); the frame's parent joint and placement in it.
        m = self.rows.size
        self._gains = np.zeros((4, 6))
        self._gains[0], self._gains[1] = _gains(stiffness, damping, 6)
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, robot.reference_configuration)
        self._reference = np.zeros((3, 4), order="F")
        self._reference[:, :3] = data.oMf[self.frame_id].rotation
        self._reference[:, 3] = data.oMf[self.frame_id].translation
        self._out = np.zeros(m + 6)
        self.target, self._error = self._out[:m], self._out[m:]
        self._jacobians = np.zeros((m + 6, robot.nv))
        self.jacobian, self._frame_jacobian = self._jacobians[:m], self._jacobians[m:]
        self._indices = np.concatenate(
            [self.rows, _support_columns(robot.model, self.frame_id)]
        ).astype(np.int64)
        self._joint, self._placement = _frame_in_joint(robot.model, self.frame_id)
        self._rows_kernel = kernels.Binding(kernels.frame_rows)

    stiffness = _GainRow(0, "stiffness", nonnegative=True)
    damping = _GainRow(1, "damping", nonnegative=True)
    target_velocity = _GainRow(2, "target_velocity")
    target_acceleration = _GainRow(3, "target_acceleration")

    @property
    def target_placement(self) -> pin.SE3:
        """The desired placement (a copy; assigning sets it, checked, and keeps the target
        velocity and acceleration; :meth:`set_target` sets all three)."""
        return pin.SE3(self._reference[:, :3].copy(), self._reference[:, 3].copy())

    @target_placement.setter
    def target_placement(self, placement: pin.SE3 | np.ndarray) -> None:
        self._set_placement(placement)

    def set_target(self, placement: pin.SE3 | np.ndarray, velocity=None, acceleration=None):
        """Set the desired placement (or position), velocity and acceleration.

        Parameters
        ----------
        placement : pinocchio.SE3 or ndarray, shape (3,)
            Desired placement; a 3-vector sets the position and keeps the orientation.
        velocity, acceleration : ndarray, shape (6,) or (3,), optional
            Desired (linear, angular) velocity and acceleration in world-aligned axes; a
            3-vector is the linear part (angular zero), e.g. a position DMP's output; zero if
            omitted.
        """
        self._set_placement(placement)
        for name, value, slot in (
            ("velocity", velocity, self.target_velocity),
            ("acceleration", acceleration, self.target_acceleration),
        ):
            if value is None:
                slot[:] = 0.0
                continue
            array = _array(value, name)
            if array.shape not in ((), (3,), (6,)):
                raise ShapeError(f"{name} has shape {array.shape}, expected (), (3,) or (6,)")
            array = _vector(array, array.size, name)
            slot[:] = 0.0
            slot[: 3 if array.shape == (3,) else 6] = array

    def _set_placement(self, placement) -> None:
        """The desired placement (pinocchio.SE3) or position (shape (3,)), checked."""
        if isinstance(placement, pin.SE3):
            if not kernels.is_placement(placement.homogeneous):
                raise InvalidInputError(
                    "placement must be finite with a rotation matrix (R^T R = I); it holds "
                    "NaN, inf or a non-orthonormal rotation"
                )
            self._reference[:, :3] = placement.rotation
            self._reference[:, 3] = placement.translation
        else:
            position = _array(placement, "placement")
            if position.shape != (3,):
                raise ShapeError(
                    f"placement has shape {position.shape}, expected a pinocchio.SE3 or (3,)"
                )
            if not np.isfinite(position).all():
                raise InvalidInputError("placement must be finite; it holds NaN or inf")
            self._reference[:, 3] = position

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Compute the rows of the frame Jacobian and the desired acceleration (one compiled
        call, :func:`kernels.frame_rows`: the frame's placement, Jacobian and drift from its
        parent joint's placement, velocity and acceleration and the joint Jacobians
        ``data.J``)."""
        reference = self._reference
        if not self._rows_kernel(
            v, self._out, self._jacobians, self._indices, self._gains, reference[:, :3],
            reference[:, 3], *joint_views(data, self._joint), self._placement, False, data.J, v,
        ):  # fmt: skip
            self._near_half_turn(v, data)

    def _near_half_turn(self, v: np.ndarray, data: pin.Data) -> None:
        """:meth:`update` for a rotation error near pi (the frame Jacobian written): the
        error by Pinocchio's log3."""
        model, frame_id, gains = self.model, self.frame_id, self._gains
        placement = pin.updateFramePlacement(model, data, frame_id)
        drift = pin.getFrameClassicalAcceleration(model, data, frame_id, _LWA).vector
        error, reference = self._error, self._reference
        np.subtract(reference[:, 3], placement.translation, out=error[:3])
        error[3:] = pin.log3(reference[:, :3] @ placement.rotation.T)
        kernels.pd_task_rows(
            self.target, self.jacobian, self.rows, error, self._frame_jacobian, v, drift,
            gains[2], gains[3], gains[0], gains[1],
        )  # fmt: skip


class ComTask(Task):
    r"""Track the centre of mass :math:`c` with a PD law and feed-forward.

    .. math:: \ddot c^* = \ddot c_{\mathrm{ref}} + K_p (c_{\mathrm{ref}} - c)
              + K_d (\dot c_{\mathrm{ref}} - \dot c)

    Parameters
    ----------
    robot : RobotModel
        The robot.
    weight : float
        Task weight.
    stiffness, damping : float or ndarray, shape (3,)
        PD gains; damping defaults to critical.

    Notes
    -----
    The target starts at the centre of mass of ``robot.reference_configuration``.
    """

    def __init__(self, robot, weight: float = 1.0, stiffness=50.0, damping=None):
        self.model = robot.model
        self.weight = _check_weight(weight)
        # Packed once (kernels.com_rows): gains rows Kp, Kd, c_ref velocity, acceleration,
        # position; out (target, error).
        self._gains = np.zeros((5, 3))
        self._gains[0], self._gains[1] = _gains(stiffness, damping, 3)
        data = robot.model.createData()
        self._gains[4] = pin.centerOfMass(robot.model, data, robot.reference_configuration)
        self._out = np.zeros(6)
        self.target, self._error = self._out[:3], self._out[3:]
        self.jacobian = np.zeros((3, robot.nv))
        self._rows_kernel = kernels.Binding(kernels.com_rows)

    stiffness = _GainRow(0, "stiffness", nonnegative=True)
    damping = _GainRow(1, "damping", nonnegative=True)
    target_velocity = _GainRow(2, "target_velocity")
    target_acceleration = _GainRow(3, "target_acceleration")
    target_position = _GainRow(4, "target_position")

    def set_target(self, position, velocity=None, acceleration=None) -> None:
        """Set the desired CoM position [m], velocity [m/s] and acceleration [m/s^2], shape (3,)."""
        position = _vector(position, 3, "position")
        velocity = 0.0 if velocity is None else _vector(velocity, 3, "velocity")
        acceleration = 0.0 if acceleration is None else _vector(acceleration, 3, "acceleration")
        self._gains[4], self._gains[2], self._gains[3] = position, velocity, acceleration

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Compute the CoM Jacobian and desired acceleration minus drift (one compiled call,
        :func:`kernels.com_rows`).

        Uses ``data.Jcom`` from ``computeAllTerms`` and the CoM drift from the zero-acceleration
        kinematics already in ``data``.
        """
        com = pin.centerOfMass(self.model, data, pin.ACCELERATION, False)  # data.com[0]
        self._rows_kernel(v, self._out, self.jacobian, self._gains, com, data.Jcom, data.acom[0], v)
