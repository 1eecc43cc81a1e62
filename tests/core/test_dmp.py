"""Properties of the DMP systems: invariances (Section 3.3), convergence, limit cycles."""

import ast
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from problems import random_discrete, random_rhythmic

from dmpopt import (
    DiscreteDMP,
    InvalidInputError,
    ResourceLimitError,
    ShapeError,
    Stepper,
    Trajectory,
    fit_discrete,
    stepper,
    symbolic,
)
from dmpopt.basis import discrete_phase
from dmpopt.dmp import goal_transform


def test_canonical_phase_matches_closed_form():
    """Eq. (6) normalised, critically damped: x(t) = 1 - (1 + s) exp(-s), s = alpha t / 2."""
    times = np.linspace(0.0, 0.5, 11)
    phase = discrete_phase((25.0, 6.25, 25.0, 6.25), tuple(times))
    s = 25.0 * times / 2
    np.testing.assert_allclose(phase, 1 - (1 + s) * np.exp(-s), atol=1e-12)


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_rollout_equals_direct_integration(form):
    """The affine rollout is the symbolic system integrated step by step."""
    dmp = random_discrete(seed=3, n_dofs=3, form=form)
    plan = dmp.rollout(0.6, 0.002)
    rows = [dmp.start, np.zeros(3)] + ([dmp.start] if form == "acceleration" else [])
    initial = np.concatenate([[0.0, 0.0], *rows])
    _, y, yd, ydd = symbolic.simulate(dmp.signature, plan.n_steps, initial, 0.002, dmp.parameters())
    np.testing.assert_allclose(plan.positions, y, atol=1e-12)
    np.testing.assert_allclose(plan.velocities, yd, atol=1e-10)
    np.testing.assert_allclose(plan.accelerations, ydd, atol=1e-8)


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_accelerations_are_derivatives_of_velocities(form):
    dmp = random_discrete(seed=1, form=form)
    plan = dmp.rollout(0.8, 0.0001)
    numeric = np.gradient(plan.velocities, plan.times, axis=0)
    scale = np.abs(plan.accelerations).max()
    np.testing.assert_allclose(numeric[20:-5], plan.accelerations[20:-5], atol=5e-4 * scale)


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_goal_scaling_from_zero_start_scales_plan(form):
    """Start 0, goal c g: the plan is c times the plan to g (Section 3.3)."""
    dmp = random_discrete(seed=2, form=form).replace(start=np.zeros(2))
    c = 2.7
    plan = dmp.rollout(0.6, 0.001).positions
    scaled = dmp.with_goal(c * dmp.goal).rollout(0.6, 0.001).positions
    np.testing.assert_allclose(scaled, c * plan, atol=1e-12 * np.abs(scaled).max())


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
@pytest.mark.parametrize("scaled_start_velocity", [0.0, [1.5, -0.7]])
def test_tau_scaling_stretches_time_exactly(form, scaled_start_velocity):
    """tau -> c tau with dt -> c dt gives the same positions at times scaled by c, also for a
    plan that starts moving (its start velocity is divided by c)."""
    dmp = random_discrete(seed=4, form=form, scaled_start_velocity=scaled_start_velocity)
    c = 1.9
    plan = dmp.rollout(0.5, 0.001)
    slow = dmp.with_tau(c * dmp.tau).rollout(c * 0.5, c * 0.001)
    np.testing.assert_allclose(slow.times, c * plan.times, rtol=1e-12)
    np.testing.assert_allclose(slow.positions, plan.positions, atol=1e-12)
    np.testing.assert_allclose(slow.velocities, plan.velocities / c, atol=1e-10)


def test_tau_scaling_at_fixed_step_is_accurate():
    dmp = random_discrete(seed=5)
    plan = dmp.rollout(0.5, 0.0005)
    slow = dmp.with_tau(2 * dmp.tau).rollout(1.0, 0.0005)
    np.testing.assert_allclose(slow.positions[::2], plan.positions, atol=2e-6)


