"""Independent answer keys: the paper's equations written plainly here, against the library.

Nothing in this file evaluates :mod:`dmpopt.symbolic`: the keys are the paper's equations
(eqs. (5)-(7), (10), (11)-(12), (13)-(14), written out in docs/glossary.md) in numpy,
integrated by scipy's DOP853 at rtol = atol = 1e-12, or closed-form solutions.

The library integrates with classical RK4 at the sample step (inputs held over the step).
Tolerances are 4x the difference measured at the step used (noted beside each); the
measured differences scale as dt^4, the signature of RK4's discretisation error
(`python benchmarks/answer_key_errors.py`).
"""

import json
from dataclasses import dataclass, field

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from problems import minimum_jerk_demo, periodic_demo, random_discrete
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from dmpopt import (
    DiscreteDMP,
    FileFormatError,
    InvalidInputError,
    RhythmicDMP,
    ShapeError,
    Trajectory,
)
from dmpopt import io as dmpopt_io
from dmpopt.basis import convergence_time, discrete_basis, discrete_phase, rhythmic_basis
from dmpopt.fitting import fit_discrete, fit_rhythmic, minimum_jerk, minimum_jerk_via_points
from dmpopt.fitting.imitation import _filtered, forcing_targets
from dmpopt.stepper import Stepper

ALPHA = 25.0  # alpha_z = alpha_v, the paper's typical value
GAINS = (ALPHA, ALPHA / 4, ALPHA, ALPHA / 4)
HYPOTHESIS = settings(max_examples=8, deadline=None)
FORMS = ["velocity", "acceleration", "phase", "energy"]


# ---------------------------------------------------------------------------------------
# The equations, plainly
# ---------------------------------------------------------------------------------------


@dataclass
class Equations:
    """Constants and inputs of one system; ``weights`` are the forcing weights.

    Discrete forms: ``weights`` (n_dofs, n_basis) multiply eq. (7)'s features directly.
    Rhythmic forms: ``weights`` (n_dofs, n_basis, 2), ``target`` is A (eq. 11) or E0 (13).
    """

    form: str
    tau: float
    goal: np.ndarray
    weights: np.ndarray
    centres: np.ndarray
    widths: np.ndarray
    alpha_z: float = ALPHA
    beta_z: float = ALPHA / 4
    alpha_v: float = ALPHA  # canonical system (6)
    beta_v: float = ALPHA / 4
    alpha_g: float = ALPHA / 2  # goal filter (10)
    rate: float = 10.0  # alpha_r (11) or alpha_E (13)
    k: float = 1.0  # frequency of (13)
    target: float = 1.0
    coupling: np.ndarray = field(default_factory=lambda: np.zeros(1))
    canonical_coupling: float = 0.0
    kernel: str = "von_mises"  # rhythmic forms: or "paper", eq. (12) as printed

    @property
    def n(self) -> int:
        return len(self.goal)


def forcing(eq: Equations, canonical) -> np.ndarray:
    """f of every DOF: eq. (7) on the normalised phase, eqs. (12) and (14) with the kernel
    exp(h (cos(angle - c) - 1)) or, as printed, exp(-h (mod(angle, 2 pi) - c)^2)."""
    first, second = canonical
    if eq.form in ("velocity", "acceleration"):
        psi = np.exp(-eq.widths * (first - eq.centres) ** 2)
        return eq.weights @ psi * second / psi.sum()
    if eq.form == "phase":
        angle, carrier = first, second * np.array([np.cos(first), np.sin(first)])
    else:
        angle, carrier = np.arctan2(second, first), np.array([first, second])
    if eq.kernel == "paper":
        psi = np.exp(-eq.widths * (np.mod(angle, 2 * np.pi) - eq.centres) ** 2)
    else:
        psi = np.exp(eq.widths * (np.cos(angle - eq.centres) - 1.0))
    return (eq.weights @ carrier) @ psi / psi.sum()


def rate(eq: Equations, state: np.ndarray) -> np.ndarray:
    """d(state)/dt; state = [canonical (2), y (n), z (n), r (n, acceleration form)]."""
    n, tau = eq.n, eq.tau
    first, second = state[0], state[1]
    y, z = state[2 : 2 + n], state[2 + n : 2 + 2 * n]
    f = forcing(eq, (first, second))
    cc = eq.canonical_coupling
    if eq.form in ("velocity", "acceleration"):  # eq. (6) with start 0, goal 1
        canonical = [second, eq.alpha_v * (eq.beta_v * (1.0 - first) - second) + cc]
    elif eq.form == "phase":  # eq. (11)
        canonical = [1.0 + cc, eq.rate * (eq.target - second)]
    else:  # eq. (13)
        energy = 0.5 * (second**2 + eq.k**2 * first**2)
        canonical = [second, -eq.rate * (energy - eq.target) * second - eq.k**2 * first + cc]
    if eq.form == "acceleration":  # eq. (10)
        r = state[2 + 2 * n :]
        transformation = [
            z,
            eq.alpha_z * (eq.beta_z * (r - y) - z) + f + eq.coupling,
            eq.alpha_g * (eq.goal - r),
        ]
    else:  # eq. (5)
        transformation = [z + f, eq.alpha_z * (eq.beta_z * (eq.goal - y) - z) + eq.coupling]
    return np.concatenate([canonical, *transformation]) / tau


def outputs(eq: Equations, state: np.ndarray):
    """Position, velocity and acceleration; the acceleration is the derivative of the
    velocity along the flow, by a fourth-order central difference."""
    n = eq.n
    direction = rate(eq, state)

    def velocity(s):
        return rate(eq, s)[2 : 2 + n]

    h = 1e-4 * eq.tau
    acceleration = (
        -velocity(state + 2 * h * direction)
        + 8 * velocity(state + h * direction)
        - 8 * velocity(state - h * direction)
        + velocity(state - 2 * h * direction)
    ) / (12 * h)
    return state[2 : 2 + n], direction[2 : 2 + n], acceleration


def initial_state(eq, start, start_velocity, canonical) -> np.ndarray:
    """z(0) gives the requested velocity (tau yd = z + f); r(0) = y(0) (eq. 10)."""
    start = np.broadcast_to(np.asarray(start, float), (eq.n,))
    z = eq.tau * np.broadcast_to(start_velocity, (eq.n,))
    if eq.form != "acceleration":
        z = z - forcing(eq, canonical)
    rows = [canonical, start, z] + ([start] if eq.form == "acceleration" else [])
    return np.concatenate(rows)


def integrate(eq: Equations, state0, times):
    """DOP853 at rtol = atol = 1e-12; returns the final state and (3, n_times, n) outputs."""
    solution = solve_ivp(
        lambda t, s: rate(eq, s),
        (times[0], times[-1]),
        state0,
        method="DOP853",
        rtol=1e-12,
        atol=1e-12,
        t_eval=times,
    )
    assert solution.success, solution.message
    plan = np.array([np.stack(o) for o in zip(*(outputs(eq, s) for s in solution.y.T))])
    return solution.y[:, -1], plan


def run_stepper(stepper, n_steps, **inputs):
    """Outputs at 0, dt, ..., (n_steps - 1) dt, shape (3, n_steps, n_dofs)."""
    first = (stepper.position, stepper.velocity, stepper.acceleration)
    rest = [stepper.step(**inputs) for _ in range(n_steps - 1)]
    return np.array([np.stack(o) for o in zip(first, *rest)])


