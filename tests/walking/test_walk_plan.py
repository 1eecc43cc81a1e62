"""Tests of the walking plans: footsteps, the LIPM / DCM CoM plan, the swing-foot DMPs.

Answer keys: the LIPM's closed form written out here and a numerical integration of
x'' = (g / z_c)(x - p) by scipy; the DCM recursion between footsteps written plainly
(xi_i = p_{i+1} + exp(-T / T_c) (xi_{i+1} - p_{i+1})) and its steady-state offset
L / (exp(T / T_c) - 1); the footholds themselves for the swing-foot references.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.walk_plan import (
    GRAVITY,
    Footstep,
    fit_swing_dmps,
    footstep_plan,
    lipm_state,
    lipm_time_constant,
    plan_walk,
    quintic,
    steady_dcm_offset,
    swing_reference,
)

LEFT, RIGHT = np.array([0.0, 0.085, 0.0]), np.array([0.0, -0.085, 0.0])
COM = np.array([0.0, 0.0, 0.87])
SINGLE, DOUBLE = 0.8, 0.3


@pytest.fixture(scope="module")
def swing_dmps():
    return fit_swing_dmps(SINGLE, step_length=0.2, height=0.05)


def walk(n_in_place=1, n_forward=4, length=0.1, double=DOUBLE):
    steps = footstep_plan(LEFT, RIGHT, n_in_place, n_forward, length)
    return plan_walk(steps, COM, COM[2], SINGLE, double, initial_hold=1.5, final_hold=1.0)


# ------------------------------------------------------------------------------ LIPM
@settings(max_examples=30, deadline=None)
@given(
    x0=st.floats(-0.2, 0.2),
    v0=st.floats(-0.5, 0.5),
    p=st.floats(-0.2, 0.2),
    t=st.floats(0.0, 1.0),
    height=st.floats(0.3, 1.2),
)
def test_lipm_state_solves_the_pendulum(x0, v0, p, t, height):
    """Answer key: scipy integrates x'' = (g / z_c)(x - p) from (x0, v0)."""
    tc = lipm_time_constant(height)
    assert tc == pytest.approx(np.sqrt(height / 9.81))
    position, velocity = lipm_state([x0], [v0], [p], t, tc)
    ode = solve_ivp(
        lambda _, y: [y[1], GRAVITY / height * (y[0] - p)],
        (0.0, t),
        [x0, v0],
        rtol=1e-11,
        atol=1e-13,
    )
    np.testing.assert_allclose([position[0], velocity[0]], ode.y[:, -1], atol=1e-8)


def test_single_support_com_is_the_closed_form_about_the_stance_foot():
    """In each single support the plan's CoM is x0 cosh(t/Tc) + Tc xd0 sinh(t/Tc) about the
    stance foot (written here), from the plan's own state at lift-off."""
    plan = walk()
    tc = np.sqrt(COM[2] / 9.81)
    for step, start in zip(plan.footsteps, plan.lift_off):
        x0, v0, _ = plan.com(start)
        p = step.stance[:2]
        for t in np.linspace(0.0, SINGLE, 9):
            expected = p + (x0[:2] - p) * np.cosh(t / tc) + tc * v0[:2] * np.sinh(t / tc)
            np.testing.assert_allclose(plan.com(start + t)[0][:2], expected, atol=1e-9)


def test_plan_obeys_the_lipm_and_the_dcm_definition_everywhere():
    """x'' = (x - p) / Tc^2 (acceleration by finite differences of the velocity) and
    xi = x + Tc x' on the whole plan, double supports included; the plan ends at rest on
    the middle of the last two footholds."""
    plan = walk()
    tc = plan.time_constant
    t = np.arange(0.0, plan.duration, 1e-4)
    position, velocity, acceleration = plan.com(t)
    zmp = plan.zmp(t)
    np.testing.assert_allclose(plan.dcm(t), position[:, :2] + tc * velocity[:, :2], atol=1e-12)
    np.testing.assert_allclose(acceleration[:, :2], (position[:, :2] - zmp) / tc**2, atol=1e-9)
    numeric = np.gradient(velocity[:, :2], t, axis=0)
    away = np.min(np.abs(t[:, None] - plan.knot_times[None, :]), axis=1) > 2e-4
    dcm_rate = np.gradient(plan.dcm(t), t, axis=0)  # xi' = (xi - p) / Tc
    np.testing.assert_allclose(dcm_rate[away], (plan.dcm(t) - zmp)[away] / tc, atol=1e-5)
    np.testing.assert_allclose(numeric[away], acceleration[away, :2], atol=1e-5)
    np.testing.assert_allclose(
        np.gradient(position[:, :2], t, axis=0)[1:-1], velocity[1:-1, :2], atol=1e-6
    )
    last = plan.footsteps[-1]
    middle = 0.5 * (last.goal[:2] + last.stance[:2])
    np.testing.assert_allclose(plan.dcm(plan.duration), middle, atol=1e-12)
    assert np.linalg.norm(plan.com(plan.duration)[0][:2] - middle) < 5e-3
    assert np.abs(plan.com(0.0)[1]).max() < 0.01  # starts nearly at rest (long initial hold)
    np.testing.assert_allclose(plan.com(0.0)[0], COM)


@settings(max_examples=40, deadline=None)
@given(t=st.floats(-0.5, 9.0))
def test_a_ticks_floats_are_the_plans_arrays_bit_for_bit(t):
    """values_at (a tick's floats) gives each bit of zmp, dcm and com evaluated on an array
    of times (the other code path, one exponential per element and axis); with no ulp of
    tolerance, a reordered sum or a shared factor computed differently fails."""
    plan = walk()
    values = np.array(plan.values_at(t))
    position, velocity, acceleration = plan.com(np.array([t]))
    arrays = [plan.zmp(np.array([t])), plan.dcm(np.array([t]))]
    arrays += [a[:, :2] for a in (position, velocity, acceleration)]
    np.testing.assert_array_equal(values, np.concatenate(arrays, axis=1).ravel())
    single = np.concatenate([plan.zmp(t), plan.dcm(t), *(a[:2] for a in plan.com(t))])
    np.testing.assert_array_equal(values, single)


