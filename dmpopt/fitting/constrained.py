r"""Constrained imitation: DMP weights under limits, via-points and a new start, goal, duration.

For a discrete DMP with fixed start, goal and time constant the plan is affine in the forcing
weights (:class:`dmpopt.dmp.AffinePlan`, derived from the one CasADi definition in
:mod:`dmpopt.symbolic`):

.. math:: Y_k = F_k + G_k W_f^T, \quad k \in \{\text{position}, \text{velocity},
          \text{acceleration}\}.

Staying close to a demonstration while holding every sample of the plan inside box limits is
therefore a convex quadratic programme in :math:`W_f`:

.. math::
    \min_{W_f} \; \sum_d \|G_0 w_d + F_{0,d} - y^{\text{target}}_d\|^2 + \lambda \|w_d\|^2
    \quad \text{s.t.} \quad l \le A\, \mathrm{vec}(W_f) \le u

(objective ``"position"``), or the same with the forcing term :math:`\Phi w_d` against the
imitation fit's forcing term (objective ``"forcing"``). The rows of :math:`A` are position,
velocity, acceleration and jerk limits at every sample, via-points (linear interpolation
between samples, a box of half-width ``tolerance`` per DOF) and start/end conditions. Jerk is
the forward finite difference of the plan's accelerations (:mod:`dmpopt.metrics`).

Conditioning: each weight is divided by the norm of its objective column and by the
demonstration's extent ``L``; each constraint row by its physical unit (``L``, ``L/T``,
``L/T^2``, ``L/T^3``), so that every scaled quantity is of order one; the ridge term
:math:`\lambda = \text{regularization} \cdot \mathrm{tr}(G_0^T G_0) / n` is the one of
:func:`dmpopt.fitting.imitation.fit_discrete`, so that a request without constraints
reproduces the plain imitation fit.

Via-points with ``norm="ball"`` (Euclidean tolerance) are not linear: only then the problem
is solved as an NLP with IPOPT through ``casadi.Opti`` over the same matrices.

:func:`build_fitting_problem` returns an inspectable :class:`FittingProblem` (matrices,
constraint groups, a ``casadi.Opti`` view); :func:`fit_weights_constrained` solves it. The
QP backend is chosen in one place, :func:`solve_qp`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import NamedTuple, Sequence

import numpy as np

from ..dmp import AffinePlan, DiscreteDMP, goal_transform
from ..exceptions import (
    FittingFailed,
    InfeasibleProblem,
    InvalidInputError,
    ResourceLimitError,
    ShapeError,
)
from ..trajectory import Trajectory
from ..validation import check_resources, integer, real, real_array, sequence_of
from .imitation import _check_demo, fit_discrete

OBJECTIVES = ("position", "forcing")
SOLVERS = ("daqp", "qpoases", "proxsuite")
DEFAULT_SOLVER = "daqp"
"""QP backend used by ``solver="auto"`` (see ``benchmarks/bench_constrained.py``)."""
FEASIBILITY_TOLERANCE = 1e-7
"""A constraint counts as violated on the rollout above this fraction of its unit."""
_INFINITY = 1e20
MAX_VIA_POINTS = 10_000
"""Largest number of via-points :func:`build_fitting_problem` accepts."""


# ---------------------------------------------------------------------------------------
# Requests
# ---------------------------------------------------------------------------------------


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
            if np.any(lower > upper):
                raise InvalidInputError("position_lower exceeds position_upper for some DOF")


@dataclass(frozen=True, eq=False)
class ViaPoint:
    """Pass through ``position`` at ``time`` (from the start of the plan) within ``tolerance``.

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
                f"tolerance must be a number >= 0 or one per DOF, got {tolerance.tolist()}"
            )
        if not isinstance(self.norm, str) or self.norm not in ("box", "ball"):
            raise InvalidInputError(f"norm must be 'box' or 'ball', got {self.norm!r}")
        if self.norm == "ball" and tolerance.size != 1:
            raise InvalidInputError("a 'ball' via-point takes one scalar tolerance (its radius)")
        object.__setattr__(self, "tolerance", tolerance)


def _per_dof(name: str, value: np.ndarray, n_dofs: int) -> np.ndarray:
    value = np.atleast_1d(value)
    if value.size == 1:
        return np.full(n_dofs, float(value[0]))
    if value.shape != (n_dofs,):
        raise ShapeError(f"{name} has shape {value.shape}, expected ({n_dofs},) for {n_dofs} DOFs")
    return value


# ---------------------------------------------------------------------------------------
# The problem
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ConstraintGroup:
    """Rows of the (per-DOF) constraint matrix that encode one request.

    ``unit`` is the physical size of one scaled unit of these rows: ``L``, ``L/T``, ``L/T^2``
    or ``L/T^3`` for positions, velocities, accelerations, jerks (``L`` the motion's extent,
    ``T`` its duration).
    """

    name: str
    rows: slice
    unit: float
    quantity: str


