r"""Weighted QP inverse dynamics on Pinocchio and proxsuite (the role TSID plays in C++).

Unknowns :math:`x = (\ddot q, f_1, \dots, f_{n_c})`: joint accelerations and one 6-D wrench per
sole contact (in the sole frame). Each tick solves

.. math::

    \min_x \; \sum_k w_k \lVert J_k \ddot q - b_k \rVert^2
              + \epsilon_a \lVert \ddot q \rVert^2 + \epsilon_f \lVert f \rVert^2

    \text{s.t.}\quad
    M_b \ddot q + h_b = J_{c,b}^\top f                  \quad\text{(unactuated base rows)}

    \hphantom{\text{s.t.}\quad} J_c \ddot q = a_c^* - \dot J_c \dot q \quad\text{(rigid contacts)}

    \hphantom{\text{s.t.}\quad} -\tau_{\max} \le M_a \ddot q + h_a - J_{c,a}^\top f
                                \le \tau_{\max}           \quad\text{(torque limits)}

    \hphantom{\text{s.t.}\quad} C f \le u              \quad\text{(friction and CoP cones)}

    \hphantom{\text{s.t.}\quad} l(q, \dot q) \le \ddot q_a \le u(q, \dot q)
                                \quad\text{(joint limits, on by default)}

where the rows of :math:`M, h, J_c` are split into base (b) and actuated (a) coordinates, the
task terms come from :mod:`dmpopt.control.tasks`, the acceleration bounds l, u keep the joints
within their position and velocity limits (:func:`kernels.acceleration_bounds`), and the
torque is read off the equations of motion, :math:`\tau = M_a \ddot q + h_a - J_{c,a}^\top f`
[DelPrete2016]_.

The QP that proxsuite sees is smaller than this statement, with the same solution:

- **Constraints eliminated.** The base rows and the contact rows are :math:`n_b + 6 n_c`
  linear equations; they are solved each tick (one LU factorisation) for as many *basic*
  accelerations: the base and, per contact, the joints that move that sole (chosen once by a
  column-pivoted QR of the contact Jacobians; for Talos the 12 leg joints). The QP variables
  are the remaining accelerations and the wrenches, :math:`z`, with no equality rows: for the
  full Talos 44 variables instead of 62 and 18 equality rows, and the dynamics and contact
  equations hold to machine precision instead of the solver tolerance. If that basic block is
  ill-conditioned on a tick (a stretched leg), that tick falls back to eliminating only the
  base rows (with :math:`M_{bb}`, the robot's composite inertia, always positive definite) and
  keeping the contact rows as equality constraints.
- **Inequality rows on demand.** The QP without inequality rows is solved first; it is an
  unconstrained least-squares problem over z, solved by one Cholesky factorisation of its
  Hessian, without proxsuite. On a fixed base with a posture task on every joint, its Hessian
  is diagonal plus a low-rank term from the frame tasks (none for posture tasks alone): it is
  solved by the Woodbury identity, and :math:`\tau = \mathrm{RNEA}(q, \dot q, \ddot q)`,
  without the mass matrix.
  If its wrenches are inside the cones, its torques within the limits and its accelerations
  within their bounds, it is also the solution with them (a convex problem whose optimum
  without some constraints satisfies them); on the drumming study this holds on every tick.
  Otherwise the QP with the cone rows is solved, and if the torques leave their limits (or
  the accelerations their bounds) the QP with cone, torque and bound rows (over
  :math:`(\ddot q_a, f)`, base rows eliminated). A QP with more rows is used first on the
  following ticks until its extra rows are slack by a margin (1 % of the torque limits,
  0.01 rad/s^2 for the bounds, 0.1 % of the robot's weight for the cones).

Pinocchio computes the model terms and task quantities; everything after them on a tick
without an active inequality row (elimination, reduced Hessian and gradient, Cholesky or
Woodbury solve, torques, cone and torque checks) runs as one compiled call of
:mod:`dmpopt.control.kernels`, as do the tasks' PD laws: in NumPy each of those small
operations would cost about a microsecond whatever its size, and a tick would make about 75.

The wrenches enter the QP divided by the robot's weight, so that forces and accelerations have
the same scale. Every proxsuite QP is sized once and warm-started from its previous primal and
dual solution; the constant cone rows are passed to proxsuite once. A warm start carries the
previous tick's multipliers, so proxsuite's residuals can be small while its active set is
stale: with a proximal parameter of 1e-8 it returned feasible points whose cost exceeded the
optimum by up to 268 times it (Talos with weak motors). So proxsuite keeps its default
proximal parameter, also checks the duality gap, and its answer is refined to the exact
optimum of its active set (:func:`_active_set`). Before proxsuite, each QP is tried by
active-set iterations from its previous tick's active set: in a closed loop that set is
usually still optimal, and the tick costs one KKT solve. Either way the answer carries the
KKT certificate of :func:`_active_set` (when no active set verifies after proxsuite,
proxsuite's answer to its tolerance is kept). A tick that cannot be solved gives a defined
degraded answer within its time budget (see :class:`InverseDynamicsController`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin
import proxsuite
import scipy.linalg
from scipy.linalg import lapack

from dmpopt.exceptions import InvalidInputError, NoSolutionFound, ShapeError

from . import kernels
from .tasks import FrameTask, PointContact, PostureTask, SoleContact, Task

CONTACT_TYPES = (SoleContact, PointContact)

__all__ = ["JOINT_LIMIT_TOLERANCE", "ContactSetQP", "ControllerStats"]

_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
_MAX_ITER = proxsuite.proxqp.QPSolverOutput.PROXQP_MAX_ITER_REACHED
_WARM = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
_COLD = proxsuite.proxqp.InitialGuess.NO_INITIAL_GUESS
_DIRECT = "CHOLESKY_SOLVED"  # ControllerStats.last_status of a tick without inequality rows
_ACTIVE_SET = "ACTIVE_SET_SOLVED"  # ... of a QP solved by active-set iterations alone
_NO_BOUND = 1e20  # proxsuite treats |bound| >= 1e20 as absent
_RELEASE_MARGIN = 0.99  # leave the torque-limited QP once all |tau| < 0.99 tau_max
_BOUND_RELEASE_MARGIN = 1e-2  # ... and all joint accelerations 0.01 rad/s^2 inside their bounds
_MIRRORED_SETTINGS = (
    "eps_abs", "eps_rel", "eps_duality_gap_abs", "max_iter", "max_iter_in", "verbose",
)  # fmt: skip
# [rad] how far past a position limit the acceleration bounds let a joint go: a joint resting
# exactly at its limit then leaves its bound slack.
JOINT_LIMIT_TOLERANCE = 1e-3
# Inner iterations per outer iteration of proxsuite (its default 1500): with max_iter, the cap
# on one solve's iterations.
_MAX_INNER_ITERATIONS = 10
# Weight of the slacks of the relaxed QP (contact and acceleration-bound rows), per row.
_RELAXATION_WEIGHT = 1e4
# Active-set refinement rounds after proxsuite (each one KKT solve).
_REFINEMENT_ROUNDS = 10
# Active-set rounds from the previous tick's active set before proxsuite is called.
_WARM_ROUNDS = 5
# Share of the time budget the exact QP may use; the rest is left to the relaxed QP.
_EXACT_SHARE = 0.5
# proxsuite runs in calls of this many outer iterations, the time budget checked between
# (always the same calls, so that the time taken does not change the answer).
_CHUNK_ITERATIONS = 3
# Leave the QP with cone rows once all are slack by this fraction of the robot's weight [N].
_CONE_RELEASE_MARGIN = 1e-3
# Smallest |pivot| ratio of the LU factorisation of the basic block for the elimination.
_MIN_PIVOT_RATIO = 1e-9


@dataclass
class ControllerStats:
    """Counters of the controller's answers and solver health since construction or
    :meth:`~InverseDynamicsController.reset`.

    Every tick gives one of four answers (see :class:`InverseDynamicsController`, Notes),
    counted in ``n_direct``, ``n_solved``, ``n_relaxed`` and ``n_fallbacks``.

    Attributes
    ----------
    n_ticks : int
        Calls to :meth:`InverseDynamicsController.compute_torques`.
    n_direct : int
        Ticks solved without proxsuite: no inequality row was active, so the QP reduced to a
        least-squares problem (one Cholesky factorisation, or closed form for posture tasks
        on a fixed base).
    n_solved : int
        Ticks whose QP with its active inequality rows was solved, by active-set iterations
        from the last tick's active set or by proxsuite.
    n_relaxed : int
        Ticks whose QP could not be solved (infeasible, or out of iterations) and that
        returned the solution of the relaxed QP.
    n_fallbacks : int
        Ticks that returned the hold torque (relaxed QP failed too, or out of time).
    n_cold_restarts : int
        Warm-started solves that failed and were solved again from scratch.
    n_torque_limited : int
        Ticks that needed the QP with torque-limit and acceleration-bound rows.
    last_answer : str
        ``"direct"``, ``"solved"``, ``"relaxed"`` or ``"hold"``.
    last_status : str
        proxsuite status of the last solve, ``"CHOLESKY_SOLVED"`` for a direct one,
        ``"ACTIVE_SET_SOLVED"`` for one solved by active-set iterations alone, or
        ``"NON_FINITE_PROBLEM"`` for a QP refused before proxsuite (a NaN in a task).
    last_iterations : int
        Iterations of the last solve (proxsuite's inner iterations, or KKT solves).
    """

    n_ticks: int = 0
    n_direct: int = 0
    n_solved: int = 0
    n_relaxed: int = 0
    n_fallbacks: int = 0
    n_cold_restarts: int = 0
    n_torque_limited: int = 0
    last_answer: str = "not run"
    last_status: str = "not run"
    last_iterations: int = 0


class _Stage:
    """One QP with its proxsuite solver, its own warm start and the (preallocated) arrays it
    reads.

    ``problem`` is (H, g, A, b, C, l, u), None for absent blocks: what the active-set
    iterations read. ``at_upper`` and ``at_lower`` mark the rows active at the last solution
    (``known``): the next tick starts from them. ``stale``: inequality bounds changed (a
    contact transition), so the next proxsuite update passes them too.
    """

    __slots__ = (
        "qp", "initialized", "init_arguments", "update_arguments", "problem", "at_upper",
        "at_lower", "known", "stale",
    )  # fmt: skip

    def __init__(self, n, n_eq, n_in, backend, init_arguments, update_arguments):
        dense = proxsuite.proxqp.dense
        self.qp = dense.QP(n, n_eq, n_in, False, dense.HessianType.Dense, backend)
        settings = self.qp.settings
        settings.verbose = False
        settings.initial_guess = _WARM
        settings.max_iter_in = _MAX_INNER_ITERATIONS
        # Stop on a small duality gap too, not only on small residuals: a warm start from the
        # previous tick's multipliers can have small residuals with a stale active set.
        settings.check_duality_gap = True
        self.initialized = False
        self.init_arguments = init_arguments
        self.update_arguments = update_arguments
        self.problem = (init_arguments + (None,) * 5)[:7]
        self.at_upper = np.zeros(n_in, dtype=bool)
        self.at_lower = np.zeros(n_in, dtype=bool)
        self.known = False
        self.stale = False  # bounds changed since proxsuite last saw them: update with all


def _arguments(hessian, gradient, equalities=None, inequalities=None) -> tuple:
    """Positional arguments of proxsuite's init/update, with None for absent blocks."""
    arguments = (hessian, gradient)
    if equalities is not None:
        arguments += equalities
    elif inequalities is not None:
        arguments += (None, None)
    if inequalities is not None:
        arguments += inequalities
    return arguments


def _check_positive(name: str, value) -> None:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if isinstance(value, bool) or not (math.isfinite(number) and number > 0):
        raise InvalidInputError(f"{name} must be a finite number > 0, got {value!r}")


def _check_items(robot, tasks, contacts) -> None:
    """Tasks and contacts of the right types, built for this robot."""
    if isinstance(tasks, Task) or isinstance(contacts, CONTACT_TYPES):
        raise InvalidInputError(
            "tasks and contacts must be sequences; wrap a single one in a list: [task]"
        )
    if not tasks:
        raise InvalidInputError("tasks is empty; give at least one task (e.g. PostureTask)")
    for name, items, kind in (("tasks", tasks, Task), ("contacts", contacts, CONTACT_TYPES)):
        for item in items:
            if not isinstance(item, kind):
                expected = "Task" if kind is Task else "SoleContact or PointContact"
                raise InvalidInputError(
                    f"{name} holds {type(item).__name__!s}, expected {expected} objects"
                )
            model = getattr(item, "model", robot.model)  # a user's Task may have none
            if model.nv != robot.nv or model.nq != robot.model.nq:
                raise ShapeError(
                    f"{name}: a {type(item).__name__} was built for another robot than "
                    f"{robot.name!r} (nq={robot.model.nq}, nv={robot.nv}); build it with "
                    "the controller's robot"
                )


def _active_set(
    problem: tuple, at_upper: np.ndarray, at_lower: np.ndarray, tolerance: float, rounds: int
) -> tuple[np.ndarray | None, int]:
    r"""Primal-dual active-set iterations from the active set ``at_upper | at_lower``.

    The QP restricted to its active rows as equalities is one linear KKT solve,

    .. math:: \begin{bmatrix} H & E^\top \\ E & 0 \end{bmatrix}
              \begin{bmatrix} x \\ \nu \end{bmatrix} = \begin{bmatrix} -g \\ e
              \end{bmatrix}.

    Its solution is the optimum (the certificate) if every inactive row holds to
    ``tolerance`` and every multiplier has the sign of its side (:math:`\nu \ge 0` at an
    upper bound, :math:`\le 0` at a lower one): the KKT conditions then hold exactly.
    Otherwise the rows of the wrong sign leave the set, or else the most violated row enters
    it, for at most ``rounds`` solves. ``at_upper`` and ``at_lower`` are updated in place.

    Returns
    -------
    (x, solves) : the certified optimum, or None if no set verified (or the active rows are
    dependent); and the number of KKT solves made.
    """
    hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper = problem
    n = hessian.shape[0]
    if in_matrix is None:  # no inequality rows
        in_matrix, lower, upper = np.zeros((0, n)), np.zeros(0), np.zeros(0)
    for solves in range(1, rounds + 1):
        rows = np.flatnonzero(at_upper | at_lower)
        bounds = np.where(at_upper, upper, lower)[rows]
        matrix, target = in_matrix[rows], bounds
        if eq_matrix is not None:
            matrix, target = np.vstack([eq_matrix, matrix]), np.concatenate([eq_vector, bounds])
        m = matrix.shape[0]
        kkt = np.zeros((n + m, n + m))
        kkt[:n, :n], kkt[:n, n:], kkt[n:, :n] = hessian, matrix.T, matrix
        solution = np.concatenate([-gradient, target])
        if not kernels.solve_in_place(kkt, solution):  # dependent active rows
            return None, solves
        candidate, multipliers = solution[:n], solution[n + m - rows.size :]
        slack = 1e-9 * max(1.0, float(np.abs(multipliers).max(initial=0.0)))
        wrong = np.zeros_like(at_upper)
        wrong[rows] = np.where(at_upper[rows], multipliers < -slack, multipliers > slack)
        if wrong.any():  # these rows leave the active set
            at_upper &= ~wrong
            at_lower &= ~wrong
            continue
        values = in_matrix @ candidate
        violation = np.maximum(values - upper, lower - values)
        if not violation.size or violation.max() <= tolerance:
            return candidate, solves
        worst = int(np.argmax(violation))
        at_upper[worst] = values[worst] > upper[worst]
        at_lower[worst] = values[worst] < lower[worst]
    return None, rounds


def _contact_joints(robot, contacts, n_base: int) -> np.ndarray | None:
    """Velocity indices of as many joints as contact rows that move the feet, or None.

    Chosen by a column-pivoted QR of the contacts' actuated Jacobian columns in the reference
    configuration (for Talos: the 12 leg joints); None if that block is rank deficient.
    """
    model, data = robot.model, robot.create_data()
    pin.computeJointJacobians(model, data, robot.reference_configuration)
    pin.updateFramePlacements(model, data)
    jacobian = np.vstack([c.contact_jacobian(data) for c in contacts])[:, n_base:]
    n_rows = jacobian.shape[0]
    if n_rows > jacobian.shape[1]:
        return None
    r, pivots = scipy.linalg.qr(jacobian, mode="r", pivoting=True)
    diagonal = np.abs(np.diagonal(r))
    if diagonal.size < n_rows or diagonal[n_rows - 1] < 1e-6 * diagonal[0]:
        return None
    return np.sort(pivots[:n_rows]) + n_base


class ContactSetQP:
    """The QP of :class:`~dmpopt.control.InverseDynamicsController` for one set of active
    contacts and tasks: its rows, eliminated basic joints, sized proxsuite QPs and compiled
    stages (see the module docstring). The controller builds one per set it meets and keeps
    them; the parameters are the controller's.
    """

    def __init__(
        self,
        robot,
        tasks: Sequence[Task],
        contacts: Sequence[SoleContact] = (),
        *,
        acceleration_regularization: float = 1e-6,
        force_regularization: float = 1e-8,
        tolerance: float = 1e-6,
        max_iterations: int = 50,
        time_budget: float = 5e-3,
        raise_on_failure: bool = False,
        joint_limit_horizon: float | None = 0.05,
        limited_joints: str | Sequence[str] | None = None,
        torque_limit_scale: float = 1.0,
        dense_backend=proxsuite.proxqp.dense.DenseBackend.PrimalDualLDLT,
    ):
        _check_items(robot, tasks, contacts)
        for name, value in (
            ("acceleration_regularization", acceleration_regularization),
            ("force_regularization", force_regularization),
            ("tolerance", tolerance),
            ("time_budget", time_budget),
            ("torque_limit_scale", torque_limit_scale),
        ):
            _check_positive(name, value)
        if isinstance(max_iterations, bool) or not (
            isinstance(max_iterations, (int, np.integer)) and max_iterations >= 1
        ):
            raise InvalidInputError(
                f"max_iterations must be an integer >= 1, got {max_iterations!r}"
            )
        self.time_budget = float(time_budget)
        self._deadline = self._exact_deadline = 0.0
        self.robot = robot
        self.model = robot.model
        self.data = robot.create_data()
        # Views of the mass matrix and bias forces, refilled in place by computeAllTerms.
        self._mass, self._bias = self.data.M, self.data.nle
        self.tasks = tuple(tasks)
        self.contacts = tuple(contacts)
        self.raise_on_failure = raise_on_failure

        nv, n_act, n_c = robot.nv, robot.n_actuated, len(self.contacts)
        force_offsets = np.cumsum([0] + [c.n_force for c in self.contacts]).astype(int)
        cone_offsets = np.cumsum([0] + [c.wrench_upper.size for c in self.contacts]).astype(int)
        n_base, n_force = nv - n_act, int(force_offsets[-1])
        n_x = nv + n_force  # unknowns x = (qdd, f / force_scale)
        n = n_act + n_force  # unknowns y = (qdd_a, f / force_scale), base rows eliminated
        n_cone = int(cone_offsets[-1])
        self._force_slices = tuple(slice(a, b) for a, b in zip(force_offsets, force_offsets[1:]))
        # Cone rows of each contact's normal-force bounds (its last two: -f_n <= -f_min, f_n <=
        # f_max), which a transition changes.
        self._normal_rows = tuple((int(b) - 2, int(b) - 1) for b in cone_offsets[1:])
        self._nv, self._n_base, self._n_act, self._n = nv, n_base, n_act, n
        self.torque_limit = float(torque_limit_scale) * np.asarray(robot.torque_limit, float)
        if not (self.torque_limit > 0).all():  # NaN too
            raise InvalidInputError(
                f"robot.torque_limit must be > 0 for every actuated joint, got "
                f"{robot.torque_limit!r}; fix the robot model's effort limits"
            )
        self._release_limit = _RELEASE_MARGIN * self.torque_limit
        self._bound_tolerance = -tolerance  # margin of kernels.feasible: bounds within tolerance
        # Arguments of kernels.acceleration_bounds (no joints without limits).
        self._bounds = self._joint_limits(joint_limit_horizon, limited_joints)
        n_bound = self._bounds[1].size
        # The QP's wrench unknowns are wrenches divided by the robot's weight: dimensionless
        # forces as large as the accelerations, so that proxsuite's absolute tolerance pins
        # the internal forces between the soles (which only eps_f determines).
        scale = pin.computeTotalMass(self.model) * 9.81 if n_c else 1.0
        self._force_scale = scale

        # Linear rows [A | t] over x, each for A x = t (least squares or exact), in self._rows:
        # [tasks | base regularisation | contacts | base dynamics]
        # - task k: J_k qdd = b_k, least squares with weight w_k;
        # - base regularisation: qdd_b = 0, least squares with weight eps_a (used with y);
        # - contacts: J_c qdd = b_c;
        # - base dynamics: M_b qdd - J_cb^T f = -h_b (used for the elimination).
        # The tasks and contacts write their `jacobian` and `target` straight into these rows
        # (they are bound to views of them below).
        self._posture_tasks = tuple(t for t in self.tasks if isinstance(t, PostureTask))
        self._stacked_tasks = tuple(t for t in self.tasks if not isinstance(t, PostureTask))
        sizes = [task.target.size for task in self._stacked_tasks]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self._task_rows = tuple(slice(a, b) for a, b in zip(offsets[:-1], offsets[1:]))
        n_task = int(offsets[-1])
        n_cost = n_task + n_base
        self._n_task, self._n_cost = n_task, n_cost
        self._rows = np.zeros((n_cost + n_force + n_base, n_x + 1))
        self._rows[n_task:n_cost, :n_base] = np.eye(n_base)
        self._row_scale = np.ones((n_cost, 1))  # square roots of the least-squares weights
        for task, rows in zip(self._stacked_tasks, self._task_rows):
            self._row_scale[rows] = np.sqrt(task.weight)
        self._row_scale[n_task:] = np.sqrt(acceleration_regularization)
        self._contact_rows = tuple(
            slice(n_cost + a.start, n_cost + a.stop) for a in self._force_slices
        )
        self._bound = tuple(
            self._bind(item, rows)
            for item, rows in zip(
                self._stacked_tasks + self.contacts, self._task_rows + self._contact_rows
            )
        )
        self._dynamics_rows = slice(n_cost + n_force, n_cost + n_force + n_base)

        # Constant Hessian diagonal over x: eps_a on qdd plus the posture weights, eps_f on the
        # wrenches. The posture tasks' linear terms -w qdd* go to posture_gradient.
        diagonal = np.full(n_x, force_regularization * scale**2)
        diagonal[:nv] = acceleration_regularization
        for task in self._posture_tasks:
            diagonal[np.asarray(task.velocity_indices, dtype=int)] += task.weight
        self._bind_posture_tasks(n_x)
        # Fixed base, posture tasks on every joint plus frame tasks: the Hessian is diagonal
        # plus a low-rank term, solved through the Woodbury identity without the mass matrix,
        # and the torques come from RNEA (see _solve_joint_space).
        covered = diagonal[:nv] >= acceleration_regularization + min(
            (task.weight for task in self._posture_tasks), default=np.inf
        )
        self._joint_space = (
            not self.contacts
            and nv == robot.n_actuated
            and all(isinstance(task, FrameTask) for task in self._stacked_tasks)
            and (not self._stacked_tasks or bool(covered.all()))
        )
        self._inverse_diagonal = 1.0 / diagonal[:nv]
        self._zero_acceleration = np.zeros(nv)
        # Woodbury solve: W^-1 + J D^-1 J^T and J D^-1 over the frame-task rows.
        self._task_weights = self._row_scale[:n_task, 0] ** 2
        self._woodbury = (  # arguments of kernels.joint_space_accelerations
            self._rows, n_task, self._inverse_diagonal, self._task_weights,
            np.zeros((n_task, nv)), np.zeros((n_task, n_task)), np.zeros((n_task, n_task)),
            np.zeros(n_task),
        )  # fmt: skip

        # Cone rows over x (scaled wrenches): constant.
        cone_matrix = np.zeros((n_cone, n_x))
        cone_upper = np.full(n_cone, _NO_BOUND)
        for contact, forces, a, b in zip(
            self.contacts, self._force_slices, cone_offsets, cone_offsets[1:]
        ):
            cone_matrix[a:b, nv + forces.start : nv + forces.stop] = scale * contact.wrench_matrix
            cone_upper[a:b] = contact.wrench_upper
        self._cone_upper, self._n_limit = cone_upper, None  # n_limit set below
        cone_lower = np.full(n_cone, -_NO_BOUND)

        # ---- QPs over y = x[n_base:] (base rows eliminated): without torque rows (used when
        # the elimination below is unavailable) and with them.
        self._mapped = np.zeros((n_cost + n_force, n + 1))
        self._base_rhs = np.zeros((n_base, n + 1), order="F")  # [-M_ba, J_cb^T, h_b]
        self._base_map = np.zeros((n_base, n + 1))  # qdd_b = base_map @ (y, -1)
        self._hessian_diagonal = diagonal[n_base:].copy()
        self._hessian = np.zeros((n, n))
        self._hessian_diagonal_view = self._hessian.reshape(-1)[:: n + 1]
        self._gradient = np.zeros(n)
        self._eq_vector = self._mapped[n_cost:, n]
        # Inequality rows over y: torques, acceleration bounds (if any), cones.
        n_limit = n_act + n_bound
        self._n_limit = n_limit
        self._in_matrix = np.zeros((n_limit + n_cone, n))
        self._in_matrix[n_act + np.arange(n_bound), self._bounds[1] - n_base] = 1.0
        self._in_matrix[n_limit:] = cone_matrix[:, n_base:]
        self._in_lower = np.concatenate([np.full(n_limit, -_NO_BOUND), cone_lower])
        self._in_upper = np.concatenate([np.full(n_limit, _NO_BOUND), cone_upper])
        self._torque_rows = np.zeros((n_act, n + 1))
        equalities = (self._mapped[n_cost:, :n], self._eq_vector) if n_force else None
        cones = (
            (self._in_matrix[n_limit:], self._in_lower[n_limit:], self._in_upper[n_limit:])
            if n_cone
            else None
        )
        everything = (self._in_matrix, self._in_lower, self._in_upper)
        self._free = _Stage(
            n,
            n_force,
            n_cone,
            dense_backend,
            _arguments(self._hessian, self._gradient, equalities, cones),
            _arguments(self._hessian, self._gradient, equalities),
        )
        self._limited = _Stage(
            n,
            n_force,
            n_limit + n_cone,
            dense_backend,
            _arguments(self._hessian, self._gradient, equalities, everything),
            _arguments(self._hessian, self._gradient, equalities, everything),
        )

        # The relaxed QP over (y, s_c, s_b): slacks on the contact rows, A y - s_c = b, and on
        # the acceleration bounds, l <= qdd_j + s_b <= u, weighted in the cost; torque and
        # cone rows kept. Its Hessian, gradient and matrices are filled when it is used.
        n_relaxed = n + n_force + n_bound
        hessian = np.zeros((n_relaxed, n_relaxed))
        hessian.reshape(-1)[(n * (n_relaxed + 1)) :: n_relaxed + 1] = _RELAXATION_WEIGHT
        relaxed_equalities = None
        if n_force:
            relaxed_equalities = (np.zeros((n_force, n_relaxed)), self._eq_vector)
            relaxed_equalities[0][:, n : n + n_force] = -np.eye(n_force)
        relaxed_rows = np.zeros((n_limit + n_cone, n_relaxed))
        relaxed_rows[n_act + np.arange(n_bound), n + n_force + np.arange(n_bound)] = 1.0
        relaxed = _arguments(
            hessian, np.zeros(n_relaxed), relaxed_equalities,
            (relaxed_rows, self._in_lower, self._in_upper),
        )  # fmt: skip
        n_in = n_limit + n_cone
        self._relaxed = _Stage(n_relaxed, n_force, n_in, dense_backend, relaxed, relaxed)
        # Feasible by construction: an infeasibility report would be a false alarm.
        self._relaxed.qp.settings.eps_primal_inf = 1e-14

        # ---- QPs over z = x_N (nonbasic): the base and contact rows [G | t] solved for the
        # basic accelerations, x_B = U_c - U_N z with [U_N | U_c] = G_B^-1 [G_N | t]; without
        # inequality rows (primary) and with the cone rows.
        self._basic = self._eliminated_cones = None
        joints = _contact_joints(robot, self.contacts, n_base) if n_c else np.zeros(0, int)
        if joints is not None and n_base + joints.size:
            basic = np.concatenate([np.arange(n_base), joints])
            nonbasic = np.setdiff1d(np.arange(n_x), basic)
            n_z = nonbasic.size
            self._basic = basic
            self._nonbasic_constant = np.append(nonbasic, n_x)  # and the constant column
            self._basic_scale = -np.sqrt(diagonal[basic])  # rows -sqrt(d_B) U
            self._lu = np.zeros((basic.size, basic.size))
            self._elimination = np.zeros((basic.size, n_z + 1))
            self._z_matrix = np.zeros((n_task + basic.size, n_z))
            self._z_target = np.zeros(n_task + basic.size)
            self._z_hessian = np.zeros((n_z, n_z))
            self._z_hessian_diagonal = diagonal[nonbasic].copy()
            self._z_gradient = np.zeros(n_z)
            self._z_cone_matrix = np.ascontiguousarray(cone_matrix[:, nonbasic])
            self._z_cone_release = cone_upper - _CONE_RELEASE_MARGIN * scale
            self._z_cone_values = np.zeros(n_cone)
            self._z_accepted = np.zeros(n_z)  # the last accepted solution over z
            self._z_solution = np.zeros(n_z)
            self._z_factor = np.zeros((n_z, n_z))
            # Arguments of the compiled stages (persistent arrays, filled in place).
            self._elimination_arguments = (
                self._rows, n_cost, nv, n_base, self._mass, self._bias, scale, basic,
                self._nonbasic_constant, self._lu, self._elimination, _MIN_PIVOT_RATIO,
            )  # fmt: skip
            self._reduction_arguments = (
                self._rows, n_task, basic, self._nonbasic_constant, self._elimination,
                self._row_scale[:, 0].copy(), self._basic_scale, self._posture_gradient,
                self._z_hessian_diagonal, self._z_matrix, self._z_target, self._z_hessian,
                self._z_gradient,
            )  # fmt: skip
            self._solve_arguments = (
                self._z_factor, self._z_solution, self._z_cone_matrix, cone_upper,
                self.torque_limit, self._bounds, self._bound_tolerance,
            )  # fmt: skip
            z_cones = (self._z_cone_matrix, cone_lower, cone_upper)
            z_arguments = _arguments(self._z_hessian, self._z_gradient)
            if n_cone:
                self._eliminated_cones = _Stage(
                    n_z,
                    0,
                    n_cone,
                    dense_backend,
                    _arguments(self._z_hessian, self._z_gradient, None, z_cones),
                    z_arguments,
                )
        self._primary = self._limited
        self._y_factor = np.zeros((n, n))  # for the Cholesky factor of the Hessian over y
        self._y_solution = np.zeros(n)
        self._stages = tuple(
            s
            for s in (self._eliminated_cones, self._free, self._limited, self._relaxed)
            if s is not None
        )
        self.qp = self._primary.qp
        self.qp.settings.eps_abs = tolerance
        self.qp.settings.eps_rel = 0.0
        self.qp.settings.max_iter = int(max_iterations)
        self.qp.settings.eps_duality_gap_abs = tolerance
        self._level = 0  # inequality rows in use: 0 none, 1 cones, 2 cones and torques

        self.stats = ControllerStats()
        self._torques = np.zeros(n_act)
        self._tau = np.zeros(n_act)
        self._solution = np.zeros(n_x)
        self._candidate = np.zeros(n_x)
        self._has_valid_torque = False
        self._compile_kernels()

    def _compile_kernels(self) -> None:
        """Compile (or load from numba's disk cache) the kernels a tick can use, so that no
        tick of a control loop waits for a compilation: one tick on the reference
        configuration with a read-only and a writable state, and the stages used around
        proxsuite; then the controller is as new (contact references kept)."""
        references = [contact.reference_placement for contact in self.contacts]
        v = np.zeros(self._nv)
        v.flags.writeable = False
        q = np.array(self.robot.reference_configuration, dtype=float)
        q.flags.writeable = False
        for state in ((q, v), (q.copy(), v.copy())):
            self._level = 0  # the path of a tick without active inequality rows
            self.compute_torques(*state)
            self._feasible(self.torque_limit, self._bound_tolerance, *state)
            kernels.acceleration_bounds(self._bounds, *state)
        if self._basic is not None:
            self._assemble_eliminated()
            self._accept(self._z_solution, eliminated=True)
        self._solve_direct()
        kernels.solve_in_place(np.eye(1), np.ones(1))  # of _active_set
        self.reset()
        for contact, reference in zip(self.contacts, references):
            contact.reference_placement = reference

    def _joint_limits(self, horizon: float | None, joints) -> tuple:
        """Arguments of kernels.acceleration_bounds (without q, v): for no joint if
        ``horizon`` is None."""
        robot, model = self.robot, self.model
        if horizon is None:
            if joints is not None:
                raise InvalidInputError(
                    "limited_joints is given without joint_limit_horizon; give both (e.g. "
                    "joint_limit_horizon=0.05) or neither"
                )
            joints = []
        elif not (isinstance(horizon, (int, float)) and math.isfinite(horizon) and horizon > 0):
            raise InvalidInputError(
                f"joint_limit_horizon must be finite and > 0 [s], got {horizon!r}; "
                "None disables the joint limits"
            )
        elif joints is None:  # every actuated joint with a finite position limit
            lower, upper = robot.position_lower, robot.position_upper
            joints = [
                name
                for name in robot.actuated_joint_names
                if model.joints[model.getJointId(name)].nq == 1
                and np.isfinite(lower[model.joints[model.getJointId(name)].idx_q])
                and np.isfinite(upper[model.joints[model.getJointId(name)].idx_q])
            ]
        try:
            q_index = robot.configuration_indices(joints).astype(np.int64)
        except InvalidInputError as error:
            raise InvalidInputError(f"limited_joints: {error}") from None
        v_index = robot.velocity_indices(joints).astype(np.int64)
        names = robot.joint_groups[joints] if isinstance(joints, str) else joints
        for name in names:
            if model.joints[model.getJointId(name)].nq != 1:
                raise InvalidInputError(
                    f"limited_joints: {name!r} has no position limit (a continuous joint); "
                    "leave it out"
                )
        return (
            q_index, v_index,
            np.asarray(robot.position_lower, dtype=float)[q_index] - JOINT_LIMIT_TOLERANCE,
            np.asarray(robot.position_upper, dtype=float)[q_index] + JOINT_LIMIT_TOLERANCE,
            np.asarray(robot.velocity_limit, dtype=float)[v_index],
            1.0 if horizon is None else float(horizon),
            np.full(v_index.size, -np.inf), np.full(v_index.size, np.inf),
        )  # fmt: skip

    def _feasible(self, torque_limit: np.ndarray, margin: float, q, v) -> bool:
        """Whether the candidate's torques are within ``torque_limit`` and its accelerations
        ``margin`` inside their bounds (kernels.feasible)."""
        return kernels.feasible(
            self._tau, torque_limit, self._candidate, self._bounds, q, v, margin
        )

    # ------------------------------------------------------------------ results
    @property
    def joint_accelerations(self) -> np.ndarray:
        """Joint accelerations of the last solve, shape (nv,) (copy)."""
        return self._solution[: self._nv].copy()

    @property
    def contact_wrenches(self) -> np.ndarray:
        """Contact wrenches of the last solve, shape (n_contacts, 6) (copy).

        Rows are (fx, fy, fz, tx, ty, tz) [N, N m] in each sole frame, in contact order.
        """
        forces = self._solution[self._nv :]
        if not self.contacts:
            return np.zeros((0, 6))
        return np.array([forces[rows] for rows in self._force_slices])

    def set_normal_force_limit(self, index: int, limit: float) -> None:
        """Bound the normal force of contact ``index`` by ``limit`` [N] from the next tick
        (its lower bound becomes min(f_min, limit)); only the bound vectors change."""
        contact = self.contacts[index]
        lower = -min(contact.min_normal_force, limit)
        rows = self._normal_rows[index]
        if (self._cone_upper[list(rows)] == (lower, limit)).all():
            return
        margin = _CONE_RELEASE_MARGIN * self._force_scale
        for row, value in zip(rows, (lower, limit)):
            self._cone_upper[row] = value
            self._in_upper[self._n_limit + row] = value
            if self._basic is not None:
                self._z_cone_release[row] = value - margin
        for stage in self._stages:
            stage.stale = True

    @property
    def torques(self) -> np.ndarray:
        """Torques returned by the last tick, shape (n_actuated,) (copy)."""
        return self._torques.copy()

    def reset(self) -> None:
        """Forget the warm start, the contact reference placements and the counters."""
        for stage in self._stages:
            stage.initialized = stage.known = False
        self._level = 0
        self._has_valid_torque = False
        self.stats = ControllerStats()
        for contact in self.contacts:
            contact.reference_placement = None

    # ------------------------------------------------------------------ one tick
    def compute_torques(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Joint torques for the state ``(q, v)``: one model update, QP assembly and solve.

        Parameters
        ----------
        q : ndarray, shape (nq,)
            Configuration (free-flyer position and unit quaternion first, if floating).
        v : ndarray, shape (nv,)
            Velocity (base twist in the base frame first, if floating).

        Returns
        -------
        ndarray, shape (n_actuated,)
            Torques of the actuated joints [N m], within the torque limits, always finite.
        """
        if q.shape != (self.model.nq,) or v.shape != (self._nv,):
            raise ShapeError(
                f"q and v have shapes {q.shape} and {v.shape}, expected ({self.model.nq},) and "
                f"({self._nv},) for {self.robot.name}"
            )
        if not kernels.all_finite(q, v):
            raise InvalidInputError("q and v must be finite; the state holds NaN or inf")
        self.stats.n_ticks += 1
        start = time.thread_time()
        self._deadline = start + self.time_budget
        self._exact_deadline = start + _EXACT_SHARE * self.time_budget
        # Inequality rows are added only when the solution without them violates them; a
        # level is kept until its rows are slack by a margin (hysteresis). Without inequality
        # rows the QP is a least-squares problem, solved by one Cholesky factorisation.
        level, solved, mapped, checked = self._level, True, False, False
        # Posture tasks on a fixed base need no model terms below the torque limits.
        assembled = not (self._joint_space and level == 0)
        if not assembled:
            solved = self._solve_joint_space(q, v)
            if not solved:  # not expected: W^-1 + J D^-1 J^T is positive definite
                level = 2
        else:
            self._assemble(q, v)
        if assembled and level < 2:
            outcome = kernels.ILL_CONDITIONED
            if self._basic is not None:
                outcome = self._eliminated_tick(q, v) if level == 0 else self._assemble_eliminated()
            if outcome == kernels.SOLVED:
                checked = True  # cones, torques and acceleration bounds checked by the tick
            elif outcome == kernels.LIMITS_VIOLATED:
                level = 2
            elif outcome == kernels.CHOLESKY_FAILED:
                solved, level = False, 2
            elif outcome == kernels.CONES_VIOLATED:
                solved = self._solve(self._eliminated_cones, self._exact_deadline)
                level = 0 if solved and self._cones_released() else 1
            elif not self.contacts:  # fixed base: no equality rows
                self._assemble_y()
                mapped = True
                solved = self._solve_direct()
            else:  # ill-conditioned elimination: contact rows as equalities, with the cones
                self._assemble_y()
                mapped = True
                solved = self._solve(self._free, self._exact_deadline)
                level = min(level, 1)
        # A failed solve, or a NaN torque (from a NaN written into a task), goes to the QP
        # with every inequality row.
        if not solved or (level < 2 and not checked):
            if not (solved and self._feasible(self.torque_limit, self._bound_tolerance, q, v)):
                level = 2
        answer = "direct" if self.stats.last_status is _DIRECT else "solved"
        if level == 2:
            self.stats.n_torque_limited += 1
            if not assembled:
                self._assemble(q, v)
            if not mapped:
                self._assemble_y()
            kernels.acceleration_bounds(self._bounds, q, v)
            self._assemble_torque_rows()
            answer = "solved"
            solved = self._solve(self._limited, self._exact_deadline)
            if solved and self._feasible(self._release_limit, _BOUND_RELEASE_MARGIN, q, v):
                level = 1 if self.contacts else 0  # without contacts there are no cone rows
            elif not solved:
                answer = "relaxed"
                solved = self._time_left() and self._solve_relaxed()
        self._level = level
        if not solved:
            self._fall_back()
            return self._torques.copy()
        self._count(answer)
        self._has_valid_torque = True
        self._solution, self._candidate = self._candidate, self._solution
        if answer == "direct":  # its torques were checked against the limits
            np.copyto(self._torques, self._tau)
        else:  # proxsuite meets the limit rows only to its tolerance
            np.minimum(self._tau, self.torque_limit, out=self._torques)
            np.maximum(self._torques, -self.torque_limit, out=self._torques)
        return self._torques.copy()

    def _count(self, answer: str) -> None:
        stats = self.stats
        stats.last_answer = answer
        if answer == "direct":
            stats.n_direct += 1
        elif answer == "solved":
            stats.n_solved += 1
        else:
            stats.n_relaxed += 1

    def _time_left(self) -> bool:
        """Whether the tick's time budget allows another solve."""
        return time.thread_time() < self._deadline

    def _solve_joint_space(self, q: np.ndarray, v: np.ndarray) -> bool:
        r"""Fixed base, posture tasks on every joint plus frame tasks: the QP without torque
        rows, without the mass matrix.

        Its Hessian is :math:`H = D + J^\top W J` (D the diagonal posture and regularisation
        weights; J, t the frame-task rows, a few, with weights W), its gradient
        :math:`p - J^\top W t`, so by the Woodbury identity

        .. math:: \ddot q = H^{-1} r = D^{-1} r - D^{-1} J^\top (W^{-1} + J D^{-1} J^\top)^{-1}
                  J D^{-1} r, \qquad r = J^\top W t - p,

        with a factorisation of the small matrix only; posture tasks alone give
        :math:`\ddot q = -p/d`. Then :math:`\tau = \mathrm{RNEA}(q, \dot q, \ddot q)`.
        """
        model, data, x = self.model, self.data, self._candidate
        stats = self.stats
        stats.last_status, stats.last_iterations = _DIRECT, 0
        if self._stacked_tasks:
            pin.forwardKinematics(model, data, q, v, self._zero_acceleration)
            pin.computeJointJacobians(model, data)
            self._update_rows(q, v)
        if not kernels.joint_space_accelerations(self._posture_arguments, self._woodbury, q, v, x):
            return False
        self._tau[:] = pin.rnea(model, data, q, v, x)
        return True

    # ------------------------------------------------------------------ assembly
    def _bind(self, item, rows: slice) -> tuple:
        """Make a task's or contact's ``jacobian`` and ``target`` views of its rows."""
        jacobian, target = self._rows[rows, : self._nv], self._rows[rows, -1]
        jacobian[:] = item.jacobian
        target[:] = item.target
        item.jacobian, item.target = jacobian, target
        return item, jacobian, rows

    def _assemble(self, q: np.ndarray, v: np.ndarray) -> None:
        """Model terms, then the task and contact rows and the posture gradient over x."""
        model, data = self.model, self.data
        pin.computeAllTerms(model, data, q, v)
        self._update_rows(q, v)
        self._update_posture(q, v)

    def _update_rows(self, q: np.ndarray, v: np.ndarray) -> None:
        """Let the tasks and contacts write their rows (copied if they were rebound since,
        e.g. by another controller built on them)."""
        rows, data, nv = self._rows, self.data, self._nv
        for item, jacobian, block in self._bound:
            item.update(q, v, data)
            if item.jacobian is not jacobian:
                rows[block, :nv] = item.jacobian
                rows[block, -1] = item.target

    def _bind_posture_tasks(self, n_x: int) -> None:
        """Stack the posture tasks' state blocks into one, which the tasks then view.

        The PD laws of all posture tasks then run as one vectorised law, and their gradient
        terms -w qdd* are scattered over x by one product with a constant matrix.
        """
        tasks = self._posture_tasks
        sizes = [task._state.shape[1] for task in tasks]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self._posture_state = np.zeros((7, int(offsets[-1])))
        self._posture_views = []
        for task, start, stop in zip(tasks, offsets[:-1], offsets[1:]):
            columns = slice(int(start), int(stop))
            self._posture_state[:, columns] = task._state
            task._state = self._posture_state[:, columns]
            self._posture_views.append((task, task._state, columns))
        indices = [np.zeros(0, dtype=np.int64)]
        self._posture_gradient = np.zeros(n_x)
        self._posture_arguments = (  # of kernels.posture_gradient, without q and v
            self._posture_state,
            np.concatenate(indices + [t.configuration_indices for t in tasks]),
            np.concatenate(indices + [t.velocity_indices for t in tasks]),
            np.concatenate([[]] + [np.full(t._state.shape[1], t.weight) for t in tasks]),
            self._posture_gradient,
        )

    def _update_posture(self, q: np.ndarray, v: np.ndarray) -> None:
        """Posture targets (the PD law of :class:`PostureTask`, all tasks at once) and their
        gradient terms -w qdd* over x."""
        state = self._posture_state
        for task, view, columns in self._posture_views:
            if task._state is not view:  # rebound since (by another controller): take it back
                state[:, columns] = task._state
                task._state = view
        kernels.posture_gradient(*self._posture_arguments, q, v)

    def _eliminated_tick(self, q: np.ndarray, v: np.ndarray) -> int:
        """The tick without inequality rows over z, as one compiled call (an outcome of
        :func:`kernels.eliminated_tick`)."""
        stats = self.stats
        stats.last_status, stats.last_iterations = _DIRECT, 0
        return kernels.eliminated_tick(
            self._elimination_arguments, self._reduction_arguments, self._solve_arguments,
            q, v, self._candidate, self._tau,
        )  # fmt: skip

    def _assemble_eliminated(self) -> int:
        """Hessian and gradient over z for the QP with cone rows: CONES_VIOLATED (to be
        solved with them), or ILL_CONDITIONED if the basic block is."""
        if not kernels.eliminate(*self._elimination_arguments):
            return kernels.ILL_CONDITIONED
        kernels.reduce_costs(*self._reduction_arguments)
        return kernels.CONES_VIOLATED

    def _cones_released(self) -> bool:
        """Whether all cone rows are slack by the release margin."""
        values = np.dot(self._z_cone_matrix, self._z_accepted, out=self._z_cone_values)
        return bool((values < self._z_cone_release).all())

    def _assemble_y(self) -> None:
        """Base rows eliminated with M_bb: Hessian, gradient and contact equalities over y."""
        rows, n_base, n, n_cost = self._rows, self._n_base, self._n, self._n_cost
        mapped, used = self._mapped, rows[: self._dynamics_rows.start]
        if n_base:  # qdd_b = M_bb^-1 (J_cb^T f - M_ba qdd_a - h_b) = X_y y - X_c
            n_act, mass, rhs = self._n_act, self._mass, self._base_rhs
            np.negative(mass[:n_base, n_base:], out=rhs[:, :n_act])
            np.multiply(used[n_cost:, :n_base].T, self._force_scale, out=rhs[:, n_act:n])
            rhs[:, n] = self._bias[:n_base]
            _, solution, info = lapack.dposv(mass[:n_base, :n_base], rhs)
            if info != 0:  # M_bb not positive definite: only for a corrupted model
                solution = np.linalg.lstsq(mass[:n_base, :n_base], rhs, rcond=None)[0]
            self._base_map[:] = solution
            # [A_b | A_y | t] -> [A_y + A_b X_y | t + A_b X_c]
            np.dot(used[:, :n_base], self._base_map, out=mapped)
            mapped += used[:, n_base:]
            mapped[:n_cost] *= self._row_scale
        else:
            np.multiply(used[:n_cost], self._row_scale, out=mapped[:n_cost])
            if used.shape[0] > n_cost:
                mapped[n_cost:] = used[n_cost:]
        cost = mapped[:n_cost, :n]
        np.dot(cost.T, cost, out=self._hessian)
        self._hessian_diagonal_view += self._hessian_diagonal
        gradient = self._gradient
        np.dot(cost.T, mapped[:n_cost, n], out=gradient)
        if self._posture_tasks:  # g = p - A^T t
            np.subtract(self._posture_gradient[n_base:], gradient, out=gradient)
        else:
            np.negative(gradient, out=gradient)

    def _assemble_torque_rows(self) -> None:
        """tau = M_a qdd + h_a - J_ca^T f as rows over y, and the torque-limit bounds."""
        n_base, n_act, n = self._n_base, self._n_act, self._n
        mass, torque = self._mass, self._torque_rows
        if n_base:  # [M_ab X_y | M_ab X_c], qdd_b = X_y y - X_c
            np.dot(mass[n_base:, :n_base], self._base_map, out=torque)
        else:
            torque[:] = 0.0
        torque[:, :n_act] += mass[n_base:, n_base:]
        contact = self._rows[self._n_cost : self._dynamics_rows.start, n_base : self._nv]
        torque[:, n_act:n] -= self._force_scale * contact.T
        np.subtract(torque[:, n], self._bias[n_base:], out=torque[:, n])  # -(h_a - M_ab X_c)
        self._in_matrix[:n_act] = torque[:, :n]
        np.add(-self.torque_limit, torque[:, n], out=self._in_lower[:n_act])
        np.add(self.torque_limit, torque[:, n], out=self._in_upper[:n_act])
        lower, upper = self._bounds[6:]  # proxsuite takes |bound| >= 1e20 as none
        np.clip(lower, -_NO_BOUND, _NO_BOUND, self._in_lower[n_act:][: lower.size])
        np.clip(upper, -_NO_BOUND, _NO_BOUND, self._in_upper[n_act:][: upper.size])

    # ------------------------------------------------------------------ solve
    def _solve(self, stage: _Stage, deadline: float) -> bool:
        """Solve one stage: active-set iterations from its last active set, else proxsuite
        warm (cold on its first use), then once more cold if ``deadline`` (thread CPU time)
        allows.

        A non-finite Hessian or gradient (a NaN written into a task) fails without a solve:
        proxsuite can report such a problem solved.
        """
        hessian, gradient = stage.update_arguments[:2]
        stats = self.stats
        if not math.isfinite(hessian.sum() + gradient.sum()):
            stats.last_status, stats.last_iterations = "NON_FINITE_PROBLEM", 0
            stage.initialized = stage.known = False
            return False
        if stage.known:
            solution, solves = _active_set(
                stage.problem, stage.at_upper, stage.at_lower, self.qp.settings.eps_abs,
                _WARM_ROUNDS,
            )  # fmt: skip
            stats.last_status, stats.last_iterations = _ACTIVE_SET, solves
            if solution is not None and self._take(stage, solution):
                return True
        qp = stage.qp
        if qp is not self.qp:
            settings, source = qp.settings, self.qp.settings
            for name in _MIRRORED_SETTINGS:
                setattr(settings, name, getattr(source, name))
        if not stage.initialized:
            qp.init(*stage.init_arguments)
            solved = self._run(stage, True, deadline)
        else:
            qp.update(*(stage.init_arguments if stage.stale else stage.update_arguments))
            solved = self._run(stage, False, deadline)
            # proxsuite can also report a feasible QP infeasible from a stale warm start.
            if not solved and time.thread_time() < deadline:
                stats.n_cold_restarts += 1
                solved = self._run(stage, True, deadline)
        stage.initialized = stage.known = solved
        stage.stale = False
        return solved

    def _run(self, stage: _Stage, cold: bool, deadline: float) -> bool:
        """proxsuite on one stage until ``deadline``; its answer refined by active-set
        iterations from its active set.

        proxsuite runs in calls of ``_CHUNK_ITERATIONS`` outer iterations (of at most 10
        inner ones), each warm from the last, up to ``max_iter`` while time is left: a solve
        ends at most one call after ``deadline``, and the calls do not depend on the time.
        """
        qp = stage.qp
        settings = qp.settings
        limit, done, iterations = settings.max_iter, 0, 0
        chunk = min(limit, _CHUNK_ITERATIONS)
        settings.initial_guess = _COLD if cold else _WARM
        while True:
            settings.max_iter = chunk
            qp.solve()
            settings.initial_guess = _WARM  # any next call goes on from this result
            info = qp.results.info
            done, iterations = done + chunk, iterations + int(info.iter)
            if info.status != _MAX_ITER or done >= limit or time.thread_time() >= deadline:
                break
            chunk = min(_CHUNK_ITERATIONS, limit - done)
        settings.max_iter = limit
        stats = self.stats
        stats.last_status = info.status.name
        stats.last_iterations = iterations
        if info.status != _SOLVED:
            return False
        results = qp.results
        z = results.z
        noise = 1e-12 * max(1.0, float(np.abs(z).max(initial=0.0)))  # its zeros are ~1e-19
        np.greater(z, noise, out=stage.at_upper)
        np.less(z, -noise, out=stage.at_lower)
        solution, _ = _active_set(
            stage.problem, stage.at_upper, stage.at_lower, settings.eps_abs, _REFINEMENT_ROUNDS
        )
        if solution is None:  # no active set verified: proxsuite's answer, to its tolerance
            solution = results.x
            np.greater(z, noise, out=stage.at_upper)
            np.less(z, -noise, out=stage.at_lower)
        return self._take(stage, solution)

    def _take(self, stage: _Stage, solution: np.ndarray) -> bool:
        """Accept a stage's solution as the tick's candidate, if finite."""
        if not math.isfinite(solution.sum()):
            return False
        if stage is self._relaxed:  # (y, slacks)
            solution = solution[: self._n]
        if stage is self._eliminated_cones:
            self._z_accepted[:] = solution
        self._accept(solution, eliminated=stage is self._eliminated_cones)
        return True

    def _solve_relaxed(self) -> bool:
        """The QP with every inequality row, with slacks on its contact and acceleration-bound
        rows (assembled by the caller): always feasible (see the class notes)."""
        stage, n = self._relaxed, self._n
        hessian, gradient, equality, _, inequality = stage.problem[:5]
        hessian[:n, :n] = self._hessian
        gradient[:n] = self._gradient
        if equality is not None:
            equality[:, :n] = self._mapped[self._n_cost :, :n]
        inequality[:, :n] = self._in_matrix
        stage.initialized = False  # solved from scratch: its last problem is unrelated
        return self._solve(stage, self._deadline)

    def _solve_direct(self) -> bool:
        """The QP over y without inequality rows (fixed base): H y = -g by Cholesky."""
        solution = self._y_solution
        solved = kernels.cholesky_solve(self._hessian, self._y_factor, self._gradient, solution)
        stats = self.stats
        stats.last_status, stats.last_iterations = _DIRECT, 0
        if solved:
            self._accept(solution, eliminated=False)
        return solved

    def _accept(self, solution: np.ndarray, eliminated: bool) -> None:
        """Expand a QP solution (over z or y) into the candidate x and compute its torques."""
        x, n_base = self._candidate, self._n_base
        if eliminated:  # x_B = U_c - U_N z
            kernels.expand(self._elimination, self._basic, self._nonbasic_constant, solution, x)
        else:  # x = (qdd_b, y), qdd_b = X_y y - X_c
            x[n_base:] = solution
            if n_base:
                base_map, n = self._base_map, self._n
                np.dot(base_map[:, :n], solution, out=x[:n_base])
                x[:n_base] -= base_map[:, n]
        kernels.torques(
            self._mass, self._bias, self._rows, self._n_cost, n_base, self._force_scale, x,
            self._tau,
        )  # fmt: skip

    def _fall_back(self) -> None:
        """The hold answer: the last valid torque (h_a on the first tick), clipped."""
        self.stats.n_fallbacks += 1
        self.stats.last_answer = "hold"
        if self.raise_on_failure:
            raise NoSolutionFound(
                f"inverse-dynamics QP and its relaxation failed with status "
                f"{self.stats.last_status} after {self.stats.last_iterations} iterations; "
                "check that the tasks and contacts are compatible with the torque limits, or "
                "raise max_iterations or time_budget",
                stats=self.stats,
            )
        if not self._has_valid_torque:
            self._torques[:] = self.data.nle[self._n_base :]
        np.clip(self._torques, -self.torque_limit, self.torque_limit, out=self._torques)
        for stage in self._stages:
            stage.initialized = False
        self._level = 0