def test_translation_translates_plan():
    dmp = random_discrete(seed=6, n_dofs=3)
    shift = np.array([0.3, -1.2, 2.0])
    plan = dmp.rollout(0.6).positions
    moved = dmp.replace(start=dmp.start + shift, goal=dmp.goal + shift).rollout(0.6).positions
    np.testing.assert_allclose(moved, plan + shift, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(angle=st.floats(-np.pi, np.pi), scale=st.floats(0.05, 20.0))
def test_rotation_scaling_maps_plan(angle, scale):
    """In rotation mode the plan to a rotated, scaled goal is the plan rotated and scaled,
    its start velocity included."""
    dmp = random_discrete(seed=7, scaled_start_velocity=[0.8, -0.5])
    rotation = scale * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    plan = dmp.rollout(0.6)
    goal = dmp.start + rotation @ (dmp.goal - dmp.start)
    moved = dmp.with_goal(goal).rollout(0.6)
    expected = dmp.start + (plan.positions - dmp.start) @ rotation.T
    np.testing.assert_allclose(moved.positions, expected, atol=1e-9 * max(1.0, scale))
    np.testing.assert_allclose(moved.velocities[0], rotation @ [0.8, -0.5] / dmp.tau)


def test_paper_scaling_scales_each_dof():
    """Paper mode: y_d' - y0_d = (y_d - y0_d) (g_d' - y0_d) / (g_d - y0_d), start velocity
    included (the invariance of Section 3.3, per DOF)."""
    dmp = random_discrete(
        seed=14, goal_scaling="paper", reference_displacement=None, scaled_start_velocity=[2, 1]
    )
    plan = dmp.rollout(0.6).positions
    goal = dmp.start + np.array([-0.3, 2.5]) * (dmp.goal - dmp.start)
    moved = dmp.with_goal(goal).rollout(0.6).positions
    expected = dmp.start + (plan - dmp.start) * np.array([-0.3, 2.5])
    np.testing.assert_allclose(moved, expected, atol=1e-12 * np.abs(plan).max())


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_translation_moves_plan_by_at_most_the_goal_change(form):
    """Translation mode: y' - y = e(t) delta, the unforced response from rest to a goal step
    delta; for the velocity form, critically damped, e = 1 - (1 + s) exp(-s), s = alpha t / 2 tau.
    """
    dmp = random_discrete(
        seed=15,
        form=form,
        goal_scaling="translation",
        reference_displacement=None,
        scaled_start_velocity=[3.0, -1.0],
    )
    delta = np.array([0.4, -1.1])
    plan = dmp.rollout(1.0).positions
    change = dmp.with_goal(dmp.goal + delta).rollout(1.0).positions - plan
    response = change @ delta / (delta @ delta)
    np.testing.assert_allclose(change, np.outer(response, delta), atol=1e-12)
    assert np.all(response >= -1e-12) and np.all(response <= 1 + 1e-12)
    if form == "velocity":
        s = dmp.alpha_z * np.arange(len(plan)) * 0.001 / (2 * dmp.tau)
        np.testing.assert_allclose(response, 1 - (1 + s) * np.exp(-s), atol=1e-8)


def _erlang_remaining(s, n_poles):
    """Distance left to the goal at s of the step response of n poles at -1:
    exp(-s) sum_{j<n} s^j / j!."""
    return np.exp(-s) * sum(s**j / math.factorial(j) for j in range(n_poles))


@pytest.mark.parametrize("form, n_poles", [("velocity", 4), ("acceleration", 5)])
@pytest.mark.parametrize("alpha_v", [25.0, 5.0])
def test_default_duration_is_the_settling_time(form, n_poles, alpha_v):
    """Closed forms. The velocity form from rest, critically damped: 1 - (1 + s) exp(-s)
    reaches 95 % at the convergence time (s = alpha_z t / 2 tau). Then the canonical (2 poles
    at -alpha_v / 2) and transformation systems (2 at -alpha_z / 2, the goal filter at
    -alpha_g = -alpha_z / 2) are counted as n poles at the slowest rate r: the plan goes on
    until exp(-r t) sum_{j<n} (r t)^j / j! = 1e-4."""
    from scipy.optimize import brentq

    dmp = random_discrete(seed=16, form=form).replace(alpha_v=alpha_v, beta_v=alpha_v / 4)
    rate = dmp.alpha_z / (2 * dmp.tau)
    if form == "velocity":
        reached = brentq(lambda s: (1 + s) * np.exp(-s) - 0.05, 0.1, 50)
        assert dmp.convergence_time == pytest.approx(reached / rate, rel=1e-5)
    slowest = min(dmp.alpha_z, alpha_v) / (2 * dmp.tau)
    settle = brentq(lambda s: _erlang_remaining(s, n_poles) - 1e-4, 0.1, 100) / slowest
    assert dmp.settling_time == pytest.approx(dmp.convergence_time + settle, rel=1e-9)
    assert dmp.rollout(dt=0.002).times[-1] == pytest.approx(dmp.settling_time, abs=0.002)


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
@pytest.mark.parametrize("alpha_v", [25.0, 10.0, 5.0, 1.0])
def test_default_rollout_of_a_demo_ending_in_motion_ends_at_rest_at_its_goal(form, alpha_v):
    """The demo ends at 3.7 units/s (the README's); whatever the phase's speed, the default plan
    ends within 1 - SETTLING_FRACTION = 1e-4 of the movement's extent from the goal, with a
    speed below 1e-4 extents per second (the fraction the settling time is built for; a
    settling time that ignored alpha_v ended 7-259 % of the extent away at alpha_v = 10-1)."""
    times = np.linspace(0.0, 1.0, 500)
    demo = Trajectory.from_positions(times, np.c_[np.sin(np.pi * times), times**2])
    dmp = fit_discrete(demo, 30, form=form, alpha_v=alpha_v)
    plan = dmp.rollout()
    extent = np.linalg.norm(demo.positions - demo.positions[0], axis=1).max()
    assert np.linalg.norm(plan.positions[-1] - demo.positions[-1]) < 1e-4 * extent
    assert np.linalg.norm(plan.velocities[-1]) < 1e-4 * extent


def test_a_phase_far_slower_than_the_movement_is_refused():
    """Bound MAX_PHASE_SLOWDOWN = 50 on the ratio of the slowest rates, alpha_z / alpha_v for
    critically damped systems."""
    dmp = random_discrete(seed=16)
    assert dmp.replace(alpha_v=0.5, beta_v=None).alpha_v == 0.5
    with pytest.raises(InvalidInputError) as error:
        dmp.replace(alpha_v=0.001, beta_v=None)
    assert str(error.value) == (
        "alpha_v = 0.001, beta_v = 0.00025 make the canonical system (6) 2.5e+04 times slower "
        "than the transformation system (slowest rates 0.0005 and 12.5 per tau); at most 50 "
        "times is accepted, as the forcing term would outlast the movement and the default "
        "plan (settling_time) last hundreds of its durations: pass alpha_v >= 0.5 (with "
        "beta_v = alpha_v / 4)"
    )


def test_a_stepper_too_large_to_build_is_refused_before_building():
    """10^5 bases on 2 DOFs: 10^5 x (48 kB + 2 x 8 kB) = 5.96 GiB estimated for the symbolic
    step, beyond the 2 GiB budget (it once took 183 s and 4.8 GB before a stepper existed)."""
    n_basis = 10**5
    dmp = DiscreteDMP(
        np.zeros((2, n_basis)),
        [0.0, 0.0],
        [1.0, 1.0],
        1.0,
        np.linspace(0.0, 1.0, n_basis),
        np.full(n_basis, 1e10),
        goal_scaling="translation",
    )
    with pytest.raises(ResourceLimitError) as error:
        dmp.stepper()
    assert str(error.value) == (
        "the symbolic step of 2 DOFs x 100000 basis features (a stepper's) needs about "
        f"{6.4e9 / 1024**3:.3g} GiB; dmpopt allows at most 2 GiB (dmpopt.validation."
        "MEMORY_BUDGET): use fewer basis functions (the step grows with their number times "
        "the DOFs)"
    )


def test_a_goal_near_the_float_range_is_the_plan_scaled():
    """Goal [1e200, 1e200] under "rotation": the plan is the original about the start,
    rotated and scaled by |g' - y0| / |g - y0| (module docstring), finite (the norm of the
    displacement once overflowed into a NaN start velocity that was blamed)."""
    dmp = random_discrete(seed=16, scaled_start_velocity=[0.5, -0.2])
    far = dmp.with_goal([1e200, 1e200])
    plan, original = far.rollout(0.5), dmp.rollout(0.5)
    np.testing.assert_allclose(dmp.goal_map(), np.eye(2), atol=1e-15)  # its demonstrated goal
    mapped = dmp.start + (original.positions - dmp.start) @ far.goal_map().T
    assert np.all(np.isfinite(plan.positions)) and np.all(np.isfinite(plan.accelerations))
    np.testing.assert_allclose(plan.positions, mapped, rtol=1e-9, atol=1e-9 * 1e200)


def test_fast_gains_are_integrated_at_a_step_they_allow():
    """alpha_z = alpha_v = 1e6 (once "cannot convert float NaN to integer"): the same system
    as the defaults with tau divided by 4e4, so the convergence time in tau is 25/1e6 times
    the default one."""
    default = random_discrete(seed=16)
    fast = default.replace(alpha_z=1e6, beta_z=None, alpha_v=1e6, beta_v=None, alpha_g=None)
    ratio = fast.convergence_time / default.convergence_time
    assert ratio == pytest.approx(25.0 / 1e6, rel=1e-6)


def test_stepper_and_affine_plan_start_like_the_rollout():
    """Their default start velocity is the DMP's, as for rollout()."""
    dmp = random_discrete(seed=17, scaled_start_velocity=[-2.0, 0.5])
    plan = dmp.rollout(0.1, 0.001)
    stepper = dmp.stepper(0.001)
    stepped = [stepper.position] + [stepper.step()[0] for _ in range(100)]
    np.testing.assert_allclose(stepped, plan.positions, atol=1e-12)
    np.testing.assert_allclose(plan.velocities[0], [-2.0 / 0.4, 0.5 / 0.4], rtol=1e-12)
    affine = dmp.affine_plan(0.1, 0.001).evaluate(dmp.forcing_weights())[0]
    np.testing.assert_allclose(affine, plan.positions, atol=1e-12)


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    scale=st.floats(0.0, 500.0),
    form=st.sampled_from(["velocity", "acceleration"]),
)
def test_converges_to_goal_for_bounded_weights(seed, scale, form):
    dmp = random_discrete(seed=seed, form=form, scale=scale)
    plan = dmp.rollout(8 * dmp.convergence_time, 0.002)
    distance = np.linalg.norm(dmp.goal - dmp.start)
    assert np.all(np.isfinite(plan.positions))
    np.testing.assert_allclose(plan.positions[-1], dmp.goal, atol=1e-6 * max(distance, 1.0))
    np.testing.assert_allclose(plan.velocities[-1], 0.0, atol=1e-5 * max(distance, 1.0))


