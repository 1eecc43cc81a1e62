r"""A built constrained fit (the QP's matrices, constraint groups, views) and its result.

Built by :func:`dmpopt.fitting.constrained.build_fitting_problem`, solved by
:func:`dmpopt.fitting.constrained.solve_fitting_problem` (module docstring there).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..dmp import AffinePlan, DiscreteDMP
from ..trajectory import Trajectory
from . import groups as _groups
from .nlp import to_opti
from .requests import Bounds


@dataclass(frozen=True, eq=False)
class FittingProblem:
    r"""A constrained fit, ready to solve and open for inspection; a frozen value.

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
    objective : {"position", "forcing"}
    duration, dt : float
        [s]
    start_velocity : ndarray, shape (n_dofs,)
    length_scale : float
        ``L``.
    scale : ndarray, shape (n_basis,)
        ``s``: weights divided by their objective column norm.
    hessian : ndarray, shape (n_basis, n_basis)
    gradient : ndarray, shape (n_dofs, n_basis)
    constraint_matrix : ndarray, shape (n_rows, n_basis)
        Rows scaled to unit norm.
    lower, upper : ndarray, shape (n_dofs, n_rows)
    row_scale : ndarray, shape (n_rows,)
        Norm removed from each row (row in group units = stored row * ``row_scale``).
    groups : tuple of ConstraintGroup
        Which rows encode which request, with the requested limits.
    bounds : Bounds or None
    via_points : tuple of ViaPoint
    balls : tuple of BallViaPoint
        Euclidean via-points (non-linear: force the NLP).
    solver : str
        QP backend (:mod:`dmpopt.fitting.qp`).
    margin : float
        Tightening of the inequalities, in units of each group.
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
        """The DMP with these forcing weights at the problem's start, goal, tau, start velocity."""
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
        return _groups.violations(self.groups, self.balls, trajectory)

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
        the NLP that is solved when ``balls`` is not empty.
        """
        return to_opti(self)


@dataclass(frozen=True, eq=False)
class FitReport:
    """What a constrained fit did.

    Attributes
    ----------
    solver : str
        ``"daqp"``, ``"qpoases"``, ``"proxsuite"`` or ``"ipopt"`` (the NLP); ``"daqp+qpoases"``
        if the fallback solved a DOF.
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
    working_sets : ndarray of bool, shape (n_dofs, n_rows), or None
        Rows active at the QP's solution (``None`` for the NLP); pass this report as
        ``warm_start`` to the next fit of a problem of the same size.
    """

    solver: str
    status: str
    solve_time: float
    iterations: int
    violations: dict
    trajectory: Trajectory
    problem: FittingProblem
    working_sets: np.ndarray | None = None


class ConstrainedFit(NamedTuple):
    """``(dmp, report)`` returned by :func:`solve_fitting_problem`."""

    dmp: DiscreteDMP
    report: FitReport
