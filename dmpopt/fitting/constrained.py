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

:func:`build_fitting_problem` returns an inspectable, frozen :class:`FittingProblem`
(matrices, constraint groups, a ``casadi.Opti`` view); :func:`solve_fitting_problem` solves
it; :func:`fit_weights_constrained` does both. The requests live in
:mod:`dmpopt.fitting.requests`, the constraint groups in :mod:`dmpopt.fitting.groups`, the
QP layer in :mod:`dmpopt.fitting.qp`, the NLP in :mod:`dmpopt.fitting.nlp` and the
infeasibility diagnosis in :mod:`dmpopt.fitting.diagnosis`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from ..dmp import DiscreteDMP, goal_transform
from ..exceptions import FittingFailed, InvalidInputError, ResourceLimitError
from ..trajectory import Trajectory
from ..validation import check_resources, integer, real, real_array, sequence_of
from ._recall import Recall, exact
from .diagnosis import diagnose_infeasibility, infeasibility_error
from .groups import ConstraintGroup, end_groups, limit_groups, sample, via_point_groups
from .imitation import _check_demo, fit_discrete
from .nlp import solve_nlp
from .problem import ConstrainedFit, FitReport, FittingProblem
from .qp import check_solver, scale_rows, solve_blocks, solve_qp, stack_rows
from .requests import Bounds, ViaPoint, check_bounds, per_dof

OBJECTIVES = ("position", "forcing")
FEASIBILITY_TOLERANCE = 1e-7
"""A constraint counts as violated on the rollout above this fraction of its unit."""
MAX_VIA_POINTS = 10_000
"""Largest number of via-points :func:`build_fitting_problem` accepts."""


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

    Solve it with :func:`solve_fitting_problem`.

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
        QP backend (see :func:`dmpopt.fitting.qp.solve_qp`).
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
    solver = check_solver(solver)
    bounds = check_bounds(bounds)
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
        raise InvalidInputError(
            f"reference must be a DiscreteDMP with the demonstration's {demo.n_dofs} DOFs, got "
            f"{_description(reference)}; pass fit_discrete(demo, n_basis) or None"
        )
    start = (
        demo.positions[0] if start is None else per_dof("start", real_array("start", start), n_dofs)
    )
    goal = demo.positions[-1] if goal is None else per_dof("goal", real_array("goal", goal), n_dofs)
    dt = duration / (n_steps - 1)
    times = np.arange(n_steps) * dt

    tau = reference.tau * duration / demo.duration
    dmp = reference.replace(start=start, goal=goal, tau=tau)
    target, moved_velocity = _moved_demonstration(demo, dmp, start, goal, times, duration)
    if start_velocity is None:
        start_velocity = moved_velocity
    start_velocity = per_dof("start_velocity", real_array("start_velocity", start_velocity), n_dofs)
    plan = dmp.affine_plan(duration, dt, start_velocity=start_velocity)
    # scales: one length for all DOFs (keeps the DOFs' weighting), the duration for time
    length = float(max(np.ptp(target, axis=0).max(), np.abs(goal - start).max(), 1e-12))
    scale, hessian, gradient = _objective(dmp, plan, target, objective, regularization, length)
    # constraints: one labelled group per request, rows shared by all DOFs
    vias, balls = via_point_groups(via_points, dt, n_steps, n_dofs)
    requested = limit_groups(bounds, n_steps, n_dofs) + vias + end_groups(goal, tolerances, n_steps)
    units = _units(length, duration)
    groups, rows = _assemble(requested, plan, scale * length, units, margin)
    return FittingProblem(
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
        constraint_matrix=rows.matrix,
        lower=rows.lower,
        upper=rows.upper,
        row_scale=rows.norms,
        groups=groups,
        bounds=bounds,
        via_points=via_points,
        balls=tuple(balls),
        solver=solver,
        margin=margin,
    )


def _description(value) -> str:
    if isinstance(value, DiscreteDMP):
        return f"a DiscreteDMP with {value.n_dofs} DOFs"
    return type(value).__name__


def _units(length: float, duration: float) -> dict:
    """Physical size of one scaled unit of each quantity."""
    return {
        "position": length,
        "velocity": length / duration,
        "acceleration": length / duration**2,
        "jerk": length / duration**3,
    }


def _objective(dmp, plan, target, objective, regularization, length):
    r"""``(s, H, g)``: scaling and the per-DOF QP objective in :math:`x = w / (L s)`.

    :math:`\|M w_d - b_d\|^2 + \lambda \|w_d - w^0_d\|^2`, with ``M`` the position response
    and ``b`` the moved demonstration minus the free plan (``"position"``), or ``M`` the phase
    features and ``b`` the reference's forcing term (``"forcing"``).
    """
    n_steps = plan.times.size
    if objective == "position":
        matrix = plan.weight_response[0]
        targets = target - plan.free[0]
        prior = np.zeros((dmp.n_dofs, dmp.n_basis))
    else:
        matrix = dmp.phase_features(n_steps, plan.times[1] - plan.times[0])
        prior = dmp.forcing_weights()
        targets = matrix @ prior.T
    key = exact(np.array([regularization, length, dmp.n_basis]), matrix, targets, prior)
    return _OBJECTIVES(
        key,
        lambda: _normal_equations(matrix, targets, prior, regularization, length, dmp.n_basis),
    )


_OBJECTIVES = Recall(4)
"""Objectives of the last exact inputs of :func:`_objective`: fits of one demonstration to the
same request under other constraints (bounds, end conditions) share theirs."""


