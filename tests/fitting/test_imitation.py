"""Imitation learning (Section 3.4): targets, regressions, reproduction, bad input."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from problems import minimum_jerk_demo, periodic_demo

from dmpopt import (
    InvalidInputError,
    Trajectory,
    fit_discrete,
    fit_rhythmic,
    fit_to_accuracy,
    reproduction_error,
    symbolic,
)
from dmpopt.fitting import estimate_period


@pytest.mark.parametrize(
    "form, method, tolerance",
    [
        ("velocity", "position", 1e-4),
        ("acceleration", "position", 2e-3),
        ("velocity", "least_squares", 1e-3),
        ("velocity", "lwr", 2e-2),
        ("acceleration", "lwr", 5e-2),
    ],
)
def test_reproduces_minimum_jerk(form, method, tolerance):
    demo = minimum_jerk_demo()
    dmp = fit_discrete(demo, 30, form=form, method=method)
    amplitude = np.abs(demo.positions[-1] - demo.positions[0]).max()
    assert reproduction_error(dmp, demo) < tolerance * amplitude


def test_position_fit_hits_start_and_goal_exactly():
    demo = minimum_jerk_demo(seed=2)
    dt = demo.duration / (demo.n_steps - 1)
    plan = fit_discrete(demo, 10).rollout(demo.duration, dt, demo.velocities[0])
    np.testing.assert_allclose(plan.positions[0], demo.positions[0], atol=1e-12)
    np.testing.assert_allclose(plan.positions[-1], demo.positions[-1], atol=1e-9)


@pytest.mark.parametrize("n_basis, regularization", [(10, 1e-9), (150, 0.0), (200, 1e-14)])
def test_position_fit_plan_ends_at_the_goal_to_rounding(n_basis, regularization):
    """The goal equality of the position fit holds to rounding even where its KKT system is
    ill-conditioned (many basis functions, little or no ridge): the plan of the fitted
    weights, at the demo's own samples, ends at the goal."""
    demo = minimum_jerk_demo(n_dofs=2, seed=3)
    dmp = fit_discrete(demo, n_basis, regularization=regularization, goal_scaling="translation")
    dt = demo.duration / (demo.n_steps - 1)
    plan = dmp.affine_plan(demo.duration, dt, start_velocity=demo.velocities[0])
    end = plan.evaluate(dmp.forcing_weights())[0][-1]
    np.testing.assert_allclose(end, demo.positions[-1], rtol=0, atol=1e-14)


def test_reproduces_planar_figure_eight_stroke():
    times = np.linspace(0, 2, 1001)
    s = np.pi * (10 * (times / 2) ** 3 - 15 * (times / 2) ** 4 + 6 * (times / 2) ** 5)
    demo = Trajectory.from_positions(times, np.c_[np.sin(2 * s), np.sin(s) + s / 3])
    assert reproduction_error(fit_discrete(demo, 40), demo) < 1e-3


def test_closed_movement_uses_translation_and_stays_finite():
    times = np.linspace(0, 1, 500)
    loop = np.c_[np.sin(2 * np.pi * times), 1 - np.cos(2 * np.pi * times)]
    dmp = fit_discrete(Trajectory.from_positions(times, loop), 30)
    assert dmp.goal_scaling == "translation"
    moved = dmp.with_goal(dmp.goal + 1.0).rollout(8 * dmp.convergence_time)
    assert np.all(np.isfinite(moved.positions))
    np.testing.assert_allclose(moved.positions[-1], dmp.goal + 1.0, atol=1e-4)


def test_paper_scaling_refuses_degenerate_axis():
    """DOF 1 ends where it starts: the paper's (g - y0) factor would amplify its goal
    changes without bound."""
    times = np.linspace(0, 1, 300)
    demo = Trajectory.from_positions(times, np.c_[times, np.sin(np.pi * times)])
    with pytest.raises(
        InvalidInputError,
        match=r"goal_scaling='paper' would amplify goal changes of DOF\(s\) \[1\] .*"
        r"use goal_scaling='auto'",
    ):
        fit_discrete(demo, 10, goal_scaling="paper")


