r"""Minimum-jerk baselines for point-to-point movements [Flash1985]_.

Three baselines, each returning a :class:`~dmpopt.trajectory.Trajectory`:

:func:`minimum_jerk`
    The closed-form rest-to-rest optimum, a 5th-order polynomial in :math:`s = t / T`:

    .. math:: y(t) = y_0 + (g - y_0)(10 s^3 - 15 s^4 + 6 s^5).

:func:`minimum_jerk_via_points`
    The exact optimum through via-points: one quintic per segment; position, velocity and
    acceleration given at both ends (rest), the position at each via-point, and the first four
    derivatives continuous there (the optimality conditions of :math:`\int \dddot y^2 dt`).

:func:`minimum_jerk_constrained`
    The optimum under the same bounds and via-points as a constrained DMP fit, as a QP: the
    jerk is piecewise constant on ``n_segments`` equal intervals, so positions, velocities and
    accelerations at every sample are linear in it, and the cost
    :math:`\int \dddot y^2 dt = h \sum_i j_i^2` is exact. Solved with
    :func:`dmpopt.fitting.qp.solve_blocks` per DOF, the QP layer of the constrained DMP fit.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple, Sequence

import numpy as np

from ..exceptions import InfeasibleProblem, InvalidInputError, ShapeError
from ..trajectory import Trajectory
from ..validation import MEMORY_BUDGET, check_resources, integer, real, real_array, sequence_of
from .groups import QUANTITIES, end_groups, limit_groups, sample
from .qp import scale_rows, solve_blocks, stack_rows
from .requests import Bounds, ViaPoint, check_bounds, per_dof

MIN_SEGMENT_FRACTION = 0.01
"""Via-points must be at least this fraction of the duration away from each other and from
both ends. In time normalised by the duration, the via-point system's condition number grows
like ``(duration / gap) ** 5`` (about 1e11 at 1 %), and the optimum's peak acceleration like
``(duration / gap) ** 2`` times the plain movement's (1e4 at 1 %): closer via-points give
numbers that no robot can follow (a via-point 1e-12 s after the start gave positions of 1e22)."""


def _grid(duration, dt, n_samples, n_dofs: int) -> np.ndarray:
    duration = real("duration", duration, minimum=0.0, open_minimum=True)
    if n_samples is None:
        dt = real(
            "dt",
            dt,
            minimum=0.0,
            maximum=duration / 2,
            open_minimum=True,
            fix="or give n_samples",
        )
        estimate = duration / dt + 1
        check_resources(
            f"sampling {duration:g} s every {dt:g} s ({n_dofs} DOFs)",
            8.0 * (4 * estimate * n_dofs),
            "raise dt or shorten the duration",
        )
        n_samples = int(round(duration / dt)) + 1
    else:
        n_samples = integer(
            "n_samples",
            n_samples,
            minimum=3,
            maximum=MEMORY_BUDGET // (32 * n_dofs),
            fix="sample more coarsely",
        )
    return np.linspace(0.0, duration, n_samples)


def _endpoints(start, goal):
    start = np.atleast_1d(real_array("start", start))
    goal = np.atleast_1d(real_array("goal", goal))
    if start.ndim != 1 or start.shape != goal.shape:
        raise ShapeError(
            f"start has shape {start.shape} and goal {goal.shape}; expected both (n_dofs,)"
        )
    return start, goal


def minimum_jerk(
    start, goal, duration: float, dt: float | None = 0.001, *, n_samples: int | None = None
) -> Trajectory:
    r"""Closed-form rest-to-rest minimum-jerk movement (5th-order polynomial).

    Parameters
    ----------
    start, goal : array_like, shape (n_dofs,)
    duration : float
        [s]
    dt : float
        Sample step [s] (ignored if ``n_samples`` is given).
    n_samples : int, optional
        Number of samples on ``[0, duration]``.
    """
    start, goal = _endpoints(start, goal)
    times = _grid(duration, dt, n_samples, start.size)
    s = times / times[-1]
    shape = 10 * s**3 - 15 * s**4 + 6 * s**5
    rate = (30 * s**2 - 60 * s**3 + 30 * s**4) / times[-1]
    curvature = (60 * s - 180 * s**2 + 120 * s**3) / times[-1] ** 2
    delta = goal - start
    return Trajectory(
        times, start + shape[:, None] * delta, rate[:, None] * delta, curvature[:, None] * delta
    )


def _quintic_rows(t, derivative: int) -> np.ndarray:
    """Rows of ``d^k/dt^k [1, t, ..., t^5]`` at ``t`` (a float: shape (6,); an array: (n, 6))."""
    t = np.asarray(t, dtype=float)
    rows = np.zeros(t.shape + (6,))
    for power in range(derivative, 6):
        factor = np.prod(np.arange(power - derivative + 1, power + 1)) if derivative else 1.0
        rows[..., power] = factor * t ** (power - derivative)
    return rows


def _via_knots(via_points, duration: float) -> tuple:
    """Via-points sorted by time and the knots ``0, t_1, ..., duration``; gaps checked."""
    vias = sorted(sequence_of("via_points", via_points, ViaPoint), key=lambda via: via.time)
    knots = np.array([0.0] + [via.time for via in vias] + [duration])
    gap = MIN_SEGMENT_FRACTION * duration
    # a gap of exactly MIN_SEGMENT_FRACTION of the duration passes, whatever its rounding
    too_close = np.nonzero(np.diff(knots) < gap * (1 - 1e-9))[0]
    if too_close.size:
        k = int(too_close[0])
        raise InvalidInputError(
            f"via_points: times {knots[k]:.12g} s and {knots[k + 1]:.12g} s (counting the start 0 "
            f"and the end {duration:g} s) are closer than {MIN_SEGMENT_FRACTION:g} of the "
            f"duration ({gap:g} s); the optimum through them would need absurd accelerations. "
            "Spread the via-points, drop one or lengthen the duration"
        )
    return vias, knots


def minimum_jerk_via_points(
    start,
    goal,
    duration: float,
    via_points: Sequence[ViaPoint],
    dt: float | None = 0.001,
    *,
    n_samples: int | None = None,
) -> Trajectory:
    """Exact rest-to-rest minimum-jerk movement through via-points (tolerances ignored).

    Piecewise quintic; at each via-point the position is prescribed and velocity,
    acceleration, jerk and snap are continuous. Solved in time normalised by the duration.

    Raises
    ------
    InvalidInputError
        If two via-points, or a via-point and an end, are closer than
        :data:`MIN_SEGMENT_FRACTION` of the duration (hence at most 99 via-points).
    """
    start, goal = _endpoints(start, goal)
    times = _grid(duration, dt, n_samples, start.size)
    total = float(times[-1])
    vias, knots = _via_knots(via_points, total)
    knots = knots / total  # normalised time: conditioning independent of the duration
    n_segments = len(knots) - 1
    n_dofs = start.size
    points = [per_dof(f"via_points[{i}].position", v.position, n_dofs) for i, v in enumerate(vias)]
    size = 6 * n_segments
    system = np.zeros((size, size))
    rhs = np.zeros((size, n_dofs))
    row = 0
    # rest at both ends: position, velocity, acceleration
    for k in range(3):
        system[row, 0:6] = _quintic_rows(0.0, k)
        rhs[row] = start if k == 0 else 0.0
        row += 1
        last = knots[-1] - knots[-2]
        system[row, 6 * (n_segments - 1) : 6 * n_segments] = _quintic_rows(last, k)
        rhs[row] = goal if k == 0 else 0.0
        row += 1
    # via-points: position on both sides, derivatives 1-4 continuous (local time per segment)
    for i, point in enumerate(points):
        length = knots[i + 1] - knots[i]
        left, right = slice(6 * i, 6 * i + 6), slice(6 * i + 6, 6 * i + 12)
        system[row, left] = _quintic_rows(length, 0)
        rhs[row] = point
        row += 1
        system[row, right] = _quintic_rows(0.0, 0)
        rhs[row] = point
        row += 1
        for k in range(1, 5):
            system[row, left] = _quintic_rows(length, k)
            system[row, right] = -_quintic_rows(0.0, k)
            row += 1
    coefficients = np.linalg.solve(system, rhs)
    normalised = times / total
    segment = np.clip(np.searchsorted(knots, normalised, side="right") - 1, 0, n_segments - 1)
    local = normalised - knots[segment]
    blocks = coefficients.reshape(n_segments, 6, n_dofs)[segment]  # (n, 6, d)
    values = [np.einsum("nc,ncd->nd", _quintic_rows(local, k), blocks) / total**k for k in range(3)]
    return Trajectory(times, *values)


class MinimumJerkReport(NamedTuple):
    """Solver outcome of :func:`minimum_jerk_constrained`."""

    solve_time: float  # [s]
    iterations: int
    violations: dict


def _ramp(x: np.ndarray, power: int) -> np.ndarray:
    return np.maximum(x, 0.0) ** power / math.factorial(power)


def jerk_response(times: np.ndarray, n_segments: int) -> np.ndarray:
    """Positions, velocities, accelerations per unit jerk on each segment, (3, n, n_segments).

    Jerk ``j_i`` constant on ``[t_i, t_{i+1})``, equal segments over ``[0, times[-1]]``, from
    rest: e.g. the position response is :math:`R_3(t - t_i) - R_3(t - t_{i+1})` with
    :math:`R_k(x) = \\max(x, 0)^k / k!`.
    """
    times = real_array("times", times, ndim=1)
    n_segments = integer("n_segments", n_segments, minimum=1)
    check_resources(
        f"jerk responses at {times.size} times for {n_segments} segments",
        8.0 * (3 * times.size * n_segments),
        "lower n_segments or use fewer times",
    )
    return _response(times.tobytes(), n_segments).copy()


@lru_cache(maxsize=4)  # an entry holds 3 x n_samples x n_segments floats
def _response(times: bytes, n_segments: int) -> np.ndarray:
    """:func:`jerk_response` of the float64 ``times`` (as bytes), read-only; one per grid:
    a search over via-points (e.g. the constrained study's) solves many QPs on one grid."""
    times = np.frombuffer(times)
    knots = np.linspace(0.0, times[-1], n_segments + 1)
    begin = times[:, None] - knots[None, :-1]
    end = times[:, None] - knots[None, 1:]
    response = np.stack([_ramp(begin, p) - _ramp(end, p) for p in (3, 2, 1)])
    response.setflags(write=False)
    return response


def _box_via_points(via_points, duration: float) -> tuple:
    """``via_points`` checked: box via-points within the duration."""
    via_points = sequence_of("via_points", via_points, ViaPoint)
    for i, via in enumerate(via_points):
        if via.norm != "box":
            raise InvalidInputError(
                f"via_points[{i}] has norm {via.norm!r}; minimum_jerk_constrained takes 'box' "
                "via-points only"
            )
        if via.time > duration:
            raise InvalidInputError(
                f"via_points[{i}].time = {via.time:g} s is after the end ({duration:g} s); "
                "give a time within the duration"
            )
    return via_points


class _ViaRow(NamedTuple):
    """A box via-point as one exact row of the jerk response (no interpolation)."""

    name: str
    row: np.ndarray  # (1, n_segments)
    lower: np.ndarray  # (n_dofs,)
    upper: np.ndarray


def _via_rows(via_points, duration: float, n_segments: int, n_dofs: int) -> list[_ViaRow]:
    if not via_points:
        return []
    # the position rows at every via time from one call (the last time fixes the segments)
    times = np.array([0.0, *(via.time for via in via_points), duration])
    positions = jerk_response(times, n_segments)[0]
    rows = []
    for i, via in enumerate(via_points):
        point = per_dof(f"via_points[{i}].position", via.position, n_dofs)
        tolerance = per_dof(f"via_points[{i}].tolerance", via.tolerance, n_dofs)
        row = positions[i + 1 : i + 2]
        rows.append(_ViaRow(f"via_point[{i}]", row, point - tolerance, point + tolerance))
    return rows


def _length_scale(start, goal, via_points) -> float:
    """Extent of the motion: of start, goal and via-points together."""
    points = np.vstack([start, goal] + [np.atleast_1d(v.position) for v in via_points])
    return float(max(np.abs(goal - start).max(), np.ptp(points, axis=0).max(), 1e-12))


def _constraint_rows(groups, vias, response, free, step, start, units, margin):
    """Scaled rows of the groups (sampled) and of the via-points (exact), one block per DOF."""
    jerk_unit = units["jerk"]
    parts = []
    for group in groups:
        matrix = sample(response, step, group.quantity, group.at) * jerk_unit
        offset = sample(free, step, group.quantity, group.at)
        parts.append(
            scale_rows(matrix, offset, group.lower, group.upper, units[group.quantity], margin)
        )
    for via in vias:
        parts.append(
            scale_rows(
                via.row * jerk_unit, start[None, :], via.lower, via.upper, units["position"], margin
            )
        )
    return stack_rows(parts, response.shape[2], start.size)


def _violations(groups, vias, values, jerks, step, start) -> dict:
    """Largest violation of each request on the answer [physical units]."""
    violations = {group.name: group.excess(values, step) for group in groups}
    for via in vias:
        sample_ = start[None, :] + via.row @ jerks
        excess = np.maximum(via.lower - sample_, sample_ - via.upper)
        violations[via.name] = float(max(np.max(excess, initial=0.0), 0.0))
    return violations


def minimum_jerk_constrained(
    start,
    goal,
    duration: float,
    *,
    bounds: Bounds | None = None,
    via_points: Sequence[ViaPoint] = (),
    dt: float | None = 0.001,
    n_samples: int | None = None,
    n_segments: int = 60,
    margin: float = 1e-6,
) -> tuple[Trajectory, MinimumJerkReport]:
    """Minimum-jerk rest-to-rest movement under bounds and via-points (QP).

    The same :class:`Bounds` and box :class:`ViaPoint` as the constrained DMP fit, held at
    every sample (via-points exactly at their time). Solved per DOF with
    :func:`dmpopt.fitting.qp.solve_blocks` (DAQP, qpOASES as fallback). Returns
    ``(trajectory, report)``.

    Raises
    ------
    InfeasibleProblem
        If the bounds and via-points cannot all hold within ``duration``.
    ResourceLimitError
        If the QP's matrices (about ``7 * n_samples * n_segments`` entries) would exceed
        20 million entries.
    """
    start, goal = _endpoints(start, goal)
    times = _grid(duration, dt, n_samples, start.size)
    n_dofs, duration = start.size, float(times[-1])
    step = times[1] - times[0]
    n_segments = integer("n_segments", n_segments, minimum=3)
    margin = real("margin", margin, minimum=0.0, maximum=0.1, fix="keep it tiny, e.g. 1e-6")
    bounds = check_bounds(bounds)
    via_points = _box_via_points(via_points, duration)
    check_resources(
        f"a minimum-jerk QP with {times.size} samples and {n_segments} jerk segments",
        8.0 * ((3 + 4) * times.size * n_segments),
        "lower n_segments or sample more coarsely (raise dt)",
    )
    response = _response(times.tobytes(), n_segments)  # checked above; read-only, shared
    vias = _via_rows(via_points, duration, n_segments, n_dofs)  # checks their sizes
    length = _length_scale(start, goal, via_points)
    units = dict(
        zip(QUANTITIES, [length, length / duration, length / duration**2, length / duration**3])
    )
    # free motion (jerk zero): at rest at the start
    free = np.zeros((3, times.size, n_dofs))
    free[0] = start
    # end conditions (at the goal, at rest), limits at every sample, via-points
    groups = end_groups(goal, (0.0, 0.0, 0.0), times.size) + limit_groups(
        bounds, times.size, n_dofs
    )
    rows = _constraint_rows(groups, vias, response, free, step, start, units, margin)
    qp = solve_blocks(
        np.eye(n_segments),
        np.zeros((n_dofs, n_segments)),
        rows.matrix,
        rows.lower,
        rows.upper,
        solver="daqp",
    )
    if not qp.success:
        raise InfeasibleProblem(
            f"minimum-jerk movement infeasible on DOF {qp.failed_block} ({qp.status}): the "
            "bounds and via-points cannot all hold within the duration; relax them or lengthen it",
            stats={"status": qp.status},
        )
    jerks = qp.x.T * units["jerk"]
    values = free + response @ jerks
    trajectory = Trajectory(times, values[0], values[1], values[2])
    violations = _violations(groups, vias, values, jerks, step, start)
    return trajectory, MinimumJerkReport(qp.solve_time, qp.iterations, violations)


__all__ = [
    "MinimumJerkReport",
    "jerk_response",
    "minimum_jerk",
    "minimum_jerk_constrained",
    "minimum_jerk_via_points",
]