def test_paper_goal_scaling_vanishes_when_goal_equals_start():
    """The paper's (g - y0) factor: no forcing term when start and goal coincide."""
    dmp = random_discrete(seed=8, goal_scaling="paper", reference_displacement=None)
    still = dmp.with_goal(dmp.start).rollout(0.6).positions
    np.testing.assert_allclose(still, np.broadcast_to(dmp.start, still.shape), atol=1e-12)


def test_rotation_mode_handles_opposite_goal():
    """A goal on the other side of the start (sign flip) gives the half-turned plan."""
    dmp = random_discrete(seed=9)
    plan = dmp.rollout(0.6).positions
    flipped = dmp.with_goal(2 * dmp.start - dmp.goal).rollout(0.6).positions
    np.testing.assert_allclose(flipped, 2 * dmp.start - plan, atol=1e-9)


@pytest.mark.parametrize("form, tolerance", [("phase", 1e-12), ("energy", 1e-7)])
def test_amplitude_scales_oscillation(form, tolerance):
    """Exact for the phase oscillator; for the energy oscillator up to the RK4 drift off
    the limit cycle, whose correction rate depends on the energy (eq. 13)."""
    dmp = random_rhythmic(seed=1, form=form, setpoint=np.zeros(2))
    plan = dmp.rollout(2.0, 0.001).positions
    scaled = dmp.with_amplitude(2.5).rollout(2.0, 0.001).positions
    np.testing.assert_allclose(scaled, 2.5 * plan, atol=tolerance)


