r"""Two hands on one object: a coupling of two Cartesian DMPs that holds their relative pose.

A box held by both hands stays held while the pose of the right hand in the left hand's frame
stays what it was at the grasp: position :math:`r^*` and orientation :math:`q^*`. Two
:class:`dmpopt.CartesianDMP` (one per hand) plan the hands; the coupling term of this module
pulls each plan towards that relative pose, in the spirit of the bimanual coupling terms of
Gams, Nemec, Ijspeert and Ude [Gams2014]_ (our formulation below: a spring-damper on the
relative pose error, split between the hands).

Relative pose error, in the world frame (hand poses :math:`(p_L, R_L)`, :math:`(p_R, R_R)`,
world-frame velocities :math:`v` and angular velocities :math:`\omega`):

.. math::

    e_p = p_R - p_L - R_L r^*, \qquad
    \dot e_p = v_R - v_L - \omega_L \times (R_L r^*),

    R_e = R_R (R_L R^*)^\top, \qquad e_o = \log(R_e) \in \mathbb{R}^3, \qquad
    \omega_e = \omega_R - R_e\, \omega_L,

:math:`e_o` the rotation vector from the right hand's orientation the grasp asks for to its
current one, :math:`\omega_e` the world-frame angular velocity of :math:`R_e`
(:math:`\dot R_e = [\omega_e]_\times R_e`).

Coupling accelerations (world frame), with ``share`` :math:`\lambda` the part of the
correction the right hand makes and :math:`1 - \lambda` the left hand's:

.. math::

    a_R = -\lambda (k_p e_p + d_p \dot e_p), \qquad a_L = (1 - \lambda)(k_p e_p + d_p \dot e_p),

    \alpha_R = -\lambda (k_o e_o + d_o \omega_e), \qquad
    \alpha_L = (1 - \lambda)(k_o e_o + d_o \omega_e).

They enter each hand's transformation system as its coupling term on :math:`\tau \dot z`
(eqs. (5), (10); :meth:`dmpopt.CartesianStepper.step`), where a term :math:`C` adds
:math:`C / \tau^2` to the acceleration: :math:`C = \tau^2 a` on the position and
:math:`C = \tau^2 J(e)^{-1} \alpha` on the orientation's log coordinates :math:`e`
(:math:`\omega = J(e)\dot e`, :mod:`dmpopt.cartesian`).

What this gives, plainly: for two hands whose DMPs share their forcing term, time constant
and gains, with goals :math:`r^*` apart and fixed orientations, the relative position error
obeys the linear system

.. math:: \tau^2 \ddot e_p + (\alpha_z \tau + d_p \tau^2) \dot e_p + (\alpha_z \beta_z + k_p
    \tau^2) e_p = 0,

the DMP's own spring :math:`\alpha_z\beta_z` stiffened by :math:`k_p \tau^2`; a perturbation
of one hand (a new goal, another speed) moves the relative pose by a factor
:math:`\alpha_z\beta_z / (\alpha_z\beta_z + k_p\tau^2)` of what it would without coupling
(statically). With :math:`d = 2\sqrt{k}` (the default) and :math:`\beta_z = \alpha_z / 4`
the system stays overdamped. The coupling uses the plans' states, not measured poses: it
shapes the plans, the robot's controller tracks them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .cartesian import CartesianDMP, CartesianStepper, near_side, unit_quaternions
from .exceptions import InvalidInputError
from .validation import real, vector

HANDS = ("left", "right")


def rotation_matrix(quaternion) -> np.ndarray:
    """The rotation matrix of a unit quaternion ``(w, x, y, z)``, shape (3, 3)."""
    w, x, y, z = quaternion
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _cross(a, b) -> np.ndarray:
    """``a x b`` of two 3-vectors (NumPy's cross is slow on single vectors)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def matrix_quaternion(rotation: np.ndarray) -> np.ndarray:
    """The unit quaternion ``(w, x, y, z)`` of a rotation matrix, with ``w >= 0``."""
    quaternion = pin.Quaternion(rotation)
    wxyz = np.array([quaternion.w, quaternion.x, quaternion.y, quaternion.z])
    return -wxyz if wxyz[0] < 0.0 else wxyz


def left_jacobian_inverse(rotation) -> np.ndarray:
    r""":math:`J(e)^{-1}` of the left Jacobian of SO(3) (:math:`\omega = J(e)\dot e`), shape
    (3, 3): :math:`I - \frac12 [e]_\times + \left(\frac{1}{\theta^2} - \frac{1 + \cos\theta}
    {2\theta\sin\theta}\right)[e]_\times^2`, :math:`\theta = |e| < 2\pi` (its series
    :math:`\frac{1}{12} + \frac{\theta^2}{720}` near 0)."""
    e = np.asarray(rotation, dtype=float)
    theta = float(np.linalg.norm(e))
    skew = pin.skew(e)
    if theta < 1e-4:
        factor = 1.0 / 12.0 + theta**2 / 720.0
    else:
        factor = 1.0 / theta**2 - (1.0 + np.cos(theta)) / (2.0 * theta * np.sin(theta))
    return np.eye(3) - 0.5 * skew + factor * skew @ skew


@dataclass(frozen=True, eq=False)
class RelativePoseCoupling:
    r"""Coupling term holding the right hand's pose in the left hand's frame (module docstring).

    Attributes
    ----------
    relative_position : ndarray, shape (3,)
        :math:`r^*`, the right hand's position in the left hand's frame [m].
    relative_orientation : ndarray, shape (4,)
        :math:`q^*`, the right hand's orientation in the left hand's frame, ``(w, x, y, z)``.
    stiffness, damping : float
        :math:`k_p` [1/s^2] and :math:`d_p` [1/s] on the position error; damping defaults to
        :math:`2\sqrt{k_p}`.
    angular_stiffness, angular_damping : float
        :math:`k_o` [1/s^2] and :math:`d_o` [1/s] on the orientation error; defaults
        ``stiffness`` and :math:`2\sqrt{k_o}`.
    share : float
        :math:`\lambda \in [0, 1]`, the part of the correction made by the right hand (0.5:
        both alike; 1: the right hand follows the left).
    """

    relative_position: np.ndarray
    relative_orientation: np.ndarray
    stiffness: float = 1000.0
    damping: float | None = None
    angular_stiffness: float | None = None
    angular_damping: float | None = None
    share: float = 0.5

    def __post_init__(self):
        position = vector("relative_position", self.relative_position, 3, "a 3-D position")
        orientation = unit_quaternions("relative_orientation", self.relative_orientation, (4,))
        stiffness = real("stiffness", self.stiffness, minimum=0.0)
        angular = stiffness if self.angular_stiffness is None else self.angular_stiffness
        angular = real("angular_stiffness", angular, minimum=0.0)
        damping = 2.0 * np.sqrt(stiffness) if self.damping is None else self.damping
        angular_damping = (
            2.0 * np.sqrt(angular) if self.angular_damping is None else self.angular_damping
        )
        values = {
            "relative_position": position,
            "relative_orientation": orientation,
            "stiffness": stiffness,
            "damping": real("damping", damping, minimum=0.0),
            "angular_stiffness": angular,
            "angular_damping": real("angular_damping", angular_damping, minimum=0.0),
            "share": real("share", self.share, minimum=0.0, maximum=1.0),
        }
        for array in (position, orientation):
            array.setflags(write=False)
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @classmethod
    def from_poses(
        cls, left_position, left_orientation, right_position, right_orientation, **gains
    ) -> RelativePoseCoupling:
        """The coupling that holds the relative pose of the given hand poses (e.g. the grasp).

        Positions in [m], orientations as unit quaternions ``(w, x, y, z)``; ``gains`` are the
        other attributes (``stiffness``, ``share``, ...).
        """
        left_position = vector("left_position", left_position, 3, "a 3-D position")
        right_position = vector("right_position", right_position, 3, "a 3-D position")
        left = rotation_matrix(unit_quaternions("left_orientation", left_orientation, (4,)))
        right = rotation_matrix(unit_quaternions("right_orientation", right_orientation, (4,)))
        return cls(
            relative_position=left.T @ (right_position - left_position),
            relative_orientation=matrix_quaternion(left.T @ right),
            **gains,
        )

    def error(self, left_pose, right_pose) -> tuple[np.ndarray, np.ndarray]:
        r"""World-frame relative pose error :math:`(e_p, e_o)` [m, rad], each shape (3,).

        ``left_pose`` and ``right_pose`` are ``(position, orientation)`` pairs (orientation a
        unit quaternion ``(w, x, y, z)``).
        """
        (p_left, q_left), (p_right, q_right) = left_pose, right_pose
        left, right = rotation_matrix(q_left), rotation_matrix(q_right)
        position = np.asarray(p_right) - np.asarray(p_left) - left @ self.relative_position
        wanted = left @ rotation_matrix(self.relative_orientation)
        return position, pin.log3(right @ wanted.T)

    def accelerations(self, left_state, right_state) -> tuple[np.ndarray, ...]:
        r"""Coupling accelerations :math:`(a_L, \alpha_L, a_R, \alpha_R)`, world frame
        [m/s^2, rad/s^2], each shape (3,).

        Each state is ``(position, velocity, orientation, angular_velocity)`` of one hand
        (world frame; orientation ``(w, x, y, z)``).
        """
        p_left, v_left, q_left, w_left = (np.asarray(x, dtype=float) for x in left_state)
        p_right, v_right, q_right, w_right = (np.asarray(x, dtype=float) for x in right_state)
        left, right = rotation_matrix(q_left), rotation_matrix(q_right)
        arm = left @ self.relative_position
        error = p_right - p_left - arm
        rate = v_right - v_left - _cross(w_left, arm)
        error_rotation = right @ (left @ rotation_matrix(self.relative_orientation)).T
        angle = pin.log3(error_rotation)
        angular_rate = w_right - error_rotation @ w_left
        linear = self.stiffness * error + self.damping * rate
        angular = self.angular_stiffness * angle + self.angular_damping * angular_rate
        right_share, left_share = self.share, 1.0 - self.share
        return (
            left_share * linear,
            left_share * angular,
            -right_share * linear,
            -right_share * angular,
        )


def relative_pose_error(coupling: RelativePoseCoupling, left_pose, right_pose) -> tuple:
    """Size of the relative pose error: ``(|e_p|, |e_o|)`` [m, rad] (module docstring)."""
    position, rotation = coupling.error(left_pose, right_pose)
    return float(np.linalg.norm(position)), float(np.linalg.norm(rotation))


class BimanualStepper:
    """Two :class:`dmpopt.CartesianStepper` (left and right hand) stepped together, coupled.

    Each :meth:`step` evaluates the coupling on both plans' current states and passes it to
    each stepper as its coupling term (module docstring); ``coupling=None`` steps the two
    plans independently (the comparison).

    Parameters
    ----------
    left, right : CartesianDMP
        The hands' plans (their time constants may differ).
    coupling : RelativePoseCoupling or None
    dt : float
        Step [s], at most each DMP's ``max_step``.
    compile : bool
        Compile the steppers to C (:class:`dmpopt.CartesianStepper`).

    Attributes
    ----------
    left, right : CartesianStepper
    """

    def __init__(
        self,
        left: CartesianDMP,
        right: CartesianDMP,
        coupling: RelativePoseCoupling | None,
        dt: float = 0.001,
        compile: bool = False,
    ):
        for name, dmp in (("left", left), ("right", right)):
            if not isinstance(dmp, CartesianDMP):
                raise InvalidInputError(f"{name} must be a CartesianDMP, got {type(dmp).__name__}")
        if coupling is not None and not isinstance(coupling, RelativePoseCoupling):
            raise InvalidInputError(
                f"coupling must be a RelativePoseCoupling or None, got {type(coupling).__name__}"
            )
        self.coupling = coupling
        self.left = CartesianStepper(left, dt, compile)
        self.right = CartesianStepper(right, dt, compile)
        self._goal_orientations = {"left": left.goal_orientation, "right": right.goal_orientation}

    def _stepper(self, hand: str) -> CartesianStepper:
        if hand not in HANDS:
            raise InvalidInputError(f"hand must be 'left' or 'right', got {hand!r}")
        return self.left if hand == "left" else self.right

    def set_goal(self, hand: str, position=None, orientation=None) -> None:
        """New goal of one hand (``"left"`` or ``"right"``), from the next step on."""
        stepper = self._stepper(hand)
        if orientation is not None:
            orientation = near_side(
                unit_quaternions("orientation", orientation, (4,)), stepper.orientation
            )
            self._goal_orientations[hand] = orientation
        stepper.set_goal(position, orientation)

    def state(self, hand: str) -> tuple:
        """``(position, velocity, orientation, angular_velocity)`` of one hand's plan."""
        stepper = self._stepper(hand)
        return stepper.position, stepper.velocity, stepper.orientation, stepper.angular_velocity

    def relative_pose_error(self) -> tuple[float, float]:
        """``(|e_p|, |e_o|)`` of the plans [m, rad]; needs a coupling (its :math:`r^*, q^*`)."""
        if self.coupling is None:
            raise InvalidInputError("relative_pose_error needs the coupling's relative pose")
        left, right = self.state("left"), self.state("right")
        return relative_pose_error(self.coupling, left[::2], right[::2])

    def _log_terms(self, hand: str, linear, angular) -> tuple[np.ndarray, np.ndarray]:
        """Coupling inputs of one stepper: :math:`\\tau^2 a`, :math:`\\tau^2 J(e)^{-1}\\alpha`."""
        stepper = self._stepper(hand)
        goal = rotation_matrix(self._goal_orientations[hand])
        log = pin.log3(rotation_matrix(stepper.orientation) @ goal.T)
        scale = stepper.dmp.tau**2
        return scale * linear, scale * (left_jacobian_inverse(log) @ angular)

    def step(self) -> None:
        """Advance both plans by ``dt`` (coupled if there is a coupling)."""
        if self.coupling is None:
            self.left.step()
            self.right.step()
            return
        a_left, alpha_left, a_right, alpha_right = self.coupling.accelerations(
            self.state("left"), self.state("right")
        )
        terms_left = self._log_terms("left", a_left, alpha_left)
        terms_right = self._log_terms("right", a_right, alpha_right)
        self.left.step(*terms_left)
        self.right.step(*terms_right)
