"""What a constrained plan must respect: :class:`Bounds` at every sample and :class:`ViaPoint`.

The same requests serve the constrained DMP fit (:mod:`dmpopt.fitting.constrained`) and the
minimum-jerk baselines (:mod:`dmpopt.fitting.minimum_jerk`); :class:`TorqueLimits` and
:class:`Balance` are the robot requests of the dynamics-feasible fit
(:mod:`dmpopt.fitting.dynamics`). :func:`bound_limits` turns a
:class:`Bounds` into one ``(name, quantity, lower, upper)`` entry per limited quantity, so
both read the limits the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..exceptions import InvalidInputError, ShapeError
from ..validation import real, real_array

NORMS = ("box", "ball")


def _optional_array(name: str, value, positive: bool = False):
    if value is None:
        return None
    array = np.atleast_1d(real_array(name, value))
    if array.ndim != 1:
        raise ShapeError(f"{name} has shape {array.shape}, expected (n_dofs,) or a scalar")
    if positive and np.any(array <= 0.0):
        raise InvalidInputError(f"{name} must be positive, got {array.tolist()}")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class Bounds:
    """Limits that every sample of a plan must respect, per DOF (scalars broadcast).

    Attributes
    ----------
    position_lower, position_upper : array_like, shape (n_dofs,), optional
        Box on the positions.
    velocity, acceleration, jerk : array_like, shape (n_dofs,), optional
        Symmetric limits on the absolute velocity [unit/s], acceleration [unit/s^2] and
        finite-difference jerk [unit/s^3] (see :mod:`dmpopt.metrics`).
    """

    position_lower: np.ndarray | None = None
    position_upper: np.ndarray | None = None
    velocity: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    jerk: np.ndarray | None = None

    def __post_init__(self):
        for name in ("position_lower", "position_upper"):
            object.__setattr__(self, name, _optional_array(name, getattr(self, name)))
        for name in ("velocity", "acceleration", "jerk"):
            object.__setattr__(self, name, _optional_array(name, getattr(self, name), True))
        lower, upper = self.position_lower, self.position_upper
        if lower is not None and upper is not None and lower.size == upper.size:
            crossed = np.nonzero(lower > upper)[0]
            if crossed.size:
                d = int(crossed[0])
                raise InvalidInputError(
                    f"position_lower exceeds position_upper for DOF(s) {crossed.tolist()} "
                    f"({lower[d]:g} > {upper[d]:g}); give position_lower <= position_upper"
                )


@dataclass(frozen=True, eq=False)
class ViaPoint:
    """Pass through ``position`` at ``time`` (from the start of the plan) within ``tolerance``.

    A hard constraint. (A reinforcement-learning task rewards closeness to a point instead:
    :class:`dmpopt.learning.rewards.ViaPointReward`.)

    Attributes
    ----------
    time : float
        [s], between 0 and the plan's duration; the plan is interpolated linearly between
        its two neighbouring samples.
    position : array_like, shape (n_dofs,)
    tolerance : float or array_like, shape (n_dofs,)
        Half-width of the box (``norm="box"``, linear: QP) or radius of the ball
        (``norm="ball"``, a scalar: solved as an NLP).
    norm : {"box", "ball"}
    """

    time: float
    position: np.ndarray
    tolerance: float | np.ndarray = 0.0
    norm: str = "box"

    def __post_init__(self):
        object.__setattr__(self, "time", real("time", self.time, minimum=0.0))
        if self.position is None:
            raise InvalidInputError("position must be an array of real numbers, got None")
        object.__setattr__(self, "position", _optional_array("position", self.position))
        tolerance = np.atleast_1d(real_array("tolerance", self.tolerance))
        if tolerance.ndim != 1 or np.any(tolerance < 0.0):
            raise InvalidInputError(
                f"tolerance must be a number >= 0 or one per DOF, got {tolerance.tolist()}; "
                "give the half-width of the box (or the ball's radius)"
            )
        if not isinstance(self.norm, str) or self.norm not in NORMS:
            raise InvalidInputError(f"norm must be 'box' or 'ball', got {self.norm!r}")
        if self.norm == "ball" and tolerance.size != 1:
            raise InvalidInputError("a 'ball' via-point takes one scalar tolerance (its radius)")
        tolerance.setflags(write=False)
        object.__setattr__(self, "tolerance", tolerance)


@dataclass(frozen=True, eq=False)
class TorqueLimits:
    """Joint torques within their limits at every sample (a dynamics-feasible fit's request).

    Used by :func:`dmpopt.fitting.dynamics.build_dynamics_problem`, whose ``robot`` gives the
    model and, by default, the limits.

    Attributes
    ----------
    joints : sequence of str, optional
        The joints whose torques are limited (default: the joints the DMP drives).
    limit : float or array_like, shape (n_joints,), optional
        Symmetric limits [N m] (default: the robot's ``torque_limit`` of those joints).
    fraction : float
        The limits used are ``fraction * limit`` (0 < fraction <= 1), e.g. 0.9 to keep room
        for the feedback of the controller.
    """

    joints: tuple | None = None
    limit: np.ndarray | None = None
    fraction: float = 1.0

    def __post_init__(self):
        if self.joints is not None:
            joints = (self.joints,) if isinstance(self.joints, str) else tuple(self.joints)
            if not joints or not all(isinstance(name, str) for name in joints):
                raise InvalidInputError(
                    f"joints must be joint names (strings), got {self.joints!r}; pass None for "
                    "the joints the DMP drives"
                )
            object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "limit", _optional_array("limit", self.limit, True))
        object.__setattr__(
            self,
            "fraction",
            real("fraction", self.fraction, minimum=0.0, maximum=1.0, open_minimum=True),
        )


@dataclass(frozen=True, eq=False)
class Balance:
    """A standing robot stays balanced: the ground can supply the wrench the movement needs.

    The centre of pressure (CoP) of the net contact wrench stays ``cop_margin`` inside the
    support polygon (convex hull of the contact soles' corners) and the net horizontal force
    inside the friction pyramid inscribed in the cone of coefficient ``friction`` (module
    :mod:`dmpopt.fitting.dynamics`).

    Attributes
    ----------
    contacts : sequence of str, optional
        Sole frames on the ground, flat at one height (default: the robot's ``foot_frames``).
    cop_margin : float
        [m], >= 0.
    friction : float
        Coulomb coefficient, > 0.
    """

    contacts: tuple | None = None
    cop_margin: float = 0.0
    friction: float = 0.7

    def __post_init__(self):
        if self.contacts is not None:
            contacts = (self.contacts,) if isinstance(self.contacts, str) else tuple(self.contacts)
            if not contacts or not all(isinstance(name, str) for name in contacts):
                raise InvalidInputError(
                    f"contacts must be frame names (strings), got {self.contacts!r}; pass None "
                    "for the robot's feet"
                )
            object.__setattr__(self, "contacts", contacts)
        object.__setattr__(self, "cop_margin", real("cop_margin", self.cop_margin, minimum=0.0))
        object.__setattr__(
            self, "friction", real("friction", self.friction, minimum=0.0, open_minimum=True)
        )


def per_dof(name: str, value, n_dofs: int) -> np.ndarray:
    """``value`` as one entry per DOF: a single entry is repeated, else it must have n_dofs."""
    value = np.atleast_1d(value)
    if value.size == 1:
        return np.full(n_dofs, float(value.ravel()[0]))
    if value.shape != (n_dofs,):
        raise ShapeError(f"{name} has shape {value.shape}, expected ({n_dofs},) for {n_dofs} DOFs")
    return value


def check_bounds(bounds) -> Bounds | None:
    """``bounds`` if it is ``None`` or a :class:`Bounds`, else an error that shows how."""
    if bounds is not None and not isinstance(bounds, Bounds):
        raise InvalidInputError(
            f"bounds must be a Bounds, got {type(bounds).__name__}; "
            "write bounds=Bounds(velocity=..., acceleration=...)"
        )
    return bounds


class Limit(NamedTuple):
    """One limited quantity of a :class:`Bounds`, per DOF, ``-inf``/``inf`` for a free side."""

    name: str
    quantity: str
    lower: np.ndarray
    upper: np.ndarray


def bound_limits(bounds: Bounds | None, n_dofs: int) -> list[Limit]:
    """The limits of ``bounds``: position box, then velocity, acceleration, jerk if set."""
    if bounds is None:
        return []
    limits = []
    if bounds.position_lower is not None or bounds.position_upper is not None:
        low = -np.inf if bounds.position_lower is None else bounds.position_lower
        high = np.inf if bounds.position_upper is None else bounds.position_upper
        lower = per_dof("position_lower", low, n_dofs)
        upper = per_dof("position_upper", high, n_dofs)
        limits.append(Limit("position", "position", lower, upper))
    for name in ("velocity", "acceleration", "jerk"):
        value = getattr(bounds, name)
        if value is not None:
            limit = per_dof(name, value, n_dofs)
            limits.append(Limit(name, name, -limit, limit))
    return limits


__all__ = [
    "Balance",
    "Bounds",
    "Limit",
    "TorqueLimits",
    "ViaPoint",
    "bound_limits",
    "check_bounds",
    "per_dof",
]
