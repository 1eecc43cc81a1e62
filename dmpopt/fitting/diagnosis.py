r"""Why a constrained fit is infeasible: the smallest relaxation of each constraint group.

Per DOF, the elastic problem

.. math:: \min_{x, s} \sum_g s_g + \epsilon(\|x\|^2 + \|s\|^2) \quad\text{s.t.}\quad
          l_g - s_g \le A_g x \le u_g + s_g, \quad s \ge 0,

has one slack :math:`s_g` per constraint group ``g``, in the group's physical unit; a group
whose slack is positive must be relaxed by at least that much.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import FittingFailed, InfeasibleProblem, InvalidInputError
from .problem import FittingProblem
from .qp import FALLBACK_SOLVER, INFINITY, solve_qp

ELASTIC_REGULARIZATION = 1e-6
"""``epsilon``: makes the elastic LP a strictly convex QP."""


def _elastic_qp(problem):
    """``(H, g, A)`` of the elastic problem over ``(x, s)``, rows in group units."""
    n, n_groups = problem.n_basis, len(problem.groups)
    matrix_units = problem.constraint_matrix * problem.row_scale[:, None]
    membership = np.zeros((matrix_units.shape[0], n_groups))
    for g, group in enumerate(problem.groups):
        membership[group.rows, g] = 1.0
    matrix = np.block(
        [
            [matrix_units, membership],
            [matrix_units, -membership],
            [np.zeros((n_groups, n)), np.eye(n_groups)],
        ]
    )
    gradient = np.concatenate([np.zeros(n), np.ones(n_groups)])
    return ELASTIC_REGULARIZATION * np.eye(n + n_groups), gradient, matrix


def _elastic_bounds(problem, d: int):
    """Bounds of the elastic rows for DOF ``d``: ``A x + s >= l``, ``A x - s <= u``, ``s >= 0``."""
    m, n_groups = problem.row_scale.size, len(problem.groups)
    lower = np.concatenate(
        [problem.lower[d] * problem.row_scale, np.full(m, -INFINITY), np.zeros(n_groups)]
    )
    upper = np.concatenate(
        [np.full(m, INFINITY), problem.upper[d] * problem.row_scale, np.full(n_groups, INFINITY)]
    )
    return lower, upper


def diagnose_infeasibility(problem) -> dict:
    """Smallest relaxation of each constraint group, per DOF, that makes the QP feasible.

    Returns ``{group name: (relaxation in physical units, DOFs)}`` for the groups that need
    one (module docstring); empty if the linear constraints can all hold.
    """
    if not isinstance(problem, FittingProblem):
        raise InvalidInputError(
            f"problem must be a FittingProblem, got {type(problem).__name__}; "
            "build one with build_fitting_problem(...)"
        )
    n_groups = len(problem.groups)
    if n_groups == 0:
        return {}
    hessian, gradient, matrix = _elastic_qp(problem)
    keep = np.zeros(matrix.shape[0], dtype=bool)
    keep[-n_groups:] = True  # s >= 0 from the start: the elastic LP is bounded
    relaxations = {}
    for d in range(problem.n_dofs):
        lower, upper = _elastic_bounds(problem, d)
        solution = solve_qp(
            hessian, gradient, matrix, lower, upper, solver=FALLBACK_SOLVER, rows=keep
        )
        if not solution.success:
            raise FittingFailed(
                f"the elastic problem that locates the infeasibility failed ({solution.status})",
                problem=problem,
            )
        for group, slack in zip(problem.groups, solution.x[problem.n_basis :]):
            if slack > 0.1 * problem.margin:
                amount, dofs = relaxations.get(group.name, (0.0, []))
                relaxations[group.name] = (max(amount, float(slack * group.unit)), dofs + [d])
    return relaxations


def infeasibility_error(problem, status: str, stats) -> InfeasibleProblem | None:
    """An :class:`InfeasibleProblem` naming the groups to relax, or ``None`` if feasible."""
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
