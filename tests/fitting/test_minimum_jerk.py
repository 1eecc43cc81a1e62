"""Minimum-jerk baselines: closed form, via-points, and the bounded QP."""

import importlib
import math

import numpy as np
import pytest
import qpsolvers
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.exceptions import InfeasibleProblem, InvalidInputError
from dmpopt.fitting.constrained import Bounds, ViaPoint
from dmpopt.fitting.minimum_jerk import (
    jerk_response,
    minimum_jerk,
    minimum_jerk_constrained,
    minimum_jerk_via_points,
)
from dmpopt.metrics import integrated_squared_jerk


@settings(max_examples=20, deadline=None)
@given(start=st.floats(-2, 2), delta=st.floats(0.1, 3), duration=st.floats(0.3, 3))
def test_polynomial_matches_its_closed_form(start, delta, duration):
    """Positions, velocities, accelerations equal the quintic and its derivatives."""
    plan = minimum_jerk([start], [start + delta], duration, n_samples=201)
    s = plan.times / duration
    np.testing.assert_allclose(
        plan.positions[:, 0], start + delta * (10 * s**3 - 15 * s**4 + 6 * s**5), atol=1e-12
    )
    np.testing.assert_allclose(plan.velocities[-1], 0.0, atol=1e-12)
    peak = 1.875 * delta / duration
    np.testing.assert_allclose(np.abs(plan.velocities).max(), peak, rtol=1e-6)


def test_polynomial_jerk_cost_is_720_delta2_over_t5():
    """Integrated squared jerk of the quintic is 720 d^2 / T^5 (finite differences, fine grid)."""
    plan = minimum_jerk([0.0, 0.0], [1.0, 2.0], 1.5, n_samples=20001)
    np.testing.assert_allclose(integrated_squared_jerk(plan), 720 * 5 / 1.5**5, rtol=1e-3)


def test_via_points_are_passed_with_continuous_derivatives():
    """The piecewise quintic passes its via-points, at rest at both ends."""
    via = [ViaPoint(0.3, [0.5, -0.2]), ViaPoint(0.7, [0.8, 1.0])]
    plan = minimum_jerk_via_points([0.0, 0.0], [1.0, 2.0], 1.0, via, n_samples=1001)
    np.testing.assert_allclose(plan.positions[300], [0.5, -0.2], atol=1e-12)
    np.testing.assert_allclose(plan.positions[700], [0.8, 1.0], atol=1e-12)
    np.testing.assert_allclose(plan.velocities[[0, -1]], 0.0, atol=1e-10)
    steps = np.diff(plan.accelerations, axis=0)  # jerk * dt: continuous at the via-points
    for k in (300, 700):
        assert np.all(np.abs(steps[k] - steps[k - 1]) <= 0.01 * np.abs(steps).max(0))


def test_qp_without_bounds_approaches_the_polynomial():
    """With no bounds the piecewise-constant-jerk QP converges to the quintic."""
    exact = minimum_jerk([0.0], [1.0], 1.0, n_samples=1001)
    plan, report = minimum_jerk_constrained([0.0], [1.0], 1.0, n_samples=1001, n_segments=100)
    np.testing.assert_allclose(plan.positions, exact.positions, atol=1e-4)
    assert integrated_squared_jerk(plan) >= integrated_squared_jerk(exact) * (1 - 1e-3)


def test_qp_matches_exact_via_point_solution():
    """Through a via-point the QP approaches the exact piecewise quintic."""
    via = [ViaPoint(0.4, [0.7, 0.1])]
    exact = minimum_jerk_via_points([0, 0], [1, 1], 1.0, via, n_samples=501)
    plan, _ = minimum_jerk_constrained(
        [0, 0], [1, 1], 1.0, via_points=via, n_samples=501, n_segments=100
    )
    np.testing.assert_allclose(plan.positions, exact.positions, atol=5e-4)


@settings(max_examples=8, deadline=None)
@given(fraction=st.floats(0.8, 0.99))
def test_qp_bounds_hold_at_every_sample(fraction):
    """Velocity and acceleration limits below the quintic's peaks hold on the result."""
    exact = minimum_jerk([0, 0], [1, 2], 1.0, n_samples=401)
    peak_v = np.abs(exact.velocities).max(0)
    peak_a = np.abs(exact.accelerations).max(0)
    bounds = Bounds(velocity=fraction * peak_v + 0.1 * peak_v, acceleration=fraction * 1.3 * peak_a)
    plan, report = minimum_jerk_constrained([0, 0], [1, 2], 1.0, bounds=bounds, n_samples=401)
    assert np.all(np.abs(plan.velocities) <= bounds.velocity)
    assert np.all(np.abs(plan.accelerations) <= bounds.acceleration)
    np.testing.assert_allclose(plan.positions[-1], [1, 2], atol=1e-9)