def relative_error(actual, key) -> np.ndarray:
    """Max error of positions, velocities, accelerations, each relative to its key's peak."""
    actual, key = np.asarray(actual), np.asarray(key)
    return np.array([np.abs(a - k).max() / np.abs(k).max() for a, k in zip(actual, key)])


def plan_of(trajectory: Trajectory) -> np.ndarray:
    return np.array([trajectory.positions, trajectory.velocities, trajectory.accelerations])


# ---------------------------------------------------------------------------------------
# Systems with seeded random non-zero weights
# ---------------------------------------------------------------------------------------


def discrete_case(form, seed=0, n_basis=10, tau=0.5, scale=20.0, n_dofs=2):
    """A DiscreteDMP with forcing weights = weights (translation) and its equations."""
    rng = np.random.default_rng(seed)
    centres, widths = discrete_basis(n_basis, GAINS)
    weights = scale * rng.normal(size=(n_dofs, n_basis))
    start, goal = rng.normal(size=n_dofs), rng.normal(size=n_dofs)
    dmp = DiscreteDMP(
        weights, start, goal, tau, centres, widths, form=form, goal_scaling="translation"
    )
    eq = Equations(form, tau, goal, weights, centres, widths, coupling=np.zeros(n_dofs))
    return dmp, eq


def rhythmic_case(form, seed=0, n_basis=8, tau=0.15, amplitude=1.3, n_dofs=2, kernel="von_mises"):
    """A RhythmicDMP (k = 1.5) and its equations."""
    rng = np.random.default_rng(seed)
    centres, widths = rhythmic_basis(n_basis, kernel)
    weights = 3.0 * rng.normal(size=(n_dofs, n_basis, 2))
    setpoint = rng.normal(size=n_dofs)
    dmp = RhythmicDMP(
        weights, setpoint, tau, centres, widths, form=form, amplitude=amplitude,
        kernel=kernel, k=1.5,
    )  # fmt: skip
    target = amplitude if form == "phase" else 0.5 * (1.5 * amplitude) ** 2
    eq = Equations(
        form, tau, setpoint, weights, centres, widths, k=1.5, target=target,
        coupling=np.zeros(n_dofs), kernel=kernel,
    )  # fmt: skip
    return dmp, eq


def case(form, seed):
    """A system of either kind and the canonical state of its rollouts from phase 0.7."""
    if form in ("velocity", "acceleration"):
        dmp, eq = discrete_case(form, seed)
        return dmp, eq, np.zeros(2), {}
    dmp, eq = rhythmic_case(form, seed)
    return dmp, eq, rhythmic_canonical(form, dmp.amplitude, 1.5, 0.7), {"phase": 0.7}


def rhythmic_canonical(form, amplitude, k, phase):
    """Library convention: (phi, A) or, on the energy limit cycle, (A cos p, A k sin p)."""
    if form == "phase":
        return np.array([phase, amplitude])
    return np.array([amplitude * np.cos(phase), amplitude * k * np.sin(phase)])


def grid(duration, dt):
    return np.arange(int(round(duration / dt)) + 1) * dt


def rollout_errors(form, dt):
    """Rollout and stepper against the key, from an offset start with a start velocity."""
    dmp, eq, canonical, phase = case(form, seed=1)
    start = (dmp.start if form in ("velocity", "acceleration") else dmp.setpoint) + 0.2
    times = grid(0.8, dt)
    _, key = integrate(eq, initial_state(eq, start, -0.4, canonical), times)
    if form in ("velocity", "acceleration"):
        dmp = dmp.with_start(start)
        rollout = dmp.rollout(times[-1], dt, start_velocity=-0.4)
        stepper = dmp.stepper(dt, start_velocity=-0.4)
    else:
        rollout = dmp.rollout(times[-1], dt, start, -0.4, **phase)
        stepper = dmp.stepper(dt, start, -0.4, **phase)
    stepped = run_stepper(stepper, len(times))
    return relative_error(plan_of(rollout), key), relative_error(stepped, key)


def coupling_errors(form, dt):
    """Constant coupling on the transformation (tau zdot += C) and canonical
    (tau vdot or tau phidot += C_c) systems; sample 0 precedes any coupling."""
    dmp, eq, canonical, phase = case(form, seed=3)
    eq.coupling, eq.canonical_coupling = np.array([4.0, -7.0]), 0.6
    start = dmp.start if form in ("velocity", "acceleration") else dmp.setpoint
    times = grid(0.6, dt)
    _, key = integrate(eq, initial_state(eq, start, 0.0, canonical), times)
    stepper = dmp.stepper(dt, **phase)
    stepped = run_stepper(stepper, len(times), coupling=eq.coupling, canonical_coupling=0.6)
    return relative_error(stepped[:, 1:], key[:, 1:])


def goal_change_errors(form, dt):
    """set_goal after 0.2 s against the key with g and the forcing weights of eq. (7),
    (g - y0) w, switched at the same time; compared after the switch."""
    dmp, eq, canonical, _ = case(form, seed=4)
    dmp = dmp.replace(goal_scaling="paper")
    new_goal = dmp.goal + np.array([1.3, -0.8])
    times, switch = grid(0.7, dt), int(round(0.2 / dt))
    eq.weights = (dmp.goal - dmp.start)[:, None] * dmp.weights
    state0 = initial_state(eq, dmp.start, 0.0, canonical)
    state, _ = integrate(eq, state0, times[: switch + 1])
    eq.goal, eq.weights = new_goal, (new_goal - dmp.start)[:, None] * dmp.weights
    _, key = integrate(eq, state, times[switch:])
    stepper = dmp.stepper(dt)
    run_stepper(stepper, switch + 1)
    stepper.set_goal(new_goal)
    stepped = run_stepper(stepper, len(times) - switch)
    return relative_error(stepped[:, 1:], key[:, 1:])


def phase_reset_errors(form, dt):
    """reset_phase(2) after 0.3 s, eq. (21): returns the error of the reset state against
    (phi, r) -> (2, r), or (x, v) -> (a cos 2, a k sin 2) with a = sqrt(x^2 + v^2 / k^2),
    and the errors of the next 0.3 s against the key started from that state."""
    dmp, eq, _, phase = case(form, seed=5)
    stepper = dmp.stepper(dt, **phase)
    times = grid(0.3, dt)
    run_stepper(stepper, len(times))
    state = stepper.state
    stepper.reset_phase(2.0)
    if form == "phase":
        state[0] = 2.0
    else:
        amplitude = np.hypot(state[0], state[1] / 1.5)
        state[:2] = amplitude * np.cos(2.0), amplitude * 1.5 * np.sin(2.0)
    reset_error = np.abs(stepper.state - state).max()
    _, key = integrate(eq, state, times)
    return reset_error, relative_error(run_stepper(stepper, len(times))[:, 1:], key[:, 1:])


def affine_errors(form, dt):
    """The affine plan of the DMP with other weights (a third of them), evaluated at the
    key's forcing weights, against the key of rollout_errors: affine in any weights,
    including through z(0) = tau yd(0) - f(0) (rhythmic forms start with f(0) != 0)."""
    dmp, eq, canonical, phase = case(form, seed=1)
    start = (dmp.start if form in ("velocity", "acceleration") else dmp.setpoint) + 0.2
    times = grid(0.8, dt)
    _, key = integrate(eq, initial_state(eq, start, -0.4, canonical), times)
    other = dmp.replace(weights=dmp.weights / 3)
    if form in ("velocity", "acceleration"):
        dmp, other = dmp.with_start(start), other.with_start(start)
        plan = other.affine_plan(times[-1], dt, start_velocity=-0.4)
    else:
        plan = other.affine_plan(times[-1], dt, start, -0.4, **phase)
    trajectory = plan.trajectory(dmp.forcing_weights())
    np.testing.assert_allclose(trajectory.times, times, rtol=0, atol=1e-15)
    return relative_error(plan_of(trajectory), key)


