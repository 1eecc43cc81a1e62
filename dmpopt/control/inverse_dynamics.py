r"""Weighted QP inverse dynamics on Pinocchio and proxsuite (the role TSID plays in C++).

Decision variables :math:`x = (\ddot q, f_1, \dots, f_{n_c})`: joint accelerations and one
6-D wrench per sole contact (in the sole frame). Each tick solves

.. math::

    \min_x \; \sum_k w_k \lVert J_k \ddot q - b_k \rVert^2
              + \epsilon_a \lVert \ddot q \rVert^2 + \epsilon_f \lVert f \rVert^2

    \text{s.t.}\quad
    M_b \ddot q + h_b = J_{c,b}^\top f                  \quad\text{(unactuated base rows)}

    \hphantom{\text{s.t.}\quad} J_c \ddot q = a_c^* - \dot J_c \dot q \quad\text{(rigid contacts)}

    \hphantom{\text{s.t.}\quad} -\tau_{\max} \le M_a \ddot q + h_a - J_{c,a}^\top f
                                \le \tau_{\max}           \quad\text{(torque limits)}

    \hphantom{\text{s.t.}\quad} C f \le u              \quad\text{(friction and CoP cones)}

where the rows of :math:`M, h, J_c` are split into base (b) and actuated (a) coordinates, the
task terms come from :mod:`dmpopt.control.tasks`, and the torque is read off the equations of
motion, :math:`\tau = M_a \ddot q + h_a - J_{c,a}^\top f` [DelPrete2016]_. The QP is sized
once and warm-started from the previous tick's primal and dual solution.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin
import proxsuite

from dmpopt.exceptions import InvalidInputError, NoSolutionFound, ShapeError

from .tasks import ComTask, PostureTask, SoleContact, Task

__all__ = ["ControllerStats", "InverseDynamicsController"]

_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
_WARM = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
_COLD = proxsuite.proxqp.InitialGuess.NO_INITIAL_GUESS
_NO_BOUND = 1e20  # proxsuite treats |bound| >= 1e20 as absent


@dataclass
class ControllerStats:
    """Counters of the controller's solver health since construction or :meth:`reset`.

    Attributes
    ----------
    n_ticks : int
        Calls to :meth:`InverseDynamicsController.compute_torques`.
    n_cold_restarts : int
        Ticks whose warm-started solve failed (status not solved, or non-finite values) and
        were solved again from scratch.
    n_fallbacks : int
        Ticks where the cold solve failed too and the fallback torque was returned.
    last_status : str
        proxsuite status of the last solve.
    last_iterations : int
        Iterations of the last solve.
    """

    n_ticks: int = 0
    n_cold_restarts: int = 0
    n_fallbacks: int = 0
    last_status: str = "not run"
    last_iterations: int = 0


class InverseDynamicsController:
    r"""Task-space inverse dynamics with rigid sole contacts, solved by proxsuite each tick.

    Parameters
    ----------
    robot : RobotModel
        The robot (see :mod:`robots`); floating or fixed base.
    tasks : sequence of Task
        Weighted tasks (:class:`~dmpopt.control.tasks.PostureTask`, ``FrameTask``,
        ``ComTask``). Keep a reference to update their targets between ticks.
    contacts : sequence of SoleContact
        Active rigid contacts; their wrenches become decision variables.
    acceleration_regularization : float
        :math:`\epsilon_a`, keeps the Hessian positive definite when tasks leave joints free.
    force_regularization : float
        :math:`\epsilon_f`, spreads the load between contacts. Forces are in newtons, hundreds
        of times larger than accelerations, so it is small: 1e-5 would already let Talos sag
        by 0.02 m/s^2 to save force.
    tolerance : float
        proxsuite absolute tolerance ``eps_abs`` on the KKT residuals.
    max_iterations : int
        proxsuite iteration limit per solve.
    raise_on_failure : bool
        If True, a tick whose warm and cold solves both fail raises :class:`NoSolutionFound`
        instead of returning the fallback torque.
    dense_backend : proxsuite.proxqp.dense.DenseBackend
        Factorisation used by proxsuite. ``PrimalDualLDLT`` (the KKT system) is the default:
        ``PrimalLDLT`` factorises :math:`H + C^\top C/\mu` and stalls at tight tolerances on
        ill-conditioned task Hessians.

    Notes
    -----
    A failed solve (status other than solved, or any non-finite value) is re-solved once
    without initial guess; if that fails too, the controller returns the last valid torque
    (gravity and Coriolis compensation :math:`h_a` on the first tick), clipped to the torque
    limits, and counts the event in :attr:`stats`. It never returns NaN.
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
        max_iterations: int = 1000,
        raise_on_failure: bool = False,
        dense_backend=proxsuite.proxqp.dense.DenseBackend.PrimalDualLDLT,
    ):
        if not tasks:
            raise InvalidInputError("tasks is empty; give at least one task (e.g. PostureTask)")
        for name, value in (
            ("acceleration_regularization", acceleration_regularization),
            ("force_regularization", force_regularization),
            ("tolerance", tolerance),
        ):
            if not (np.isfinite(value) and value > 0):
                raise InvalidInputError(f"{name} must be finite and > 0, got {value!r}")
        self.robot = robot
        self.model = robot.model
        self.data = robot.create_data()
        self.tasks = tuple(tasks)
        self.contacts = tuple(contacts)
        self.raise_on_failure = raise_on_failure
        self._needs_com = any(isinstance(task, ComTask) for task in self.tasks)

        nv, n_act, n_c = robot.nv, robot.n_actuated, len(self.contacts)
        n_base = nv - n_act
        n = nv + 6 * n_c
        n_eq = n_base + 6 * n_c
        n_in = n_act + SoleContact.n_wrench_rows * n_c
        self._nv, self._n_base = nv, n_base
        self.torque_limit = np.asarray(robot.torque_limit, dtype=float).copy()

        # Row-major arrays: proxsuite's update copies them fastest.
        self._hessian_base = np.zeros((n, n))
        self._hessian_base[:nv, :nv] += acceleration_regularization * np.eye(nv)
        self._hessian_base[nv:, nv:] += force_regularization * np.eye(n - nv)
        self._posture_tasks = tuple(t for t in self.tasks if isinstance(t, PostureTask))
        for task in self._posture_tasks:  # constant Hessian term w on the selected diagonal
            self._hessian_base[task.velocity_indices, task.velocity_indices] += task.weight
        self._stacked_tasks = tuple(t for t in self.tasks if not isinstance(t, PostureTask))
        sizes = [task.target.size for task in self._stacked_tasks]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self._task_rows = tuple(slice(a, b) for a, b in zip(offsets[:-1], offsets[1:]))
        self._task_sqrt_weight = np.repeat(
            [np.sqrt(t.weight) for t in self._stacked_tasks], sizes
        ).reshape(-1, 1)
        self._task_jacobian = np.zeros((offsets[-1], nv))  # rows sqrt(w_k) J_k
        self._task_target = np.zeros(offsets[-1])  # rows sqrt(w_k) b_k
        self._hessian = self._hessian_base.copy()
        self._gradient = np.zeros(n)
        self._eq_matrix = np.zeros((n_eq, n))
        self._eq_vector = np.zeros(n_eq)
        self._in_matrix = np.zeros((n_in, n))
        self._in_lower = np.full(n_in, -_NO_BOUND)
        self._in_upper = np.full(n_in, _NO_BOUND)
        self._contact_jacobian = np.zeros((6 * n_c, nv))
        for k, contact in enumerate(self.contacts):
            rows = slice(n_act + 12 * k, n_act + 12 * (k + 1))
            self._in_matrix[rows, nv + 6 * k : nv + 6 * (k + 1)] = contact.wrench_matrix
            self._in_upper[rows] = contact.wrench_upper

        dense = proxsuite.proxqp.dense
        self.qp = dense.QP(n, n_eq, n_in, False, dense.HessianType.Dense, dense_backend)
        self.qp.settings.eps_abs = tolerance
        self.qp.settings.eps_rel = 0.0
        self.qp.settings.max_iter = max_iterations
        self.qp.settings.verbose = False
        self.qp.settings.initial_guess = _WARM
        self._initialized = False

        self.stats = ControllerStats()
        self._torques = np.zeros(n_act)
        self._solution = np.zeros(n)
        self._has_valid_torque = False

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
        return self._solution[self._nv :].reshape(-1, 6).copy()

    @property
    def torques(self) -> np.ndarray:
        """Torques returned by the last tick, shape (n_actuated,) (copy)."""
        return self._torques.copy()

    def reset(self) -> None:
        """Forget the warm start, the contact reference placements and the counters."""
        self._initialized = False
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
        if not (np.isfinite(q).all() and np.isfinite(v).all()):
            raise InvalidInputError("q and v must be finite; the state holds NaN or inf")
        self.stats.n_ticks += 1
        self._assemble(q, v)
        solved = self._solve(cold=not self._initialized)
        if not solved and self._initialized:
            self.stats.n_cold_restarts += 1
            solved = self._solve(cold=True)
        if solved:
            self._initialized = True
            self._has_valid_torque = True
            self._read_torques()
        else:
            self._fall_back()
        return self._torques.copy()

    def _assemble(self, q: np.ndarray, v: np.ndarray) -> None:
        model, data, nv, n_base = self.model, self.data, self._nv, self._n_base
        pin.computeAllTerms(model, data, q, v)
        pin.updateFramePlacements(model, data)

        hessian, gradient = self._hessian, self._gradient
        np.copyto(hessian, self._hessian_base)
        gradient[:] = 0.0
        for task in self._posture_tasks:
            task.update(q, v, data)
            gradient[task.velocity_indices] -= task.weight * task.target
        if self._stacked_tasks:
            stacked_jacobian, stacked_target = self._task_jacobian, self._task_target
            for task, rows in zip(self._stacked_tasks, self._task_rows):
                task.update(q, v, data)
                stacked_jacobian[rows] = task.jacobian
                stacked_target[rows] = task.target
            stacked_jacobian *= self._task_sqrt_weight
            stacked_target *= self._task_sqrt_weight[:, 0]
            hessian[:nv, :nv] += stacked_jacobian.T @ stacked_jacobian
            gradient[:nv] -= stacked_jacobian.T @ stacked_target

        mass, bias = data.M, data.nle
        jacobian = self._contact_jacobian
        eq, eq_vector = self._eq_matrix, self._eq_vector
        for k, contact in enumerate(self.contacts):
            contact.update(q, v, data)
            rows = slice(n_base + 6 * k, n_base + 6 * (k + 1))
            jacobian[6 * k : 6 * (k + 1)] = contact.jacobian
            eq[rows, :nv] = contact.jacobian
            eq_vector[rows] = contact.target
        if n_base:
            eq[:n_base, :nv] = mass[:n_base]
            eq[:n_base, nv:] = -jacobian[:, :n_base].T
            eq_vector[:n_base] = -bias[:n_base]

        n_act = nv - n_base
        self._in_matrix[:n_act, :nv] = mass[n_base:]
        self._in_matrix[:n_act, nv:] = -jacobian[:, n_base:].T
        np.subtract(-self.torque_limit, bias[n_base:], out=self._in_lower[:n_act])
        np.subtract(self.torque_limit, bias[n_base:], out=self._in_upper[:n_act])

    def _solve(self, cold: bool) -> bool:
        qp = self.qp
        eq = (self._eq_matrix, self._eq_vector) if self._eq_vector.size else (None, None)
        arguments = (self._hessian, self._gradient, *eq, self._in_matrix)
        bounds = (self._in_lower, self._in_upper)
        if not self._initialized:
            qp.init(*arguments, *bounds)
        else:
            qp.update(*arguments, *bounds)
        if cold:
            qp.settings.initial_guess = _COLD
        qp.solve()
        qp.settings.initial_guess = _WARM
        info = qp.results.info
        self.stats.last_status = info.status.name
        self.stats.last_iterations = info.iter
        x = qp.results.x
        if info.status != _SOLVED or not np.isfinite(x).all():
            return False
        self._solution[:] = x
        return True

    def _read_torques(self) -> None:
        # The torque rows of the inequality matrix are [M_a, -J_c,a^T]: tau = C_a x + h_a.
        n_act = self._nv - self._n_base
        tau = self._in_matrix[:n_act] @ self._solution
        tau += self.data.nle[self._n_base :]
        np.clip(tau, -self.torque_limit, self.torque_limit, out=self._torques)

    def _fall_back(self) -> None:
        self.stats.n_fallbacks += 1
        if self.raise_on_failure:
            raise NoSolutionFound(
                f"inverse-dynamics QP failed twice (warm and cold) with status "
                f"{self.stats.last_status} after {self.stats.last_iterations} iterations; "
                "check that the tasks and contacts are compatible with the torque limits",
                stats=self.stats,
            )
        if not self._has_valid_torque:
            self._torques[:] = self.data.nle[self._n_base :]
        np.clip(self._torques, -self.torque_limit, self.torque_limit, out=self._torques)
        self._initialized = False
