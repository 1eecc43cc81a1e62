r"""The one QP layer of the fitting modules: backends, settings, row generation, warm start.

Every quadratic programme of :mod:`dmpopt.fitting` (constrained DMP fits, minimum-jerk
baselines, infeasibility diagnosis) is dense,

.. math:: \min_x \tfrac12 x^T H x + g^T x \quad\text{s.t.}\quad l \le A x \le u,

with rows scaled to unit norm (:func:`scale_rows`) and is solved by :func:`solve_qp`; a
problem made of independent blocks with the same ``H`` and ``A`` (one per DOF) by
:func:`solve_blocks`, which falls back to qpOASES on a block the first backend fails.

Solver output: DAQP and ProxQP are silent with the settings below. qpOASES (through CasADi)
prints its copyright banner on every solve whatever its ``printLevel``; it is left printing
(it runs only as the fallback and to confirm an infeasibility).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from ..exceptions import InvalidInputError, ShapeError
from ..validation import real_array

SOLVERS = ("daqp", "qpoases", "proxsuite")
DEFAULT_SOLVER = "daqp"
"""QP backend used by ``solver="auto"`` (see ``benchmarks/bench_constrained.py``)."""
FALLBACK_SOLVER = "qpoases"
"""Backend tried on a block that the first one failed (it also confirms infeasibility)."""
ZERO_ROW = 1e-12
"""Rows of smaller norm (in units of their group) are not normalised (:func:`scale_rows`)."""
INFINITY = 1e20
"""Bound that stands for a free side (the backends take finite numbers)."""
ACTIVE_MULTIPLIER = 1e-9
"""A row is in the working set if its multiplier exceeds this, relative (ProxQP's multipliers
of inactive rows are tiny, not zero)."""
PROXSUITE_TOLERANCE = 1e-8  # absolute; relative tolerance 0
DAQP_PRIMAL_TOLERANCE = 1e-10


def check_solver(solver) -> str:
    """The backend named by ``solver`` (``"auto"`` is :data:`DEFAULT_SOLVER`)."""
    if solver == "auto":
        return DEFAULT_SOLVER
    if not isinstance(solver, str) or solver not in SOLVERS:
        raise InvalidInputError(f"solver must be 'auto' or one of {SOLVERS}, got {solver!r}")
    return solver


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


def _proxsuite_solve(hessian, gradient, matrix, lower, upper):
    import proxsuite

    n, m = hessian.shape[0], matrix.shape[0]
    qp = proxsuite.proxqp.dense.QP(n, 0, m)
    qp.settings.eps_abs = PROXSUITE_TOLERANCE
    qp.settings.eps_rel = 0.0
    qp.settings.verbose = False
    qp.init(hessian, gradient, None, None, matrix, lower, upper)
    qp.solve()
    status = qp.results.info.status
    success = status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
    return np.array(qp.results.x), np.array(qp.results.z), bool(success), str(status)


def _casadi_solve(solver, hessian, gradient, matrix, lower, upper):
    import casadi as ca

    n, m = hessian.shape[0], matrix.shape[0]
    options = {"error_on_fail": False}
    if solver == "qpoases":
        options["printLevel"] = "none"
    else:
        options["daqp"] = {"primal_tol": DAQP_PRIMAL_TOLERANCE}
    structure = {"h": ca.Sparsity.dense(n, n), "a": ca.Sparsity.dense(m, n)}
    function = ca.conic("dmpopt_qp", solver, structure, options)
    result = function(h=hessian, g=gradient, a=matrix, lba=lower, uba=upper)
    stats = function.stats()
    status = str(stats.get("return_status", stats.get("unified_return_status", "")))
    success = bool(stats.get("success", False))
    return result["x"].full().ravel(), result["lam_a"].full().ravel(), success, status


def _backend_solve(solver, hessian, gradient, matrix, lower, upper):
    """One dense solve with the chosen backend: ``(x, multipliers, success, status)``."""
    if solver == "proxsuite":
        return _proxsuite_solve(hessian, gradient, matrix, lower, upper)
    return _casadi_solve(solver, hessian, gradient, matrix, lower, upper)


def _checked_qp(hessian, gradient, constraint_matrix, lower, upper):
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
    crossed = np.nonzero(lower > upper)[0]
    if crossed.size:
        raise InvalidInputError(
            f"lower exceeds upper in row(s) {crossed[:5].tolist()} of constraint_matrix (e.g. "
            f"{lower[crossed[0]]:g} > {upper[crossed[0]]:g}); give lower <= upper"
        )
    return hessian, gradient, matrix, lower, upper


def _first_rows(lower, upper, stride, rows) -> np.ndarray:
    """Rows of the first round: every ``stride``-th, the last, equalities and ``rows``."""
    selected = np.zeros(lower.size, dtype=bool)
    if rows is not None:  # warm start: the previous working set and a sparser grid
        stride = 5 * stride
    selected[:: max(int(stride), 1)] = True
    selected[-1:] = True
    selected |= np.isfinite(lower) & np.isfinite(upper) & (upper - lower < 1e-12)
    if rows is not None:
        selected |= np.asarray(rows, dtype=bool)
    return selected


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
        changes between neighbouring samples); prints its banner (module docstring).
    ``"proxsuite"``
        the standalone proxsuite dense ProxQP. casadi 3.8's ``proxqp`` conic plugin reports
        these problems infeasible and is not offered; the standalone solver can also stop
        with a (wrong) infeasibility status on them, reported as a failure.

    Returns
    -------
    QpSolution
    """
    solver = check_solver(solver)
    hessian, gradient, matrix, lower, upper = _checked_qp(
        hessian, gradient, constraint_matrix, lower, upper
    )
    begin = time.perf_counter()
    selected = _first_rows(lower, upper, stride, rows)
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
    active = np.zeros(lower.size, dtype=bool)
    multipliers = np.abs(multipliers[: index.size])
    active[index[multipliers > ACTIVE_MULTIPLIER * (1.0 + multipliers.max(initial=0.0))]] = True
    return QpSolution(x, success, status, time.perf_counter() - begin, rounds, active)