def paper_kernel_errors(form, dt, turns=0):
    """Eq. (12)/(14) with the printed kernel exp(-h (mod(angle, 2 pi) - c)^2), over a
    stretch that does not cross the kernel's jump at angle 0 (phase 0.7 -> 4.7, or the
    energy oscillator's angle 6.0 -> 1.0, which turns clockwise); the phase oscillator
    ``turns`` periods later, where mod(phase, 2 pi) is the same."""
    phase, duration = (0.7 + 2 * np.pi * turns, 0.6) if form == "phase" else (6.0, 0.5)
    dmp, eq = rhythmic_case(form, seed=6, kernel="paper")
    times = grid(duration, dt)
    canonical = rhythmic_canonical(form, dmp.amplitude, 1.5, phase)
    _, key = integrate(eq, initial_state(eq, dmp.setpoint, 0.3, canonical), times)
    plan = dmp.rollout(times[-1], dt, dmp.setpoint, 0.3, phase)
    return relative_error(plan_of(plan), key)


def kick_errors(form, dt):
    """One step(coupling=C, canonical_coupling=C_c), then plain steps: the key integrates
    [0, dt] with the coupling and the rest without."""
    dmp, eq, canonical, _ = case(form, seed=12)
    times = grid(0.3, dt)
    eq.coupling, eq.canonical_coupling = np.array([3.0, -2.0]) / dt, 0.2 / dt
    state, _ = integrate(eq, initial_state(eq, dmp.start, 0.0, canonical), times[:2])
    stepper = dmp.stepper(dt)
    stepper.step(coupling=eq.coupling, canonical_coupling=eq.canonical_coupling)
    eq.coupling, eq.canonical_coupling = np.zeros(2), 0.0
    _, key = integrate(eq, state, times[1:])
    # sample 0 is the kick step's own output, evaluated with the coupling still applied
    return relative_error(run_stepper(stepper, len(times) - 1)[:, 1:], key[:, 1:])


# Errors relative to the key's peak (positions, velocities, accelerations) measured at
# dt = 1 ms by `python benchmarks/answer_key_errors.py`, which also shows that halving dt
# divides them by about 16: they are RK4's discretisation error, nothing else. The tests
# allow 4x these.
MEASURED = {  # the stepper's errors equal the rollout's to every printed digit
    ("rollout", "velocity"): [3.9e-8, 3.5e-8, 3.6e-8],
    ("rollout", "acceleration"): [7.9e-9, 6.2e-8, 9.0e-8],
    ("rollout", "phase"): [9.0e-8, 1.6e-6, 8.3e-7],  # dt / tau = 1 / 150
    ("rollout", "energy"): [9.9e-8, 1.0e-6, 7.9e-7],
    ("coupling", "velocity"): [1.9e-7, 3.8e-8, 7.0e-8],
    ("coupling", "acceleration"): [1.0e-8, 1.1e-7, 2.9e-7],
    ("coupling", "phase"): [8.1e-8, 6.7e-7, 1.0e-6],
    ("coupling", "energy"): [9.3e-8, 6.1e-7, 9.6e-7],
    ("goal", "velocity"): [6.1e-9, 1.1e-8, 4.6e-9],
    ("goal", "acceleration"): [3.6e-9, 2.7e-8, 6.1e-8],
    ("reset", "phase"): [1.2e-7, 5.5e-7, 1.7e-6],
    ("reset", "energy"): [1.2e-7, 4.6e-7, 1.0e-6],
    ("paper", "phase"): [3.0e-7, 1.9e-6, 8.2e-7],
    ("paper", "energy"): [1.6e-7, 1.3e-6, 7.0e-7],
    ("kick", "velocity"): [3.3e-8, 3.0e-8, 4.6e-8],
    ("kick", "acceleration"): [7.8e-9, 4.0e-8, 4.8e-8],
}
FACTOR = 4.0


@pytest.mark.parametrize("form", FORMS)
def test_rollout_and_stepper_match_plain_equations(form):
    """Eqs. (5)-(7), (10), (11)-(12), (13)-(14) with non-zero weights, goal filter, an
    offset start and a start velocity: rollout and stepper equal the plain equations."""
    rollout, stepped = rollout_errors(form, 1e-3)
    tolerance = FACTOR * np.array(MEASURED["rollout", form])
    assert np.all(rollout < tolerance), rollout
    assert np.all(stepped < tolerance), stepped


@pytest.mark.parametrize("form", FORMS)
def test_stepper_coupling_terms_match_plain_equations(form):
    """Coupling terms enter tau zdot and the canonical system as in the plain equations."""
    errors = coupling_errors(form, 1e-3)
    assert np.all(errors < FACTOR * np.array(MEASURED["coupling", form])), errors


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_online_goal_change_matches_plain_equations_with_switched_goal(form):
    """Stepper.set_goal switches the goal and the goal-scaled forcing weights together."""
    errors = goal_change_errors(form, 1e-3)
    assert np.all(errors < FACTOR * np.array(MEASURED["goal", form])), errors


@pytest.mark.parametrize("form", ["phase", "energy"])
def test_phase_reset_matches_plain_equations_restarted_at_the_new_phase(form):
    """reset_phase keeps the amplitude and jumps to the new phase (eq. 21)."""
    reset_error, errors = phase_reset_errors(form, 1e-3)
    assert reset_error < 1e-14
    assert np.all(errors < FACTOR * np.array(MEASURED["reset", form])), errors


@pytest.mark.parametrize("form", FORMS)
def test_affine_plan_matches_plain_equations(form):
    """The affine plan F + G W^T of a DMP with other weights, at the key's forcing weights,
    is the plan of the plain equations (same samples, same errors as the rollout)."""
    errors = affine_errors(form, 1e-3)
    assert np.all(errors < FACTOR * np.array(MEASURED["rollout", form])), errors


@pytest.mark.parametrize("form", ["phase", "energy"])
def test_printed_kernel_matches_plain_equations(form):
    """kernel="paper": eqs. (12) and (14) with the kernel as printed."""
    errors = paper_kernel_errors(form, 1e-3)
    assert np.all(errors < FACTOR * np.array(MEASURED["paper", form])), errors


def test_printed_kernel_wraps_the_phase_of_later_periods():
    """Two periods on (phase 0.7 + 4 pi -> 4.7 + 4 pi) the printed kernel sees the same
    mod(phase, 2 pi): the same errors against the plain equations."""
    errors = paper_kernel_errors("phase", 1e-3, turns=2)
    assert np.all(errors < FACTOR * np.array(MEASURED["paper", "phase"])), errors


