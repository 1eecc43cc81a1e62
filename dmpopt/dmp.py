r"""Discrete and rhythmic DMPs: immutable parameters and whole-plan rollouts.

A DMP is a frozen value. ``with_goal``, ``with_tau``, ... return new objects.
Rollouts use the affine structure of the plan: for a fixed time constant, step and
canonical trajectory, positions, velocities and accelerations are linear in the initial
transformation state, the goal and the weights. The response matrices are evaluated once
from the symbolic system (:mod:`dmpopt.symbolic`: the RK4 step's matrices and the features at
its stages) and cached, so a rollout of any number of DOFs is one matrix product.

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
import functools
import math
import warnings
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from . import basis, forms, symbolic, validation
from .exceptions import InvalidInputError, ShapeError
from .response import ResponseMatrices, response_matrices
from .stepper import Stepper
from .trajectory import Trajectory
from .validation import check_resources, flag, positive, real, real_array, vector

GOAL_SCALINGS = ("paper", "rotation", "translation")
#: A rhythmic stepper whose first acceleration exceeds this multiple of its limit cycle's largest
#: warns (:meth:`RhythmicDMP.stepper`).
FAR_ACCELERATION = 10.0
RENAMED = {
    "time_constant": "tau",
    "stiffness": "alpha_z",
    "damping": "beta_z",
    "phase_stiffness": "alpha_v",
    "phase_damping": "beta_v",
    "goal_rate": "alpha_g",
    "amplitude_rate": "alpha_r",
    "frequency": "k",
}
"""Former field names and the paper's symbols that replaced them (docs/glossary.md); in the
energy form ``amplitude_rate`` became ``alpha_E``."""
MAX_PHASE_SLOWDOWN = 50.0
"""Largest accepted ratio of the transformation system's slowest rate to the canonical
system's (eq. (6)): at the bound, with the default gains (``alpha_v = 0.5``), a fitted DMP's
default plan lasts about 170 times its demonstration."""
SETTLING_FRACTION = 0.9999
"""Fraction of the way to rest that the canonical and transformation systems together cover,
counted as modes all as slow as the slowest, in the time a default plan lasts beyond the
convergence time (:attr:`DiscreteDMP.settling_time`)."""


PLACEMENT_FIELDS = frozenset(
    ("start", "goal", "setpoint", "goal_scaling", "reference_displacement", "scaled_start_velocity")
)
"""Fields that say where a movement goes, not how it unfolds in time: the response matrices,
step limit and start features do not depend on them (:meth:`DiscreteDMP.replace`)."""


def _frozen(array: np.ndarray) -> np.ndarray:
    """A read-only C-ordered float copy. C order always, whatever the layout given (e.g.
    fitted weights as a transposed view): a product with the array (``forcing_weights() @
    features``) rounds differently in another layout, and pickling (the trip to a worker of
    :func:`dmpopt.parallel.map_runs`) turns a non-contiguous view into a C-ordered array, so
    the same values would otherwise give other bits in a worker than in this process."""
    array = np.array(array, dtype=float, order="C")
    array.setflags(write=False)
    return array


def _refuse_former_names(cls):
    """Make the constructor (and ``replace``) name the new field for a former one."""
    init = cls.__init__

    @functools.wraps(init)
    def __init__(self, *args, **fields):
        former = sorted(set(fields) & set(RENAMED))
        if former:
            name = former[0]
            new = "alpha_E" if name == "amplitude_rate" and fields.get("form") == "energy" else ""
            new = new or RENAMED[name]
            raise InvalidInputError(
                f"{cls.__name__} has no field {name!r}: it is now {new!r}, after the paper's "
                f"symbol (docs/glossary.md); pass {new}={fields[name]!r}"
            )
        init(self, *args, **fields)

    cls.__init__ = __init__
    return cls


def _memo(instance, key, compute):
    """A value derived from the fields of a frozen DMP, computed once per instance: a rollout
    would otherwise redo the goal map, feature and step-limit evaluations each time
    (``dataclasses.replace`` makes a new instance, with an empty memo)."""
    memo = instance.__dict__.setdefault("_memo", {})
    if key not in memo:
        memo[key] = compute()
    return memo[key]


def goal_transform(goal_scaling: str, reference, displacement) -> np.ndarray:
    r"""Matrix :math:`M` that carries a plan demonstrated for the start-goal vector
    ``reference`` to one for ``displacement`` (module docstring), shape (n_dofs, n_dofs).

    ``"paper"``: :math:`\mathrm{diag}(d' / d)`, eq. (7) per DOF; ``"rotation"``:
    :func:`similarity_transform`; ``"translation"``: the identity.
    """
    reference, displacement = np.asarray(reference), np.asarray(displacement)
    if goal_scaling == "paper":
        return np.diag(displacement / reference)
    if goal_scaling == "rotation":
        return similarity_transform(reference, displacement)
    if goal_scaling == "translation":
        return np.eye(displacement.size)
    raise InvalidInputError(f"goal_scaling must be one of {GOAL_SCALINGS}, got {goal_scaling!r}")


def similarity_transform(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Rotation times uniform scaling that maps vector ``source`` onto ``target``.

    The rotation is the smallest one: it turns the plane spanned by the two vectors and
    leaves its orthogonal complement alone. In one dimension it is a sign.
    """
    # scalar arithmetic (called on every rollout); hypot does not overflow for large goals
    source_norm, target_norm = math.hypot(*source), math.hypot(*target)
    n = source.size
    if target_norm == 0.0:
        return np.zeros((n, n))
    a, b = source / source_norm, target / target_norm
    cosine = min(max(float(a @ b), -1.0), 1.0)
    if n == 1:
        rotation = np.array([[np.sign(cosine)]])
    elif cosine > -1.0 + 1e-12:
        cross = b[:, None] * a - a[:, None] * b
        rotation = np.eye(n) + cross + cross @ cross / (1.0 + cosine)
    else:  # half turn in a plane that contains a
        helper = np.eye(n)[np.argmin(np.abs(a))]
        u = helper - (helper @ a) * a
        u /= np.linalg.norm(u)
        rotation = np.eye(n) - 2 * np.outer(a, a) - 2 * np.outer(u, u)
    return target_norm / source_norm * rotation


