"""Imitation learning (Section 3.4): targets, regressions, reproduction, bad input."""

import numpy as np
import pytest
from problems import minimum_jerk_demo, periodic_demo

from dmpopt import (
    InvalidInputError,
    Trajectory,
    fit_discrete,
    fit_rhythmic,
    fit_to_accuracy,
    reproduction_error,
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