def test_impossible_bounds_raise():
    """A velocity limit below distance / duration is infeasible."""
    with pytest.raises(InfeasibleProblem, match="minimum-jerk movement infeasible on DOF 0"):
        minimum_jerk_constrained([0.0], [1.0], 1.0, bounds=Bounds(velocity=0.9), n_samples=201)


def test_qp_matches_the_plain_jerk_qp_solved_by_a_second_solver():
    """Piecewise-constant jerk j_i on equal segments from rest: position
    sum_i j_i ((t - t_i)_+^3 - (t - t_{i+1})_+^3) / 6 (velocity: squares / 2, acceleration:
    ramps). Minimising sum j_i^2 with the goal reached at rest, |velocity| and |jerk| bounded
    and a box via-point, written plainly and solved by Clarabel, gives the same movement."""
    n_samples, n_segments, duration = 201, 30, 1.0
    start, goal = np.array([0.2, -0.1]), np.array([1.0, 0.6])
    times = np.linspace(0.0, duration, n_samples)
    knots = np.linspace(0.0, duration, n_segments + 1)

    def response(t, power):
        ramp = np.maximum(np.subtract.outer(t, knots), 0.0) ** power / np.prod(range(1, power + 1))
        return ramp[:, :-1] - ramp[:, 1:]

    position, velocity, acceleration = (response(times, p) for p in (3, 2, 1))
    peak = 1.875 * np.abs(goal - start) / duration
    via = ViaPoint(0.3, [0.5, 0.2], tolerance=0.01)
    bounds = Bounds(velocity=0.95 * peak + 0.05, jerk=250.0)
    plan, report = minimum_jerk_constrained(
        start,
        goal,
        duration,
        bounds=bounds,
        via_points=[via],
        n_samples=n_samples,
        n_segments=n_segments,
        margin=0.0,  # the plain problem has no safety margin
    )
    jerk = np.diff(acceleration, axis=0) / (times[1] - times[0])
    at_via = response(np.array([via.time]), 3)
    for d in range(2):
        limit = np.concatenate(
            [np.full(n_samples, bounds.velocity[d]), np.full(n_samples - 1, 250.0)]
        )
        inequality = np.vstack([velocity, jerk, at_via])
        upper = np.concatenate([limit, [via.position[d] + 0.01 - start[d]]])
        lower = np.concatenate([-limit, [via.position[d] - 0.01 - start[d]]])
        x = qpsolvers.solve_qp(
            np.eye(n_segments),
            np.zeros(n_segments),
            np.vstack([inequality, -inequality]),
            np.concatenate([upper, -lower]),
            np.vstack([position[-1], velocity[-1], acceleration[-1]]),
            np.array([goal[d] - start[d], 0.0, 0.0]),
            solver="clarabel",
            tol_gap_abs=1e-12,
            tol_gap_rel=1e-12,
            tol_feas=1e-12,
        )
        key = start[d] + position @ x
        np.testing.assert_allclose(plan.positions[:, d], key, atol=1e-7)
        np.testing.assert_allclose(plan.velocities[:, d], velocity @ x, atol=1e-6)
    assert max(report.violations.values()) < 1e-7
    assert set(report.violations) == {
        "end_position",
        "end_velocity",
        "end_acceleration",
        "velocity",
        "jerk",
        "via_point[0]",
    }


@pytest.mark.parametrize("quantity", ["position", "velocity", "acceleration", "jerk"])
def test_active_limits_are_tightened_by_the_margin_in_their_unit(quantity):
    """With L the extent (of start, goal and via-points) and T the duration, an active limit
    holds with a gap of exactly margin * L, L/T, L/T^2 or L/T^3: positions, velocities,
    accelerations or finite-difference jerks reach limit - margin * unit and no further."""
    start, goal, duration, margin = np.array([0.0]), np.array([3.0]), 2.0, 1e-3
    length = 3.0  # |goal - start|
    exact = minimum_jerk(start, goal, duration, n_samples=401)
    power = ["position", "velocity", "acceleration", "jerk"].index(quantity)
    if quantity == "position":  # a box below the goal's overshoot-free path: via-point above
        bounds = Bounds(position_upper=3.2)
        vias = [ViaPoint(1.0, [3.5], tolerance=0.4)]
        values = lambda plan: plan.positions  # noqa: E731
        limit, length = 3.2, 3.5  # the via-point widens the extent
    else:
        series = {
            "velocity": exact.velocities,
            "acceleration": exact.accelerations,
            "jerk": np.diff(exact.accelerations, axis=0) / (exact.times[1] - exact.times[0]),
        }[quantity]
        limit = 0.9 * np.abs(series).max()
        bounds = Bounds(**{quantity: limit})
        vias = []
        values = {
            "velocity": lambda plan: plan.velocities,
            "acceleration": lambda plan: plan.accelerations,
            "jerk": lambda plan: (
                np.diff(plan.accelerations, axis=0) / (plan.times[1] - plan.times[0])
            ),
        }[quantity]
    plan, report = minimum_jerk_constrained(
        start, goal, duration, bounds=bounds, via_points=vias, n_samples=401, margin=margin
    )
    unit = length / duration**power
    np.testing.assert_allclose(np.abs(values(plan)).max(), limit - margin * unit, rtol=1e-9)
    assert report.violations[quantity] == 0.0 and report.iterations >= 1 and report.solve_time > 0


