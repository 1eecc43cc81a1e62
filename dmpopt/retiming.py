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

_TOLERANCE = 1e-9


def _limits(name: str, value, n_dofs: int):
    if value is None:
        return None
    value = np.atleast_1d(np.asarray(value, dtype=float))
    if value.size == 1:
        value = np.full(n_dofs, float(value[0]))
    if value.shape != (n_dofs,):
        raise ShapeError(f"{name} has shape {value.shape}, expected ({n_dofs},)")
    if not np.all(np.isfinite(value)) or np.any(value <= 0):
        raise InvalidInputError(f"{name} must be positive and finite, got {value.tolist()}")
    return value


def _robot_arguments(robot, torque_limit, n_dofs):
    if (robot is None) != (torque_limit is None):
        raise InvalidInputError(
            "torque limits need both robot (a pinocchio.Model) and torque_limit"
        )
    if robot is None:
        return None, None
    if robot.nq != n_dofs or robot.nv != n_dofs:
        raise ShapeError(f"robot has nq = {robot.nq}, nv = {robot.nv}; the plan has {n_dofs} DOFs")
    return robot, _limits("torque_limit", torque_limit, n_dofs)


def time_scaled(trajectory: Trajectory, factor: float) -> Trajectory:
    """The same path ``factor`` times slower: ``t -> c t``, ``v -> v / c``, ``a -> a / c^2``.

    For a DMP this is exactly ``dmp.with_time_constant(c * tau)`` (Section 3.3).
    """
    factor = float(factor)
    if not factor > 0:
        raise InvalidInputError(f"factor must be positive, got {factor!r}")
    return Trajectory(
        trajectory.times * factor,
        trajectory.positions,
        trajectory.velocities / factor,
        trajectory.accelerations / factor**2,
    )


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
    NoSolutionFound
        If gravity alone exceeds a torque limit somewhere on the path.
    """
    n_dofs = trajectory.n_dofs
    velocity_limit = _limits("velocity_limit", velocity_limit, n_dofs)
    acceleration_limit = _limits("acceleration_limit", acceleration_limit, n_dofs)
    robot, torque_limit = _robot_arguments(robot, torque_limit, n_dofs)
    factor = 1e-12
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
    return float(factor)


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
    """
    import toppra as ta
    import toppra.algorithm as algorithm
    import toppra.constraint as constraint

    if not isinstance(trajectory, Trajectory):
        raise InvalidInputError(f"trajectory must be a Trajectory, got {type(trajectory).__name__}")
    n_dofs = trajectory.n_dofs
    velocity_limit = _limits("velocity_limit", velocity_limit, n_dofs)
    acceleration_limit = _limits("acceleration_limit", acceleration_limit, n_dofs)
    robot, torque_limit = _robot_arguments(robot, torque_limit, n_dofs)
    if velocity_limit is None and acceleration_limit is None and robot is None:
        raise InvalidInputError("give at least one of velocity_limit, acceleration_limit, robot")
    dt = float(np.mean(np.diff(trajectory.times))) if dt is None else float(dt)
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
    gridpoints = np.linspace(0.0, path_time[-1], max(int(n_gridpoints), 3))
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
