r"""Cartesian DMPs: a 3-D position and a unit-quaternion orientation on one canonical system.

Orientations are unit quaternions stored ``(w, x, y, z)`` (Hamilton product, world-frame
angular velocity: :math:`\dot q = \frac12 \omega \otimes q`).

Position: the discrete DMP of eq. (5) (or eq. (10)) on :math:`y \in \mathbb{R}^3`.

Orientation: the quaternion DMP of Ude, Nemec, Petric and Morimoto [Ude2014]_ in the
log-space form of Koutras and Doulgeri [Koutras2020]_ (``docs/references.rst``).
Ude et al. drive the angular velocity with the quaternion logarithm :math:`2 \log(g
\otimes \bar q)`; Koutras and Doulgeri run the DMP on the logarithm of the orientation
error itself; here (our choices: the factor 2, which makes it the rotation vector, the world
frame, eqs. (5) and (10) as the linear system, the goal-change rule of
:class:`CartesianStepper`)

.. math:: e = 2 \log(q \otimes \bar g) \in \mathbb{R}^3, \qquad q = \exp(e / 2) \otimes g,

as a linear transformation system with goal :math:`e = 0`: eq. (5),
:math:`\tau \dot z = \alpha_z(\beta_z(0 - e) - z)`, :math:`\tau \dot e = z + f` (or eq. (10)).
The angular velocity follows from :math:`\omega = J(e)\, \dot e`, :math:`J` the left
Jacobian of SO(3) (:func:`dmpopt.symbolic.orientation_function`). This system is linear, so
it converges to :math:`q = g` from any start for bounded :math:`f`, it keeps the affine
structure that makes rollouts one matrix product (:mod:`dmpopt.dmp`), and the quaternion is
the exponential map of the state, unit to rounding error at every step whatever the step.

Both parts are :class:`dmpopt.DiscreteDMP` of 3 DOFs with the same time constant, gains and
basis, so they share one canonical system; the plan is one 6-DOF system of
:mod:`dmpopt.symbolic` (the online :class:`CartesianStepper` integrates exactly that) followed
by the orientation map. Goal changes of the orientation move the forcing term with the
start-goal rotation vector :math:`-e_0` as goal changes of the position do with
:math:`g - y_0` (``goal_scaling``).

Sign of quaternions: :math:`q` and :math:`-q` are the same orientation. A demonstration's
quaternions are made continuous (each sample on the side of the previous one, the first with
:math:`w \ge 0`) and a goal is taken on the side of the start (the short way round, at most
:math:`\pi`), so the sign in which quaternions arrive never changes a plan.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from . import symbolic
from .dmp import DiscreteDMP, _frozen
from .exceptions import InvalidInputError, ShapeError
from .validation import flag, positive, real_array, vector

UNIT_TOLERANCE = 1e-6
"""Largest accepted deviation of an input quaternion's norm from 1 (it is then normalised)."""
ANTIPODAL_MARGIN = 1e-9
r"""Smallest :math:`1 + w` of :math:`q \otimes \bar g` for which the logarithm is computed
(0.005 degrees from a full turn): at :math:`q = -g` it has no defined axis."""


def unit_quaternions(name: str, value, shape: tuple) -> np.ndarray:
    """``value`` as unit quaternions ``(w, x, y, z)`` of ``shape`` (ending in 4), normalised.

    Refuses norms further than :data:`UNIT_TOLERANCE` from 1, naming the first culprit.
    """
    array = real_array(name, value, shape=shape, expected="unit quaternions (w, x, y, z)")
    norms = np.linalg.norm(array, axis=-1)
    bad = np.abs(norms - 1.0) > UNIT_TOLERANCE
    if bad.any():
        index = np.unravel_index(np.flatnonzero(bad)[0], norms.shape)
        where = f"{name}[{', '.join(map(str, index))}]" if index else name
        raise InvalidInputError(
            f"{where} has norm {norms[index]:.9g}, expected a unit quaternion (w, x, y, z) to "
            f"{UNIT_TOLERANCE:g}; normalise it (q / np.linalg.norm(q))"
        )
    return array / norms[..., None]


