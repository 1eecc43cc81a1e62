r"""Discrete and rhythmic DMPs: immutable parameters and whole-plan rollouts.

A DMP is a frozen value. ``with_goal``, ``with_time_constant``, ... return new objects.
Rollouts use the affine structure of the plan: for a fixed time constant, step and
canonical trajectory, positions, velocities and accelerations are linear in the initial
transformation state, the goal and the weights. The response matrices are evaluated once
from the symbolic rollout (:mod:`dmpopt.symbolic`) and cached, so a rollout of any number of
DOFs is one matrix product.

Goal generalisation of discrete DMPs (``goal_scaling``). The forcing weights and the
scaled start velocity :math:`\tau \dot y(0)` are mapped by the same matrix :math:`M`, so each
plan to a new start :math:`y_0'` and goal :math:`g'` is the original plan mapped by :math:`M`:

``"paper"``
    eq. (7) per DOF: :math:`M = \mathrm{diag}(g - y_0)`, weights stored per unit of that
    distance. Per DOF, :math:`y_d' - y_{0,d}' = (y_d - y_{0,d})\,(g_d' - y_{0,d}') / (g_d -
    y_{0,d})`.
``"rotation"``
    :math:`M` is the rotation and uniform scaling that carry the demonstrated start-goal
    vector :math:`d` (``reference_displacement``) onto the new one :math:`d'`. The
    transformation system is linear and isotropic, so :math:`y' - y_0' = M (y - y_0)`: the
    reproduction of the demonstration, rotated and scaled about the start.
``"translation"``
    :math:`M = I`: new start and goal translate the shape; the unforced system takes up
    the rest. For closed or nearly closed movements.

Amplification: a goal moved by :math:`\delta` moves no point of the plan by more than
:math:`|\delta|\, \max_t |y(t) - y_0| / |d|` under ``"rotation"`` (:math:`|M - I| = |\delta|
/ |d|`; per DOF under ``"paper"``) and :math:`|\delta|` under ``"translation"``. The ratio
:math:`\max_t |y(t) - y_0| / |d| \ge 1` is large when start and goal nearly coincide;
:func:`dmpopt.fit_discrete` keeps it at most
:data:`dmpopt.fitting.imitation.MAX_GOAL_AMPLIFICATION`. A DMP built by hand in
``"rotation"`` mode trusts its ``reference_displacement``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from . import basis, symbolic, validation
from .exceptions import InvalidInputError, ShapeError
from .trajectory import Trajectory
from .validation import check_resources, real, real_array

GOAL_SCALINGS = ("paper", "rotation", "translation")
SETTLING_FRACTION = 0.9999
"""Fraction of the way to its goal that the unforced system covers, from rest, in the time
a default plan lasts beyond the convergence time (:attr:`DiscreteDMP.settling_time`)."""


def _positive(name: str, value) -> float:
    return real(name, value, minimum=0.0, open_minimum=True)


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float)
    array.setflags(write=False)
    return array


def _vector(name: str, value, size: int, reference: str) -> np.ndarray:
    array = np.atleast_1d(real_array(name, value, empty=True))
    if array.shape == (1,) and size > 1:
        array = np.full(size, array[0])
    if array.shape != (size,):
        raise ShapeError(f"{name} has shape {array.shape}, expected ({size},) to match {reference}")
    return array


def similarity_transform(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Rotation times uniform scaling that maps vector ``source`` onto ``target``.

    The rotation is the smallest one: it turns the plane spanned by the two vectors and
    leaves its orthogonal complement alone. In one dimension it is a sign.
    """
    source_norm = np.linalg.norm(source)
    target_norm = np.linalg.norm(target)
    n = source.size
    if target_norm == 0.0:
        return np.zeros((n, n))
    a, b = source / source_norm, target / target_norm
    cosine = float(np.clip(a @ b, -1.0, 1.0))
    if n == 1:
        rotation = np.array([[np.sign(cosine)]])
    elif cosine > -1.0 + 1e-12:
        cross = np.outer(b, a) - np.outer(a, b)
        rotation = np.eye(n) + cross + cross @ cross / (1.0 + cosine)
    else:  # half turn in a plane that contains a
        helper = np.eye(n)[np.argmin(np.abs(a))]
        u = helper - (helper @ a) * a
        u /= np.linalg.norm(u)
        rotation = np.eye(n) - 2 * np.outer(a, a) - 2 * np.outer(u, u)
    return target_norm / source_norm * rotation


