r"""Fall detection from the base pose, the ground contacts and the base's rotation speed.

Every simulation backend reports falls the same way: after each step it measures four numbers
of the robot's base (the body of the unactuated root joint) and asks
:meth:`FallDetector.check`, which returns a :class:`Fall` for the first threshold crossed:

=================  ====================================================  =====================
quantity           meaning                                               fall when
=================  ====================================================  =====================
``height``         base origin above the ground plane [m]                ``< min_height``
``tilt``           angle between the base's z axis and the world z [rad] ``> max_tilt``
``flight_time``    time since the last step with any contact point in    ``> max_flight_time``
                   contact [s]; 0 before the first touchdown
``spin``           norm of the base's angular velocity [rad/s]           ``> max_spin``
=================  ====================================================  =====================

A single foot lifting is normal, so only the loss of *all* contacts counts, and only for longer
than a flight phase. :meth:`FallDetector.for_standing_height` derives every threshold from one
length of the robot, the height :math:`h` of its base above its feet when standing straight:

.. math::

    h_{\min} = \tfrac12 h, \qquad
    T_{\mathrm{flight}} = \sqrt{2 (h - h_{\min}) / g}, \qquad
    \omega_{\max} = \sqrt{2 g / h}:

the time to free-fall from standing height to the fall height, and the largest angular speed
that a body toppling about its feet from standing reaches when it hits the ground (energy
:math:`m g h = \tfrac12 I \omega^2` with :math:`I \ge m h^2`, taking the centre of mass at
the base height). A base turning faster is not toppling but thrown around: balance and control
are lost, and catching it stops a simulation before the state diverges numerically.

Both backends (:class:`dmpopt.sim.Simulator`, :class:`dmpopt.sim.MujocoSimulator`) take the
same options (``falls``, ``fall_frame``, ``fall_height``) and turn them into thresholds and a
watched frame with :func:`fall_checks`, so the same robot with the same contact points falls
at the same thresholds on either. After each step a backend does::

    placement, spin = watched.measure(q, v)  # Pinocchio coordinates
    fall = detector.check(t, height, base_tilt(placement.rotation), t - last_contact_time, spin)
    if fall is not None:
        ...  # stop; fall.reason says why, e.g. "base height 0.31 m below 0.54 m"

and refuses to step on until ``reset``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError
from dmpopt.validation import real

__all__ = ["BaseFrame", "Fall", "FallDetector", "base_tilt", "fall_checks", "standing_height"]

STANDARD_GRAVITY = 9.81  # [m/s^2]


@dataclass(frozen=True)
class Fall:
    """The robot fell.

    Attributes
    ----------
    time : float
        Simulation time of the first state past a threshold [s].
    cause : {"height", "tilt", "no contact", "spin"}
        Which check of :class:`FallDetector` fired.
    value, threshold : float
        The measured quantity and its threshold, in the units of :class:`FallDetector`.
    reason : str
        Readable summary, e.g. ``"base tilted 62 deg > 45 deg"``.
    """

    time: float
    cause: str
    value: float
    threshold: float
    reason: str


@dataclass(frozen=True)
class FallDetector:
    """Thresholds of the fall checks; ``np.inf`` (``-np.inf`` for ``min_height``) disables one.

    Parameters
    ----------
    min_height : float
        Lowest base height above the ground [m].
    max_tilt : float
        Largest angle between the base's z axis and the world z axis [rad].
    max_flight_time : float
        Longest time with no contact point touching the ground [s].
    max_spin : float
        Largest angular speed of the base [rad/s].
    """

    min_height: float
    max_tilt: float = np.radians(45.0)
    max_flight_time: float = np.inf
    max_spin: float = np.inf

    def __post_init__(self):
        height = real(
            "min_height",
            self.min_height,
            finite=False,
            expected="a height [m], or -np.inf to disable",
        )
        if height == np.inf:
            raise InvalidInputError("min_height must be below +inf; pass -np.inf to disable")
        object.__setattr__(self, "min_height", height)
        for name in ("max_tilt", "max_flight_time", "max_spin"):
            bound = real(
                name,
                getattr(self, name),
                minimum=0.0,
                open_minimum=True,
                finite=False,
                expected="a bound > 0, or np.inf to disable",
            )
            object.__setattr__(self, name, bound)

    @classmethod
    def for_standing_height(
        cls, standing_height: float, max_tilt: float = np.radians(45.0)
    ) -> FallDetector:
        """Thresholds derived from the base height above the feet of the standing robot.

        Parameters
        ----------
        standing_height : float
            :math:`h`, base height above the feet with straight legs [m].
        max_tilt : float
            [rad]

        Returns
        -------
        FallDetector
            ``min_height = h / 2``, ``max_flight_time = sqrt(h / g)``,
            ``max_spin = sqrt(2 g / h)`` (module docstring), ``g = 9.81 m/s^2``.
        """
        standing_height = real(
            "standing_height",
            standing_height,
            minimum=0.0,
            open_minimum=True,
            expected="a height [m] > 0 of the base above the feet",
        )
        min_height = 0.5 * standing_height
        return cls(
            min_height=min_height,
            max_tilt=max_tilt,
            max_flight_time=np.sqrt(2.0 * (standing_height - min_height) / STANDARD_GRAVITY),
            max_spin=np.sqrt(2.0 * STANDARD_GRAVITY / standing_height),
        )

    def check(
        self, time: float, height: float, tilt: float, flight_time: float, spin: float
    ) -> Fall | None:
        """The first threshold crossed, in the order height, tilt, no contact, spin, or None.

        Parameters
        ----------
        time : float
            Time of the state [s], copied into the :class:`Fall`.
        height : float
            Base height above the ground [m].
        tilt : float
            Base tilt, e.g. :func:`base_tilt` [rad].
        flight_time : float
            Time since the last step with a contact [s]; 0 before the first touchdown.
        spin : float
            Norm of the base's angular velocity [rad/s].
        """
        if not math.isfinite(time + height + tilt + flight_time + spin):
            for name, value in zip(
                ("time", "height", "tilt", "flight_time", "spin"),
                (time, height, tilt, flight_time, spin),
            ):
                real(
                    name,
                    value,
                    expected="a finite number; the state diverged before the fall check",
                )
        if height < self.min_height:
            return Fall(
                time,
                "height",
                height,
                self.min_height,
                f"base height {height:.3f} m below {self.min_height:.3f} m",
            )
        if tilt > self.max_tilt:
            return Fall(
                time,
                "tilt",
                tilt,
                self.max_tilt,
                f"base tilted {np.degrees(tilt):.0f} deg > {np.degrees(self.max_tilt):.0f} deg",
            )
        if flight_time > self.max_flight_time:
            return Fall(
                time,
                "no contact",
                flight_time,
                self.max_flight_time,
                f"no contact for {flight_time:.2f} s > {self.max_flight_time:.2f} s",
            )
        if spin > self.max_spin:
            return Fall(
                time,
                "spin",
                spin,
                self.max_spin,
                f"base turning at {spin:.2f} rad/s > {self.max_spin:.2f} rad/s, faster than "
                "a toppling robot: balance lost",
            )
        return None


def base_tilt(rotation) -> float:
    """Angle between the z axis of a frame and the world z axis [rad], in [0, pi].

    Parameters
    ----------
    rotation : array_like, shape (3, 3)
        Orientation of the frame in the world.
    """
    return math.acos(min(1.0, max(-1.0, float(rotation[2, 2]))))


def _frame_id(model: pin.Model, name, argument: str) -> int:
    if not isinstance(name, str) or not model.existFrame(name):
        raise InvalidInputError(
            f"{argument}: frame {name!r} is not in the model {model.name!r}; pass one of "
            f"the names in [f.name for f in model.frames]"
        )
    return model.getFrameId(name)


class BaseFrame:
    """A frame on the base body (the body of the root joint), measured from ``(q, v)`` alone.

    Parameters
    ----------
    model : pinocchio.Model
        Robot whose root joint (``model.joints[1]``) is its floating base.
    frame : str, optional
        A frame of the base body, e.g. the pelvis; default: the root joint's frame.
    """

    def __init__(self, model: pin.Model, frame: str | None = None):
        self._free = model.joints[1].shortname() == "JointModelFreeFlyer"
        self._joint = model.joints[1]
        self._data = self._joint.createData()
        self._placement = model.jointPlacements[1]
        self._offset = pin.SE3.Identity()
        if frame is not None:
            placed = model.frames[_frame_id(model, frame, "fall_frame")]
            if placed.parentJoint != 1:
                raise InvalidInputError(
                    f"fall_frame {frame!r} is not on the base body (joint "
                    f"{model.names[1]!r}); pass a frame of the base, e.g. the pelvis"
                )
            self._offset = placed.placement

    def measure(self, q: np.ndarray, v: np.ndarray) -> tuple[pin.SE3, float]:
        """World placement of the frame and the norm of the base's angular velocity [rad/s]."""
        self._joint.calc(self._data, q, v)
        spin = math.hypot(*self._data.v.angular)
        return self._placement * self._data.M * self._offset, spin

    def height_tilt_spin(self, q: np.ndarray, v: np.ndarray) -> tuple[float, float, float]:
        """The frame's height above z = 0 [m], its tilt (:func:`base_tilt`) [rad] and the base's
        spin [rad/s]: :meth:`measure`'s numbers, in one compiled call for a free flyer."""
        if self._free:
            from dmpopt.sim.kernels import free_base_measure

            height, cosine, spin = free_base_measure(
                q,
                v,
                self._placement.rotation,
                self._placement.translation,
                self._offset.rotation,
                self._offset.translation,
            )
            return height, math.acos(min(1.0, max(-1.0, cosine))), spin
        placement, spin = self.measure(q, v)
        return float(placement.translation[2]), base_tilt(placement.rotation), spin