def test_zmp_sits_on_the_stance_foot_in_single_support_and_moves_in_double_support():
    plan = walk()
    for i, (step, start, end) in enumerate(zip(plan.footsteps, plan.lift_off, plan.touchdown)):
        for t in np.linspace(start, end, 5):
            np.testing.assert_allclose(plan.zmp(t), step.stance[:2], atol=1e-12)
            assert plan.phase(min(max(t, start + 1e-9), end - 1e-9)) == ("single", i)
        assert plan.phase(start - 1e-9) == ("double", i)
        middle = plan.zmp(start - DOUBLE / 2)  # half-way through the weight transfer
        previous = plan.zmp(start - DOUBLE)
        np.testing.assert_allclose(middle, 0.5 * (previous + step.stance[:2]), atol=1e-12)


# ----------------------------------------------------------------------- DCM recursion
def test_end_of_step_dcm_follows_the_recursion_and_its_steady_offset():
    """No double support: xi at each touchdown equals p_next + e^(-T/Tc)(xi_next - p_next),
    p_next the next stance foothold, from the final DCM on the middle of the feet; in the
    middle of a long walk it lies L / (e^(T/Tc) - 1) ahead of the next foothold."""
    length = 0.1
    plan = walk(n_in_place=0, n_forward=16, length=length, double=0.0)
    tc = np.sqrt(COM[2] / 9.81)
    steps = plan.footsteps
    decay = np.exp(-SINGLE / tc)
    # Written plainly: the ZMP sits on stance_i during step i, on the middle at the end.
    last = 0.5 * (steps[-1].goal[:2] + steps[-1].stance[:2])
    # After the last touchdown the ZMP jumps to the middle and stays: the DCM rests there.
    xi_end = [None] * len(steps)
    xi_end[-1] = last
    for i in range(len(steps) - 2, -1, -1):
        p_next = steps[i + 1].stance[:2]
        xi_end[i] = p_next + decay * (xi_end[i + 1] - p_next)
    for i, t in enumerate(plan.touchdown):
        np.testing.assert_allclose(plan.dcm(t), xi_end[i], atol=1e-12)
    offset = length / (np.exp(SINGLE / tc) - 1.0)
    assert steady_dcm_offset(length, SINGLE, tc) == pytest.approx(offset, rel=1e-12)
    middle = len(steps) // 2
    ahead = plan.dcm(plan.touchdown[middle])[0] - steps[middle + 1].stance[0]
    assert ahead == pytest.approx(offset, abs=1e-6)


# ----------------------------------------------------------------------------- footsteps
def test_footsteps_alternate_and_close_side_by_side():
    steps = footstep_plan(LEFT, RIGHT, n_in_place=2, n_forward=10, step_length=0.1)
    assert len(steps) == 13
    assert [s.side for s in steps[:4]] == ["right", "left", "right", "left"]
    assert [s.length for s in steps] == pytest.approx([0, 0, 0.1] + [0.2] * 9 + [0.1])
    final = {s.side: s.goal for s in steps}
    np.testing.assert_allclose(final["left"], LEFT + [1.0, 0, 0])
    np.testing.assert_allclose(final["right"], RIGHT + [1.0, 0, 0])
    for before, after in zip(steps, steps[1:]):  # each step stands on the foot that just moved
        np.testing.assert_allclose(after.stance, before.goal)