@lru_cache(maxsize=16)
def _affine_step(signature: symbolic.Signature) -> ca.Function:
    """One RK4 step of one DOF and its Jacobians with respect to the DOF's inputs.

    ``(state, dt, *parameters) -> (next_state, step, outputs)``: ``step`` (n_transformation,
    n_inputs) is the derivative of the next transformation state and ``outputs`` (3,
    n_inputs) that of position, velocity and acceleration at ``state``, with respect to the
    inputs (transformation state, goal, forcing weights). Both are affine in these inputs,
    so the Jacobians depend only on the canonical part of ``state``.
    """
    s = symbolic.make_symbols(signature)
    inputs = ca.vertcat(s.state[2:], s.goal, ca.vec(s.forcing_weights))
    next_state = symbolic.step_function(signature)(s.state, s.dt, *s.parameters())[0]
    outputs = ca.vertcat(*symbolic.output_function(signature)(s.state, *s.parameters()))
    return ca.Function(
        "dmp_affine_step",
        [s.state, s.dt, *s.parameters()],
        [
            next_state,
            ca.densify(ca.jacobian(next_state[2:], inputs)),
            ca.densify(ca.jacobian(outputs, inputs)),
        ],
    )


@lru_cache(maxsize=16)  # an entry holds 3 x n_steps x (n_features + 3) floats
def _response(key: tuple) -> np.ndarray:
    """Response matrices of one DOF, in time normalised by ``tau``.

    Returns an array of shape (3, n_steps, n_inputs): position, velocity and acceleration
    responses to each input (initial transformation states, goal, weights). Each RK4 step
    is affine in the inputs, with Jacobians from :func:`_affine_step` along the canonical
    trajectory, so the responses follow from the affine recurrence. The cost grows linearly
    with the number of basis functions (integrating one DOF per input, as before, grew
    quadratically: over a minute for 400 basis functions).
    """
    (form, kernel, n_basis, n_steps, dt, target, canonical0, centres, widths, gains) = key
    signature = symbolic.Signature(form, 1, n_basis, kernel)
    n_transformation = symbolic.n_transformation_states(form)
    n_inputs = n_transformation + 1 + signature.n_features
    function = symbolic.NumericFunction(_affine_step(signature))
    function.set_inputs(
        np.concatenate([canonical0, np.zeros(n_transformation)]),
        dt,
        1.0,
        0.0,
        target,
        np.zeros(signature.n_features),
        np.array(centres),
        np.array(widths),
        np.array(gains),
        0.0,
        0.0,
    )
    state, (next_state, step, outputs) = function.inputs[0], function.outputs
    step = step.reshape((n_transformation, n_inputs), order="F")  # views of the buffers
    outputs = outputs.reshape((3, n_inputs), order="F")
    transformation = np.eye(n_transformation, n_inputs)  # d(transformation state)/d(inputs)
    response = np.empty((3, n_steps, n_inputs))
    for k in range(n_steps):
        function.evaluate()
        response[:, k] = outputs[:, :n_transformation] @ transformation
        response[:, k, n_transformation:] += outputs[:, n_transformation:]
        transformation = step[:, :n_transformation] @ transformation
        transformation[:, n_transformation:] += step[:, n_transformation:]
        state[:] = next_state
    response.setflags(write=False)
    return response


