"""Online integration of a DMP inside a control loop.

The stepper is the real-time part of a DMP: it owns the state and the input buffers of
the compiled step (:func:`dmpopt.symbolic.step_function`) and changes goal, setpoint,
speed and amplitude between steps, adds coupling terms, and resets the phase.
"""

from __future__ import annotations

import numpy as np

from . import symbolic
from .dmp import DiscreteDMP, RhythmicDMP, _positive, _vector
from .exceptions import InvalidInputError, ShapeError
from .validation import flag, real, real_array

_INPUT = {name: 2 + i for i, name in enumerate(symbolic.PARAMETER_NAMES)}


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
        if not isinstance(dmp, (DiscreteDMP, RhythmicDMP)):
            raise InvalidInputError(
                f"dmp must be a DiscreteDMP or RhythmicDMP, got {type(dmp).__name__}"
            )
        self.dmp = dmp
        self.dt = dmp.check_step(dt)
        self._max_step_per_tau = dmp.max_step / dmp.time_constant
        step = symbolic.step_function(dmp.signature)
        compile = flag("compile", compile)
        self._function = symbolic.NumericFunction(symbolic.compiled(step) if compile else step)
        self.time = 0.0
        self._start = _vector("start", start, dmp.n_dofs, f"{dmp.n_dofs} DOFs")
        # eq. (7): the forcing term scales by the movement's own start
        parameters = (
            dmp.with_start(self._start) if isinstance(dmp, DiscreteDMP) else dmp
        ).parameter_values()
        self._function.set_inputs(np.zeros(dmp.signature.n_states), self.dt, *parameters)
        self._goal = np.array(dmp._goal_input(), dtype=float)
        if isinstance(dmp, RhythmicDMP):
            canonical = dmp.canonical_state(phase)
        else:
            canonical = (0.0, 0.0)
        velocity = _vector("start_velocity", start_velocity, dmp.n_dofs, f"{dmp.n_dofs} DOFs")
        rows = [self._start, dmp._initial_z(velocity, canonical)]
        if dmp.form == "acceleration":
            rows.append(self._start)
        self._state = self._function.inputs[0]
        self._state[:] = np.concatenate([canonical, *rows])
        initial = symbolic.output_function(dmp.signature)(self._state, *parameters)
        self.position, self.velocity, self.acceleration = (o.full().ravel() for o in initial)

    @property
    def compiled(self) -> bool:
        """True if the step runs as generated C (``compile=True`` and a C compiler found)."""
        return self._function.function.class_name() == "External"

    # -- inputs -------------------------------------------------------------------------
    def _write(self, name: str, value) -> None:
        self._function.inputs[_INPUT[name]][:] = np.ravel(value, order="F")

    def set_goal(self, goal) -> None:
        """New goal (discrete) or setpoint (rhythmic), effective from the next step."""
        self._goal = _vector("goal", goal, self.dmp.n_dofs, f"{self.dmp.n_dofs} DOFs")
        self._write("goal", self._goal)
        if isinstance(self.dmp, DiscreteDMP):
            self._write("forcing_weights", self.dmp.forcing_weights(self._start, self._goal))

    set_setpoint = set_goal

    def set_time_constant(self, time_constant: float) -> None:
        """New ``tau``: the rest of the movement runs faster (smaller) or slower.

        Refused if it puts the step ``dt`` beyond the stability limit, which is
        proportional to ``tau`` (:attr:`DiscreteDMP.max_step`).
        """
        time_constant = _positive("time_constant", time_constant)
        self._check_stable(time_constant, self._max_step_per_tau)
        self._write("time_constant", time_constant)

    def _check_stable(self, time_constant: float, max_step_per_tau: float) -> None:
        limit = time_constant * max_step_per_tau
        if self.dt > limit:
            raise InvalidInputError(
                f"time_constant = {time_constant:.4g} s puts the step dt = {self.dt:.4g} s beyond "
                f"the stability limit {limit:.4g} s of the integration; keep time_constant >= "
                f"{self.dt / max_step_per_tau:.4g} s or build a stepper with a smaller dt"
            )

    def set_amplitude(self, amplitude: float) -> None:
        """New oscillation amplitude (rhythmic DMPs); the oscillator converges to it."""
        if not isinstance(self.dmp, RhythmicDMP):
            raise InvalidInputError("set_amplitude applies to rhythmic DMPs; use set_goal")
        scaled = self.dmp.replace(amplitude=_positive("amplitude", amplitude))
        per_tau = scaled.max_step / scaled.time_constant
        self._check_stable(self._function.inputs[_INPUT["time_constant"]][0], per_tau)
        self._max_step_per_tau = per_tau
        self._write("canonical_target", scaled._canonical_target())

    def reset_phase(self, phase: float) -> None:
        """Jump the oscillator to ``phase`` [rad], keeping its amplitude (eq. (21))."""
        if not isinstance(self.dmp, RhythmicDMP):
            raise InvalidInputError("reset_phase applies to rhythmic DMPs")
        phase = real("phase", phase)
        first, second = self._state[0], self._state[1]
        if self.dmp.form == "phase":
            self._state[0] = phase
        else:
            amplitude = np.hypot(first, second / self.dmp.frequency)
            self._state[0] = amplitude * np.cos(phase)
            self._state[1] = amplitude * self.dmp.frequency * np.sin(phase)

    # -- state --------------------------------------------------------------------------
    @property
    def phase(self) -> float:
        """Normalised phase (discrete, 0 to 1) or oscillator angle [rad] (rhythmic)."""
        if self.dmp.form == "energy":
            return float(np.arctan2(self._state[1], self._state[0]))
        return float(self._state[0])

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
            self._write("coupling", coupling)
        canonical_coupling = real("canonical_coupling", canonical_coupling)
        self._function.inputs[_INPUT["canonical_coupling"]][0] = canonical_coupling
        self._function.evaluate()
        next_state, position, velocity, acceleration = self._function.outputs
        if not np.isfinite(next_state).all():
            raise InvalidInputError(
                "the DMP state became non-finite; check the coupling terms and time constant"
            )
        self._state[:] = next_state
        if coupling is not None:
            self._write("coupling", 0.0)
        self.time += self.dt
        self.position, self.velocity, self.acceleration = (
            position.copy(),
            velocity.copy(),
            acceleration.copy(),
        )
        return self.position, self.velocity, self.acceleration