def continuous(quaternions: np.ndarray) -> np.ndarray:
    """The same orientations with signs chosen so that the first has ``w >= 0`` and each
    is on the side of the one before (no jump between ``q`` and ``-q``), shape (n, 4)."""
    signs = np.ones(len(quaternions))
    signs[1:] = np.where(np.sum(quaternions[1:] * quaternions[:-1], axis=1) < 0.0, -1.0, 1.0)
    signs = np.cumprod(signs)
    if quaternions[0, 0] < 0.0:
        signs = -signs
    return quaternions * signs[:, None]


def near_side(quaternion: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``quaternion`` or ``-quaternion``, whichever is nearer to ``reference``."""
    return -quaternion if quaternion @ reference < 0.0 else quaternion


def orientation_log(orientations, goal_orientation, name: str = "orientations") -> np.ndarray:
    r""":math:`e = 2 \log(q \otimes \bar g)` of each orientation, shape (n, 3) (or (3,)).

    Refuses an orientation at :math:`-g` (a full turn from the goal along its sign), where the
    logarithm has no direction.
    """
    q = np.atleast_2d(orientations)
    relative_w = q @ np.asarray(goal_orientation)
    if np.any(relative_w < -1.0 + ANTIPODAL_MARGIN):
        k = int(np.argmin(relative_w))
        raise InvalidInputError(
            f"{name}[{k}] is a full turn (2 pi) from the goal along the quaternions' sign, "
            "where the logarithm has no axis; pass orientations on the goal's side"
        )
    function = symbolic.mapped(symbolic.orientation_log_function(), len(q))
    log = function(q.T, np.asarray(goal_orientation)).full().T
    return log if np.ndim(orientations) == 2 else log[0]


def _orientation_outputs(log, goal_orientation) -> tuple:
    """Orientations, angular velocities and accelerations of a log-space plan, (n, 4|3)."""
    n = log.positions.shape[0]
    outputs = symbolic.mapped(symbolic.orientation_function(), n)(
        log.positions.T, log.velocities.T, log.accelerations.T, goal_orientation
    )
    return tuple(outputs[k].full().T for k in range(3))


def _log_jacobian(log) -> np.ndarray:
    r""":math:`J(e)` with :math:`\omega = J(e) \dot e` (3, 3)."""
    return symbolic.orientation_function()(log, np.zeros(3), np.zeros(3), [1, 0, 0, 0])[3].full()


@dataclass(frozen=True, eq=False)
class CartesianTrajectory:
    """A sampled pose plan: positions and unit-quaternion orientations with derivatives.

    Attributes
    ----------
    times : ndarray, shape (n_steps,)
    positions, velocities, accelerations : ndarray, shape (n_steps, 3)
    orientations : ndarray, shape (n_steps, 4)
        Unit quaternions ``(w, x, y, z)``.
    angular_velocities, angular_accelerations : ndarray, shape (n_steps, 3)
        In the world frame [rad/s, rad/s^2].
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    orientations: np.ndarray
    angular_velocities: np.ndarray
    angular_accelerations: np.ndarray


@dataclass(frozen=True, eq=False)
class CartesianDMP:
    r"""A point-to-point DMP of a pose: 3-D position and unit-quaternion orientation.

    The equations are in the module docstring. Built by :func:`dmpopt.fit_cartesian` or by hand.

    Attributes
    ----------
    position_weights, orientation_weights : ndarray, shape (3, n_basis)
        :math:`w_i` of eq. (7) of the position and of the log-space orientation system.
    start, goal : ndarray, shape (3,)
        Start and goal positions.
    start_orientation, goal_orientation : ndarray, shape (4,)
        Start and goal as unit quaternions ``(w, x, y, z)``; the goal is stored on the side
        of the start (the plan turns the short way, at most :math:`\pi`).
    tau : float
        :math:`\tau` [s], shared by both parts.
    centres, widths : ndarray, shape (n_basis,)
        Basis on the normalised phase of the shared canonical system (6).
    form : {"velocity", "acceleration"}
        Eqs. (5)-(7) or eq. (10), for both parts.
    position_scaling, orientation_scaling : {"rotation", "paper", "translation"}
        How each forcing term follows a new start or goal (:mod:`dmpopt.dmp`): the vector
        :math:`g - y_0` for the position, :math:`-e_0 = -2\log(q_0 \otimes \bar g)` for the
        orientation.
    position_reference, orientation_reference : ndarray, shape (3,), optional
        The demonstrated :math:`g - y_0` and :math:`-e_0`, needed by ``"rotation"``.
    scaled_start_velocity, scaled_start_log_rate : ndarray, shape (3,)
        :math:`\tau \dot y(0)` and :math:`\tau \dot e(0)` of the demonstration, stored like
        the weights (default 0: start at rest).
    alpha_z, beta_z, alpha_v, beta_v, alpha_g : float
        Gains as in :class:`dmpopt.DiscreteDMP`.
    """

    position_weights: np.ndarray
    orientation_weights: np.ndarray
    start: np.ndarray
    goal: np.ndarray
    start_orientation: np.ndarray
    goal_orientation: np.ndarray
    tau: float
    centres: np.ndarray
    widths: np.ndarray
    form: str = "velocity"
    position_scaling: str = "translation"
    orientation_scaling: str = "translation"
    position_reference: np.ndarray | None = None
    orientation_reference: np.ndarray | None = None
    scaled_start_velocity: np.ndarray | float = 0.0
    scaled_start_log_rate: np.ndarray | float = 0.0
    alpha_z: float = 25.0
    beta_z: float | None = None
    alpha_v: float = 25.0
    beta_v: float | None = None
    alpha_g: float | None = None

    def __post_init__(self):
        weights = real_array("position_weights", self.position_weights, ndim=2)
        if weights.shape[0] != 3:
            raise ShapeError(
                f"position_weights has shape {weights.shape}, expected (3, n_basis): one row "
                "per coordinate x, y, z"
            )
        expected = (3, weights.shape[1])
        orientation = real_array("orientation_weights", self.orientation_weights, shape=expected)
        start = unit_quaternions("start_orientation", self.start_orientation, (4,))
        goal = near_side(unit_quaternions("goal_orientation", self.goal_orientation, (4,)), start)
        fields = {
            "position_weights": weights,
            "orientation_weights": orientation,
            "start_orientation": start,
            "goal_orientation": goal,
        }
        for name in ("start", "goal", "scaled_start_velocity", "scaled_start_log_rate"):
            fields[name] = vector(name, getattr(self, name), 3, "a 3-D pose")
        for name, value in fields.items():
            object.__setattr__(self, name, _frozen(value))
        # the two parts validate and complete everything else (gains, basis, scalings)
        part = self.position_dmp
        for name in ("tau", "beta_z", "beta_v", "alpha_g", "centres", "widths"):
            object.__setattr__(self, name, getattr(part, name))
        self.orientation_dmp  # noqa: B018 (validates the orientation's scaling)

    def _part(self, prefix: str, **fields) -> DiscreteDMP:
        scaling, reference = (
            getattr(self, f"{prefix}_scaling"),
            getattr(self, f"{prefix}_reference"),
        )
        try:
            return DiscreteDMP(
                weights=getattr(self, f"{prefix}_weights"),
                tau=self.tau,
                centres=self.centres,
                widths=self.widths,
                form=self.form,
                goal_scaling=scaling,
                reference_displacement=reference,
                alpha_z=self.alpha_z,
                beta_z=self.beta_z,
                alpha_v=self.alpha_v,
                beta_v=self.beta_v,
                alpha_g=self.alpha_g,
                **fields,
            )
        except InvalidInputError as error:  # name this class's fields, not the part's
            message = str(error).replace("goal_scaling", f"{prefix}_scaling")
            message = message.replace("reference_displacement", f"{prefix}_reference")
            raise type(error)(message) from None

    @cached_property
    def position_dmp(self) -> DiscreteDMP:
        """The position part, a 3-DOF :class:`dmpopt.DiscreteDMP`."""
        return self._part(
            "position",
            start=self.start,
            goal=self.goal,
            scaled_start_velocity=self.scaled_start_velocity,
        )

    @cached_property
    def orientation_dmp(self) -> DiscreteDMP:
        r"""The orientation part: a 3-DOF :class:`dmpopt.DiscreteDMP` on
        :math:`e = 2\log(q \otimes \bar g)`, from :attr:`start_log` to 0."""
        return self._part(
            "orientation",
            start=self.start_log,
            goal=np.zeros(3),
            scaled_start_velocity=self.scaled_start_log_rate,
        )

    @property
    def start_log(self) -> np.ndarray:
        r""":math:`e_0 = 2 \log(q_0 \otimes \bar g)`: the rotation vector from the goal to the
        start orientation (world frame), shape (3,)."""
        return orientation_log(self.start_orientation, self.goal_orientation, "start_orientation")

    @property
    def n_basis(self) -> int:
        """Number of basis functions per coordinate."""
        return self.position_weights.shape[1]

    @property
    def settling_time(self) -> float:
        """Default plan length [s] (:attr:`dmpopt.DiscreteDMP.settling_time`)."""
        return self.position_dmp.settling_time

    @property
    def max_step(self) -> float:
        """Largest stable integration step [s] (:attr:`dmpopt.DiscreteDMP.max_step`)."""
        return self.position_dmp.max_step

    def replace(self, **changes) -> CartesianDMP:
        """Return a copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def with_goal(self, position=None, orientation=None) -> CartesianDMP:
        """Same movement towards a new goal position and/or orientation (taken on the side
        of the start: the short way round)."""
        changes = {} if position is None else {"goal": vector("position", position, 3, "3-D")}
        return self.replace(**changes, goal_orientation=self._given(orientation, "goal"))

    def with_start(self, position=None, orientation=None) -> CartesianDMP:
        """Same movement from a new start position and/or orientation."""
        changes = {} if position is None else {"start": vector("position", position, 3, "3-D")}
        return self.replace(**changes, start_orientation=self._given(orientation, "start"))

    def _given(self, orientation, which: str) -> np.ndarray:
        current = getattr(self, f"{which}_orientation")
        if orientation is None:
            return current
        return unit_quaternions("orientation", orientation, (4,))

    def with_tau(self, tau: float) -> CartesianDMP:
        """Same movement, time scaled by ``tau`` (Section 3.3)."""
        return self.replace(tau=tau)

    def rollout(
        self, duration=None, dt: float = 0.001, start_velocity=None, start_angular_velocity=None
    ) -> CartesianTrajectory:
        """The whole plan from the start pose.

        Parameters
        ----------
        duration : float, optional
            Length of the plan [s]; defaults to :attr:`settling_time`.
        dt : float
            Sample (and integration) step [s].
        start_velocity, start_angular_velocity : array_like, shape (3,), optional
            Initial velocity [m/s] and world-frame angular velocity [rad/s]; default the
            demonstrated ones, mapped to the current start and goal.
        """
        duration = self.settling_time if duration is None else duration
        position = self.position_dmp.rollout(duration, dt, start_velocity)
        log_rate = None
        if start_angular_velocity is not None:
            omega = vector("start_angular_velocity", start_angular_velocity, 3, "3-D rotations")
            log_rate = np.linalg.solve(_log_jacobian(self.start_log), omega)
        log = self.orientation_dmp.rollout(duration, dt, log_rate)
        orientations, omega, omega_rate = _orientation_outputs(log, self.goal_orientation)
        return CartesianTrajectory(
            position.times,
            position.positions,
            position.velocities,
            position.accelerations,
            orientations,
            omega,
            omega_rate,
        )

    def stepper(self, dt: float = 0.001, compile: bool = False) -> CartesianStepper:
        """An online integrator for control loops (:class:`CartesianStepper`)."""
        return CartesianStepper(self, dt, compile)

    def joint_dmp(self) -> DiscreteDMP:
        """Both parts as one 6-DOF :class:`dmpopt.DiscreteDMP` (position, then the log of the
        orientation) with the forcing weights of the current start and goal: the system that
        :class:`CartesianStepper` integrates."""
        position, orientation = self.position_dmp, self.orientation_dmp
        return DiscreteDMP(
            weights=np.vstack([position.forcing_weights(), orientation.forcing_weights()]),
            start=np.concatenate([position.start, orientation.start]),
            goal=np.concatenate([position.goal, orientation.goal]),
            tau=self.tau,
            centres=self.centres,
            widths=self.widths,
            form=self.form,
            goal_scaling="translation",
            scaled_start_velocity=self.tau
            * np.concatenate([position.start_velocity, orientation.start_velocity]),
            alpha_z=self.alpha_z,
            beta_z=self.beta_z,
            alpha_v=self.alpha_v,
            beta_v=self.beta_v,
            alpha_g=self.alpha_g,
        )


class CartesianStepper:
    """Integrates a :class:`CartesianDMP` one step at a time (the real-time part).

    The state is that of the 6-DOF system of :meth:`CartesianDMP.joint_dmp`; each step is one
    call of the compiled RK4 step (:func:`dmpopt.symbolic.step_function`) and one of the
    orientation map (:func:`dmpopt.symbolic.orientation_function`).

    A new goal orientation re-expresses the state about it: :math:`e' = 2\\log(q \\otimes
    \\bar g')` with :math:`g'` on the side of the current orientation :math:`q`, the velocity
    state :math:`z` carried as the angular velocity it stands for
    (:math:`z' = J(e')^{-1} J(e) z`) and, in the acceleration form, the goal filter as the
    orientation it stands for. The orientation stays continuous; as for a new goal position,
    the forcing term switches to the new goal.

    Parameters
    ----------
    dmp : CartesianDMP
    dt : float
        Step [s], at most ``dmp.max_step``.
    compile : bool
        Compile the step and the orientation map to C (as :class:`dmpopt.Stepper` does).
    """

    def __init__(self, dmp: CartesianDMP, dt: float = 0.001, compile: bool = False):
        if not isinstance(dmp, CartesianDMP):
            raise InvalidInputError(f"dmp must be a CartesianDMP, got {type(dmp).__name__}")
        self.dmp = dmp
        self.dt = dmp.position_dmp.check_step(dt)
        joint = dmp.joint_dmp()
        self._max_step_per_tau = joint.max_step / joint.tau
        step = symbolic.step_function(joint.signature)
        orientation = symbolic.orientation_function()
        if flag("compile", compile):
            step, orientation = symbolic.compiled(step), symbolic.compiled(orientation)
        self._function = symbolic.NumericFunction(step)
        self._orientation = symbolic.NumericFunction(orientation)
        self._state = self._function.inputs["state"]
        self._state[:] = joint.initial_state(joint.start, joint.start_velocity, (0.0, 0.0))
        self._function.set_inputs(dt=self.dt, **joint.parameters())
        self._goal_orientation = dmp.goal_orientation.copy()
        self.time = 0.0
        initial = symbolic.output_function(joint.signature)(state=self._state, **joint.parameters())
        self._publish(*(initial[name].full().ravel() for name in symbolic.PLAN_OUTPUTS))

    def _publish(self, position, velocity, acceleration) -> None:
        self._orientation.set_inputs(
            log=position[3:],
            log_rate=velocity[3:],
            log_acceleration=acceleration[3:],
            goal_orientation=self._goal_orientation,
        )
        self._orientation.evaluate()
        outputs = self._orientation.outputs
        self.position, self.velocity = position[:3].copy(), velocity[:3].copy()
        self.acceleration = acceleration[:3].copy()
        self.orientation = outputs["orientation"].copy()
        self.angular_velocity = outputs["angular_velocity"].copy()
        self.angular_acceleration = outputs["angular_acceleration"].copy()

    @property
    def state(self) -> np.ndarray:
        """Copy of the state: canonical, then the 6-DOF transformation states."""
        return self._state.copy()

    def set_goal(self, position=None, orientation=None) -> None:
        """New goal position and/or orientation, effective from the next step."""
        goal = self._function.inputs["goal"]
        weights = self._function.inputs["forcing_weights"].reshape((6, -1), order="F").copy()
        if position is not None:
            goal[:3] = vector("position", position, 3, "a 3-D position")
            weights[:3] = self.dmp.position_dmp.forcing_weights(self.dmp.start, goal[:3])
        if orientation is not None:
            new = near_side(unit_quaternions("orientation", orientation, (4,)), self.orientation)
            self._reexpress(new)
            start = orientation_log(self.dmp.start_orientation, new, "start_orientation")
            weights[3:] = self.dmp.orientation_dmp.forcing_weights(start, np.zeros(3))
        self._function.set_inputs(forcing_weights=weights)

    def _reexpress(self, goal_orientation: np.ndarray) -> None:
        """Move the orientation states from the current goal's coordinates to the new one's."""
        # the state: canonical (2), then each transformation state of the 6 DOFs in turn,
        # the orientation's 3 after the position's 3
        names = self.dmp.position_dmp.equations.transformation_states
        rows = {name: self._state[2 + 6 * i + 3 : 2 + 6 * i + 6] for i, name in enumerate(names)}
        log, z = rows["y"], rows["z"]
        new_log = orientation_log(self.orientation, goal_orientation, "orientation")
        z[:] = np.linalg.solve(_log_jacobian(new_log), _log_jacobian(log) @ z)
        if "r" in rows:  # the goal filter r (acceleration form), an orientation
            filtered = rows["r"]
            old = symbolic.orientation_function()(
                filtered, np.zeros(3), np.zeros(3), self._goal_orientation
            )
            filtered[:] = orientation_log(old[0].full().ravel(), goal_orientation, "goal filter")
        log[:] = new_log
        self._goal_orientation = goal_orientation
        self._orientation.set_inputs(goal_orientation=goal_orientation)

    def set_tau(self, tau: float) -> None:
        """New ``tau`` for the rest of the movement (refused beyond the stability limit)."""
        tau = positive("tau", tau)
        if self.dt > tau * self._max_step_per_tau:
            raise InvalidInputError(
                f"tau = {tau:.4g} s puts the step dt = {self.dt:.4g} s beyond the stability "
                f"limit; keep tau >= {self.dt / self._max_step_per_tau:.4g} s"
            )
        self._function.set_inputs(tau=tau)

    def step(self, coupling=None, angular_coupling=None) -> tuple:
        """Advance by ``dt``; return position, velocity, acceleration, orientation, angular
        velocity and angular acceleration (copies, also kept as attributes).

        Parameters
        ----------
        coupling : array_like, shape (3,), optional
            Additive term on the position's transformation system (added to ``tau * zdot``,
            as in :meth:`dmpopt.Stepper.step`), e.g. an obstacle term of
            :mod:`dmpopt.obstacles`; for this step only.
        angular_coupling : array_like, shape (3,), optional
            The same on the orientation's system (the log coordinates about the goal).
        """
        if coupling is not None or angular_coupling is not None:
            terms = np.zeros(6)
            if coupling is not None:
                terms[:3] = vector("coupling", coupling, 3, "the 3-D position")
            if angular_coupling is not None:
                terms[3:] = vector("angular_coupling", angular_coupling, 3, "the 3-D rotation")
            self._function.set_inputs(coupling=terms)
        self._function.evaluate()
        next_state, position, velocity, acceleration = (
            self._function.outputs[name] for name in ("next_state", *symbolic.PLAN_OUTPUTS)
        )
        if coupling is not None or angular_coupling is not None:
            self._function.set_inputs(coupling=0.0)
            if not np.isfinite(next_state).all():
                raise InvalidInputError(
                    "the DMP state became non-finite; check the coupling terms and time constant"
                )
        self._state[:] = next_state
        self.time += self.dt
        self._publish(position, velocity, acceleration)
        return (
            self.position,
            self.velocity,
            self.acceleration,
            self.orientation,
            self.angular_velocity,
            self.angular_acceleration,
        )
