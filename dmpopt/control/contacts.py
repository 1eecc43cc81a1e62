r"""Rigid contacts of the inverse-dynamics QP: one :class:`Contact` base, one class per kind.

A contact holds a frame still (the contact rows :math:`J \ddot q = a^* - \dot J \dot q`, with
the Baumgarte law :math:`a^*` of :mod:`dmpopt.control.tasks`) and adds ``n_force`` unknowns,
its wrench or force, bounded by the cone rows ``wrench_matrix f <= wrench_upper``.
A new kind of contact is one subclass of :class:`Contact` that

- sets ``n_force`` and ``normal_index`` (which force component is the normal force),
- returns its friction (and centre-of-pressure) rows and their names from
  :meth:`Contact.friction_rows` (the base appends the two normal-force rows
  :math:`-f_n \le -f_{\min}` and :math:`f_n \le f_{\max}` last, which the controller's
  transitions move),
- fills ``jacobian`` and ``target`` in :meth:`Contact.update` and gives
  :meth:`Contact.contact_jacobian`.

The kinds dmpopt ships: :class:`SoleContact` (a flat sole, 6-D wrench), :class:`PointContact`
(a point foot, force in world axes) and :class:`SurfaceContact` (a point, e.g. a hand, pressing
on a surface of any normal).
"""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError

from . import kernels
from .tasks import _array, _frame_in_joint, _gain, _support_columns, joint_views

__all__ = ["Contact", "PointContact", "SoleContact", "SurfaceContact"]

_LWA = pin.LOCAL_WORLD_ALIGNED
_SPATIAL = np.arange(6)
_LINEAR = np.arange(3)
_ZERO_MOTION = np.zeros(6)


