"""Assembly of the inverse-dynamics QP from the model terms, tasks and contacts.

A part of :class:`~dmpopt.control.inverse_dynamics.ContactSetQP`: the preallocated arrays of
one contact set's QP and what fills them each tick: the task and contact rows, the posture
gradient, the eliminations (base rows by :math:`M_{bb}`, or base and contact rows by the basic
block) and the torque rows, and the expansion of a QP solution into the joint accelerations,
wrenches and torques.
"""

from __future__ import annotations

import types

import numpy as np
import pinocchio as pin
import scipy.linalg

from . import kernels
from .contacts import SoleContact
from .qp_stages import _NO_BOUND
from .tasks import ComTask, FrameTask, joint_views

# Leave the QP with cone rows once all are slack by this fraction of the robot's weight [N].
CONE_RELEASE_MARGIN = 1e-3
# Smallest |pivot| ratio of the LU factorisation of the basic block for the elimination.
_MIN_PIVOT_RATIO = 1e-9
_UNHELD = object()  # a sole's reference placement not yet read by the compiled rows


def _compiled_kind(item) -> str | None:
    """Which part of :func:`kernels.stacked_rows` computes an item's rows: "frame", "sole",
    "com", or None (its own :meth:`update`, e.g. a subclass that overrides it)."""
    for kind, cls in (("frame", FrameTask), ("sole", SoleContact), ("com", ComTask)):
        if isinstance(item, cls) and type(item).update is cls.update:
            return kind
    return None


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