def test_fit_is_invariant_to_time_scaling_of_the_demo():
    """A demo played c times slower gives the same weights and c times the tau."""
    demo = minimum_jerk_demo(n_dofs=2)
    slow = Trajectory.from_positions(3 * demo.times, demo.positions)
    fast_dmp, slow_dmp = fit_discrete(demo, 20), fit_discrete(slow, 20)
    np.testing.assert_allclose(slow_dmp.weights, fast_dmp.weights, rtol=1e-6, atol=1e-9)
    assert slow_dmp.tau == pytest.approx(3 * fast_dmp.tau, rel=1e-12)


def test_fit_to_accuracy_picks_fewest_bases():
    demo = minimum_jerk_demo(n_dofs=1)
    dmp = fit_to_accuracy(demo, tolerance=1e-4)
    assert reproduction_error(dmp, demo) <= 1e-4
    smaller = fit_discrete(demo, {5: 5, 10: 5, 15: 10, 20: 15}.get(dmp.n_basis, 5))
    assert dmp.n_basis == 5 or reproduction_error(smaller, demo) > 1e-4
    with pytest.raises(InvalidInputError, match="no number of basis functions"):
        fit_to_accuracy(demo, tolerance=1e-30, candidates=(3,))


@pytest.mark.parametrize("form", ["phase", "energy"])
@pytest.mark.parametrize(
    "method, tolerance", [("position", 3e-3), ("least_squares", 4e-3), ("lwr", 1e-2)]
)
def test_rhythmic_reproduces_periodic_demo(form, method, tolerance):
    demo = periodic_demo()
    dmp = fit_rhythmic(demo, 15, form=form, method=method)
    assert dmp.period == pytest.approx(0.8, rel=1e-4)
    assert reproduction_error(dmp, demo) < tolerance


def test_period_estimate():
    assert estimate_period(periodic_demo(period=0.37, duration=1.5)) == pytest.approx(
        0.37, rel=1e-4
    )


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda d: fit_discrete(d, 0), "n_basis must be an integer >= 1, got 0"),
        (lambda d: fit_discrete(d, 2.5), "n_basis must be an integer >= 1, got 2.5"),
        (lambda d: fit_discrete(d.positions, 10), "demo must be a Trajectory"),
        (lambda d: fit_discrete(d, 10, method="magic"), "method must be one of"),
        (
            lambda d: fit_rhythmic(d, 10, period=-1.0),
            "period must be a finite number > 0, got -1.0",
        ),
        (lambda d: fit_rhythmic(d, 10, period=5.0), "less than one period"),
    ],
)
def test_bad_input_names_the_argument(call, message):
    with pytest.raises(InvalidInputError, match=message):
        call(minimum_jerk_demo(n_dofs=1))


def test_fit_to_accuracy_rhythmic():
    demo = periodic_demo()
    candidates = (5, 10, 15, 20, 30, 40)
    dmp = fit_to_accuracy(demo, 1e-3, candidates, rhythmic=True, period=0.8)
    assert reproduction_error(dmp, demo) <= 1e-3
    previous = candidates[candidates.index(dmp.n_basis) - 1]
    assert reproduction_error(fit_rhythmic(demo, previous, period=0.8), demo) > 1e-3


def _loop_with_gap(gap: float, n_steps: int = 400) -> Trajectory:
    """A circle of diameter 2 traced from the origin, ending ``gap`` away from its start."""
    times = np.linspace(0.0, 1.0, n_steps)
    circle = np.c_[np.sin(2 * np.pi * times), 1 - np.cos(2 * np.pi * times)]
    return Trajectory.from_positions(times, circle + gap * np.c_[times, times] / np.sqrt(2))


