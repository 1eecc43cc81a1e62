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
from typing import Sequence

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError, ShapeError

from . import kernels

__all__ = ["ComTask", "FrameTask", "PostureTask", "Task"]

_LWA = pin.LOCAL_WORLD_ALIGNED
_XYZ = np.arange(3)


def _array(value, name: str) -> np.ndarray:
    """``value`` as a float array, or the named error (not numpy's)."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name} must be numbers, got {value!r}") from None


def _vector(value, size: int, name: str) -> np.ndarray:
    """Broadcast a scalar or check a vector of length ``size``; all entries finite."""
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
        placements are not refreshed for all frames: a task that reads a frame updates its
        own (``pin.updateFramePlacement``).
        """
        raise NotImplementedError

    def error(self) -> np.ndarray:
        """Tracking error :math:`e` of the last :meth:`update`."""
        return self._error.copy()


@dataclass(frozen=True)
class _PostureRow:
    """Row ``index`` of a PostureTask's state block, as an attribute: reading gives a view of
    the row, assigning writes into it (checked). A descriptor, so that its code runs when the
    attribute is used, not when the class is built."""

    index: int
    name: str
    nonnegative: bool = False

    def __get__(self, task, owner=None):
        return self if task is None else task._state[self.index]

    def __set__(self, task, value) -> None:
        value = _vector(value, task._state.shape[1], self.name)
        if self.nonnegative and (value < 0).any():  # finite: _vector checked
            raise InvalidInputError(f"{self.name} must be finite and >= 0")
        if self.index == 0:
            task._warn_outside_limits(value)
        task._state[self.index] = value


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
        size = len(self.velocity_indices)
        for name, value, slot in (
            ("positions", positions, self.reference_position),
            ("velocities", velocities, self.reference_velocity),
            ("accelerations", accelerations, self.reference_acceleration),
        ):
            if value is None:
                slot[:] = 0.0
                continue
            value = _array(value, name)
            if value.shape != (size,):
                raise ShapeError(
                    f"{name} has shape {value.shape}, expected ({size},) for the joints "
                    f"{self.joint_names}"
                )
            if not math.isfinite(value.sum()) and not np.isfinite(value).all():
                raise InvalidInputError(f"{name} must be finite; it holds NaN or inf")
            if name == "positions":
                self._warn_outside_limits(value)
            slot[:] = value

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
        self._tracks_position = bool(self.rows.min() < 3)
        self._tracks_orientation = bool(self.rows.max() >= 3)
        self.model = robot.model
        self.frame = frame
        self.frame_id = robot.model.getFrameId(frame)
        self.weight = _check_weight(weight)
        self.stiffness, self.damping = _gains(stiffness, damping, 6)
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, robot.reference_configuration)
        self.target_placement = data.oMf[self.frame_id].copy()
        self.target_velocity = np.zeros(6)
        self.target_acceleration = np.zeros(6)
        self._error = np.zeros(6)
        self.target = np.zeros(self.rows.size)
        self.jacobian = np.zeros((self.rows.size, robot.nv))
        self._columns = _support_columns(robot.model, self.frame_id)
        self._frame_jacobian = np.zeros((6, robot.nv))  # its other columns stay zero
        self._rows_kernel = kernels.Binding(kernels.frame_task_rows)

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
        if isinstance(placement, pin.SE3):
            if not (
                np.isfinite(placement.homogeneous).all()
                and np.allclose(placement.rotation.T @ placement.rotation, np.eye(3), atol=1e-6)
            ):
                raise InvalidInputError(
                    "placement must be finite with a rotation matrix (R^T R = I); it holds "
                    "NaN, inf or a non-orthonormal rotation"
                )
            self.target_placement = placement.copy()
        else:
            position = _array(placement, "placement")
            if position.shape != (3,):
                raise ShapeError(
                    f"placement has shape {position.shape}, expected a pinocchio.SE3 or (3,)"
                )
            if not np.isfinite(position).all():
                raise InvalidInputError("placement must be finite; it holds NaN or inf")
            self.target_placement.translation = position
        for name, value, slot in (
            ("velocity", velocity, self.target_velocity),
            ("acceleration", acceleration, self.target_acceleration),
        ):
            slot[:] = 0.0
            if value is None:
                continue
            array = _array(value, name)
            if array.shape not in ((), (3,), (6,)):
                raise ShapeError(f"{name} has shape {array.shape}, expected (), (3,) or (6,)")
            slot[: 3 if array.shape == (3,) else 6] = _vector(array, array.size, name)

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Compute the rows of the frame Jacobian and the desired acceleration (one compiled
        call, :func:`kernels.frame_task_rows`: the frame Jacobian from the joint Jacobians
        ``data.J``)."""
        model, frame_id = self.model, self.frame_id
        placement = pin.updateFramePlacement(model, data, frame_id)
        target, jacobian = self.target_placement, self._frame_jacobian
        drift = pin.getFrameClassicalAcceleration(model, data, frame_id, _LWA).vector
        stiffness, damping = self.stiffness, self.damping
        velocity, acceleration = self.target_velocity, self.target_acceleration
        if not self._rows_kernel(
            (v, stiffness, damping, velocity, acceleration), self.target, self.jacobian,
            self.rows, self._error, target.rotation, target.translation, placement.rotation,
            placement.translation, data.J, self._columns, jacobian, v, drift, velocity,
            acceleration, stiffness, damping, self._tracks_position, self._tracks_orientation,
        ):  # fmt: skip
            # rotation error near pi: Pinocchio's log3
            error = self._error
            np.subtract(target.translation, placement.translation, out=error[:3])
            error[3:] = pin.log3(target.rotation @ placement.rotation.T)
            kernels.pd_task_rows(
                self.target, self.jacobian, self.rows, error, jacobian, v, drift, velocity,
                acceleration, stiffness, damping,
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
        self.stiffness, self.damping = _gains(stiffness, damping, 3)
        data = robot.model.createData()
        self.target_position = np.array(
            pin.centerOfMass(robot.model, data, robot.reference_configuration), dtype=float
        )
        self.target_velocity = np.zeros(3)
        self.target_acceleration = np.zeros(3)
        self._error = np.zeros(3)
        self.target = np.zeros(3)
        self.jacobian = np.zeros((3, robot.nv))
        self._rows_kernel = kernels.Binding(kernels.com_task_rows)

    def set_target(self, position, velocity=None, acceleration=None) -> None:
        """Set the desired CoM position [m], velocity [m/s] and acceleration [m/s^2], shape (3,)."""
        self.target_position[:] = _vector(position, 3, "position")  # the bound array
        self.target_velocity[:] = 0.0 if velocity is None else _vector(velocity, 3, "velocity")
        self.target_acceleration[:] = (
            0.0 if acceleration is None else _vector(acceleration, 3, "acceleration")
        )

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Compute the CoM Jacobian and desired acceleration minus drift.

        Uses ``data.Jcom`` from ``computeAllTerms`` and the CoM drift from the zero-acceleration
        kinematics already in ``data``.
        """
        pin.centerOfMass(self.model, data, pin.ACCELERATION, False)
        stiffness, damping, position = self.stiffness, self.damping, self.target_position
        velocity, acceleration = self.target_velocity, self.target_acceleration
        self._rows_kernel(
            (v, stiffness, damping, velocity, acceleration, position), self.target,
            self.jacobian, _XYZ, self._error, position, data.com[0], data.Jcom, v, data.acom[0],
            velocity, acceleration, stiffness, damping,
        )  # fmt: skip
