r"""Acceleration tasks and rigid sole contacts of the inverse-dynamics QP.

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

A :class:`SoleContact` is not a task but a constraint: it holds a sole still (a 6-D rigid
contact) and bounds its contact wrench to a linearised friction cone with centre-of-pressure
bounds. A :class:`PointContact` holds a point foot still with a force in a linearised friction
pyramid (3-D, or in-plane on a planar robot). Both expose the same interface to the
controller: ``n_force`` unknowns, ``update`` writing ``jacobian`` and ``target`` (the contact
rows), ``contact_jacobian`` and the cone rows ``wrench_matrix f <= wrench_upper`` whose last two
rows bound the normal force: :math:`-f_n \le -f_{\min}` and :math:`f_n \le f_{\max}`.
"""

from __future__ import annotations

import math
import warnings
from typing import Sequence

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError, ShapeError

from . import kernels

__all__ = ["ComTask", "FrameTask", "PointContact", "PostureTask", "SoleContact", "Task"]

_LWA = pin.LOCAL_WORLD_ALIGNED
_XYZ = np.arange(3)
_SPATIAL = np.arange(6)
_ZERO_MOTION = np.zeros(6)


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
    if np.any(kp < 0) or np.any(kd < 0) or not np.all(np.isfinite(kp) & np.isfinite(kd)):
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

    An :class:`~dmpopt.control.InverseDynamicsController` makes ``jacobian`` and ``target``
    views of its own QP rows when it is built, so that :meth:`update` writes straight into
    them: read them through the attributes, not through references kept from before. (An
    update that rebinds them instead, or a second controller sharing the task, is detected
    and handled by copying.) :class:`SoleContact` is bound the same way, and a
    :class:`PostureTask`'s references, gains and target are views of a block the controller
    stacks for all its posture tasks (assigning to them writes into that block).
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


