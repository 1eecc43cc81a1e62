"""One tick of the inverse-dynamics QP: which QP is solved, and the degraded answers.

A part of :class:`~dmpopt.control.inverse_dynamics.ContactSetQP`: inequality rows are added
only when the least-squares optimum without them violates them (see the module docstring of
:mod:`dmpopt.control.inverse_dynamics`); a failed QP gives the relaxed answer, and a failed
relaxed QP or a spent time budget the hold answer.
"""

from __future__ import annotations

import gc
import math
import time

import numpy as np

from dmpopt.exceptions import InvalidInputError, NoSolutionFound, ShapeError

from . import kernels
from .qp_stages import _DIRECT, ControllerStats, _Stage

_RELEASE_MARGIN = 0.99  # leave the torque-limited QP once all |tau| < 0.99 tau_max
_BOUND_RELEASE_MARGIN = 1e-2  # ... and all joint accelerations 0.01 rad/s^2 inside their bounds
# Share of the time budget the exact QP may use; the rest is left to the relaxed QP.
_EXACT_SHARE = 0.5


class Tick:
    """The tick's control flow over the stages of one contact set's QP (see the module
    docstring), and its state: the inequality rows in use, the deadlines of the tick, the
    last valid torques.

    Parameters
    ----------
    robot : Robot
        The controller's robot; ``data`` its Pinocchio data (read for the hold answer).
    layout : QpLayout
    assembly : Assembly
        The arrays the tick fills and reads.
    stages : tuple
        ``(eliminated_cones, eliminated_limited, free, limited, relaxed)``: the QPs over z
        with the cone rows (None without an elimination or without cones) and with every
        inequality row (None without an elimination), the QPs over y with the cone rows and
        with every inequality row, and the relaxed QP.
    solver : StageSolver
    torque_limit : ndarray, shape (n_actuated,)
        [N m]
    tolerance : float
        Tolerance of the acceleration bounds.
    time_budget : float
        CPU seconds per tick.
    raise_on_failure : bool
        Raise :class:`NoSolutionFound` instead of the hold answer.

    Attributes
    ----------
    stats : ControllerStats
        Where the ticks are counted (the controller's, shared by its contact sets).
    time_budget, raise_on_failure
        As given (the controller sets them on every contact set).
    eliminated_cones, eliminated_limited, free, limited, relaxed : _Stage
    stages : tuple of _Stage
        The stages that exist.
    ramping : set of int
        The contacts whose normal force is bounded below its maximum (a transition): the
        QP with every inequality row is then solved over y only (see :meth:`_over_z`).
    solver : StageSolver
    """

    def __init__(
        self, robot, data, layout, assembly, stages, solver, torque_limit, tolerance,
        time_budget, raise_on_failure,
    ):  # fmt: skip
        self._nq, self._name, self._data = robot.model.nq, robot.name, data
        self._has_contacts = layout.n_force > 0
        self.layout, self.assembly, self.solver = layout, assembly, solver
        self.eliminated_cones, self.eliminated_limited = stages[:2]
        self.free, self.limited, self.relaxed = stages[2:]
        self.stages = tuple(s for s in stages if s is not None)
        self.torque_limit = torque_limit
        self._release_limit = _RELEASE_MARGIN * torque_limit
        self._bound_tolerance = -tolerance  # margin of kernels.feasible: bounds within tolerance
        self.time_budget = time_budget
        self.raise_on_failure = raise_on_failure
        self.stats = ControllerStats()
        self._deadline = self._exact_deadline = 0.0
        self._level = 0  # inequality rows in use: 0 none, 1 cones, 2 cones and torques
        self.ramping = set()
        self._torques = np.zeros(layout.n_act)
        self._has_valid_torque = False

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

        Notes
        -----
        Python's cyclic garbage collector is paused during the tick (and resumed after it,
        if it was on), so that no collection, which can take tens of milliseconds in a
        process with many objects, runs inside a tick; the tick itself creates no reference
        cycles. :func:`dmpopt.control.control_loop` keeps the collections between ticks
        short too.
        """
        if not gc.isenabled():
            return self._tick(q, v)
        gc.disable()
        try:
            return self._tick(q, v)
        finally:
            gc.enable()

    def _tick(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """:meth:`compute_torques` with the collector paused."""
        if q.shape != (self._nq,) or v.shape != (self.layout.nv,):
            raise ShapeError(
                f"q and v have shapes {q.shape} and {v.shape}, expected ({self._nq},) and "
                f"({self.layout.nv},) for {self._name}"
            )
        assembly = self.assembly
        q, v = assembly.set_state(q, v)  # the tick's own float64 copies
        if not assembly.state_finite():
            raise InvalidInputError("q and v must be finite; the state holds NaN or inf")
        self.stats.n_ticks += 1
        start = time.thread_time()
        self._deadline = start + self.time_budget
        self._exact_deadline = start + _EXACT_SHARE * self.time_budget
        # Inequality rows are added only when the solution without them violates them; a
        # level is kept until its rows are slack by a margin (hysteresis). Without inequality
        # rows the QP is a least-squares problem, solved by one Cholesky factorisation.
        level, solved, mapped, checked = self._level, True, False, False
        eliminated = False  # the elimination over z is filled (U, Hessian and gradient)
        # Posture tasks on a fixed base need no model terms below the torque limits.
        assembled = not (assembly.joint_space and level == 0)
        if not assembled:
            self._direct()
            solved = assembly.solve_joint_space(q, v)
            if not solved:  # not expected: W^-1 + J D^-1 J^T is positive definite
                level = 2
        else:
            assembly.assemble(q, v)
        if assembled and level < 2:
            outcome = kernels.ILL_CONDITIONED
            if assembly.eliminable and level == 0:
                self._direct()
                outcome = assembly.eliminated_tick(q, v)
            elif assembly.eliminable:
                outcome = assembly.assemble_eliminated()
            eliminated = outcome != kernels.ILL_CONDITIONED
            if outcome == kernels.SOLVED:
                checked = True  # cones, torques and acceleration bounds checked by the tick
            elif outcome == kernels.LIMITS_VIOLATED:
                level = 2
            elif outcome == kernels.CHOLESKY_FAILED:
                solved, level = False, 2
            elif outcome == kernels.CONES_VIOLATED:
                solved = self._solve(self.eliminated_cones, self._exact_deadline)
                level = 0 if solved and assembly.cones_released() else 1
            elif not self._has_contacts:  # fixed base: no equality rows
                assembly.assemble_y()
                mapped = True
                solved = self._solve_direct()
            else:  # ill-conditioned elimination: contact rows as equalities, with the cones
                assembly.assemble_y()
                mapped = True
                solved = self._solve(self.free, self._exact_deadline)
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
                assembly.assemble(q, v)
            answer, solved = "solved", False
            assembly.acceleration_bounds(q, v)
            # First over z (base and contact rows eliminated, no equality rows), else over y.
            if self._over_z() and (
                eliminated or assembly.assemble_eliminated() == kernels.CONES_VIOLATED
            ):
                assembly.assemble_eliminated_torque_rows()
                solved = self._solve(self.eliminated_limited, self._exact_deadline)
            if not solved:
                if not mapped:
                    assembly.assemble_y()
                assembly.assemble_torque_rows()
                solved = self._solve(self.limited, self._exact_deadline)
            if solved and self._feasible(self._release_limit, _BOUND_RELEASE_MARGIN, q, v):
                level = 1 if self._has_contacts else 0  # without contacts there are no cone rows
            elif not solved:
                answer = "relaxed"
                solved = self._time_left() and self._solve_relaxed()
        self._level = level
        if not solved:
            self._fall_back()
            return self._torques.copy()
        self._count(answer)
        self._has_valid_torque = True
        assembly.keep_candidate()
        if answer == "direct":  # its torques were checked against the limits
            np.copyto(self._torques, assembly.tau)
        else:  # the certificate meets the limit rows only to its tolerance
            np.minimum(assembly.tau, self.torque_limit, out=self._torques)
            np.maximum(self._torques, -self.torque_limit, out=self._torques)
        return self._torques.copy()

    def _over_z(self) -> bool:
        """Whether the QP with every inequality row is solved over z first: if it exists,
        outside a contact transition (cone rows nearly degenerate near a zero normal force),
        and once the QP over y holds a certified optimum (the first such QPs of a contact
        set are solved over y), so that a failed solve over z falls back to a warm one."""
        return self.eliminated_limited is not None and not self.ramping and self.limited.certified

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

    def _feasible(self, torque_limit: np.ndarray, margin: float, q, v) -> bool:
        """Whether the candidate's torques are within ``torque_limit`` and its accelerations
        ``margin`` inside their bounds (kernels.feasible)."""
        return self.assembly.feasible(torque_limit, margin, q, v)

    def _solve(self, stage: _Stage, deadline: float) -> bool:
        """Solve one stage by the QP's :class:`StageSolver`; its answer goes to :meth:`_take`."""
        return self.solver.solve(stage, deadline, self.stats, self._take)

    def _take(self, stage: _Stage, solution: np.ndarray) -> bool:
        """Accept a stage's solution as the tick's candidate, if finite."""
        if not math.isfinite(solution.sum()):
            return False
        if stage is self.relaxed:  # (y, slacks)
            solution = solution[: self.layout.n]
        if stage is self.eliminated_cones or stage is self.eliminated_limited:
            self.assembly.accept_eliminated(solution)
        else:
            self.assembly.accept(solution, eliminated=False)
        return True

    def _solve_relaxed(self) -> bool:
        """The QP with every inequality row, with slacks on its contact and acceleration-bound
        rows (assembled by the caller): always feasible (see the class notes)."""
        stage, n, assembly = self.relaxed, self.layout.n, self.assembly
        hessian, gradient, equality, _, inequality = stage.problem[:5]
        hessian[:n, :n] = assembly.hessian
        gradient[:n] = assembly.gradient
        if equality is not None:
            equality[:, :n] = assembly.mapped[self.layout.n_cost :, :n]
        inequality[:, :n] = assembly.in_matrix
        stage.initialized = False  # solved from scratch: its last problem is unrelated
        return self._solve(stage, self._deadline)

    def _solve_direct(self) -> bool:
        """The QP over y without inequality rows (fixed base): H y = -g by Cholesky."""
        self._direct()
        return self.assembly.solve_direct()

    def _direct(self) -> None:
        """Report a solve without proxsuite."""
        stats = self.stats
        stats.last_status, stats.last_iterations = _DIRECT, 0

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
            self._torques[:] = self._data.nle[self.layout.n_base :]
        np.clip(self._torques, -self.torque_limit, self.torque_limit, out=self._torques)
        for stage in self.stages:
            stage.initialized = False
        self._level = 0

    @property
    def torques(self) -> np.ndarray:
        """Torques returned by the last tick, shape (n_actuated,) (copy)."""
        return self._torques.copy()

    def continue_from(self, previous: Tick) -> None:
        """Take over from the tick of another contact set on a switch: its last valid torque
        (the hold answer) carries over; this tick starts from its path without inequality
        rows."""
        np.copyto(self._torques, previous._torques)
        self._has_valid_torque = previous._has_valid_torque
        self._level = 0

    def mark_stale(self) -> None:
        """Inequality bounds changed: every stage passes them to proxsuite on its next
        solve."""
        for stage in self.stages:
            stage.stale = True

    def reset(self) -> None:
        """Forget the warm starts, the last valid torque and the counters."""
        for stage in self.stages:
            stage.initialized = stage.known = False
        self._level = 0
        self._has_valid_torque = False
        self.stats = ControllerStats()
