"""Fall detection (dmpopt.sim.falls): thresholds, each check against an answer key, the planar
biped, and pushes on standing Talos that end in a detected fall, never in divergence."""

from dataclasses import astuple

import numpy as np
import pinocchio as pin
import pytest
from dmpopt_robots import biped as biped_model
from hypothesis import given, settings
from hypothesis import strategies as st
from test_simulator import GRAVITY, box_at, box_corners, free_box

from dmpopt.exceptions import InvalidInputError
from dmpopt.sim import FallDetector, GroundContact, Simulator, base_tilt

GROUND = GroundContact(stiffness=2e4, damping=300.0, friction=0.8)


def test_thresholds_derived_from_the_standing_height():
    """h / 2, the free-fall time over the other half, and the toppling speed sqrt(2 g / h)."""
    detector = FallDetector.for_standing_height(1.2)
    assert detector.min_height == pytest.approx(0.6)
    assert detector.max_flight_time == pytest.approx(np.sqrt(2 * 0.6 / GRAVITY))
    assert detector.max_spin == pytest.approx(np.sqrt(2 * GRAVITY / 1.2))
    assert detector.max_tilt == pytest.approx(np.pi / 4)


@pytest.mark.parametrize(
    "arguments, message",
    [
        (dict(min_height=float("nan")), "min_height must be a height"),
        (dict(min_height=np.inf), "min_height must be below"),
        (dict(min_height=0.5, max_tilt=0.0), "max_tilt must be a bound > 0"),
        (dict(min_height=0.5, max_flight_time=-1.0), "max_flight_time must be a bound > 0"),
        (
            dict(min_height=0.5, max_spin="fast"),
            r"max_spin must be a real number \(a bound > 0, or np.inf to disable\), got 'fast'",
        ),
    ],
)
def test_bad_thresholds_are_named(arguments, message):
    with pytest.raises(InvalidInputError, match=message):
        FallDetector(**arguments)


def test_bad_check_inputs_and_standing_height_are_named():
    with pytest.raises(InvalidInputError, match="height must be a finite number"):
        FallDetector(0.5).check(0.1, float("nan"), 0.0, 0.0, 0.0)
    with pytest.raises(InvalidInputError, match="standing_height must be a height"):
        FallDetector.for_standing_height(-1.0)


@settings(max_examples=40, deadline=None)
@given(
    values=st.tuples(*[st.floats(0.0, 2.0) for _ in range(4)]),
    limits=st.tuples(*[st.floats(0.1, 1.9) for _ in range(4)]),
)
def test_check_reports_the_first_threshold_crossed(values, limits):
    """Order height, tilt, no contact, spin; the Fall carries the value and its threshold."""
    height, tilt, flight, spin = values
    detector = FallDetector(*limits)
    crossed = [
        ("height", height, height < limits[0]),
        ("tilt", tilt, tilt > limits[1]),
        ("no contact", flight, flight > limits[2]),
        ("spin", spin, spin > limits[3]),
    ]
    expected = next(((c, v, i) for i, (c, v, hit) in enumerate(crossed) if hit), None)
    fall = detector.check(1.5, height, tilt, flight, spin)
    if expected is None:
        assert fall is None
    else:
        cause, value, index = expected
        assert (fall.time, fall.cause, fall.value, fall.threshold) == (
            1.5,
            cause,
            value,
            limits[index],
        )


@settings(max_examples=30, deadline=None)
@given(angle=st.floats(0.0, np.pi), heading=st.floats(-np.pi, np.pi), yaw=st.floats(-3.0, 3.0))
def test_tilt_of_a_rotation_about_a_horizontal_axis_is_its_angle(angle, heading, yaw):
    """Yaw first, then a rotation by ``angle`` about any horizontal axis: the tilt is ``angle``."""
    axis = np.array([np.cos(heading), np.sin(heading), 0.0])
    rotation = pin.AngleAxis(angle, axis).toRotationMatrix() @ pin.utils.rotate("z", yaw)
    assert base_tilt(rotation) == pytest.approx(angle, abs=1e-6)