@pytest.mark.parametrize("gap", [0.0, 1e-5, 1e-3, 0.1, 0.3, 1.0])
def test_auto_goal_scaling_bounds_the_amplification(gap):
    """'auto' takes rotation only if it amplifies goal changes at most 10-fold.

    Rotation moves the plan by |delta| max|y - y0| / |g - y0| exactly (the plan is mapped by
    a similarity whose deviation from the identity has norm |delta| / |g - y0|); translation
    by at most |delta|. Issue 13: a gap of 1e-5 moved by 0.1 reached |y| = 1.3e4.
    """
    demo = _loop_with_gap(gap)
    offsets = demo.positions - demo.positions[0]
    amplification = np.linalg.norm(offsets, axis=1).max() / max(np.linalg.norm(offsets[-1]), 1e-300)
    dmp = fit_discrete(demo, 30)
    assert dmp.goal_scaling == ("rotation" if amplification <= 10 else "translation")
    delta = np.array([0.1, -0.05])
    dt = demo.duration / (demo.n_steps - 1)
    plan = dmp.rollout(dt=dt).positions
    change = np.linalg.norm(dmp.with_goal(dmp.goal + delta).rollout(dt=dt).positions - plan, axis=1)
    if dmp.goal_scaling == "rotation":
        gap_norm = np.linalg.norm(dmp.goal - dmp.start)
        plan_amplification = np.linalg.norm(plan - dmp.start, axis=1).max() / gap_norm
        expected = np.linalg.norm(delta) * plan_amplification
        assert change.max() == pytest.approx(expected, rel=1e-6)
        assert plan_amplification < 10.5  # the plan reproduces the demo's excursion
    else:
        assert change.max() <= np.linalg.norm(delta) * (1 + 1e-9)


@pytest.mark.parametrize("gap", [0.0, 1e-5, 0.1])
def test_explicit_rotation_beyond_the_bound_is_refused(gap):
    with pytest.raises(
        InvalidInputError,
        match=r"goal_scaling='rotation' would amplify goal changes .*, more than the bound "
        r"10 .*use goal_scaling='translation'",
    ):
        fit_discrete(_loop_with_gap(gap), 10, goal_scaling="rotation")


def test_unknown_goal_scaling_names_the_choices():
    with pytest.raises(InvalidInputError, match=r"goal_scaling must be one of \('auto', "):
        fit_discrete(minimum_jerk_demo(), 10, goal_scaling="rotate")


@pytest.mark.parametrize("goal_scaling", ["rotation", "paper", "translation"])
def test_default_plan_reproduces_a_demo_that_starts_moving(goal_scaling):
    """The fitted DMP keeps the demo's start velocity: the default rollout follows the demo
    (answer key: the closed-form demo) and then rests at the goal."""
    times = np.linspace(0.0, 2.0, 801)
    u = times / 2.0
    profile = 10 * u**3 - 15 * u**4 + 6 * u**5
    positions = np.c_[
        0.5 * np.sin(np.pi * u) * (1 - u) ** 2 + profile, 2 * profile - 0.3 * u * (1 - u) ** 3
    ]
    demo = Trajectory.from_positions(times, positions)
    dmp = fit_discrete(demo, 40, goal_scaling=goal_scaling)
    assert np.linalg.norm(demo.velocities[0]) > 0.5
    np.testing.assert_allclose(dmp.start_velocity, demo.velocities[0], rtol=1e-12)
    plan = dmp.rollout(dt=0.0025)
    assert plan.times[-1] > demo.duration
    errors = np.linalg.norm(plan.positions[: demo.n_steps] - positions, axis=1)
    assert np.sqrt(np.mean(errors**2)) < 1e-4
    np.testing.assert_allclose(plan.velocities[0], demo.velocities[0], rtol=1e-12)
    np.testing.assert_allclose(plan.positions[-1], positions[-1], atol=1e-4)
    np.testing.assert_allclose(plan.velocities[-1], 0.0, atol=1e-3)