class BlockSolution(NamedTuple):
    """Result of :func:`solve_blocks`; ``failed_block`` is -1 on success."""

    x: np.ndarray  # (n_blocks, n)
    active: np.ndarray  # (n_blocks, m) working sets
    success: bool
    status: str  # the last block's
    solver: str  # "daqp", or "daqp+qpoases" if the fallback solved a block
    solve_time: float  # [s], summed over blocks
    iterations: int  # rounds of row generation, summed over blocks
    failed_block: int


def solve_blocks(
    hessian, gradients, constraint_matrix, lower, upper, *, solver="auto", working_sets=None
) -> BlockSolution:
    """Solve one QP per row of ``gradients``, ``lower``, ``upper`` (same ``H`` and ``A``).

    Each block is solved with ``solver`` and, if that fails, with :data:`FALLBACK_SOLVER`;
    the first block that both fail stops the loop. ``working_sets`` (n_blocks, m), e.g.
    ``active`` of a previous solution, warm-starts the row generation of :func:`solve_qp`.
    """
    solver = check_solver(solver)
    n_blocks = len(gradients)
    x = np.full((n_blocks, np.shape(hessian)[0]), np.nan)
    active = np.zeros(np.shape(lower), dtype=bool)
    name, solve_time, iterations, status = solver, 0.0, 0, ""
    for block in range(n_blocks):
        for backend in dict.fromkeys([solver, FALLBACK_SOLVER]):
            solution = solve_qp(
                hessian,
                gradients[block],
                constraint_matrix,
                lower[block],
                upper[block],
                solver=backend,
                rows=None if working_sets is None else working_sets[block],
            )
            solve_time += solution.solve_time
            iterations += solution.iterations
            if solution.success:
                break
        if backend != solver:
            name = f"{solver}+{backend}"
        status = solution.status
        if not solution.success:
            return BlockSolution(x, active, False, status, name, solve_time, iterations, block)
        x[block], active[block] = solution.x, solution.active
    return BlockSolution(x, active, True, status, name, solve_time, iterations, -1)


class ScaledRows(NamedTuple):
    """Constraint rows of unit norm and their bounds (see :func:`scale_rows`)."""

    matrix: np.ndarray  # (m, n)
    lower: np.ndarray  # (m, n_blocks)
    upper: np.ndarray  # (m, n_blocks)
    norms: np.ndarray  # (m,): row in units = stored row * norm


def scale_rows(matrix, offset, lower, upper, unit: float, margin: float) -> ScaledRows:
    """Rows ``lower <= offset + matrix @ x <= upper`` in units of ``unit``, of unit norm.

    ``matrix`` (m, n) maps the scaled variables to the quantity; ``offset``, ``lower`` and
    ``upper`` broadcast to (m, n_blocks), ``-inf``/``inf`` for a free side. A box wider than
    twice ``margin * unit`` is tightened by ``margin`` units on both sides, so that the answer
    holds despite the solver's tolerance; bounds are then clipped to :data:`INFINITY`. A row of
    norm below :data:`ZERO_ROW` (a quantity the variables cannot change, such as the first
    sample's position) is kept as it is: normalising it would blow its bounds up to infinity
    and hide how far a fixed value lies outside its limits.
    """
    offset = np.asarray(offset, dtype=float)
    shape = (matrix.shape[0], offset.shape[-1])
    low = np.broadcast_to(lower, shape).astype(float)
    high = np.broadcast_to(upper, shape).astype(float)
    scaled = matrix / unit
    norms = np.linalg.norm(scaled, axis=1)[:, None]
    norms[norms < ZERO_ROW] = 1.0  # a row the variables do not move (a fixed start) stays
    tight = (high - low) > 2 * margin * unit
    low = np.where(np.isfinite(low), (low - offset) / unit + margin * tight, -np.inf)
    high = np.where(np.isfinite(high), (high - offset) / unit - margin * tight, np.inf)
    return ScaledRows(
        scaled / norms,
        np.clip(low / norms, -INFINITY, INFINITY),
        np.clip(high / norms, -INFINITY, INFINITY),
        norms[:, 0],
    )


def stack_rows(parts: list[ScaledRows], n: int, n_blocks: int) -> ScaledRows:
    """The rows of ``parts`` one below the other; bounds transposed to (n_blocks, m)."""
    if not parts:
        return ScaledRows(
            np.zeros((0, n)), np.zeros((n_blocks, 0)), np.zeros((n_blocks, 0)), np.zeros(0)
        )
    return ScaledRows(
        np.vstack([p.matrix for p in parts]),
        np.vstack([p.lower for p in parts]).T,
        np.vstack([p.upper for p in parts]).T,
        np.concatenate([p.norms for p in parts]),
    )


__all__ = [
    "DEFAULT_SOLVER",
    "SOLVERS",
    "BlockSolution",
    "QpSolution",
    "ScaledRows",
    "check_solver",
    "scale_rows",
    "solve_blocks",
    "solve_qp",
    "stack_rows",
]
