r"""Plan metrics shared by the constrained fits, the baselines and the retiming.

Jerk is not part of a DMP's plan (the plan carries positions, velocities and accelerations).
Everywhere in dmpopt it is the forward finite difference of the sampled accelerations,

.. math:: j_k = (\ddot y_{k+1} - \ddot y_k) / (t_{k+1} - t_k), \quad k = 0 \dots n - 2,

which is exact for plans whose acceleration is piecewise linear between samples (the
minimum-jerk QP baseline) and the honest average jerk over each step otherwise. For a
time-optimal (toppra) retiming the acceleration jumps between grid points, and the finite
difference reports those jumps divided by the step: large, as they are.
"""

from __future__ import annotations

import numpy as np

from . import validation
from .exceptions import InvalidInputError, ResourceLimitError, ShapeError
from .trajectory import Trajectory
from .validation import real_array

MAX_PAIRS = 1e9
"""Largest ``n * m`` (sample pairs) that :func:`path_distance` accepts (its time grows with it)."""


def _check_trajectory(trajectory) -> Trajectory:
    if not isinstance(trajectory, Trajectory):
        raise InvalidInputError(f"trajectory must be a Trajectory, got {type(trajectory).__name__}")
    return trajectory


def _samples(name: str, value, n_dofs: int | None = None) -> np.ndarray:
    """Positions as a finite (n, n_dofs) array with at least two samples."""
    array = real_array(name, value)
    if array.ndim != 2 or array.shape[0] < 2:
        raise ShapeError(f"{name} has shape {array.shape}, expected (n >= 2, n_dofs)")
    if n_dofs is not None and array.shape[1] != n_dofs:
        raise ShapeError(f"{name} has {array.shape[1]} DOFs, expected {n_dofs} like the other")
    return array


def _limit(name: str, value, n_dofs: int) -> np.ndarray:
    limit = np.atleast_1d(real_array(name, value))
    if limit.size == 1:
        limit = np.full(n_dofs, float(limit[0]))
    if limit.shape != (n_dofs,) or np.any(limit <= 0):
        raise InvalidInputError(
            f"{name} must be positive, one per DOF ({n_dofs}) or a scalar, got {limit.tolist()}"
        )
    return limit


def jerk(trajectory: Trajectory) -> np.ndarray:
    """Forward finite difference of the accelerations, shape (n_steps - 1, n_dofs)."""
    trajectory = _check_trajectory(trajectory)
    steps = np.diff(trajectory.times)[:, None]
    return np.diff(trajectory.accelerations, axis=0) / steps


def integrated_squared_jerk(trajectory: Trajectory) -> float:
    r"""Integral of the squared jerk norm, :math:`\sum_k \|j_k\|^2 (t_{k+1} - t_k)`."""
    steps = np.diff(trajectory.times)
    return float(np.sum(np.sum(jerk(trajectory) ** 2, axis=1) * steps))


def peak_velocity(trajectory: Trajectory) -> np.ndarray:
    """Largest absolute velocity per DOF, shape (n_dofs,)."""
    trajectory = _check_trajectory(trajectory)
    return np.max(np.abs(trajectory.velocities), axis=0)


def peak_acceleration(trajectory: Trajectory) -> np.ndarray:
    """Largest absolute acceleration per DOF, shape (n_dofs,)."""
    trajectory = _check_trajectory(trajectory)
    return np.max(np.abs(trajectory.accelerations), axis=0)


def limit_use(trajectory: Trajectory, velocity_limit=None, acceleration_limit=None) -> dict:
    """Peak velocity and acceleration as fractions of symmetric per-DOF limits.

    Returns ``{"velocity": float, "acceleration": float}`` (largest over DOFs; 1 means a
    limit is reached, above 1 that it is exceeded). Missing limits are left out.
    """
    n_dofs = _check_trajectory(trajectory).n_dofs
    use = {}
    if velocity_limit is not None:
        limit = _limit("velocity_limit", velocity_limit, n_dofs)
        use["velocity"] = float(np.max(peak_velocity(trajectory) / limit))
    if acceleration_limit is not None:
        limit = _limit("acceleration_limit", acceleration_limit, n_dofs)
        use["acceleration"] = float(np.max(peak_acceleration(trajectory) / limit))
    return use


def _closest_distances(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance of every point to the nearest point of a polyline (segments included).

    Only the segments that can be nearest are measured: segment ``j`` is at least
    ``|p - m_j| - h_j`` from ``p`` (midpoint ``m_j``, half length ``h_j``) and the nearest
    vertex is at most ``u`` away, so the candidates lie within ``u + max h`` of ``p`` (k-d
    trees of ``scipy.spatial``, a relative margin of 1e-9 for rounding). Each candidate pair
    is measured with the all-pairs formula, so the minimum is the same float.
    """
    from scipy.spatial import cKDTree

    start, end = polyline[:-1], polyline[1:]
    segment = end - start
    length2 = np.maximum(np.sum(segment**2, axis=1), 1e-300)
    nearest_vertex = cKDTree(polyline).query(points)[0]
    reach = nearest_vertex + 0.5 * np.sqrt(np.max(length2))
    reach = reach * (1.0 + 1e-9) + 1e-300
    candidates = cKDTree(0.5 * (start + end)).query_ball_point(points, reach)
    counts = np.array([len(c) for c in candidates])
    owner = np.repeat(np.arange(points.shape[0]), counts)
    first = np.concatenate([[0], np.cumsum(counts)])  # each point's first pair
    best = np.empty(points.shape[0])
    # four temporaries of pairs x n_dofs float64 values, within 1/16 of the budget
    pairs_per_chunk = validation.MEMORY_BUDGET // (16 * 32 * points.shape[1])
    step = max(1, int(pairs_per_chunk // counts.max()))
    for begin in range(0, points.shape[0], step):
        rows = slice(begin, min(begin + step, points.shape[0]))
        pairs = slice(first[rows.start], first[rows.stop])
        index = np.concatenate(candidates[rows]).astype(int)
        point = points[owner[pairs]]
        offset = point - start[index]
        fraction = np.clip(np.sum(offset * segment[index], axis=1) / length2[index], 0.0, 1.0)
        nearest = start[index] + fraction[:, None] * segment[index]
        distance = np.linalg.norm(point - nearest, axis=1)
        best[rows] = np.minimum.reduceat(distance, first[rows] - first[rows.start])
    return best


def path_distance(positions: np.ndarray, reference: np.ndarray) -> float:
    """Timing-free distance between two paths: symmetric mean closest-point distance.

    The mean, over the samples of each path, of the distance to the other path (taken as a
    polyline), averaged over both directions. Two timings of one path are at distance zero,
    which makes it the fair shape error for retimed plans.

    Parameters
    ----------
    positions, reference : ndarray, shape (n, n_dofs) and (m, n_dofs)
    """
    positions = _samples("positions", positions)
    reference = _samples("reference", reference, positions.shape[1])
    pairs = positions.shape[0] * reference.shape[0]
    if pairs > MAX_PAIRS:
        raise ResourceLimitError(
            f"path_distance compares every sample of each path with every segment of the "
            f"other: {positions.shape[0]} x {reference.shape[0]} = {pairs:.3g} pairs, above "
            f"the bound of {MAX_PAIRS:g}; subsample the paths"
        )
    forward = _closest_distances(positions, reference).mean()
    backward = _closest_distances(reference, positions).mean()
    return float(0.5 * (forward + backward))