def test_still_demo_is_translated_and_paper_refused():
    """A demo that does not move has no start-goal vector to rotate or divide by."""
    times = np.linspace(0.0, 1.0, 100)
    demo = Trajectory.from_positions(times, np.tile([0.3, -1.0], (100, 1)))
    dmp = fit_discrete(demo, 10)
    assert dmp.goal_scaling == "translation"
    plan = dmp.rollout(dt=0.01).positions
    np.testing.assert_allclose(plan, np.tile([0.3, -1.0], (len(plan), 1)), atol=1e-12)
    with pytest.raises(InvalidInputError, match=r"DOF\(s\) \[0, 1\] \(largest: without bound\)"):
        fit_discrete(demo, 10, goal_scaling="paper")


# ---------------------------------------------------------------- arguments and documented bounds
@pytest.mark.parametrize(
    "call, message",
    [
        (lambda d: fit_discrete(d, 10, regularization=-1.0),
         r"^regularization must be a finite number >= 0, got -1.0$"),
        (lambda d: fit_rhythmic(d, 10, regularization=-1.0),
         r"^regularization must be a finite number >= 0, got -1.0$"),
        (lambda d: fit_rhythmic(d, 10, warm_up_periods=-1),
         r"^warm_up_periods must be an integer >= 0, got -1$"),
        (lambda d: fit_rhythmic(d, 10, periodicity_tolerance=0.0),
         r"^periodicity_tolerance must be a finite number > 0, got 0.0$"),
        (lambda d: fit_to_accuracy(d, 0.0), r"^tolerance must be a finite number > 0, got 0.0$"),
        (lambda d: fit_to_accuracy(d, 1e-3, candidates=5),
         r"^candidates must be a sequence of integers, got 5$"),
        (lambda d: fit_to_accuracy(d, 1e-3, candidates="ab"),
         r"^candidates must be a sequence of integers, got 'ab'$"),
        (lambda d: fit_to_accuracy(d, 1e-3, rhythmic="yes"),
         r"^rhythmic must be True or False, got 'yes'$"),
        (lambda d: fit_rhythmic(d.resampled(25), 15),
         r"^n_basis = 15 gives 30 weights per DOF but demo has only 25 samples"),
        (lambda d: fit_discrete(d.resampled(25), 26),
         r"^n_basis = 26 gives 26 weights per DOF but demo has only 25 samples"),
    ],
)  # fmt: skip
def test_bad_arguments_are_named_exactly(call, message):
    with pytest.raises(InvalidInputError, match=message):
        call(periodic_demo())


@pytest.mark.parametrize("rhythmic", [False, True])
def test_memory_bound_of_a_fit_is_its_regressors(monkeypatch, rhythmic):
    """8 bytes x (12 n (F + 3 + D) + 3 (F + 1)^2) for n samples, F weights per DOF and D
    DOFs: accepted at exactly that budget, refused one byte below, with the request named."""
    from dmpopt import ResourceLimitError, validation

    demo = periodic_demo(duration=1.6, n_steps=101)  # two periods, 3 DOFs
    n_weights = 20 if rhythmic else 10
    n_bytes = 8.0 * (12 * 101 * (n_weights + 3 + 3) + 3 * (n_weights + 1) ** 2)

    def fit():
        return fit_rhythmic(demo, 10, period=0.8) if rhythmic else fit_discrete(demo, 10)

    monkeypatch.setattr(validation, "MEMORY_BUDGET", n_bytes)
    fit()
    monkeypatch.setattr(validation, "MEMORY_BUDGET", n_bytes - 1)
    with pytest.raises(
        ResourceLimitError,
        match=r"^a fit of 10 basis functions to 101 samples needs 101 samples and about .*: "
        r"lower n_basis or resample the demonstration to fewer samples$",
    ):
        fit()


def test_as_many_weights_as_samples_is_a_determined_fit():
    demo = minimum_jerk_demo(n_dofs=1, n_steps=12)
    assert fit_discrete(demo, 12).n_basis == 12
    coarse = periodic_demo().resampled(24)
    options = dict(period=0.8, method="least_squares", periodicity_tolerance=np.inf)
    assert fit_rhythmic(coarse, 12, **options).n_basis == 12


