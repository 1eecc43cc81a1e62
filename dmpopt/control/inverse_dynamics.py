r"""Weighted QP inverse dynamics on Pinocchio and proxsuite (the role TSID plays in C++).

Unknowns :math:`x = (\ddot q, f_1, \dots, f_{n_c})`: joint accelerations and, per active
contact, a 6-D wrench (a sole, in the sole frame) or a force (a point foot, in world axes; its
in-plane (x, z) components on a planar robot). This is the QP of one set of active contacts
and tasks (:class:`ContactSetQP`); the controller keeps one per set it meets. Each tick solves

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

- **Constraints eliminated.** The base rows and the contact rows are :math:`n_b + \sum_c m_c`
  linear equations (:math:`m_c` = 6 per sole, 3 or 2 per point foot); they are solved each
  tick (one LU factorisation) for as many *basic* accelerations: the base and, per contact,
  the joints that move that foot (chosen once by a column-pivoted QR of the contact
  Jacobians; for Talos the 12 leg joints). The QP variables
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
  the accelerations their bounds) the QP with cone, torque and bound rows, over z too
  (the torques are affine in z); over :math:`(\ddot q_a, f)` with the base rows eliminated
  and the contact rows as equalities during a contact transition, for a contact set's first
  such QPs, and when the solve over z fails. A QP with more rows is used first on the
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
optimum of its active set (:func:`_active_set`). Each QP is tried first by active-set
iterations from its previous tick's active set (in a closed loop that set is usually still
optimal, and the tick costs one KKT solve), then by DAQP from scratch (a dual active-set
solver in plain C: the same bits in every process, where proxsuite's verdict on a nearly
infeasible QP differed between processes), and proxsuite only where DAQP fails numerically.
Either way the answer carries the KKT certificate of :func:`_active_set`: a QP whose active
set does not verify counts as failed, and a solver's own answer is never returned. A tick
that cannot be solved gives a defined degraded answer within its time budget (see
:class:`InverseDynamicsController`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import proxsuite

from dmpopt.exceptions import InvalidInputError, ShapeError

from . import kernels
from .assembly import Assembly
from .contacts import Contact
from .layout import build_layout
from .qp_stages import ControllerStats, StageSolver, _active_set, _arguments, _Stage
from .tasks import PostureTask, Task
from .tick import Tick

__all__ = ["JOINT_LIMIT_TOLERANCE", "ContactSetQP", "ControllerStats", "SolverSettings"]

# [rad] how far past a position limit the acceleration bounds let a joint go: a joint resting
# exactly at its limit then leaves its bound slack.
JOINT_LIMIT_TOLERANCE = 1e-3
# Weight of the slacks of the relaxed QP (contact and acceleration-bound rows), per row.
_RELAXATION_WEIGHT = 1e4


def _check_positive(name: str, value) -> None:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if isinstance(value, bool) or not (math.isfinite(number) and number > 0):
        raise InvalidInputError(f"{name} must be a finite number > 0, got {value!r}")


def _check_items(robot, tasks, contacts) -> None:
    """Tasks and contacts of the right types, built for this robot."""
    if isinstance(tasks, Task) or isinstance(contacts, Contact):
        raise InvalidInputError(
            "tasks and contacts must be sequences; wrap a single one in a list: [task]"
        )
    if not tasks:
        raise InvalidInputError("tasks is empty; give at least one task (e.g. PostureTask)")
    for name, items, kind in (("tasks", tasks, Task), ("contacts", contacts, Contact)):
        for item in items:
            if not isinstance(item, kind):
                expected = "Task" if kind is Task else "Contact (SoleContact, PointContact, ...)"
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


@dataclass(frozen=True, eq=False)
class AssembledQp:
    r"""The QP of one tick with every inequality row, for inspection.

    .. math:: \min_y \tfrac12 y^\top H y + g^\top y + c \quad\text{s.t.}\quad A y = b,
              \quad l \le C y \le u

    over :math:`y = (\ddot q_a, f / (m g))`: the actuated joint accelerations [rad/s^2 or
    m/s^2] and the contact wrenches divided by the robot's weight ``force_scale`` (1 without
    contacts), the base rows eliminated (see :mod:`dmpopt.control.inverse_dynamics`). The
    constant :math:`c` makes the objective the full least-squares cost of the tasks and
    regularisation. The controller's answer is its optimum (to the solver tolerance when a
    tick's answer is ``solved`` without a certificate). Bounds of magnitude 1e20 mean none.

    Attributes
    ----------
    hessian : ndarray, shape (n, n)
    gradient : ndarray, shape (n,)
    equality_matrix, equality_vector : ndarray, shapes (m, n) and (m,)
        The contact rows :math:`J_c \ddot q = a^* - \dot J_c \dot q`.
    inequality_matrix : ndarray, shape (p, n)
        Torque rows, joint-limit acceleration-bound rows, then cone rows.
    lower, upper : ndarray, shape (p,)
    constant : float
    force_scale : float
        The robot's weight [N] (1.0 without contacts).
    variable_names, equality_names, inequality_names : tuple of str
        One name per variable, equality row and inequality row.
    """

    hessian: np.ndarray
    gradient: np.ndarray
    equality_matrix: np.ndarray
    equality_vector: np.ndarray
    inequality_matrix: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    constant: float
    force_scale: float
    variable_names: tuple[str, ...]
    equality_names: tuple[str, ...]
    inequality_names: tuple[str, ...]

    def objective(self, y: np.ndarray) -> float:
        """The cost :math:`\tfrac12 y^\top H y + g^\top y + c` of a point ``y``."""
        y = np.asarray(y, dtype=float)
        return float(0.5 * y @ self.hessian @ y + self.gradient @ y + self.constant)


DEFAULT_TIME_BUDGET = 5e-3
"""CPU seconds per tick the controller may spend by default (see ``time_budget``)."""


@dataclass(frozen=True)
class SolverSettings:
    """The settings of a controller's QPs, the same for every contact set: each field is the
    :class:`~dmpopt.control.InverseDynamicsController` parameter of that name (documented
    there), checked here once (``joint_limit_horizon`` and ``limited_joints`` by the QP,
    which knows the robot)."""

    acceleration_regularization: float = 1e-6
    force_regularization: float = 1e-8
    tolerance: float = 1e-6
    max_iterations: int = 50
    time_budget: float = DEFAULT_TIME_BUDGET
    raise_on_failure: bool = False
    joint_limit_horizon: float | None = 0.05
    limited_joints: str | Sequence[str] | None = None
    torque_limit_scale: float = 1.0
    dense_backend: proxsuite.proxqp.dense.DenseBackend = (
        proxsuite.proxqp.dense.DenseBackend.PrimalDualLDLT
    )

    def __post_init__(self):
        for name in (
            "acceleration_regularization", "force_regularization", "tolerance", "time_budget",
            "torque_limit_scale",
        ):  # fmt: skip
            _check_positive(name, getattr(self, name))
        max_iterations = self.max_iterations
        if isinstance(max_iterations, bool) or not (
            isinstance(max_iterations, (int, np.integer)) and max_iterations >= 1
        ):
            raise InvalidInputError(
                f"max_iterations must be an integer >= 1, got {max_iterations!r}"
            )


class ContactSetQP:
    """The QP of :class:`~dmpopt.control.InverseDynamicsController` for one set of active
    contacts and tasks: its rows, eliminated basic joints, sized proxsuite QPs and compiled
    stages (see the module docstring). The controller builds one per set it meets and keeps
    them; its ``settings`` (:class:`SolverSettings`) are the controller's, and
    ``settings_source`` is the proxsuite QP whose settings every stage takes (the
    controller's ``qp``).

    Its parts, each with its own state: ``layout`` (:class:`~dmpopt.control.layout.QpLayout`:
    sizes, blocks, row names), ``assembly`` (:class:`~dmpopt.control.assembly.Assembly`: the
    arrays the tick fills and the compiled kernels bound to them) and ``tick``
    (:class:`~dmpopt.control.tick.Tick`: the tick's flow over the stages, each a
    :class:`~dmpopt.control.qp_stages._Stage` solved by a
    :class:`~dmpopt.control.qp_stages.StageSolver`, and the tick's state).
    """

    def __init__(
        self,
        robot,
        tasks: Sequence[Task],
        contacts: Sequence[Contact] = (),
        *,
        settings: SolverSettings | None = None,
        settings_source: proxsuite.proxqp.dense.QP | None = None,
    ):
        _check_items(robot, tasks, contacts)
        settings = SolverSettings() if settings is None else settings
        if not isinstance(settings, SolverSettings):
            raise InvalidInputError(
                f"settings must be a SolverSettings, got {type(settings).__name__}"
            )
        self.settings = settings
        tolerance, dense_backend = settings.tolerance, settings.dense_backend
        self.robot = robot
        self.model = robot.model
        self.data = robot.create_data()
        self.tasks = tuple(tasks)
        self.contacts = tuple(contacts)

        self.torque_limit = float(settings.torque_limit_scale) * np.asarray(
            robot.torque_limit, float
        )
        if not (self.torque_limit > 0).all():  # NaN too
            raise InvalidInputError(
                f"robot.torque_limit must be > 0 for every actuated joint, got "
                f"{robot.torque_limit!r}; fix the robot model's effort limits"
            )
        # Arguments of kernels.acceleration_bounds (no joints without limits).
        bounds = self._joint_limits(settings.joint_limit_horizon, settings.limited_joints)
        posture_tasks = tuple(t for t in self.tasks if isinstance(t, PostureTask))
        stacked_tasks = tuple(t for t in self.tasks if not isinstance(t, PostureTask))
        # The QP's wrench unknowns are wrenches divided by the robot's weight (force_scale):
        # dimensionless forces as large as the accelerations, so that proxsuite's absolute
        # tolerance pins the internal forces between the soles (which only eps_f determines).
        self.layout = layout = build_layout(robot, stacked_tasks, self.contacts, bounds.v_index)
        self.assembly = assembly = Assembly(
            robot, self.data, layout, stacked_tasks, posture_tasks, self.contacts,
            bounds, self.torque_limit, settings.acceleration_regularization,
            settings.force_regularization,
            -tolerance,  # margin of kernels.feasible: bounds within tolerance
        )  # fmt: skip
        n_act, n_force, n, n_cone = layout.n_act, layout.n_force, layout.n, layout.n_cone
        n_bound, n_limit = layout.n_bound, layout.n_limit

        # ---- QPs over y = x[n_base:] (base rows eliminated): without torque rows (used when
        # the elimination is unavailable) and with them.
        hessian, gradient = assembly.hessian, assembly.gradient
        in_matrix, in_lower, in_upper = assembly.in_matrix, assembly.in_lower, assembly.in_upper
        eq_vector = assembly.mapped[layout.n_cost :, n]
        equalities = (assembly.mapped[layout.n_cost :, :n], eq_vector) if n_force else None
        cones = (in_matrix[n_limit:], in_lower[n_limit:], in_upper[n_limit:]) if n_cone else None
        everything = (in_matrix, in_lower, in_upper)
        free = _Stage(
            n,
            n_force,
            n_cone,
            dense_backend,
            _arguments(hessian, gradient, equalities, cones),
            _arguments(hessian, gradient, equalities),
        )
        limited = _Stage(
            n,
            n_force,
            n_limit + n_cone,
            dense_backend,
            _arguments(hessian, gradient, equalities, everything),
            _arguments(hessian, gradient, equalities, everything),
        )

        # The relaxed QP over (y, s_c, s_b): slacks on the contact rows, A y - s_c = b, and on
        # the acceleration bounds, l <= qdd_j + s_b <= u, weighted in the cost; torque and
        # cone rows kept. Its Hessian, gradient and matrices are filled when it is used.
        n_relaxed = n + n_force + n_bound
        hessian = np.zeros((n_relaxed, n_relaxed))
        hessian.reshape(-1)[(n * (n_relaxed + 1)) :: n_relaxed + 1] = _RELAXATION_WEIGHT
        relaxed_equalities = None
        if n_force:
            relaxed_equalities = (np.zeros((n_force, n_relaxed)), eq_vector)
            relaxed_equalities[0][:, n : n + n_force] = -np.eye(n_force)
        relaxed_rows = np.zeros((n_limit + n_cone, n_relaxed))
        relaxed_rows[n_act + np.arange(n_bound), n + n_force + np.arange(n_bound)] = 1.0
        arguments = _arguments(
            hessian, np.zeros(n_relaxed), relaxed_equalities,
            (relaxed_rows, in_lower, in_upper),
        )  # fmt: skip
        n_in = n_limit + n_cone
        relaxed = _Stage(n_relaxed, n_force, n_in, dense_backend, arguments, arguments)
        # Feasible by construction: an infeasibility report would be a false alarm.
        relaxed.qp.settings.eps_primal_inf = 1e-14
        relaxed.feasible_by_construction = True

        # ---- The QP over z = x_N (nonbasic), base and contact rows eliminated, with the cone
        # rows (without them it is solved by the assembly's compiled tick).
        eliminated_cones = None
        if assembly.eliminable and n_cone:
            z_cones = (assembly.z_cone_matrix, assembly.cone_lower, assembly.cone_upper)
            eliminated_cones = _Stage(
                assembly.z_hessian.shape[0],
                0,
                n_cone,
                dense_backend,
                _arguments(assembly.z_hessian, assembly.z_gradient, None, z_cones),
                _arguments(assembly.z_hessian, assembly.z_gradient),
            )
        # ... and with every inequality row (torques, acceleration bounds, cones): the QP of
        # `limited` over z, smaller and without equality rows.
        eliminated_limited = None
        if assembly.eliminable:
            z_everything = (assembly.z_in_matrix, assembly.z_in_lower, assembly.z_in_upper)
            z_arguments = _arguments(assembly.z_hessian, assembly.z_gradient, None, z_everything)
            eliminated_limited = _Stage(
                assembly.z_hessian.shape[0], 0, n_limit + n_cone, dense_backend, z_arguments,
                z_arguments,
            )  # fmt: skip
        self.qp = limited.qp
        self.qp.settings.eps_abs = tolerance
        self.qp.settings.eps_rel = 0.0
        self.qp.settings.max_iter = int(settings.max_iterations)
        self.qp.settings.eps_duality_gap_abs = tolerance
        if settings_source is not None:  # another contact set's QP: one source for all sets
            self.qp = settings_source
        stages = (eliminated_cones, eliminated_limited, free, limited, relaxed)
        self.tick = Tick(
            robot, self.data, layout, assembly, stages,
            StageSolver(self.qp), self.torque_limit, tolerance, float(settings.time_budget),
            settings.raise_on_failure,
        )  # fmt: skip
        self._compile_kernels(-tolerance)

    def _compile_kernels(self, bound_tolerance: float) -> None:
        """Compile (or load from numba's disk cache) the kernels a tick can use, so that no
        tick of a control loop waits for a compilation: one tick on the reference
        configuration, and the stages used around proxsuite; then the controller is as new
        (contact references kept)."""
        references = [contact.reference_placement for contact in self.contacts]
        state = np.array(self.robot.reference_configuration, dtype=float), np.zeros(self.layout.nv)
        self.compute_torques(*state)  # copies the state: every kernel sees writable float64
        assembly = self.assembly
        assembly.feasible(self.torque_limit, bound_tolerance, *state)
        kernels.acceleration_bounds(assembly.bounds, *state)
        if assembly.eliminable:
            assembly.assemble_eliminated()
            assembly.assemble_eliminated_torque_rows()
            assembly.accept_eliminated(assembly.z_accepted)
        assembly.solve_direct()
        problem = (np.eye(1), np.ones(1), None, None, np.ones((1, 1)), -np.ones(1), np.ones(1))
        _active_set(problem, np.zeros(1, bool), np.zeros(1, bool), 1e-9, 1)
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
        return kernels.JointBounds(
            q_index, v_index,
            np.asarray(robot.position_lower, dtype=float)[q_index] - JOINT_LIMIT_TOLERANCE,
            np.asarray(robot.position_upper, dtype=float)[q_index] + JOINT_LIMIT_TOLERANCE,
            np.asarray(robot.velocity_limit, dtype=float)[v_index],
            1.0 if horizon is None else float(horizon),
            np.full(v_index.size, -np.inf), np.full(v_index.size, np.inf),
        )  # fmt: skip

    def compute_torques(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Joint torques for the state ``(q, v)``, shape (n_actuated,) [N m]: one tick
        (:meth:`Tick.compute_torques <dmpopt.control.tick.Tick.compute_torques>`)."""
        return self.tick.compute_torques(q, v)

    @property
    def torques(self) -> np.ndarray:
        """Torques returned by the last tick, shape (n_actuated,) (copy)."""
        return self.tick.torques

    @property
    def stats(self) -> ControllerStats:
        """Where the ticks are counted (the controller shares its own among its sets)."""
        return self.tick.stats

    @stats.setter
    def stats(self, value: ControllerStats) -> None:
        self.tick.stats = value

    @property
    def time_budget(self) -> float:
        """CPU seconds a tick may spend."""
        return self.tick.time_budget

    @time_budget.setter
    def time_budget(self, value: float) -> None:
        self.tick.time_budget = value

    @property
    def raise_on_failure(self) -> bool:
        """Whether a tick raises :class:`NoSolutionFound` instead of the hold answer."""
        return self.tick.raise_on_failure

    @raise_on_failure.setter
    def raise_on_failure(self, value: bool) -> None:
        self.tick.raise_on_failure = value

    @property
    def joint_accelerations(self) -> np.ndarray:
        """Joint accelerations of the last solve, shape (nv,) (copy)."""
        return self.assembly.solution[: self.layout.nv].copy()

    @property
    def contact_wrenches(self) -> np.ndarray:
        """Contact wrenches (or forces) of the last solve, shape (n_contacts, width) (copy).

        One row per contact in contact order: (fx, fy, fz, tx, ty, tz) [N, N m] in a sole
        frame, a point force in world axes, a surface force in surface axes. ``width`` is the
        largest contact's ``n_force``; a smaller contact's row is padded with zeros (a
        point force has no torque about its point).
        """
        forces = self.assembly.solution[self.layout.nv :]
        if not self.contacts:
            return np.zeros((0, 6))
        width = max(c.n_force for c in self.contacts)
        wrenches = np.zeros((len(self.contacts), width))
        for row, rows in zip(wrenches, self.layout.force_slices):
            row[: rows.stop - rows.start] = forces[rows]
        return wrenches

    def set_normal_force_limit(self, index: int, limit: float) -> None:
        """Bound the normal force of contact ``index`` by ``limit`` [N] from the next tick
        (its lower bound becomes min(f_min, limit)); only the bound vectors change."""
        contact = self.contacts[index]
        lower = -min(contact.min_normal_force, limit)
        if not self.assembly.set_normal_force_limit(self.layout.normal_rows[index], lower, limit):
            return
        if limit < contact.max_normal_force:
            self.tick.ramping.add(index)
        else:
            self.tick.ramping.discard(index)
        self.tick.mark_stale()

    def assembled_qp(self, q: np.ndarray, v: np.ndarray) -> AssembledQp:
        """The QP of a tick at ``(q, v)`` with every inequality row (copies; see
        :class:`AssembledQp`). Assembling it changes no answer of a later tick."""
        assembly = self.assembly
        q, v = assembly.set_state(q, v)
        assembly.assemble(q, v)
        assembly.assemble_y()
        kernels.acceleration_bounds(assembly.bounds, q, v)
        assembly.assemble_torque_rows()
        n, n_cost, mapped = self.layout.n, self.layout.n_cost, assembly.mapped
        state, weights = assembly.posture.state, assembly.posture.weights
        constant = 0.5 * mapped[:n_cost, n] @ mapped[:n_cost, n] + 0.5 * weights @ state[5] ** 2
        return AssembledQp(
            hessian=assembly.hessian.copy(),
            gradient=assembly.gradient.copy(),
            equality_matrix=mapped[n_cost:, :n].copy(),
            equality_vector=mapped[n_cost:, n].copy(),
            inequality_matrix=assembly.in_matrix.copy(),
            lower=assembly.in_lower.copy(),
            upper=assembly.in_upper.copy(),
            constant=float(constant),
            force_scale=float(self.layout.force_scale),
            variable_names=self.layout.variable_names,
            equality_names=self.layout.equality_names,
            inequality_names=self.layout.inequality_names,
        )

    def continue_from(self, previous: ContactSetQP) -> None:
        """Take over from the QP of another contact set on a switch: its last valid torque
        (the hold answer) carries over; this QP starts from its path without inequality
        rows."""
        self.tick.continue_from(previous.tick)

    def reset(self) -> None:
        """Forget the warm start, the contact reference placements and the counters."""
        self.tick.reset()
        for contact in self.contacts:
            contact.reference_placement = None
