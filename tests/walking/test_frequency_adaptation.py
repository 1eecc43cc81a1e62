"""Tests of dmpopt.frequency_adaptation: eq. (21) phase resetting, frequency adaptation and
heel strikes."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.exceptions import InvalidInputError
from dmpopt.frequency_adaptation import (
    FrequencyAdaptation,
    HeelStrike,
    HeelStrikeDetector,
    adapt_frequency,
    heel_strike_phase,
    measured_frequency,
)


def test_measured_frequency_is_pi_over_step_duration():
    """omega_measured = pi / T_n: a step is half a period."""
    assert measured_frequency(0.5) == pytest.approx(2 * np.pi)


def test_adaptation_law_matches_eq_21():
    """omega_{n+1} = omega_n + K (pi / T_n - omega_n)."""
    assert adapt_frequency(4.0, 0.5, 0.25) == pytest.approx(4.0 + 0.25 * (2 * np.pi - 4.0))


def test_adaptation_converges_geometrically_to_measured_frequency():
    """With a constant step duration the error shrinks by (1 - K) per step."""
    frequency, target = 2.0, np.pi / 0.4
    errors = []
    for _ in range(20):
        frequency = adapt_frequency(frequency, 0.4, 0.3)
        errors.append(abs(frequency - target))
    assert np.allclose(np.diff(np.log(errors)), np.log(0.7))


def test_heel_strike_phase_is_zero_for_own_leg_and_pi_for_other():
    assert heel_strike_phase(0) == 0.0
    assert heel_strike_phase(1) == pytest.approx(np.pi)
    assert heel_strike_phase(0, oscillator_leg=1) == pytest.approx(np.pi)


def test_phase_reset_and_adaptation_at_heel_strikes():
    """Each strike returns the eq. (21) phase; the frequency moves after the second strike."""
    adaptation = FrequencyAdaptation(frequency=3.0, gain=0.5)
    phase, frequency = adaptation.on_heel_strike(HeelStrike(1.0, 0, np.zeros(3)))
    assert (phase, frequency) == (0.0, 3.0)
    phase, frequency = adaptation.on_heel_strike(HeelStrike(1.5, 1, np.zeros(3)))
    assert phase == pytest.approx(np.pi)
    assert frequency == pytest.approx(3.0 + 0.5 * (np.pi / 0.5 - 3.0))
    assert adaptation.step_durations == [0.5]
    assert adaptation.frequencies == [3.0, frequency]


def test_switches_turn_resetting_and_adaptation_off():
    adaptation = FrequencyAdaptation(frequency=3.0, gain=0.5, reset_phase=False, adapt=False)
    for k, t in enumerate((1.0, 1.4, 1.9)):
        phase, frequency = adaptation.on_heel_strike(HeelStrike(t, k % 2, np.zeros(3)))
        assert phase is None and frequency == 3.0
    assert adaptation.step_durations == pytest.approx([0.4, 0.5])


def test_detector_reports_alternating_strikes_and_ignores_chatter():
    """A bounce (short flight) and a repeated touchdown of the same leg are not steps."""
    detector = HeelStrikeDetector(min_swing_time=0.1)
    sequence = [
        (0.00, (True, True)),
        (0.05, (True, False)),  # left lifts off
        (0.40, (True, True)),  # left lands: strike
        (0.45, (False, True)),  # right lifts off
        (0.47, (True, True)),  # right bounces back after 20 ms: chatter
        (0.50, (False, True)),
        (0.90, (True, True)),  # right lands: strike
        (0.95, (True, False)),
        (1.30, (True, False)),
    ]
    strikes = [s for t, c in sequence if (s := detector.update(t, c)) is not None]
    assert [(s.time, s.leg) for s in strikes] == [(0.40, 1), (0.90, 0)]


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.booleans()), max_size=40))
def test_skipping_updates_with_the_last_seen_flags_finds_the_same_strikes(flags):
    """``last_contact`` is what the last update was given (both True at first), and updates
    with those flags find nothing: a detector fed only the changes finds the strikes of one
    fed every tick (the walker skips the rest)."""
    every, changes = HeelStrikeDetector(0.1), HeelStrikeDetector(0.1)
    assert every.last_contact == (True, True)
    for k, pair in enumerate(flags):
        time = 0.06 * k
        every.update(time, pair)
        assert every.last_contact == pair
        if pair != changes.last_contact:
            changes.update(time, pair)
    assert [(s.time, s.leg) for s in changes.strikes] == [(s.time, s.leg) for s in every.strikes]


def test_bad_arguments_are_named():
    with pytest.raises(InvalidInputError, match="^step_duration must be a finite number > 0"):
        measured_frequency(0.0)
    with pytest.raises(InvalidInputError, match="^gain must be a finite number >= 0 and <= 2"):
        adapt_frequency(1.0, 0.5, -0.1)
    with pytest.raises(InvalidInputError, match="^leg must be 0 or 1"):
        heel_strike_phase(2)
    with pytest.raises(InvalidInputError, match="^frequency must be a finite number > 0"):
        FrequencyAdaptation(frequency=0.0)


def _pendulum(mass=2.0, lever=0.25, inertia_com=0.01):
    """One revolute joint about y, centre of mass ``lever`` below the axis."""
    import pinocchio as pin

    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRY(), pin.SE3.Identity(), "hip")
    inertia = pin.Inertia(mass, np.array([0.0, 0.0, -lever]), np.diag([1.0, inertia_com, 1.0]))
    model.appendBodyToJoint(joint, inertia, pin.SE3.Identity())
    return model


@pytest.mark.parametrize("stiffness", [0.0, 3.0, 40.0])
def test_closed_loop_frequency_of_a_pendulum_is_sqrt_of_stiffness_plus_mgd_over_i(stiffness):
    """Hand-derived: omega = sqrt((k_p + m g d) / (I_c + m d^2)); damping does not change it."""
    from dmpopt.frequency_adaptation import closed_loop_frequencies

    m, d, i_c = 2.0, 0.25, 0.01
    model = _pendulum(m, d, i_c)

    def law(q, v):
        return np.array([-stiffness * q[0] - 0.7 * v[0]])

    omega = closed_loop_frequencies(model, np.zeros(1), [0], law)
    expected = np.sqrt((stiffness + m * 9.81 * d) / (i_c + m * d**2))
    assert omega == pytest.approx([expected], rel=1e-6)


def test_closed_loop_frequency_flags_an_unstable_mode_as_nan():
    """Inverted (q = pi) and unactuated: K = -m g d < 0, no oscillation."""
    from dmpopt.frequency_adaptation import closed_loop_frequencies

    omega = closed_loop_frequencies(_pendulum(), np.array([np.pi]), [0], lambda q, v: [0.0])
    assert np.isnan(omega).all()


@pytest.mark.parametrize(
    "joints, law, match",
    [
        ([1], lambda q, v: [0.0], "joints must be distinct"),
        ([0, 0], lambda q, v: [0.0, 0.0], "joints must be distinct"),
        ([0.5], lambda q, v: [0.0], "joints must be distinct"),
        ([0], "pd", "torque_law must be a callable"),
        (
            [0],
            lambda q, v: [np.nan],
            r"^torque_law\(q, v\)\[0\] is nan: .*\(generalised forces on joints \[N m\]\)",
        ),
        (
            [0],
            lambda q, v: [0.0, 1.0],
            r"^torque_law\(q, v\) has shape \(2,\), expected \(1,\) "
            r"\(generalised forces on joints \[N m\]\)",
        ),
    ],
)
def test_closed_loop_frequencies_refuses_bad_input(joints, law, match):
    from dmpopt.exceptions import DmpoptError
    from dmpopt.frequency_adaptation import closed_loop_frequencies

    with pytest.raises(DmpoptError, match=match):
        closed_loop_frequencies(_pendulum(), np.zeros(1), joints, law)


def test_closed_loop_frequencies_needs_a_configuration_of_the_model():
    from dmpopt.exceptions import ShapeError
    from dmpopt.frequency_adaptation import closed_loop_frequencies

    match = r"^q has shape \(2,\), expected \(1,\) \(a configuration of model\)"
    with pytest.raises(ShapeError, match=match):
        closed_loop_frequencies(_pendulum(), np.zeros(2), [0], lambda q, v: [0.0])


# ------------------------------------------------------------- answer keys (mutation run)
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: measured_frequency(-1.0), r"^step_duration must be a finite number > 0, got -1"),
        (lambda: adapt_frequency(0.0, 0.5, 0.5), r"^frequency must be a finite number > 0, got 0"),
        (lambda: adapt_frequency(1.0, 0.5, 2.01), r"^gain must be a finite number >= 0 and <= 2"),
        (
            lambda: adapt_frequency(1.0, 0.5, 3.0),
            r"^gain must .*, got 3\.0; \[0, 1\] converges without overshoot$",
        ),
        (lambda: heel_strike_phase(True), r"^leg must be 0 or 1, got True"),
        (lambda: heel_strike_phase(1.0), r"^leg must be 0 or 1, got 1\.0"),
        (lambda: heel_strike_phase(0, -1), r"^oscillator_leg must be 0 or 1, got -1"),
        (lambda: HeelStrike(np.nan, 0, np.zeros(3)), r"^time must be a finite number"),
        (lambda: HeelStrike(0.0, 2, np.zeros(3)), r"^leg must be 0 or 1, got 2"),
        (lambda: HeelStrike(0.0, 0, [0.0, np.inf, 0.0]), r"^position"),
        (lambda: HeelStrike(0.0, 0, np.zeros(2)), r"^position has shape \(2,\), expected \(3,\)"),
        (lambda: HeelStrikeDetector().update(np.nan, (1, 1)), r"^time must be a finite number"),
        (lambda: HeelStrikeDetector(-0.1), r"^min_swing_time must be a finite number >= 0"),
        (lambda: HeelStrikeDetector(0.1, alternate=1), r"^alternate must be True or False"),
        (lambda: FrequencyAdaptation(1.0, gain=2.5), r"^gain must be a finite number >= 0"),
        (lambda: FrequencyAdaptation(1.0, oscillator_leg=2), r"^oscillator_leg must be 0 or 1"),
        (lambda: FrequencyAdaptation(1.0, reset_phase=1), r"^reset_phase must be True or False"),
        (lambda: FrequencyAdaptation(1.0, adapt="yes"), r"^adapt must be True or False"),
        (lambda: FrequencyAdaptation(1.0).on_heel_strike(1.0), r"^strike must be a HeelStrike"),
    ],
)
def test_every_argument_is_checked_by_name_with_its_bounds(call, match):
    from dmpopt.exceptions import DmpoptError

    with pytest.raises(DmpoptError, match=match):
        call()


def test_bounds_are_inclusive_where_documented():
    """gain in [0, 2] (2 included: eq. (21) still converges, with overshoot), leg 0 or 1 as
    NumPy integers, swing time 0 allowed."""
    assert adapt_frequency(1.0, 0.5, 2.0) == pytest.approx(1.0 + 2.0 * (2 * np.pi - 1.0))
    assert adapt_frequency(1.0, 0.5, 0.0) == 1.0
    assert heel_strike_phase(np.int64(1), np.int8(1)) == 0.0
    assert HeelStrikeDetector(0.0).min_swing_time == 0.0


def test_heel_strike_keeps_its_values_as_floats_and_arrays():
    strike = HeelStrike(1, np.int64(1), [0.1, 0.2, 0.3])
    assert type(strike.time) is float and type(strike.leg) is int
    assert isinstance(strike.position, np.ndarray)
    np.testing.assert_array_equal(strike.position, [0.1, 0.2, 0.3])


def test_detector_defaults_and_the_swing_time_boundary():
    """Defaults: 0.1 s of flight, alternation required. A flight of exactly min_swing_time
    counts (>=); the detector starts with both feet down (no strike at the first update)."""
    detector = HeelStrikeDetector()
    assert detector.min_swing_time == 0.1 and detector.alternate is True
    assert detector.update(0.0, (True, True)) is None
    detector = HeelStrikeDetector(min_swing_time=0.25)
    assert detector.update(0.5, (True, False)) is None  # right lifts off
    strike = detector.update(0.75, (True, True))  # 0.25 s exactly in the air
    assert (strike.time, strike.leg) == (0.75, 1)
    np.testing.assert_array_equal(strike.position, np.zeros(3))
    assert detector.strikes == [strike]


def test_detector_accepts_integer_flags_equal_times_and_stores_positions():
    detector = HeelStrikeDetector(min_swing_time=0.1)
    detector.update(0.0, np.array([1, 0]))
    detector.update(0.0, np.array([1, 0]))  # the same time again is allowed
    feet = np.array([[0.1, 0.1, 0.0], [0.4, -0.1, 0.0]])
    strike = detector.update(0.3, [1, 1], positions=feet)
    assert strike.leg == 1
    np.testing.assert_array_equal(strike.position, feet[1])
    with pytest.raises(InvalidInputError, match="time must not decrease between updates"):
        detector.update(0.2, (True, True))


@pytest.mark.parametrize(
    ("flags", "positions", "match"),
    [
        (None, None, r"in_contact must be two booleans"),
        ((True,), None, r"in_contact must be two booleans"),
        ((0.5, 1.0), None, r"in_contact must be two booleans"),
        (("a", "b"), None, r"in_contact must be two booleans"),
        ((True, True), np.zeros((2, 2)), r"positions has shape \(2, 2\), expected \(2, 3\)"),
        ((True, True), np.full((2, 3), np.nan), r"^positions\[0, 0\] is nan"),
    ],
)
def test_detector_refuses_bad_flags_and_positions(flags, positions, match):
    from dmpopt.exceptions import DmpoptError

    with pytest.raises(DmpoptError, match=match):
        HeelStrikeDetector().update(1.0, flags, positions)


def test_detector_without_alternation_counts_the_same_leg_twice():
    """alternate=False: two touchdowns of the right foot, each after a long flight, count."""
    for alternate, expected in ((False, [1, 1]), (True, [1])):
        detector = HeelStrikeDetector(min_swing_time=0.1, alternate=alternate)
        legs = []
        for t, flags in ((0.1, (1, 0)), (0.5, (1, 1)), (0.6, (1, 0)), (1.0, (1, 1))):
            strike = detector.update(t, flags)
            if strike is not None:
                legs.append(strike.leg)
        assert legs == expected


def test_frequency_adaptation_defaults_follow_eq_21():
    """Defaults: K = 0.3, resetting and adaptation on, phase 0 at the left (0) heel strike."""
    adaptation = FrequencyAdaptation(frequency=2)
    assert adaptation.frequency == 2.0 and type(adaptation.frequency) is float
    phase, _ = adaptation.on_heel_strike(HeelStrike(0.0, 0, np.zeros(3)))
    assert phase == 0.0
    phase, frequency = adaptation.on_heel_strike(HeelStrike(0.4, 1, np.zeros(3)))
    assert phase == pytest.approx(np.pi)
    assert frequency == pytest.approx(2.0 + 0.3 * (np.pi / 0.4 - 2.0))
    assert adaptation.frequencies == pytest.approx([2.0, frequency])


def test_frequency_adaptation_refuses_strikes_out_of_order():
    adaptation = FrequencyAdaptation(frequency=2.0)
    adaptation.on_heel_strike(HeelStrike(1.0, 0, np.zeros(3)))
    with pytest.raises(InvalidInputError, match=r"strike.time = 1.0 does not follow .* at 1.0"):
        adaptation.on_heel_strike(HeelStrike(1.0, 1, np.zeros(3)))
    assert adaptation.step_durations == []


def _double_pendulum(m1, l1, i1, m2, l2, i2):
    """Two revolute joints about y; link k has its centre of mass l_k below its joint, the
    second joint sits l1 below the first."""
    import pinocchio as pin

    model = pin.Model()
    first = model.addJoint(0, pin.JointModelRY(), pin.SE3.Identity(), "hip")
    model.appendBodyToJoint(
        first,
        pin.Inertia(m1, np.array([0.0, 0.0, -l1]), np.diag([1.0, i1, 1.0])),
        pin.SE3.Identity(),
    )
    placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, -l1]))
    second = model.addJoint(first, pin.JointModelRY(), placement, "knee")
    model.appendBodyToJoint(
        second,
        pin.Inertia(m2, np.array([0.0, 0.0, -l2]), np.diag([1.0, i2, 1.0])),
        pin.SE3.Identity(),
    )
    return model


def test_closed_loop_frequencies_of_a_double_pendulum_solve_k_x_equals_lambda_m_x():
    """Answer key: the hanging double pendulum's mass and stiffness matrices written plainly,
    M = [[I1 + m1 l1^2 + I2 + m2 (l1^2 + l2^2 + 2 l1 l2), I2 + m2 (l2^2 + l1 l2)], [., I2 +
    m2 l2^2]], K = diag(k) + g [[m1 l1 + m2 (l1 + l2), m2 l2], [m2 l2, m2 l2]], and scipy's
    generalised symmetric eigensolver; with the first joint held, the second alone."""
    from scipy.linalg import eigh

    from dmpopt.frequency_adaptation import closed_loop_frequencies

    m1, l1, i1, m2, l2, i2, g = 3.0, 0.4, 0.02, 1.5, 0.3, 0.01, 9.81
    k = np.array([30.0, 5.0])
    model = _double_pendulum(m1, l1, i1, m2, l2, i2)
    model.gravity.linear = np.array([0.0, 0.0, -g])
    mass = np.array(
        [
            [
                i1 + m1 * l1**2 + i2 + m2 * (l1**2 + l2**2 + 2 * l1 * l2),
                i2 + m2 * (l2**2 + l1 * l2),
            ],
            [i2 + m2 * (l2**2 + l1 * l2), i2 + m2 * l2**2],
        ]
    )
    stiffness = np.diag(k) + g * np.array([[m1 * l1 + m2 * (l1 + l2), m2 * l2], [m2 * l2, m2 * l2]])
    expected = np.sqrt(eigh(stiffness, mass, eigvals_only=True))

    def law(q, v):
        return -k * q - 0.5 * v

    omega = closed_loop_frequencies(model, np.zeros(2), [0, 1], law)
    np.testing.assert_allclose(omega, expected, rtol=1e-6)
    assert omega[0] < omega[1]
    knee = closed_loop_frequencies(model, np.zeros(2), np.array([1]), lambda q, v: law(q, v)[1:])
    np.testing.assert_allclose(knee, [np.sqrt((k[1] + m2 * g * l2) / (i2 + m2 * l2**2))], rtol=1e-6)


def test_a_neutral_mode_has_frequency_zero_not_nan():
    """Centre of mass on the axis, no feedback: K = 0 exactly, omega = 0 (only K < 0 is NaN)."""
    from dmpopt.frequency_adaptation import closed_loop_frequencies

    omega = closed_loop_frequencies(_pendulum(lever=0.0), np.zeros(1), [0], lambda q, v: [0.0])
    assert omega.tolist() == [0.0]


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("model", np.zeros(1), [0]), r"^model must be a pinocchio.Model, got str"),
        ((None, np.zeros(1), [[0]]), r"^joints must be distinct velocity indices in \[0, 1\)"),
        ((None, np.zeros(1), []), r"^joints must be distinct"),
        ((None, np.zeros(1), [-1]), r"^joints must be distinct"),
        ((None, np.zeros(1), [0], 0.0), r"^step must be a finite number > 0"),
        ((None, [np.nan], [0]), r"^q\[0\] is nan: q contains 1 NaN .*\(a configuration of model\)"),
    ],
)
def test_closed_loop_frequencies_names_each_bad_argument(args, match):
    from dmpopt.exceptions import DmpoptError
    from dmpopt.frequency_adaptation import closed_loop_frequencies

    model, q, joints, *step = args
    model = _pendulum() if model is None else model
    with pytest.raises(DmpoptError, match=match):
        closed_loop_frequencies(model, q, joints, lambda q, v: [0.0], *step)


def test_detector_measures_the_flight_from_the_first_update_in_the_air():
    """Lift-off is the first update without contact (later updates in the air do not move it);
    the last update in contact before it does not count."""
    detector = HeelStrikeDetector(min_swing_time=0.4)  # flight 1.0 -> 1.5: a strike
    for t, flags in ((0.0, (1, 1)), (1.0, (1, 0)), (1.2, (1, 0))):
        assert detector.update(t, flags) is None
    assert detector.update(1.5, (1, 1)).leg == 1
    detector = HeelStrikeDetector(min_swing_time=0.75)  # flight 0.5 s only: no strike
    for t, flags in ((0.0, (1, 1)), (1.0, (1, 0)), (1.5, (1, 1))):
        assert detector.update(t, flags) is None


def test_phase_reset_of_an_oscillator_on_the_right_leg():
    adaptation = FrequencyAdaptation(frequency=3.0, oscillator_leg=1)
    assert adaptation.on_heel_strike(HeelStrike(0.0, 1, np.zeros(3)))[0] == 0.0
    assert adaptation.on_heel_strike(HeelStrike(0.5, 0, np.zeros(3)))[0] == pytest.approx(np.pi)


@pytest.mark.parametrize("rate, slope", [(6.0, 0.0), (3.0, 0.5), (1.0, 0.9)])
def test_eq_21_settles_at_its_fixed_point_not_necessarily_the_legs(rate, slope):
    """Eq. (21) settles where the measured step rate equals the oscillator's: for a walker
    whose step rate pi / T_n is rate + slope * omega (slope 0: set by the legs alone; slope
    near 1: the controller imposes its own timing), omega* = rate / (1 - slope), reached
    geometrically as (1 - K (1 - slope))^n."""
    from dmpopt.frequency_adaptation import adapt_frequency

    gain, omega = 0.3, 13.0
    expected = rate / (1 - slope)
    for n in range(1, 1000):
        omega = adapt_frequency(omega, np.pi / (rate + slope * omega), gain)
        contraction = (1 - gain * (1 - slope)) ** n
        assert abs(omega - expected) <= abs(13.0 - expected) * contraction * (1 + 1e-9) + 1e-12
    assert omega == pytest.approx(expected, rel=1e-6)