def test_goal_amplification_is_the_largest_excursion_over_the_goal_distance():
    """Answer key: max_t |y(t) - y0| / |g - y0| (rotation) and per DOF (paper), written
    out for six samples whose first two and last two differ."""
    from dmpopt.fitting.imitation import goal_amplification

    positions = np.array([[0.0, 0.0], [3.0, 1.0], [5.0, -2.0], [4.0, 4.0], [2.0, 0.5], [1.0, 2.0]])
    demo = Trajectory.from_positions(np.linspace(0.0, 1.0, 6), positions)
    rotation, paper = goal_amplification(demo)
    assert rotation == pytest.approx(np.hypot(4.0, 4.0) / np.hypot(1.0, 2.0), rel=1e-15)
    np.testing.assert_allclose(paper, [5.0 / 1.0, 4.0 / 2.0], rtol=1e-15)


def test_an_amplification_of_exactly_ten_is_allowed():
    """MAX_GOAL_AMPLIFICATION = 10 is inclusive: a triangle from 0 up to 10 and down to 1
    fits under 'rotation' and 'paper' (auto picks rotation); a second DOF up to 20 is the
    only one 'paper' refuses."""
    times = np.linspace(0.0, 1.0, 101)
    up_to = lambda peak: np.interp(times, [0.0, 0.5, 1.0], [0.0, peak, 1.0])  # noqa: E731
    demo = Trajectory.from_positions(times, up_to(10.0)[:, None])
    assert fit_discrete(demo, 10).goal_scaling == "rotation"
    assert fit_discrete(demo, 10, goal_scaling="rotation").goal_scaling == "rotation"
    assert fit_discrete(demo, 10, goal_scaling="paper").goal_scaling == "paper"
    two = Trajectory.from_positions(times, np.c_[up_to(10.0), up_to(20.0)])
    with pytest.raises(InvalidInputError, match=r"DOF\(s\) \[1\] \(largest: 20-fold\) more"):
        fit_discrete(two, 10, goal_scaling="paper")


def test_a_non_uniform_demo_is_fitted_on_its_uniform_resampling():
    uniform = minimum_jerk_demo(n_dofs=2, n_steps=301)
    times = uniform.times**1.5  # denser at the start
    positions = np.column_stack([np.interp(times, uniform.times, p) for p in uniform.positions.T])
    demo = Trajectory.from_positions(times, positions)
    expected = fit_discrete(demo.resampled(demo.n_steps), 15).weights
    np.testing.assert_array_equal(fit_discrete(demo, 15).weights, expected)


def test_fit_discrete_keeps_its_gains_and_defaults():
    demo = minimum_jerk_demo(n_dofs=1)
    dmp = fit_discrete(demo, 10, alpha_z=16.0, alpha_v=12.0)
    assert (dmp.alpha_z, dmp.beta_z, dmp.alpha_v, dmp.beta_v) == (16.0, 4.0, 12.0, 3.0)
    default = fit_discrete(demo)
    assert (default.n_basis, default.form, default.alpha_z, default.alpha_v) == (
        30, "velocity", 25.0, 25.0,
    )  # fmt: skip


# ---------------------------------------------------------------- reproduction_error
def test_reproduction_error_of_a_dmps_own_plan_is_zero():
    """A plan rolled out from a moving start (discrete) or from any start state (rhythmic) is
    reproduced exactly: reproduction_error starts the DMP from the demo's first sample."""
    discrete = fit_discrete(minimum_jerk_demo(n_dofs=2), 10)
    plan = discrete.rollout(1.0, 0.005, start_velocity=[0.5, -0.3])
    assert reproduction_error(discrete, plan) < 1e-13
    default = discrete.rollout(1.0, 0.005)  # from the demo's start velocity (zero)
    assert np.abs(plan.positions - default.positions).max() > 1e-3
    rhythmic = fit_rhythmic(periodic_demo(), 10, period=0.8)
    plan = rhythmic.rollout(1.6, 0.004, [0.3, -0.2, 0.1], [1.0, 0.0, -1.0])
    assert reproduction_error(rhythmic, plan) < 1e-13