@pytest.mark.parametrize("goal_scaling", ["paper", "rotation"])
def test_stepper_from_another_start_scales_forcing_by_its_own_start(goal_scaling):
    """Eq. (7): from start y0 the forcing weights are those of (y0, g), as in a rollout of
    dmp.with_start(y0)."""
    dmp, eq = discrete_case("velocity", seed=7)
    dmp = dmp.replace(goal_scaling=goal_scaling, reference_displacement=dmp.goal - dmp.start)
    start = dmp.start + np.array([0.5, -0.3])
    eq.weights = dmp.forcing_weights(start, dmp.goal)
    times = grid(0.5, 1e-3)
    _, key = integrate(eq, initial_state(eq, start, 0.0, np.zeros(2)), times)
    errors = relative_error(run_stepper(Stepper(dmp, 1e-3, start), len(times)), key)
    assert np.all(errors < FACTOR * np.array(MEASURED["rollout", "velocity"])), errors


@HYPOTHESIS
@given(
    seed=st.integers(0, 2**16),
    tau=st.floats(0.3, 2.0),
    scale=st.floats(1.0, 50.0),
    form=st.sampled_from(["velocity", "acceleration"]),
)
def test_random_discrete_systems_match_plain_equations(seed, tau, scale, form):
    """Random weights, starts, goals and time constants (a coarser grid keeps it cheap)."""
    dmp, eq = discrete_case(form, seed=seed, tau=tau, scale=scale, n_basis=6)
    dt = 2e-3
    times = grid(1.5 * tau, dt)
    _, key = integrate(eq, initial_state(eq, dmp.start, 0.0, np.zeros(2)), times)
    errors = relative_error(plan_of(dmp.rollout(times[-1], dt)), key)
    # RK4: error = C (dt / tau)^4; the worst C of 40 random draws was 3.2e3, 9.4e3, 1.35e4
    assert np.all(errors < FACTOR * np.array([3.2e3, 9.4e3, 1.35e4]) * (dt / tau) ** 4), errors


# ---------------------------------------------------------------------------------------
# Closed forms
# ---------------------------------------------------------------------------------------


@HYPOTHESIS
@given(
    tau=st.floats(0.2, 3.0),
    start=st.floats(-5, 5),
    goal=st.floats(-5, 5),
    start_velocity=st.floats(-3, 3),
    alpha_z=st.floats(5.0, 60.0),
)
def test_unforced_velocity_form_is_critically_damped(tau, start, goal, start_velocity, alpha_z):
    """w = 0, eq. (5): e = y - g solves e'' + 2 w e' + w^2 e = 0, w = alpha_z / (2 tau),
    so e(t) = (e0 + (e0' + w e0) t) exp(-w t)."""
    dmp = DiscreteDMP(
        np.zeros((1, 3)), start, goal, tau, np.zeros(3), np.ones(3),
        goal_scaling="translation", alpha_z=alpha_z,
    )  # fmt: skip
    dt = 1e-3 * tau
    plan = dmp.rollout(2.0 * tau, dt, start_velocity=start_velocity)
    t, w, e0, de0 = plan.times, alpha_z / (2 * tau), start - goal, start_velocity
    decay = np.exp(-w * t)
    e = (e0 + (de0 + w * e0) * t) * decay
    de = (de0 - w * (de0 + w * e0) * t) * decay
    dde = -2 * w * de - w**2 * e
    # RK4: error = C (|e0| + |e0'| / w) (w dt)^4 w^k for the k-th derivative; the worst C
    # over 60 draws was 0.013, 0.016, 0.019 (w dt up to 0.03), plus rounding
    bound = (abs(e0) + abs(de0) / w) * (w * dt) ** 4
    rounding = 1e-13 * (1 + abs(start) + abs(goal))
    for k, (actual, key) in enumerate(zip(plan_of(plan), (e + goal, de, dde))):
        atol = (4 * (0.013, 0.016, 0.019)[k] * bound + rounding) * w**k
        np.testing.assert_allclose(actual[:, 0], key, rtol=0, atol=atol)


@HYPOTHESIS
@given(tau=st.floats(0.2, 3.0), start=st.floats(-5, 5), goal=st.floats(-5, 5))
def test_unforced_acceleration_form_has_a_triple_pole(tau, start, goal):
    """w = 0, eq. (10) with alpha_g = alpha_z / 2 from rest: the goal filter and the
    transformation system make a triple pole at -w, w = alpha_z / (2 tau), so
    e(t) = e0 (1 + w t + (w t)^2 / 2) exp(-w t)."""
    dmp = DiscreteDMP(
        np.zeros((1, 3)), start, goal, tau, np.zeros(3), np.ones(3),
        form="acceleration", goal_scaling="translation",
    )  # fmt: skip
    dt = 1e-3 * tau
    plan = dmp.rollout(2.0 * tau, dt)
    t, w, e0 = plan.times, ALPHA / (2 * tau), start - goal
    decay = np.exp(-w * t)
    e = e0 * (1 + w * t + (w * t) ** 2 / 2) * decay
    de = -e0 * w**3 * t**2 / 2 * decay
    dde = -e0 * w**3 * (t - w * t**2 / 2) * decay
    # RK4 at w dt = 0.0125: worst error over 30 draws 2.6e-10, 4.9e-10, 7.9e-10 |e0| w^k
    rounding = 1e-13 * (1 + abs(start) + abs(goal))
    for k, (actual, key) in enumerate(zip(plan_of(plan), (e + goal, de, dde))):
        atol = (4 * (2.6e-10, 4.9e-10, 7.9e-10)[k] * abs(e0) + rounding) * w**k
        np.testing.assert_allclose(actual[:, 0], key, rtol=0, atol=atol)


def canonical_phase(t, tau, alpha_v=ALPHA):
    """Eq. (6) normalised with beta_v = alpha_v / 4, from rest at 0:
    x(t) = 1 - (1 + w t) exp(-w t), w = alpha_v / (2 tau)."""
    w = alpha_v / (2 * tau)
    return 1.0 - (1.0 + w * t) * np.exp(-w * t)


@HYPOTHESIS
@given(tau=st.floats(0.1, 3.0), start=st.floats(-3, 3), goal=st.floats(-3, 3))
def test_stepper_phase_is_the_closed_form_canonical_solution(tau, start, goal):
    """The stepper's phase follows the canonical closed form whatever the start and goal
    (the phase is goal-independent, Section 3.6)."""
    dmp, _ = discrete_case("velocity", seed=0, tau=tau)
    stepper = dmp.replace(start=[start, start], goal=[goal, goal]).stepper(1e-3)
    phases = [stepper.phase] + [(stepper.step(), stepper.phase)[1] for _ in range(400)]
    key = canonical_phase(np.arange(401) * 1e-3, tau)
    # RK4: measured error 2.4e2-2.7e2 (dt / tau)^4 for tau in [0.1, 3]
    np.testing.assert_allclose(phases, key, rtol=0, atol=1.1e3 * (1e-3 / tau) ** 4)