# --------------------------------------------------------------------------- swing foot
@settings(max_examples=12, deadline=None)
@given(
    forward=st.floats(0.0, 0.3),
    lateral=st.floats(-0.05, 0.05),
    rise=st.floats(-0.02, 0.02),
)
def test_swing_reference_starts_and_ends_at_the_footholds_at_rest(
    swing_dmps, forward, lateral, rise
):
    start = np.array([0.3, -0.085, 0.0])
    goal = start + [forward, lateral, rise]
    reference = swing_reference(swing_dmps, start, goal)
    assert reference.times[-1] == pytest.approx(SINGLE)
    np.testing.assert_allclose(reference.positions[0], start, atol=1e-12)
    np.testing.assert_allclose(reference.velocities[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(reference.positions[-1], goal, atol=1.5e-3)
    np.testing.assert_allclose(reference.velocities[-1], 0.0, atol=0.02)
    assert reference.positions[:, 2].max() > max(start[2], goal[2]) + 0.03  # the foot lifts


def _minimum_jerk(u):
    u = np.clip(u, 0.0, 1.0)
    return 10 * u**3 - 15 * u**4 + 6 * u**5


def test_swing_reference_is_the_demonstration_re_targeted(swing_dmps):
    """At the demonstrated step (0.2 m) the path is the demonstration (written here with the
    default descent d = 0.4): minimum-jerk forward, over by s = 1 - d/2 = 0.8; up over the
    first 0.4 of the swing, level at 0.05 m, down over the last 0.4. A step in place goes
    straight up and down."""
    start = np.array([0.1, 0.085, 0.0])
    reference = swing_reference(swing_dmps, start, start + [0.2, 0, 0])
    s = reference.times / SINGLE
    forward = 0.2 * _minimum_jerk(s / 0.8)
    lift = 0.05 * np.where(s <= 0.5, _minimum_jerk(s / 0.4), _minimum_jerk((1 - s) / 0.4))
    np.testing.assert_allclose(reference.positions[:, 0] - start[0], forward, atol=5e-4)
    np.testing.assert_allclose(reference.positions[:, 2], lift, atol=5e-4)
    in_place = swing_reference(swing_dmps, start, start)
    np.testing.assert_allclose(
        in_place.positions[:, :2], np.tile(start[:2], (s.size, 1)), atol=1e-12
    )
    assert in_place.positions[:, 2].max() == pytest.approx(0.05, abs=5e-4)
    half = swing_reference(swing_dmps, start, start + [0.1, 0, 0])  # goal change: half the length
    np.testing.assert_allclose(half.positions[:, 0] - start[0], forward / 2, atol=5e-4)


@pytest.mark.parametrize("descent", [0.2, 0.4, 0.5])
def test_a_foot_meeting_ground_half_its_lift_higher_is_over_its_foothold(descent):
    """A box 4 cm high (half the 8 cm lift) from 0.36 m on, the step from x = 0 to 0.5 m (a
    sole 0.1 m long ahead of its frame): while the toe is over the box and the foot more than
    2 mm short of its foothold, the sole stays above the box's top, so it lands within 2 mm
    of the foothold (the old lift, a 5 cm bump 64 (s(1 - s))^3 h with progress m(s), met the
    box's top at 0.37 m: 128 mm short in MuJoCo)."""
    box, edge, toe, goal = 0.04, 0.36, 0.1, 0.5
    dmps = fit_swing_dmps(0.6, step_length=goal, height=2 * box, descent=descent)
    reference = swing_reference(dmps, np.zeros(3), np.array([goal, 0.0, 0.0]))
    x, z = reference.positions[:, 0], reference.positions[:, 2]
    short = (x + toe >= edge) & (x < goal - 2e-3)  # the toe over the box, the foot short
    assert short.any() and z[short].min() > box  # it would not touch the box there
    assert z[-1] == pytest.approx(0.0, abs=1e-3)
    s = np.linspace(0.0, 1.0, 601)
    old_z, old_x = 0.05 * 64 * (s * (1 - s)) ** 3, goal * _minimum_jerk(s)  # 5 cm high
    old_first = np.argmax((s > 0.5) & (old_z <= box))
    assert old_x[old_first] == pytest.approx(0.37, abs=0.01)


@settings(max_examples=20, deadline=None)
@given(
    state=st.lists(st.floats(-2.0, 2.0), min_size=4, max_size=4),
    duration=st.floats(0.05, 1.0),
)
def test_quintic_meets_its_boundary_conditions_and_its_derivatives(state, duration):
    """Starts at (p0, v0, a0), ends at the goal at rest at ``duration``, stays there after;
    its velocity and acceleration are its position's central differences (step 1e-5 s,
    truncation error ~ 1e-10 x the fifth derivative); from rest it is the minimum-jerk
    p0 + h (10 u^3 - 15 u^4 + 6 u^5) (written here)."""
    p0, v0, a0, goal = (np.array([x]) for x in state)
    at = lambda t: quintic(p0, v0, a0, goal, duration, t)  # noqa: E731
    for value, expected in zip(at(0.0), (p0, v0, a0)):
        np.testing.assert_allclose(value, expected, atol=1e-12)
    for t in (duration, 2 * duration):
        for value, expected in zip(at(t), (goal, 0.0, 0.0)):
            np.testing.assert_allclose(value, expected, atol=1e-8 / duration**2)
    t, h = 0.37 * duration, 1e-5
    np.testing.assert_allclose(at(t)[1], (at(t + h)[0] - at(t - h)[0]) / (2 * h), atol=1e-4)
    np.testing.assert_allclose(at(t)[2], (at(t + h)[1] - at(t - h)[1]) / (2 * h), atol=1e-3)
    u = 0.37
    rest = quintic(p0, 0.0 * v0, 0.0 * a0, goal, duration, t)[0]
    np.testing.assert_allclose(rest, p0 + (goal - p0) * _minimum_jerk(u), atol=1e-12)


# ---------------------------------------------------------------------------- bad inputs
@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda: lipm_time_constant(-0.8), InvalidInputError, "^com_height"),
        (lambda: lipm_time_constant(float("nan")), InvalidInputError, "^com_height"),
        (lambda: lipm_state([0.0, 1.0], [0.0], [0.0, 0.0], 0.1, 0.3), ShapeError, "^velocity"),
        (lambda: lipm_state([0.0], [0.0], [0.0], -1.0, 0.3), InvalidInputError, "^t must"),
        (lambda: footstep_plan(LEFT, RIGHT, 0, 3, float("nan")), InvalidInputError, "^step_length"),
        (lambda: footstep_plan(LEFT, RIGHT, 0, 3, 1.0), InvalidInputError, "^step_length"),
        (lambda: footstep_plan(LEFT[:2], RIGHT, 0, 3, 0.1), ShapeError, "^left"),
        (lambda: footstep_plan(LEFT, RIGHT, -1, 3, 0.1), InvalidInputError, "^n_in_place"),
        (lambda: footstep_plan(LEFT, RIGHT, 0, 2.5, 0.1), InvalidInputError, "^n_forward"),
        (lambda: footstep_plan(LEFT, RIGHT, 0, 3, 0.1, "middle"), InvalidInputError, "^first_side"),
        (lambda: plan_walk([(0, 1)], COM, 0.87, 0.8, 0.3), InvalidInputError, r"^footsteps\[0\]"),
        (lambda: plan_walk([], COM, 0.87, 0.0, 0.3), InvalidInputError, "^single_support"),
        (lambda: plan_walk([], COM, 0.87, 0.8, -0.1), InvalidInputError, "^double_support"),
        (lambda: plan_walk([], [0, 0, np.inf], 0.87, 0.8, 0.1), InvalidInputError, "^com"),
        (lambda: fit_swing_dmps(0.0), InvalidInputError, "^duration"),
        (lambda: fit_swing_dmps(0.8, height=-0.05), InvalidInputError, "^height"),
        (lambda: fit_swing_dmps(0.8, descent=0.6), InvalidInputError, "^descent"),
        (lambda: fit_swing_dmps(0.8, descent=0.0), InvalidInputError, "^descent"),
        (lambda: swing_reference("dmps", LEFT, LEFT), InvalidInputError, "^dmps"),
    ],
)
def test_bad_inputs_are_refused_with_the_argument_named(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_bad_swing_footholds_are_refused(swing_dmps):
    with pytest.raises(ShapeError, match="^goal"):
        swing_reference(swing_dmps, LEFT, [0.1, 0.0])
    with pytest.raises(InvalidInputError, match="^start"):
        swing_reference(swing_dmps, [np.nan, 0, 0], LEFT)


def test_footstep_is_a_checked_read_only_value():
    step = Footstep("left", LEFT, LEFT + [0.2, 0, 0], RIGHT)
    assert step.length == pytest.approx(0.2)
    with pytest.raises(ValueError, match="read-only"):
        step.goal[0] = 1.0
    with pytest.raises(InvalidInputError, match="^side"):
        Footstep("middle", LEFT, LEFT, RIGHT)
    with pytest.raises(ShapeError, match="^stance"):
        Footstep("left", LEFT, LEFT, RIGHT[:2])
    with pytest.raises(InvalidInputError, match="^goal"):
        Footstep("left", LEFT, [0.0, np.nan, 0.0], RIGHT)


@pytest.mark.parametrize("t", [np.nan, np.inf, "1.0", None])
def test_plan_refuses_times_that_are_not_finite_numbers(t):
    plan = walk()
    for query in (plan.com, plan.dcm, plan.zmp, plan.phase):
        with pytest.raises(InvalidInputError, match=r"^t[ \[]"):
            query(t)


# ------------------------------------------------------------- answer keys (mutation run)
def test_zmp_plan_is_the_piecewise_linear_schedule_written_plainly():
    """Two steps, default holds (1 s): the ZMP at the CoM for 1 s, then per step a double
    support moving it onto the stance foot and a single support on it, then a double support
    to the middle of the feet and 1 s there (np.interp of the knots written here)."""
    steps = footstep_plan(LEFT, RIGHT, 0, 1, 0.1)  # right forward, then left level with it
    plan = plan_walk(steps, COM, COM[2], SINGLE, DOUBLE)
    s, d = SINGLE, DOUBLE
    times = [0, 1, 1 + d, 1 + d + s, 1 + 2 * d + s, 1 + 2 * d + 2 * s, 1 + 3 * d + 2 * s]
    times.append(times[-1] + 1.0)
    middle = 0.5 * (steps[1].goal[:2] + steps[1].stance[:2])
    points = [COM[:2], COM[:2], LEFT[:2], LEFT[:2], steps[0].goal[:2], steps[0].goal[:2]]
    points += [middle, middle]
    points = np.array(points)
    np.testing.assert_allclose(plan.knot_times, times, atol=1e-15)
    np.testing.assert_allclose(plan.zmp_knots, points, atol=1e-15)
    np.testing.assert_allclose(plan.lift_off, [times[2], times[4]], atol=1e-15)
    np.testing.assert_allclose(plan.touchdown, [times[3], times[5]], atol=1e-15)
    assert plan.duration == pytest.approx(times[-1], abs=1e-15)
    t = np.linspace(0.0, times[-1], 701)
    expected = np.column_stack([np.interp(t, times, points[:, k]) for k in range(2)])
    np.testing.assert_allclose(plan.zmp(t), expected, atol=1e-12)
    assert plan.time_constant == pytest.approx(np.sqrt(COM[2] / 9.81))


def test_com_follows_scipy_integration_of_the_lipm_on_each_segment():
    """Answer key: scipy integrates x'' = (g / z_c)(x - p(t)), p(t) linear between the knots,
    over each segment from the plan's state at its start (the LIPM diverges: restarting per
    segment keeps round-off small)."""
    steps = footstep_plan(LEFT, RIGHT, 1, 2, 0.15)
    plan = plan_walk(steps, COM, 0.8, SINGLE, DOUBLE, initial_hold=1.2, final_hold=0.7)
    w2 = GRAVITY / 0.8
    knots, points = plan.knot_times, plan.zmp_knots  # checked against the plain schedule above
    for ta, tb, pa, pb in zip(knots, knots[1:], points, points[1:]):
        if tb == ta:
            continue
        x0, v0, _ = plan.com(ta)

        def rhs(t, y, ta=ta, tb=tb, pa=pa, pb=pb):
            p = pa + (pb - pa) * (t - ta) / (tb - ta)
            return np.concatenate([y[2:], w2 * (y[:2] - p)])

        t = np.linspace(ta, tb, 6)
        ode = solve_ivp(rhs, (ta, tb), np.concatenate([x0[:2], v0[:2]]), t_eval=t, rtol=1e-11,
                        atol=1e-13)  # fmt: skip
        position, velocity, _ = plan.com(t)
        np.testing.assert_allclose(position[:, :2], ode.y[:2].T, atol=1e-8)
        np.testing.assert_allclose(velocity[:, :2], ode.y[2:].T, atol=1e-7)
        np.testing.assert_allclose(position[:, 2], 0.8)  # the plan's height, not the CoM's z
        np.testing.assert_array_equal(velocity[:, 2], 0.0)
    assert plan.com_height == 0.8 and type(plan.com_height) is float


def test_without_footsteps_the_plan_holds_the_com_still():
    com = np.array([0.02, -0.01, 0.87])
    plan = plan_walk([], com, COM[2], SINGLE, DOUBLE, initial_hold=0.5, final_hold=0.25)
    np.testing.assert_allclose(plan.knot_times, [0.0, 0.5, 0.75])
    for knots in (plan.zmp_knots, plan.dcm_knots, plan.com_knots):
        np.testing.assert_array_equal(knots, np.tile(com[:2], (3, 1)))
    assert plan.lift_off.shape == (0,) and plan.touchdown.shape == (0,)
    t = np.linspace(0.0, 0.75, 7)
    position, velocity, acceleration = plan.com(t)
    np.testing.assert_allclose(position, np.tile(com, (7, 1)), atol=1e-15)
    np.testing.assert_allclose(velocity, 0.0, atol=1e-15)
    np.testing.assert_allclose(acceleration, 0.0, atol=1e-15)
    np.testing.assert_allclose(plan.dcm(t), np.tile(com[:2], (7, 1)), atol=1e-15)
    assert plan.phase(0.1) == ("double", 0)


def test_queries_outside_the_plan_are_clipped_and_keep_their_shape():
    plan = walk()
    for query in (plan.zmp, plan.dcm):
        np.testing.assert_array_equal(query(-1.0), query(0.0))
        np.testing.assert_array_equal(query(plan.duration + 3.0), query(plan.duration))
        assert query(0.3).shape == (2,)
        assert query([0.3]).shape == (1, 2)
        assert query(np.full((2, 3), 0.3)).shape == (2, 3, 2)
    for part, before, start in zip(plan.com(-1.0), plan.com(0.0), plan.com([0.0, 0.0])):
        np.testing.assert_array_equal(part, before)
        assert part.shape == (3,) and start.shape == (2, 3)
    end = plan.com(plan.duration)
    for part, after in zip(end, plan.com(plan.duration + 2.0)):
        np.testing.assert_array_equal(part, after)


def test_at_a_zmp_jump_the_plan_takes_the_segment_after_it():
    """No double support: at each lift-off the ZMP is already on the new stance foot, and the
    DCM and CoM are finite and continuous across it."""
    plan = walk(n_in_place=0, n_forward=3, double=0.0)
    for step, start in zip(plan.footsteps, plan.lift_off):
        np.testing.assert_allclose(plan.zmp(start), step.stance[:2], atol=1e-15)
        for query in (plan.dcm, lambda t: plan.com(t)[0]):
            np.testing.assert_allclose(query(start), query(start - 1e-9), atol=1e-7)
        assert np.isfinite(plan.com(np.array([start]))[2]).all()


def test_phase_at_the_exact_lift_off_and_touchdown_times():
    plan = walk()
    n = len(plan.footsteps)
    for i, (start, end) in enumerate(zip(plan.lift_off, plan.touchdown)):
        assert plan.phase(start) == ("single", i)
        assert plan.phase(end) == ("double", i + 1)
    assert plan.phase(-1.0) == ("double", 0)
    assert plan.phase(plan.duration + 1.0) == ("double", n)


def test_defaults_gravity_first_side_holds_and_sample_period():
    assert lipm_time_constant(0.981) == pytest.approx(np.sqrt(0.1), rel=1e-15)
    assert lipm_time_constant(2.0, gravity=2.0) == 1.0
    steps = footstep_plan(LEFT, RIGHT, 3, 0, 0.1)
    assert [s.side for s in steps] == ["right", "left", "right"]  # in place only: no closing
    assert [s.side for s in footstep_plan(LEFT, RIGHT, 0, 1, 0.1, first_side="left")] == [
        "left",
        "right",
    ]
    plan = plan_walk(steps, COM, COM[2], SINGLE, 0.0)
    assert plan.duration == pytest.approx(1.0 + 3 * SINGLE + 1.0)
    dmps = fit_swing_dmps(0.4)
    assert dmps.duration == 0.4
    reference = swing_reference(dmps, LEFT, LEFT)
    np.testing.assert_allclose(np.diff(reference.times), 1e-3, atol=1e-12)
    assert reference.positions[:, 2].max() == pytest.approx(0.05, abs=2e-3)  # default height
    assert reference.positions.shape == (401, 3)


def test_lipm_state_at_time_zero_is_the_start_and_rows_are_refused():
    position, velocity = lipm_state([0.1, -0.2], [0.3, 0.0], [0.0, 0.05], 0, 0.3)
    np.testing.assert_array_equal(position, [0.1, -0.2])
    np.testing.assert_array_equal(velocity, [0.3, 0.0])
    with pytest.raises(ShapeError, match="^position"):
        lipm_state([[0.1]], [[0.0]], [[0.0]], 0.1, 0.3)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: lipm_time_constant(0.0), r"^com_height must be a finite number > 0, got 0"),
        (lambda: lipm_time_constant(0.8, gravity=0.0), r"^gravity must be a finite number > 0"),
        (lambda: lipm_state([0.0], [0.0], [0.0, 1.0], 0.1, 0.3), r"^zmp"),
        (lambda: lipm_state([0.0], [0.0], [0.0], 0.1, 0.0), r"^time_constant must be .* > 0"),
        (lambda: lipm_state([0.0], [0.0], [0.0], -0.1, 0.3), r"^t must be a finite number >= 0"),
        (lambda: steady_dcm_offset(np.nan, 0.8, 0.3), r"^step_length must be a finite number"),
        (lambda: steady_dcm_offset(0.1, 0.0, 0.3), r"^single_support must be .* > 0, got 0"),
        (lambda: steady_dcm_offset(0.1, 0.8, 0.0), r"^time_constant must be .* > 0, got 0"),
        (lambda: footstep_plan(LEFT, RIGHT, 0, 1, 0.41), r"^step_length must be .* <= 0\.4"),
        (lambda: footstep_plan(LEFT, RIGHT, 0, 1, -0.01), r"^step_length must be .* >= 0"),
        (lambda: footstep_plan(LEFT, [0, 0], 0, 1, 0.1), r"^right has shape \(2,\), expected"),
        (lambda: plan_walk([], COM, 0.0, 0.8, 0.3), r"^com_height must be .* > 0"),
        (lambda: plan_walk([], COM, 0.87, 0.8, 0.3, 0.0), r"^initial_hold must be .* > 0, got 0"),
        (lambda: plan_walk([], COM, 0.87, 0.8, 0.3, 1.0, 0.0), r"^final_hold must be .* > 0"),
        (lambda: plan_walk([], COM, 0.87, 0.8, 0.3, gravity=-1), r"^gravity must be .* > 0"),
        (lambda: plan_walk([], COM[:2], 0.87, 0.8, 0.3), r"^com has shape \(2,\)"),
        (lambda: fit_swing_dmps(0.8, step_length=0.0), r"^step_length must be .* > 0, got 0"),
        (lambda: fit_swing_dmps(0.8, height=0.0), r"^height must be .* > 0, got 0"),
        (lambda: fit_swing_dmps(0.8, dt=0.0), r"^dt must be .* > 0 and <= 0\.04, got 0"),
        (lambda: fit_swing_dmps(0.1), r"^dt must be .* <= 0\.005, got 0\.01"),
    ],
)
def test_each_argument_is_named_with_its_bounds(call, match):
    from dmpopt.exceptions import DmpoptError

    with pytest.raises(DmpoptError, match=match):
        call()


