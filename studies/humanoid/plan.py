"""The drumming DMPs, their online plan with the Fig. 4 modifications, and settle times."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dmpopt import RhythmicDMP, Trajectory, fit_rhythmic

from .demos import DRUM_JOINTS, Demonstration
from .parameters import (
    CHANGE_END,
    CHANGE_START,
    DT,
    ELBOW,
    ELBOW_PHASE_COUPLING,
    N_BASIS,
    PERIOD,
    SETPOINT_SHIFT,
)


# ------------------------------------------------------------------------------------ DMPs
@dataclass
class DrumDmps:
    """The learned drumming: 11 DOFs on the shared oscillator and the right elbow on its own."""

    shared: RhythmicDMP  # DRUM_JOINTS without the right elbow
    elbow: RhythmicDMP  # one DOF
    elbow_index: int  # position of the right elbow in DRUM_JOINTS
    start: np.ndarray  # (12,) limit-cycle posture at phase 0 (right-hand strike) [rad]
    start_velocity: np.ndarray  # (12,) limit-cycle velocity at phase 0 [rad/s]


def learn_drumming(demo: Demonstration) -> DrumDmps:
    """Fit the rhythmic DMPs (phase oscillator, ``N_BASIS`` basis functions per DOF)."""
    elbow_index = DRUM_JOINTS.index(ELBOW)
    others = [i for i in range(len(DRUM_JOINTS)) if i != elbow_index]
    joints = demo.joints
    shared_demo = Trajectory(
        joints.times,
        joints.positions[:, others],
        joints.velocities[:, others],
        joints.accelerations[:, others],
    )
    elbow_demo = Trajectory(
        joints.times,
        joints.positions[:, [elbow_index]],
        joints.velocities[:, [elbow_index]],
        joints.accelerations[:, [elbow_index]],
    )
    shared = fit_rhythmic(shared_demo, N_BASIS, period=PERIOD, form="phase")
    elbow = fit_rhythmic(elbow_demo, N_BASIS, period=PERIOD, form="phase")
    start = np.empty(len(DRUM_JOINTS))
    start_velocity = np.empty(len(DRUM_JOINTS))
    for dmp, index in ((shared, others), (elbow, [elbow_index])):
        start[index], start_velocity[index] = dmp.limit_cycle_state(0.0, DT)
    return DrumDmps(shared, elbow, elbow_index, start, start_velocity)


@dataclass(frozen=True)
class Modification:
    """A change of the right elbow's DMP between ``start`` and ``end`` [s] (Fig. 4 right)."""

    name: str  # "none", "amplitude", "frequency" or "setpoint"
    start: float = CHANGE_START
    end: float = CHANGE_END
    filter: float = 0.0  # [s] time constant of the parameters' first-order filter; 0: a step

    @property
    def label(self) -> str:
        """Legend text."""
        return {
            "none": "A: unmodified",
            "amplitude": "B: A -> 2A",
            "frequency": "C: tau -> tau/2",
            "setpoint": f"D: g -> g + {SETPOINT_SHIFT:g} rad",
        }[self.name]


MODIFICATIONS = tuple(Modification(n) for n in ("none", "amplitude", "frequency", "setpoint"))