def test_sampling_defaults_and_grid():
    """dt = 1 ms by default, samples at k dt from 0 to the duration; n_segments = 60 by
    default (the same plan as asked for explicitly)."""
    plan = minimum_jerk([0.0], [1.0], 0.5)
    np.testing.assert_allclose(plan.times, np.arange(501) * 1e-3, rtol=0, atol=1e-12)
    coarse = minimum_jerk([0.0], [1.0], 1.2, 0.1)
    np.testing.assert_allclose(coarse.times, np.arange(13) * 0.1, rtol=0, atol=1e-12)
    default, _ = minimum_jerk_constrained([0.0], [1.0], 1.0, dt=0.01)
    explicit, _ = minimum_jerk_constrained([0.0], [1.0], 1.0, dt=0.01, n_segments=60)
    np.testing.assert_array_equal(default.positions, explicit.positions)
    other, _ = minimum_jerk_constrained([0.0], [1.0], 1.0, dt=0.01, n_segments=61)
    assert np.abs(other.positions - default.positions).max() > 1e-9


def test_arguments_are_checked_by_name():
    """start, goal, via_points and each via-point's position and tolerance name themselves;
    a via-point exactly at the end is accepted, one after it refused."""
    from dmpopt.exceptions import ShapeError

    for name in ("start", "goal"):
        with pytest.raises(InvalidInputError, match=f"^{name} must be an array of real numbers"):
            minimum_jerk(**{"start": [0.0], "goal": [1.0], name: "here"}, duration=1.0)
    with pytest.raises(InvalidInputError, match="^via_points must be a sequence"):
        minimum_jerk_via_points([0.0], [1.0], 1.0, "halfway")
    with pytest.raises(InvalidInputError, match="^via_points must be a sequence"):
        minimum_jerk_constrained([0.0], [1.0], 1.0, via_points="halfway")
    two = ([0.0, 0.0], [1.0, 1.0])
    with pytest.raises(ShapeError, match=r"^via_points\[0\]\.position has shape \(3,\)"):
        minimum_jerk_via_points(*two, 1.0, [ViaPoint(0.5, [0.5] * 3)])
    with pytest.raises(ShapeError, match=r"^via_points\[0\]\.tolerance has shape \(3,\)"):
        minimum_jerk_constrained(*two, 1.0, via_points=[ViaPoint(0.5, [0.5] * 2, [0.1] * 3)])
    end, _ = minimum_jerk_constrained([0.0], [1.0], 1.0, dt=0.01,
                                      via_points=[ViaPoint(1.0, [1.0])])  # fmt: skip
    assert end.positions[-1, 0] == pytest.approx(1.0, abs=1e-6)
    with pytest.raises(InvalidInputError, match=r"^via_points\[0\]\.time = 1\.1 s is after"):
        minimum_jerk_constrained([0.0], [1.0], 1.0, via_points=[ViaPoint(1.1, [1.0])])


def test_three_via_points_are_met_with_continuous_derivatives():
    """Four quintic segments through three via-points: each point met at its time, velocity
    and acceleration continuous across them (finite differences of the 1 ms plan), rest at
    both ends."""
    vias = [ViaPoint(0.3, [0.6, -0.2]), ViaPoint(0.5, [0.1, 0.3]), ViaPoint(0.7, [0.2, 0.5])]
    plan = minimum_jerk_via_points([0.0, 0.0], [1.0, 1.0], 1.0, vias, dt=1e-3)
    for via in vias:
        k = int(round(via.time / 1e-3))
        np.testing.assert_allclose(plan.positions[k], via.position, rtol=0, atol=1e-9)
        for values in (plan.velocities, plan.accelerations):
            jump = np.abs(values[k + 1] - 2 * values[k] + values[k - 1]).max()
            assert jump < 1e-3 * np.abs(values).max()
    np.testing.assert_allclose(plan.velocities[[0, -1]], 0.0, atol=1e-9)
    np.testing.assert_allclose(plan.positions[-1], [1.0, 1.0], atol=1e-9)