def test_basis_centres_sit_at_the_phase_of_equally_spaced_times():
    """Centres c_i = x(t_i) at t_i = i T / (N - 1), T the 95 % convergence time of the
    unforced eq. (5) from rest (closed form: (1 + w T) exp(-w T) = 0.05); widths
    h_i = 2 ln 2 / (c_{i+1} - c_i)^2 (the last repeats the last spacing)."""
    w = ALPHA / 2
    end = brentq(lambda t: (1 + w * t) * np.exp(-w * t) - 0.05, 1e-3, 10.0)
    # the library interpolates an RK4 run at 0.1 ms: measured 4.1e-9 off
    assert convergence_time("velocity", GAINS) == pytest.approx(end, abs=1.6e-8)
    for n_basis in (1, 2, 7, 20):
        centres, widths = discrete_basis(n_basis, GAINS)
        times = np.linspace(0.0, end, n_basis) if n_basis > 1 else np.array([end / 2])
        key_centres = canonical_phase(times, 1.0)
        # linear interpolation on the 0.1 ms grid: measured 8.8e-8 and 6.7e-6 (N = 20)
        np.testing.assert_allclose(centres, key_centres, rtol=0, atol=3.5e-7)
        if n_basis == 1:  # one basis normalises to 1 whatever its width: any positive one
            assert widths.shape == (1,) and widths[0] > 0
            continue
        spacing = np.diff(key_centres)
        key_widths = 2 * np.log(2) / np.append(spacing, spacing[-1]) ** 2
        np.testing.assert_allclose(widths, key_widths, rtol=2.7e-5)
    times = np.linspace(0, 0.5, 11)
    phases = discrete_phase(GAINS, tuple(times))
    np.testing.assert_allclose(phases, canonical_phase(times, 1.0), rtol=0, atol=1e-12)


@pytest.mark.parametrize("kernel", ["von_mises", "paper"])
def test_rhythmic_basis_neighbours_cross_at_half_height(kernel):
    """Centres 2 pi i / N; halfway between neighbours (pi / N away) each kernel is 1/2:
    exp(h (cos(pi / N) - 1)) (von Mises) or exp(-h (pi / N)^2) (eq. 12 as printed)."""
    centres, widths = rhythmic_basis(8, kernel)
    np.testing.assert_allclose(centres, 2 * np.pi * np.arange(8) / 8, rtol=0, atol=1e-15)
    half = np.pi / 8
    height = (
        np.exp(widths * (np.cos(half) - 1)) if kernel == "von_mises" else np.exp(-widths * half**2)
    )
    np.testing.assert_allclose(height, 0.5, rtol=1e-12)


def test_rhythmic_basis_names_the_kernels_it_knows():
    with pytest.raises(
        InvalidInputError, match="kernel must be 'von_mises' or 'paper', got 'gauss'"
    ):
        rhythmic_basis(8, "gauss")


def test_acceleration_form_convergence_time_is_the_triple_pole_crossing():
    """(1 + wT + (wT)^2 / 2) exp(-wT) = 0.05, w = alpha_z / 2, for tau = 1."""
    w = ALPHA / 2
    end = brentq(lambda t: (1 + w * t + (w * t) ** 2 / 2) * np.exp(-w * t) - 0.05, 1e-3, 10)
    gains = GAINS + (ALPHA / 2,)
    # measured 9.9e-9 off (RK4 at 0.1 ms, linear interpolation of the crossing)
    assert convergence_time("acceleration", gains) == pytest.approx(end, abs=4e-8)


def quintic(start, goal, duration, t):
    """Minimum jerk: y = y0 + (g - y0)(10 s^3 - 15 s^4 + 6 s^5), s = t / T, and derivatives."""
    s, d = t / duration, goal - start
    return (
        start + d * (10 * s**3 - 15 * s**4 + 6 * s**5),
        d * (30 * s**2 - 60 * s**3 + 30 * s**4) / duration,
        d * (60 * s - 180 * s**2 + 120 * s**3) / duration**2,
    )


@HYPOTHESIS
@given(start=st.floats(-5, 5), goal=st.floats(-5, 5), duration=st.floats(0.2, 5.0))
def test_minimum_jerk_is_the_quintic(start, goal, duration):
    """Closed form and the via-point solver without via-points both give the quintic."""
    key = quintic(start, goal, duration, np.linspace(0, duration, 201))
    for trajectory in (
        minimum_jerk([start], [goal], duration, n_samples=201),
        minimum_jerk_via_points([start], [goal], duration, [], n_samples=201),
    ):
        for actual, expected in zip(plan_of(trajectory), key):
            scale = (abs(goal - start) + 1e-9) * max(1.0, duration**-2)
            np.testing.assert_allclose(actual[:, 0], expected, atol=1e-9 * scale)


# ---------------------------------------------------------------------------------------
# Locally weighted regression
# ---------------------------------------------------------------------------------------


def test_lwr_weights_are_per_basis_weighted_least_squares():
    """Eq. (16) targets on a minimum-jerk demo, regressed per basis i on f ~ w_i v with
    weights psi_i: lstsq on rows sqrt(psi_i) v, sqrt(psi_i) f. Phase, goal filter and
    tau come from closed forms (tau: triple-pole 95 % crossing at the demo's end)."""
    duration, n = 1.0, 1001
    t = np.linspace(0, duration, n)
    start, goal = np.array([0.3, -1.0]), np.array([1.5, 0.5])
    y, yd, ydd = (np.outer(q, goal - start) for q in quintic(0.0, 1.0, duration, t))
    y = y + start
    demo = Trajectory(t, y, yd, ydd)
    dmp = fit_discrete(demo, 12, form="acceleration", method="lwr", goal_scaling="translation")

    w = ALPHA / 2
    crossing = brentq(lambda s: (1 + w * s + (w * s) ** 2 / 2) * np.exp(-w * s) - 0.05, 1e-3, 9)
    assert dmp.tau == pytest.approx(duration / crossing, rel=8e-8)  # measured 2e-8
    tau = dmp.tau  # the regression is sensitive to tau: isolate it
    phase = canonical_phase(t, tau)
    phase_velocity = (ALPHA / 2) ** 2 * (t / tau) * np.exp(-(ALPHA / 2) * t / tau)
    r = goal + (start - goal) * np.exp(-(ALPHA / 2) * t / tau)[:, None]
    targets = tau**2 * ydd - ALPHA * (ALPHA / 4 * (r - y) - tau * yd)
    key = np.empty((2, 12))
    for i, (c, h) in enumerate(zip(dmp.centres, dmp.widths)):
        root_psi = np.sqrt(np.exp(-h * (phase - c) ** 2))
        rows = (root_psi * phase_velocity)[:, None]
        key[:, i] = np.linalg.lstsq(rows, root_psi[:, None] * targets, rcond=None)[0][0]
    # measured 1.3e-11 of the largest weight (the library's phase is RK4 at 0.5 ms / tau)
    np.testing.assert_allclose(dmp.weights, key, rtol=0, atol=5e-11 * np.abs(key).max())


def test_least_squares_weights_are_ridge_regression_on_eq_7_features():
    """The same closed forms as the LWR key; the global regression of the forcing targets on
    the features psi_i v / sum_j psi_j with a ridge lambda = 1e-3 trace(A^T A) / N."""
    duration, n = 1.0, 1001
    t = np.linspace(0, duration, n)
    start, goal = np.array([0.3, -1.0]), np.array([1.5, 0.5])
    y, yd, ydd = (np.outer(q, goal - start) for q in quintic(0.0, 1.0, duration, t))
    demo = Trajectory(t, y + start, yd, ydd)
    options = dict(form="acceleration", method="least_squares", goal_scaling="translation")
    dmp = fit_discrete(demo, 12, regularization=1e-3, **options)
    tau = dmp.tau
    phase = canonical_phase(t, tau)
    phase_velocity = (ALPHA / 2) ** 2 * (t / tau) * np.exp(-(ALPHA / 2) * t / tau)
    r = goal + (start - goal) * np.exp(-(ALPHA / 2) * t / tau)[:, None]
    targets = tau**2 * ydd - ALPHA * (ALPHA / 4 * (r - (y + start)) - tau * yd)
    psi = np.exp(-dmp.widths * (phase[:, None] - dmp.centres) ** 2)
    features = psi * phase_velocity[:, None] / psi.sum(axis=1, keepdims=True)
    gram = features.T @ features
    ridge = 1e-3 * np.trace(gram) / 12
    key = np.linalg.solve(gram + ridge * np.eye(12), features.T @ targets).T
    # measured 1.7e-11 of the largest weight (the library's phase is RK4 at 0.5 ms / tau)
    np.testing.assert_allclose(dmp.weights, key, rtol=0, atol=7e-11 * np.abs(key).max())