class DrumPlan:
    """Online drumming plan: steps both DMPs each tick and applies a :class:`Modification`.

    ``position, velocity, acceleration`` (shape (12,), ``DRUM_JOINTS`` order) are the plan at
    the current time; :meth:`step` advances by ``dt``. Both DMPs start on their limit cycle
    at phase 0 (the right-hand strike).
    """

    def __init__(self, dmps: DrumDmps, dt: float = DT, modification=None, compile=False):
        self.dmps = dmps
        self.dt = dt
        self.modification = modification or Modification("none")
        i = dmps.elbow_index
        self._others = np.array([k for k in range(len(DRUM_JOINTS)) if k != i])
        self._elbow = i
        self.shared = dmps.shared.stepper(dt, on_limit_cycle=True, compile=compile)
        self.elbow = dmps.elbow.stepper(dt, on_limit_cycle=True, compile=compile)
        self.time = 0.0
        self._requested = {active: self._targets(active) for active in (False, True)}
        self._parameters = self._targets(False)
        self._reached = self._requested[False]  # the target the parameters equal, if any
        self.position = np.empty(len(DRUM_JOINTS))
        self.velocity = np.empty(len(DRUM_JOINTS))
        self.acceleration = np.empty(len(DRUM_JOINTS))
        self._gather()

    def _gather(self) -> None:
        for stepper, index in ((self.shared, self._others), (self.elbow, [self._elbow])):
            self.position[index] = stepper.position
            self.velocity[index] = stepper.velocity
            self.acceleration[index] = stepper.acceleration

    def _targets(self, active: bool) -> np.ndarray:
        """Elbow (amplitude, time constant, setpoint) requested at this time."""
        name, elbow = self.modification.name, self.dmps.elbow
        return np.array(
            [
                elbow.amplitude * (2.0 if active and name == "amplitude" else 1.0),
                elbow.tau / (2.0 if active and name == "frequency" else 1.0),
                elbow.setpoint[0] + (SETPOINT_SHIFT if active and name == "setpoint" else 0.0),
            ]
        )

    def step(self) -> None:
        """Advance both DMPs by ``dt``; the elbow's A, tau, g follow the modification."""
        mod = self.modification
        active = mod.name != "none" and mod.start <= self.time + 1e-9 < mod.end
        target = self._requested[active]
        if target is not self._reached:  # (once reached, compared no more)
            if np.any(target != self._parameters):
                rate = min(1.0, self.dt / mod.filter) if mod.filter > 0 else 1.0
                self._parameters += (target - self._parameters) * rate
                close = np.abs(target - self._parameters) < 1e-9
                self._parameters[close] = target[close]
                amplitude, tau, setpoint = self._parameters
                self.elbow.set_amplitude(amplitude)
                self.elbow.set_tau(tau)
                self.elbow.set_setpoint([setpoint])
            self._reached = target if np.array_equal(target, self._parameters) else None
        # Phase lock to the shared oscillator, except while the elbow runs at its own tau.
        locked = abs(self._parameters[1] - self.dmps.elbow.tau) < 1e-6
        coupling = ELBOW_PHASE_COUPLING * np.sin(self.shared.phase - self.elbow.phase)
        self.shared.step()
        self.elbow.step(canonical_coupling=coupling if locked else 0.0)
        self.time += self.dt
        self._gather()

    @property
    def phase(self) -> float:
        """Phase of the shared oscillator [rad]."""
        return self.shared.phase

    @property
    def elbow_phase(self) -> float:
        """Phase of the right elbow's oscillator [rad]."""
        return self.elbow.phase


def plan_rollout(dmps: DrumDmps, duration: float, modification=None, dt: float = DT) -> dict:
    """The drumming plan alone (no robot): times, positions (n, 12), elbow phase (n,).

    Its steps are compiled where a C compiler exists, as in the closed loop (the same numbers
    as CasADi's virtual machine; 5x faster)."""
    plan = DrumPlan(dmps, dt, modification, compile=True)
    n = int(round(duration / dt)) + 1
    positions = np.empty((n, len(DRUM_JOINTS)))
    elbow_phase = np.empty(n)
    for k in range(n):
        positions[k] = plan.position
        elbow_phase[k] = plan.elbow_phase
        if k < n - 1:
            plan.step()
    return {"times": np.arange(n) * dt, "positions": positions, "elbow_phase": elbow_phase}


def elbow_limit_cycle(dmps: DrumDmps, dt: float = DT):
    """The elbow's unmodified limit cycle as a function of its phase: ``y(phi)`` callable.

    The plan starts on the limit cycle (phase 0), so one period of the rollout is the cycle.
    """
    elbow, i = dmps.elbow, [dmps.elbow_index]
    plan = elbow.rollout(
        elbow.period + 2 * dt, dt, start=dmps.start[i], start_velocity=dmps.start_velocity[i]
    )
    phase = plan.times / elbow.tau  # tau * phidot = 1
    values = plan.positions[:, 0]

    def cycle(phi):
        return np.interp(np.mod(phi, 2 * np.pi), phase, values)

    return cycle


def ideal_elbow(dmps: DrumDmps, modification: Modification, times, elbow_phase) -> np.ndarray:
    """The new limit cycle the elbow should follow: ``g' + (A'/A) (y(phi) - g)``.

    ``y(phi)`` is the unmodified limit cycle at the elbow oscillator's actual phase, so the
    frequency change is accounted for by the phase itself.
    """
    cycle = elbow_limit_cycle(dmps)
    g = float(dmps.elbow.setpoint[0])
    window = (times >= modification.start) & (times < modification.end)
    scale = np.where(window & (modification.name == "amplitude"), 2.0, 1.0)
    shift = np.where(window & (modification.name == "setpoint"), SETPOINT_SHIFT, 0.0)
    return g + shift + scale * (cycle(elbow_phase) - g)


def settle_time(times, actual, ideal, start, end, tolerance) -> float | None:
    """Time after ``start`` from which ``|actual - ideal| <= tolerance`` until ``end`` [s].

    None if the error never stays within the tolerance before ``end``.
    """
    window = (times >= start) & (times < end)
    error = np.abs(actual[window] - ideal[window])
    outside = np.flatnonzero(error > tolerance)
    if outside.size == 0:
        return 0.0
    last = outside[-1]
    if last == error.size - 1:
        return None
    return float(times[window][last + 1] - start)


def stepper_compiles(dmps: DrumDmps) -> bool:
    """Whether the compiled DMP step is available (needs a C compiler)."""
    return dmps.elbow.stepper(DT, on_limit_cycle=True, compile=True).compiled
