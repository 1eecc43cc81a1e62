"""The public whole-body controller: QP inverse dynamics with contact switching.

:class:`InverseDynamicsController` keeps one :class:`~dmpopt.control.inverse_dynamics.ContactSetQP`
per set of active contacts and tasks it has met, and runs the contact transitions of the
contact-switching API (``remove_contact`` with a normal-force ramp, ``add_contact``,
``add_task``/``remove_task``).
"""

from __future__ import annotations

import dataclasses
import gc
import math
import numbers
from collections import OrderedDict
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError
from dmpopt.validation import real_array, unit_rotation_blocks

from . import kernels
from .inverse_dynamics import (
    AssembledQp,
    ContactSetQP,
    ControllerStats,
    SolverSettings,
    _check_items,
    _check_positive,
)
from .joint_impedance import JointImpedance
from .tasks import Task

__all__ = ["InverseDynamicsController"]

# Contact-set QPs kept at most (least recently used dropped): a walking gait meets four.
_CACHE_SIZE = 16
UNIT_NORM_TOLERANCE = 1e-3
"""Largest accepted deviation from 1 of the norm of a state's quaternions (the simulators')."""


@dataclass
class _Ramp:
    """A pending transition: the normal-force bound goes linearly from ``initial`` at
    ``start`` to ``final`` at ``start + duration`` (start: the first tick after the request);
    a contact ramping to 0 is then dropped."""

    duration: float
    initial: float
    final: float
    start: float | None = None

    def limit(self, t: float) -> float | None:
        """The bound at ``t``, or None once the transition is over."""
        if self.start is None:
            self.start = t
        elapsed = t - self.start
        if elapsed < 0:
            raise InvalidInputError(
                f"t={t!r} is before the start of a contact transition at t={self.start!r}; "
                "the controller time must not go back"
            )
        if elapsed >= self.duration:
            return None
        return self.initial + (self.final - self.initial) * elapsed / self.duration


def _duration(value) -> float:
    duration = _time(value, "transition_time")
    if duration < 0:
        raise InvalidInputError(
            f"transition_time must be >= 0 [s], got {value!r}; 0 switches at once"
        )
    return duration


def _time(value, name: str) -> float:
    real = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
    if not (real and math.isfinite(value)):
        kind = f" (a {type(value).__name__}: pass a number)" if not real else ""
        raise InvalidInputError(f"{name} must be a finite number of seconds, got {value!r}{kind}")
    return float(value)


