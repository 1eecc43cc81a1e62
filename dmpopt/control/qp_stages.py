"""The QP stages of the inverse-dynamics controller and their active-set certificate.

Each QP the controller may solve on a tick (with cone rows, with torque and bound rows, the
relaxed one; see :mod:`dmpopt.control.inverse_dynamics`) is a :class:`_Stage`: the arrays it
reads, its last active set and optimum, and a proxsuite QP sized once. A stage is solved first
by active-set iterations from its last active set (:func:`_active_set`, one KKT solve when that
set is still optimal), else by DAQP (a dual active-set solver, deterministic) from scratch, and
only if DAQP fails for another reason than infeasibility by proxsuite in short calls within a
time budget. The solvers' multipliers only seed active-set iterations: every answer is the
exact optimum of a verified active set, never a solver's own iterate."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import daqp
import numpy as np
import proxsuite

from . import kernels

_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
_MAX_ITER = proxsuite.proxqp.QPSolverOutput.PROXQP_MAX_ITER_REACHED
_WARM = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
_WARM_GIVEN = proxsuite.proxqp.InitialGuess.WARM_START
_COLD = proxsuite.proxqp.InitialGuess.NO_INITIAL_GUESS
# DAQP's exit flags (its documentation's list; 2, "soft optimal", needs soft rows: none here)
_DAQP_STATUS = {
    1: "DAQP_SOLVED", -1: "DAQP_INFEASIBLE", -2: "DAQP_CYCLING", -3: "DAQP_UNBOUNDED",
    -4: "DAQP_ITERATION_LIMIT", -5: "DAQP_NONCONVEX", -6: "DAQP_OVERDETERMINED_START",
}  # fmt: skip
_DAQP_SOLVED, _DAQP_INFEASIBLE = 1, -1
_DAQP_EQUALITY = 5  # DAQP's sense flag of an equality row
_DIRECT = "CHOLESKY_SOLVED"  # ControllerStats.last_status of a tick without inequality rows
_ACTIVE_SET = "ACTIVE_SET_SOLVED"  # ... of a QP solved by active-set iterations alone
_NO_BOUND = 1e20  # proxsuite treats |bound| >= 1e20 as absent
_MIRRORED_SETTINGS = (
    "eps_abs", "eps_rel", "eps_duality_gap_abs", "max_iter", "max_iter_in", "verbose",
)  # fmt: skip
# Inner iterations per outer iteration of proxsuite (its default 1500): with max_iter, the cap
# on one solve's iterations.
_MAX_INNER_ITERATIONS = 10
# Active-set refinement rounds after proxsuite (each one KKT solve).
_REFINEMENT_ROUNDS = 10
# Active-set rounds from the previous tick's active set before proxsuite is called.
_WARM_ROUNDS = 5
# A row enters the first active set after proxsuite if its multiplier exceeds this share of
# the largest (at least 1). Over the stress runs of bench_qp_stress.py, proxsuite's
# multipliers of the rows of the certified sets were at least 1e-8 of the largest and those of
# the other rows at most 5e-15: the threshold sits in that gap, 100x and 2e4x away, so
# proxsuite's ~1e-12 differences between processes cannot move a row across it.
_ACTIVE_MULTIPLIER = 1e-10
# proxsuite runs in calls of this many outer iterations, the time budget checked between
# (always the same calls, so that the time taken does not change the answer).
_CHUNK_ITERATIONS = 3


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
    n_proxsuite : int
        Solves that went on to proxsuite because DAQP failed for another reason than
        infeasibility (or on the relaxed QP, feasible by construction); their answers can
        differ between processes (see :class:`StageSolver`).
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
    n_proxsuite: int = 0
    last_answer: str = "not run"
    last_status: str = "not run"
    last_iterations: int = 0


class _Stage:
    """One QP with its proxsuite solver, its own warm start and the (preallocated) arrays it
    reads.

    ``problem`` is (H, g, A, b, C, l, u), None for absent blocks: what the active-set
    iterations read. ``at_upper`` and ``at_lower`` mark the rows active at the last solution
    (``known``): the next tick starts from them. ``stale``: inequality bounds changed (a
    contact transition), so the next proxsuite update passes them too. ``warm`` holds the
    last certified optimum and its multipliers (x, y, z) (``certified``), proxsuite's next
    warm start; ``workspace`` the :class:`ActiveSetWorkspace` of the active-set iterations on
    ``problem``, whose multipliers go to ``warm``; ``daqp_arguments`` DAQP's stacked rows,
    bounds and row kinds, filled from ``problem`` before a DAQP solve; ``status`` the status
    of its last DAQP or proxsuite solve. ``feasible_by_construction`` (the relaxed QP): an
    infeasibility report of DAQP is a numerical failure, and proxsuite gets its turn.
    """

    __slots__ = (
        "qp", "initialized", "init_arguments", "update_arguments", "problem", "at_upper",
        "at_lower", "known", "stale", "warm", "certified", "workspace", "daqp_arguments",
        "status", "feasible_by_construction",
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
        self.warm = (np.zeros(n), np.zeros(n_eq), np.zeros(n_in))
        self.certified = False
        self.status = "not run"  # the status of its last solve (ControllerStats.last_status)
        self.feasible_by_construction = False
        self.workspace = ActiveSetWorkspace(self.problem, self.warm[1:])
        # DAQP's rows: the equality rows (sense "equality", b <= A x <= b), then the
        # inequality rows, filled from ``problem`` before each DAQP solve
        sense = np.zeros(n_eq + n_in, dtype=np.intc)
        sense[:n_eq] = _DAQP_EQUALITY
        self.daqp_arguments = (
            np.zeros((n_eq + n_in, n)), np.zeros(n_eq + n_in), np.zeros(n_eq + n_in), sense,
        )  # fmt: skip


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


def _active_set(
    problem: tuple,
    at_upper: np.ndarray,
    at_lower: np.ndarray,
    tolerance: float,
    rounds: int,
    duals: tuple | None = None,
    workspace: ActiveSetWorkspace | None = None,
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
    it, for at most ``rounds`` solves (one compiled call, :func:`kernels.active_set`).
    ``at_upper`` and ``at_lower`` are updated in place; ``duals`` (y, z), if given, receive
    the multipliers of the certified optimum (those of the equality rows, and of every
    inequality row: 0 if inactive, in proxsuite's convention
    :math:`H x + g + A^\top y + C^\top z = 0`). ``workspace``: the :class:`ActiveSetWorkspace`
    of ``problem`` and ``duals`` (a stage's, made once), else made here.

    Returns
    -------
    (x, solves) : the certified optimum, or None if no set verified (or the active rows are
    dependent); and the number of KKT solves made. x is the workspace's own array,
    overwritten by its next solve.
    """
    if workspace is None or workspace.problem is not problem or workspace.duals is not duals:
        workspace = ActiveSetWorkspace(problem, duals)
    return workspace.solve(at_upper, at_lower, tolerance, rounds)