def test_plan_walk_accepts_zero_double_support_and_names_the_step_index():
    plan = plan_walk([], COM, 0.87, 0.8, 0.0)
    assert plan.duration == 2.0
    steps = footstep_plan(LEFT, RIGHT, 0, 1, 0.1)
    with pytest.raises(InvalidInputError, match=r"footsteps\[2\] is a str, expected a Footstep"):
        plan_walk([*steps, "step"], COM, 0.87, 0.8, 0.3)


# ------------------------------------------------------------------------ re-planning
# Answer keys: the LIPM's time invariance (a late touchdown only delays what follows, so the
# shifted plan's ZMP and DCM after it are the original's, delayed) and its translation
# invariance (moving every foothold from the one after step i on by d moves the ZMP and the
# DCM by d once the ZMP has left step i's stance foot); the footstep chain itself.
@settings(max_examples=15, deadline=None)
@given(step=st.integers(0, 5), delay=st.floats(-0.3, 0.4))
def test_with_touchdown_delays_everything_after_it(step, delay):
    plan = walk()
    shifted = plan.with_touchdown(step, plan.touchdown[step] + delay)
    assert shifted.touchdown[step] == pytest.approx(plan.touchdown[step] + delay)
    assert shifted.lift_off[step] == plan.lift_off[step]
    assert shifted.lift_off[step + 1 :] == pytest.approx(plan.lift_off[step + 1 :] + delay)
    t = np.linspace(shifted.touchdown[step], shifted.duration, 50)
    assert shifted.zmp(t) == pytest.approx(plan.zmp(t - delay), abs=1e-12)
    assert shifted.dcm(t) == pytest.approx(plan.dcm(t - delay), abs=1e-12)
    # the single support stretched or shortened: the ZMP stays on the stance foot
    middle = 0.5 * (shifted.lift_off[step] + shifted.touchdown[step])
    assert shifted.zmp(middle) == pytest.approx(plan.footsteps[step].stance[:2], abs=1e-12)