@dataclass(eq=False)
class FittingProblem:
    r"""A constrained fit, ready to solve and open for inspection.

    Same response for every DOF, so the QP is block-diagonal: one block per DOF with the
    same Hessian and constraint matrix and its own gradient and bounds,

    .. math:: \min_{x_d} \tfrac12 x_d^T H x_d + g_d^T x_d \quad\text{s.t.}\quad
              l_d \le A x_d \le u_d, \qquad
              W_f[d, j] = L \, s_j \, x_d[j].

    :meth:`full_qp` stacks the blocks; :meth:`to_opti` states the same problem in CasADi.

    Attributes
    ----------
    dmp : DiscreteDMP
        The imitation fit moved to the requested start, goal and duration (its weights are
        the unconstrained answer; ``dmp_for`` swaps in new forcing weights).
    plan : AffinePlan
        Plan of ``dmp`` over ``duration`` with step ``dt``, affine in the forcing weights.
    target : ndarray, shape (n_steps, n_dofs)
        The demonstration moved to the request (the objective ``"position"`` follows it).
    hessian : ndarray, shape (n_basis, n_basis)
    gradient : ndarray, shape (n_dofs, n_basis)
    constraint_matrix : ndarray, shape (n_rows, n_basis)
        Rows scaled to unit norm.
    lower, upper : ndarray, shape (n_dofs, n_rows)
    row_scale : ndarray, shape (n_rows,)
        Norm removed from each row (row in group units = stored row * ``row_scale``).
    length_scale : float
        ``L``.
    scale : ndarray, shape (n_basis,)
        ``s``: weights divided by their objective column norm.
    groups : tuple of ConstraintGroup
        Which rows encode which request: ``"position"``, ``"velocity"``, ``"acceleration"``,
        ``"jerk"``, ``"via_point[i]"``, ``"end_position"``, ``"end_velocity"``,
        ``"end_acceleration"``.
    balls : tuple
        Euclidean via-points (non-linear: force the NLP).
    """

    dmp: DiscreteDMP
    plan: AffinePlan
    target: np.ndarray
    objective: str
    duration: float
    dt: float
    start_velocity: np.ndarray
    length_scale: float
    scale: np.ndarray
    hessian: np.ndarray
    gradient: np.ndarray
    constraint_matrix: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    row_scale: np.ndarray
    groups: tuple
    bounds: Bounds | None
    via_points: tuple
    balls: tuple
    solver: str
    margin: float
    checks: dict = field(repr=False, default_factory=dict)
    cache: dict = field(repr=False, default_factory=dict)

    @property
    def n_dofs(self) -> int:
        """Number of DOFs."""
        return self.dmp.n_dofs

    @property
    def n_basis(self) -> int:
        """Weights per DOF."""
        return self.dmp.n_basis

    @property
    def is_qp(self) -> bool:
        """True unless a constraint is non-linear (a ``"ball"`` via-point)."""
        return not self.balls

    def forcing_weights(self, x: np.ndarray) -> np.ndarray:
        """Forcing weights (n_dofs, n_basis) of scaled variables (n_dofs, n_basis) or flat."""
        x = np.asarray(x, dtype=float).reshape(self.n_dofs, self.n_basis)
        return self.length_scale * x * self.scale[None, :]

    def variables(self, forcing_weights: np.ndarray) -> np.ndarray:
        """Scaled variables (n_dofs, n_basis) of forcing weights."""
        return np.asarray(forcing_weights) / (self.length_scale * self.scale[None, :])

    def dmp_for(self, forcing_weights: np.ndarray) -> DiscreteDMP:
        """The DMP that, at the problem's start, goal and tau, has these forcing weights and
        starts with the problem's start velocity."""
        dmp = self.dmp
        transform = dmp.goal_map()
        weights = np.linalg.solve(transform, forcing_weights)
        scaled_velocity = np.linalg.solve(transform, dmp.tau * self.start_velocity)
        return dmp.replace(weights=weights, scaled_start_velocity=scaled_velocity)

    def rollout(self, dmp: DiscreteDMP) -> Trajectory:
        """Plan of ``dmp`` on the problem's time grid, from the problem's start velocity."""
        return dmp.rollout(self.duration, self.dt, start_velocity=self.start_velocity)

    def violations(self, trajectory: Trajectory) -> dict:
        """Largest violation of each constraint group on ``trajectory`` [physical units].

        Zero means satisfied. Computed from the trajectory's samples (jerk by finite
        differences), with the requested limits (no safety margin), not from the QP.
        """
        values = np.stack([trajectory.positions, trajectory.velocities, trajectory.accelerations])
        dt = float(np.mean(np.diff(trajectory.times)))
        violations = {}
        for name, (select, lower, upper) in self.checks.items():
            sample = select(values, dt)
            excess = np.maximum(lower - sample, sample - upper)
            violations[name] = float(max(np.max(excess, initial=0.0), 0.0))
        for i, (row_pair, point, radius) in enumerate(self.cache.get("ball_rows", ())):
            k, a = row_pair
            position = (1 - a) * values[0, k] + a * values[0, k + 1]
            distance = np.linalg.norm(position - point) - radius
            violations[f"via_point_ball[{i}]"] = float(max(distance, 0.0))
        return violations

    def relative_violations(self, violations: dict) -> dict:
        """Violations divided by their group's unit (dimensionless)."""
        units = {group.name: group.unit for group in self.groups}
        return {
            name: value / units.get(name, self.length_scale) for name, value in violations.items()
        }

    def full_qp(self):
        """The stacked QP ``(H, g, A, l, u)`` over ``x = vec`` of all DOFs (DOF-major)."""
        eye = np.eye(self.n_dofs)
        return (
            np.kron(eye, self.hessian),
            self.gradient.ravel(),
            np.kron(eye, self.constraint_matrix),
            self.lower.ravel(),
            self.upper.ravel(),
        )

    def to_opti(self):
        """The same problem as a ``casadi.Opti`` with IPOPT selected.

        Returns ``(opti, x)`` with ``x`` the scaled variables, shape (n_basis, n_dofs). This is
        the NLP that :func:`fit_weights_constrained` solves when ``balls`` is not empty.
        """
        import casadi as ca

        opti = ca.Opti()
        x = opti.variable(self.n_basis, self.n_dofs)
        hessian = ca.DM(self.hessian)
        # objective: closeness to the demonstration, one block per DOF
        cost = 0
        for d in range(self.n_dofs):
            column = x[:, d]
            linear = ca.dot(ca.DM(self.gradient[d]), column)
            cost += 0.5 * ca.bilin(hessian, column, column) + linear
        opti.minimize(cost)
        # linear rows: limits at every sample, box via-points, end conditions (finite sides)
        if self.constraint_matrix.shape[0]:
            rows = ca.mtimes(ca.DM(self.constraint_matrix), x)
            for d in range(self.n_dofs):
                low, high = ca.DM(self.lower[d]), ca.DM(self.upper[d])
                opti.subject_to(opti.bounded(low, rows[:, d], high))
        # Euclidean via-points: ||y(t_i) - p_i|| <= r_i (squared, scaled by L)
        for row, offset, point, radius in self.balls:
            scaled_row = ca.DM((row * self.scale)[None, :])
            position = ca.mtimes(scaled_row, x).T + ca.DM((offset - point) / self.length_scale)
            inner = max(radius / self.length_scale - self.margin, 0.0)  # margin inside
            opti.subject_to(ca.sumsqr(position) <= inner**2)
        opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes", "tol": 1e-10})
        opti.set_initial(x, self.variables(self.dmp.forcing_weights()).T)
        return opti, x


