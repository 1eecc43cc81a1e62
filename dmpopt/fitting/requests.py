"""What a constrained plan must respect: :class:`Bounds` at every sample and :class:`ViaPoint`.

The same requests serve the constrained DMP fit (:mod:`dmpopt.fitting.constrained`) and the
minimum-jerk baselines (:mod:`dmpopt.fitting.minimum_jerk`). :func:`bound_limits` turns a
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
    :class:`dmpopt.learning.tasks.ViaPointReward`.)

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


__all__ = ["Bounds", "Limit", "ViaPoint", "bound_limits", "check_bounds", "per_dof"]