@dataclass(frozen=True, eq=False)
class AffinePlan:
    r"""A plan written as an affine function of the forcing weights.

    For fixed start, goal, time constant and step, positions, velocities and
    accelerations are exactly (for the discretisation used)

    .. math:: Y_k = F_k + G_k W_f^T, \quad k \in \{0, 1, 2\}

    with :math:`W_f` the forcing weights of shape (n_dofs, n_features) (see
    ``forcing_weights()`` of each DMP: the weights mapped to the current goal).

    Attributes
    ----------
    times : ndarray, shape (n_steps,)
    free : ndarray, shape (3, n_steps, n_dofs)
        Positions, velocities, accelerations with zero weights.
    weight_response : ndarray, shape (3, n_steps, n_features)
        Response of one DOF to each forcing weight (identical for every DOF).
    """

    times: np.ndarray
    free: np.ndarray
    weight_response: np.ndarray

    def evaluate(self, forcing_weights: np.ndarray) -> np.ndarray:
        """Positions, velocities, accelerations, shape (3, n_steps, n_dofs)."""
        return self.free + self.weight_response @ np.asarray(forcing_weights).T

    def trajectory(self, forcing_weights: np.ndarray) -> Trajectory:
        """The plan for ``forcing_weights`` as a :class:`Trajectory`."""
        positions, velocities, accelerations = self.evaluate(forcing_weights)
        return Trajectory(self.times, positions, velocities, accelerations)