def _interpolation(time_value: float, dt: float, n_steps: int, name: str) -> tuple[int, float]:
    position = time_value / dt
    if position < -1e-9 or position > n_steps - 1 + 1e-9:
        raise InvalidInputError(
            f"{name} time {time_value} s is outside the plan [0, {dt * (n_steps - 1)}] s"
        )
    k = int(min(np.floor(position + 1e-9), n_steps - 2))
    return k, float(np.clip(position - k, 0.0, 1.0))


def _moved_demonstration(demo, dmp, start, goal, times, duration):
    """The demonstration carried to a new start, goal and duration by the goal scaling."""
    normalised = times / duration * demo.duration + demo.times[0]
    positions = np.column_stack(
        [np.interp(normalised, demo.times, demo.positions[:, d]) for d in range(demo.n_dofs)]
    )
    old_start, old_goal = demo.positions[0], demo.positions[-1]
    transform = goal_transform(dmp.goal_scaling, old_goal - old_start, goal - start)
    moved = start + (positions - old_start) @ transform.T
    velocity = transform @ demo.velocities[0] * demo.duration / duration
    return moved, velocity


def _end_tolerances(*values) -> tuple:
    names = ("end_position_tolerance", "end_velocity_tolerance", "end_acceleration_tolerance")
    return tuple(
        None if value is None else real(name, value, minimum=0.0, fix="pass None to leave it free")
        for name, value in zip(names, values)
    )


def _check_problem_size(n_steps, n_basis, n_dofs, bounds, n_via_points) -> None:
    """Refuse up front a problem whose matrices would exceed ``dmpopt.validation.MEMORY_BUDGET``."""
    n_basis = integer("n_basis", n_basis, minimum=1)
    if n_via_points > MAX_VIA_POINTS:
        raise ResourceLimitError(
            f"via_points holds {n_via_points} via-points, above the bound of {MAX_VIA_POINTS} "
            "(each costs a constraint row and a check; the fit takes about 0.2 ms per "
            "via-point); merge them or use position bounds"
        )
    n_limits = 0 if bounds is None else 4
    rows = n_limits * n_steps + n_via_points + 3
    check_resources(
        f"a constrained fit with {n_steps} samples, {n_basis} basis functions, {n_dofs} DOFs and "
        f"{n_via_points} via-points",
        8.0 * (max(3 * n_steps * n_basis, rows * n_basis, n_steps * n_dofs, n_basis**2)),
        "lower n_samples (constraints hold at every sample; a few hundred suffice), "
        "n_basis or the number of via-points",
    )