def standing_height(
    model: pin.Model, contact_points, base: BaseFrame, normal=(0.0, 0.0, 1.0)
) -> float:
    """Height of the watched base frame above the lowest contact point, neutral configuration.

    Parameters
    ----------
    model : pinocchio.Model
    contact_points : sequence of (str, array_like)
        ``(frame_name, offset_xyz)`` pairs, offset in the frame [m]; at least one.
    base : BaseFrame
        The watched frame.
    normal : array_like, shape (3,)
        Upward unit normal of the ground [-].

    Returns
    -------
    float
        Largest ``normal @ (base - point)`` over the points, at ``pinocchio.neutral(model)``
        (straight legs) [m].
    """
    q = pin.neutral(model)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    points = np.array(
        [
            data.oMf[_frame_id(model, name, f"contact_points[{i}]")].act(np.asarray(offset, float))
            for i, (name, offset) in enumerate(contact_points)
        ]
    )
    origin = base.measure(q, np.zeros(model.nv))[0].translation
    height = float(np.max((origin - points) @ np.asarray(normal, dtype=float)))
    if not height > 0:
        raise InvalidInputError(
            f"the base is {height:.3g} m above the lowest contact point in the neutral "
            "configuration, so fall thresholds cannot be derived from it; pass "
            "falls=FallDetector(min_height=...) or falls=False"
        )
    return height