def test_position_weights_solve_the_goal_constrained_ridge_problem():
    """method="position": min |R w - (y - y_free)|^2 + lambda |w|^2 with the last sample
    held to the goal, lambda = 1e-2 trace(R^T R) / N. R and y_free come from rollouts of
    the fitted DMP with each weight set to one (the plan is affine in the weights); the
    KKT system is solved here."""
    demo = minimum_jerk_demo(n_dofs=1, n_steps=201)
    moving = Trajectory.from_positions(demo.times[20:] - demo.times[20], demo.positions[20:])
    dmp = fit_discrete(moving, 8, regularization=1e-2, goal_scaling="translation")
    dt = moving.duration / (moving.n_steps - 1)

    def plan(weights):
        return dmp.replace(weights=weights).rollout(moving.duration, dt).positions[:, 0]

    free = plan(np.zeros((1, 8)))
    response = np.column_stack([plan(np.eye(8)[[i]]) - free for i in range(8)])
    gram = response.T @ response
    kkt = np.zeros((9, 9))
    kkt[:8, :8] = gram + 1e-2 * np.trace(gram) / 8 * np.eye(8)
    kkt[:8, 8] = kkt[8, :8] = response[-1]
    residual = moving.positions[:, 0] - free
    rhs = np.r_[response.T @ residual, residual[-1]]
    solution = np.linalg.solve(kkt, rhs)
    key = solution[:8]
    # the fit's response (affine_plan) and these rollouts each lie within delta = 4 n_steps eps
    # of their largest value of the exact plan (tests/core/test_response.py), so they differ by
    # 2 delta per entry at most; to first order the solution moves by at most
    # |K^-1|_2 (|dK|_2 |x| + |d rhs|) (|dK|_2 <= its Frobenius norm), times 2 for safety
    delta = 2 * 4 * moving.n_steps * np.finfo(float).eps * np.abs(response).max()
    d_response = delta * np.sqrt(response.size)  # Frobenius
    norm = np.linalg.norm(response)
    d_gram = 2 * norm * d_response + d_response**2
    d_kkt = d_gram * (1 + 1e-2) + 2 * delta * np.sqrt(8)  # the trace term, the border rows
    d_rhs = d_response * np.linalg.norm(residual) + norm * delta * np.sqrt(residual.size)
    d_rhs += delta
    inverse = np.linalg.norm(np.linalg.inv(kkt), 2)
    bound = 2 * inverse * (d_kkt * np.linalg.norm(solution) + d_rhs)
    np.testing.assert_allclose(dmp.weights[0], key, rtol=0, atol=bound)
    assert abs(plan(dmp.weights)[-1] - moving.positions[-1, 0]) < 1e-12


@pytest.mark.parametrize("form", ["phase", "energy"])
@pytest.mark.parametrize("method", ["least_squares", "lwr"])
def test_rhythmic_regressions_are_plain_least_squares(form, method):
    """tau = P / (2 pi); the canonical state on its limit cycle from phase 0 at the demo's
    first sample (t0 = 2.1 s): (phi, r) = (t / tau, A) for eq. (11), (x, tau x') = (A cos,
    -A sin)(t / tau) for eq. (13); the features of eqs. (12) and (14) with von Mises kernels;
    targets f = tau y' - z of eq. (15) with the periodic filter about the demo's mean; then
    ridge regression (lambda = 1e-3 trace / 2N) or LWR per basis function (2 x 2 weighted
    least squares, unnormalised psi)."""
    base = periodic_demo()
    demo = Trajectory.from_positions(base.times + 2.1, base.positions)  # 2.625 periods
    n_basis, amplitude, alpha_z, period = 8, 1.5, 20.0, 0.8
    dmp = fit_rhythmic(
        demo, n_basis, period=period, form=form, method=method, amplitude=amplitude,
        alpha_z=alpha_z, regularization=1e-3,
    )  # fmt: skip
    tau = period / (2 * np.pi)
    assert dmp.tau == pytest.approx(tau, rel=1e-15)
    t = demo.times - demo.times[0]
    angle = t / tau if form == "phase" else -t / tau
    carrier = amplitude * np.c_[np.cos(t / tau), np.sin(angle)]
    centres, widths = rhythmic_basis(n_basis, "von_mises")
    psi = np.exp(widths * (np.cos(angle[:, None] - centres) - 1.0))
    y, setpoint = demo.positions, demo.positions.mean(axis=0)
    z = np.empty_like(y)
    z[0] = tau * demo.velocities[0]
    for _ in range(2):
        for k in range(demo.n_steps - 1):
            decay = np.exp(-alpha_z * (demo.times[k + 1] - demo.times[k]) / tau)
            z[k + 1] = decay * z[k] + (1 - decay) * alpha_z / 4 * (setpoint - (y[k] + y[k + 1]) / 2)
        z[0] = z[-1]
    targets = tau * demo.velocities - z
    if method == "least_squares":
        normalised = psi / psi.sum(axis=1, keepdims=True)
        features = (normalised[:, :, None] * carrier[:, None, :]).reshape(len(t), -1)
        gram = features.T @ features
        ridge = 1e-3 * np.trace(gram) / (2 * n_basis)
        matrix = gram + ridge * np.eye(2 * n_basis)
        key = np.linalg.solve(matrix, features.T @ targets).T
        condition = np.linalg.cond(matrix)
    else:
        key, condition = np.empty((demo.n_dofs, n_basis, 2)), 1.0
        for i in range(n_basis):
            moments = (psi[:, i, None] * carrier).T @ carrier
            key[:, i] = np.linalg.solve(moments, (psi[:, i, None] * carrier).T @ targets).T
            condition = max(condition, np.linalg.cond(moments))
    actual = dmp.weights.reshape(demo.n_dofs, -1)
    key = key.reshape(demo.n_dofs, -1)
    # Error bound: the library and the key each form their matrices, right-hand sides and
    # targets from sums and recursions over the N samples, each within gamma_N ~ N eps of
    # the exact values (Higham 2002, Thm. 3.1); a relative perturbation d of a linear system
    # moves its solution by at most about kappa d (Thm. 7.2). Two such computations: 4 kappa
    # N eps of the largest weight (kappa 589 and 8.9 here: 1.0e-9 and 1.6e-11; measured
    # 2.1e-14 and 4.4e-12 on this machine with 1 or 2 BLAS threads and the Haswell and
    # Sandybridge kernels, 5.3e-13 for least squares on another of this kind, which failed
    # the former fixed 1e-13).
    tolerance = 4 * condition * demo.n_steps * np.finfo(float).eps
    np.testing.assert_allclose(actual, key, rtol=0, atol=tolerance * np.abs(key).max())


