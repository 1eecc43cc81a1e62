"""Assembly of the inverse-dynamics QP from the model terms, tasks and contacts.

Mixed into :class:`~dmpopt.control.inverse_dynamics.ContactSetQP`: the task and contact rows,
the posture gradient, the eliminations (base rows by :math:`M_{bb}`, or base and contact rows
by the basic block) and the torque rows, and the expansion of a QP solution into the joint
accelerations, wrenches and torques.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack

from . import kernels
from .qp_stages import _DIRECT, _NO_BOUND


class Assembly:
    """Rows, eliminations and expansion of the QP (see the module docstring)."""

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
        self._stack_posture()
        if not self._compiled.joint_space_accelerations(
            self._posture, self._layout, self._woodbury, q, v, x
        ):
            return False
        self._tau[:] = pin.rnea(model, data, q, v, x)
        return True

    def _assemble(self, q: np.ndarray, v: np.ndarray) -> None:
        """Model terms, then the task and contact rows and the posture gradient over x."""
        model, data = self.model, self.data
        pin.computeAllTerms(model, data, q, v)
        self._update_rows(q, v)
        self._update_posture(q, v)

    def _update_rows(self, q: np.ndarray, v: np.ndarray) -> None:
        """The tasks and contacts compute their rows; copy them into the QP's rows."""
        data = self.data
        for items, jacobians, targets in self._row_groups:
            for item in items:
                item.update(q, v, data)
            np.concatenate([item.jacobian for item in items], out=jacobians)
            np.concatenate([item.target for item in items], out=targets)

    def _stack_posture_tasks(self, n_x: int) -> None:
        """One block for the posture tasks' references, gains and targets, filled each tick
        from the tasks: their gradient terms -w qdd* are then scattered over x by one
        compiled call."""
        tasks = self._posture_tasks
        sizes = [task.velocity_indices.size for task in tasks]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self._posture_state = np.zeros((7, int(offsets[-1])))
        self._posture_blocks = [task.state for task in tasks]  # the tasks' own arrays

        indices = [np.zeros(0, dtype=np.int64)]
        self._posture_gradient = np.zeros(n_x)
        self._posture = kernels.PostureStack(
            self._posture_state,
            np.concatenate(indices + [t.configuration_indices for t in tasks]),
            np.concatenate(indices + [t.velocity_indices for t in tasks]),
            np.concatenate([[]] + [np.full(size, t.weight) for t, size in zip(tasks, sizes)]),
            self._posture_gradient,
        )

    def _update_posture(self, q: np.ndarray, v: np.ndarray) -> None:
        """Posture targets (the PD law of :class:`PostureTask`) and their gradient terms
        -w qdd* over x."""
        self._stack_posture()
        self._compiled.posture_gradient(self._posture, q, v)

    def _stack_posture(self) -> None:
        """Copy the posture tasks' references and gains into the stacked block (one call);
        their PD law is evaluated there, for all of them by one compiled call."""
        if self._posture_blocks:
            np.concatenate(self._posture_blocks, axis=1, out=self._posture_state)

    def _eliminated_tick(self, q: np.ndarray, v: np.ndarray) -> int:
        """The tick without inequality rows over z, as one compiled call (an outcome of
        :func:`kernels.eliminated_tick`)."""
        stats = self.stats
        stats.last_status, stats.last_iterations = _DIRECT, 0
        return self._compiled.eliminated_tick(
            self._layout, self._dynamics, self._split, self._reduced, self._checks, q, v,
            self._candidate, self._tau,
        )  # fmt: skip

    def _assemble_eliminated(self) -> int:
        """Hessian and gradient over z for the QP with cone rows: CONES_VIOLATED (to be
        solved with them), or ILL_CONDITIONED if the basic block is."""
        if not self._compiled.eliminate(self._layout, self._dynamics, self._split):
            return kernels.ILL_CONDITIONED
        self._compiled.reduce_costs(self._layout, self._split, self._reduced)
        return kernels.CONES_VIOLATED

    def _cones_released(self) -> bool:
        """Whether all cone rows are slack by the release margin."""
        values = np.dot(self._z_cone_matrix, self._z_accepted, out=self._z_cone_values)
        return bool((values < self._z_cone_release).all())

    def _assemble_y(self) -> None:
        """Base rows eliminated with M_bb: Hessian, gradient and contact equalities over y."""
        rows, n_base, n, n_cost = self._rows, self.layout.n_base, self.layout.n, self.layout.n_cost
        mapped, used = self._mapped, rows[: self.layout.dynamics_start]
        if n_base:  # qdd_b = M_bb^-1 (J_cb^T f - M_ba qdd_a - h_b) = X_y y - X_c
            n_act, mass, rhs = self.layout.n_act, self._mass, self._base_rhs
            np.negative(mass[:n_base, n_base:], out=rhs[:, :n_act])
            np.multiply(used[n_cost:, :n_base].T, self.layout.force_scale, out=rhs[:, n_act:n])
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
        n_base, n_act, n = self.layout.n_base, self.layout.n_act, self.layout.n
        mass, torque = self._mass, self._torque_rows
        if n_base:  # [M_ab X_y | M_ab X_c], qdd_b = X_y y - X_c
            np.dot(mass[n_base:, :n_base], self._base_map, out=torque)
        else:
            torque[:] = 0.0
        torque[:, :n_act] += mass[n_base:, n_base:]
        layout = self.layout
        contact = self._rows[layout.n_cost : layout.dynamics_start, n_base : layout.nv]
        torque[:, n_act:n] -= self.layout.force_scale * contact.T
        np.subtract(torque[:, n], self._bias[n_base:], out=torque[:, n])  # -(h_a - M_ab X_c)
        self._in_matrix[:n_act] = torque[:, :n]
        np.add(-self.torque_limit, torque[:, n], out=self._in_lower[:n_act])
        np.add(self.torque_limit, torque[:, n], out=self._in_upper[:n_act])
        lower, upper = self._bounds.lower, self._bounds.upper  # |bound| >= 1e20: none
        np.clip(lower, -_NO_BOUND, _NO_BOUND, self._in_lower[n_act:][: lower.size])
        np.clip(upper, -_NO_BOUND, _NO_BOUND, self._in_upper[n_act:][: upper.size])

    def _accept(self, solution: np.ndarray, eliminated: bool) -> None:
        """Expand a QP solution (over z or y) into the candidate x and compute its torques."""
        x, n_base = self._candidate, self.layout.n_base
        if eliminated:  # x_B = U_c - U_N z
            self._compiled.expand(self._split, solution, x)
        else:  # x = (qdd_b, y), qdd_b = X_y y - X_c
            x[n_base:] = solution
            if n_base:
                base_map, n = self._base_map, self.layout.n
                np.dot(base_map[:, :n], solution, out=x[:n_base])
                x[:n_base] -= base_map[:, n]
        self._compiled.torques(self._layout, self._dynamics, x, self._tau)
