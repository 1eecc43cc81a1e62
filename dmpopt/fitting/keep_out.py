r"""The constrained fit with keep-out regions: a plan that stays out of spheres and boxes.

The optimisation alternative to the online coupling terms of :mod:`dmpopt.obstacles`: the
weights of :func:`~dmpopt.fitting.constrained.build_fitting_problem` (closest to the
demonstration, with its bounds, via-points and end conditions) under one more inequality
per sample :math:`k` and region, on the plan's positions :math:`y_k = F_{0,k} + G_{0,k}
W_f^T` (affine in the weights):

* :class:`~dmpopt.obstacles.Sphere` of centre :math:`c` and radius :math:`\rho`:
  :math:`\|y_k - c\|^2 \ge (\rho + \delta)^2`;
* :class:`~dmpopt.obstacles.Box` of centre :math:`c` and half-widths :math:`h`: outside the
  box is :math:`\|(y_k - c) / h\|_\infty \ge 1`, non-smooth; it is replaced by
  :math:`\log \sum_i ((y_{k,i} - c_i) / h_i)^{p} \ge \log n` with :math:`p` =
  :data:`BOX_POWER` (the logarithm keeps the row of order one far from the box): since
  :math:`\|v\|_p \le n^{1/p}\|v\|_\infty`, every point outside this superellipsoid is
  outside the box (a conservative region, at most :math:`n^{1/p} - 1` wider per axis:
  9 % in 2-D, 15 % in 3-D).

These are non-convex, so the problem is the NLP of :meth:`FittingProblem.to_opti` with these
rows, solved by IPOPT from the unconstrained fit: a local optimum, which side of an obstacle
the plan passes is that of the demonstration's nearer free side. The regions hold at the
samples (``n_samples`` sets their density).
"""

from __future__ import annotations

import time
from typing import Sequence

import numpy as np

from ..exceptions import FittingFailed, InvalidInputError, ShapeError
from ..obstacles import Box, Sphere, clearance
from ..trajectory import Trajectory
from ..validation import sequence_of
from .constrained import FEASIBILITY_TOLERANCE, build_fitting_problem
from .problem import ConstrainedFit, FitReport

BOX_POWER = 8
"""Even exponent of the superellipsoid that stands for a box (see the module docstring)."""
IPOPT_TOLERANCE = 1e-8
"""IPOPT's tolerance here (the QP-equivalent NLP uses 1e-10; the non-convex rows converge
slowly to that)."""
MAX_ITERATIONS = 500


def fit_keep_out(
    demo: Trajectory,
    keep_out: Sequence[Sphere | Box],
    n_basis: int = 30,
    **options,
) -> ConstrainedFit:
    """Fit a discrete DMP to ``demo`` whose plan stays out of every region of ``keep_out``.

    Parameters
    ----------
    demo : Trajectory
    keep_out : sequence of Sphere or Box
        Regions in the demonstration's position space (one centre entry per DOF).
    n_basis : int
    **options
        Keywords of :func:`dmpopt.fitting.constrained.build_fitting_problem` (bounds,
        via-points, start, goal, duration, ``n_samples``, ``margin`` ...).

    Returns
    -------
    ConstrainedFit
        ``(dmp, report)``; ``report.violations["keep_out"]`` is the deepest penetration of
        the rollout into a region (0 when clear).

    Raises
    ------
    FittingFailed
        IPOPT found no plan that clears the regions (e.g. the start or goal lies inside
        one), or its plan violates a constraint on the rollout.
    """
    regions = sequence_of("keep_out", keep_out, (Sphere, Box))
    if not regions:
        raise InvalidInputError(
            "keep_out is empty; give Sphere or Box regions (or use fit_weights_constrained)"
        )
    problem = build_fitting_problem(demo, n_basis, **options)
    for k, region in enumerate(regions):
        if region.centre.shape != (problem.n_dofs,):
            raise ShapeError(
                f"keep_out[{k}] has a centre of shape {region.centre.shape}, expected "
                f"({problem.n_dofs},) for the demonstration's DOFs"
            )
    inside = [k for k, r in enumerate(regions) if r.distance(problem.dmp.start)[0] <= 0.0]
    inside += [k for k, r in enumerate(regions) if r.distance(problem.dmp.goal)[0] <= 0.0]
    if inside:
        raise InvalidInputError(
            f"the start or goal lies inside keep_out[{inside[0]}]; move the region or the "
            "start and goal"
        )
    import casadi as ca

    opti, x = problem.to_opti()
    length = problem.length_scale
    response = problem.plan.weight_response[0] * problem.scale  # (n_steps, n_basis)
    positions = ca.mtimes(ca.DM(response), x)  # scaled, minus the free plan, (n_steps, n_dofs)
    for region in regions:
        offset = ca.DM((problem.plan.free[0] - region.centre) / length)
        relative = positions + offset
        if isinstance(region, Sphere):
            outer = region.radius / length + problem.margin
            opti.subject_to(ca.sum2(relative**2) >= outer**2)
        else:
            half = ca.DM((region.half_widths / length + problem.margin)[None, :])
            scaled = relative / ca.repmat(half, relative.shape[0], 1)
            opti.subject_to(ca.log(ca.sum2(scaled**BOX_POWER)) >= np.log(problem.n_dofs))
    options = {"print_level": 0, "sb": "yes", "tol": IPOPT_TOLERANCE, "max_iter": MAX_ITERATIONS}
    opti.solver("ipopt", {"print_time": False}, options)
    begin = time.perf_counter()
    try:
        solution = opti.solve()
        values, success = np.asarray(solution.value(x), float), True
    except RuntimeError:
        values, success = np.full((problem.n_basis, problem.n_dofs), np.nan), False
    solve_time = time.perf_counter() - begin
    stats = opti.stats()
    status, iterations = str(stats.get("return_status", "")), int(stats.get("iter_count", -1))
    report_stats = {"solver": "ipopt", "status": status, "solve_time": solve_time}
    if not success or not np.all(np.isfinite(values)):
        raise FittingFailed(
            f"IPOPT found no plan clear of the keep-out regions ({status}); move or shrink "
            "them, or relax the bounds and end conditions",
            problem=problem,
            stats=report_stats,
        )
    dmp = problem.dmp_for(problem.forcing_weights(values.reshape(problem.n_basis, -1).T))
    trajectory = problem.rollout(dmp)
    violations = problem.violations(trajectory)
    violations["keep_out"] = float(max(-clearance(trajectory.positions, regions).min(), 0.0))
    relative = problem.relative_violations(violations)
    worst = max(relative, key=relative.get)
    if relative[worst] > FEASIBILITY_TOLERANCE:
        raise FittingFailed(
            f"the IPOPT answer violates '{worst}' by {violations[worst]:.3g} on the rollout; "
            "raise margin",
            problem=problem,
            stats=report_stats,
        )
    report = FitReport("ipopt", status, solve_time, iterations, violations, trajectory, problem)
    return ConstrainedFit(dmp, report)
