r"""Rigid contacts of the inverse-dynamics QP: flat soles and point feet.

A :class:`SoleContact` holds a sole still (a 6-D rigid contact) and bounds its contact wrench
to a linearised friction cone with centre-of-pressure bounds. A :class:`PointContact` holds a
point foot still with a force in a linearised friction pyramid (3-D, or in-plane on a planar
robot). Both expose the same interface to the controller: ``n_force`` unknowns, ``update``
writing ``jacobian`` and ``target`` (the contact rows :math:`J \ddot q = a^* - \dot J \dot q`
with the Baumgarte law :math:`a^*` of :mod:`dmpopt.control.tasks`), ``contact_jacobian`` and
the cone rows ``wrench_matrix f <= wrench_upper`` whose last two rows bound the normal force:
:math:`-f_n \le -f_{\min}` and :math:`f_n \le f_{\max}`.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError

from . import kernels
from .tasks import _array, _gain

__all__ = ["PointContact", "SoleContact"]

_LWA = pin.LOCAL_WORLD_ALIGNED
_SPATIAL = np.arange(6)
_ZERO_MOTION = np.zeros(6)


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
        if len(robot.sole_corners) == 0:
            raise InvalidInputError(
                f"SoleContact: robot {robot.name!r} has no sole_corners, so the sole's extent is "
                "unknown; build it with RobotModel.from_urdf(..., feet={frame: None}) (soles from "
                "the collision geometry) or feet={frame: [[x, y], ...]} (corners in the foot frame)"
            )
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