class Contact:
    r"""Base class of a rigid contact: frame, friction, normal-force bounds, Baumgarte gains.

    Parameters
    ----------
    robot : RobotModel
        The robot.
    frame : str
        The contact frame (a frame of ``robot.model``).
    friction_coefficient : float
        :math:`\mu`.
    min_normal_force, max_normal_force : float
        Bounds on the normal force :math:`f_n` [N].
    stiffness, damping : float
        Baumgarte gains pulling the frame back to its reference placement [1/s^2], [1/s];
        damping defaults to critical, :math:`2 \sqrt{K_p}`.

    Attributes
    ----------
    n_force : int
        Force unknowns (class attribute or set by the subclass).
    normal_index : int
        Index of the normal force in the contact's force vector.
    force_names : tuple of str
        Names of the force unknowns (``("fx", "fy", "fz", "tx", "ty", "tz")`` for a sole).
    wrench_matrix, wrench_upper : ndarray
        The cone rows :math:`C f \le u`, the normal-force rows last.
    row_names : tuple of str
        One name per cone row (what :func:`~dmpopt.control.active_constraints` prints).
    jacobian, target : ndarray, shapes (n_force, nv) and (n_force,)
        The contact rows of the last :meth:`update`.
    reference_placement : pinocchio.SE3 or None
        Placement held; None: the frame's placement at the next update.
    """

    n_force: int
    normal_index: int
    force_names: tuple[str, ...] = ()
    _release = "the contact is about to release"  # what a binding minimum normal force means

    def __init__(
        self, robot, frame: str, friction_coefficient: float = 0.7,
        min_normal_force: float = 1.0, max_normal_force: float = 5000.0,
        stiffness: float = 10.0, damping: float | None = None,
    ):  # fmt: skip
        kind = type(self).__name__
        if not isinstance(frame, str) or not robot.model.existFrame(frame):
            raise InvalidInputError(
                f"{kind}: frame={frame!r} is not a frame of {robot.name!r}; expected a frame "
                f"name of robot.model (feet: {robot.foot_frames})"
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
        self.model = robot.model
        self.frame = frame
        self.frame_id = robot.model.getFrameId(frame)
        self.friction_coefficient = float(friction_coefficient)
        self.min_normal_force, self.max_normal_force = float(forces[0]), float(forces[1])
        self._gains = np.zeros((2, 6))  # the gains Kp, Kd, per component
        self._stiffness, self._damping = self._gains
        self.stiffness = stiffness
        self.damping = 2.0 * np.sqrt(self.stiffness) if damping is None else damping
        self.reference_placement = None
        self.jacobian = np.zeros((self.n_force, robot.nv))
        self.target = np.zeros(self.n_force)
        if len(self.force_names) != self.n_force:
            self.force_names = tuple(f"f{k}" for k in range(self.n_force))

    @functools.cached_property
    def _cone(self) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
        """Cone rows from :meth:`friction_rows` and the two normal-force rows, built on first
        use (after the subclass's ``__init__`` has set its geometry)."""
        friction, names = self.friction_rows()
        normal = np.eye(self.n_force)[self.normal_index]
        matrix = np.vstack([np.asarray(friction, dtype=float), -normal, normal])
        upper = np.zeros(matrix.shape[0])
        upper[-2:] = -self.min_normal_force, self.max_normal_force
        lift = f"minimum normal force of {self.frame} ({self._release})"
        return matrix, upper, (*names, lift, f"maximum normal force of {self.frame}")

    wrench_matrix = property(lambda self: self._cone[0], doc="Cone rows C, shape (m, n_force).")
    wrench_upper = property(lambda self: self._cone[1], doc="Cone bounds u, shape (m,).")
    row_names = property(lambda self: self._cone[2], doc="One name per cone row.")

    def friction_rows(self) -> tuple[np.ndarray, list[str]]:
        """Rows ``C f <= 0`` other than the normal-force bounds (friction, centre of
        pressure), shape (m, n_force), and one name per row."""
        raise NotImplementedError(f"{type(self).__name__} must implement friction_rows")

    def contact_jacobian(self, data: pin.Data) -> np.ndarray:
        """The contact rows' Jacobian, shape (n_force, nv), from the joint Jacobians in
        ``data`` (used once, to choose the joints the elimination solves for)."""
        raise NotImplementedError(f"{type(self).__name__} must implement contact_jacobian")

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Fill :attr:`jacobian` and :attr:`target` for the state in ``data`` (after
        ``computeAllTerms``); set ``reference_placement`` if None."""
        raise NotImplementedError(f"{type(self).__name__} must implement update")

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

    def __getstate__(self) -> dict:
        """A copy (pickle, deepcopy) makes its own views of the point it holds (_hold_point):
        views into the original's placements would not follow the copy's."""
        state = self.__dict__.copy()
        if "_point_views" in state:
            state["_point_views"] = (None, None)
        return state

    def normal_force(self, wrench: np.ndarray) -> float:
        """The normal force [N] of a wrench (or force) of this contact."""
        return float(np.asarray(wrench, dtype=float)[self.normal_index])

    def cone_margin(self, wrench: np.ndarray) -> np.ndarray:
        """Slack ``u - C f`` of each cone row for a wrench; >= 0 inside the cone."""
        return self.wrench_upper - self.wrench_matrix @ np.asarray(wrench, dtype=float)

    def placement(self, data: pin.Data) -> pin.SE3:
        """The frame's placement in ``data`` (after the kinematics); it becomes
        ``reference_placement`` if that is None."""
        placement = pin.updateFramePlacement(self.model, data, self.frame_id)
        if self.reference_placement is None:
            self.reference_placement = placement.copy()
        return placement


class SoleContact(Contact):
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
        Sole frame, one of ``robot.foot_frames``, e.g. ``"left_sole_link"``.
    friction_coefficient, min_normal_force, max_normal_force, stiffness, damping
        As :class:`Contact`.
    cop_fraction : float
        Fraction (0, 1] of the sole's extent (about the frame origin) the centre of pressure
        may use. On compliant ground a centre of pressure on the sole's edge unloads the
        opposite edge and the foot starts to roll; 0.7 keeps it clear of the edges.
    """

    n_wrench_rows = 12
    n_force = 6  #: wrench unknowns
    normal_index = 2  #: index of the normal force f_z in the wrench
    force_names = ("fx", "fy", "fz", "tx", "ty", "tz")
    _release = "the foot is about to lift"

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
        if frame not in robot.foot_frames:
            raise InvalidInputError(
                f"SoleContact: frame={frame!r} is not a foot frame of {robot.name!r}; "
                f"expected one of {robot.foot_frames} (the sole rectangle belongs to the feet)"
            )
        super().__init__(
            robot, frame, friction_coefficient, min_normal_force, max_normal_force, stiffness,
            damping,
        )  # fmt: skip
        fraction = _array(cop_fraction, "cop_fraction")
        if fraction.shape != () or not 0 < fraction <= 1:
            raise InvalidInputError(f"cop_fraction must be in (0, 1], got {cop_fraction!r}")
        self.cop_fraction = float(fraction)
        if len(robot.sole_corners) == 0:
            raise InvalidInputError(
                f"SoleContact: robot {robot.name!r} has no sole_corners, so the sole's extent is "
                "unknown; build it with RobotModel.from_urdf(..., feet={frame: None}) (soles from "
                "the collision geometry) or feet={frame: [[x, y], ...]} (corners in the foot frame)"
            )
        corners = self.cop_fraction * np.asarray(robot.sole_corners)
        self.x_min, self.y_min = corners[:, :2].min(axis=0)
        self.x_max, self.y_max = corners[:, :2].max(axis=0)
        # Packed (kernels.frame_rows): out (target, error log6(M^-1 M_ref) of the last
        # update); jacobians (rows, frame Jacobian: its other columns stay zero); indices
        # (the 6 rows, the supporting columns); the frame's parent joint and placement in it.
        self._out = np.zeros(12)
        self.target, self._error = self._out[:6], self._out[6:]
        self._jacobians = np.zeros((12, robot.nv))
        self.jacobian, self._frame_jacobian = self._jacobians[:6], self._jacobians[6:]
        self._indices = np.concatenate([_SPATIAL, _support_columns(robot.model, self.frame_id)])
        self._joint, self._placement = _frame_in_joint(robot.model, self.frame_id)
        self._rows_kernel = kernels.Binding(kernels.frame_rows)

    def friction_rows(self) -> tuple[np.ndarray, list[str]]:
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
            ]
        )
        names = [f"friction cone of {self.frame} ({axis})" for axis in ("+x", "-x", "+y", "-y")]
        names += [
            f"CoP of {self.frame} at its {edge} edge" for edge in ("toe", "heel", "left", "right")
        ]
        names += [f"yaw friction of {self.frame} ({sign}z)" for sign in "+-"]
        return matrix, names

    def contact_jacobian(self, data: pin.Data) -> np.ndarray:
        """The contact rows' Jacobian (LOCAL), shape (6, nv), from the joint Jacobians in
        ``data``."""
        return pin.getFrameJacobian(self.model, data, self.frame_id, pin.LOCAL)

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Sole Jacobian (LOCAL) and desired sole acceleration minus drift (one compiled call,
        :func:`kernels.frame_rows`), the error log6(M^-1 M_ref) = -log6(M_ref^-1 M)."""
        if self.reference_placement is None:
            self.placement(data)
        reference = self.reference_placement
        if not self._rows_kernel(
            v, self._out, self._jacobians, self._indices, self._gains, reference.rotation,
            reference.translation, *joint_views(data, self._joint), self._placement, True,
            data.J, v,
        ):  # fmt: skip
            self._near_half_turn(v, data)

    def _near_half_turn(self, v: np.ndarray, data: pin.Data) -> None:
        """:meth:`update` for a rotation error near pi (the frame Jacobian written): the
        error by Pinocchio's log6."""
        model, frame_id = self.model, self.frame_id
        placement = pin.updateFramePlacement(model, data, frame_id)
        drift = pin.getFrameAcceleration(model, data, frame_id, pin.LOCAL).vector
        self._error[:] = pin.log6(placement.actInv(self.reference_placement)).vector
        kernels.pd_task_rows(
            self.target, self.jacobian, _SPATIAL, self._error, self._frame_jacobian, v, drift,
            _ZERO_MOTION, _ZERO_MOTION, self._stiffness, self._damping,
        )  # fmt: skip