def test_memory_estimates_are_eight_bytes_a_value(monkeypatch):
    """The refusals count 8 bytes a value: 4 n D for a sampled plan, 3 n S for the jerk
    responses, 7 n S for the constrained QP (n samples, D DOFs, S segments); a budget of
    exactly that much is enough, a byte less is not, and the message names the remedy."""
    from dmpopt import validation
    from dmpopt.exceptions import ResourceLimitError

    n, segments = 101, 60
    cases = [
        (8.0 * 4 * n * 2, lambda: minimum_jerk([0.0, 0.0], [1.0, 1.0], 1.0, 0.01),
         r"^sampling 1 s every 0\.01 s \(2 DOFs\) needs .*: raise dt or shorten the duration$"),
        (8.0 * 3 * n * segments, lambda: jerk_response(np.linspace(0.0, 1.0, n), segments),
         r"^jerk responses at 101 times for 60 segments needs .*: lower n_segments or use "
         r"fewer times$"),
        (8.0 * 7 * n * segments, lambda: minimum_jerk_constrained([0.0], [1.0], 1.0, dt=0.01),
         r"^a minimum-jerk QP with 101 samples and 60 jerk segments needs .*: lower "
         r"n_segments or sample more coarsely \(raise dt\)$"),
    ]  # fmt: skip
    for n_bytes, call, message in cases:
        monkeypatch.setattr(validation, "MEMORY_BUDGET", n_bytes)
        call()
        monkeypatch.setattr(validation, "MEMORY_BUDGET", n_bytes - 1)
        with pytest.raises(ResourceLimitError, match=message):
            call()
    module = importlib.import_module("dmpopt.fitting.minimum_jerk")

    monkeypatch.setattr(module, "MEMORY_BUDGET", 32 * 100)  # n_samples <= budget / 32 D
    minimum_jerk([0.0], [1.0], 1.0, n_samples=100)
    with pytest.raises(ResourceLimitError, match="^n_samples = 101 exceeds the bound 100 .*; "
                       "sample more coarsely$"):  # fmt: skip
        minimum_jerk([0.0], [1.0], 1.0, n_samples=101)


def test_a_constrained_via_point_of_the_wrong_size_is_named():
    """A via-point with three entries for two DOFs: the library's ShapeError naming it (it
    used to reach numpy's vstack first)."""
    from dmpopt.exceptions import ShapeError

    with pytest.raises(ShapeError, match=r"^via_points\[0\]\.position has shape \(3,\)"):
        minimum_jerk_constrained([0.0, 0.0], [1.0, 1.0], 1.0,
                                 via_points=[ViaPoint(0.5, [0.5] * 3)])  # fmt: skip


def test_a_box_via_point_binds_at_the_edge_of_its_band_and_a_hold_stays():
    """0 -> 1 in 1 s passes 0.5 at mid-time; a via-point 0.3 +- 0.05 there is met at the
    band's upper edge 0.35 (the nearest to the free path), not inside or at 0.25. A move from
    1 to 1 (no extent) stays at 1, at rest."""
    via = ViaPoint(0.5, [0.3], tolerance=0.05)
    plan, _ = minimum_jerk_constrained([0.0], [1.0], 1.0, dt=0.01, via_points=[via], margin=0.0)
    assert plan.positions[50, 0] == pytest.approx(0.35, abs=1e-6)
    hold, _ = minimum_jerk_constrained([1.0], [1.0], 1.0, dt=0.01)
    np.testing.assert_allclose(hold.positions, 1.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(hold.velocities, 0.0, rtol=0, atol=1e-9)


def test_jerk_response_is_the_ramp_formula_and_a_callers_copy():
    """Unit jerk on segment i from rest: position R3(t - t_i) - R3(t - t_{i+1}), R_k(x) =
    max(x, 0)^k / k!, velocity with R2, acceleration with R1 (the docstring's formula).

    The responses are kept per grid for searches that solve many QPs on one grid: what a
    caller gets is its own copy, so writing into it changes no later answer.
    """
    times = np.linspace(0.0, 2.0, 41)
    knots = np.linspace(0.0, 2.0, 5)

    def ramp(x, k):
        return np.maximum(x, 0.0) ** k / math.factorial(k)

    expected = np.stack(
        [
            ramp(times[:, None] - knots[:-1], k) - ramp(times[:, None] - knots[1:], k)
            for k in (3, 2, 1)
        ]
    )
    first = jerk_response(times, 4)
    np.testing.assert_allclose(first, expected, rtol=0, atol=1e-15)
    first[:] = 7.0
    np.testing.assert_allclose(jerk_response(times, 4), expected, rtol=0, atol=1e-15)