@lru_cache(maxsize=16)  # an entry holds 3 x n_steps x (n_features + 3) floats
def _response(key: tuple, factored: bool = True) -> ResponseMatrices:
    """Response matrices of one DOF, in time normalised by ``tau``, read-only.

    Position, velocity and acceleration responses to each input (initial transformation
    states, goal, weights), computed in one compiled pass
    (:func:`dmpopt.response.response_matrices`; ``factored``: kept segment by segment, the
    columns a segment does not force as a factor of their states at its start, as for
    rollouts; else dense, as for :class:`AffinePlan`, whose weight response is dense anyway).
    The first rollout of the LASA demo's plan (10676 steps, 53 inputs; 3.9 MB in all) took
    8.9-15.9 ms of thread time on this 2-core machine at load 1.8-2.2, median 11.5 (where it
    goes: the module docstring of :mod:`dmpopt.response`; 27 ms with the whole plan dense,
    13.6 MB, at load 3-4), a repeated one 0.4-0.5 ms (2.6 ms dense);
    evaluating the features at all stages on arrays and the recurrence in numpy blocks took
    110-170 ms at load 12-14 (benchmarks/bench_core.py).
    """
    matrices = response_matrices(key, factored)
    matrices.freeze()
    return matrices


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
        centres = vector("centres", self.centres, n_basis, f"{n_basis} basis functions")
        widths = vector("widths", self.widths, n_basis, f"{n_basis} basis functions")
        if np.any(widths <= 0):
            raise InvalidInputError(f"widths must all be positive, got {widths.min()!r}")
        object.__setattr__(self, "centres", _frozen(centres))
        object.__setattr__(self, "widths", _frozen(widths))
        object.__setattr__(self, "tau", positive("tau", self.tau))
        object.__setattr__(self, "alpha_z", positive("alpha_z", self.alpha_z))
        if self.beta_z is None:
            object.__setattr__(self, "beta_z", self.alpha_z / 4.0)
        object.__setattr__(self, "beta_z", positive("beta_z", self.beta_z))

    @property
    def n_dofs(self) -> int:
        """Number of DOFs sharing the canonical system."""
        return self.weights.shape[0]

    @property
    def n_basis(self) -> int:
        """Number of basis functions per DOF."""
        return self.weights.shape[1]

    @property
    def equations(self) -> forms.Form:
        """The form's object: its equations, state layout and constants (:mod:`dmpopt.forms`)."""
        return forms.FORMS[self.form]

    @property
    def gains(self) -> tuple:
        """The form's constants, in the order of its ``gain_names`` (:mod:`dmpopt.forms`)."""
        return tuple(getattr(self, name) for name in self.equations.gain_names)

    @property
    def signature(self) -> symbolic.Signature:
        """Sizes and choices of the compiled system."""
        return symbolic.Signature(self.form, self.n_dofs, self.n_basis, self.kernel)

    def replace(self, **changes):
        """Return a copy with some fields changed (validated again).

        A copy that differs only in where the movement goes (:data:`PLACEMENT_FIELDS`) keeps
        what was derived from the other fields: the step limit, the last plan's response
        matrices and the features at its start (a loop over goals then costs one product
        per rollout)."""
        copy = dataclasses.replace(self, **changes)
        if set(changes) <= PLACEMENT_FIELDS:
            memo = self.__dict__.get("_memo", {})
            kept = {key: memo[key] for key in ("max_step", "response_key") if key in memo}
            copy.__dict__["_memo"] = kept
            for name in ("_last_plan", "_last_features"):
                if name in self.__dict__:
                    copy.__dict__[name] = self.__dict__[name]
        return copy

    @property
    def max_step(self) -> float:
        """Largest step [s] at which the RK4 integration is stable (:func:`basis.stable_step`)."""
        return _memo(
            self,
            "max_step",
            lambda: (
                self.tau
                * basis.stable_step(
                    self.form,
                    tuple(self.gains),
                    float(self._canonical_target()),
                    self._cycle_states(),
                )
            ),
        )

    def _cycle_states(self) -> tuple:
        """Canonical states at which the system is linearised for its stability limit."""
        if not self.equations.discrete:
            angles = np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
            return tuple(self.canonical_state(angle) for angle in angles)
        return ((0.0, 0.0),)

    def check_step(self, dt, name: str = "dt") -> float:
        """Return ``dt`` if it is a positive step within :attr:`max_step`, else raise."""
        dt = positive(name, dt)
        if dt > self.max_step:
            raise InvalidInputError(
                f"{name} = {dt:.4g} s is beyond the stability limit {self.max_step:.4g} s of the "
                f"RK4 integration for tau = {self.tau:.4g} s and these gains "
                "(the plan would grow without bound); use a smaller step"
            )
        return dt

    def with_tau(self, tau: float):
        """Same movement, time scaled by ``tau`` (Section 3.3)."""
        return self.replace(tau=tau)

    def parameters(self) -> dict:
        """Numeric inputs of the symbolic functions by name (:data:`symbolic.PARAMETER_NAMES`)."""
        return symbolic.parameters(
            tau=self.tau,
            goal=self._goal_input(),
            canonical_target=self._canonical_target(),
            forcing_weights=self.forcing_weights(),
            centres=np.asarray(self.centres),
            widths=np.asarray(self.widths),
            gains=np.asarray(self.gains),
        )

    def _response_and_inputs(self, duration, dt, start, start_velocity, canonical0, factored):
        """Sample times, the response matrices (:func:`_response`, ``factored`` or not) and
        their inputs.

        A DMP is a frozen value, so the last plan's times and response are kept with it (a
        repeated rollout then skips the checks that the same floats already passed, and the
        cache key of 2 n_basis floats), and so are the inputs of its default start.
        """
        canonical0 = tuple(canonical0)
        key = (duration, dt, canonical0, factored)
        last = self.__dict__.get("_last_plan")
        if (
            last is None
            or last[0] != key
            or type(duration) is not float
            or type(dt) is not float
            or not last[3] <= validation.MEMORY_BUDGET  # the bounds may have been lowered since
            or last[1].size > validation.MAX_SAMPLES
        ):
            last = (key, *self._plan_matrices(duration, dt, canonical0, factored))
            self.__dict__["_last_plan"] = last
        _, times, response, _ = last
        if start is None and start_velocity is None:  # the default start, kept with the DMP
            inputs = _memo(
                self,
                ("inputs", canonical0),
                lambda: _frozen(
                    self._response_inputs(self.start, self.start_velocity, canonical0, True)
                ),
            )
        else:
            start = self.start if start is None else start
            start_velocity = self.start_velocity if start_velocity is None else start_velocity
            inputs = self._response_inputs(start, start_velocity, canonical0)
        return times, response, inputs

    def _plan_matrices(self, duration, dt, canonical0, factored):
        """Checked sample times, the response matrices of one DOF for them, and the bytes a
        plan of them takes (checked against the budget)."""
        duration = positive("duration", duration)
        dt = self.check_step(dt)
        n_steps = int(round(duration / dt)) + 1
        if n_steps < 3:
            raise InvalidInputError(
                f"duration {duration} is shorter than two steps of dt = {dt}; lower dt"
            )
        n_inputs = symbolic.n_transformation_states(self.form) + 1 + self.signature.n_features
        # counted as 6 floats per input and sample, though the compiled pass that computes
        # the response (dmpopt.response) holds only the response (3) and work arrays of a
        # few inputs; the plan takes 6 per DOF (positions, velocities, accelerations and the
        # product they come from)
        n_bytes = 8.0 * n_steps * (6 * n_inputs + 6 * self.n_dofs)
        check_resources(
            f"a plan of {duration:.4g} s at dt = {dt:.4g} s",
            n_bytes,
            "raise dt or shorten duration (by default the convergence time or three periods, "
            "both proportional to tau)",
            n_samples=n_steps,
        )
        form, kernel, n_basis, target, centres, widths, gains = _memo(
            self,
            "response_key",
            lambda: (
                self.form,
                self.kernel,
                self.n_basis,
                float(self._canonical_target()),
                tuple(self.centres),
                tuple(self.widths),
                tuple(self.gains),
            ),
        )
        key = (
            form, kernel, n_basis, n_steps, dt / self.tau, target, canonical0, centres,
            widths, gains,
        )  # fmt: skip
        times = _frozen(np.arange(n_steps) * dt)
        # the cache keeps 16 entries: keep out those that would hold over 1/16 of the budget
        small = 24.0 * n_steps * n_inputs <= validation.MEMORY_BUDGET / 16
        response = _response(key, factored) if small else _response.__wrapped__(key, factored)
        return times, response, n_bytes

    def _affine(self, duration, dt, start, start_velocity, canonical0) -> AffinePlan:
        times, response, inputs = self._response_and_inputs(
            duration, dt, start, start_velocity, canonical0, False
        )
        response = response.dense()
        scale = np.array([1.0, self.tau, self.tau**2])[:, None, None]
        n_free = inputs.shape[0] - symbolic.n_features(self.form, self.n_basis)
        free_inputs, weight_response = inputs[:n_free], response[:, :, n_free:]
        if self.equations.forcing_on_velocity:
            # z(0) = tau yd(0) - f(0) (initial_state) is affine in the weights too: the
            # response to W includes that of z(0) to -W feature(0), the free part keeps tau yd(0)
            feature = self._features(canonical0)
            free_inputs = free_inputs.copy()
            free_inputs[1] += self.forcing_weights() @ feature
            weight_response = weight_response - response[:, :, 1:2] * feature
        return AffinePlan(
            times=times,
            free=response[:, :, :n_free] @ free_inputs / scale,
            weight_response=weight_response / scale,
        )

    def _rollout(self, duration, dt, start, start_velocity, canonical0) -> Trajectory:
        times, response, inputs = self._response_and_inputs(
            duration, dt, start, start_velocity, canonical0, True
        )
        plan = response.product(inputs)  # (3, n_steps, n_dofs)
        plan[1] /= self.tau
        plan[2] /= self.tau**2
        return Trajectory.trusted(times, plan[0], plan[1], plan[2])

    def initial_state(self, start, start_velocity, canonical0) -> np.ndarray:
        """The state vector that starts at ``start`` with ``start_velocity`` and the canonical
        state ``canonical0``: ``y = start``, ``z`` such that ``tau yd = z + f`` (eq. (5); ``z =
        tau yd`` in eq. (10)) and ``r = start`` (eq. (10)). Shape (n_states,)."""
        start = vector("start", start, self.n_dofs, f"{self.n_dofs} DOFs")
        velocity = vector("start_velocity", start_velocity, self.n_dofs, f"{self.n_dofs} DOFs")
        return np.concatenate([canonical0, *self._transformation0(start, velocity, canonical0)])

    def _transformation0(self, start, velocity, canonical0, forcing_weights=None) -> list:
        """The initial transformation states of checked ``start`` and ``velocity``
        (:meth:`initial_state`), one row per state of the form."""
        forcing_weights = self.forcing_weights() if forcing_weights is None else forcing_weights
        forcing = forcing_weights @ self._features(canonical0)
        return self.equations.initial_transformation(start, self.tau * velocity, forcing)

    def _features(self, canonical) -> np.ndarray:
        """The forcing term's features (eq. (7), (12) or (14)) at one canonical state."""
        canonical = tuple(float(value) for value in canonical)
        last = self.__dict__.get("_last_features")  # rollouts repeat one canonical start
        if last is None or last[0] != canonical:
            function = symbolic.feature_function(self.signature)
            centres, widths = np.asarray(self.centres), np.asarray(self.widths)
            last = canonical, _frozen(function(canonical, centres, widths).full()[:, 0])
            self.__dict__["_last_features"] = last
        return last[1]

    def _response_inputs(self, start, start_velocity, canonical0, checked=False) -> np.ndarray:
        """The inputs the response matrices multiply: initial transformation states, goal,
        forcing weights, shape (n_inputs, n_dofs). ``checked``: ``start`` and
        ``start_velocity`` are the DMP's own (validated) arrays."""
        if not checked:
            start = vector("start", start, self.n_dofs, f"{self.n_dofs} DOFs")
            n = self.n_dofs
            start_velocity = vector("start_velocity", start_velocity, n, f"{n} DOFs")
        weights = self.forcing_weights()
        rows = self._transformation0(start, start_velocity, canonical0, weights)
        return np.vstack([*rows, self._goal_input(), weights.T])