@settings(max_examples=15, deadline=None)
@given(step=st.integers(0, 4), dx=st.floats(-0.1, 0.1), dy=st.floats(-0.1, 0.1))
def test_with_goal_translates_the_rest_of_the_walk(step, dx, dy):
    plan = walk()
    shift = np.array([dx, dy, 0.0])
    moved = plan.with_goal(step, plan.footsteps[step].goal + shift)
    for j, (old, new) in enumerate(zip(plan.footsteps, moved.footsteps)):
        assert new.goal == pytest.approx(old.goal + (shift if j >= step else 0.0), abs=1e-15)
    for before, after in zip(moved.footsteps, moved.footsteps[1:]):  # the chain holds
        assert after.stance == pytest.approx(before.goal, abs=1e-15)
    t = np.linspace(moved.lift_off[step + 1], moved.duration, 50)
    assert moved.dcm(t) == pytest.approx(plan.dcm(t) + shift[:2], abs=1e-12)
    assert moved.zmp(t) == pytest.approx(plan.zmp(t) + shift[:2], abs=1e-12)
    assert moved.knot_times == pytest.approx(plan.knot_times, abs=0.0)


@settings(max_examples=15, deadline=None)
@given(step=st.integers(0, 5), early=st.floats(0.01, 0.9))
def test_an_early_touchdown_keeps_the_next_lift_off_and_stretches_the_double_support(step, early):
    """shift_later=False: the knots from the next lift-off on are the original's, so (the DCM
    being solved backwards from the end) the ZMP and DCM from there on are the original's;
    in the stretched double support the ZMP moves linearly from the stance foot to the next
    (written here)."""
    plan = walk()
    time = plan.touchdown[step] - early * SINGLE  # ``early`` of the single support early
    kept = plan.with_touchdown(step, time, shift_later=False)
    assert kept.touchdown[step] == pytest.approx(time)
    np.testing.assert_array_equal(kept.lift_off, plan.lift_off)
    np.testing.assert_array_equal(np.delete(kept.touchdown, step), np.delete(plan.touchdown, step))
    end = kept.knot_times[4 + 2 * step]
    t = np.linspace(end, kept.duration, 40)
    assert kept.zmp(t) == pytest.approx(plan.zmp(t), abs=1e-12)
    assert kept.dcm(t) == pytest.approx(plan.dcm(t), abs=1e-12)
    a, b = plan.footsteps[step].stance[:2], kept.zmp(end)
    for fraction in (0.25, 0.5, 0.75):
        middle = time + fraction * (end - time)
        assert kept.zmp(middle) == pytest.approx(a + fraction * (b - a), abs=1e-12)