class PointContact(Contact):
    r"""A point foot held still on the ground, its force in a linearised friction pyramid.

    The force :math:`f` is expressed in world axes at the frame's origin. The QP keeps the
    point's acceleration at :math:`a^* = K_p (p_{\mathrm{ref}} - p) - K_d \dot p` (Baumgarte
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
        The contact frame (e.g. one of ``robot.foot_frames``), its origin the contact point.
    friction_coefficient, min_normal_force, max_normal_force, stiffness, damping
        As :class:`Contact`.
    """

    _release = "the foot is about to lift"

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
        planar = robot.base == "planar"
        self.components = np.array([0, 2] if planar else [0, 1, 2], dtype=np.int64)
        self.n_force = self.components.size
        self.normal_index = self.n_force - 1
        self.force_names = ("fx", "fz") if planar else ("fx", "fy", "fz")
        super().__init__(
            robot, frame, friction_coefficient, min_normal_force, max_normal_force, stiffness,
            damping,
        )  # fmt: skip
        self._error = np.zeros(6)
        self._point_views = (None, None)  # see _hold_point

    def friction_rows(self) -> tuple[np.ndarray, list[str]]:
        planar = self.n_force == 2
        mu = self.friction_coefficient if planar else self.friction_coefficient / np.sqrt(2.0)
        tangential = np.eye(self.n_force)[:-1]
        slope = np.full((self.n_force - 1, 1), -mu)
        matrix = np.vstack(
            [np.hstack([tangential[:, :-1], slope]), np.hstack([-tangential[:, :-1], slope])]
        )
        axes = "x" if planar else "xy"
        names = [f"friction cone of {self.frame} ({s}{a})" for s in "+-" for a in axes]
        return matrix, names

    def contact_jacobian(self, data: pin.Data) -> np.ndarray:
        """The contact rows' Jacobian (world axes), shape (n_force, nv)."""
        jacobian = pin.getFrameJacobian(self.model, data, self.frame_id, _LWA)
        return jacobian[self.components]

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Point Jacobian (world axes) and desired point acceleration minus drift."""
        _hold_point(self, v, data, self.target, self.jacobian, self.components)


class SurfaceContact(Contact):
    r"""A point (a hand, a fingertip, a tool tip) pressing on a surface of any orientation.

    The force is expressed in surface axes :math:`(t_1, t_2, n)`: :math:`n` the surface's unit
    normal pointing towards the robot (the direction the surface pushes), :math:`t_1, t_2`
    tangent to it. The QP holds the point still, :math:`a^* = K_p (p_{\mathrm{ref}} - p) - K_d
    \dot p` in world axes as :class:`PointContact`, and imposes
    :math:`|f_{t_1}|, |f_{t_2}| \le (\mu/\sqrt 2) f_n` and
    :math:`f_{\min} \le f_n \le f_{\max}`: a hand on a table has :math:`n = (0, 0, 1)`, a hand
    on a wall in front of the robot :math:`n = (-1, 0, 0)`. A ``min_normal_force`` above 0
    makes the robot press with at least that force.

    Parameters
    ----------
    robot : RobotModel
        The robot (3-D; not planar).
    frame : str
        The frame whose origin touches the surface (e.g. one of ``robot.hand_frames``).
    normal : array_like, shape (3,)
        The surface normal in world axes (normalised here).
    friction_coefficient, min_normal_force, max_normal_force, stiffness, damping
        As :class:`Contact`; ``min_normal_force`` defaults to 0.

    Attributes
    ----------
    axes : ndarray, shape (3, 3)
        Columns :math:`t_1, t_2, n` in world axes.
    """

    n_force = 3
    normal_index = 2
    force_names = ("ft1", "ft2", "fn")
    _release = "the point is about to leave the surface"

    def __init__(
        self,
        robot,
        frame: str,
        normal=(0.0, 0.0, 1.0),
        friction_coefficient: float = 0.7,
        min_normal_force: float = 0.0,
        max_normal_force: float = 5000.0,
        stiffness: float = 10.0,
        damping: float | None = None,
    ):
        if robot.base == "planar":
            raise InvalidInputError(
                "SurfaceContact needs a 3-D robot; on a planar robot use PointContact"
            )
        n = _array(normal, "normal")
        length = float(np.linalg.norm(n)) if n.shape == (3,) else 0.0
        if not (np.isfinite(length) and length > 1e-9):
            raise InvalidInputError(
                f"SurfaceContact: normal must be a finite non-zero 3-vector, got {normal!r}"
            )
        super().__init__(
            robot, frame, friction_coefficient, min_normal_force, max_normal_force, stiffness,
            damping,
        )  # fmt: skip
        n = n / length
        helper = np.eye(3)[int(np.argmin(np.abs(n)))]  # the world axis least along n
        t1 = np.cross(helper, n)
        t1 /= np.linalg.norm(t1)
        self.axes = np.column_stack([t1, np.cross(n, t1), n])
        self._world_jacobian = np.zeros((3, robot.nv))
        self._world_target = np.zeros(3)
        self._error = np.zeros(6)
        self._point_views = (None, None)  # see _hold_point

    def friction_rows(self) -> tuple[np.ndarray, list[str]]:
        mu = self.friction_coefficient / np.sqrt(2.0)
        matrix = np.array([[1.0, 0.0, -mu], [0.0, 1.0, -mu], [-1.0, 0.0, -mu], [0.0, -1.0, -mu]])
        names = [f"friction cone of {self.frame} ({s}t{i})" for s in "+-" for i in "12"]
        return matrix, names

    def contact_jacobian(self, data: pin.Data) -> np.ndarray:
        """The contact rows' Jacobian (surface axes), shape (3, nv)."""
        jacobian = pin.getFrameJacobian(self.model, data, self.frame_id, _LWA)
        return self.axes.T @ jacobian[:3]

    def update(self, q: np.ndarray, v: np.ndarray, data: pin.Data) -> None:
        """Point Jacobian and desired acceleration minus drift, in surface axes."""
        _hold_point(self, v, data, self._world_target, self._world_jacobian, _LINEAR)
        np.dot(self.axes.T, self._world_jacobian, out=self.jacobian)
        np.dot(self.axes.T, self._world_target, out=self.target)