def build_fitting_problem(
    demo: Trajectory,
    n_basis: int = 30,
    *,
    bounds: Bounds | None = None,
    via_points: Sequence[ViaPoint] = (),
    start=None,
    goal=None,
    duration: float | None = None,
    n_samples: int | None = None,
    start_velocity=None,
    end_position_tolerance: float | None = 0.0,
    end_velocity_tolerance: float | None = None,
    end_acceleration_tolerance: float | None = None,
    objective: str = "position",
    form: str = "velocity",
    goal_scaling: str = "auto",
    regularization: float = 1e-9,
    margin: float = 1e-6,
    solver: str = "auto",
    reference: DiscreteDMP | None = None,
) -> FittingProblem:
    r"""Build the constrained fit of a discrete DMP to ``demo``.

    Solve it with :func:`fit_weights_constrained`.

    Parameters
    ----------
    demo : Trajectory
        The demonstration (``n_dofs`` DOFs).
    n_basis : int
        Basis functions per DOF (ignored if ``reference`` is given).
    bounds : Bounds, optional
        Limits held at every sample of the plan.
    via_points : sequence of ViaPoint
        Points to pass through.
    start, goal : array_like, shape (n_dofs,), optional
        New start and goal (default: the demonstration's).
    duration : float, optional
        Length of the plan [s] (default: the demonstration's); ``tau`` scales with it.
    n_samples : int, optional
        Samples of the plan, at which every constraint holds (default: the demonstration's).
    start_velocity : array_like, shape (n_dofs,), optional
        Initial velocity (default: the demonstration's, moved like its shape).
    end_position_tolerance, end_velocity_tolerance, end_acceleration_tolerance : float or None
        Half-widths of boxes on ``y(T) - g``, ``yd(T)``, ``ydd(T)``; ``None`` leaves it free.
        The default holds the goal exactly at the last sample, as the imitation fit does.
    objective : {"position", "forcing"}
        Stay close to the demonstrated positions (moved to the request), or to the
        imitation fit's forcing term.
    form, goal_scaling : str
        As in :func:`dmpopt.fitting.imitation.fit_discrete`.
    regularization : float
        Ridge weight relative to the mean diagonal of the normal equations.
    margin : float
        Inequalities are tightened by this fraction of their unit so that the rollout
        satisfies them despite the solver's tolerance.
    solver : {"auto", "daqp", "qpoases", "proxsuite"}
        QP backend (see :func:`solve_qp`).
    reference : DiscreteDMP, optional
        An imitation fit of ``demo`` to reuse instead of fitting again.

    Returns
    -------
    FittingProblem

    Raises
    ------
    InvalidInputError, ShapeError
        An argument is not finite, out of range, of the wrong type or DOF count (the message
        names it). ``None`` is the only way to leave an end condition free.
    ResourceLimitError
        The matrices would exceed 20 million entries (``n_samples * n_basis`` and the rows of
        every sample's limits), or ``via_points`` exceeds :data:`MAX_VIA_POINTS`; lower
        ``n_samples``.
    """
    demo = _check_demo(demo)
    if not isinstance(objective, str) or objective not in OBJECTIVES:
        raise InvalidInputError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    solver = _check_solver(solver)
    if bounds is not None and not isinstance(bounds, Bounds):
        raise InvalidInputError(
            f"bounds must be a Bounds, got {type(bounds).__name__}; "
            "write bounds=Bounds(velocity=..., acceleration=...)"
        )
    via_points = sequence_of("via_points", via_points, ViaPoint)
    tolerances = _end_tolerances(
        end_position_tolerance, end_velocity_tolerance, end_acceleration_tolerance
    )
    regularization = real("regularization", regularization, minimum=0.0)
    margin = real("margin", margin, minimum=0.0, maximum=0.1, fix="keep it tiny, e.g. 1e-6")
    duration = (
        demo.duration
        if duration is None
        else real("duration", duration, minimum=0.0, open_minimum=True)
    )
    n_steps = demo.n_steps if n_samples is None else integer("n_samples", n_samples, minimum=3)
    n_dofs = demo.n_dofs
    n_basis = reference.n_basis if isinstance(reference, DiscreteDMP) else n_basis
    _check_problem_size(n_steps, n_basis, n_dofs, bounds, len(via_points))
    if reference is None:
        reference = fit_discrete(
            demo, n_basis, form=form, goal_scaling=goal_scaling, regularization=regularization
        )
    elif not isinstance(reference, DiscreteDMP) or reference.n_dofs != demo.n_dofs:
        raise InvalidInputError("reference must be a DiscreteDMP with the demonstration's DOFs")
    start = (
        demo.positions[0]
        if start is None
        else _per_dof("start", real_array("start", start), n_dofs)
    )
    goal = (
        demo.positions[-1] if goal is None else _per_dof("goal", real_array("goal", goal), n_dofs)
    )
    dt = duration / (n_steps - 1)
    times = np.arange(n_steps) * dt

    tau = reference.tau * duration / demo.duration
    dmp = reference.replace(start=start, goal=goal, tau=tau)
    target, moved_velocity = _moved_demonstration(demo, dmp, start, goal, times, duration)
    if start_velocity is None:
        start_velocity = moved_velocity
    start_velocity = _per_dof(
        "start_velocity", real_array("start_velocity", start_velocity), n_dofs
    )
    plan = dmp.affine_plan(duration, dt, start_velocity=start_velocity)
    response = plan.weight_response

    # scales: one length for all DOFs (keeps the DOFs' weighting), the duration for time
    length = float(max(np.ptp(target, axis=0).max(), np.abs(goal - start).max(), 1e-12))
    units = {
        "position": length,
        "velocity": length / duration,
        "acceleration": length / duration**2,
        "jerk": length / duration**3,
    }

    # objective: ||M w_d - b_d||^2 + lambda ||w_d - w0_d||^2 per DOF, in x = w / (L s)
    if objective == "position":
        matrix = response[0]
        targets = target - plan.free[0]
        prior = np.zeros((n_dofs, dmp.n_basis))
    else:
        matrix = dmp.phase_features(n_steps, dt)
        prior = dmp.forcing_weights()
        targets = matrix @ prior.T
    gram = matrix.T @ matrix
    lam = regularization * np.trace(gram) / dmp.n_basis
    scale = 1.0 / np.maximum(np.sqrt(np.diag(gram) + lam), 1e-300)
    hessian = scale[:, None] * (gram + lam * np.eye(dmp.n_basis)) * scale[None, :]
    normaliser = float(np.mean(np.diag(hessian)))
    hessian = hessian / normaliser
    gradient = -((matrix.T @ targets + lam * prior.T) * scale[:, None]).T / (length * normaliser)

    # constraints: one labelled block per request, rows shared by all DOFs
    blocks, checks = [], {}

    def add(name, quantity, select, matrix_rows, lower, upper):
        lower = np.broadcast_to(lower, (matrix_rows.shape[0], n_dofs)).astype(float)
        upper = np.broadcast_to(upper, (matrix_rows.shape[0], n_dofs)).astype(float)
        if np.isnan(lower).any() or np.isnan(upper).any():  # NaN would read as "no limit"
            raise InvalidInputError(f"the bounds of '{name}' contain NaN; give finite limits")
        checks[name] = (select, lower, upper)
        blocks.append((name, quantity, select, matrix_rows, lower, upper))

    if bounds is not None:
        # position box at every sample
        if bounds.position_lower is not None or bounds.position_upper is not None:
            low = -np.inf if bounds.position_lower is None else bounds.position_lower
            high = np.inf if bounds.position_upper is None else bounds.position_upper
            add(
                "position",
                "position",
                lambda v, h: v[0],
                response[0],
                _per_dof("position_lower", np.atleast_1d(low), n_dofs),
                _per_dof("position_upper", np.atleast_1d(high), n_dofs),
            )
        # |velocity| <= limit at every sample
        if bounds.velocity is not None:
            limit = _per_dof("velocity", bounds.velocity, n_dofs)
            add("velocity", "velocity", lambda v, h: v[1], response[1], -limit, limit)
        # |acceleration| <= limit at every sample
        if bounds.acceleration is not None:
            limit = _per_dof("acceleration", bounds.acceleration, n_dofs)
            add("acceleration", "acceleration", lambda v, h: v[2], response[2], -limit, limit)
        # |jerk| <= limit between samples (forward difference of accelerations)
        if bounds.jerk is not None:
            limit = _per_dof("jerk", bounds.jerk, n_dofs)
            add(
                "jerk",
                "jerk",
                lambda v, h: np.diff(v[2], axis=0) / h,
                np.diff(response[2], axis=0) / dt,
                -limit,
                limit,
            )
    # via-points: plan interpolated linearly between the neighbouring samples
    balls, ball_rows = [], []
    for i, via in enumerate(via_points):
        point = _per_dof(f"via_points[{i}].position", via.position, n_dofs)
        k, a = _interpolation(via.time, dt, n_steps, f"via_points[{i}]")
        row = (1 - a) * response[0, k] + a * response[0, k + 1]
        if via.norm == "ball":  # ||y(t) - p|| <= r: non-linear, NLP
            offset = (1 - a) * plan.free[0, k] + a * plan.free[0, k + 1]
            balls.append((row, offset, point, float(via.tolerance[0])))
            ball_rows.append(((k, a), point, float(via.tolerance[0])))
            continue
        tolerance = _per_dof(f"via_points[{i}].tolerance", via.tolerance, n_dofs)

        def select(v, h, k=k, a=a):
            return ((1 - a) * v[0, k] + a * v[0, k + 1])[None, :]

        add(
            f"via_point[{i}]",
            "position",
            select,
            row[None, :],
            point - tolerance,
            point + tolerance,
        )
    # end conditions at the last sample: goal reached, at rest
    for (quantity, index, centre), tolerance in zip(
        (("position", 0, goal), ("velocity", 1, 0.0), ("acceleration", 2, 0.0)), tolerances
    ):
        if tolerance is None:
            continue
        add(
            f"end_{quantity}",
            quantity,
            lambda v, h, i=index: v[i, -1:],
            response[index, -1][None, :],
            centre - tolerance,
            centre + tolerance,
        )

    # scale: rows in group units (divide by unit), then to unit norm; margin inside the box
    matrices, lowers, uppers, row_scales, groups = [], [], [], [], []
    count = 0
    for name, quantity, select, matrix_rows, low, high in blocks:
        unit = units[quantity]
        offset = select(plan.free, dt)
        scaled = matrix_rows * scale[None, :] * length / unit
        norms = np.maximum(np.linalg.norm(scaled, axis=1), 1e-300)
        tight = (high - low) > 2 * margin * unit
        low_scaled = np.where(np.isfinite(low), (low - offset) / unit + margin * tight, -np.inf)
        high_scaled = np.where(np.isfinite(high), (high - offset) / unit - margin * tight, np.inf)
        matrices.append(scaled / norms[:, None])
        lowers.append(low_scaled / norms[:, None])
        uppers.append(high_scaled / norms[:, None])
        row_scales.append(norms)
        groups.append(ConstraintGroup(name, slice(count, count + len(norms)), unit, quantity))
        count += len(norms)
    constraint_matrix = np.vstack(matrices) if matrices else np.zeros((0, dmp.n_basis))
    lower = np.vstack(lowers).T if lowers else np.zeros((n_dofs, 0))
    upper = np.vstack(uppers).T if uppers else np.zeros((n_dofs, 0))
    row_scale = np.concatenate(row_scales) if row_scales else np.zeros(0)

    problem = FittingProblem(
        dmp=dmp,
        plan=plan,
        target=target,
        objective=objective,
        duration=duration,
        dt=dt,
        start_velocity=start_velocity,
        length_scale=length,
        scale=scale,
        hessian=hessian,
        gradient=gradient,
        constraint_matrix=constraint_matrix,
        lower=np.clip(lower, -_INFINITY, _INFINITY),
        upper=np.clip(upper, -_INFINITY, _INFINITY),
        row_scale=row_scale,
        groups=tuple(groups),
        bounds=bounds,
        via_points=via_points,
        balls=tuple(balls),
        solver=solver,
        margin=margin,
        checks=checks,
    )
    problem.cache["ball_rows"] = tuple(ball_rows)
    return problem