@settings(max_examples=15, deadline=None)
@given(step=st.integers(1, 5), change=st.floats(-0.2, 0.3))
def test_with_lift_off_shortens_the_double_support_and_delays_the_rest(step, change):
    """The double support before step ``step`` ends ``change`` later (earlier if negative):
    its start (the previous touchdown) is kept, the knots from the lift-off on are the
    original's shifted by ``change`` (time invariance: the ZMP and DCM from there on are the
    original's, delayed), and in the double support the ZMP moves linearly between the two
    feet (written here)."""
    plan = walk()
    time = plan.lift_off[step] + change
    moved = plan.with_lift_off(step, time)
    assert moved.lift_off[step] == pytest.approx(time)
    np.testing.assert_array_equal(moved.knot_times[: 2 + 2 * step], plan.knot_times[: 2 + 2 * step])
    assert moved.knot_times[2 + 2 * step :] == pytest.approx(
        plan.knot_times[2 + 2 * step :] + change
    )
    t = np.linspace(time, moved.duration, 40)
    assert moved.zmp(t) == pytest.approx(plan.zmp(t - change), abs=1e-12)
    assert moved.dcm(t) == pytest.approx(plan.dcm(t - change), abs=1e-12)
    start = plan.touchdown[step - 1]
    a, b = plan.footsteps[step - 1].stance[:2], plan.footsteps[step].stance[:2]
    for fraction in (0.25, 0.5, 0.75):
        assert moved.zmp(start + fraction * (time - start)) == pytest.approx(
            a + fraction * (b - a), abs=1e-12
        )