class ActiveSetWorkspace:
    """The arguments of :func:`kernels.active_set` for one QP, made once: its arrays as
    given (float64 views allowed, no copies: a stage's QP arrays are refilled in place each
    tick; arrays of another dtype are converted once, so later changes to them are not seen),
    the scratch arrays and the solution, with the kernel compiled for their types
    (:func:`kernels.entry_point`: called without numba's type dispatch).

    ``problem`` is (H, g, A, b, C, l, u) with None for absent blocks; ``duals`` (y, z)
    receive the multipliers of a certified optimum (made here if None).
    """

    __slots__ = ("problem", "duals", "x", "_arguments", "_code")

    def __init__(self, problem: tuple, duals: tuple | None = None):
        hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper = problem
        n = hessian.shape[0]
        if eq_matrix is None:
            eq_matrix, eq_vector = np.zeros((0, n)), np.zeros(0)
        if in_matrix is None:
            in_matrix, lower, upper = np.zeros((0, n)), np.zeros(0), np.zeros(0)
        arrays = tuple(  # the fields of kernels.QpArrays, as a plain tuple (faster dispatch)
            a if isinstance(a, np.ndarray) and a.dtype == np.float64 else np.asarray(a, float)
            for a in (hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper)
        )
        n_eq, n_in = arrays[2].shape[0], arrays[4].shape[0]
        if duals is None:
            duals = np.zeros(n_eq), np.zeros(n_in)
        self.problem, self.duals, self.x = problem, duals, np.zeros(n)
        size = n + n_eq + min(n, n_in)
        scratch = (  # the fields of kernels.KktWorkspace
            np.zeros(size * size), np.zeros(size), np.zeros(n_in), np.zeros(n_in, np.int64),
            np.zeros(3 * size),
        )  # fmt: skip
        self._arguments = (arrays, scratch, self.x, *duals)
        flags = np.zeros(n_in, dtype=bool)
        # the equality rows are a strided view of a stage's stacked rows in some QPs, arrays
        # of their own in others: one compiled code for both
        self._code = kernels.entry_point(
            kernels.active_set, kernels.with_open_layout(arrays, (2, 3)), flags, flags, 0.0, 1,
            scratch, self.x, *duals,
        )  # fmt: skip

    def solve(self, at_upper, at_lower, tolerance: float, rounds: int) -> tuple:
        """:func:`_active_set` on this workspace's problem: (x or None, KKT solves)."""
        arrays, scratch, x, y, z = self._arguments
        # the compiled code takes only the types it was made for; others go through numba's
        # dispatch (e.g. a caller's non-boolean flags)
        code = self._code if at_upper.dtype == at_lower.dtype == np.bool_ else kernels.active_set
        solves = code(arrays, at_upper, at_lower, float(tolerance), int(rounds), scratch, x, y, z)
        return (x, solves) if solves > 0 else (None, -solves)


