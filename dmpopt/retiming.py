r"""Time-optimal retiming of a plan's path with toppra [Pham2018]_, and uniform time scaling.

A DMP plan is a geometric path :math:`q(s)` traversed with the DMP's timing. :func:`retime`
keeps the path (a cubic spline through the plan's samples, with the plan's own time as path
parameter) and finds the fastest timing :math:`s(t)` under joint velocity and acceleration
limits, and optionally joint torque limits of a Pinocchio model, by reachability analysis
(toppra's TOPP-RA, constant :math:`\ddot s` between grid points).

Honest reporting: toppra's :math:`\ddot s` is piecewise constant, so the joint accelerations
jump between grid points and the jerk (finite differences, :mod:`dmpopt.metrics`) is large;
limits are met at toppra's grid points, and any excess found when the result is sampled
densely is removed by a uniform stretch of the retimed trajectory (reported as ``stretch``).

The DMP's own way to respect limits is to change :math:`\tau`: scaling time by ``c`` divides
velocities by ``c`` and accelerations by ``c^2`` (Section 3.3). :func:`uniform_time_scaling`
returns the smallest such ``c``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .exceptions import InvalidInputError, NoSolutionFound, ShapeError
from .trajectory import Trajectory
from .validation import check_resources, integer, real, real_array

_TOLERANCE = 1e-9
MAX_GRIDPOINTS = 100_000
"""Largest toppra grid :func:`retime` accepts (its time grows linearly with the grid)."""


STILL_TOLERANCE = 16 * np.finfo(float).eps
"""A DOF whose positions vary by at most this fraction of their magnitude stands still: its
velocities and accelerations are rounding (a constant path's, by finite differences, gave a
factor of 5.7e-14 where :func:`retime` refused)."""


def _check_trajectory(trajectory) -> Trajectory:
    if not isinstance(trajectory, Trajectory):
        raise InvalidInputError(
            f"trajectory must be a Trajectory, got {type(trajectory).__name__}; "
            "build one with Trajectory.from_positions(times, positions)"
        )
    return trajectory


def _limits(name: str, value, n_dofs: int):
    if value is None:
        return None
    value = np.atleast_1d(real_array(name, value))
    if value.size == 1:
        value = np.full(n_dofs, float(value[0]))
    if value.shape != (n_dofs,):
        raise ShapeError(f"{name} has shape {value.shape}, expected ({n_dofs},): one per DOF")
    if np.any(value <= 0):
        raise InvalidInputError(f"{name} must be positive, got {value.tolist()}")
    return value


def _robot_arguments(robot, torque_limit, n_dofs):
    import pinocchio as pin

    if (robot is None) != (torque_limit is None):
        raise InvalidInputError(
            "torque limits need both robot (a pinocchio.Model) and torque_limit"
        )
    if robot is None:
        return None, None
    if not isinstance(robot, pin.Model):
        raise InvalidInputError(f"robot must be a pinocchio.Model, got {type(robot).__name__}")
    if robot.nq != n_dofs or robot.nv != n_dofs:
        raise ShapeError(f"robot has nq = {robot.nq}, nv = {robot.nv}; the plan has {n_dofs} DOFs")
    return robot, _limits("torque_limit", torque_limit, n_dofs)


def time_scaled(trajectory: Trajectory, factor: float) -> Trajectory:
    """The same path ``factor`` times slower: ``t -> c t``, ``v -> v / c``, ``a -> a / c^2``.

    For a DMP this is exactly ``dmp.with_tau(c * tau)`` (Section 3.3).
    """
    trajectory = _check_trajectory(trajectory)
    factor = real("factor", factor, minimum=0.0, open_minimum=True)
    with np.errstate(all="ignore"):
        times = trajectory.times * factor
        velocities = trajectory.velocities / factor
        accelerations = trajectory.accelerations / factor**2
    if not all(np.all(np.isfinite(a)) for a in (times, velocities, accelerations)):
        raise InvalidInputError(
            f"factor = {factor!r} overflows the scaled times, velocities or accelerations; "
            "give a factor nearer 1"
        )
    return Trajectory(times, trajectory.positions, velocities, accelerations)


def _torque_parts(robot, trajectory: Trajectory):
    """Gravity ``g(q)`` and the rest ``M(q) a + C(q, v) v`` at every sample."""
    import pinocchio as pin

    data = robot.createData()
    zero = np.zeros(robot.nv)
    gravity = np.empty_like(trajectory.positions)
    dynamic = np.empty_like(trajectory.positions)
    for k, (q, v, a) in enumerate(
        zip(trajectory.positions, trajectory.velocities, trajectory.accelerations)
    ):
        gravity[k] = pin.rnea(robot, data, q, zero, zero)
        dynamic[k] = pin.rnea(robot, data, q, v, a) - gravity[k]
    return gravity, dynamic


def uniform_time_scaling(
    trajectory: Trajectory,
    velocity_limit=None,
    acceleration_limit=None,
    *,
    robot=None,
    torque_limit=None,
) -> float:
    r"""Smallest factor ``c`` such that ``time_scaled(trajectory, c)`` respects every limit.

    ``c < 1`` means the plan may be sped up. Velocities scale with :math:`1/c`,
    accelerations with :math:`1/c^2`, and torques as
    :math:`\tau = g(q) + (M(q)\ddot q + C(q,\dot q)\dot q) / c^2` (exact for rigid bodies).

    Raises
    ------
    InvalidInputError
        Without any limit, or if the trajectory neither moves nor accelerates (every factor
        then respects the limits: there is no smallest one), or its positions stand still
        to rounding (:data:`STILL_TOLERANCE`).
    NoSolutionFound
        If gravity alone exceeds a torque limit somewhere on the path.
    """
    n_dofs = _check_trajectory(trajectory).n_dofs
    velocity_limit = _limits("velocity_limit", velocity_limit, n_dofs)
    acceleration_limit = _limits("acceleration_limit", acceleration_limit, n_dofs)
    robot, torque_limit = _robot_arguments(robot, torque_limit, n_dofs)
    if velocity_limit is None and acceleration_limit is None and robot is None:
        raise InvalidInputError(
            "give at least one of velocity_limit, acceleration_limit, robot and torque_limit"
        )
    factor = 0.0
    if velocity_limit is not None:
        factor = max(factor, float(np.max(np.abs(trajectory.velocities) / velocity_limit)))
    if acceleration_limit is not None:
        ratio = float(np.max(np.abs(trajectory.accelerations) / acceleration_limit))
        factor = max(factor, np.sqrt(ratio))
    if robot is not None:
        gravity, dynamic = _torque_parts(robot, trajectory)
        room_up = torque_limit - gravity  # dynamic / c^2 <= room_up
        room_down = torque_limit + gravity  # -dynamic / c^2 <= room_down
        if np.any(room_up <= 0) or np.any(room_down <= 0):
            raise NoSolutionFound(
                "gravity alone exceeds the torque limit on this path: no timing can respect it; "
                "raise torque_limit or change the path"
            )
        need = np.where(dynamic > 0, dynamic / room_up, -dynamic / room_down)
        factor = max(factor, float(np.sqrt(np.max(need))))
    positions = trajectory.positions
    still = np.ptp(positions, axis=0) <= STILL_TOLERANCE * np.max(np.abs(positions), axis=0)
    if not factor > 0.0 or np.all(still):
        raise InvalidInputError(
            "trajectory neither moves nor accelerates, so every time scaling respects the "
            "limits and there is no smallest factor"
        )
    return float(factor)


def _shortest_duration(trajectory: Trajectory, velocity_limit, acceleration_limit) -> float:
    """A lower bound of any timing's duration: travel / velocity limit, and from rest the
    largest excursion ``D`` needs ``sqrt(2 D / a)`` under an acceleration limit ``a``."""
    bound = 0.0
    positions = trajectory.positions
    if velocity_limit is not None:
        travel = np.abs(np.diff(positions, axis=0)).sum(axis=0)
        bound = max(bound, float(np.max(travel / velocity_limit)))
    if acceleration_limit is not None:
        excursion = np.abs(positions - positions[0]).max(axis=0)
        bound = max(bound, float(np.max(np.sqrt(2 * excursion / acceleration_limit))))
    return bound


def _check_output_size(duration: float, dt: float, n_dofs: int = 1) -> None:
    check_resources(
        f"the retimed trajectory ({duration:.4g} s sampled every {dt:g} s, {n_dofs} DOFs)",
        8.0 * (4 * (duration / dt + 1) * n_dofs),
        "raise dt or the limits",
    )


@dataclass(frozen=True, eq=False)
class RetimingResult:
    """A retimed plan.

    Attributes
    ----------
    trajectory : Trajectory
        The path with its new timing, sampled every ``dt``.
    duration : float
        [s]
    path_parameter : ndarray, shape (n_steps,)
        The original plan's time ``s`` reached at each new sample.
    stretch : float
        Uniform stretch applied after toppra so that the densely sampled result respects
        the limits (1.0 if none was needed).
    solve_time : float
        Wall time of toppra [s].
    """

    trajectory: Trajectory
    duration: float
    path_parameter: np.ndarray
    stretch: float
    solve_time: float


def retime(
    trajectory: Trajectory,
    velocity_limit=None,
    acceleration_limit=None,
    *,
    robot=None,
    torque_limit=None,
    dt: float | None = None,
    n_gridpoints: int = 400,
) -> RetimingResult:
    """Fastest timing of ``trajectory``'s path under joint limits (toppra), from and to rest.

    Parameters
    ----------
    trajectory : Trajectory
        The plan whose path is kept.
    velocity_limit, acceleration_limit : array_like, shape (n_dofs,), optional
        Symmetric joint limits.
    robot : pinocchio.Model, optional
        With ``torque_limit``: torques by ``pinocchio.rnea`` must stay within
        ``+-torque_limit``.
    dt : float, optional
        Sample step of the result (default: the plan's mean step).
    n_gridpoints : int
        toppra's grid on the path.

    Raises
    ------
    NoSolutionFound
        If toppra finds no admissible timing (e.g. gravity exceeds a torque limit).
    ResourceLimitError
        If the result would hold more than 20 million values (``duration / dt`` samples;
        checked on a lower bound of the duration before toppra runs, and on toppra's
        duration before sampling), or ``n_gridpoints`` exceeds :data:`MAX_GRIDPOINTS`.
    """
    import toppra as ta
    import toppra.algorithm as algorithm
    import toppra.constraint as constraint

    n_dofs = _check_trajectory(trajectory).n_dofs
    velocity_limit = _limits("velocity_limit", velocity_limit, n_dofs)
    acceleration_limit = _limits("acceleration_limit", acceleration_limit, n_dofs)
    robot, torque_limit = _robot_arguments(robot, torque_limit, n_dofs)
    if velocity_limit is None and acceleration_limit is None and robot is None:
        raise InvalidInputError("give at least one of velocity_limit, acceleration_limit, robot")
    if dt is None:
        dt = float(np.mean(np.diff(trajectory.times)))
    dt = real("dt", dt, minimum=0.0, open_minimum=True)
    n_gridpoints = integer(
        "n_gridpoints", n_gridpoints, minimum=3, maximum=MAX_GRIDPOINTS, fix="use a coarser grid"
    )
    shortest = _shortest_duration(trajectory, velocity_limit, acceleration_limit)
    _check_output_size(shortest, dt, n_dofs)
    path_time = trajectory.times - trajectory.times[0]
    path = ta.SplineInterpolator(path_time, trajectory.positions)
    constraints = []
    if velocity_limit is not None:
        constraints.append(
            constraint.JointVelocityConstraint(np.column_stack([-velocity_limit, velocity_limit]))
        )
    if acceleration_limit is not None:
        constraints.append(
            constraint.JointAccelerationConstraint(
                np.column_stack([-acceleration_limit, acceleration_limit]),
                discretization_scheme=constraint.DiscretizationType.Interpolation,
            )
        )
    if robot is not None:
        import pinocchio as pin

        data = robot.createData()

        def inverse_dynamics(q, qd, qdd):
            return pin.rnea(
                robot, data, np.asarray(q, float), np.asarray(qd, float), np.asarray(qdd, float)
            )

        constraints.append(
            constraint.JointTorqueConstraint(
                inverse_dynamics,
                np.column_stack([-torque_limit, torque_limit]),
                np.zeros(n_dofs),
                discretization_scheme=constraint.DiscretizationType.Interpolation,
            )
        )
    gridpoints = np.linspace(0.0, path_time[-1], n_gridpoints)
    begin = time.perf_counter()
    instance = algorithm.TOPPRA(
        constraints, path, gridpoints=gridpoints, parametrizer="ParametrizeConstAccel"
    )
    timed = instance.compute_trajectory(0.0, 0.0)
    elapsed = time.perf_counter() - begin
    if timed is None:
        raise NoSolutionFound(
            "toppra found no admissible timing for this path under the given limits "
            "(e.g. gravity exceeds a torque limit); relax the limits",
            stats={"solve_time": elapsed},
        )
    duration = float(timed.duration)
    _check_output_size(duration, dt, n_dofs)
    n_steps = max(int(np.ceil(duration / dt)) + 1, 3)
    times = np.linspace(0.0, duration, n_steps)
    result = Trajectory(times, timed(times), timed(times, 1), timed(times, 2))
    # path parameter s(t): toppra's path is parametrised by the plan's own time
    parameter = np.asarray(timed._eval_params(times)[0], dtype=float)  # s(t) on the path
    stretch = uniform_time_scaling(
        result, velocity_limit, acceleration_limit, robot=robot, torque_limit=torque_limit
    )
    stretch = max(stretch * (1 + _TOLERANCE), 1.0) if stretch > 1.0 else 1.0
    if stretch > 1.0:
        result = time_scaled(result, stretch)
        duration *= stretch
        parameter = np.interp(np.linspace(0.0, duration, result.n_steps), result.times, parameter)
    return RetimingResult(result, duration, parameter, stretch, elapsed)


__all__ = ["RetimingResult", "retime", "time_scaled", "uniform_time_scaling"]