def test_replanning_names_a_bad_step_or_time():
    plan = walk()
    with pytest.raises(InvalidInputError, match="^step must be < 6"):
        plan.with_goal(6, [0.0, 0.0, 0.0])
    with pytest.raises(InvalidInputError, match="^time must be"):
        plan.with_touchdown(0, plan.lift_off[0])
    with pytest.raises(InvalidInputError, match=r"^time must be <= .*shift_later=True"):
        plan.with_touchdown(0, plan.lift_off[1] + 0.1, shift_later=False)
    with pytest.raises(ShapeError, match="^goal has shape"):
        plan.with_goal(0, [0.0, 0.0])
    with pytest.raises(
        InvalidInputError, match=r"^time must be .* >= 2.6, .*start of step 1.s double support"
    ):
        plan.with_lift_off(1, plan.touchdown[0] - 0.01)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: quintic([np.nan], [0.0], [0.0], [1.0], 0.5, 0.1), r"^position\[0\] is nan"),
        (lambda: quintic([0.0], [np.nan], [0.0], [1.0], 0.5, 0.1), r"^velocity\[0\] is nan"),
        (lambda: quintic([0.0], [0.0], [np.nan], [1.0], 0.5, 0.1), r"^acceleration\[0\] is nan"),
        (lambda: quintic([0.0], [0.0], [0.0], [np.nan], 0.5, 0.1), r"^goal\[0\] is nan"),
        (lambda: quintic([0.0], [0.0], [0.0], [1.0], 0.0, 0.1),
         r"^duration must be a finite number > 0, got 0"),
        (lambda: quintic([0.0], [0.0], [0.0], [1.0], 0.5, -0.1),
         r"^t must be a finite number >= 0, got -0\.1"),
    ],
)  # fmt: skip
def test_quintic_names_each_argument_with_its_bound(call, match):
    with pytest.raises(InvalidInputError, match=match):
        call()


def test_replanned_walks_keep_the_com_height_and_the_feet_chain():
    """A replanned plan's CoM stays at the 0.87 m it was planned at; after with_goal each step
    starts where its foot last landed (the first ones from the initial LEFT and RIGHT)."""
    plan = walk()
    t = np.linspace(0.0, plan.duration, 7)
    for replanned in (
        plan.with_lift_off(2, plan.lift_off[2] - 0.1),
        plan.with_goal(2, plan.footsteps[2].goal + [0.05, 0.02, 0.0]),
        plan.with_touchdown(2, plan.touchdown[2] - 0.1, shift_later=False),
    ):
        np.testing.assert_array_equal(replanned.com(t)[0][:, 2], 0.87)  # fmt: skip
        assert replanned.com(0.0)[0][:2] == pytest.approx(COM[:2], abs=1e-15)  # at rest at COM
    forward = walk(n_in_place=0)  # its first step moves (a step in place would hide the start)
    moved = forward.with_goal(2, forward.footsteps[2].goal + [0.05, 0.02, 0.0])
    last = {"left": LEFT, "right": RIGHT}
    for step in moved.footsteps:
        np.testing.assert_array_equal(step.start, last[step.side])
        last[step.side] = step.goal