def _normal_equations(matrix, targets, prior, regularization, length, n_basis):
    """``(s, H, g)`` of :func:`_objective` from ``M``, ``b`` and :math:`w^0`."""
    gram = matrix.T @ matrix
    lam = regularization * np.trace(gram) / n_basis
    scale = 1.0 / np.maximum(np.sqrt(np.diag(gram) + lam), 1e-300)
    hessian = scale[:, None] * (gram + lam * np.eye(n_basis)) * scale[None, :]  # unit diagonal
    gradient = -((matrix.T @ targets + lam * prior.T) * scale[:, None]).T / length
    return scale, hessian, gradient


def _assemble(requested, plan, variable_scale, units, margin):
    """Groups with their rows and units, and the stacked rows (:func:`qp.scale_rows`)."""
    dt = plan.times[1] - plan.times[0]
    groups, parts, count = [], [], 0
    for group in requested:
        unit = units[group.quantity]
        matrix = sample(plan.weight_response, dt, group.quantity, group.at) * variable_scale
        offset = sample(plan.free, dt, group.quantity, group.at)
        part = scale_rows(matrix, offset, group.lower, group.upper, unit, margin)
        rows = slice(count, count + part.norms.size)
        groups.append(replace(group, unit=unit, rows=rows))
        parts.append(part)
        count = rows.stop
    return tuple(groups), stack_rows(parts, variable_scale.size, plan.free.shape[2])


def _working_sets(problem: FittingProblem, warm_start) -> np.ndarray | None:
    """The working sets of ``warm_start`` (a FitReport or None), checked against ``problem``."""
    if warm_start is None:
        return None
    if not isinstance(warm_start, FitReport):
        raise InvalidInputError(
            f"warm_start must be a FitReport (the report of a previous fit) or None, got "
            f"{type(warm_start).__name__}"
        )
    working_sets = warm_start.working_sets
    if working_sets is not None and working_sets.shape != problem.lower.shape:
        raise InvalidInputError(
            f"warm_start comes from a problem with {working_sets.shape} (DOFs, rows), this one "
            f"has {problem.lower.shape}; pass the report of a fit of the same size, or None"
        )
    return working_sets


def _failure(problem: FittingProblem, message: str, stats: dict) -> Exception:
    """:class:`InfeasibleProblem` if the constraints cannot hold, else FittingFailed(message)."""
    error = infeasibility_error(problem, stats["status"], stats)
    return error if error is not None else FittingFailed(message, problem=problem, stats=stats)


def solve_fitting_problem(problem: FittingProblem, *, warm_start=None) -> ConstrainedFit:
    """Solve a constrained fit built by :func:`build_fitting_problem`.

    The QP is solved per DOF with :func:`dmpopt.fitting.qp.solve_blocks`; if a via-point is
    Euclidean, the NLP of :meth:`FittingProblem.to_opti` with IPOPT instead. The returned DMP
    is rolled out and every constraint is checked on that rollout.

    Parameters
    ----------
    problem : FittingProblem
    warm_start : FitReport, optional
        The report of a previous fit of a problem of the same size: its working sets start
        the row generation (the answer does not depend on it, only the time).

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
        raise InvalidInputError(
            f"problem must be a FittingProblem, got {type(problem).__name__}; build one with "
            "build_fitting_problem(demo, ...) or call fit_weights_constrained(demo, ...)"
        )
    working_sets = _working_sets(problem, warm_start)
    if problem.is_qp:
        qp = solve_blocks(
            problem.hessian,
            problem.gradient,
            problem.constraint_matrix,
            problem.lower,
            problem.upper,
            solver=problem.solver,
            working_sets=working_sets,
        )
        x, success, status, solve_time, iterations = (
            qp.x,
            qp.success,
            qp.status,
            qp.solve_time,
            qp.iterations,
        )
        working_sets, solver = qp.active, qp.solver
    else:
        x, success, status, solve_time, iterations = solve_nlp(problem)
        working_sets, solver = None, "ipopt"
    stats = {"solver": solver, "status": status, "solve_time": solve_time, "iterations": iterations}
    if not success or not np.all(np.isfinite(x)):
        remedy = (
            "try another solver ('daqp', 'qpoases') or a larger regularization"
            if problem.is_qp
            else "so a Euclidean via-point may be out of reach of them: widen its tolerance, "
            "move it or relax the bounds"
        )
        raise _failure(
            problem,
            f"the {solver} solver failed ({status}) although the linear constraints can "
            f"hold; {remedy}",
            stats,
        )
    dmp = problem.dmp_for(problem.forcing_weights(x))
    trajectory = problem.rollout(dmp)
    violations = problem.violations(trajectory)
    relative = problem.relative_violations(violations)
    worst = max(relative, key=relative.get) if relative else None
    if worst is not None and relative[worst] > FEASIBILITY_TOLERANCE:
        raise _failure(
            problem,
            f"the {solver} answer violates '{worst}' by {violations[worst]:.3g} on the "
            "rollout; raise margin (build_fitting_problem) or try another solver",
            stats,
        )
    report = FitReport(
        solver, status, solve_time, iterations, violations, trajectory, problem, working_sets
    )
    return ConstrainedFit(dmp, report)


def fit_weights_constrained(
    demo: Trajectory, n_basis: int = 30, *, warm_start=None, **options
) -> ConstrainedFit:
    """Build and solve a constrained fit in one call.

    ``solve_fitting_problem(build_fitting_problem(demo, n_basis, **options), warm_start=...)``;
    ``options`` are the keywords of :func:`build_fitting_problem`, the errors those of both.
    """
    if isinstance(demo, FittingProblem):
        raise InvalidInputError(
            "demo must be a Trajectory, got a FittingProblem; solve a built problem with "
            "solve_fitting_problem(problem)"
        )
    problem = build_fitting_problem(demo, n_basis, **options)
    return solve_fitting_problem(problem, warm_start=warm_start)


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
    "solve_fitting_problem",
    "solve_qp",
]