def test_free_fall_height_follows_half_g_t_squared_until_the_fall():
    """A box dropped from 3 m falls as 3 - g t^2 / 2 (semi-implicit Euler: within g dt t / 2)
    and is reported at the first step below 1 m, at t = sqrt(2 (3 - 1) / g)."""
    dt = 1e-3
    model = free_box()
    sim = Simulator(model, dt, box_corners(), GROUND, falls=FallDetector(min_height=1.0))
    sim.reset(box_at(3.0, model))
    while True:
        state = sim.step(np.zeros(0))
        if state.fall is not None:
            break
        assert state.q[2] == pytest.approx(
            3.0 - 0.5 * GRAVITY * state.t**2, abs=GRAVITY * dt * state.t
        )
    expected = np.sqrt(2 * 2.0 / GRAVITY)
    assert state.fall.cause == "height" and state.fall.time == pytest.approx(expected, abs=2 * dt)
    assert state.fall.value < 1.0 <= state.fall.value + GRAVITY * expected * dt
    assert state.fallen and sim.fallen
    with pytest.raises(
        InvalidInputError, match=r"step\(\) after the robot fell at t = .*base height"
    ):
        sim.step(np.zeros(0))
    sim.reset(box_at(3.0, model))  # reset clears the fall
    assert sim.step(np.zeros(0)).fall is None


@pytest.mark.parametrize("angle_deg, falls", [(30.0, False), (50.0, True), (170.0, True)])
def test_box_rotated_by_a_known_angle_has_that_tilt(angle_deg, falls):
    """A box held in the air (no gravity) rotated about x falls by tilt iff the angle > 45 deg."""
    model = free_box()
    model.gravity.linear[:] = 0.0
    sim = Simulator(model, 1e-3, falls=FallDetector(min_height=-np.inf))
    q = box_at(1.0, model)
    q[3:7] = pin.Quaternion(pin.utils.rotate("x", np.radians(angle_deg))).coeffs()
    sim.reset(q)
    fall = sim.step(np.zeros(0)).fall
    assert (fall is not None) == falls
    if falls:
        assert fall.cause == "tilt" and fall.value == pytest.approx(np.radians(angle_deg))
        assert fall.reason == f"base tilted {angle_deg:.0f} deg > 45 deg"


@pytest.mark.parametrize("rate, falls", [(2.0, False), (6.0, True)])
def test_spin_faster_than_the_bound_is_a_fall(rate, falls):
    """A box spinning about z (no tilt) in zero gravity falls iff its rate exceeds max_spin."""
    model = free_box()
    model.gravity.linear[:] = 0.0
    sim = Simulator(model, 1e-3, falls=FallDetector(min_height=-np.inf, max_spin=4.0))
    sim.reset(box_at(1.0, model), [0, 0, 0, 0, 0, rate])
    fall = sim.step(np.zeros(0)).fall
    assert (fall is not None) == falls
    if falls:
        assert fall.cause == "spin" and fall.value == pytest.approx(rate)


@pytest.mark.parametrize("speed", [0.3, 1.0])
def test_flight_longer_than_the_limit_is_a_fall_a_short_hop_is_not(speed):
    """A box leaving the ground at ``speed`` is airborne 2 speed / g: 0.06 s is a hop, 0.2 s
    is more than max_flight_time = 0.1 s and a fall 0.1 s after the last contact."""
    dt, limit = 1e-3, 0.1
    model = free_box()
    sim = Simulator(
        model, dt, box_corners(), GROUND, falls=FallDetector(-np.inf, max_flight_time=limit)
    )
    sim.reset(box_at(0.1 - 1e-5, model), [0, 0, speed, 0, 0, 0])
    last_contact, fall = 0.0, None
    for _ in range(400):
        state = sim.step(np.zeros(0))
        fall = state.fall
        if fall is not None:
            break
        if state.in_contact.any():
            last_contact = state.t
    airtime = 2 * speed / GRAVITY
    if airtime < limit:
        assert fall is None
    else:
        assert last_contact == pytest.approx(dt)
        assert fall.cause == "no contact"
        assert fall.time == pytest.approx(last_contact + limit, abs=1.5 * dt)


