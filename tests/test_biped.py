"""Tests of the planar biped: model, ground contact, heel strikes, phase reset, a short walk."""

import numpy as np
import pytest

from dmpopt.sim import GroundContact, Simulator
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
    assert biped.leg_length == pytest.approx(0.6)
    assert biped.model.nq == biped.model.nv == 7
    q = biped.configuration(0.0, 0.6, 0.0, [0.3, 0.0, 0.0, 0.0])
    right, left = biped.foot_positions(q)
    assert right == pytest.approx([0.6 * np.sin(0.3), 0.6 - 0.6 * np.cos(0.3)])
    assert left == pytest.approx([0.0, 0.0])


def test_actuator_torques_follow_the_model_order(biped):
    torques = biped.actuator_torques([1.0, 2.0, 3.0, 4.0])
    assert torques[biped.joint_velocity_indices - 3] == pytest.approx([1, 2, 3, 4])


def test_standing_biped_rests_at_spring_height_with_weight_on_feet(biped):
    """Dropped with locked joints, the feet carry m g and sink by F / k each."""
    ground = GroundContact(stiffness=1e4, damping=150.0, friction=0.8)
    sim = Simulator(biped.model, 1e-3, biped.contact_points, ground)
    assert sim.n_base_dofs == 3
    joints = np.array([0.15, 0.1, -0.15, 0.1])
    q = biped.configuration(0.0, 0.0, 0.0, joints)
    q[1] = 0.05 - biped.foot_positions(q)[:, 1].min()
    state = sim.reset(q)
    index = biped.joint_velocity_indices
    for _ in range(2500):
        torque = 200.0 * (joints - state.q[index]) - 2.0 * state.v[index]
        boom = [0.0, 0.0, -500.0 * state.q[2] - 30.0 * state.v[2]]
        state = sim.step(biped.actuator_torques(torque), boom)
    assert state.in_contact.all()
    assert state.contact_forces[:, 2].sum() == pytest.approx(biped.mass * GRAVITY, rel=2e-3)
    sink = -state.contact_positions[:, 2]
    assert sink == pytest.approx(state.contact_forces[:, 2] / 1e4, rel=1e-2, abs=1e-5)
    assert np.abs(state.v).max() < 1e-2


def test_short_walk_does_not_fall_and_strikes_alternate(biped, gait):
    """Seeded 6 s walk: no fall, forward progress, alternating heel strikes with the phase
    reset to 0 (right) or pi (left) as eq. (21) says."""
    from studies.biped import walk

    _, dmp = gait
    log = walk(biped, dmp, duration=6.0, frequency=5.0, adapt=True, seed=0)
    assert not log.fell, log.diverged
    assert log.distance > 0.5
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
        stepper.set_time_constant(1.0 / frequency)
        assert stepper.phase == pytest.approx(expected)
    stepper.step()
    assert stepper.phase == pytest.approx(frequency * 1e-3)