@pytest.mark.parametrize("form", ["phase", "energy"])
def test_rhythmic_time_scaling_and_setpoint_translation(form):
    dmp = random_rhythmic(seed=2, form=form)
    plan = dmp.rollout(1.0, 0.001)
    slow = dmp.with_tau(2 * dmp.tau).rollout(2.0, 0.002)
    np.testing.assert_allclose(slow.positions, plan.positions, atol=1e-12)
    moved = dmp.with_setpoint(dmp.setpoint + 1.5).rollout(1.0, 0.001)
    np.testing.assert_allclose(moved.positions, plan.positions + 1.5, atol=1e-12)


@pytest.mark.parametrize("form", ["phase", "energy"])
def test_limit_cycle_attracts_perturbed_state(form):
    """From a perturbed oscillator and position, the plan converges to the same cycle."""
    dmp = random_rhythmic(seed=3, form=form)
    n = int(round(6 * dmp.period / 0.001)) + 1
    canonical = np.array(dmp.canonical_state(0.0))
    reference = np.concatenate([canonical, dmp.setpoint, np.zeros(2)])
    perturbed = reference + np.concatenate([[0.6 * canonical[0], 0.3], [0.5, -0.4], [2.0, 1.0]])
    if form == "phase":
        perturbed[0] = reference[0]  # the phase itself has no restoring force
    runs = [
        symbolic.simulate(dmp.signature, n, x0, 0.001, dmp.parameters())
        for x0 in (reference, perturbed)
    ]
    period_steps = int(round(dmp.period / 0.001))
    last = slice(n - period_steps, n)
    if form == "phase":
        np.testing.assert_allclose(runs[1][1][last], runs[0][1][last], atol=1e-6)
    else:  # the energy oscillator restores its amplitude, not its phase
        for statistic in (np.min, np.max, np.mean):
            np.testing.assert_allclose(
                statistic(runs[1][1][last], axis=0),
                statistic(runs[0][1][last], axis=0),
                atol=2e-3,
            )
        x, v = runs[1][0][-1, :2]
        energy = 0.5 * (v**2 + dmp.k**2 * x**2)
        assert abs(energy - 0.5 * dmp.amplitude**2) < 1e-6


