"""Tests of the planar biped: model, ground contact, heel strikes, phase reset, a short walk."""

import numpy as np
import pytest

from dmpopt.sim import GroundContact, Simulator
from robots import biped as biped_model
from robots.biped import load_biped

GRAVITY = 9.81


@pytest.fixture(scope="module")
def biped():
    return load_biped()


@pytest.fixture(scope="module")
def gait():
    from studies.biped import learn_gait

    return learn_gait()


def test_model_matches_its_documented_parameters(biped):
    """7 kg, 0.6 m legs, planar base (x, z, pitch) plus four actuated joints."""
    assert biped.mass == pytest.approx(7.0)
    assert biped_model.leg_length(biped) == pytest.approx(0.6)
    assert biped.model.nq == biped.model.nv == 7
    q = biped_model.configuration(biped, 0.0, 0.6, 0.0, [0.3, 0.0, 0.0, 0.0])
    right, left = biped_model.foot_positions(biped, q)
    assert right == pytest.approx([0.6 * np.sin(0.3), 0.6 - 0.6 * np.cos(0.3)])
    assert left == pytest.approx([0.0, 0.0])


def test_actuator_torques_follow_the_model_order(biped):
    torques = biped_model.actuator_torques(biped, [1.0, 2.0, 3.0, 4.0])
    assert torques[biped.velocity_indices("gait") - 3] == pytest.approx([1, 2, 3, 4])


def test_standing_biped_rests_at_spring_height_with_weight_on_feet(biped):
    """Dropped with locked joints, the feet carry m g and sink by F / k each."""
    ground = GroundContact(stiffness=1e4, damping=150.0, friction=0.8)
    sim = Simulator(biped.model, 1e-3, biped.contact_points, ground)
    assert sim.n_base_dofs == 3
    joints = np.array([0.15, 0.1, -0.15, 0.1])
    q = biped_model.configuration(biped, 0.0, 0.0, 0.0, joints)
    q[1] = 0.05 - biped_model.foot_positions(biped, q)[:, 1].min()
    state = sim.reset(q)
    index = biped.velocity_indices("gait")
    for _ in range(2500):
        torque = 200.0 * (joints - state.q[index]) - 2.0 * state.v[index]
        boom = [0.0, 0.0, -500.0 * state.q[2] - 30.0 * state.v[2]]
        state = sim.step(biped_model.actuator_torques(biped, torque), boom)
    assert state.in_contact.all()
    assert state.contact_forces[:, 2].sum() == pytest.approx(biped.mass * GRAVITY, rel=2e-3)
    sink = -state.contact_positions[:, 2]
    assert sink == pytest.approx(state.contact_forces[:, 2] / 1e4, rel=1e-2, abs=1e-5)
    assert np.abs(state.v).max() < 1e-2


@pytest.mark.parametrize("backend", ["mujoco", "native"])
def test_short_walk_does_not_fall_and_strikes_alternate(biped, gait, backend):
    """Seeded 6 s walk on each simulator: no fall, forward progress, alternating heel strikes
    with the phase reset to 0 (right) or pi (left) as eq. (21) says."""
    from studies.biped import walk

    _, dmp = gait
    log = walk(biped, dmp, duration=6.0, frequency=5.0, adapt=True, seed=0, backend=backend)
    assert not log.fell, log.diverged
    assert log.distance > 1.5
    assert log.positive_work > 0 and log.absolute_work >= log.positive_work
    legs = [leg for _, leg, _ in log.strikes]
    assert len(legs) >= 4
    assert all(a != b for a, b in zip(legs, legs[1:]))
    times = np.array([t for t, _, _ in log.strikes])
    assert np.all(np.diff(times) > 0.1)
    assert len(log.frequencies) == len(log.strikes)


