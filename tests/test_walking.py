"""Tests of dmpopt.walking: eq. (21) phase resetting, frequency adaptation, heel strikes."""

import numpy as np
import pytest

from dmpopt.exceptions import InvalidInputError
from dmpopt.walking import (
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


def test_bad_arguments_are_named():
    with pytest.raises(InvalidInputError, match="step_duration must be a finite number > 0"):
        measured_frequency(0.0)
    with pytest.raises(InvalidInputError, match="gain must be a finite number >= 0 and <= 2"):
        adapt_frequency(1.0, 0.5, -0.1)
    with pytest.raises(InvalidInputError, match="leg must be 0 or 1"):
        heel_strike_phase(2)
    with pytest.raises(InvalidInputError, match="frequency must be a finite number > 0"):
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
    from dmpopt.walking import closed_loop_frequencies

    m, d, i_c = 2.0, 0.25, 0.01
    model = _pendulum(m, d, i_c)

    def law(q, v):
        return np.array([-stiffness * q[0] - 0.7 * v[0]])

    omega = closed_loop_frequencies(model, np.zeros(1), [0], law)
    expected = np.sqrt((stiffness + m * 9.81 * d) / (i_c + m * d**2))
    assert omega == pytest.approx([expected], rel=1e-6)


def test_closed_loop_frequency_flags_an_unstable_mode_as_nan():
    """Inverted (q = pi) and unactuated: K = -m g d < 0, no oscillation."""
    from dmpopt.walking import closed_loop_frequencies

    omega = closed_loop_frequencies(_pendulum(), np.array([np.pi]), [0], lambda q, v: [0.0])
    assert np.isnan(omega).all()


@pytest.mark.parametrize(
    "joints, law, match",
    [
        ([1], lambda q, v: [0.0], "joints must be distinct"),
        ([0, 0], lambda q, v: [0.0, 0.0], "joints must be distinct"),
        ([0.5], lambda q, v: [0.0], "joints must be distinct"),
        ([0], "pd", "torque_law must be a callable"),
        ([0], lambda q, v: [np.nan], r"torque_law\(q, v\)"),
        ([0], lambda q, v: [0.0, 1.0], r"torque_law\(q, v\) has shape"),
    ],
)
def test_closed_loop_frequencies_refuses_bad_input(joints, law, match):
    from dmpopt.exceptions import DmpoptError
    from dmpopt.walking import closed_loop_frequencies

    with pytest.raises(DmpoptError, match=match):
        closed_loop_frequencies(_pendulum(), np.zeros(1), joints, law)


def test_closed_loop_frequencies_needs_a_configuration_of_the_model():
    from dmpopt.exceptions import ShapeError
    from dmpopt.walking import closed_loop_frequencies

    with pytest.raises(ShapeError, match="q has shape"):
        closed_loop_frequencies(_pendulum(), np.zeros(2), [0], lambda q, v: [0.0])