# ---------------------------------------------------------------- fit_to_accuracy
def test_fit_to_accuracy_accepts_an_error_equal_to_the_tolerance_and_passes_options():
    demo = minimum_jerk_demo(n_dofs=1)
    five = reproduction_error(fit_discrete(demo, 5, form="acceleration"), demo)
    dmp = fit_to_accuracy(demo, five, candidates=(5, 10), form="acceleration")
    assert (dmp.n_basis, dmp.form) == (5, "acceleration")


# ---------------------------------------------------------------- periods
def test_periodicity_mismatch_is_the_relative_rms_difference_one_period_later():
    """Answer key: a plain loop over the samples i with t_i + P <= t_end (P = 500 samples),
    DOF 0 drifting quadratically (its difference varies along the demo), DOF 1 periodic with
    the larger range; velocities are the demo's own samples."""
    from dmpopt.fitting.imitation import periodicity_mismatch

    times = np.linspace(0.0, 2.0, 2001)
    wave = 2 * np.pi * times / 0.5
    positions = np.c_[1.0 + 0.1 * np.sin(wave) + 0.02 * times**2, 0.3 * np.cos(wave)]
    demo = Trajectory.from_positions(times, positions)
    key = []
    for values in (demo.positions, demo.velocities):
        difference = values[500:] - values[:-500]  # samples 0 .. 1500
        rms = np.sqrt((difference**2).mean(axis=0))
        key.append(rms.max() / (values.max(axis=0) - values.min(axis=0)).max())
    assert key[1] < 0.5 * key[0]
    np.testing.assert_allclose(periodicity_mismatch(demo, 0.5), key, rtol=1e-9)


@settings(max_examples=12, deadline=None)
@given(
    period=st.floats(0.2, 2.0),
    cycles=st.floats(1.35, 4.0),
    samples_per_period=st.integers(150, 1000),
    scale=st.sampled_from([1e-6, 1e-3, 1.0, 1e6]),
    offset=st.floats(-100.0, 100.0),
)
def test_period_estimate_is_accurate_at_any_scale(
    period, cycles, samples_per_period, scale, offset
):
    """Measured at most 1.2e-5 relative over such demos (from 1.35 cycles, where the
    spectrum's peak is its first bin, to 4; 150 to 1000 samples per period)."""
    n_steps = int(cycles * samples_per_period) + 1
    shape = periodic_demo(period=period, duration=cycles * period, n_steps=n_steps)
    demo = Trajectory.from_positions(shape.times, offset + scale * shape.positions)
    assert estimate_period(demo) == pytest.approx(period, rel=4e-5)


def test_period_estimate_refuses_what_it_cannot_find():
    with pytest.raises(InvalidInputError, match="pass period= explicitly"):
        estimate_period(periodic_demo(period=0.8, duration=0.96, n_steps=961))  # 1.2 cycles
    times = np.linspace(0.0, 1.0, 1001)  # a ramp with a ripple: the spectrum peaks at the
    drifting = times + 0.01 * np.sin(20 * np.pi * times)  # ramp, whose "period" is no shift
    with pytest.raises(InvalidInputError, match="self-similarity has no minimum between"):
        estimate_period(Trajectory.from_positions(times, drifting[:, None]))
    still = Trajectory.from_positions(np.linspace(0.0, 1.0, 50), np.ones((50, 2)))
    with pytest.raises(InvalidInputError, match="^demo does not oscillate; pass period="):
        estimate_period(still)


# ---------------------------------------------------------------- fit_rhythmic's options
def test_fit_rhythmic_defaults_and_options_reach_the_dmp():
    demo = periodic_demo()
    default = fit_rhythmic(demo)
    assert (default.n_basis, default.form, default.kernel) == (15, "phase", "von_mises")
    assert (default.amplitude, default.alpha_z) == (1.0, 25.0)
    np.testing.assert_array_equal(default.setpoint, demo.positions.mean(axis=0))
    np.testing.assert_array_equal(
        default.weights, fit_rhythmic(demo, 15, warm_up_periods=2).weights
    )
    dmp = fit_rhythmic(demo, 10, form="energy", amplitude=2.0, kernel="paper", alpha_z=12.0)
    assert (dmp.form, dmp.amplitude, dmp.kernel, dmp.alpha_z) == ("energy", 2.0, "paper", 12.0)
    assert dmp.period == pytest.approx(0.8, rel=1e-4)