def _hold_point(contact, v, data, target, jacobian, components) -> None:
    """Rows ``components`` (world axes) that hold ``contact``'s frame origin at its reference:
    ``jacobian`` the point Jacobian, ``target`` :math:`K_p (p_{ref} - p) - K_d \\dot p - \\dot J
    \\dot q` (the classical acceleration's drift), both filled in place."""
    model, frame_id = contact.model, contact.frame_id
    if contact.reference_placement is None:
        contact.placement(data)  # it takes the reference
    else:
        pin.updateFramePlacement(model, data, frame_id)
    # p_ref - p through views made once per reference and data (Pinocchio's translations are
    # views of their placements; a placement changed in place is seen through them)
    views = contact._point_views
    if views[0] is not contact.reference_placement or views[1] is not data:
        reference = contact.reference_placement
        views = contact._point_views = (
            reference, data, reference.translation, data.oMf[frame_id].translation,
            contact._error[:3],
        )  # fmt: skip
    np.subtract(views[2], views[3], out=views[4])
    kernels.pd_task_rows(
        target, jacobian, components, contact._error,
        pin.getFrameJacobian(model, data, frame_id, _LWA), v,
        pin.getFrameClassicalAcceleration(model, data, frame_id, _LWA).vector,
        _ZERO_MOTION, _ZERO_MOTION, contact._stiffness, contact._damping,
    )  # fmt: skip