class InverseDynamicsController:
    r"""Task-space inverse dynamics with rigid contacts that can be switched, solved each tick.

    Contacts are removed (at once, or with a transition that ramps their normal force down)
    and added back at run time, and tasks added and removed (a swing foot). The QP of each
    set of active contacts and tasks (:class:`ContactSetQP`) is built the first time the set
    is used and kept, so a switch back to a known set costs nothing; a transition changes
    only a normal-force bound of that QP each tick.

    Parameters
    ----------
    robot : RobotModel
        The robot (see :mod:`robots`); floating or fixed base.
    tasks : sequence of Task
        Weighted tasks (:class:`~dmpopt.control.tasks.PostureTask`, ``FrameTask``,
        ``ComTask``). Keep a reference to update their targets between ticks.
    contacts : sequence of Contact
        Every contact the robot may use, one per frame, of any kinds
        (:class:`~dmpopt.control.SoleContact`, ``PointContact``, ``SurfaceContact``, or a
        subclass of :class:`~dmpopt.control.Contact` of your own). The active ones' wrenches
        are decision variables.
    inactive : sequence of str
        Frames of ``contacts`` not active at construction (e.g. a foot in the air).
    joint_impedance : JointImpedance, optional
        A stiff joint loop around the QP's motion, added to its torques (for a plant that is
        not the model: friction, damping, armature, delay; :mod:`.joint_impedance`). The
        returned torques are then the sum, still within the torque limits.
    acceleration_regularization : float
        :math:`\epsilon_a`, keeps the Hessian positive definite when tasks leave joints free.
    force_regularization : float
        :math:`\epsilon_f`, spreads the load between contacts. Forces are in newtons, hundreds
        of times larger than accelerations, so it is small: 1e-5 would already let Talos sag
        by 0.02 m/s^2 to save force.
    tolerance : float
        proxsuite absolute tolerance ``eps_abs`` on the KKT residuals and the duality gap;
        the acceleration bounds of the joint limits are met to it (a joint resting at its
        limit would otherwise violate them by rounding errors). A much tighter tolerance needs
        more iterations: raise ``max_iterations`` with it.
    max_iterations : int
        proxsuite's outer iteration limit per solve (each of at most 10 inner iterations):
        with ``time_budget``, what bounds a tick's time.
    time_budget : float
        CPU seconds (of the calling thread) per tick. The exact QP may use the first half,
        the relaxed QP the rest; a tick that runs out of it gives the hold answer. proxsuite
        runs in calls of 3 outer iterations (at most 30 inner ones) with the time checked
        between, so a tick overruns its budget by about one such call plus the active-set
        rounds, which are not interrupted (the bound is soft: for Talos with infeasible torque
        limits on a busy 2-core machine, at most 6.6 ms CPU for the default 5 ms,
        ``benchmarks/bench_qp_stress.py``). The calls do not depend on the time: a tick whose
        budget is not spent gives the same answer for the same inputs and history. CPU time,
        not wall time, so that a busy machine changes the answers less; on a dedicated
        real-time core they are the same.
    raise_on_failure : bool
        If True, a tick that would give the hold answer raises :class:`NoSolutionFound`.
    joint_limit_horizon : float or None
        h [s]: bound the accelerations of ``limited_joints`` so that they stay within the
        robot's position and velocity limits (see :func:`kernels.acceleration_bounds`: a joint
        brakes no later than a critically damped approach of time constant h). None: no such
        bounds, torque limits only.
    limited_joints : str or sequence of str, optional
        The joints so bounded: a joint group (``"right_arm"``) or joint names; default all
        actuated joints with finite position limits. A joint may end up to
        ``JOINT_LIMIT_TOLERANCE`` (1e-3 rad) past its limit: the bounds aim at the limit plus
        that margin, so that a joint resting exactly at its limit (Talos's closed grippers)
        leaves its bound inactive.
    torque_limit_scale : float
        The torque limits used are ``torque_limit_scale * robot.torque_limit`` (> 0; e.g.
        0.3 to test a controller with weak motors).
    dense_backend : proxsuite.proxqp.dense.DenseBackend
        Factorisation used by proxsuite. ``PrimalDualLDLT`` (the KKT system) is the default:
        ``PrimalLDLT`` factorises :math:`H + C^\top C/\mu` and stalls at tight tolerances on
        ill-conditioned task Hessians.

    Attributes
    ----------
    qp : proxsuite.proxqp.dense.QP
        The QP with torque-limit rows (and cone rows, if in contact) of the first contact
        set. Its settings ``eps_abs``, ``eps_rel``, ``max_iter`` and ``verbose`` are copied
        to every other proxsuite QP (of every contact set) before each of their solves.
        Ticks without an active inequality row do not use proxsuite.
    contacts : tuple
        Every contact given at construction.

    Notes
    -----
    Each tick gives one of four answers, counted in :attr:`stats`:

    - ``direct``: no inequality row active; the least-squares optimum (exact).
    - ``solved``: the QP with its inequality rows: by at most 5 active-set iterations from
      the last tick's active set, else by DAQP (a dual active-set solver, deterministic;
      only if it fails numerically by proxsuite, warm-started, retried cold once on
      failure, within the first half of the time budget) whose multipliers seed
      active-set iterations: the answer is the exact optimum of an active set that verifies
      (:func:`_active_set`), the same bits in every process wherever DAQP decides
      (``stats.n_proxsuite`` counts the solves that reached proxsuite).
    - ``relaxed``: if that QP fails (infeasible, e.g. torque limits too weak to hold the
      robot, out of iterations or of its half of the budget, or no active set verified),
      the QP with every
      inequality row in which the contact rows and the acceleration bounds get slacks
      weighted by 1e4 in the cost; the torque and cone rows stay hard. It is always
      feasible (the contact wrenches can sit inside their cones, and the joint
      accelerations can produce any torque).
    - ``hold``: if that fails too or the whole time budget is spent, the last valid torque
      (gravity and Coriolis compensation :math:`h_a` on the first tick), clipped to the
      torque limits.

    The torques are always finite and within the torque limits.

    A transition (``remove_contact(frame, transition_time)``, as TSID's
    ``removeRigidContact``) keeps the contact rigid while the upper bound of its normal force
    falls linearly from its normal force of the last tick (``max_normal_force`` before the
    first tick) to 0 over ``transition_time`` seconds of controller time, counted from the
    first tick after the call; its lower bound is ``min(min_normal_force, upper)``. The tick
    at or after the end drops the contact. While a transition is pending
    :meth:`compute_torques` needs the controller time ``t``.
    """

    def __init__(
        self,
        robot,
        tasks: Sequence[Task],
        contacts: Sequence = (),
        *,
        inactive: Sequence[str] = (),
        joint_impedance: JointImpedance | None = None,
        acceleration_regularization: float = SolverSettings.acceleration_regularization,
        force_regularization: float = SolverSettings.force_regularization,
        tolerance: float = SolverSettings.tolerance,
        max_iterations: int = SolverSettings.max_iterations,
        time_budget: float = SolverSettings.time_budget,
        raise_on_failure: bool = SolverSettings.raise_on_failure,
        joint_limit_horizon: float | None = SolverSettings.joint_limit_horizon,
        limited_joints: str | Sequence[str] | None = SolverSettings.limited_joints,
        torque_limit_scale: float = SolverSettings.torque_limit_scale,
        dense_backend=SolverSettings.dense_backend,
    ):
        _check_items(robot, tasks, contacts)
        if joint_impedance is not None and not isinstance(joint_impedance, JointImpedance):
            raise InvalidInputError(
                f"joint_impedance must be a JointImpedance or None, got "
                f"{type(joint_impedance).__name__}"
            )
        self.joint_impedance = joint_impedance
        self.robot, self.model = robot, robot.model
        self.contacts = tuple(contacts)
        frames = [contact.frame for contact in self.contacts]
        for frame in set(frames):
            if frames.count(frame) > 1:
                raise InvalidInputError(
                    f"contacts holds {frames.count(frame)} contacts on {frame!r}; give one "
                    "contact per foot frame"
                )
        self._by_frame = dict(zip(frames, self.contacts))
        if isinstance(inactive, str):
            raise InvalidInputError(
                f"inactive must be a sequence of frame names; wrap one in a list: [{inactive!r}]"
            )
        for frame in inactive:
            self._known(frame, "inactive")
        self._initial = tuple(f for f in frames if f not in set(inactive))
        self._active = self._initial
        self._tasks = tuple(tasks)
        self._settings = SolverSettings(
            acceleration_regularization, force_regularization, tolerance, max_iterations,
            time_budget, raise_on_failure, joint_limit_horizon, limited_joints,
            torque_limit_scale, dense_backend,
        )  # fmt: skip
        self._stats = ControllerStats()
        self._formulations: OrderedDict[tuple, ContactSetQP] = OrderedDict()
        self._ramps: dict[str, _Ramp] = {}
        self.qp = None
        self._current = self._formulation()
        self.qp = self._current.qp
        self._changed = False  # active contacts or tasks changed since the last tick

    # ------------------------------------------------------------------ switching
    @property
    def active_contacts(self) -> tuple[str, ...]:
        """Frames of the contacts in use, in construction order (including ones ramping
        down)."""
        return self._active

    @property
    def tasks(self) -> tuple[Task, ...]:
        """The tasks in use."""
        return self._tasks

    def remove_contact(self, frame: str, transition_time: float = 0.0) -> None:
        """Stop using the contact on ``frame``.

        Parameters
        ----------
        frame : str
            An active contact's frame.
        transition_time : float
            0: the contact is dropped from the next tick. > 0 [s]: its normal-force bound
            ramps to 0 over this much controller time first (see the class notes).
        """
        self._known(frame, "frame")
        if frame not in self._active:
            raise InvalidInputError(
                f"frame={frame!r} is not an active contact; active: {self._active}"
            )
        duration = _duration(transition_time)
        if duration == 0:
            self._ramps.pop(frame, None)
            self._set_active(f for f in self._active if f != frame)
        elif frame in self._ramps and self._ramps[frame].final == 0:
            raise InvalidInputError(
                f"frame={frame!r} is already being removed; call remove_contact({frame!r}) "
                "with transition_time=0 to drop it at once"
            )
        else:
            self._ramps[frame] = _Ramp(duration, self._normal_force(frame), 0.0)

    def add_contact(
        self, frame: str, reference: pin.SE3 | None = None, transition_time: float = 0.0
    ) -> None:
        """Use the contact on ``frame`` from the next tick, held at ``reference``.

        Parameters
        ----------
        frame : str
            The frame of one of :attr:`contacts`, not active (or being removed: its
            transition is cancelled).
        reference : pinocchio.SE3, optional
            Placement the contact holds; default the frame's placement at the next tick.
        transition_time : float
            0: the normal force is free at once. > 0 [s]: its upper bound ramps from 0 to
            ``max_normal_force`` over this much controller time (the mirror of
            :meth:`remove_contact`), so that the load moves onto the foot gradually.
        """
        contact = self._known(frame, "frame")
        duration = _duration(transition_time)
        if frame in self._active and frame not in self._ramps:
            raise InvalidInputError(f"frame={frame!r} is already an active contact")
        if reference is not None:
            if not isinstance(reference, pin.SE3):
                raise InvalidInputError(
                    f"reference must be a pinocchio.SE3 or None, got {type(reference).__name__}"
                )
            if not kernels.is_placement(reference.homogeneous):
                raise InvalidInputError(
                    "reference must be finite with a rotation matrix (R^T R = I); it holds "
                    "NaN, inf or a non-orthonormal rotation"
                )
            reference = reference.copy()
        if frame in self._ramps:  # being removed: cancelled, the contact kept
            del self._ramps[frame]
            self._changed = True  # restore its normal-force bound
            if reference is None:
                return
        contact.reference_placement = reference
        if duration > 0:
            self._ramps[frame] = _Ramp(duration, 0.0, contact.max_normal_force)
        self._set_active(self._active + (frame,))

    def add_task(self, task: Task) -> None:
        """Use ``task`` from the next tick (e.g. a swing foot's FrameTask)."""
        _check_items(self.robot, [task], ())
        if any(task is other for other in self._tasks):
            raise InvalidInputError("task is already in use; add each task once")
        self._tasks = self._tasks + (task,)
        self._changed = True

    def remove_task(self, task: Task) -> None:
        """Stop using ``task`` from the next tick."""
        if not any(task is other for other in self._tasks):
            raise InvalidInputError(
                f"task ({type(task).__name__}) is not in use; remove only a task given to "
                "the controller or added with add_task"
            )
        if len(self._tasks) == 1:
            raise InvalidInputError(
                "remove_task would leave no task; add another (e.g. PostureTask) first"
            )
        self._tasks = tuple(other for other in self._tasks if other is not task)
        self._changed = True

    def prepare(self, contacts: Sequence[str], tasks: Sequence[Task] | None = None) -> None:
        """Build the QP of a set of active ``contacts`` (frames) and ``tasks`` (default: the
        tasks in use) now, so that a later switch to that set inside the control loop finds it
        ready: building one costs milliseconds (model data, proxsuite QPs, a first solve),
        switching to a built one tens of microseconds. Up to 16 sets are kept."""
        if isinstance(contacts, str):
            raise InvalidInputError(
                f"contacts must be a sequence of frame names; wrap one in a list: [{contacts!r}]"
            )
        for frame in contacts:
            self._known(frame, "contacts")
        tasks = self._tasks if tasks is None else tuple(tasks)
        _check_items(self.robot, tasks, ())
        active, current = self._active, self._tasks
        self._active = tuple(f for f in self._by_frame if f in set(contacts))
        self._tasks = tasks
        try:
            self._formulation()
        finally:
            self._active, self._tasks = active, current
            if self._key() in self._formulations:  # the set in use is the last to be dropped
                self._formulations.move_to_end(self._key())

    def _known(self, frame, name: str):
        if frame not in self._by_frame:
            raise InvalidInputError(
                f"{name}={frame!r} is not the frame of a contact given to the controller; "
                f"expected one of {tuple(self._by_frame)}"
            )
        return self._by_frame[frame]

    def _set_active(self, frames) -> None:
        chosen = set(frames)
        self._active = tuple(f for f in self._by_frame if f in chosen)
        self._changed = True

    def _normal_force(self, frame: str) -> float:
        """The contact's normal force of the last tick, else its max_normal_force."""
        contact = self._by_frame[frame]
        formulation = self._current
        if self._stats.n_ticks and contact in formulation.contacts:
            index = formulation.contacts.index(contact)
            return contact.normal_force(formulation.contact_wrenches[index])
        return contact.max_normal_force

    def _key(self) -> tuple:
        return (self._active, tuple(map(id, self._tasks)))

    def _formulation(self) -> ContactSetQP:
        """The QP of the active contacts and tasks, built on first use; shares the stats."""
        key = self._key()
        formulation = self._formulations.pop(key, None)
        if formulation is None:
            contacts = [self._by_frame[f] for f in self._active]
            formulation = ContactSetQP(
                self.robot, self._tasks, contacts, settings=self._settings, settings_source=self.qp
            )
        self._formulations[key] = formulation
        if len(self._formulations) > _CACHE_SIZE:
            self._formulations.popitem(last=False)
        formulation.stats = self._stats
        return formulation

    def _switch(self) -> None:
        """Move to the QP of the current set; hold torque and normal-force bounds carried."""
        previous, current = self._current, self._formulation()
        if current is not previous:
            current.continue_from(previous)
        for index, contact in enumerate(current.contacts):
            if contact.frame not in self._ramps:
                current.set_normal_force_limit(index, contact.max_normal_force)
        self._current = current
        self._changed = False

    def _advance_transitions(self, t) -> None:
        """Normal-force bounds of the contacts ramping down at time ``t``; drop finished ones."""
        if t is None:
            raise InvalidInputError(
                f"t is required while a contact transition is pending ({sorted(self._ramps)}); "
                "pass the controller time: compute_torques(q, v, t)"
            )
        t = _time(t, "t")
        limits = {}
        for frame, ramp in list(self._ramps.items()):
            limit = ramp.limit(t)
            if limit is not None:
                limits[frame] = limit
                continue
            del self._ramps[frame]
            self._changed = True  # its bound back to max_normal_force, or dropped:
            if ramp.final == 0:
                self._set_active(f for f in self._active if f != frame)
        if self._changed:
            self._switch()
        formulation = self._current
        for index, contact in enumerate(formulation.contacts):
            if contact.frame in limits:
                formulation.set_normal_force_limit(index, limits[contact.frame])

    # ------------------------------------------------------------------ one tick
    def compute_torques(self, q: np.ndarray, v: np.ndarray, t: float | None = None) -> np.ndarray:
        """Joint torques for the state ``(q, v)``: one model update, QP assembly and solve.

        Parameters
        ----------
        q : ndarray, shape (nq,)
            Configuration (base coordinates first, if floating).
        v : ndarray, shape (nv,)
            Velocity (base velocity first, if floating).
        t : float, optional
            Controller time [s]; required while a contact transition is pending.

        Returns
        -------
        ndarray, shape (n_actuated,)
            Torques of the actuated joints [N m], within the torque limits, always finite.

        Notes
        -----
        Python's cyclic garbage collector is paused for the whole call (contact transitions,
        a switch to another contact set's QP and the joint impedance included), as in
        :meth:`Tick.compute_torques <dmpopt.control.tick.Tick.compute_torques>`.
        """
        if not gc.isenabled():
            return self._compute_torques(q, v, t)
        gc.disable()
        try:
            return self._compute_torques(q, v, t)
        finally:
            gc.enable()

    def _compute_torques(self, q, v, t) -> np.ndarray:
        """:meth:`compute_torques` with the collector paused."""
        q, v = self._check_state(q, v)
        if self._ramps:
            self._advance_transitions(t)
        elif t is not None:
            _time(t, "t")
        if self._changed:
            self._switch()
        torques = self._current.tick._tick(q, v)  # (the collector is paused here already)
        if self.joint_impedance is None:
            return torques
        current = self._current
        return self.joint_impedance.torques(q, v, current.joint_accelerations, torques)

    def _check_state(self, q, v) -> tuple[np.ndarray, np.ndarray]:
        """``q`` and ``v`` (arrays or lists) as float arrays of the model's sizes, with unit
        quaternions and unit complex numbers as the simulators require (a norm within
        :data:`UNIT_NORM_TOLERANCE` of 1). Float arrays of the right shapes pass as they are
        (the tick checks that they are finite)."""
        model = self.model
        name = self.robot.name
        if not (isinstance(q, np.ndarray) and q.dtype == np.float64 and q.shape == (model.nq,)):
            q = real_array("q", q, shape=(model.nq,), expected=f"the configuration of {name}")
        if not (isinstance(v, np.ndarray) and v.dtype == np.float64 and v.shape == (model.nv,)):
            v = real_array("v", v, shape=(model.nv,), expected=f"the velocity of {name}")
        if pin.isNormalized(model, q, UNIT_NORM_TOLERANCE):
            return q, v
        if not np.isfinite(q).all():
            raise InvalidInputError("q and v must be finite; the state holds NaN or inf")
        unit_rotation_blocks(model, q, UNIT_NORM_TOLERANCE)
        raise InvalidInputError(
            "q has a non-unit quaternion or complex number inside a composite joint; pass a "
            "normalised configuration (pinocchio.normalize(model, q))"
        )

    # ------------------------------------------------------------------ results
    @property
    def stats(self) -> ControllerStats:
        """Counters of the answers since construction or :meth:`reset`."""
        return self._stats

    @property
    def joint_accelerations(self) -> np.ndarray:
        """Joint accelerations of the last solve, shape (nv,) (copy)."""
        return self._current.joint_accelerations

    @property
    def contact_wrenches(self) -> np.ndarray:
        """Wrenches (forces of point contacts) of the last solve, one row per contact active
        on that tick, in :attr:`active_contacts` order (copy).

        Rows are (fx, fy, fz, tx, ty, tz) [N, N m] in each sole frame, or the point force in
        world axes ((fx, fz) on a planar robot).
        """
        return self._current.contact_wrenches

    def assembled_qp(self, q: np.ndarray, v: np.ndarray) -> AssembledQp:
        """The QP of a tick at ``(q, v)`` for the contacts and tasks in use, with every
        inequality row and the names of its variables and rows (see :class:`AssembledQp`);
        for inspection, e.g. after a tick: ``qp = controller.assembled_qp(q, v)``, then
        ``qp.objective(y)`` of any candidate. Changes no answer of a later tick."""
        q, v = self._check_state(q, v)
        if self._changed:
            self._switch()
        return self._current.assembled_qp(q, v)

    def contact_force(self, frame: str) -> np.ndarray:
        """The wrench (or point force) of the contact on ``frame`` at the last solve; zeros if
        it was not active."""
        contact = self._known(frame, "frame")
        formulation = self._current
        if contact not in formulation.contacts:
            return np.zeros(contact.n_force)
        return formulation.contact_wrenches[formulation.contacts.index(contact), : contact.n_force]

    @property
    def torques(self) -> np.ndarray:
        """Torques returned by the last tick, shape (n_actuated,) (copy)."""
        return self._current.torques

    @property
    def torque_limit(self) -> np.ndarray:
        """Torque limits used [N m] (``torque_limit_scale * robot.torque_limit``)."""
        return self._current.torque_limit

    @property
    def time_budget(self) -> float:
        """CPU seconds per tick (see the parameter)."""
        return self._current.time_budget

    @time_budget.setter
    def time_budget(self, value: float) -> None:
        _check_positive("time_budget", value)
        self._set_everywhere("time_budget", float(value))

    @property
    def raise_on_failure(self) -> bool:
        """Whether a tick that would give the hold answer raises :class:`NoSolutionFound`."""
        return self._current.raise_on_failure

    @raise_on_failure.setter
    def raise_on_failure(self, value: bool) -> None:
        self._set_everywhere("raise_on_failure", bool(value))

    def _set_everywhere(self, name: str, value) -> None:
        self._settings = dataclasses.replace(self._settings, **{name: value})
        for formulation in self._formulations.values():
            setattr(formulation, name, value)

    def reset(self) -> None:
        """Back to the contacts active at construction, without transitions; forget the warm
        starts, the contact reference placements and the counters."""
        self._stats = ControllerStats()
        if self.joint_impedance is not None:
            self.joint_impedance.reset()
        for formulation in self._formulations.values():
            formulation.reset()
            formulation.stats = self._stats
        for contact in self.contacts:
            contact.reference_placement = None
        self._ramps.clear()
        self._set_active(self._initial)