# ---------------------------------------------------------------------------------------
# Solving
# ---------------------------------------------------------------------------------------


class QpSolution(NamedTuple):
    """Result of :func:`solve_qp`.

    ``active`` marks the rows in the working set at the solution (reuse it as ``rows``
    of the next, similar problem to warm-start).
    """

    x: np.ndarray
    success: bool
    status: str
    solve_time: float  # [s] wall time, row generation included
    iterations: int  # rounds of row generation
    active: np.ndarray


def _check_solver(solver: str) -> str:
    if solver == "auto":
        return DEFAULT_SOLVER
    if solver not in SOLVERS:
        raise InvalidInputError(f"solver must be 'auto' or one of {SOLVERS}, got {solver!r}")
    return solver


def _silenced(call):
    """Run ``call()`` with the process's stdout closed (qpOASES prints a banner in C)."""
    import os
    import sys

    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as sink:
            os.dup2(sink.fileno(), 1)
            return call()
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def _backend_solve(solver, hessian, gradient, matrix, lower, upper):
    """One dense solve with the chosen backend: ``(x, multipliers, success, status)``."""
    n, m = hessian.shape[0], matrix.shape[0]
    if solver == "proxsuite":
        import proxsuite

        qp = proxsuite.proxqp.dense.QP(n, 0, m)
        qp.settings.eps_abs = 1e-8
        qp.settings.eps_rel = 0.0
        qp.settings.verbose = False
        qp.init(hessian, gradient, None, None, matrix, lower, upper)
        qp.solve()
        status = qp.results.info.status
        success = status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
        return np.array(qp.results.x), np.array(qp.results.z), bool(success), str(status)

    import casadi as ca

    options = {"error_on_fail": False}
    if solver == "qpoases":
        options.update({"printLevel": "none"})
    else:
        options["daqp"] = {"primal_tol": 1e-10}
    structure = {"h": ca.Sparsity.dense(n, n), "a": ca.Sparsity.dense(m, n)}

    def call():
        function = ca.conic("dmpopt_qp", solver, structure, options)
        return function, function(h=hessian, g=gradient, a=matrix, lba=lower, uba=upper)

    function, result = _silenced(call) if solver == "qpoases" else call()
    stats = function.stats()
    status = str(stats.get("return_status", stats.get("unified_return_status", "")))
    return (
        result["x"].full().ravel(),
        result["lam_a"].full().ravel(),
        bool(stats.get("success", False)),
        status,
    )