def test_phase_reset_sets_the_dmp_phase_per_eq_21(gait):
    """After a strike of the right leg the shared phase is 0, after the left leg pi."""
    from dmpopt.walking import FrequencyAdaptation, HeelStrike

    _, dmp = gait
    stepper = dmp.stepper(1e-3)
    adaptation = FrequencyAdaptation(frequency=5.0, gain=0.3)
    for _ in range(123):
        stepper.step()
    for time, leg, expected in ((0.123, 1, np.pi), (0.6, 0, 0.0)):
        phase, frequency = adaptation.on_heel_strike(HeelStrike(time, leg, np.zeros(3)))
        stepper.reset_phase(phase)
        stepper.set_tau(1.0 / frequency)
        assert stepper.phase == pytest.approx(expected)
    stepper.step()
    assert stepper.phase == pytest.approx(frequency * 1e-3)


def test_demonstration_puts_both_feet_on_the_ground_at_heel_strike(gait):
    """Retargeted to point feet: both legs reach equally far down at phase 0 and pi."""
    demo, _ = gait

    def reach(hip, knee):  # vertical hip-to-foot distance, thigh and shank 0.3 m
        return 0.3 * np.cos(hip) + 0.3 * np.cos(hip - knee)

    n = (len(demo.times) - 1) // 2
    for k in (0, n // 2):
        right, left = demo.positions[k, :2], demo.positions[k, 2:]
        assert reach(*right) == pytest.approx(reach(*left), abs=2e-3)


def test_adaptation_moves_towards_the_measured_step_rate(biped, gait):
    """From the too-high demonstrated frequency the walker steps slower than pi / omega, so
    eq. (21) lowers omega, every update by K times the measured error."""
    from studies.biped import ADAPTATION_GAIN, walk

    _, dmp = gait
    log = walk(biped, dmp, duration=6.0, frequency=5.0, adapt=True, seed=0, log_every=10**9)
    frequencies = np.asarray(log.frequencies)
    durations = np.diff([t for t, _, _ in log.strikes])
    expected = frequencies[:-1] + ADAPTATION_GAIN * (np.pi / durations - frequencies[:-1])
    assert frequencies[1:] == pytest.approx(expected, rel=1e-12)
    assert frequencies[-1] < 0.9 * frequencies[0]


def test_push_survival_needs_continued_stepping(biped, gait):
    """A small push is survived; the bisection returns the upper bound when that survives."""
    from studies.biped import largest_survived_push, survives_push

    _, dmp = gait
    assert survives_push(biped, dmp, 2.4, True, 2.0, seed=0)
    assert largest_survived_push(biped, dmp, 2.4, True, 0, upper=5.0, tolerance=10.0) == 5.0


def test_unknown_backend_is_refused(biped, gait):
    from dmpopt.exceptions import InvalidInputError
    from studies.biped import walk

    with pytest.raises(InvalidInputError, match="backend must be one of .*'native2'"):
        walk(biped, gait[1], duration=1.0, frequency=5.0, backend="native2")


def test_mujoco_fall_height_matches_the_native_one(biped):
    """Both backends get the same fall options: the same thresholds, min height FALL_HEIGHT."""
    from studies.biped import FALL_HEIGHT, make_simulator

    mujoco, native = (make_simulator(biped, b).fall_detector for b in ("mujoco", "native"))
    assert mujoco == native
    assert mujoco.min_height == FALL_HEIGHT


def test_quick_study_walks_in_mujoco(tmp_path):
    """Quick study, MuJoCo by default: walks without falling, native numbers side by side."""
    from studies import biped as study

    metrics = study.run(tmp_path, quick=True)
    mujoco, native = metrics["mujoco"], metrics["native"]
    assert metrics["backend"] == "mujoco"
    assert mujoco["fell"] is False and mujoco["steps_walked"] >= 10
    assert mujoco["steps_walked"] == metrics["steps_walked"]
    assert native["fell"] is False and native["steps_walked"] >= 10
    assert mujoco["real_time_factor"] > 0 and native["real_time_factor"] > 0
    # 20 s of walking at the adapted ~4 rad/s: pi / omega s per step, about 25 steps.
    expected = 20.0 * mujoco["frequency_final"] / np.pi
    assert abs(mujoco["steps_walked"] - expected) < 0.25 * expected
    assert metrics["videos"] == [] and metrics["videos_skipped"] == "quick run"