class StageSolver:
    """Solves the stages of one contact set's QP (a part of
    :class:`~dmpopt.control.inverse_dynamics.ContactSetQP`).

    ``settings_source`` is the proxsuite QP whose settings (tolerances, iteration limits,
    verbosity) every stage's proxsuite QP takes before a solve: the controller's ``qp``,
    shared by the QPs of every contact set. A solve reports to the ``stats`` it is given and
    hands each candidate optimum to ``accept(stage, solution) -> bool`` (the QP's expansion
    into accelerations, wrenches and torques, False for a non-finite one).

    The answer of a solve is decided by the active-set certificate and DAQP, both
    deterministic, never by proxsuite's last bits: proxsuite's iterates differ in their last
    bits between processes for the same inputs (its vectorised kernels depend on where its
    buffers lie in memory), and on a nearly infeasible QP whether it converges at all differs
    too. A solver's answer is only a guess of the active set, which :func:`_active_set`
    refines to the exact optimum. So the same problems give bitwise the same answers in any
    process, serial or parallel, as long as DAQP decides (it solved or refused every QP of the
    studies' walks; proxsuite is the fallback for a QP DAQP cannot factor or cycles on). A
    solve that no active set verifies fails (the tick goes on to its next stage, in the end to
    the hold answer); a solver's own answer is never returned.
    """

    __slots__ = ("settings_source",)

    def __init__(self, settings_source):
        self.settings_source = settings_source

    def solve(self, stage: _Stage, deadline: float, stats: ControllerStats, accept) -> bool:
        """Solve one stage: active-set iterations from its last active set, else DAQP from
        scratch (its active set refined by the same iterations); only if DAQP fails for
        another reason than infeasibility (or on a stage feasible by construction),
        proxsuite warm (cold on its first use), then once more cold if ``deadline`` (thread
        CPU time) allows. A stage DAQP finds infeasible fails: the tick goes on to its next
        stage, whatever proxsuite would say (its verdict on a nearly infeasible QP differs
        between processes).

        A non-finite Hessian or gradient (a NaN written into a task) fails without a solve:
        proxsuite can report such a problem solved.
        """
        hessian, gradient = stage.update_arguments[:2]
        if not math.isfinite(hessian.sum() + gradient.sum()):
            stats.last_status, stats.last_iterations = "NON_FINITE_PROBLEM", 0
            stage.status = stats.last_status
            stage.initialized = stage.known = stage.certified = False
            return False
        if stage.known:
            tolerance = self.settings_source.settings.eps_abs
            solution, solves = _active_set(
                stage.problem, stage.at_upper, stage.at_lower, tolerance, _WARM_ROUNDS,
                stage.workspace.duals, stage.workspace,
            )  # fmt: skip
            stats.last_status, stats.last_iterations = _ACTIVE_SET, solves
            if solution is not None and self._certified(stage, solution, accept):
                return True
        solved = self._daqp(stage, stats, accept)
        if solved or (solved is False and not stage.feasible_by_construction):
            stage.known = solved
            return solved
        stats.n_proxsuite += 1
        qp = stage.qp
        if qp is not self.settings_source:
            settings, source = qp.settings, self.settings_source.settings
            for name in _MIRRORED_SETTINGS:
                setattr(settings, name, getattr(source, name))
        if not stage.initialized:
            qp.init(*stage.init_arguments)
            solved = self._run(stage, True, deadline, stats, accept)
        else:
            qp.update(*(stage.init_arguments if stage.stale else stage.update_arguments))
            solved = self._run(stage, False, deadline, stats, accept)
            # proxsuite can also report a feasible QP infeasible from a stale warm start.
            if not solved and time.thread_time() < deadline:
                stats.n_cold_restarts += 1
                solved = self._run(stage, True, deadline, stats, accept)
        stage.initialized = stage.known = solved
        stage.stale = False
        return solved

    @staticmethod
    def _certified(stage: _Stage, solution: np.ndarray, accept) -> bool:
        """Take a certified optimum (its multipliers are in ``stage.warm``), if finite."""
        stage.certified = accept(stage, solution)
        if stage.certified:
            stage.warm[0][:] = solution
        return stage.certified

    def _daqp(self, stage: _Stage, stats: ControllerStats, accept) -> bool | None:
        """DAQP (a dual active-set solver) on one stage from scratch; its multipliers seed
        the active set that :func:`_active_set` refines.

        DAQP is plain C without vectorised reductions: the same problem gives the same bits
        in every process, so whether a QP is solved or found infeasible does not depend on
        where its buffers lie (proxsuite's iterates do, and on a nearly infeasible QP they
        part: one process solved a QP another called infeasible).

        Returns True if a set verified (the certified optimum went to ``accept``), False if
        DAQP found the QP infeasible, None if it failed otherwise (cycling, out of
        iterations, a Hessian it could not factor) or its set did not verify.
        """
        hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper = stage.problem
        rows, row_upper, row_lower, sense = stage.daqp_arguments
        n_eq = 0
        if eq_matrix is not None:
            n_eq = eq_matrix.shape[0]
            rows[:n_eq] = eq_matrix
            row_upper[:n_eq] = eq_vector
            row_lower[:n_eq] = eq_vector
        if in_matrix is not None:
            rows[n_eq:] = in_matrix
            row_upper[n_eq:] = upper
            row_lower[n_eq:] = lower
        _, _, flag, info = daqp.solve(hessian, gradient, rows, row_upper, row_lower, sense)
        stats.last_status = stage.status = _DAQP_STATUS.get(flag, f"DAQP_EXIT_{flag}")
        stats.last_iterations = int(info["iterations"])
        if flag == _DAQP_INFEASIBLE:
            stage.certified = False
            return False
        if flag != _DAQP_SOLVED:
            return None
        _guess_active_set(info["lam"][n_eq:], stage.at_upper, stage.at_lower)
        solution, _ = _active_set(
            stage.problem, stage.at_upper, stage.at_lower, self.settings_source.settings.eps_abs,
            _REFINEMENT_ROUNDS, stage.workspace.duals, stage.workspace,
        )  # fmt: skip
        if solution is not None and self._certified(stage, solution, accept):
            return True
        return None

    def _run(self, stage: _Stage, cold: bool, deadline: float, stats, accept) -> bool:
        """proxsuite on one stage until ``deadline``, from scratch (``cold``) or from the
        last certified optimum; its active set refined by active-set iterations.

        proxsuite runs in calls of ``_CHUNK_ITERATIONS`` outer iterations (of at most 10
        inner ones), each warm from the last, up to ``max_iter`` while time is left: a solve
        ends at most one call after ``deadline``, and the calls do not depend on the time.
        proxsuite's answer only seeds the active set (:func:`_guess_active_set`) of the
        refinement, and only if it converged (else the refinement starts from the stage's own
        set); the stage is solved only if a set verifies, and then its answer is that set's
        KKT solution.
        """
        qp = stage.qp
        settings = qp.settings
        limit, done, iterations = settings.max_iter, 0, 0
        chunk = min(limit, _CHUNK_ITERATIONS)
        settings.max_iter = chunk
        if cold or not stage.certified:
            settings.initial_guess = _COLD
            qp.solve()
        else:
            settings.initial_guess = _WARM_GIVEN
            qp.solve(*stage.warm)
        settings.initial_guess = _WARM  # any next call goes on from this result
        while True:
            info = qp.results.info
            done, iterations = done + chunk, iterations + int(info.iter)
            if info.status != _MAX_ITER or done >= limit or time.thread_time() >= deadline:
                break
            chunk = min(_CHUNK_ITERATIONS, limit - done)
            settings.max_iter = chunk
            qp.solve()
        settings.max_iter = limit
        stats.last_status = stage.status = info.status.name
        stats.last_iterations = iterations
        # Only a converged proxsuite's multipliers seed the set: those of one stopped early
        # (out of iterations, or a problem it called infeasible) can differ between
        # processes in more than their last bits (on a near-infeasible QP, |z| grows to
        # 1e20 and two processes' iterates part), and so would the set and whether it
        # verifies. Then the refinement goes on from the stage's own set (deterministic).
        if info.status == _SOLVED:
            z = qp.results.z
            if not math.isfinite(z.sum()):
                stage.certified = False
                return False
            _guess_active_set(z, stage.at_upper, stage.at_lower)
        solution, _ = _active_set(
            stage.problem, stage.at_upper, stage.at_lower, settings.eps_abs, _REFINEMENT_ROUNDS,
            stage.workspace.duals, stage.workspace,
        )  # fmt: skip
        if solution is not None and self._certified(stage, solution, accept):
            return True
        # No active set verified: the stage fails (the tick goes on to its next stage; see
        # Tick), never proxsuite's own answer, whose last bits depend on the process.
        stage.certified = False
        return False


def _guess_active_set(z: np.ndarray, at_upper: np.ndarray, at_lower: np.ndarray) -> None:
    """The first active set of the refinement, from proxsuite's multipliers ``z`` (written
    into ``at_upper`` and ``at_lower``): the rows whose multiplier exceeds
    :data:`_ACTIVE_MULTIPLIER` times the largest one (at least 1), with its sign.

    proxsuite's answers to the same QP differ by ~1e-12 between processes; the threshold lies
    far from that noise on both sides (see :data:`_ACTIVE_MULTIPLIER`), so such differences
    do not change the set, and the refinement from it (a compiled, deterministic KKT solve)
    gives the same bits in every process.
    """
    threshold = _ACTIVE_MULTIPLIER * max(1.0, float(np.abs(z).max(initial=0.0)))
    np.greater(z, threshold, out=at_upper)
    np.less(z, -threshold, out=at_lower)