@dataclass(frozen=True, eq=False)
class _DmpCommon:
    """Fields and behaviour shared by discrete and rhythmic DMPs."""

    def _check_basis(self, n_basis: int):
        if 0 in self.weights.shape:
            raise ShapeError(
                f"weights has shape {self.weights.shape}: a DMP needs at least one DOF and one "
                "basis function"
            )
        centres = _vector("centres", self.centres, n_basis, f"{n_basis} basis functions")
        widths = _vector("widths", self.widths, n_basis, f"{n_basis} basis functions")
        if np.any(widths <= 0):
            raise InvalidInputError(f"widths must all be positive, got {widths.min()!r}")
        object.__setattr__(self, "centres", _frozen(centres))
        object.__setattr__(self, "widths", _frozen(widths))
        object.__setattr__(self, "time_constant", _positive("time_constant", self.time_constant))
        object.__setattr__(self, "stiffness", _positive("stiffness", self.stiffness))
        if self.damping is None:
            object.__setattr__(self, "damping", self.stiffness / 4.0)
        object.__setattr__(self, "damping", _positive("damping", self.damping))

    @property
    def n_dofs(self) -> int:
        """Number of DOFs sharing the canonical system."""
        return self.weights.shape[0]

    @property
    def n_basis(self) -> int:
        """Number of basis functions per DOF."""
        return self.weights.shape[1]

    @property
    def signature(self) -> symbolic.Signature:
        """Sizes and choices of the compiled system."""
        return symbolic.Signature(self.form, self.n_dofs, self.n_basis, self.kernel)

    def replace(self, **changes):
        """Return a copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @property
    def max_step(self) -> float:
        """Largest step [s] at which the RK4 integration is stable (:func:`basis.stable_step`)."""
        return self.time_constant * basis.stable_step(
            self.form, tuple(self.gains), float(self._canonical_target()), self._cycle_states()
        )

    def _cycle_states(self) -> tuple:
        """Canonical states at which the system is linearised for its stability limit."""
        if isinstance(self, RhythmicDMP):
            angles = np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
            return tuple(self.canonical_state(angle) for angle in angles)
        return ((0.0, 0.0),)

    def check_step(self, dt, name: str = "dt") -> float:
        """Return ``dt`` if it is a positive step within :attr:`max_step`, else raise."""
        dt = _positive(name, dt)
        if dt > self.max_step:
            raise InvalidInputError(
                f"{name} = {dt:.4g} s is beyond the stability limit {self.max_step:.4g} s of the "
                f"RK4 integration for time_constant {self.time_constant:.4g} s and these gains "
                "(the plan would grow without bound); use a smaller step"
            )
        return dt

    def with_time_constant(self, time_constant: float):
        """Same movement, time scaled: ``tau -> time_constant`` (Section 3.3)."""
        return self.replace(time_constant=time_constant)

    def parameter_values(self) -> list:
        """Numeric inputs of the symbolic functions, in :data:`symbolic.PARAMETER_NAMES` order."""
        return [
            self.time_constant,
            self._goal_input(),
            self._canonical_target(),
            self.forcing_weights(),
            np.asarray(self.centres),
            np.asarray(self.widths),
            np.asarray(self.gains),
            np.zeros(self.n_dofs),
            0.0,
        ]

    def _response_and_inputs(self, duration, dt, start, start_velocity, canonical0):
        duration = _positive("duration", duration)
        dt = self.check_step(dt)
        n_steps = int(round(duration / dt)) + 1
        if n_steps < 3:
            raise InvalidInputError(
                f"duration {duration} is shorter than two steps of dt = {dt}; lower dt"
            )
        n_inputs = symbolic.n_transformation_states(self.form) + 1 + self.signature.n_features
        check_resources(
            f"a plan of {duration:.4g} s at dt = {dt:.4g} s",
            8.0 * n_steps * (6 * n_inputs + 6 * self.n_dofs),
            "raise dt or shorten duration (by default the convergence time or three periods, "
            "both proportional to time_constant)",
            n_samples=n_steps,
        )
        key = (
            self.form,
            self.kernel,
            self.n_basis,
            n_steps,
            dt / self.time_constant,
            float(self._canonical_target()),
            tuple(canonical0),
            tuple(self.centres),
            tuple(self.widths),
            tuple(self.gains),
        )
        times = np.arange(n_steps) * dt
        # the cache keeps 16 entries: keep out those that would hold over 1/16 of the budget
        small = 24.0 * n_steps * n_inputs <= validation.MEMORY_BUDGET / 16
        response = _response(key) if small else _response.__wrapped__(key)
        return times, response, self._response_inputs(start, start_velocity, canonical0)

    def _affine(self, duration, dt, start, start_velocity, canonical0) -> AffinePlan:
        times, response, inputs = self._response_and_inputs(
            duration, dt, start, start_velocity, canonical0
        )
        scale = np.array([1.0, self.time_constant, self.time_constant**2])[:, None, None]
        n_free = inputs.shape[0] - symbolic.n_features(self.form, self.n_basis)
        return AffinePlan(
            times=times,
            free=response[:, :, :n_free] @ inputs[:n_free] / scale,
            weight_response=response[:, :, n_free:] / scale,
        )

    def _rollout(self, duration, dt, start, start_velocity, canonical0) -> Trajectory:
        times, response, inputs = self._response_and_inputs(
            duration, dt, start, start_velocity, canonical0
        )
        tau = self.time_constant
        return Trajectory(
            times,
            response[0] @ inputs,
            response[1] @ inputs / tau,
            response[2] @ inputs / tau**2,
        )

    def _initial_z(self, start_velocity, canonical0):
        """``z`` such that the initial velocity is ``start_velocity``: ``tau yd = z + f``."""
        z = self.time_constant * start_velocity
        if self.form == "velocity" or self.form in symbolic.RHYTHMIC_FORMS:
            feature = symbolic.feature_function(self.signature)(
                canonical0, np.asarray(self.centres), np.asarray(self.widths)
            ).full()[:, 0]
            z = z - self.forcing_weights() @ feature
        return z

    def _response_inputs(self, start, start_velocity, canonical0) -> np.ndarray:
        start = _vector("start", start, self.n_dofs, f"{self.n_dofs} DOFs")
        velocity = _vector("start_velocity", start_velocity, self.n_dofs, f"{self.n_dofs} DOFs")
        rows = [start, self._initial_z(velocity, canonical0)]
        if self.form == "acceleration":
            rows.append(start)  # r(0) = y(0), eq. (10)
        rows.append(self._goal_input())
        return np.vstack(rows + [self.forcing_weights().T])


@dataclass(frozen=True, eq=False)
class DiscreteDMP(_DmpCommon):
    r"""A point-to-point DMP with several DOFs on one canonical system (Sections 3.2, 3.6).

    Attributes
    ----------
    weights : ndarray, shape (n_dofs, n_basis)
        :math:`w_i` of eq. (7), per DOF.
    start, goal : ndarray, shape (n_dofs,)
        :math:`y_0` and :math:`g`.
    time_constant : float
        :math:`\tau` [s].
    centres, widths : ndarray, shape (n_basis,)
        :math:`c_i, h_i` of the Gaussians on the normalised phase.
    form : {"velocity", "acceleration"}
        Eqs. (5)-(7) (the default) or eq. (10) (continuous accelerations from rest, for
        inverse-dynamics control).
    goal_scaling : {"rotation", "paper", "translation"}
        How the forcing term follows a new start or goal (module docstring).
    reference_displacement : ndarray, shape (n_dofs,), optional
        Demonstrated ``goal - start``; needed by ``"rotation"``.
    scaled_start_velocity : ndarray, shape (n_dofs,)
        :math:`\tau \dot y(0)` of the demonstration (default 0: start at rest), stored like
        ``weights`` (per unit of ``goal - start`` under ``"paper"``). Plans start with
        :attr:`start_velocity`, this mapped to the current start and goal and divided by
        :math:`\tau`.
    stiffness, damping : float
        :math:`\alpha_z` and :math:`\beta_z` (default :math:`\alpha_z / 4`).
    phase_stiffness, phase_damping : float
        :math:`\alpha_v, \beta_v` of eq. (6).
    goal_rate : float
        :math:`\alpha_g` of eq. (10) (default :math:`\alpha_z / 2`).
    """

    weights: np.ndarray
    start: np.ndarray
    goal: np.ndarray
    time_constant: float
    centres: np.ndarray
    widths: np.ndarray
    form: str = "velocity"
    goal_scaling: str = "rotation"
    reference_displacement: np.ndarray | None = None
    scaled_start_velocity: np.ndarray | float = 0.0
    stiffness: float = 25.0
    damping: float | None = None
    phase_stiffness: float = 25.0
    phase_damping: float | None = None
    goal_rate: float | None = None
    kernel: str = dataclasses.field(default="gaussian", init=False)

    def __post_init__(self):
        if self.form not in symbolic.DISCRETE_FORMS:
            raise InvalidInputError(
                f"form must be one of {symbolic.DISCRETE_FORMS}, got {self.form!r}"
            )
        if self.goal_scaling not in GOAL_SCALINGS:
            raise InvalidInputError(
                f"goal_scaling must be one of {GOAL_SCALINGS}, got {self.goal_scaling!r}"
            )
        weights = np.atleast_2d(real_array("weights", self.weights, empty=True))
        if weights.ndim != 2:
            raise ShapeError(f"weights has shape {weights.shape}, expected (n_dofs, n_basis)")
        n_dofs, n_basis = weights.shape
        object.__setattr__(self, "weights", _frozen(weights))
        self._check_basis(n_basis)
        for name in ("start", "goal", "scaled_start_velocity"):
            value = _vector(name, getattr(self, name), n_dofs, f"weights {weights.shape}")
            object.__setattr__(self, name, _frozen(value))
        if self.goal_scaling == "rotation":
            if self.reference_displacement is None:
                raise InvalidInputError(
                    "goal_scaling='rotation' needs reference_displacement (the demonstrated "
                    "goal - start); pass it or use goal_scaling='translation'"
                )
            reference = _vector(
                "reference_displacement", self.reference_displacement, n_dofs, "weights"
            )
            if not np.linalg.norm(reference) > 0.0:
                raise InvalidInputError(
                    "reference_displacement is zero, so no rotation is defined; use "
                    "goal_scaling='translation' for movements that end where they start"
                )
            object.__setattr__(self, "reference_displacement", _frozen(reference))
        for name, default in (
            ("phase_damping", self.phase_stiffness / 4.0),
            ("goal_rate", self.stiffness / 2.0),
        ):
            if getattr(self, name) is None:
                object.__setattr__(self, name, default)
            object.__setattr__(self, name, _positive(name, getattr(self, name)))
        object.__setattr__(
            self, "phase_stiffness", _positive("phase_stiffness", self.phase_stiffness)
        )

    @property
    def gains(self) -> tuple:
        """Constants in the order of :data:`symbolic.GAIN_NAMES`."""
        values = (self.stiffness, self.damping, self.phase_stiffness, self.phase_damping)
        return values + ((self.goal_rate,) if self.form == "acceleration" else ())

    def _goal_input(self) -> np.ndarray:
        return np.asarray(self.goal)

    def _canonical_target(self) -> float:
        return 1.0

    def goal_map(self, start=None, goal=None) -> np.ndarray:
        """Matrix :math:`M` that maps the stored weights to the current (or given) start and
        goal (module docstring), shape (n_dofs, n_dofs)."""
        start = self.start if start is None else start
        goal = self.goal if goal is None else goal
        displacement = np.asarray(goal) - np.asarray(start)
        if self.goal_scaling == "paper":
            return np.diag(displacement)
        if self.goal_scaling == "rotation":
            return similarity_transform(self.reference_displacement, displacement)
        return np.eye(self.n_dofs)

    def forcing_weights(self, start=None, goal=None) -> np.ndarray:
        """Weights mapped to the current (or given) start and goal, shape (n_dofs, n_basis)."""
        return self.goal_map(start, goal) @ self.weights

    @property
    def start_velocity(self) -> np.ndarray:
        r"""Initial velocity [units/s] of plans by default: ``scaled_start_velocity`` mapped to
        the current start and goal, divided by :math:`\tau`, shape (n_dofs,)."""
        return self.goal_map() @ self.scaled_start_velocity / self.time_constant

    def with_goal(self, goal) -> DiscreteDMP:
        """Same movement towards a new goal."""
        return self.replace(goal=goal)

    def with_start(self, start) -> DiscreteDMP:
        """Same movement from a new start."""
        return self.replace(start=start)

    @property
    def convergence_time(self) -> float:
        """Time [s] at which the unforced system is 95 % of the way to its goal."""
        gains = self.gains[:4] + ((self.goal_rate,) if self.form == "acceleration" else ())
        return self.time_constant * basis.convergence_time(self.form, gains)

    @property
    def settling_time(self) -> float:
        """Default plan length [s]: :attr:`convergence_time` (the demonstration's duration
        for a fitted DMP), then the time the unforced system needs from rest to come within
        0.01 % of its goal (:data:`SETTLING_FRACTION`). The margin lets a movement still
        under way at the end of its demonstration come to rest: the README's quickstart demo
        ends at 3.7 units/s and its plan ends within 0.1 % of its extent from the goal."""
        gains = self.gains[:4] + ((self.goal_rate,) if self.form == "acceleration" else ())
        settle = basis.convergence_time(self.form, gains, SETTLING_FRACTION)
        return self.convergence_time + self.time_constant * settle

    def phase_features(self, n_steps: int, dt: float) -> np.ndarray:
        """Regressors of the forcing term, eq. (7), at ``k dt`` for ``k < n_steps``.

        The canonical system (6) is integrated from rest as in a rollout; the result does not
        depend on the weights, start or goal. Shape (n_steps, n_basis).
        """
        n_steps = validation.integer("n_steps", n_steps, minimum=1)
        dt = self.check_step(dt)
        check_resources(
            f"phase_features({n_steps}, {dt:.4g})",
            8.0 * n_steps * (2 * self.n_basis + 8),
            "ask for fewer samples",
            n_samples=n_steps,
        )
        signature = symbolic.Signature(self.form, 1, self.n_basis, self.kernel)
        unforced = self.replace(
            weights=np.zeros((1, self.n_basis)),
            start=[0.0],
            goal=[0.0],
            goal_scaling="translation",
            reference_displacement=None,
            scaled_start_velocity=0.0,
        )
        states = symbolic.simulate(
            signature, n_steps, np.zeros(signature.n_states), dt, unforced.parameter_values()
        )[0]
        features = symbolic.feature_function(signature).map(n_steps)
        return features(states[:, :2].T, self.centres, self.widths).full().T

    def rollout(self, duration: float | None = None, dt: float = 0.001, start_velocity=None):
        """The whole plan from ``start``.

        Parameters
        ----------
        duration : float, optional
            Length of the plan [s]; defaults to :attr:`settling_time`.
        dt : float
            Sample (and integration) step [s].
        start_velocity : array_like, shape (n_dofs,), optional
            Initial velocity [units/s]; defaults to :attr:`start_velocity` (the demonstrated
            one, mapped to the current start and goal, for a fitted DMP).

        Returns
        -------
        Trajectory
            Samples at ``0, dt, ..., duration``.
        """
        duration = self.settling_time if duration is None else duration
        velocity = self.start_velocity if start_velocity is None else start_velocity
        return self._rollout(duration, dt, self.start, velocity, (0.0, 0.0))

    def affine_plan(self, duration=None, dt: float = 0.001, start_velocity=None) -> AffinePlan:
        """The plan as an affine function of the forcing weights (see :class:`AffinePlan`).

        ``self.rollout(...)`` equals ``self.affine_plan(...).trajectory(self.forcing_weights())``;
        the arguments and their defaults are those of :meth:`rollout`.
        """
        duration = self.settling_time if duration is None else duration
        velocity = self.start_velocity if start_velocity is None else start_velocity
        return self._affine(duration, dt, self.start, velocity, (0.0, 0.0))

    def stepper(self, dt: float = 0.001, start_velocity=None, compile: bool = False):
        """An online integrator for control loops (see :class:`dmpopt.stepper.Stepper`),
        starting with ``start_velocity`` (default :attr:`start_velocity`)."""
        from .stepper import Stepper

        velocity = self.start_velocity if start_velocity is None else start_velocity
        return Stepper(self, dt, self.start, velocity, compile=compile)


@dataclass(frozen=True, eq=False)
class RhythmicDMP(_DmpCommon):
    r"""A periodic DMP with several DOFs on one oscillator (Sections 3.2, 3.6).

    Attributes
    ----------
    weights : ndarray, shape (n_dofs, n_basis, 2)
        The 2-vectors :math:`w_i` of eqs. (12) and (14), per DOF.
    setpoint : ndarray, shape (n_dofs,)
        :math:`g`, the centre of the oscillation.
    time_constant : float
        :math:`\tau`: the period is :math:`2\pi\tau` (``phase``) or :math:`2\pi\tau/k`
        (``energy``).
    centres, widths : ndarray, shape (n_basis,)
        Basis on the oscillator's phase angle.
    form : {"phase", "energy"}
        Phase oscillator eqs. (11)-(12) or energy limit cycle eqs. (13)-(14).
    amplitude : float
        :math:`A` of eq. (11), or the amplitude of :math:`x` on the limit cycle of eq. (13)
        (:math:`E_0 = (k A)^2 / 2`). The plan's oscillation scales with it.
    kernel : {"von_mises", "paper"}
        Periodic kernel :math:`\exp(h(\cos(\phi - c) - 1))` or eq. (12) as printed.
    stiffness, damping : float
        :math:`\alpha_z, \beta_z` of eq. (5).
    amplitude_rate : float
        :math:`\alpha_r` of eq. (11) (``phase``) or :math:`\alpha_E` of eq. (13) (``energy``).
    frequency : float
        :math:`k` of eq. (13) (``energy`` only).
    """

    weights: np.ndarray
    setpoint: np.ndarray
    time_constant: float
    centres: np.ndarray
    widths: np.ndarray
    form: str = "phase"
    amplitude: float = 1.0
    kernel: str = "von_mises"
    stiffness: float = 25.0
    damping: float | None = None
    amplitude_rate: float = 10.0
    frequency: float = 1.0

    def __post_init__(self):
        if self.form not in symbolic.RHYTHMIC_FORMS:
            raise InvalidInputError(
                f"form must be one of {symbolic.RHYTHMIC_FORMS}, got {self.form!r}"
            )
        if self.kernel not in ("von_mises", "paper"):
            raise InvalidInputError(f"kernel must be 'von_mises' or 'paper', got {self.kernel!r}")
        weights = real_array("weights", self.weights, empty=True)
        if weights.ndim == 2 and weights.shape[1] % 2 == 0:
            weights = weights.reshape(weights.shape[0], -1, 2)
        if weights.ndim != 3 or weights.shape[2] != 2:
            raise ShapeError(f"weights has shape {weights.shape}, expected (n_dofs, n_basis, 2)")
        object.__setattr__(self, "weights", _frozen(weights))
        self._check_basis(weights.shape[1])
        setpoint = _vector("setpoint", self.setpoint, weights.shape[0], f"weights {weights.shape}")
        object.__setattr__(self, "setpoint", _frozen(setpoint))
        for name in ("amplitude", "amplitude_rate", "frequency"):
            object.__setattr__(self, name, _positive(name, getattr(self, name)))

    @property
    def gains(self) -> tuple:
        """Constants in the order of :data:`symbolic.GAIN_NAMES`."""
        if self.form == "phase":
            return (self.stiffness, self.damping, self.amplitude_rate)
        return (self.stiffness, self.damping, self.amplitude_rate, self.frequency)

    @property
    def period(self) -> float:
        """Period of the oscillator [s]."""
        scale = 1.0 if self.form == "phase" else 1.0 / self.frequency
        return 2 * np.pi * self.time_constant * scale

    def _goal_input(self) -> np.ndarray:
        return np.asarray(self.setpoint)

    def _canonical_target(self) -> float:
        if self.form == "phase":
            return self.amplitude
        return 0.5 * (self.frequency * self.amplitude) ** 2

    def canonical_state(self, phase: float = 0.0) -> tuple[float, float]:
        """The oscillator's state on its limit cycle at ``phase`` [rad]."""
        phase = real("phase", phase)
        if self.form == "phase":
            return (phase, self.amplitude)
        # x = A cos(theta), v = A k sin(theta) gives atan2(v, x) = theta for k = 1
        return (
            self.amplitude * float(np.cos(phase)),
            self.amplitude * self.frequency * float(np.sin(phase)),
        )

    def forcing_weights(self) -> np.ndarray:
        """Weights flattened to (n_dofs, 2 n_basis), the layout of the features."""
        return np.asarray(self.weights).reshape(self.n_dofs, -1)

    def with_setpoint(self, setpoint) -> RhythmicDMP:
        """Same oscillation around a new setpoint."""
        return self.replace(setpoint=setpoint)

    def with_amplitude(self, amplitude: float) -> RhythmicDMP:
        """Same oscillation, scaled in space about the setpoint (Section 3.3)."""
        return self.replace(amplitude=amplitude)

    def rollout(self, duration=None, dt=0.001, start=None, start_velocity=0.0, phase=0.0):
        """The plan from ``start`` (default: the setpoint) with the oscillator at ``phase``.

        ``duration`` defaults to three periods. Returns a :class:`Trajectory`.
        """
        duration = 3 * self.period if duration is None else duration
        start = self.setpoint if start is None else start
        return self._rollout(duration, dt, start, start_velocity, self.canonical_state(phase))

    def affine_plan(self, duration=None, dt=0.001, start=None, start_velocity=0.0, phase=0.0):
        """The plan as an affine function of the flattened weights (see :class:`AffinePlan`)."""
        duration = 3 * self.period if duration is None else duration
        start = self.setpoint if start is None else start
        return self._affine(duration, dt, start, start_velocity, self.canonical_state(phase))

    def stepper(self, dt=0.001, start=None, start_velocity=0.0, phase=0.0, compile=False):
        """An online integrator for control loops (see :class:`dmpopt.stepper.Stepper`)."""
        from .stepper import Stepper

        start = self.setpoint if start is None else start
        return Stepper(self, dt, start, start_velocity, phase, compile)