def test_defaults_come_from_the_neutral_standing_height(talos, biped):
    """Talos: base 1.083 m above its soles with straight legs; the biped: its 0.6 m leg."""
    data = talos.model.createData()
    pin.framesForwardKinematics(talos.model, data, pin.neutral(talos.model))
    soles = [data.oMf[talos.model.getFrameId(f)].translation[2] for f in talos.foot_frames]
    talos_height = data.oMi[1].translation[2] - min(soles)
    points = [(f, c) for f in talos.foot_frames for c in talos.sole_corners]
    assert talos_height == pytest.approx(1.083, abs=1e-3)
    for sim, height in (
        (Simulator(talos.model, 1e-3, points, GROUND), talos_height),
        (Simulator(biped.model, 1e-3, biped.contact_points, GROUND), biped_model.leg_length(biped)),
    ):
        expected = FallDetector.for_standing_height(height)
        assert astuple(sim.fall_detector) == pytest.approx(astuple(expected), rel=1e-12)
    sim = Simulator(biped.model, 1e-3, biped.contact_points, GROUND, fall_height=0.35)
    assert sim.fall_detector.min_height == 0.35


@pytest.mark.parametrize("pitch, falls", [(0.5, False), (-0.5, False), (0.9, True), (-0.9, True)])
def test_planar_biped_tilt_is_its_pitch(biped, pitch, falls):
    """The planar base's orientation is the pitch coordinate: |pitch| > 45 deg is a fall."""
    sim = Simulator(biped.model, 1e-3, biped.contact_points, GROUND)
    q = biped_model.configuration(biped, 0.0, 2.0, pitch, np.zeros(4))
    sim.reset(q)
    fall = sim.step(np.zeros(4)).fall
    assert (fall is not None) == falls
    if falls:
        assert fall.cause == "tilt" and fall.value == pytest.approx(abs(pitch), abs=1e-6)


def test_biped_collapsing_without_torques_falls_below_half_its_leg(biped):
    """Straight-legged biped standing with no torques and no boom: it falls; the first check
    to fire is reported and the hip is then above the ground (it did not sink through it)."""
    sim = Simulator(biped.model, 1e-3, biped.contact_points, GROUND)
    q = biped_model.configuration(
        biped, 0.0, biped_model.leg_length(biped), 0.02, [0.1, 0.2, -0.1, 0.2]
    )
    q[1] -= biped_model.foot_positions(biped, q)[:, 1].min()
    state = sim.reset(q)
    for _ in range(3000):
        state = sim.step(np.zeros(4))
        if state.fall:
            break
    assert state.fall is not None and state.fall.cause in ("height", "tilt")
    assert state.q[1] > 0.0


# ------------------------------------------------------------ pushes on standing Talos
def _push_standing_talos(robot, force, duration=1.5, push_time=0.3):
    """Talos standing under the humanoid study's QP controller, pushed forward at the pelvis
    for 0.1 s; returns the final state."""
    from dmpopt_studies.humanoid import build_controller, make_simulator

    q_start = np.array(robot.reference_configuration)
    controller, _ = build_controller(robot, q_start)
    simulator, q0 = make_simulator(robot, q_start)
    state = simulator.reset(q0)
    for k in range(int(round(duration / 1e-3))):
        if k == int(round(push_time / 1e-3)):
            simulator.push("base_link", [force, 0.0, 0.0], 0.1)
        state = simulator.step(controller.compute_torques(state.q, state.v))
        if state.fall is not None:
            break
    return state


def test_small_push_is_survived(talos):
    """50 N for 0.1 s: Talos stays up, no fall."""
    state = _push_standing_talos(talos, 50.0)
    assert state.fall is None and state.t == pytest.approx(1.5)


@pytest.mark.parametrize("force", [200.0, 300.0, 400.0])
def test_strong_push_ends_in_a_fall_not_in_divergence(talos, force):
    """200-400 N for 0.1 s (30-40 N s on 100 kg, beyond the capture region of feet 0.21 m
    long at 300 N and above): the run ends standing or in a detected fall, never in
    SimulationDiverged; 300 N and more always fall."""
    state = _push_standing_talos(talos, force)
    if force >= 300.0:
        assert state.fall is not None
    if state.fall is not None:
        assert state.fall.time > 0.3 and state.fall.reason
        assert np.abs(state.v).max() < 1e3