@_refuse_former_names
@dataclass(frozen=True, eq=False)
class DiscreteDMP(_DmpCommon):
    r"""A point-to-point DMP with several DOFs on one canonical system (Sections 3.2, 3.6).

    Attributes
    ----------
    weights : ndarray, shape (n_dofs, n_basis)
        :math:`w_i` of eq. (7), per DOF.
    start, goal : ndarray, shape (n_dofs,)
        :math:`y_0` and :math:`g`.
    tau : float
        :math:`\tau` [s], the time constant.
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
    alpha_z, beta_z : float
        :math:`\alpha_z, \beta_z` of eqs. (5) and (10) (default :math:`\beta_z = \alpha_z / 4`).
    alpha_v, beta_v : float
        :math:`\alpha_v, \beta_v` of eq. (6) (default :math:`\beta_v = \alpha_v / 4`); the
        canonical system may be at most :data:`MAX_PHASE_SLOWDOWN` times slower than the
        transformation system (``alpha_v >= alpha_z / 50`` with the default damping).
    alpha_g : float
        :math:`\alpha_g` of eq. (10) (default :math:`\alpha_z / 2`).
    """

    weights: np.ndarray
    start: np.ndarray
    goal: np.ndarray
    tau: float
    centres: np.ndarray
    widths: np.ndarray
    form: str = "velocity"
    goal_scaling: str = "rotation"
    reference_displacement: np.ndarray | None = None
    scaled_start_velocity: np.ndarray | float = 0.0
    alpha_z: float = 25.0
    beta_z: float | None = None
    alpha_v: float = 25.0
    beta_v: float | None = None
    alpha_g: float | None = None
    kernel: str = dataclasses.field(default="gaussian", init=False)

    def __post_init__(self):
        forms.get(self.form, "discrete")
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
            value = vector(name, getattr(self, name), n_dofs, f"weights {weights.shape}")
            object.__setattr__(self, name, _frozen(value))
        if self.goal_scaling == "rotation":
            if self.reference_displacement is None:
                raise InvalidInputError(
                    "goal_scaling='rotation' needs reference_displacement (the demonstrated "
                    "goal - start); pass it or use goal_scaling='translation'"
                )
            reference = vector(
                "reference_displacement", self.reference_displacement, n_dofs, "weights"
            )
            if not np.linalg.norm(reference) > 0.0:
                raise InvalidInputError(
                    "reference_displacement is zero, so no rotation is defined; use "
                    "goal_scaling='translation' for movements that end where they start"
                )
            object.__setattr__(self, "reference_displacement", _frozen(reference))
        for name, default in (
            ("beta_v", self.alpha_v / 4.0),
            ("alpha_g", self.alpha_z / 2.0),
        ):
            if getattr(self, name) is None:
                object.__setattr__(self, name, default)
            object.__setattr__(self, name, positive(name, getattr(self, name)))
        object.__setattr__(self, "alpha_v", positive("alpha_v", self.alpha_v))
        self._check_phase_rate()

    def _check_phase_rate(self):
        """Refuse a canonical system over :data:`MAX_PHASE_SLOWDOWN` times slower than the
        transformation system (their slowest rates, :func:`basis.discrete_eigenvalues`)."""
        canonical, transformation = basis.discrete_eigenvalues(self.form, self.gains)
        phase_rate, rate = np.min(-canonical.real), np.min(-transformation.real)
        if phase_rate * MAX_PHASE_SLOWDOWN < rate * (1.0 - 1e-12):
            raise InvalidInputError(
                f"alpha_v = {self.alpha_v:.4g}, beta_v = {self.beta_v:.4g} make the canonical "
                f"system (6) {rate / phase_rate:.4g} times slower than the transformation system "
                f"(slowest rates {phase_rate:.4g} and {rate:.4g} per tau); at most "
                f"{MAX_PHASE_SLOWDOWN:g} times is accepted, as the forcing term would outlast the "
                "movement and the default plan (settling_time) last hundreds of its durations: "
                f"pass alpha_v >= {2 * rate / MAX_PHASE_SLOWDOWN:.4g} (with beta_v = alpha_v / 4)"
            )

    def _goal_input(self) -> np.ndarray:
        return np.asarray(self.goal)

    def _canonical_target(self) -> float:
        return 1.0

    def goal_map(self, start=None, goal=None) -> np.ndarray:
        """Matrix :math:`M` that maps the stored weights to the current (or given) start and
        goal (module docstring), shape (n_dofs, n_dofs)."""
        if start is None and goal is None:
            return _memo(self, "goal_map", lambda: _frozen(self.goal_map(self.start, self.goal)))
        start = self.start if start is None else start
        goal = self.goal if goal is None else goal
        displacement = np.asarray(goal) - np.asarray(start)
        # "paper" stores the weights per unit of goal - start: the reference is all ones
        rotation = self.goal_scaling == "rotation"
        reference = self.reference_displacement if rotation else np.ones(self.n_dofs)
        return goal_transform(self.goal_scaling, reference, displacement)

    def forcing_weights(self, start=None, goal=None) -> np.ndarray:
        """Weights mapped to the current (or given) start and goal, shape (n_dofs, n_basis)."""
        return self.goal_map(start, goal) @ self.weights

    @property
    def start_velocity(self) -> np.ndarray:
        r"""Initial velocity [units/s] of plans by default: ``scaled_start_velocity`` mapped to
        the current start and goal, divided by :math:`\tau`, shape (n_dofs,)."""
        return self.goal_map() @ self.scaled_start_velocity / self.tau

    def with_goal(self, goal) -> DiscreteDMP:
        """Same movement towards a new goal."""
        return self.replace(goal=goal)

    def with_start(self, start) -> DiscreteDMP:
        """Same movement from a new start."""
        return self.replace(start=start)

    @property
    def convergence_time(self) -> float:
        """Time [s] at which the unforced system is 95 % of the way to its goal."""
        return self.tau * basis.convergence_time(self.form, self.gains)

    @property
    def settling_time(self) -> float:
        """Default plan length [s]: :attr:`convergence_time` (the demonstration's duration
        for a fitted DMP), then the time the canonical and transformation systems together
        need to come 99.99 % of the way to rest (:data:`SETTLING_FRACTION`,
        :func:`basis.settling_time`), from their eigenvalues, so it grows as ``alpha_v``
        slows the phase. The margin lets a movement still under way at the end of its
        demonstration come to rest: the README's quickstart demo ends at 3.7 units/s and its
        plan ends 0.0024 % of its extent from the goal (below 0.01 % for demos ending
        moving, at ``alpha_v`` from 1 to 25, in tests/core/test_dmp.py)."""
        settle = basis.settling_time(self.form, tuple(self.gains), SETTLING_FRACTION)
        return self.convergence_time + self.tau * settle

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
        gains, rest = np.array(self.gains), (0.0, 0.0)
        samples = symbolic.canonical_trajectory(
            signature, n_steps, dt / self.tau, rest, 1.0, gains, with_stages=False
        )[0]
        function = symbolic.array_function(symbolic.feature_function(signature))
        return function(samples, self.centres, self.widths, n_points=n_steps)[0]

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
        return self._rollout(duration, dt, None, start_velocity, (0.0, 0.0))

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
        velocity = self.start_velocity if start_velocity is None else start_velocity
        return Stepper(self, dt, self.start, velocity, compile=compile)