# ---------------------------------------------------------------------------------------
# Documented defaults and messages (found untested by mutation testing, docs/mutation.md)
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_discrete_defaults_sample_every_millisecond_until_convergence(form):
    """rollout() and affine_plan() last the settling time, at dt = 1 ms: tau (T_95 + T_9999).
    T_95 (closed form): the unforced system from rest is 95 % of the way (2 poles at -w in
    the velocity form, 3 in the acceleration form); T_9999: n poles at -w, the canonical and
    transformation systems together (n = 4 or 5), are 99.99 % of the way; stepper() steps 1 ms."""
    dmp, _ = discrete_case(form, seed=8)
    w = ALPHA / 2
    n = 2 if form == "velocity" else 3

    def remaining(s, n_poles):  # exp(-s) sum_{j<n} s^j / j!
        return np.exp(-s) * sum(s**j / np.prod(np.arange(1, j + 1)) for j in range(n_poles))

    reached = [
        brentq(lambda t: remaining(w * t, k) - f, 1e-3, 20) for k, f in ((n, 0.05), (n + 2, 1e-4))
    ]
    end = dmp.tau * sum(reached)
    for times in (dmp.rollout().times, dmp.affine_plan().times):
        assert times[1] - times[0] == pytest.approx(1e-3, rel=1e-12)
        assert times[-1] == pytest.approx(end, abs=0.5e-3 + 1e-7)
    assert dmp.stepper().dt == 1e-3


@pytest.mark.parametrize("form", ["phase", "energy"])
def test_rhythmic_defaults_are_three_periods_from_the_setpoint_at_phase_zero(form):
    """Period 2 pi tau (phase) or 2 pi tau / k (energy); the default plan starts at rest at
    the setpoint with the oscillator at phase 0: (0, A) or (A, 0)."""
    dmp, _ = rhythmic_case(form, seed=8)
    period = 2 * np.pi * dmp.tau / (1.0 if form == "phase" else 1.5)
    for plan in (dmp.rollout(), dmp.affine_plan().trajectory(dmp.forcing_weights())):
        assert plan.times[1] - plan.times[0] == pytest.approx(1e-3, rel=1e-12)
        assert plan.times[-1] == pytest.approx(3 * period, abs=0.5e-3 + 1e-9)
        np.testing.assert_allclose(plan.positions[0], dmp.setpoint, rtol=0, atol=1e-15)
    stepper = dmp.stepper()
    assert stepper.dt == 1e-3
    expected = (0.0, dmp.amplitude) if form == "phase" else (dmp.amplitude, 0.0)
    np.testing.assert_allclose(stepper.state[:2], expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(stepper.position, dmp.setpoint, rtol=0, atol=1e-15)


def test_stepper_constructed_directly_has_the_documented_defaults():
    """Stepper(dmp, dt, start): at rest (start_velocity 0), phase 0, interpreted, time 0;
    time advances by dt per step."""
    dmp, _ = discrete_case("velocity", seed=11)
    stepper = Stepper(dmp, 1e-3, dmp.start)
    np.testing.assert_array_equal(stepper.state, np.concatenate([[0, 0], dmp.start, [0, 0]]))
    rhythmic, _ = rhythmic_case("phase", seed=11)
    oscillator = Stepper(rhythmic, 1e-3, rhythmic.setpoint)
    np.testing.assert_allclose(oscillator.state[:2], [0.0, rhythmic.amplitude], atol=1e-15)
    np.testing.assert_allclose(oscillator.velocity, 0.0, atol=1e-12)
    assert stepper._function.function.class_name() == "SXFunction" and stepper.time == 0.0
    for _ in range(7):
        stepper.step()
    assert stepper.time == pytest.approx(7e-3, rel=1e-12)


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_coupling_lasts_one_step(form):
    """step(coupling=C) holds C over that step only."""
    errors = kick_errors(form, 1e-3)
    assert np.all(errors < FACTOR * np.array(MEASURED["kick", form])), errors


def test_compiled_stepper_matches_plain_equations():
    """compile=True generates and compiles C for the same step: same plan as the key."""
    dmp, eq = discrete_case("velocity", seed=1)
    times = grid(0.3, 1e-3)
    _, key = integrate(eq, initial_state(eq, dmp.start, 0.0, np.zeros(2)), times)
    stepper = dmp.stepper(1e-3, compile=True)
    assert stepper.compiled
    errors = relative_error(run_stepper(stepper, len(times)), key)
    assert np.all(errors < FACTOR * np.array(MEASURED["rollout", "velocity"])), errors


@pytest.mark.parametrize("n_basis", [0, -3, 2.5, True, "4"])
def test_basis_counts_must_be_positive_integers(n_basis):
    with pytest.raises(InvalidInputError, match="n_basis must be an integer >= 1"):
        discrete_basis(n_basis, GAINS)


def test_online_setters_name_their_argument():
    dmp, _ = discrete_case("velocity", seed=9)
    with pytest.raises(InvalidInputError, match="dt must be a finite number > 0"):
        Stepper(dmp, 0.0, dmp.start)
    with pytest.raises(
        ShapeError, match=r"start has shape \(3,\), expected \(2,\) to match 2 DOFs"
    ):
        Stepper(dmp, 1e-3, [1.0, 2.0, 3.0])
    with pytest.raises(
        ShapeError, match=r"start_velocity has shape \(3,\), expected \(2,\) to match 2 DOFs"
    ):
        Stepper(dmp, 1e-3, dmp.start, [1.0, 2.0, 3.0])
    with pytest.raises(ShapeError, match=r"goal has shape \(3,\), expected \(2,\) to match 2 DOFs"):
        dmp.stepper().set_goal([1.0, 2.0, 3.0])
    rhythmic, _ = rhythmic_case("phase", seed=9)
    with pytest.raises(InvalidInputError, match="amplitude must be a finite number > 0"):
        rhythmic.stepper().set_amplitude(-1.0)
    with pytest.raises(InvalidInputError, match="weights"):
        rhythmic.replace(weights=np.full((2, 8, 2), np.nan))


def test_an_energy_amplitude_whose_square_underflows_is_refused():
    """x^2 + v^2 of the energy form's limit cycle (x = A cos, v = A k sin) underflows below the
    smallest normal float, 2.2e-308, for k A < 1.5e-154: the phase's unit vector and the
    energy are lost (the plan was NaN), so the amplitude is refused by name, on the DMP and
    through the stepper; just above the limit the plan is finite."""
    rhythmic, _ = rhythmic_case("energy", seed=9)
    with pytest.raises(InvalidInputError, match=r"amplitude = 1e-300 is too small .* >= 1.5e-154"):
        rhythmic.replace(amplitude=1e-300)
    with pytest.raises(InvalidInputError, match="amplitude = 1e-160 is too small"):
        rhythmic.stepper().set_amplitude(1e-160)
    with pytest.raises(InvalidInputError, match=r">= 3e-154"):
        rhythmic.replace(amplitude=1e-160, k=0.5)
    plan = rhythmic.replace(amplitude=1e-150).rollout()
    assert np.all(np.isfinite(plan.positions))
    # the phase form has no such limit: its oscillator's radius is the amplitude itself
    phase, _ = rhythmic_case("phase", seed=9)
    assert np.all(np.isfinite(phase.replace(amplitude=1e-300).rollout().positions))


def test_save_keeps_an_npz_name_and_load_refuses_a_foreign_header(tmp_path):
    """save(dmp, "a.npz") writes a.npz (not a.npz.npz), save(dmp, "b") writes b.npz; a file
    whose header names another format is refused whatever its version."""
    dmp, _ = rhythmic_case("energy", seed=10, kernel="paper")
    assert dmpopt_io.save(dmp, tmp_path / "a.npz") == tmp_path / "a.npz"
    assert dmpopt_io.save(dmp, tmp_path / "b") == tmp_path / "b.npz"
    loaded = dmpopt_io.load(tmp_path / "a.npz")
    assert loaded.kernel == "paper"
    np.testing.assert_array_equal(loaded.weights, dmp.weights)
    header = {"format": "other", "version": 1, "class": "RhythmicDMP", "scalars": {}}
    np.savez(tmp_path / "c.npz", header=np.array(json.dumps(header)))
    with pytest.raises(FileFormatError, match="not a dmpopt DMP file"):
        dmpopt_io.load(tmp_path / "c.npz")


def test_rhythmic_weights_accept_the_flat_feature_layout_and_are_frozen_copies():
    """Weights (n_dofs, 2 n_basis), the layout of the features, mean (n_dofs, n_basis, 2);
    the DMP keeps a read-only copy; other shapes are refused naming the argument."""
    dmp, _ = rhythmic_case("phase", seed=13)
    flat = np.array(dmp.weights).reshape(2, 16)
    same = dmp.replace(weights=flat)
    assert same.weights.shape == (2, 8, 2) and not same.weights.flags.writeable
    np.testing.assert_array_equal(same.weights, dmp.weights)
    flat[0, 0] += 1.0
    np.testing.assert_array_equal(same.weights, dmp.weights)
    for shape in [(2, 15), (2, 8, 3), (16,)]:
        with pytest.raises(
            ShapeError, match=r"weights has shape .*expected \(n_dofs, n_basis, 2\)"
        ):
            dmp.replace(weights=np.ones(shape))
    with pytest.raises(
        ShapeError, match=r"setpoint has shape \(3,\), expected \(2,\) to match weights \(2, 8, 2\)"
    ):
        dmp.replace(setpoint=[0.0, 1.0, 2.0])


def test_narrow_bases_do_not_underflow():
    """Eq. (7)'s ratio psi_i / sum_j psi_j stays defined where every psi_j underflows
    (widths 1e7: between centres exp(-h (x - c)^2) < 1e-300); the plan is finite."""
    dmp, _ = discrete_case("velocity", seed=14)
    narrow = dmp.replace(widths=np.full(dmp.n_basis, 1e7))
    assert np.isfinite(plan_of(narrow.rollout(0.5, 1e-3))).all()


def test_a_one_element_coupling_applies_to_every_dof():
    dmp, _ = discrete_case("velocity", seed=15)
    one, each = dmp.stepper(1e-3), dmp.stepper(1e-3)
    for _ in range(50):
        np.testing.assert_array_equal(
            one.step(coupling=[5.0])[0], each.step(coupling=[5.0, 5.0])[0]
        )


# --- imitation targets, eqs. (15) and (16) ----------------------------------------------


def _unit_dmp(demo, form, alpha_z, tau):
    """A zero-weight DMP with the demo's start and goal (the fits' template)."""
    return random_discrete(
        n_dofs=demo.n_dofs,
        form=form,
        scale=0.0,
        start=demo.positions[0],
        goal=demo.positions[-1],
        tau=tau,
        alpha_z=alpha_z,
        goal_scaling="translation",
        reference_displacement=None,
    )


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    alpha_z=st.floats(5.0, 60.0),
    tau=st.floats(0.05, 2.0),
)
def test_velocity_form_targets_are_eq_15(seed, alpha_z, tau):
    """f = tau yd - z, tau zdot = alpha_z (beta_z (g - y) - z), beta_z = alpha_z / 4, z(0) =
    tau yd(0), integrated exactly over each step with y held at the step's midpoint."""
    demo = minimum_jerk_demo(seed=seed)
    dmp = _unit_dmp(demo, "velocity", alpha_z, tau)
    y, yd, g = demo.positions, demo.velocities, demo.positions[-1]
    beta_z = alpha_z / 4
    z = np.empty_like(y)
    z[0] = tau * yd[0]
    for k in range(demo.n_steps - 1):
        decay = np.exp(-alpha_z * (demo.times[k + 1] - demo.times[k]) / tau)
        held = beta_z * (g - 0.5 * (y[k] + y[k + 1]))  # z at rest for this y
        z[k + 1] = decay * z[k] + (1 - decay) * held
    expected = tau * yd - z
    actual = forcing_targets(dmp, demo, states=None)
    np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-10 * np.abs(expected).max())