def test_fit_rhythmic_periodicity_and_length_bounds_are_inclusive():
    """A demo of 0.95 period is long enough; a demo exactly at periodicity_tolerance passes,
    and np.inf disables the check."""
    times = np.linspace(0.0, 0.95, 951)
    short = Trajectory.from_positions(times, np.sin(2 * np.pi * times)[:, None])
    fit_rhythmic(short, 5, period=1.0, periodicity_tolerance=np.inf)
    from dmpopt.fitting.imitation import periodicity_mismatch

    demo = periodic_demo()
    drifting = Trajectory.from_positions(demo.times, demo.positions + 0.3 * demo.times[:, None])
    with pytest.raises(InvalidInputError, match="is not periodic with period 0.8 s"):
        fit_rhythmic(drifting, 10, period=0.8)
    exact = max(periodicity_mismatch(drifting, 0.8))
    fit_rhythmic(drifting, 10, period=0.8, periodicity_tolerance=exact)
    fit_rhythmic(drifting, 10, period=0.8, periodicity_tolerance=np.inf)


@pytest.mark.parametrize("form", ["phase", "energy"])
@pytest.mark.parametrize("warm_up_periods", [0, 2])
def test_rhythmic_position_fit_minimises_the_documented_objective(form, warm_up_periods):
    """Answer key: the objective J(w) = sum |plan_w - demo|^2 over the window after
    ``warm_up_periods`` periods, the plan rolled out from the demo's first sample and
    velocity with the oscillator at -n_warm dt / tau (phase 0 at the window; the phase runs
    backwards in eq. (13)), n_warm = round(warm_up_periods P / dt). J is quadratic (no
    ridge here), so at its minimum J(w + d) = J(w - d) for every d: weights fitted to another
    window, start or phase break that symmetry. dt = 1.3 ms does not divide the period."""
    period, dt = 0.8, 1.3e-3
    demo = periodic_demo(period=period, duration=1308 * dt, n_steps=1309)
    dmp = fit_rhythmic(
        demo, 8, period=period, form=form, warm_up_periods=warm_up_periods, regularization=0.0
    )
    n_warm = round(warm_up_periods * period / dt)
    direction = 1.0 if form == "phase" else -1.0

    def objective(weights):
        plan = dmp.replace(weights=weights).rollout(
            (n_warm + demo.n_steps - 1) * dt,
            dt,
            demo.positions[0],
            demo.velocities[0],
            phase=-direction * n_warm * dt / dmp.tau,
        )
        return np.sum((plan.positions[n_warm:] - demo.positions) ** 2)

    rng = np.random.default_rng(0)
    at_minimum = objective(dmp.weights)
    for _ in range(3):
        step = 1e-2 * np.abs(dmp.weights).max() * rng.normal(size=dmp.weights.shape)
        plus, minus = objective(dmp.weights + step), objective(dmp.weights - step)
        curvature = plus + minus - 2 * at_minimum
        assert curvature > 0 and abs(plus - minus) < 1e-6 * curvature


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_unforced_states_do_not_depend_on_the_basis(form):
    """With zero weights the forcing term is exactly zero: the states integrated with one
    basis function equal, bit for bit, those integrated with the DMP's own 25 from the demo's
    first position and (non-zero) velocity."""
    from dmpopt import symbolic
    from dmpopt.fitting.imitation import unforced_states

    whole = minimum_jerk_demo()  # from its 100th sample on: it starts moving
    demo = Trajectory(
        whole.times[100:] - whole.times[100],
        whole.positions[100:],
        whole.velocities[100:],
        whole.accelerations[100:],
    )
    assert np.all(np.abs(demo.velocities[0]) > 0.01)
    dmp = fit_discrete(demo, 25, form=form, method="lwr")
    zero = dmp.replace(weights=np.zeros_like(dmp.weights))
    initial = zero.initial_state(demo.positions[0], demo.velocities[0], (0.0, 0.0))
    dt = demo.duration / (demo.n_steps - 1)
    full = symbolic.simulate(zero.signature, demo.n_steps, initial, dt, zero.parameters())[0]
    states = unforced_states(dmp, demo)
    assert np.array_equal(states, full)
    assert np.array_equal(states[0], initial)