@_refuse_former_names
@dataclass(frozen=True, eq=False)
class RhythmicDMP(_DmpCommon):
    r"""A periodic DMP with several DOFs on one oscillator (Sections 3.2, 3.6).

    Attributes
    ----------
    weights : ndarray, shape (n_dofs, n_basis, 2)
        The 2-vectors :math:`w_i` of eqs. (12) and (14), per DOF.
    setpoint : ndarray, shape (n_dofs,)
        :math:`g`, the centre of the oscillation.
    tau : float
        :math:`\tau`, the time constant: the period is :math:`2\pi\tau` (``phase``) or
        :math:`2\pi\tau/k` (``energy``).
    centres, widths : ndarray, shape (n_basis,)
        Basis on the oscillator's phase angle.
    form : {"phase", "energy"}
        Phase oscillator eqs. (11)-(12) or energy limit cycle eqs. (13)-(14).
    amplitude : float
        :math:`A` of eq. (11), or the amplitude of :math:`x` on the limit cycle of eq. (13)
        (:math:`E_0 = (k A)^2 / 2`). The plan's oscillation scales with it.
    kernel : {"von_mises", "paper"}
        Periodic kernel :math:`\exp(h(\cos(\phi - c) - 1))` or eq. (12) as printed.
    alpha_z, beta_z : float
        :math:`\alpha_z, \beta_z` of eq. (5) (default :math:`\beta_z = \alpha_z / 4`).
    alpha_r : float
        :math:`\alpha_r` of eq. (11) (``phase`` only).
    alpha_E : float
        :math:`\alpha_E` of eq. (13) (``energy`` only).
    k : float
        :math:`k` of eq. (13) (``energy`` only): a dimensionless factor; the oscillator
        turns at :math:`k / \tau` rad/s (docs/glossary.md, "Frequencies and rates").
    """

    weights: np.ndarray
    setpoint: np.ndarray
    tau: float
    centres: np.ndarray
    widths: np.ndarray
    form: str = "phase"
    amplitude: float = 1.0
    kernel: str = "von_mises"
    alpha_z: float = 25.0
    beta_z: float | None = None
    alpha_r: float = 10.0
    alpha_E: float = 10.0  # noqa: N815 (the paper's symbol)
    k: float = 1.0

    def __post_init__(self):
        forms.get(self.form, "rhythmic")
        if self.kernel not in ("von_mises", "paper"):
            raise InvalidInputError(f"kernel must be 'von_mises' or 'paper', got {self.kernel!r}")
        weights = real_array("weights", self.weights, empty=True)
        if weights.ndim == 2 and weights.shape[1] % 2 == 0:
            weights = weights.reshape(weights.shape[0], -1, 2)
        if weights.ndim != 3 or weights.shape[2] != 2:
            raise ShapeError(f"weights has shape {weights.shape}, expected (n_dofs, n_basis, 2)")
        object.__setattr__(self, "weights", _frozen(weights))
        self._check_basis(weights.shape[1])
        setpoint = vector("setpoint", self.setpoint, weights.shape[0], f"weights {weights.shape}")
        object.__setattr__(self, "setpoint", _frozen(setpoint))
        for name in ("amplitude", "alpha_r", "alpha_E", "k"):
            object.__setattr__(self, name, positive(name, getattr(self, name)))
        smallest = min(1.0, self.k) * self.amplitude  # of |x| and |v| on the limit cycle
        if self.form == "energy" and smallest**2 < np.finfo(float).tiny:
            raise InvalidInputError(
                f"amplitude = {self.amplitude:.3g} is too small for the energy form: the squared "
                "size of its oscillator's state underflows, and its phase (atan2(v, x)) and "
                f"energy are lost; use amplitude >= {1.5e-154 / min(1.0, self.k):.2g}"
            )

    @property
    def period(self) -> float:
        """Period of the oscillator [s]."""
        return self.tau * self.equations.period(self.gains)

    def _goal_input(self) -> np.ndarray:
        return np.asarray(self.setpoint)

    def _canonical_target(self) -> float:
        return self.equations.canonical_target(self.amplitude, self.gains)

    def canonical_state(self, phase: float = 0.0) -> tuple[float, float]:
        """The oscillator's state on its limit cycle at ``phase`` [rad]."""
        return self.equations.canonical_state(real("phase", phase), self.amplitude, self.gains)

    def forcing_weights(self) -> np.ndarray:
        """Weights flattened to (n_dofs, 2 n_basis), the layout of the features."""
        return np.asarray(self.weights).reshape(self.n_dofs, -1)

    def replace(self, **changes) -> RhythmicDMP:
        """As :meth:`DiscreteDMP.replace`; a phase-form copy that also differs in ``amplitude``
        keeps the step limit: ``A`` enters eq. (11) only as ``tau r' = alpha_r (A - r)``, so
        the Jacobian, and the limit, do not depend on it (the energy form's ``E_0`` of eq.
        (13) multiplies ``v``: there it does). A stepper's amplitude change each tick (a
        filtered change, :meth:`Stepper.set_amplitude`) then costs no new limit."""
        copy = super().replace(**changes)
        memo = self.__dict__.get("_memo", {})
        if self.form == "phase" and set(changes) <= PLACEMENT_FIELDS | {"amplitude"}:
            if "max_step" in memo:
                copy.__dict__.setdefault("_memo", {})["max_step"] = memo["max_step"]
        return copy

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

    def limit_cycle_state(self, phase: float = 0.0, dt: float = 0.001):
        """Position and velocity, shape (n_dofs,) each, on the limit cycle at ``phase`` [rad].

        The plan of two periods (rounded up to whole steps of ``dt``) that ends at ``phase``:
        its transient decays as :math:`e^{-\alpha_z t / (2\tau)}` (eq. (5), critically damped),
        below :math:`10^{-60}` of the start's offset after two periods at :math:`\alpha_z = 25`.
        """
        dt = self.check_step(dt)
        n_steps = int(np.ceil(2 * self.period / dt - 1e-9))  # 2 periods of 1000 dt: 2000 steps
        rate = 2 * np.pi / self.period  # [rad/s]
        plan = self.rollout(n_steps * dt, dt, phase=real("phase", phase) - rate * n_steps * dt)
        return plan.positions[-1], plan.velocities[-1]

    def stepper(
        self, dt=0.001, start=None, start_velocity=0.0, phase=0.0, compile=False,
        on_limit_cycle=False,
    ):  # fmt: skip
        """An online integrator for control loops (see :class:`dmpopt.stepper.Stepper`).

        With ``on_limit_cycle=True`` it starts on the limit cycle at ``phase``
        (:meth:`limit_cycle_state`) instead of at ``start`` with ``start_velocity``; a start
        off the cycle whose first acceleration exceeds :data:`FAR_ACCELERATION` times the
        cycle's largest warns (a robot tracking it would be jolted).
        """
        if flag("on_limit_cycle", on_limit_cycle):
            if start is not None or np.any(np.asarray(start_velocity) != 0):
                raise InvalidInputError(
                    "on_limit_cycle=True sets the start and start_velocity from the limit cycle; "
                    "pass either start (and start_velocity) or on_limit_cycle=True, not both"
                )
            start, start_velocity = self.limit_cycle_state(phase, dt)
            return Stepper(self, dt, start, start_velocity, phase, compile)
        start = self.setpoint if start is None else start
        stepper = Stepper(self, dt, start, start_velocity, phase, compile)
        on_cycle = self.limit_cycle_state(phase, dt)
        cycle = self.rollout(self.period, dt, *on_cycle, phase=phase).accelerations
        cycle = np.abs(cycle).max(axis=0)
        ratio = np.abs(stepper.acceleration) / np.maximum(cycle, 1e-9)
        if ratio.max() > FAR_ACCELERATION:
            dof = int(ratio.argmax())
            warnings.warn(
                f"the stepper's start asks {abs(stepper.acceleration[dof]):.4g} on DOF {dof} "
                f"on its first step, {ratio[dof]:.3g} times the largest acceleration of the "
                f"limit cycle ({cycle[dof]:.4g}); pass on_limit_cycle=True to start on the cycle",
                stacklevel=2,
            )
        return stepper