def solve_qp(
    hessian,
    gradient,
    constraint_matrix,
    lower,
    upper,
    *,
    solver="auto",
    rows=None,
    stride: int = 10,
    tolerance: float = 1e-9,
) -> QpSolution:
    r"""Solve :math:`\min \frac12 x^T H x + g^T x` s.t. :math:`l \le A x \le u` (dense).

    The one place where dmpopt picks a QP backend. Rows are generated lazily: the QP is
    first solved with every ``stride``-th row plus ``rows`` (a warm start: the previous
    working set), then every row that the answer violates is added, until none is. With
    limits at every one of 1,000 samples only a few hundred rows are ever used.

    ``"daqp"`` (default)
        casadi's DAQP plugin (dual active set): the fastest on these problems
        (``benchmarks/bench_constrained.py``).
    ``"qpoases"``
        casadi's qpOASES plugin: several times slower here (many degenerate active-set
        changes between neighbouring samples).
    ``"proxsuite"``
        the standalone proxsuite dense ProxQP. casadi 3.8's ``proxqp`` conic plugin reports
        these problems infeasible and is not offered; the standalone solver can also stop
        with a (wrong) infeasibility status on them, reported as a failure.

    Returns
    -------
    QpSolution
    """
    solver = _check_solver(solver)
    hessian = real_array("hessian", hessian, ndim=2)
    gradient = real_array("gradient", gradient, ndim=1)
    n = gradient.size
    matrix = np.ascontiguousarray(constraint_matrix, dtype=float)
    if matrix.ndim != 2 or matrix.shape[1] != n:
        raise ShapeError(f"constraint_matrix has shape {matrix.shape}, expected (m, {n})")
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    m = matrix.shape[0]
    if hessian.shape != (n, n) or lower.shape != (m,) or upper.shape != (m,):
        raise ShapeError(
            f"hessian {hessian.shape}, constraint_matrix {matrix.shape}, lower {lower.shape} "
            f"and upper {upper.shape} do not fit a gradient of {n} entries"
        )
    if not np.all(np.isfinite(matrix)) or np.isnan(lower).any() or np.isnan(upper).any():
        raise InvalidInputError(
            "constraint_matrix must be finite and lower, upper free of NaN (use +-inf for "
            "a free side)"
        )
    begin = time.perf_counter()
    selected = np.zeros(m, dtype=bool)
    if rows is not None:  # warm start: the previous working set and a sparser grid
        stride = 5 * stride
    selected[:: max(int(stride), 1)] = True
    selected[-1:] = True
    selected |= np.isfinite(lower) & np.isfinite(upper) & (upper - lower < 1e-12)  # equalities
    if rows is not None:
        selected |= np.asarray(rows, dtype=bool)
    rounds = 0
    while True:
        rounds += 1
        index = np.nonzero(selected)[0]
        x, multipliers, success, status = _backend_solve(
            solver, hessian, gradient, matrix[index], lower[index], upper[index]
        )
        if not success or not np.all(np.isfinite(x)):
            break
        values = matrix @ x
        violated = ((values < lower - tolerance) | (values > upper + tolerance)) & ~selected
        if not violated.any():
            break
        selected |= violated
    active = np.zeros(m, dtype=bool)
    if index.size:
        active[index[np.abs(multipliers[: index.size]) > 0]] = True
    return QpSolution(x, success, status, time.perf_counter() - begin, rounds, active)