@pytest.mark.parametrize("rhythmic", [False, True])
def test_values_at_samples_are_casadis_mapped_call_bit_for_bit(rhythmic):
    """The buffer path of the regressions gives the mapped CasADi call's answer, to the bit
    and in its memory layout (the regressions' sums follow the layout).

    Answer key: calling the mapped function and converting its DM, as the fits did before.
    """
    from dmpopt.fitting import imitation

    if rhythmic:
        demo = periodic_demo()
        dmp = fit_rhythmic(demo, 12, method="lwr")
        canonical = np.array([dmp.canonical_state(p) for p in np.linspace(0.0, 3.0, 257)])
    else:
        demo = minimum_jerk_demo(seed=3)
        dmp = fit_discrete(demo, 17, method="lwr")
        canonical = imitation.unforced_states(dmp, demo)[::3, :2]  # a strided view
    for make in (symbolic.activation_function, symbolic.feature_function):
        function = make(dmp.signature)
        mapped = symbolic.mapped(function, canonical.shape[0])
        expected = mapped(canonical.T, dmp.centres, dmp.widths).full().T
        got = imitation._at_samples(function, canonical, dmp)
        assert got.shape == expected.shape and got.strides == expected.strides
        np.testing.assert_array_equal(got.view(np.uint64), expected.view(np.uint64))


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_recalled_states_and_targets_give_the_fresh_fit(form):
    """Fits recall the unforced states and forcing targets of identical inputs; answer key:
    the same fit computed with nothing recalled, which must agree bit for bit (a key missing
    an input, e.g. the demo's positions, would hand the second demo the first one's targets)."""
    from dmpopt.fitting import imitation

    first, second = minimum_jerk_demo(n_dofs=2, seed=0), minimum_jerk_demo(n_dofs=2, seed=1)
    recalled = []
    for demo in (first, second):
        fit_discrete(demo, 12, form=form, method="least_squares")  # fills the store
        recalled.append(fit_discrete(demo, 12, form=form, method="lwr"))
    for demo, fit in zip((first, second), recalled):
        imitation._RECALLED.clear()
        fresh = fit_discrete(demo, 12, form=form, method="lwr")
        np.testing.assert_array_equal(fit.weights, fresh.weights)
    states = imitation.unforced_states(recalled[1], second)
    with pytest.raises(ValueError, match="read-only"):
        states[0, 0] = 1.0  # shared, so no caller may change it


def test_recall_keeps_the_last_answers_read_only_and_tells_layouts_apart():
    """Recall: the answer of a key already seen without computing again, at most ``size``
    answers (the one asked for longest ago forgotten), read-only; keys tell apart equal values
    in other memory layouts (a product's summation order follows the layout)."""
    from dmpopt.fitting._recall import Recall, exact

    calls = []

    def compute(value):
        calls.append(value)
        return np.full(2, float(value))

    recall = Recall(2)
    for value in (1, 2, 1, 3, 1, 2):  # 3 forgets 2 (1 was asked for since), 2 forgets 3
        answer = recall(value, lambda: compute(value))
        assert answer[0] == value
    assert calls == [1, 2, 3, 2]
    with pytest.raises(ValueError, match="read-only"):
        answer[0] = 0.0
    matrix = np.arange(6.0).reshape(2, 3)
    assert exact(matrix) == exact(matrix.copy())
    assert exact(matrix) != exact(np.asfortranarray(matrix))  # same values, other layout
    assert exact(matrix) != exact(matrix + 1e-16 * matrix.max())
