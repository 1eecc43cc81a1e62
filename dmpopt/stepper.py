"""Online integration of a DMP inside a control loop.

The stepper is the real-time part of a DMP: it owns the state and the input buffers of
the compiled step (:func:`dmpopt.symbolic.step_function`) and changes goal, setpoint,
speed and amplitude between steps, adds coupling terms, and resets the phase.
"""

from __future__ import annotations

import math

import numpy as np

from . import forms, symbolic
from .exceptions import InvalidInputError, ShapeError
from .validation import flag, positive, real, real_array, vector


class Stepper:
    """Integrates a :class:`DiscreteDMP` or :class:`RhythmicDMP` one step at a time.

    Parameters
    ----------
    dmp : DiscreteDMP or RhythmicDMP
        The movement; its parameters are copied, later changes go through the setters.
    dt : float
        Step [s], at most ``dmp.max_step`` (the stability limit of the integration).
    start, start_velocity : array_like, shape (n_dofs,)
        Initial position and velocity.
    phase : float
        Initial oscillator phase [rad] (rhythmic DMPs).
    compile : bool
        Generate C code for the step and compile it (cached in the user's cache folder; about
        five times faster per step, a few seconds once per system). Without a C compiler it
        warns once and runs on CasADi's virtual machine, with identical results.

    Examples
    --------
    >>> stepper = dmp.stepper(dt=0.001)                        # doctest: +SKIP
    >>> for k in range(1000):                                  # doctest: +SKIP
    ...     position, velocity, acceleration = stepper.step()
    ...     if k == 500:
    ...         stepper.set_goal(new_goal)
    """

    def __init__(self, dmp, dt: float, start, start_velocity=0.0, phase=0.0, compile=False):
        if not isinstance(getattr(dmp, "equations", None), forms.Form):
            raise InvalidInputError(
                f"dmp must be a DiscreteDMP or RhythmicDMP, got {type(dmp).__name__}"
            )
        self.dmp = dmp
        self._discrete = dmp.equations.discrete
        self.dt = dmp.check_step(dt)
        self._max_step_per_tau = dmp.max_step / dmp.tau
        step = symbolic.step_function(dmp.signature)
        compile = flag("compile", compile)
        # a compiled step's library is found once per process (symbolic.compiled keeps it)
        self._function = symbolic.NumericFunction(symbolic.compiled(step) if compile else step)
        self._evaluate = self._function.evaluate
        self._canonical_coupling = self._function.inputs["canonical_coupling"]
        self.time = 0.0
        self._start = vector("start", start, dmp.n_dofs, f"{dmp.n_dofs} DOFs")
        # eq. (7): the forcing term scales by the movement's own start
        own = dmp.with_start(self._start) if self._discrete else dmp
        parameters = own.parameters()
        canonical = (0.0, 0.0) if self._discrete else dmp.canonical_state(phase)
        outputs = self._function.outputs
        self._outputs = [outputs[name] for name in ("next_state", *symbolic.PLAN_OUTPUTS)]
        self._state = self._function.inputs["state"]
        self._state[:] = own.initial_state(self._start, start_velocity, canonical)
        self._function.set_inputs(dt=self.dt, **parameters)
        initial = symbolic.output_function(dmp.signature)(state=self._state, **parameters)
        self.position, self.velocity, self.acceleration = (
            initial[name].full().ravel() for name in symbolic.PLAN_OUTPUTS
        )

    @property
    def compiled(self) -> bool:
        """True if the step runs as generated C (``compile=True`` and a C compiler found)."""
        return self._function.function.class_name() == "External"

    # -- inputs -------------------------------------------------------------------------
    def set_goal(self, goal) -> None:
        """New goal (discrete) or setpoint (rhythmic), effective from the next step."""
        goal = vector("goal", goal, self.dmp.n_dofs, f"{self.dmp.n_dofs} DOFs")
        self._function.set_inputs(goal=goal)
        if self._discrete:
            weights = self.dmp.forcing_weights(self._start, goal)
            self._function.set_inputs(forcing_weights=weights)

    set_setpoint = set_goal

    def set_tau(self, tau: float) -> None:
        """New ``tau``: the rest of the movement runs faster (smaller) or slower.

        Refused if it puts the step ``dt`` beyond the stability limit, which is
        proportional to ``tau`` (:attr:`DiscreteDMP.max_step`).
        """
        tau = positive("tau", tau)
        self._check_stable(tau, self._max_step_per_tau)
        self._function.set_inputs(tau=tau)

    def _check_stable(self, tau: float, max_step_per_tau: float) -> None:
        limit = tau * max_step_per_tau
        if self.dt > limit:
            raise InvalidInputError(
                f"tau = {tau:.4g} s puts the step dt = {self.dt:.4g} s beyond the stability "
                f"limit {limit:.4g} s of the integration; keep tau >= "
                f"{self.dt / max_step_per_tau:.4g} s or build a stepper with a smaller dt"
            )

    def set_amplitude(self, amplitude: float) -> None:
        """New oscillation amplitude (rhythmic DMPs); the oscillator converges to it."""
        if self._discrete:
            raise InvalidInputError("set_amplitude applies to rhythmic DMPs; use set_goal")
        scaled = self.dmp.replace(amplitude=positive("amplitude", amplitude))
        per_tau = scaled.max_step / scaled.tau
        self._check_stable(self._function.inputs["tau"][0], per_tau)
        self._max_step_per_tau = per_tau
        self._function.set_inputs(canonical_target=scaled.parameters()["canonical_target"])

    def reset_phase(self, phase: float) -> None:
        """Jump the oscillator to ``phase`` [rad], keeping its amplitude (eq. (21))."""
        if self._discrete:
            raise InvalidInputError("reset_phase applies to rhythmic DMPs")
        phase = real("phase", phase)
        form, gains = self.dmp.equations, self.dmp.gains
        amplitude = form.amplitude_of(self._state[:2], gains)
        self._state[:2] = form.canonical_state(phase, amplitude, gains)

    # -- state --------------------------------------------------------------------------
    @property
    def phase(self) -> float:
        """Normalised phase (discrete, 0 to 1) or oscillator angle [rad] (rhythmic)."""
        return self.dmp.equations.phase_of(self._state)

    @property
    def state(self) -> np.ndarray:
        """Copy of the full state: canonical, then transformation states."""
        return self._state.copy()

    def step(self, coupling=None, canonical_coupling: float = 0.0):
        """Advance by ``dt``; return position, velocity and acceleration (copies).

        Parameters
        ----------
        coupling : array_like, shape (n_dofs,), optional
            Additive term on the transformation system (added to ``tau * zdot``).
        canonical_coupling : float
            Additive term on the canonical system (``tau * vdot`` or ``tau * phidot``).
        """
        if coupling is not None:
            coupling = np.asarray(coupling)
            if coupling.dtype != np.float64 or not np.isfinite(coupling).all():
                coupling = real_array(
                    "coupling", coupling, empty=True
                )  # converts or names the fault
            if coupling.shape not in ((), (1,), (self.dmp.n_dofs,)):
                raise ShapeError(
                    f"coupling has shape {coupling.shape}, expected ({self.dmp.n_dofs},) "
                    "(one term per DOF) or a scalar"
                )
            self._function.set_inputs(coupling=coupling)
        if not (type(canonical_coupling) is float and math.isfinite(canonical_coupling)):
            canonical_coupling = real("canonical_coupling", canonical_coupling)
        self._canonical_coupling[0] = canonical_coupling
        self._evaluate()
        next_state, position, velocity, acceleration = self._outputs
        if not np.isfinite(next_state).all():
            raise InvalidInputError(
                "the DMP state became non-finite; check the coupling terms and time constant"
            )
        self._state[:] = next_state
        if coupling is not None:
            self._function.set_inputs(coupling=0.0)
        self.time += self.dt
        self.position, self.velocity, self.acceleration = (
            position.copy(),
            velocity.copy(),
            acceleration.copy(),
        )
        return self.position, self.velocity, self.acceleration