def test_rhythmic_plan_is_periodic():
    dmp = random_rhythmic(seed=4)
    step = 0.0005
    plan = dmp.rollout(4 * dmp.period, step).positions
    k = int(round(dmp.period / step))
    # the period is 2 pi tau, not a multiple of the step: compare by interpolation
    times = np.arange(len(plan)) * step
    shifted = np.array([np.interp(times[-k // 2 :] - dmp.period, times, p) for p in plan.T]).T
    np.testing.assert_allclose(shifted, plan[-k // 2 :], atol=1e-5)


def test_affine_plan_matches_rollout():
    dmp = random_discrete(seed=11, form="acceleration")
    plan = dmp.affine_plan(0.5, 0.001)
    trajectory = dmp.rollout(0.5, 0.001)
    np.testing.assert_allclose(
        plan.evaluate(dmp.forcing_weights())[2], trajectory.accelerations, atol=1e-9
    )


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"tau": 0.0}, "tau must be a finite number > 0, got"),
        ({"tau": -1.0}, "tau must be a finite number > 0, got"),
        ({"goal": np.zeros(3)}, r"goal has shape \(3,\), expected \(2,\)"),
        ({"weights": np.full((2, 20), np.nan)}, "weights contains 40 NaN"),
        ({"form": "jerk"}, "form must be one of"),
        ({"goal_scaling": "bogus"}, "goal_scaling must be one of"),
        ({"reference_displacement": np.zeros(2)}, "reference_displacement is zero"),
        ({"scaled_start_velocity": np.zeros(3)}, r"scaled_start_velocity has shape \(3,\)"),
        ({"scaled_start_velocity": [np.inf, 0.0]}, "scaled_start_velocity contains"),
    ],
)
def test_bad_parameters_name_the_argument(changes, message):
    dmp = random_discrete()
    with pytest.raises((InvalidInputError, ShapeError), match=message):
        dmp.replace(**changes)


def test_bad_rollout_arguments():
    dmp = random_discrete()
    with pytest.raises(InvalidInputError, match="dt must be a finite number > 0, got"):
        dmp.rollout(1.0, dt=0.0)
    with pytest.raises(InvalidInputError, match="duration 0.001 is shorter than two steps"):
        dmp.rollout(0.001, dt=0.001)
    with pytest.raises(ShapeError, match="start_velocity has shape"):
        dmp.rollout(1.0, start_velocity=np.zeros(5))


def test_parameters_are_immutable():
    dmp = random_discrete()
    with pytest.raises(ValueError):
        dmp.weights[0, 0] = 1.0
    assert isinstance(dmp.with_goal(dmp.goal + 1), DiscreteDMP)


@pytest.mark.parametrize("form", ["acceleration", "energy"])
def test_symbolic_rollout_function_matches_numeric_integration(form):
    """The MX rollout (one call, differentiable) and the stepped integration agree."""
    dmp = (
        random_discrete(seed=12, form=form)
        if form == "acceleration"
        else random_rhythmic(seed=12, form=form)
    )
    n = 200
    canonical = (0.0, 0.0) if form == "acceleration" else dmp.canonical_state(0.0)
    rows = [dmp.parameters()["goal"], np.zeros(2)]
    rows += [rows[0]] if form == "acceleration" else []
    initial = np.concatenate([canonical, *rows])
    rollout = symbolic.rollout_function(dmp.signature, n)
    positions = rollout(initial_state=initial, dt=0.002, **dmp.parameters())["positions"]
    positions = positions.full().T
    stepped = symbolic.simulate(dmp.signature, n, initial, 0.002, dmp.parameters())[1]
    np.testing.assert_allclose(positions, stepped, atol=1e-12)


def test_phase_features_sum_to_the_phase_velocity():
    """Normalised activations sum to one, so the features of eq. (7) sum to v (eq. 6)."""
    dmp = random_discrete(seed=13)
    features = dmp.phase_features(300, 0.002)
    s = dmp.alpha_v * np.arange(300) * 0.002 / (2 * dmp.tau)
    velocity = dmp.alpha_v / 2 * s * np.exp(-s)  # d/dt' of 1 - (1 + s) e^-s, tau = 1
    np.testing.assert_allclose(features.sum(axis=1), velocity, atol=1e-5)  # RK4, dt/tau = 0.005


@pytest.mark.parametrize(
    "former, new, form",
    [
        ("time_constant", "tau", "velocity"),
        ("stiffness", "alpha_z", "velocity"),
        ("damping", "beta_z", "acceleration"),
        ("phase_stiffness", "alpha_v", "velocity"),
        ("phase_damping", "beta_v", "velocity"),
        ("goal_rate", "alpha_g", "acceleration"),
        ("amplitude_rate", "alpha_r", "phase"),
        ("amplitude_rate", "alpha_E", "energy"),
        ("frequency", "k", "energy"),
    ],
)
def test_a_former_field_name_is_refused_with_the_new_one(former, new, form):
    """One name per concept: the old names (stiffness/damping now mean Kp/Kd of control)."""
    dmp = random_rhythmic(form=form) if form in ("phase", "energy") else random_discrete(form=form)
    message = f"no field '{former}': it is now '{new}'.*pass {new}=2.5"
    with pytest.raises(InvalidInputError, match=message):
        dmp.replace(**{former: 2.5})
    fields = {f.name: getattr(dmp, f.name) for f in dataclasses.fields(dmp) if f.init}
    with pytest.raises(InvalidInputError, match=message):
        type(dmp)(**fields, **{former: 2.5})


def test_goal_transform_maps_the_reference_onto_the_new_displacement():
    """ "rotation": a rotation times a uniform scale with M d = d'; "paper": diag(d' / d);
    "translation": the identity."""
    rng = np.random.default_rng(3)
    reference, displacement = rng.normal(size=4), rng.normal(size=4)
    rotation = goal_transform("rotation", reference, displacement)
    np.testing.assert_allclose(rotation @ reference, displacement, atol=1e-12)
    scale = np.linalg.norm(displacement) / np.linalg.norm(reference)
    np.testing.assert_allclose(rotation.T @ rotation, scale**2 * np.eye(4), atol=1e-12)
    assert np.linalg.det(rotation) > 0  # a rotation, not a reflection
    paper = goal_transform("paper", reference, displacement)
    np.testing.assert_allclose(paper, np.diag(displacement / reference), rtol=1e-15)
    assert np.array_equal(goal_transform("translation", reference, displacement), np.eye(4))
    with pytest.raises(InvalidInputError, match="goal_scaling must be one of"):
        goal_transform("auto", reference, displacement)


def test_goal_map_of_a_dmp_is_its_goal_transform():
    """The DMP's own map: "paper" weights are stored per unit of goal - start."""
    dmp = random_discrete(seed=8)
    new_goal = dmp.goal + np.array([0.3, -0.7])
    displacement = new_goal - dmp.start
    rotation = goal_transform("rotation", dmp.reference_displacement, displacement)
    np.testing.assert_array_equal(dmp.goal_map(goal=new_goal), rotation)
    paper = dmp.replace(goal_scaling="paper", reference_displacement=None)
    np.testing.assert_array_equal(paper.goal_map(goal=new_goal), np.diag(displacement))


def test_the_stepper_does_not_import_the_dmp_module():
    """No import cycle dmp <-> stepper: dmp.py imports the stepper, never the reverse."""
    tree = ast.parse(Path(stepper.__file__).read_text())
    imported = {
        node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
    } | {
        alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
    }
    assert not any(name.endswith("dmp") for name in imported), imported


def test_a_stepper_refuses_what_is_not_a_dmp():
    with pytest.raises(InvalidInputError, match="dmp must be a DiscreteDMP or RhythmicDMP, got"):
        Stepper(object(), 0.001, [0.0])


def test_similarity_transform_of_unit_and_zero_targets():
    """A unit-length target is an ordinary one; a zero target (goal = start) maps to zero."""
    source = np.array([3.0, 4.0])
    target = np.array([0.6, -0.8])  # norm exactly 1
    matrix = goal_transform("rotation", source, target)
    np.testing.assert_allclose(matrix @ source, target, atol=1e-15)
    np.testing.assert_array_equal(goal_transform("rotation", source, np.zeros(2)), np.zeros((2, 2)))


@pytest.mark.parametrize("n_dofs", [2, 3, 5])
def test_similarity_transform_half_turn(n_dofs):
    """Opposite vectors: a half turn in a plane containing them (a rotation, det = +1)."""
    source = np.random.default_rng(n_dofs).normal(size=n_dofs)
    matrix = goal_transform("rotation", source, -2.0 * source)
    np.testing.assert_allclose(matrix @ source, -2.0 * source, atol=1e-12)
    np.testing.assert_allclose(matrix.T @ matrix, 4.0 * np.eye(n_dofs), atol=1e-12)
    assert np.linalg.det(matrix / 2.0) == pytest.approx(1.0)


@pytest.mark.parametrize("target, expected", [(3.0, 1.5), (-3.0, -1.5)])
def test_similarity_transform_in_one_dimension_is_a_signed_scale(target, expected):
    matrix = goal_transform("rotation", np.array([2.0]), np.array([target]))
    np.testing.assert_array_equal(matrix, [[expected]])


def test_symbolic_parameters_refuse_an_unknown_name():
    assert symbolic.parameters(goal=2.0)["tau"] == 1.0
    with pytest.raises(ValueError, match=r"unknown parameters \['time_constant'\]"):
        symbolic.parameters(time_constant=1.0)


def test_half_turn_along_a_coordinate_axis():
    """The helper axis of the half turn is the one least aligned with the vectors, never
    the axis they lie on."""
    matrix = goal_transform("rotation", np.array([1.0, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0]))
    np.testing.assert_allclose(matrix @ [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(matrix.T @ matrix, np.eye(3), atol=1e-15)


# ---------------------------------------------------------------- checks by name, stored values
def test_discrete_dmp_stores_read_only_float_arrays_and_names_each_bad_argument():
    """Lists and integers are stored as read-only float arrays and Python floats; each bad
    argument is refused with its own name and what fixes its size."""
    arguments = dict(
        weights=[[0, 1, 2], [3, 4, 5]], start=[0, 1], goal=[1, 3], tau=2, centres=[1, 0.5, 0.1],
        widths=[1, 2, 3], reference_displacement=[1, 2], alpha_z=np.array(24), beta_z=6,
        alpha_v=np.int64(20), beta_v=5, alpha_g=12,
    )  # fmt: skip
    dmp = DiscreteDMP(**arguments)
    for name in ("weights", "start", "goal", "centres", "widths", "reference_displacement",
                 "scaled_start_velocity"):  # fmt: skip
        value = getattr(dmp, name)
        assert isinstance(value, np.ndarray) and value.dtype == float, name
        assert not value.flags.writeable, name
    for name in ("tau", "alpha_z", "beta_z", "alpha_v", "beta_v", "alpha_g"):
        assert type(getattr(dmp, name)) is float, name
    bad = {
        "centres": ([0.5, 0.1], r"^centres has shape \(2,\), expected \(3,\) to match 3 basis "
                                r"functions$"),
        "widths": ([1, 2], r"^widths has shape \(2,\), expected \(3,\) to match 3 basis "
                           r"functions$"),
        "reference_displacement": ([1, 2, 3], r"^reference_displacement has shape \(3,\), "
                                              r"expected \(2,\) to match weights$"),
        "weights": (np.zeros((0, 3)), r"^weights has shape \(0, 3\): a DMP needs at least one "
                                      r"DOF"),
        "start": ([0, 1, 2], r"^start has shape \(3,\), expected \(2,\) to match weights "
                             r"\(2, 3\)$"),
    }  # fmt: skip
    for name, (value, message) in bad.items():
        with pytest.raises(ShapeError, match=message):
            DiscreteDMP(**{**arguments, name: value})
    for widths in ([1, 0, 3], [1, -2, 3]):
        with pytest.raises(InvalidInputError, match="^widths must all be positive"):
            DiscreteDMP(**{**arguments, "widths": widths})
    for name in ("tau", "alpha_z", "beta_z", "alpha_v", "beta_v", "alpha_g"):
        with pytest.raises(InvalidInputError, match=f"^{name} must be"):
            DiscreteDMP(**{**arguments, name: 0.0})


def test_rhythmic_dmp_stores_read_only_floats_and_names_each_bad_argument():
    from dmpopt import RhythmicDMP

    arguments = dict(
        weights=np.zeros((2, 3, 2)), setpoint=[0, 1], tau=1, centres=[0, 2, 4], widths=[1, 1, 1],
        amplitude=2, alpha_r=np.array(3), alpha_E=4, k=1,
    )  # fmt: skip
    dmp = RhythmicDMP(**arguments)
    assert isinstance(dmp.setpoint, np.ndarray) and not dmp.setpoint.flags.writeable
    assert dmp.setpoint.dtype == float
    for name in ("tau", "amplitude", "alpha_r", "alpha_E", "k"):
        assert type(getattr(dmp, name)) is float, name
        with pytest.raises(InvalidInputError, match=f"^{name} must be"):
            RhythmicDMP(**{**arguments, name: 0.0})
    flat = RhythmicDMP(**{**arguments, "weights": np.arange(12.0).reshape(2, 6)})
    np.testing.assert_array_equal(flat.weights, np.arange(12.0).reshape(2, 3, 2))
    with pytest.raises(ShapeError, match=r"^weights has shape \(0, 3, 2\): a DMP needs"):
        RhythmicDMP(**{**arguments, "weights": np.zeros((0, 3, 2))})
    with pytest.raises(InvalidInputError, match="^weights must be an array of real numbers"):
        RhythmicDMP(**{**arguments, "weights": "flat"})
    assert dmp.canonical_state() == dmp.canonical_state(0.0)
    with pytest.raises(InvalidInputError, match="^phase"):
        dmp.canonical_state("east")


def test_memory_estimates_of_plans_and_features_in_bytes(monkeypatch):
    """A plan of n steps holds 8 n (6 (y, z, goal and the N features) + 6 D) bytes, the phase
    features 8 n (2 N + 8): with the budget lowered below them, the refusals print these
    sizes (3 digits) and the remedy; a plan over 1/16 of the budget is computed without the
    response cache and equals the cached one."""
    from dmpopt import validation

    dmp = DiscreteDMP(
        weights=np.arange(6.0).reshape(2, 3), start=[0, 1], goal=[1, 3], tau=1.0,
        centres=[1, 0.5, 0.1], widths=[1, 2, 3], goal_scaling="translation",
    )  # fmt: skip
    cached = dmp.rollout(1.0, 1e-3)
    n, plan_bytes, feature_bytes = 1001, 8 * 1001 * (6 * (2 + 1 + 3) + 6 * 2), 8 * 1001 * (6 + 8)
    assert plan_bytes > 16 * feature_bytes / 5
    monkeypatch.setattr(validation, "MEMORY_BUDGET", 1.5 * plan_bytes)  # < 24 n (3 + N) 16
    uncached = dmp.rollout(1.0, 1e-3)
    np.testing.assert_array_equal(uncached.positions, cached.positions)
    monkeypatch.setattr(validation, "MEMORY_BUDGET", 0.9 * feature_bytes)
    budget = f"{0.9 * feature_bytes / 1024**3:.3g}"
    with pytest.raises(ResourceLimitError) as refused:
        dmp.rollout(1.0, 1e-3)
    assert str(refused.value) == (
        f"a plan of 1 s at dt = 0.001 s needs {n:.3g} samples and about "
        f"{plan_bytes / 1024**3:.3g} GiB; dmpopt allows at most {validation.MAX_SAMPLES:.3g} "
        f"samples (dmpopt.validation.MAX_SAMPLES) and {budget} GiB "
        "(dmpopt.validation.MEMORY_BUDGET): raise dt or shorten duration (by default the "
        "convergence time or three periods, both proportional to tau)"
    )
    with pytest.raises(ResourceLimitError) as refused:
        dmp.phase_features(n, 1e-3)
    assert str(refused.value).startswith(
        f"phase_features({n}, 0.001) needs {n:.3g} samples and about "
        f"{feature_bytes / 1024**3:.3g} GiB;"
    )
    assert str(refused.value).endswith(": ask for fewer samples")
    assert dmp.phase_features(1, 1e-3).shape == (1, 3)  # one sample is allowed
    with pytest.raises(InvalidInputError, match="^n_steps"):
        dmp.phase_features(0, 1e-3)
    with pytest.raises(InvalidInputError, match="^duration"):
        dmp.rollout(0.0, 1e-3)


def test_plan_bits_do_not_depend_on_the_layout_of_the_weights():
    """A DMP made from weights in another memory layout (the DOFs' axis last in memory, as a
    fit's transposed solution gives), and its pickled copy (what a worker process of
    dmpopt.parallel receives), give bitwise the same stepper and rollout as the DMP made from
    C-ordered weights: the same values give the same bits in any process. (Kept in the given
    layout, the product forcing_weights() @ features at the stepper's start rounds
    differently: up to 2e-11 here, 5e-14 m/s^2 for the humanoid study's drumming.)"""
    import pickle

    rng = np.random.default_rng(11)
    base = random_rhythmic(seed=11, n_dofs=11, n_basis=15)
    weights = 50.0 * rng.normal(size=(11, 15, 2))
    transposed = np.ascontiguousarray(weights.transpose(1, 2, 0)).transpose(2, 0, 1)
    np.testing.assert_array_equal(transposed, weights)
    assert not transposed.flags.c_contiguous
    reference = base.replace(weights=np.ascontiguousarray(weights))
    other = base.replace(weights=transposed)
    for dmp in (other, pickle.loads(pickle.dumps(other))):
        a = reference.stepper(0.001, on_limit_cycle=True)
        b = dmp.stepper(0.001, on_limit_cycle=True)
        np.testing.assert_array_equal(b.acceleration, a.acceleration)
        for _ in range(3):
            for mine, theirs in zip(b.step(), a.step()):
                np.testing.assert_array_equal(mine, theirs)
        plan, expected = dmp.rollout(0.05, 0.001), reference.rollout(0.05, 0.001)
        np.testing.assert_array_equal(plan.accelerations, expected.accelerations)


def test_rhythmic_affine_plan_defaults_are_rest_at_phase_zero():
    """RhythmicDMP.affine_plan() starts at rest with the oscillator at phase 0: the same plan
    as with both given, unlike a start velocity of 1 or a phase of 1 rad."""
    from dmpopt import RhythmicDMP

    dmp = RhythmicDMP(weights=np.arange(12.0).reshape(2, 3, 2), setpoint=[0, 1], tau=0.5,
                      centres=[0, 2, 4], widths=[1, 1, 1])  # fmt: skip
    default = dmp.affine_plan(2.0).evaluate(dmp.forcing_weights())
    given = dmp.affine_plan(2.0, start_velocity=0.0, phase=0.0).evaluate(dmp.forcing_weights())
    np.testing.assert_array_equal(default, given)
    for other in (dict(start_velocity=1.0), dict(phase=1.0)):
        moved = dmp.affine_plan(2.0, **other).evaluate(dmp.forcing_weights())
        assert np.abs(moved - default).max() > 1e-3


@pytest.mark.parametrize(
    "changes",
    [{"goal": [0.3, -2.0]}, {"start": [1.0, 1.0]}, {"tau": 0.5}, {"alpha_v": 5.0}],
    ids=lambda changes: next(iter(changes)),
)
def test_a_changed_copy_plans_as_a_dmp_built_afresh(changes):
    """``replace`` keeps the last plan's response and the step limit only when the change is
    where the movement goes (goal, start): every copy's plans equal those of the same DMP
    constructed from its fields, with nothing kept (a copy keeping them after a change of
    tau would plan on the old time scale)."""
    dmp = random_discrete(seed=21)
    dmp.rollout(0.5, 0.001)  # fills what a copy may keep
    copy = dmp.replace(**changes)
    fields = {f.name: getattr(copy, f.name) for f in dataclasses.fields(copy) if f.init}
    fresh = DiscreteDMP(**fields)
    for duration in (0.5, 0.3):
        planned, expected = copy.rollout(duration, 0.001), fresh.rollout(duration, 0.001)
        np.testing.assert_array_equal(planned.positions, expected.positions)
        np.testing.assert_array_equal(planned.accelerations, expected.accelerations)
    assert copy.max_step == fresh.max_step


@pytest.mark.parametrize("form", ["phase", "energy"])
def test_an_amplitude_copy_keeps_only_a_step_limit_that_does_not_depend_on_it(form):
    """A rhythmic copy with another amplitude has the step limit of the same DMP built afresh:
    the phase form keeps its limit (eq. (11) is linear in r, A only shifts it), and the
    answer key is the limit on RK4's negative real axis, h |lambda| <= 2.785293563 (the root
    of 1 + z + z^2/2 + z^3/6 + z^4/24 = 1), for the slowest-to-bound eigenvalues -alpha_r
    and -alpha_z / 2 (critically damped); the energy form's limit moves with E_0 = (k A)^2/2
    and is recomputed (keeping it is the bug this catches)."""
    from dmpopt import RhythmicDMP

    dmp = random_rhythmic(seed=3, form=form)
    dmp.max_step  # noqa: B018 - computed, so that a copy could keep it
    for amplitude in (0.5, 4.0):
        copy = dmp.replace(amplitude=amplitude)
        fields = {f.name: getattr(copy, f.name) for f in dataclasses.fields(copy) if f.init}
        assert copy.max_step == RhythmicDMP(**fields).max_step
        if form == "phase":
            fastest = max(dmp.alpha_r, dmp.alpha_z / 2)
            assert copy.max_step == pytest.approx(2.785293563 / fastest * dmp.tau, rel=1e-8)