def _posture_row(index: int, name: str, doc: str, nonnegative: bool = False) -> property:
    """Row ``index`` of a PostureTask's state block; assigning writes into the row."""

    def get(self) -> np.ndarray:
        return self._state[index]

    def set(self, value) -> None:
        value = _vector(value, self._state.shape[1], name)
        if nonnegative and not (np.isfinite(value).all() and (value >= 0).all()):
            raise InvalidInputError(f"{name} must be finite and >= 0")
        if index == 0:
            self._warn_outside_limits(value)
        self._state[index] = value

    return property(get, set, doc=doc)


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

    Notes
    -----
    The reference starts at ``robot.reference_configuration`` with zero velocity and
    acceleration.
    """

    # The task's arrays are the rows of one block, shape (7, n_joints); a controller stacks the
    # blocks of its posture tasks to run their PD laws as one vectorised law per tick.
    reference_position = _posture_row(0, "reference_position", "Desired joint positions [rad].")
    reference_velocity = _posture_row(1, "reference_velocity", "Desired joint velocities [rad/s].")
    reference_acceleration = _posture_row(
        2, "reference_acceleration", "Desired joint accelerations [rad/s^2]."
    )
    stiffness = _posture_row(3, "stiffness", ":math:`K_p` [1/s^2].", nonnegative=True)
    damping = _posture_row(4, "damping", ":math:`K_d` [1/s].", nonnegative=True)
    target = _posture_row(5, "target", "Desired joint accelerations of the last update.")
    _error = _posture_row(6, "_error", "Position error of the last update [rad].")

    def __init__(self, robot, joints=None, weight: float = 1.0, stiffness=10.0, damping=None):
        joints = robot.actuated_joint_names if joints is None else joints
        self.joint_names = (
            tuple(robot.joint_groups[joints]) if isinstance(joints, str) else (tuple(joints))
        )
        self.velocity_indices = np.asarray(robot.velocity_indices(joints), dtype=np.int64)
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

    def set_target(self, placement: pin.SE3 | np.ndarray, velocity=None, acceleration=None):
        """Set the desired placement (or position), velocity and acceleration.

        Parameters
        ----------
        placement : pinocchio.SE3 or ndarray, shape (3,)
            Desired placement; a 3-vector sets the position and keeps the orientation.
        velocity, acceleration : ndarray, shape (6,), optional
            Desired (linear, angular) velocity and acceleration in world-aligned axes; zero if
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
        self.target_velocity[:] = 0.0 if velocity is None else _vector(velocity, 6, "velocity")
        self.target_acceleration[:] = (
            0.0 if acceleration is None else _vector(acceleration, 6, "acceleration")
        )

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Compute the rows of the frame Jacobian and the desired acceleration."""
        model, frame_id = self.model, self.frame_id
        placement = pin.updateFramePlacement(model, data, frame_id)
        error = self._error
        if self._tracks_position:
            np.subtract(self.target_placement.translation, placement.translation, out=error[:3])
        if self._tracks_orientation:
            error[3:] = pin.log3(self.target_placement.rotation @ placement.rotation.T)
        kernels.pd_task_rows(
            self.target, self.jacobian, self.rows, error,
            pin.getFrameJacobian(model, data, frame_id, _LWA), v,
            pin.getFrameClassicalAcceleration(model, data, frame_id, _LWA).vector,
            self.target_velocity, self.target_acceleration, self.stiffness, self.damping,
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
        self.target_position = pin.centerOfMass(robot.model, data, robot.reference_configuration)
        self.target_velocity = np.zeros(3)
        self.target_acceleration = np.zeros(3)
        self._error = np.zeros(3)
        self.target = np.zeros(3)
        self.jacobian = np.zeros((3, robot.nv))

    def set_target(self, position, velocity=None, acceleration=None) -> None:
        """Set the desired CoM position [m], velocity [m/s] and acceleration [m/s^2], shape (3,)."""
        self.target_position = _vector(position, 3, "position")
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
        np.subtract(self.target_position, data.com[0], out=self._error)
        kernels.pd_task_rows(
            self.target, self.jacobian, _XYZ, self._error, data.Jcom, v, data.acom[0],
            self.target_velocity, self.target_acceleration, self.stiffness, self.damping,
        )  # fmt: skip


class SoleContact:
    r"""A flat foot held still on the ground, with its contact wrench in a linearised cone.

    The contact wrench :math:`f = (f_x, f_y, f_z, \tau_x, \tau_y, \tau_z)` is expressed in the
    sole frame (z normal to the sole, origin on the sole). The QP keeps the sole's spatial
    acceleration at :math:`a^* = -K_p \log_6(M_{\mathrm{ref}}^{-1} M) - K_d \nu` (zero for a
    sole at rest at its reference, Baumgarte stabilisation otherwise) and imposes

    - friction pyramid inscribed in the cone of coefficient :math:`\mu`:
      :math:`|f_x|, |f_y| \le (\mu/\sqrt 2)\, f_z`, so :math:`\lVert f_t \rVert \le \mu f_z`;
    - centre of pressure :math:`(-\tau_y/f_z,\ \tau_x/f_z)` inside the sole's bounding box;
    - yaw torque :math:`|\tau_z| \le (\mu/\sqrt 2)\, r\, f_z` with :math:`r` the smaller
      half-size of the sole (a conservative bound);
    - :math:`f_{\min} \le f_z \le f_{\max}`.

    Parameters
    ----------
    robot : RobotModel
        The robot; ``robot.sole_corners`` gives the sole's extent.
    frame : str
        Sole frame, e.g. ``"left_sole_link"``.
    friction_coefficient : float
        :math:`\mu`.
    min_normal_force, max_normal_force : float
        Bounds on :math:`f_z` [N].
    stiffness, damping : float
        Baumgarte gains pulling the sole back to its reference placement.
    cop_fraction : float
        Fraction (0, 1] of the sole's extent (about the frame origin) the centre of pressure
        may use. On compliant ground a centre of pressure on the sole's edge unloads the
        opposite edge and the foot starts to roll; 0.7 keeps it clear of the edges.
    """

    n_wrench_rows = 12
    n_force = 6  #: wrench unknowns
    normal_index = 2  #: index of the normal force f_z in the wrench

    def __init__(
        self,
        robot,
        frame: str,
        friction_coefficient: float = 0.7,
        min_normal_force: float = 1.0,
        max_normal_force: float = 5000.0,
        stiffness: float = 10.0,
        damping: float | None = None,
        cop_fraction: float = 1.0,
    ):
        _init_contact(
            self, robot, frame, friction_coefficient, min_normal_force, max_normal_force,
            stiffness, damping,
        )  # fmt: skip
        fraction = _array(cop_fraction, "cop_fraction")
        if fraction.shape != () or not 0 < fraction <= 1:
            raise InvalidInputError(f"cop_fraction must be in (0, 1], got {cop_fraction!r}")
        self.cop_fraction = float(fraction)
        corners = self.cop_fraction * np.asarray(robot.sole_corners)
        self.x_min, self.y_min = corners[:, :2].min(axis=0)
        self.x_max, self.y_max = corners[:, :2].max(axis=0)
        self.wrench_matrix, self.wrench_upper = self._wrench_cone(
            min_normal_force, max_normal_force
        )
        self.jacobian = np.zeros((6, robot.nv))
        self.target = np.zeros(6)

    stiffness = property(
        lambda self: float(self._stiffness[0]),
        lambda self, value: self._stiffness.fill(_gain(value, "stiffness")),
        doc="Baumgarte stiffness :math:`K_p` [1/s^2].",
    )
    damping = property(
        lambda self: float(self._damping[0]),
        lambda self, value: self._damping.fill(_gain(value, "damping")),
        doc="Baumgarte damping :math:`K_d` [1/s].",
    )

    def _wrench_cone(self, f_min: float, f_max: float) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``C f <= u`` of the linearised wrench cone."""
        mu = self.friction_coefficient / np.sqrt(2.0)
        radius = min(-self.x_min, self.x_max, -self.y_min, self.y_max)
        #              fx   fy   fz             tx   ty   tz
        matrix = np.array(
            [
                [1.0, 0.0, -mu, 0.0, 0.0, 0.0],  # fx <= mu' fz
                [-1.0, 0.0, -mu, 0.0, 0.0, 0.0],  # -fx <= mu' fz
                [0.0, 1.0, -mu, 0.0, 0.0, 0.0],  # fy <= mu' fz
                [0.0, -1.0, -mu, 0.0, 0.0, 0.0],  # -fy <= mu' fz
                [0.0, 0.0, -self.x_max, 0.0, -1.0, 0.0],  # CoP x = -ty/fz <= x_max
                [0.0, 0.0, self.x_min, 0.0, 1.0, 0.0],  # CoP x >= x_min
                [0.0, 0.0, -self.y_max, 1.0, 0.0, 0.0],  # CoP y = tx/fz <= y_max
                [0.0, 0.0, self.y_min, -1.0, 0.0, 0.0],  # CoP y >= y_min
                [0.0, 0.0, -mu * radius, 0.0, 0.0, 1.0],  # tz <= mu' r fz
                [0.0, 0.0, -mu * radius, 0.0, 0.0, -1.0],  # -tz <= mu' r fz
                [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],  # fz >= f_min
                [0.0, 0.0, 1.0, 0.0, 0.0, 0.0],  # fz <= f_max
            ]
        )
        upper = np.zeros(self.n_wrench_rows)
        upper[10], upper[11] = -f_min, f_max
        return matrix, upper

    def cone_margin(self, wrench: np.ndarray) -> np.ndarray:
        """Slack ``u - C f`` of each cone row for a wrench, shape (12,); >= 0 inside the cone."""
        return self.wrench_upper - self.wrench_matrix @ np.asarray(wrench, dtype=float)

    def contact_jacobian(self, data: pin.Data) -> np.ndarray:
        """The contact rows' Jacobian (LOCAL), shape (6, nv), from the joint Jacobians in
        ``data``."""
        return pin.getFrameJacobian(self.model, data, self.frame_id, pin.LOCAL)

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Sole Jacobian (LOCAL) and desired sole acceleration minus drift."""
        model, frame_id = self.model, self.frame_id
        placement = pin.updateFramePlacement(model, data, frame_id)
        if self.reference_placement is None:
            self.reference_placement = placement.copy()
        # error log6(M^-1 M_ref) = -log6(M_ref^-1 M)
        error = pin.log6(placement.actInv(self.reference_placement)).vector
        kernels.pd_task_rows(
            self.target, self.jacobian, _SPATIAL, error,
            pin.getFrameJacobian(model, data, frame_id, pin.LOCAL), v,
            pin.getFrameAcceleration(model, data, frame_id, pin.LOCAL).vector,
            _ZERO_MOTION, _ZERO_MOTION, self._stiffness, self._damping,
        )  # fmt: skip


def _init_contact(
    contact, robot, frame, friction_coefficient, min_normal_force, max_normal_force, stiffness,
    damping,
) -> None:  # fmt: skip
    """Check and set what every contact has: frame, friction, normal-force bounds, gains."""
    kind = type(contact).__name__
    if frame not in robot.foot_frames:
        raise InvalidInputError(
            f"{kind}: frame={frame!r} is not a foot frame of {robot.name!r}; "
            f"expected one of {robot.foot_frames}"
        )
    mu = _array(friction_coefficient, "friction_coefficient")
    if mu.shape != () or not (np.isfinite(mu) and mu > 0):
        raise InvalidInputError(
            f"{kind}: friction_coefficient must be finite and > 0, got {friction_coefficient!r}"
        )
    forces = _array([min_normal_force, max_normal_force], "min_normal_force/max_normal_force")
    if forces.shape != (2,) or not 0 <= forces[0] < forces[1] < np.inf:
        raise InvalidInputError(
            f"{kind}: expected finite 0 <= min_normal_force < max_normal_force, got "
            f"{min_normal_force!r} and {max_normal_force!r}"
        )
    contact.model = robot.model
    contact.frame = frame
    contact.frame_id = robot.model.getFrameId(frame)
    contact.friction_coefficient = float(friction_coefficient)
    contact.min_normal_force, contact.max_normal_force = float(forces[0]), float(forces[1])
    contact._stiffness, contact._damping = np.zeros(6), np.zeros(6)  # the gains, per component
    contact.stiffness = stiffness
    contact.damping = 2.0 * np.sqrt(contact.stiffness) if damping is None else damping
    contact.reference_placement = None


class PointContact:
    r"""A point foot held still on the ground, its force in a linearised friction pyramid.

    The force :math:`f` is expressed in world axes at the foot point. The QP keeps the point's
    acceleration at :math:`a^* = K_p (p_{\mathrm{ref}} - p) - K_d \dot p` (Baumgarte
    stabilisation, zero for a foot at rest at its reference) and imposes
    :math:`|f_x|, |f_y| \le (\mu/\sqrt 2) f_z` (the pyramid inscribed in the cone of
    coefficient :math:`\mu`) and :math:`f_{\min} \le f_z \le f_{\max}`. On a planar robot
    (``robot.base == "planar"``, motion in the x-z plane) only :math:`(f_x, f_z)` exist, with
    :math:`|f_x| \le \mu f_z`: the out-of-plane rows are not formed.

    Parameters
    ----------
    robot : RobotModel
        The robot.
    frame : str
        Foot frame (one of ``robot.foot_frames``), its origin the contact point.
    friction_coefficient : float
        :math:`\mu`.
    min_normal_force, max_normal_force : float
        Bounds on :math:`f_z` [N].
    stiffness, damping : float
        Baumgarte gains pulling the foot back to its reference position.
    """

    def __init__(
        self,
        robot,
        frame: str,
        friction_coefficient: float = 0.7,
        min_normal_force: float = 1.0,
        max_normal_force: float = 5000.0,
        stiffness: float = 10.0,
        damping: float | None = None,
    ):
        _init_contact(
            self, robot, frame, friction_coefficient, min_normal_force, max_normal_force,
            stiffness, damping,
        )  # fmt: skip
        planar = robot.base == "planar"
        self.components = np.array([0, 2] if planar else [0, 1, 2], dtype=np.int64)
        self.n_force = self.components.size
        self.normal_index = self.n_force - 1
        mu = self.friction_coefficient if planar else self.friction_coefficient / np.sqrt(2.0)
        tangential = np.eye(self.n_force)[:-1]
        self.wrench_matrix = np.vstack(
            [
                np.hstack([tangential[:, :-1], np.full((self.n_force - 1, 1), -mu)]),
                np.hstack([-tangential[:, :-1], np.full((self.n_force - 1, 1), -mu)]),
                -np.eye(self.n_force)[-1:],  # f_z >= f_min
                np.eye(self.n_force)[-1:],  # f_z <= f_max
            ]
        )
        self.wrench_upper = np.zeros(self.wrench_matrix.shape[0])
        self.wrench_upper[-2:] = -self.min_normal_force, self.max_normal_force
        self.jacobian = np.zeros((self.n_force, robot.nv))
        self.target = np.zeros(self.n_force)
        self._error = np.zeros(6)

    stiffness = SoleContact.stiffness
    damping = SoleContact.damping
    cone_margin = SoleContact.cone_margin

    def contact_jacobian(self, data: pin.Data) -> np.ndarray:
        """The contact rows' Jacobian (world axes), shape (n_force, nv)."""
        jacobian = pin.getFrameJacobian(self.model, data, self.frame_id, _LWA)
        return jacobian[self.components]

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Point Jacobian (world axes) and desired point acceleration minus drift."""
        model, frame_id = self.model, self.frame_id
        placement = pin.updateFramePlacement(model, data, frame_id)
        if self.reference_placement is None:
            self.reference_placement = placement.copy()
        error = self._error
        np.subtract(self.reference_placement.translation, placement.translation, out=error[:3])
        kernels.pd_task_rows(
            self.target, self.jacobian, self.components, error,
            pin.getFrameJacobian(model, data, frame_id, _LWA), v,
            pin.getFrameClassicalAcceleration(model, data, frame_id, _LWA).vector,
            _ZERO_MOTION, _ZERO_MOTION, self._stiffness, self._damping,
        )  # fmt: skip
