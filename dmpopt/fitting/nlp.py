"""The constrained fit as a CasADi NLP, solved with IPOPT when a via-point is Euclidean.

The problem is the QP of :class:`~dmpopt.fitting.constrained.FittingProblem` (same Hessian,
gradient and scaled rows) plus one quadratic inequality per ``"ball"`` via-point, which is
not linear. IPOPT runs with ``print_level`` 0 and without its banner (``sb``): it is silent.
"""

from __future__ import annotations

import time

import numpy as np

from .groups import sample

IPOPT_TOLERANCE = 1e-10


def to_opti(problem):
    """``(opti, x)``: ``problem`` as a ``casadi.Opti`` with IPOPT, ``x`` (n_basis, n_dofs)."""
    import casadi as ca

    opti = ca.Opti()
    x = opti.variable(problem.n_basis, problem.n_dofs)
    hessian = ca.DM(problem.hessian)
    # objective: closeness to the demonstration, one block per DOF
    cost = 0
    for d in range(problem.n_dofs):
        column = x[:, d]
        cost += 0.5 * ca.bilin(hessian, column, column) + ca.dot(ca.DM(problem.gradient[d]), column)
    opti.minimize(cost)
    # linear rows: limits at every sample, box via-points, end conditions
    if problem.constraint_matrix.shape[0]:
        rows = ca.mtimes(ca.DM(problem.constraint_matrix), x)
        for d in range(problem.n_dofs):
            low, high = ca.DM(problem.lower[d]), ca.DM(problem.upper[d])
            opti.subject_to(opti.bounded(low, rows[:, d], high))
    # Euclidean via-points: ||y(t_i) - p_i|| <= r_i, in units of L, margin inside
    plan, length = problem.plan, problem.length_scale
    for ball in problem.balls:
        row = sample(plan.weight_response, problem.dt, "position", ball.at)[0]
        offset = sample(plan.free, problem.dt, "position", ball.at)[0]
        scaled_row = ca.DM((row * problem.scale)[None, :])
        position = ca.mtimes(scaled_row, x).T + ca.DM((offset - ball.point) / length)
        inner = max(ball.radius / length - problem.margin, 0.0)
        opti.subject_to(ca.sumsqr(position) <= inner**2)
    options = {"print_level": 0, "sb": "yes", "tol": IPOPT_TOLERANCE}
    opti.solver("ipopt", {"print_time": False}, options)
    opti.set_initial(x, problem.variables(problem.dmp.forcing_weights()).T)
    return opti, x


def solve_nlp(problem):
    """``(x, success, status, solve_time, iterations)``, ``x`` of shape (n_dofs, n_basis)."""
    opti, variable = to_opti(problem)
    begin = time.perf_counter()
    try:
        solution = opti.solve()
        x, success = np.asarray(solution.value(variable), float), True
    except RuntimeError:
        x, success = np.full((problem.n_basis, problem.n_dofs), np.nan), False
    elapsed = time.perf_counter() - begin
    stats = opti.stats()
    x = x.reshape(problem.n_basis, problem.n_dofs).T
    return (
        x,
        success,
        str(stats.get("return_status", "")),
        elapsed,
        int(stats.get("iter_count", -1)),
    )
