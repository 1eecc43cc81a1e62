r"""Constraint groups of a constrained fit: which samples of which quantity, within which limits.

A plan is stored as ``values`` of shape (3, n_steps, k): positions, velocities and
accelerations at every sample (``k`` DOFs for a trajectory, ``k`` weights for the response
of an :class:`~dmpopt.dmp.AffinePlan`). A group reads one quantity with :func:`sample`,
either at every sample or interpolated linearly at one time; jerk is the forward finite
difference of the accelerations (:mod:`dmpopt.metrics`). Because :func:`sample` is linear,
the same call gives a group's constraint rows (on the weight response), their offset (on the
free plan) and, after the solve, the constrained values on the rollout.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..exceptions import InvalidInputError
from ..trajectory import Trajectory
from .requests import Bounds, bound_limits, per_dof

QUANTITIES = ("position", "velocity", "acceleration", "jerk")
END_CONDITIONS = ("end_position", "end_velocity", "end_acceleration")


def sample(values: np.ndarray, dt: float, quantity: str, at=None) -> np.ndarray:
    """``quantity`` of ``values`` (3, n_steps, k): at every sample, or at ``at = (i, a)``.

    ``at`` interpolates between samples ``i`` and ``i + 1`` with weight ``a`` on the second;
    the result then has one row.
    """
    if quantity == "jerk":
        series = np.diff(values[2], axis=0) / dt
    else:
        series = values[QUANTITIES.index(quantity)]
    if at is None:
        return series
    i, a = at
    return ((1 - a) * series[i] + a * series[i + 1])[None, :]


def interpolation(time_value: float, dt: float, n_steps: int, name: str) -> tuple[int, float]:
    """``(i, a)``: ``time_value`` lies a fraction ``a`` of the way from sample ``i`` to ``i+1``."""
    position = time_value / dt
    if position < -1e-9 or position > n_steps - 1 + 1e-9:
        raise InvalidInputError(
            f"{name} time {time_value} s is outside the plan [0, {dt * (n_steps - 1)}] s"
        )
    i = int(min(np.floor(position + 1e-9), n_steps - 2))
    return i, float(np.clip(position - i, 0.0, 1.0))


@dataclass(frozen=True, eq=False)
class ConstraintGroup:
    """Rows of the (per-DOF) constraint matrix that encode one request.

    Attributes
    ----------
    name : str
        ``"position"``, ``"velocity"``, ``"acceleration"``, ``"jerk"``, ``"via_point[i]"``,
        ``"end_position"``, ``"end_velocity"`` or ``"end_acceleration"``.
    quantity : str
        The quantity it limits, one of :data:`QUANTITIES`.
    at : tuple or None
        ``(i, a)`` for one interpolated time (:func:`sample`), ``None`` for every sample.
    lower, upper : ndarray, shape (n_rows, n_dofs)
        Requested limits [physical units], ``-inf``/``inf`` for a free side.
    unit : float
        The physical size of one scaled unit of these rows: ``L``, ``L/T``, ``L/T^2`` or
        ``L/T^3`` (``L`` the motion's extent, ``T`` its duration); 0 until assembled.
    rows : slice
        Its rows in the constraint matrix (None until assembled).
    """

    name: str
    quantity: str
    at: tuple | None
    lower: np.ndarray
    upper: np.ndarray
    unit: float = 0.0
    rows: slice | None = None

    def excess(self, values: np.ndarray, dt: float) -> float:
        """Largest violation on ``values`` (3, n_steps, n_dofs) [physical units], 0 if none."""
        measured = sample(values, dt, self.quantity, self.at)
        excess = np.maximum(self.lower - measured, measured - self.upper)
        return float(max(np.max(excess, initial=0.0), 0.0))


class BallViaPoint(NamedTuple):
    """A Euclidean via-point: ``||y(at) - point|| <= radius`` (non-linear: solved as an NLP)."""

    at: tuple
    point: np.ndarray
    radius: float


def _group(name, quantity, at, lower, upper, n_rows: int, n_dofs: int) -> ConstraintGroup:
    lower = np.broadcast_to(lower, (n_rows, n_dofs)).astype(float)
    upper = np.broadcast_to(upper, (n_rows, n_dofs)).astype(float)
    if np.isnan(lower).any() or np.isnan(upper).any():  # NaN would read as "no limit"
        raise InvalidInputError(f"the bounds of '{name}' contain NaN; give finite limits")
    return ConstraintGroup(name, quantity, at, lower, upper)


def limit_groups(bounds: Bounds | None, n_steps: int, n_dofs: int) -> list[ConstraintGroup]:
    """Limits at every sample (jerk: between samples)."""
    return [
        _group(name, quantity, None, lower, upper, n_steps - (quantity == "jerk"), n_dofs)
        for name, quantity, lower, upper in bound_limits(bounds, n_dofs)
    ]


def via_point_groups(via_points, dt: float, n_steps: int, n_dofs: int) -> tuple[list, list]:
    """Box via-points as groups ``"via_point[i]"``, Euclidean ones as :class:`BallViaPoint`."""
    groups, balls = [], []
    for i, via in enumerate(via_points):
        point = per_dof(f"via_points[{i}].position", via.position, n_dofs)
        at = interpolation(via.time, dt, n_steps, f"via_points[{i}]")
        if via.norm == "ball":
            balls.append(BallViaPoint(at, point, float(via.tolerance[0])))
            continue
        tolerance = per_dof(f"via_points[{i}].tolerance", via.tolerance, n_dofs)
        groups.append(
            _group(
                f"via_point[{i}]", "position", at, point - tolerance, point + tolerance, 1, n_dofs
            )
        )
    return groups, balls


def end_groups(goal, tolerances, n_steps: int) -> list[ConstraintGroup]:
    """Boxes on ``y(T) - g``, ``yd(T)``, ``ydd(T)`` at the last sample; ``None`` skips one."""
    centres = (goal, np.zeros_like(goal), np.zeros_like(goal))
    last = (n_steps - 2, 1.0)
    return [
        _group(name, QUANTITIES[k], last, centre - tolerance, centre + tolerance, 1, goal.size)
        for k, (name, centre, tolerance) in enumerate(zip(END_CONDITIONS, centres, tolerances))
        if tolerance is not None
    ]


def violations(groups, balls, trajectory: Trajectory) -> dict:
    """Largest violation of each group and Euclidean via-point on ``trajectory`` [units].

    Computed from the trajectory's samples (jerk by finite differences) with the requested
    limits (no safety margin), not from the QP.
    """
    values = np.stack([trajectory.positions, trajectory.velocities, trajectory.accelerations])
    dt = float(np.mean(np.diff(trajectory.times)))
    result = {group.name: group.excess(values, dt) for group in groups}
    for i, ball in enumerate(balls):
        position = sample(values, dt, "position", ball.at)[0]
        result[f"via_point_ball[{i}]"] = float(
            max(np.linalg.norm(position - ball.point) - ball.radius, 0.0)
        )
    return result


__all__ = [
    "BallViaPoint",
    "ConstraintGroup",
    "QUANTITIES",
    "end_groups",
    "interpolation",
    "limit_groups",
    "sample",
    "via_point_groups",
    "violations",
]