def test_swing_dmps_are_fitted_to_the_demonstration_at_its_sample_period():
    """The default demonstration (L = 0.2 m, h = 0.05 m, d = 0.4) written here from the
    docstring, sampled every 0.01 s over the 0.8 s swing (81 samples), fitted with 20
    basis functions: the same DMPs as fit_swing_dmps' (one fit of the same data)."""
    from dmpopt.fitting import fit_discrete
    from dmpopt.trajectory import Trajectory

    times = np.arange(81) * 0.01
    s = times / 0.8
    forward = 0.2 * _minimum_jerk(s / 0.8)
    lift = 0.05 * _minimum_jerk(np.minimum(s, 1 - s) / 0.4)
    horizontal = fit_discrete(Trajectory.from_positions(times, np.column_stack([forward, 0 * s])),
                              20, goal_scaling="rotation")  # fmt: skip
    vertical = fit_discrete(Trajectory.from_positions(times, lift[:, None]), 20,
                            goal_scaling="translation")  # fmt: skip
    dmps = fit_swing_dmps(0.8)
    np.testing.assert_allclose(dmps.horizontal.weights, horizontal.weights, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(dmps.vertical.weights, vertical.weights, rtol=1e-9, atol=1e-9)
    assert (dmps.horizontal.goal_scaling, dmps.vertical.goal_scaling) == ("rotation", "translation")


def test_replanning_names_the_step_and_the_lift_off_and_allows_touchdown_at_the_end():
    """shift_later=False accepts a touchdown at the end of the step's double support itself
    (the double support then lasts 0 s: the ZMP jumps onto the next stance foot)."""
    plan = walk()
    with pytest.raises(InvalidInputError, match=r"^step must be an integer >= 0, got -1"):
        plan.with_goal(-1, [0.0, 0.0, 0.0])
    lift_off = plan.lift_off[2]
    with pytest.raises(InvalidInputError, match=rf"; after step 2's lift-off at {lift_off:.4g} s$"):
        plan.with_touchdown(2, lift_off)
    end = plan.knot_times[4 + 2 * 2]
    at_end = plan.with_touchdown(2, end, shift_later=False)
    assert at_end.touchdown[2] == end == at_end.lift_off[3]


def test_zmp_and_dcm_in_one_call_are_the_two_queries():
    """The ZMP on the stance foot mid-swing (plan_walk's docstring) and the DCM query."""
    plan = walk()
    t = np.array([0.5 * (plan.lift_off[2] + plan.touchdown[2]), plan.duration])
    zmp, dcm = plan.zmp_and_dcm(t)
    assert zmp[0] == pytest.approx(plan.footsteps[2].stance[:2], abs=1e-15)
    np.testing.assert_array_equal(zmp, plan.zmp(t))
    np.testing.assert_array_equal(dcm, plan.dcm(t))


# --------------------------------------------------------- one float time (a walk's tick)
def _segment_written_out(plan, t):
    """ZMP, DCM and CoM position at ``t`` from the segment formula of the module docstring:
    p = p_a + m (t - t_a), xi = p + m / w + c e^{w (t - t_b)} with c = xi_b - p_b - m / w,
    x = p + c/2 e^{w (t - t_b)} + E e^{-w (t - t_a)} with E from x(t_a) = x_a."""
    times = plan.knot_times
    t = min(max(t, 0.0), times[-1])
    k = min(max(int(np.searchsorted(times, t, side="right")) - 1, 0), len(times) - 2)
    w, ta, tb = 1.0 / plan.time_constant, times[k], times[k + 1]
    pa, pb, xi_b, x_a = plan.zmp_knots[k], plan.zmp_knots[k + 1], plan.dcm_knots[k + 1], \
        plan.com_knots[k]  # fmt: skip
    m = (pb - pa) / (tb - ta)
    c = xi_b - pb - m / w
    big_e = x_a - pa - c / 2 * np.exp(-w * (tb - ta))
    p = pa + m * (t - ta)
    return p, p + m / w + c * np.exp(w * (t - tb)), \
        p + c / 2 * np.exp(w * (t - tb)) + big_e * np.exp(-w * (t - ta))  # fmt: skip


@settings(max_examples=60, deadline=None)
@given(t=st.floats(-0.5, 12.0), late=st.floats(0.0, 0.1))
def test_one_float_time_is_the_formula_and_the_array_query_to_the_last_bit(t, late):
    """A walker asks for one float time each tick, answered by its own path (per-axis float
    arithmetic on coefficients kept per segment, the last answer kept). Answer key: the
    segment formula written out here (agreeing to 1e-12 m: a few roundings of O(1 m) terms,
    the exponentials at most 1); and the array query at the same time, equal to the last bit
    (the walk's logs are compared bitwise across versions), also on a re-planned walk."""
    plan = walk()
    for query in (plan, plan.with_touchdown(2, float(plan.touchdown[2]) + late)):
        zmp, dcm = query.zmp_and_dcm(t)
        position, velocity, acceleration = query.com(t)
        np.testing.assert_allclose(
            np.concatenate([zmp, dcm, position[:2]]),
            np.concatenate(_segment_written_out(query, t)), rtol=0, atol=1e-12,
        )  # fmt: skip
        assert position[2] == COM[2] and velocity[2] == acceleration[2] == 0.0
        array = np.array([t])
        for one, many in zip((zmp, dcm), query.zmp_and_dcm(array)):
            np.testing.assert_array_equal(one, many[0])
        for one, many in zip((position, velocity, acceleration), query.com(array)):
            np.testing.assert_array_equal(one, many[0])


def test_the_kept_answer_is_read_only_and_each_plan_keeps_its_own():
    """The answer kept for the last time cannot be changed by a caller, and a re-planned walk
    (a later touchdown: the DCM differs before it) answers from its own knots."""
    plan = walk()
    t = float(plan.lift_off[2]) + 0.1
    zmp, dcm = plan.zmp_and_dcm(t)
    with pytest.raises(ValueError, match="read-only"):
        dcm[0] = 1.0
    later = plan.with_touchdown(2, float(plan.touchdown[2]) + 0.05)
    assert not np.array_equal(later.dcm(t), dcm)
    np.testing.assert_array_equal(plan.dcm(t), dcm)
    np.testing.assert_array_equal(later.dcm(t), later.dcm(np.array([t]))[0])


def test_com_at_a_grid_of_times_is_the_com_at_each_time():
    """com at times of shape (2, 3) has shape (2, 3, 3): at each time the one-time values
    (x, y, com_height), (vx, vy, 0), (ax, ay, 0)."""
    plan = walk()
    times = np.linspace(0.2, plan.duration - 0.2, 6).reshape(2, 3)
    grid = plan.com(times)
    for values in grid:
        assert values.shape == (2, 3, 3)
    for index in np.ndindex(2, 3):
        one = plan.com(float(times[index]))
        for got, expected in zip(grid, one):
            np.testing.assert_array_equal(got[index], expected)
    assert np.all(grid[0][..., 2] == COM[2]) and not grid[1][..., 2].any()