@dataclass(frozen=True, eq=False)
class FitReport:
    """What a constrained fit did.

    Attributes
    ----------
    solver : str
        ``"daqp"``, ``"qpoases"``, ``"proxsuite"`` or ``"ipopt"`` (the NLP).
    status : str
        The solver's own status (last DOF).
    solve_time : float
        Wall time of the solver calls [s] (building the problem not included).
    iterations : int
        Rounds of row generation (QP, summed over DOFs) or IPOPT iterations.
    violations : dict
        Largest violation of each constraint group on the returned DMP's rollout
        [physical units]; zero on success.
    trajectory : Trajectory
        The rollout of the returned DMP on the problem's grid.
    problem : FittingProblem
    """

    solver: str
    status: str
    solve_time: float
    iterations: int
    violations: dict
    trajectory: Trajectory
    problem: FittingProblem


class ConstrainedFit(NamedTuple):
    """``(dmp, report)`` returned by :func:`fit_weights_constrained`."""

    dmp: DiscreteDMP
    report: FitReport


def diagnose_infeasibility(problem: FittingProblem) -> dict:
    r"""Smallest relaxation of each constraint group, per DOF, that makes the QP feasible.

    Solves, per DOF, the elastic problem :math:`\min \sum_g s_g + \epsilon(\|x\|^2 +
    \|s\|^2)` with :math:`l - s_g \le A_g x \le u + s_g` and :math:`s \ge 0`, one slack per
    group in the group's unit. Returns ``{group name: (relaxation in physical units, DOFs)}``
    for the groups that need one; empty if the linear constraints can all hold.
    """
    if not isinstance(problem, FittingProblem):
        raise InvalidInputError(
            f"problem must be a FittingProblem, got {type(problem).__name__}; "
            "build one with build_fitting_problem(...)"
        )
    n, n_groups = problem.n_basis, len(problem.groups)
    if n_groups == 0:
        return {}
    matrix_units = problem.constraint_matrix * problem.row_scale[:, None]
    m = matrix_units.shape[0]
    membership = np.zeros((m, n_groups))
    for g, group in enumerate(problem.groups):
        membership[group.rows, g] = 1.0
    epsilon = 1e-6
    hessian = epsilon * np.eye(n + n_groups)
    gradient = np.concatenate([np.zeros(n), np.ones(n_groups)])
    matrix = np.block(
        [
            [matrix_units, membership],
            [matrix_units, -membership],
            [np.zeros((n_groups, n)), np.eye(n_groups)],
        ]
    )
    relaxations = {}
    for d in range(problem.n_dofs):
        lower_units = problem.lower[d] * problem.row_scale
        upper_units = problem.upper[d] * problem.row_scale
        lower = np.concatenate([lower_units, np.full(m, -_INFINITY), np.zeros(n_groups)])
        upper = np.concatenate([np.full(m, _INFINITY), upper_units, np.full(n_groups, _INFINITY)])
        keep = np.zeros(matrix.shape[0], dtype=bool)
        keep[-n_groups:] = True  # s >= 0 from the start: the elastic LP is bounded
        solution = solve_qp(hessian, gradient, matrix, lower, upper, solver="qpoases", rows=keep)
        if not solution.success:
            raise FittingFailed(
                f"the elastic problem that locates the infeasibility failed ({solution.status})",
                problem=problem,
            )
        slack = solution.x[n:]
        for g, group in enumerate(problem.groups):
            if slack[g] > 0.1 * problem.margin:
                amount, dofs = relaxations.get(group.name, (0.0, []))
                relaxations[group.name] = (max(amount, float(slack[g] * group.unit)), dofs + [d])
    return relaxations


def _infeasible(problem: FittingProblem, status: str, stats) -> InfeasibleProblem | None:
    relaxations = diagnose_infeasibility(problem)
    if not relaxations:
        return None
    parts = [
        f"'{name}' on DOF(s) {dofs} by {amount:.4g}"
        for name, (amount, dofs) in sorted(relaxations.items(), key=lambda item: -item[1][0])
    ]
    message = (
        f"infeasible constrained fit ({status}): " + ", ".join(parts) + " [physical units]; "
        "relax these constraints by at least that much (plus the safety margin of "
        f"{problem.margin:g} units), lengthen the duration or move the goal "
        "(the problem is attached as .problem)"
    )
    error = InfeasibleProblem(message, problem=problem, stats=stats)
    error.relaxations = relaxations
    return error