class Assembly:
    """The arrays of one contact set's QP and their assembly each tick (see the module
    docstring).

    Parameters
    ----------
    robot : Robot
        The controller's robot; ``data`` its Pinocchio data, refilled each tick.
    layout : QpLayout
        Sizes and blocks of the QP.
    stacked_tasks, posture_tasks : tuple of Task
        The least-squares tasks with rows, and the posture tasks (a diagonal cost).
    contacts : tuple of Contact
    bounds : kernels.JointBounds
        Arguments of :func:`kernels.acceleration_bounds` (without q, v).
    torque_limit : ndarray, shape (n_actuated,)
        [N m]
    acceleration_regularization, force_regularization : float
        :math:`\\epsilon_a, \\epsilon_f`.
    bound_tolerance : float
        Margin of :func:`kernels.feasible` for the acceleration bounds.

    Attributes
    ----------
    q, v : ndarray
        The tick's own float64 copies of the state (:meth:`set_state`).
    candidate, solution : ndarray, shape (n_x,)
        The tick's candidate x and the last accepted one (:meth:`keep_candidate`).
    tau : ndarray, shape (n_actuated,)
        The candidate's torques [N m].
    hessian, gradient : ndarray
        Over y, with the base rows eliminated (:meth:`assemble_y`).
    mapped : ndarray, shape (n_cost + n_force, n + 1)
        Cost and contact rows [A | t] over y.
    in_matrix, in_lower, in_upper : ndarray
        Inequality rows over y: torques, acceleration bounds, cones.
    cone_upper : ndarray, shape (n_cone,)
        Upper bounds of the cone rows (over x).
    bounds : kernels.JointBounds
    joint_space : bool
        Whether a tick without torque rows needs no mass matrix (fixed base, posture tasks on
        every joint plus frame tasks: :meth:`solve_joint_space`).
    eliminable : bool
        Whether the base and contact rows are eliminated by a basic block (the arrays
        ``z_*`` over the nonbasic unknowns z exist).
    """

    def __init__(
        self, robot, data, layout, stacked_tasks, posture_tasks, contacts, bounds,
        torque_limit, acceleration_regularization, force_regularization, bound_tolerance,
    ):  # fmt: skip
        self.model, self.data, self.layout = robot.model, data, layout
        self.bounds, self.torque_limit = bounds, torque_limit
        self._stacked_tasks, self._posture_tasks = stacked_tasks, posture_tasks
        # Views of the mass matrix and bias forces, refilled in place by computeAllTerms.
        self._mass, self._bias = data.M, data.nle
        nv, n_base, n_act, n_force = layout.nv, layout.n_base, layout.n_act, layout.n_force
        n, n_x, n_cone, n_bound = layout.n, layout.n_x, layout.n_cone, layout.n_bound
        n_task, n_cost, scale = layout.n_task, layout.n_cost, layout.force_scale

        # Linear rows [A | t] over x, each for A x = t (least squares or exact), in self._rows:
        # [tasks | base regularisation | contacts | base dynamics]
        # - task k: J_k qdd = b_k, least squares with weight w_k;
        # - base regularisation: qdd_b = 0, least squares with weight eps_a (used with y);
        # - contacts: J_c qdd = b_c;
        # - base dynamics: M_b qdd - J_cb^T f = -h_b (used for the elimination).
        self._rows = np.zeros((n_cost + n_force + n_base, n_x + 1))
        self._rows[n_task:n_cost, :n_base] = np.eye(n_base)
        self._row_scale = np.ones((n_cost, 1))  # square roots of the least-squares weights
        for task, rows in zip(stacked_tasks, layout.task_rows):
            self._row_scale[rows] = np.sqrt(task.weight)
        self._row_scale[n_task:] = np.sqrt(acceleration_regularization)
        # Each tick the tasks and contacts compute their rows into their own arrays, which are
        # copied here (the controller never rebinds a user's object): the frame tasks, sole
        # contacts and a CoM task by one compiled call with the posture gradient, reading the
        # Pinocchio data through views (see _pack_items); any other item by its update.
        first_rows = [rows.start for rows in layout.task_rows]
        first_rows += [n_cost + forces.start for forces in layout.force_slices]
        self._pack_items(list(stacked_tasks) + list(contacts), first_rows)
        self._kernel_rows = kernels.Rows(self._rows, n_task, n_cost, nv, n_base)
        self._dynamics = kernels.Dynamics(self._mass, self._bias, float(scale))

        # Constant Hessian diagonal over x: eps_a on qdd plus the posture weights, eps_f on the
        # wrenches. The posture tasks' linear terms -w qdd* go to posture_gradient.
        diagonal = np.full(n_x, force_regularization * scale**2)
        diagonal[:nv] = acceleration_regularization
        for task in posture_tasks:
            diagonal[np.asarray(task.velocity_indices, dtype=int)] += task.weight
        self._stack_posture_tasks(n_x)
        # Fixed base, posture tasks on every joint plus frame tasks: the Hessian is diagonal
        # plus a low-rank term, solved through the Woodbury identity without the mass matrix,
        # and the torques come from RNEA (see solve_joint_space).
        covered = diagonal[:nv] >= acceleration_regularization + min(
            (task.weight for task in posture_tasks), default=np.inf
        )
        self.joint_space = (
            not contacts
            and nv == robot.n_actuated
            and all(isinstance(task, FrameTask) for task in stacked_tasks)
            and (not stacked_tasks or bool(covered.all()))
        )
        self._zero_acceleration = np.zeros(nv)
        # Woodbury solve: W^-1 + J D^-1 J^T and J D^-1 over the frame-task rows.
        self._woodbury = kernels.Woodbury(
            1.0 / diagonal[:nv], self._row_scale[:n_task, 0] ** 2, np.zeros((n_task, nv)),
            np.zeros((n_task, n_task)), np.zeros((n_task, n_task)), np.zeros(n_task),
        )  # fmt: skip

        # Cone rows over x (scaled wrenches): constant.
        cone_matrix = np.zeros((n_cone, n_x))
        cone_upper = np.full(n_cone, _NO_BOUND)
        for contact, forces, cones in zip(contacts, layout.force_slices, layout.cone_slices):
            cone_matrix[cones, nv + forces.start : nv + forces.stop] = scale * contact.wrench_matrix
            cone_upper[cones] = contact.wrench_upper
        self.cone_upper = cone_upper
        self.cone_lower = np.full(n_cone, -_NO_BOUND)

        # ---- Over y = x[n_base:] (base rows eliminated).
        self.mapped = np.zeros((n_cost + n_force, n + 1))
        self._base_rhs = np.zeros((n_base, n + 1), order="F")  # [-M_ba, J_cb^T, h_b]
        self._base_map = np.zeros((n_base, n + 1))  # qdd_b = base_map @ (y, -1)
        self._hessian_diagonal = diagonal[n_base:].copy()
        self.hessian = np.zeros((n, n))
        self._hessian_diagonal_view = self.hessian.reshape(-1)[:: n + 1]
        self.gradient = np.zeros(n)
        # Inequality rows over y: torques, acceleration bounds (if any), cones.
        n_limit = layout.n_limit
        self.in_matrix = np.zeros((n_limit + n_cone, n))
        self.in_matrix[n_act + np.arange(n_bound), bounds.v_index - n_base] = 1.0
        self.in_matrix[n_limit:] = cone_matrix[:, n_base:]
        self.in_lower = np.concatenate([np.full(n_limit, -_NO_BOUND), self.cone_lower])
        self.in_upper = np.concatenate([np.full(n_limit, _NO_BOUND), cone_upper])
        self._torque_rows = np.zeros((n_act, n + 1))
        self._y_factor = np.zeros((n, n))  # for the Cholesky factor of the Hessian over y
        self._y_solution = np.zeros(n)

        # ---- Over z = x_N (nonbasic): the base and contact rows [G | t] solved for the basic
        # accelerations, x_B = U_c - U_N z with [U_N | U_c] = G_B^-1 [G_N | t].
        joints = _contact_joints(robot, contacts, n_base) if contacts else np.zeros(0, int)
        self.eliminable = joints is not None and bool(n_base + joints.size)
        if self.eliminable:
            basic = np.concatenate([np.arange(n_base), joints])
            nonbasic = np.setdiff1d(np.arange(n_x), basic)
            n_z = nonbasic.size
            self.z_hessian = np.zeros((n_z, n_z))
            self.z_gradient = np.zeros(n_z)
            self.z_cone_matrix = np.ascontiguousarray(cone_matrix[:, nonbasic])
            self._z_cone_release = cone_upper - CONE_RELEASE_MARGIN * scale
            self._z_cone_values = np.zeros(n_cone)
            self.z_accepted = np.zeros(n_z)  # the last accepted solution over z
            # Inequality rows over z for the QP with every inequality row: torques,
            # acceleration bounds (eliminated_torque_rows), cones (constant).
            self.z_in_matrix = np.zeros((n_limit + n_cone, n_z))
            self.z_in_matrix[n_limit:] = self.z_cone_matrix
            self.z_in_lower = np.concatenate([np.full(n_limit, -_NO_BOUND), self.cone_lower])
            self.z_in_upper = np.concatenate([np.full(n_limit, _NO_BOUND), cone_upper])
            self._z_torque_rows = np.zeros((n_act, n_z + 1))
            # Arguments of the compiled stages (persistent arrays, filled in place).
            self._split = kernels.Split(
                basic, np.append(nonbasic, n_x), np.zeros((basic.size, basic.size)),
                np.zeros((basic.size, n_z + 1)), _MIN_PIVOT_RATIO,
            )  # fmt: skip
            self._reduced = kernels.ReducedCosts(
                self._row_scale[:, 0].copy(), -np.sqrt(diagonal[basic]), self._posture_gradient,
                diagonal[nonbasic].copy(), np.zeros((n_task + basic.size, n_z)),
                np.zeros(n_task + basic.size), self.z_hessian, self.z_gradient,
            )  # fmt: skip
            self._checks = kernels.Checks(
                np.zeros((n_z, n_z)), np.zeros(n_z), self.z_cone_matrix, cone_upper,
                torque_limit, bounds, bound_tolerance,
            )  # fmt: skip

        self.tau = np.zeros(n_act)
        self.q, self.v = np.zeros(self.model.nq), np.zeros(nv)
        self.solution = np.zeros(n_x)
        self.candidate = np.zeros(n_x)
        self._bind_kernels(bound_tolerance)

    def _bind_kernels(self, bound_tolerance: float) -> None:
        """The compiled kernels of a tick, bound to the types of these arrays
        (:func:`kernels.entry_point`: called without numba's type dispatch)."""
        q, v, x, tau = self.q, self.v, self.candidate, self.tau
        rows, dynamics, bounds = self._kernel_rows, self._dynamics, self.bounds
        layout = self.layout
        contact = self._rows[layout.n_cost : layout.dynamics_start, layout.n_base : layout.nv]
        self._torque_arguments = (
            dynamics, self._base_map[: layout.n_base], contact, self.torque_limit, bounds,
            self._torque_rows, self.in_matrix, self.in_lower, self.in_upper,
        )  # fmt: skip
        self._base_arguments = (
            dynamics, self._rows[layout.n_cost : layout.dynamics_start], self._base_rhs,
            np.zeros((layout.n_base, layout.n_base)), self._base_map,
        )  # fmt: skip
        bound = {
            "stacked_rows": (
                self._frame_items,
                self._com_item,
                self._posture_blocks,
                self.posture,
                self._rows,
                q,
                v,
            ),
            "acceleration_bounds": (bounds, q, v),
            "all_finite": (q, v),
            "feasible": (tau, self.torque_limit, x, bounds, q, v, bound_tolerance),
            "torques": (rows, dynamics, x, tau),
            "torque_rows": self._torque_arguments,
        }
        used = self._rows[: layout.dynamics_start]
        self._map_arguments = (used, layout.n_cost, self._row_scale, self._base_map, self.mapped)
        bound["map_rows"] = self._map_arguments
        cost = self.mapped[: layout.n_cost, : layout.n]  # views of assemble_y, made once
        self._cost_views = (cost, cost.T, self.mapped[: layout.n_cost, layout.n], self.gradient)
        self._posture_gradient_y = self._posture_gradient[layout.n_base :]
        self._base_map_views = (self._base_map[:, : layout.n], self._base_map[:, layout.n])
        if layout.n_base:
            bound["base_map"] = self._base_arguments
        if self.joint_space:
            bound["joint_space_accelerations"] = (self.posture, rows, self._woodbury, q, v, x)
        if self.eliminable:
            split, reduced, checks = self._split, self._reduced, self._checks
            bound["eliminated_tick"] = (rows, dynamics, split, reduced, checks, q, v, x, tau)
            bound["eliminate"] = (rows, dynamics, split)
            bound["reduce_costs"] = (rows, split, reduced)
            bound["expand"] = (split, self.z_accepted, x)
            self._z_torque_arguments = (
                rows, dynamics, split, self.torque_limit, bounds, self._z_torque_rows,
                self.z_in_matrix, self.z_in_lower, self.z_in_upper, self.cone_upper,
            )  # fmt: skip
            bound["eliminated_torque_rows"] = self._z_torque_arguments
        entry_points = {
            name: kernels.entry_point(getattr(kernels, name), *arguments)
            for name, arguments in bound.items()
        }
        self._compiled = types.SimpleNamespace(**entry_points)

    def set_state(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Copy the state into :attr:`q`, :attr:`v` and return them.

        The tick's own float64 copies: numba compiles a kernel once per argument type
        (read-only or writable, dtype), so a caller's read-only or integer state would
        otherwise compile a variant inside a control loop's tick.
        """
        np.copyto(self.q, q)
        np.copyto(self.v, v)
        return self.q, self.v

    def state_finite(self) -> bool:
        """Whether :attr:`q` and :attr:`v` hold no NaN or inf (:func:`kernels.all_finite`,
        bound to their types: no dispatch)."""
        return self._compiled.all_finite(self.q, self.v)

    def keep_candidate(self) -> None:
        """The candidate becomes the accepted :attr:`solution` (the arrays swap roles)."""
        self.solution, self.candidate = self.candidate, self.solution

    def set_normal_force_limit(self, rows: tuple, lower: float, upper: float) -> bool:
        """Bound the cone ``rows`` (a contact's normal-force rows) by ``(lower, upper)``;
        False if they were already."""
        if (self.cone_upper[list(rows)] == (lower, upper)).all():
            return False
        margin = CONE_RELEASE_MARGIN * self.layout.force_scale
        for row, value in zip(rows, (lower, upper)):
            self.cone_upper[row] = value
            self.in_upper[self.layout.n_limit + row] = value
            if self.eliminable:
                self._z_cone_release[row] = value - margin
        return True

    def solve_joint_space(self, q: np.ndarray, v: np.ndarray) -> bool:
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
        model, data, x = self.model, self.data, self.candidate
        if self._stacked_tasks:
            pin.forwardKinematics(model, data, q, v, self._zero_acceleration)
            pin.computeJointJacobians(model, data)
        self._update_rows(q, v)
        if not self._compiled.joint_space_accelerations(
            self.posture, self._kernel_rows, self._woodbury, q, v, x
        ):
            return False
        self.tau[:] = pin.rnea(model, data, q, v, x)
        return True

    def assemble(self, q: np.ndarray, v: np.ndarray) -> None:
        """Model terms, then the task and contact rows and the posture gradient over x."""
        pin.computeAllTerms(self.model, self.data, q, v)
        self._update_rows(q, v)

    def _pack_items(self, items: list, first_rows: list) -> None:
        """Sort the stacked tasks and contacts by who computes their rows each tick
        (:func:`_compiled_kind`): the frame tasks and sole contacts into a
        :class:`kernels.FrameItems`, the first CoM task into a :class:`kernels.ComItem` (their
        own arrays, views of the Pinocchio data of their frames' joints and their first rows
        in the QP's rows), the others with the views of the QP's rows their rows go to."""
        data, rows, nv = self.data, self._rows, self.layout.nv
        frames, self._com_item, self._others, self._soles = [], None, [], []
        for item, first in zip(items, first_rows):
            kind = _compiled_kind(item)
            if kind in ("frame", "sole"):
                if kind == "sole":
                    self._soles.append((len(frames), item))
                frames.append((item, first, kind == "sole"))
            elif kind == "com" and self._com_item is None:
                self._com_item = kernels.ComItem(
                    item._out, item.jacobian, item._gains, data.com[0], data.Jcom,
                    data.acom[0], first,
                )  # fmt: skip
            else:
                block = slice(first, first + item.target.size)
                self._others.append((item, rows[block, :nv], rows[block, -1]))
        self._frames = [item for item, _, _ in frames]
        self._frame_items = None
        if frames:
            views = [joint_views(data, item._joint) for item in self._frames]
            # a sole's reference placement is read at its first tick (_hold_references)
            references = [
                (np.eye(3, order="F"), np.zeros(3)) if sole else
                (item._reference[:, :3], item._reference[:, 3])
                for item, _, sole in frames
            ]  # fmt: skip
            self._frame_items = kernels.FrameItems(
                *(tuple(getattr(item, name) for item in self._frames)
                  for name in ("_out", "_jacobians", "_indices", "_gains")),
                *(tuple(pair[k] for pair in references) for k in range(2)),
                *(tuple(view[k] for view in views) for k in range(4)),
                np.array([item._placement for item in self._frames]),
                np.array([sole for _, _, sole in frames]),
                np.array([first for _, first, _ in frames], dtype=np.int64),
                data.J,
            )  # fmt: skip
        self._held = [_UNHELD] * len(self._soles)

    def _hold_references(self) -> None:
        """Point the compiled rows at each sole contact's reference placement (its placement
        now if it has none: :meth:`Contact.placement`); called whenever a contact's reference
        is another object than the one held (an in-place change is seen through the views)."""
        rotations = list(self._frame_items.reference_rotations)
        translations = list(self._frame_items.reference_translations)
        for index, contact in self._soles:
            if contact.reference_placement is None:
                contact.placement(self.data)
            reference = contact.reference_placement
            rotations[index], translations[index] = reference.rotation, reference.translation
        self._held = [contact.reference_placement for _, contact in self._soles]
        self._frame_items = self._frame_items._replace(
            reference_rotations=tuple(rotations), reference_translations=tuple(translations)
        )

    def _update_rows(self, q: np.ndarray, v: np.ndarray) -> None:
        """The tasks and contacts compute their rows (into their own arrays, in place: see
        :class:`~dmpopt.control.tasks.Task`), copied into the QP's rows, and the posture
        targets (the PD law of :class:`PostureTask`) their gradient terms -w qdd* over x:
        one compiled call (:func:`kernels.stacked_rows`), then the items it does not know."""
        for (_, contact), held in zip(self._soles, self._held):
            if contact.reference_placement is not held:
                self._hold_references()
                break
        data = self.data
        if self._com_item is not None:  # the CoM drift into data.acom[0]
            pin.centerOfMass(self.model, data, pin.ACCELERATION, False)
        if not self._compiled.stacked_rows(
            self._frame_items, self._com_item, self._posture_blocks, self.posture, self._rows,
            q, v,
        ):  # fmt: skip
            # a rotation error near a half turn: each frame item by its update
            for item, first in zip(self._frames, self._frame_items.destinations):
                item.update(q, v, data)
                m = item.target.size
                self._rows[first : first + m, : self.layout.nv] = item.jacobian
                self._rows[first : first + m, -1] = item.target
        for item, jacobian, target in self._others:
            item.update(q, v, data)
            np.copyto(jacobian, item.jacobian)
            np.copyto(target, item.target)

    def _stack_posture_tasks(self, n_x: int) -> None:
        """One block for the posture tasks' references, gains and targets, filled each tick
        from the tasks' own blocks: their gradient terms -w qdd* are then scattered over x by
        one compiled call."""
        tasks = self._posture_tasks
        sizes = [task.velocity_indices.size for task in tasks]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self._posture_state = np.zeros((7, int(offsets[-1])))
        self._posture_blocks = tuple(task.state for task in tasks) or None  # the tasks' own

        indices = [np.zeros(0, dtype=np.int64)]
        self._posture_gradient = np.zeros(n_x)
        self.posture = kernels.PostureStack(
            self._posture_state,
            np.concatenate(indices + [t.configuration_indices for t in tasks]),
            np.concatenate(indices + [t.velocity_indices for t in tasks]),
            np.concatenate([[]] + [np.full(size, t.weight) for t, size in zip(tasks, sizes)]),
            self._posture_gradient,
        )

    def eliminated_tick(self, q: np.ndarray, v: np.ndarray) -> int:
        """The tick without inequality rows over z, as one compiled call (an outcome of
        :func:`kernels.eliminated_tick`)."""
        return self._compiled.eliminated_tick(
            self._kernel_rows, self._dynamics, self._split, self._reduced, self._checks, q, v,
            self.candidate, self.tau,
        )  # fmt: skip

    def assemble_eliminated(self) -> int:
        """Hessian and gradient over z for the QP with cone rows: CONES_VIOLATED (to be
        solved with them), or ILL_CONDITIONED if the basic block is."""
        if not self._compiled.eliminate(self._kernel_rows, self._dynamics, self._split):
            return kernels.ILL_CONDITIONED
        self._compiled.reduce_costs(self._kernel_rows, self._split, self._reduced)
        return kernels.CONES_VIOLATED

    def cones_released(self) -> bool:
        """Whether all cone rows are slack by the release margin."""
        values = np.dot(self.z_cone_matrix, self.z_accepted, out=self._z_cone_values)
        return bool((values < self._z_cone_release).all())

    def assemble_y(self) -> None:
        """Base rows eliminated with M_bb: Hessian, gradient and contact equalities over y."""
        n_base = self.layout.n_base
        if n_base and not self._compiled.base_map(*self._base_arguments):
            # M_bb not positive definite: only for a corrupted model
            mass = self._mass[:n_base, :n_base]
            self._base_map[:] = np.linalg.lstsq(mass, self._base_rhs, rcond=None)[0]
        # [A_b | A_y | t] -> [A_y + A_b X_y | t + A_b X_c], qdd_b = X_y y - X_c
        self._compiled.map_rows(*self._map_arguments)
        cost, cost_t, target, gradient = self._cost_views
        np.dot(cost_t, cost, out=self.hessian)
        self._hessian_diagonal_view += self._hessian_diagonal
        np.dot(cost_t, target, out=gradient)
        if self._posture_tasks:  # g = p - A^T t
            np.subtract(self._posture_gradient_y, gradient, out=gradient)
        else:
            np.negative(gradient, out=gradient)

    def assemble_torque_rows(self) -> None:
        """tau = M_a qdd + h_a - J_ca^T f as rows over y, the torque-limit bounds and the
        acceleration bounds (one compiled call, :func:`kernels.torque_rows`)."""
        self._compiled.torque_rows(*self._torque_arguments)

    def assemble_eliminated_torque_rows(self) -> None:
        """The torque rows and acceleration bounds over z, after :meth:`assemble_eliminated`
        or :meth:`eliminated_tick` and :meth:`acceleration_bounds` (one compiled call,
        :func:`kernels.eliminated_torque_rows`)."""
        self._compiled.eliminated_torque_rows(*self._z_torque_arguments)

    def accept(self, solution: np.ndarray, eliminated: bool) -> None:
        """Expand a QP solution (over z or y) into the candidate x and compute its torques."""
        x, n_base = self.candidate, self.layout.n_base
        if eliminated:  # x_B = U_c - U_N z
            self._compiled.expand(self._split, solution, x)
        else:  # x = (qdd_b, y), qdd_b = X_y y - X_c
            x[n_base:] = solution
            if n_base:
                base_x, base_c = self._base_map_views
                base = x[:n_base]
                np.dot(base_x, solution, out=base)
                base -= base_c
        self._compiled.torques(self._kernel_rows, self._dynamics, x, self.tau)

    def accept_eliminated(self, solution: np.ndarray) -> None:
        """:meth:`accept` of a solution over z, kept in :attr:`z_accepted` (the array type
        the compiled expansion is bound to)."""
        self.z_accepted[:] = solution
        self.accept(self.z_accepted, eliminated=True)

    def solve_direct(self) -> bool:
        """The QP over y without inequality rows (fixed base): H y = -g by Cholesky."""
        solution = self._y_solution
        solved = kernels.cholesky_solve(self.hessian, self._y_factor, self.gradient, solution)
        if solved:
            self.accept(solution, eliminated=False)
        return solved

    def feasible(self, torque_limit: np.ndarray, margin: float, q, v) -> bool:
        """Whether the candidate's torques are within ``torque_limit`` and its accelerations
        ``margin`` inside their bounds (kernels.feasible)."""
        return self._compiled.feasible(
            self.tau, torque_limit, self.candidate, self.bounds, q, v, margin
        )

    def acceleration_bounds(self, q: np.ndarray, v: np.ndarray) -> None:
        """The joint-limit acceleration bounds at ``(q, v)`` into :attr:`bounds`."""
        self._compiled.acceleration_bounds(self.bounds, q, v)