def test_acceleration_form_targets_are_eq_16():
    """f = tau^2 ydd - alpha_z (beta_z (r - y) - tau yd), with the goal filter of eq. (10)
    from r(0) = y(0): r(t) = g + (y(0) - g) exp(-alpha_g t / tau), alpha_g = alpha_z / 2."""
    demo = minimum_jerk_demo(seed=4)
    tau, alpha_z = 0.3, 40.0
    dmp = _unit_dmp(demo, "acceleration", alpha_z, tau)
    y, yd, ydd, g = demo.positions, demo.velocities, demo.accelerations, demo.positions[-1]
    t = demo.times - demo.times[0]
    r = g + (y[0] - g) * np.exp(-alpha_z / 2 * t / tau)[:, None]
    expected = tau**2 * ydd - alpha_z * (alpha_z / 4 * (r - y) - tau * yd)
    states = np.hstack([np.zeros((demo.n_steps, 2 + 2 * demo.n_dofs)), r])  # only r is read
    actual = forcing_targets(dmp, demo, states)
    np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def test_periodic_filter_starts_on_its_steady_cycle():
    """Eq. (15) on a periodic demo: two passes of the exact filter, the second from where the
    first ended; the first sample takes the second pass's end (a plain loop as answer key)."""
    demo = periodic_demo()
    unit = fit_rhythmic(demo, 8, period=0.8).replace(weights=np.zeros((demo.n_dofs, 8, 2)))
    tau, alpha_z = unit.tau, unit.alpha_z
    y, g = demo.positions, unit.setpoint
    z = np.empty_like(y)
    z[0] = tau * demo.velocities[0]
    for _ in range(2):
        for k in range(demo.n_steps - 1):
            decay = np.exp(-alpha_z * (demo.times[k + 1] - demo.times[k]) / tau)
            z[k + 1] = decay * z[k] + (1 - decay) * alpha_z / 4 * (g - 0.5 * (y[k] + y[k + 1]))
        z[0] = z[-1]
    np.testing.assert_allclose(_filtered(unit, demo, periodic=True), z, rtol=1e-13, atol=1e-13)


def test_simulate_starts_its_samples_at_the_initial_state():
    """symbolic.simulate's first sample is the initial state given, not memory left by
    np.empty; the next one has moved on."""
    from dmpopt import symbolic

    signature = symbolic.Signature("velocity", 1, 1, "gaussian")
    initial = np.array([0.7, -0.4, 0.9, 0.3])
    values = symbolic.parameters(goal=1.0, canonical_target=1.0,
                                 gains=np.array([25.0, 6.25, 25.0, 6.25]))  # fmt: skip
    states, *_ = symbolic.simulate(signature, 2, initial, 1e-3, values)
    np.testing.assert_array_equal(states[0], initial)
    assert np.all(np.isfinite(states[1])) and not np.array_equal(states[1], initial)