def fall_checks(
    model: pin.Model,
    n_base_dofs: int,
    contact_points,
    falls,
    fall_frame,
    fall_height,
    normal=(0.0, 0.0, 1.0),
) -> tuple[FallDetector | None, BaseFrame | None]:
    """Thresholds and watched frame of a backend's fall options (checked), or ``(None, None)``.

    Parameters
    ----------
    model : pinocchio.Model
    n_base_dofs : int
        Unactuated velocity coordinates; falls need them to be all of the root joint's.
    contact_points : sequence of (str, array_like)
        The backend's (already checked) ``(frame_name, offset_xyz)`` pairs.
    falls : bool or FallDetector
        ``True``: :meth:`FallDetector.for_standing_height` of :func:`standing_height` when there
        are contact points, else only ``fall_height`` if given; ``False``: no checks; a
        :class:`FallDetector`: these thresholds.
    fall_frame : str or None
        Watched frame of the base body (default: the root joint's frame).
    fall_height : float or None
        Replaces ``min_height`` of the derived thresholds [m above the ground].
    normal : array_like, shape (3,)
        Upward unit normal of the ground [-].
    """
    if not (falls is True or falls is False or isinstance(falls, FallDetector)):
        raise InvalidInputError(f"falls must be True, False or a FallDetector, got {falls!r}")
    asked = fall_frame is not None or fall_height is not None or falls is not True
    if falls is False:
        if fall_frame is not None or fall_height is not None:
            raise InvalidInputError(
                "fall_frame or fall_height given with falls=False; drop them or the flag"
            )
        return None, None
    if not (model.njoints > 1 and model.joints[1].nv == n_base_dofs > 0):
        if asked:
            raise InvalidInputError(
                "fall detection needs a floating base: a free-flyer, planar or composite "
                f"root joint with all {n_base_dofs} base dofs; pass falls=False"
            )
        return None, None
    base = BaseFrame(model, fall_frame)
    if fall_height is not None:
        fall_height = real(
            "fall_height", fall_height, expected="a finite height [m] above the ground"
        )
    if isinstance(falls, FallDetector):
        if fall_height is not None:
            raise InvalidInputError(
                "fall_height given with falls=FallDetector(...); set min_height in the "
                "FallDetector instead"
            )
        return falls, base
    if len(contact_points):
        detector = FallDetector.for_standing_height(
            standing_height(model, contact_points, base, normal)
        )
        if fall_height is not None:
            detector = dataclasses.replace(detector, min_height=fall_height)
        return detector, base
    if fall_height is not None:
        return FallDetector(min_height=fall_height, max_tilt=np.inf), base
    return None, None


def refuse_floating_without_contacts(model, n_base_dofs, contact_points, falls, fall_height):
    """Refuse a floating base under gravity with nothing to stand on and no fall check.

    Such a robot falls through the floor and, without contact points, no standing height is
    known, so no fall would be reported. ``falls=False``, a :class:`FallDetector`, a
    ``fall_height`` or zero gravity say the floating is meant.
    """
    if (
        n_base_dofs
        and not len(contact_points)
        and falls is True
        and fall_height is None
        and np.any(model.gravity.linear != 0)
    ):
        raise InvalidInputError(
            f"the model has a floating base ({n_base_dofs} unactuated DOFs) but no "
            "contact_points: it would fall through the floor with no fall reported; pass "
            "contact_points=robot.contact_points (the sole corners of a RobotModel), or "
            "falls=False or a fall_height for a body meant to float"
        )