def _solve_nlp(problem: FittingProblem):
    opti, variable = problem.to_opti()
    begin = time.perf_counter()
    try:
        solution = opti.solve()
        x, success = np.asarray(solution.value(variable), float), True
    except RuntimeError:
        x, success = np.full((problem.n_basis, problem.n_dofs), np.nan), False
    elapsed = time.perf_counter() - begin
    stats = opti.stats()
    return (
        x.T.reshape(problem.n_dofs, problem.n_basis),
        success,
        str(stats.get("return_status", "")),
        elapsed,
        int(stats.get("iter_count", -1)),
    )


def fit_weights_constrained(problem=None, /, *args, warm_start=None, **kwargs) -> ConstrainedFit:
    """Solve a constrained fit: a :class:`FittingProblem`, or the arguments of
    :func:`build_fitting_problem`.

    The QP is solved per DOF with :func:`solve_qp`; if a via-point is Euclidean, the NLP of
    :meth:`FittingProblem.to_opti` with IPOPT instead. The returned DMP is rolled out and
    every constraint is checked on that rollout.

    Parameters
    ----------
    warm_start : FitReport or FittingProblem, optional
        A previous fit of a problem of the same size: its working sets start the row
        generation. Without it, the problem's own last solve is used if any.

    Returns
    -------
    ConstrainedFit
        ``(dmp, report)``.

    Raises
    ------
    InfeasibleProblem
        The constraints cannot all hold. The message names each constraint group to relax,
        the DOFs and by how much (physical units); ``error.problem`` is the problem,
        ``error.relaxations`` the amounts.
    FittingFailed
        The solver failed although the constraints are feasible, or its answer violates a
        constraint on the rollout.
    """
    if not isinstance(problem, FittingProblem):
        problem = build_fitting_problem(problem, *args, **kwargs)
    elif args or kwargs:
        raise InvalidInputError("pass either a FittingProblem or build arguments, not both")
    if warm_start is not None and not isinstance(warm_start, (FitReport, FittingProblem)):
        raise InvalidInputError(
            f"warm_start must be a FitReport or FittingProblem, got {type(warm_start).__name__}"
        )
    source = warm_start.problem if isinstance(warm_start, FitReport) else warm_start
    source = problem if source is None else source
    previous = source.cache.get("active")
    if previous is not None and previous.shape != (problem.n_dofs, problem.lower.shape[1]):
        previous = None

    if problem.is_qp:
        x = np.empty((problem.n_dofs, problem.n_basis))
        active = np.zeros_like(problem.lower, dtype=bool)
        success, solve_time, iterations, status = True, 0.0, 0, ""
        solver_name = problem.solver
        for d in range(problem.n_dofs):
            for backend in dict.fromkeys([problem.solver, "qpoases"]):  # fallback: qpOASES
                solution = solve_qp(
                    problem.hessian,
                    problem.gradient[d],
                    problem.constraint_matrix,
                    problem.lower[d],
                    problem.upper[d],
                    solver=backend,
                    rows=None if previous is None else previous[d],
                )
                solve_time += solution.solve_time
                iterations += solution.iterations
                if solution.success:
                    break
            if backend != problem.solver:
                solver_name = f"{problem.solver}+{backend}"
            x[d], active[d] = solution.x, solution.active
            success &= solution.success
            status = solution.status
            if not solution.success:
                break
    else:
        x, success, status, solve_time, iterations = _solve_nlp(problem)
        active, solver_name = None, "ipopt"

    stats = {
        "solver": solver_name,
        "status": status,
        "solve_time": solve_time,
        "iterations": iterations,
    }
    if not success or not np.all(np.isfinite(x)):
        error = _infeasible(problem, status, stats)
        if error is not None:
            raise error
        raise FittingFailed(
            f"the {solver_name} solver failed ({status}) although the constraints can hold; "
            "try another solver ('daqp', 'qpoases') or a larger regularization",
            problem=problem,
            stats=stats,
        )

    dmp = problem.dmp_for(problem.forcing_weights(x))
    trajectory = problem.rollout(dmp)
    violations = problem.violations(trajectory)
    relative = problem.relative_violations(violations)
    worst = max(relative, key=relative.get) if relative else None
    if worst is not None and relative[worst] > FEASIBILITY_TOLERANCE:
        error = _infeasible(problem, status, stats)
        if error is not None:
            raise error
        raise FittingFailed(
            f"the {solver_name} answer violates '{worst}' by {violations[worst]:.3g} on the "
            "rollout; raise margin (build_fitting_problem) or try another solver",
            problem=problem,
            stats=stats,
        )
    if active is not None:
        problem.cache["active"] = active
    report = FitReport(solver_name, status, solve_time, iterations, violations, trajectory, problem)
    return ConstrainedFit(dmp, report)


__all__ = [
    "Bounds",
    "ConstrainedFit",
    "ConstraintGroup",
    "FitReport",
    "FittingProblem",
    "ViaPoint",
    "build_fitting_problem",
    "diagnose_infeasibility",
    "fit_weights_constrained",
    "solve_qp",
]
