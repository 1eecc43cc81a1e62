"""Tests of dmpopt.sim: energy, resting contact, Coulomb friction, touchdowns, falls, pushes."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.exceptions import InvalidInputError, ShapeError, SimulationDiverged
from dmpopt.sim import FallDetector, GroundContact, Simulator

GRAVITY = 9.81


def double_pendulum() -> pin.Model:
    """Fixed-base planar double pendulum (two 1 m rods of 1 kg, pitch joints)."""
    model = pin.Model()
    parent, placement = 0, pin.SE3.Identity()
    for i in range(2):
        joint = model.addJoint(parent, pin.JointModelRY(), placement, f"joint_{i}")
        rod = pin.Inertia(1.0, np.array([0, 0, -0.5]), np.diag([1 / 12, 1 / 12, 1e-3]))
        model.appendBodyToJoint(joint, rod, pin.SE3.Identity())
        model.addFrame(pin.Frame(f"link_{i}", joint, 0, pin.SE3.Identity(), pin.FrameType.BODY))
        parent, placement = joint, pin.SE3(np.eye(3), np.array([0, 0, -1.0]))
    return model


def free_box(mass=2.0, size=(0.4, 0.3, 0.2)) -> pin.Model:
    """Free-flying box with a frame ``box`` at its centre."""
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "root")
    model.appendBodyToJoint(joint, pin.Inertia.FromBox(mass, *size), pin.SE3.Identity())
    model.addFrame(pin.Frame("box", joint, 0, pin.SE3.Identity(), pin.FrameType.BODY))
    return model


def box_corners(size=(0.4, 0.3, 0.2)):
    a, b, c = (s / 2 for s in size)
    return [("box", (sx * a, sy * b, -c)) for sx in (-1, 1) for sy in (-1, 1)]


def box_at(height, model):
    q = pin.neutral(model)
    q[2] = height
    return q


def energy(sim):
    return pin.computeMechanicalEnergy(sim.model, sim.data, sim.q, sim.v)


def test_energy_conserved_without_torque_or_contact():
    """A swinging double pendulum keeps its energy to integration accuracy (error ~ dt)."""
    drifts = []
    for dt in (4e-4, 2e-4):
        sim = Simulator(double_pendulum(), dt)
        sim.reset([1.0, -0.5], [0.0, 0.0])
        e0 = energy(sim)
        worst = 0.0
        for _ in range(int(1.0 / dt)):
            sim.step(np.zeros(2))
            worst = max(worst, abs(energy(sim) - e0))
        drifts.append(worst / abs(e0))
    assert sim.n_base_dofs == 0 and sim.n_actuated == 2
    assert drifts[0] < 5e-3
    assert drifts[1] < 0.7 * drifts[0]  # first-order convergence


def test_free_flyer_tumbling_in_zero_gravity_keeps_energy():
    """A free-floating box spinning about all axes keeps its kinetic energy."""
    model = free_box()
    model.gravity.linear[:] = 0.0
    sim = Simulator(model, 1e-3)
    assert sim.n_base_dofs == 6 and sim.n_actuated == 0
    sim.reset(box_at(1.0, model), [0.1, 0.0, 0.2, 1.0, 2.0, 3.0])
    e0 = energy(sim)
    for _ in range(1000):
        sim.step(np.zeros(0))
    assert abs(energy(sim) - e0) / e0 < 1e-2


def test_dropped_box_rests_at_spring_height_with_weight_as_normal_force():
    """Four-corner box settles where 4 k d = m g and the ground carries exactly m g."""
    mass, k = 2.0, 2e4
    model = free_box(mass)
    ground = GroundContact(stiffness=k, damping=200.0, friction=0.8)
    sim = Simulator(model, 1e-3, contact_points=box_corners(), ground=ground)
    sim.reset(box_at(0.3, model))
    for _ in range(2000):
        state = sim.step(np.zeros(0))
    assert state.in_contact.all()
    assert np.sum(state.contact_forces[:, 2]) == pytest.approx(mass * GRAVITY, rel=1e-3)
    assert np.abs(state.contact_forces[:, :2]).max() < 1e-3
    expected = 0.1 - mass * GRAVITY / (4 * k)
    assert state.q[2] == pytest.approx(expected, abs=1e-5)
    assert np.abs(state.v).max() < 1e-3


def test_touchdown_time_matches_free_fall():
    """The touchdown event fires once per corner within one step of sqrt(2 h / g)."""
    model = free_box()
    ground = GroundContact(stiffness=2e4, damping=400.0, friction=0.8)
    dt = 5e-4
    sim = Simulator(model, dt, contact_points=box_corners(), ground=ground)
    drop = 0.2
    sim.reset(box_at(0.1 + drop, model))
    events = []
    for _ in range(600):
        events.extend(sim.step(np.zeros(0)).touchdowns)
    expected = np.sqrt(2 * drop / GRAVITY)
    assert sorted(e.point for e in events[:4]) == [0, 1, 2, 3]
    for event in events[:4]:
        assert event.time == pytest.approx(expected, abs=2 * dt)
        assert event.frame == "box"


@pytest.mark.parametrize("ratio, sticks", [(0.5, True), (1.5, False)])
def test_push_sticks_below_and_slides_above_coulomb_limit(ratio, sticks):
    """A horizontal force below mu m g leaves the box in place; above, it accelerates at
    (F - mu m g) / m."""
    mass, mu = 2.0, 0.5
    model = free_box(mass)
    ground = GroundContact(stiffness=2e4, damping=300.0, friction=mu)
    sim = Simulator(model, 1e-3, contact_points=box_corners(), ground=ground)
    sim.reset(box_at(0.1 - mass * GRAVITY / 8e4, model))
    for _ in range(300):
        sim.step(np.zeros(0))
    x0 = sim.q[0]
    force = ratio * mu * mass * GRAVITY
    # Push at the height of the contact plane so the box does not tip.
    sim.push("box", [force, 0.0, 0.0], duration=0.5, offset=(0, 0, -0.1))
    for _ in range(500):
        state = sim.step(np.zeros(0))
    moved = state.q[0] - x0
    if sticks:
        assert abs(moved) < 1e-3
    else:
        acceleration = (force - mu * mass * GRAVITY) / mass
        assert moved == pytest.approx(0.5 * acceleration * 0.5**2, rel=0.05)
        tangential = np.linalg.norm(state.contact_forces[:, :2], axis=1)
        assert tangential == pytest.approx(mu * state.contact_forces[:, 2], rel=1e-6)


@pytest.mark.parametrize("slope_deg, sticks", [(15.0, True), (35.0, False)])
def test_box_on_slope_sticks_or_slides(slope_deg, sticks):
    """On a slope flatter than atan(mu) the box stays; on a steeper one it slides down."""
    mu, mass = 0.5, 2.0  # atan(0.5) = 26.6 deg
    angle = np.radians(slope_deg)
    normal = np.array([-np.sin(angle), 0.0, np.cos(angle)])
    model = free_box(mass)
    ground = GroundContact(stiffness=2e4, damping=300.0, friction=mu, normal=normal)
    sim = Simulator(model, 1e-3, contact_points=box_corners(), ground=ground)
    q = pin.neutral(model)
    rotation = pin.utils.rotate("y", -angle)  # box bottom parallel to the slope
    q[:3] = normal * (0.1 - mass * GRAVITY * np.cos(angle) / 8e4)
    q[3:7] = pin.Quaternion(rotation).coeffs()
    sim.reset(q)
    for _ in range(1000):
        state = sim.step(np.zeros(0))
    downhill = np.array([np.cos(angle), 0.0, np.sin(angle)])  # x rises uphill
    travelled = -(state.q[:3] - q[:3]) @ downhill
    if sticks:
        assert abs(travelled) < 2e-3
    else:
        expected = 0.5 * GRAVITY * (np.sin(angle) - mu * np.cos(angle)) * 1.0**2
        assert travelled == pytest.approx(expected, rel=0.05)


def test_fall_flag_and_no_pulling():
    """The fall flag rises at the first step below fall_height; the ground never pulls."""
    model = free_box()
    ground = GroundContact(stiffness=2e4, damping=5e3, friction=0.8)
    sim = Simulator(
        model, 1e-3, contact_points=box_corners(), ground=ground, fall_frame="box", fall_height=0.25
    )
    sim.reset(box_at(0.3, model), [0, 0, -3.0, 0, 0, 0])
    min_force = np.inf
    for _ in range(300):
        state = sim.step(np.zeros(0))
        min_force = min(min_force, state.contact_forces[:, 2].min())
        if state.fallen:
            break
    assert state.fall.cause == "height"
    assert state.q[2] < 0.25 <= state.q[2] + 3.0 * 1e-3  # first step below (speed <= 3 m/s)
    assert min_force >= 0.0


def test_divergence_is_reported():
    """A far too stiff ground at a coarse step blows up and raises SimulationDiverged naming
    the coordinate and the time; the simulator keeps the last finite state."""
    model = free_box(mass=0.01)
    ground = GroundContact(stiffness=1e8, damping=0.0, friction=0.8)
    sim = Simulator(model, 1e-2, contact_points=box_corners(), ground=ground, falls=False)
    sim.reset(box_at(0.09, model))
    with pytest.raises(
        SimulationDiverged, match=r"\|v\[\d\]\| \(root\[\d\]\) .* at t = .*reduce dt"
    ):
        for _ in range(100):
            sim.step(np.zeros(0))
    assert np.abs(sim.v).max() <= 1e3 and np.isfinite(sim.q).all()


def test_non_finite_state_names_the_coordinate():
    """An acceleration that overflows names the first joint; the state stays the last one."""
    sim = Simulator(double_pendulum(), 1e-3)
    sim.reset([0.1, 0.2])
    with pytest.raises(SimulationDiverged, match=r"v\[0\] \(joint 'joint_0'\) became non-finite"):
        sim.step([1e308, -1e308])
    assert sim.t == 0.0 and sim.q == pytest.approx([0.1, 0.2])


def test_near_unit_quaternion_is_renormalised_others_refused():
    """|quat| = 1 + 1.25e-4 is renormalised; norms 0 and 2 are refused naming q[3:7]."""
    model = free_box()
    sim = Simulator(model, 1e-3, falls=False)
    q = box_at(1.0, model)
    q[3:7] = [0.0, 0.0, 0.6 * (1 + 1.25e-4), 0.8 * (1 + 1.25e-4)]
    assert np.linalg.norm(sim.reset(q).q[3:7]) == pytest.approx(1.0, abs=1e-15)
    for norm in (0.0, 2.0):
        q[3:7] = [0.0, 0.0, 0.6 * norm, 0.8 * norm]
        with pytest.raises(InvalidInputError, match=rf"q\[3:7\] of joint 'root' has norm {norm:g}"):
            sim.reset(q)


NAN = float("nan")


BAD_SIMULATOR_ARGUMENTS = [
    # (keyword arguments of Simulator, error, message)
    (dict(dt=0.0), InvalidInputError, "dt must be a positive finite time step"),
    (dict(dt=NAN), InvalidInputError, "dt must be .* got nan"),
    (dict(dt="1e-3"), InvalidInputError, "dt must be .* got '1e-3'"),
    (dict(max_speed=NAN), InvalidInputError, "max_speed must be a positive finite bound"),
    (dict(max_speed=np.inf), InvalidInputError, "max_speed must be"),
    (dict(max_speed=-1.0), InvalidInputError, "max_speed must be"),
    (dict(n_base_dofs=7), InvalidInputError, r"n_base_dofs must be an integer in \[0, 6\]"),
    (dict(n_base_dofs=2.5), InvalidInputError, "n_base_dofs must be an integer"),
    (dict(contact_points=[("nope", (0, 0, 0))]), InvalidInputError, "frame 'nope' is not in"),
    (dict(contact_points=["box"]), InvalidInputError, r"contact_points\[0\] must be a"),
    (dict(contact_points=[("box", (0, 0))]), ShapeError, r"contact_points\[0\] offset has shape"),
    (dict(contact_points=[("box", (0, NAN, 0))]), InvalidInputError, r"offset\[1\] is nan"),
    (dict(contact_points=[("box", (0, 0, 0))], ground=None), InvalidInputError, "pass ground="),
    (dict(fall_height=NAN), InvalidInputError, "fall_height must be a finite height"),
    (dict(fall_frame="universe"), InvalidInputError, "fall_frame 'universe' is not on the base"),
    (dict(falls="yes"), InvalidInputError, "falls must be True, False or a FallDetector"),
    (dict(falls=False, fall_height=0.1), InvalidInputError, "fall_height given with falls=False"),
    (
        dict(falls=FallDetector(0.1), fall_height=0.2),
        InvalidInputError,
        "set min_height in the FallDetector",
    ),
]


@pytest.mark.parametrize("kwargs, error, message", BAD_SIMULATOR_ARGUMENTS)
def test_bad_constructor_arguments_are_named(kwargs, error, message):
    arguments = dict(model=free_box(), dt=1e-3) | kwargs
    if "contact_points" in kwargs and "ground" not in kwargs:
        arguments["ground"] = GroundContact(1e4, 10, 1)
    with pytest.raises(error, match=message):
        Simulator(**arguments)


def test_fall_detection_on_a_fixed_base_is_refused():
    with pytest.raises(InvalidInputError, match="fall detection needs a floating base"):
        Simulator(double_pendulum(), 1e-3, falls=FallDetector(0.1))
    assert Simulator(double_pendulum(), 1e-3).fall_detector is None


def _box_sim():
    return Simulator(free_box(), 1e-3, box_corners(), GroundContact(2e4, 300, 0.8))


BAD_CALLS = [
    # (method, arguments, error, message)
    ("reset", (np.zeros(3),), ShapeError, r"q has shape \(3,\), expected \(7,\)"),
    ("reset", ([0, 0, NAN, 0, 0, 0, 1],), InvalidInputError, r"q\[2\] \(root\[2\]\) is nan"),
    ("reset", ([0, 0, 1, 0, 0, 0, 0],), InvalidInputError, r"q\[3:7\] .* norm 0, expected a unit"),
    ("reset", (box_at(1, free_box()), np.zeros(7)), ShapeError, r"v has shape \(7,\)"),
    ("reset", (box_at(1, free_box()), [0, 0, np.inf, 0, 0, 0]), InvalidInputError, r"v\[2\]"),
    ("reset", (box_at(1, free_box()), None, NAN), InvalidInputError, "t must be a finite time"),
    ("step", (np.zeros(2),), ShapeError, r"torques has shape \(2,\), expected \(0,\)"),
    ("step", (np.zeros(0), [0, 0, NAN, 0, 0, 0]), InvalidInputError, r"base_force\[2\] is nan"),
    ("step", (np.zeros(0), np.zeros(3)), ShapeError, r"base_force has shape \(3,\), expected \(6,"),
    (
        "step",
        ("abc",),
        InvalidInputError,
        r"torques must be an array of real numbers \(.*\), got 'abc'",
    ),
    ("push", ("box", [NAN, 0, 0], 0.1), InvalidInputError, r"force\[0\] is nan"),
    ("push", ("box", [1, 0], 0.1), ShapeError, r"force has shape \(2,\), expected \(3,\)"),
    ("push", ("box", [1, 0, 0], 0.0), InvalidInputError, "duration must be a positive finite"),
    ("push", ("box", [1, 0, 0], NAN), InvalidInputError, "duration must be .* got nan"),
    ("push", ("box", [1, 0, 0], np.inf), InvalidInputError, "duration must be .* got inf"),
    ("push", ("box", [1, 0, 0], 4e-4), InvalidInputError, "shorter than half the time step"),
    ("push", ("nope", [1, 0, 0], 0.1), InvalidInputError, "frame_name: frame 'nope' is not in"),
    ("push", (3, [1, 0, 0], 0.1), InvalidInputError, "frame_name: frame 3 is not in"),
    ("push", ("box", [1, 0, 0], 0.1, (0, 0, NAN)), InvalidInputError, r"^offset\[2\] is nan"),
    ("push_impulse", ("box", [0, NAN, 0]), InvalidInputError, r"impulse\[1\] is nan"),
    ("push_impulse", ("box", [1, 0, 0], -0.1), InvalidInputError, "duration must be"),
]


@pytest.mark.parametrize("method, arguments, error, message", BAD_CALLS)
def test_bad_call_arguments_are_named(method, arguments, error, message):
    with pytest.raises(error, match=message):
        getattr(_box_sim(), method)(*arguments)


@settings(max_examples=20, deadline=None)
@given(index=st.integers(0, 1), bad=st.sampled_from([NAN, np.inf, -np.inf]))
def test_non_finite_torque_names_the_joint_and_leaves_the_state(index, bad):
    sim = Simulator(double_pendulum(), 1e-3)
    sim.reset([0.1, 0.2])
    tau = [0.0, 0.0]
    tau[index] = bad
    message = rf"torques\[{index}\] \(joint 'joint_{index}'\) is"
    with pytest.raises(InvalidInputError, match=message):
        sim.step(tau)
    assert sim.t == 0.0 and sim.q == pytest.approx([0.1, 0.2])


def test_ground_contact_refuses_bad_values():
    for kwargs, message in [
        (dict(stiffness=-1.0), "stiffness must be"),
        (dict(damping=NAN), "damping must be a finite number >= 0, got nan"),
        (dict(friction=-0.1), "friction must be"),
        (dict(height=NAN), "height must be a finite height"),
        (dict(tangential_stiffness=0.0), "tangential_stiffness must be"),
        (dict(tangential_damping=-1.0), "tangential_damping must be"),
        (dict(normal=(0, 0, -1)), "normal must point up"),
        (dict(normal=(0, NAN, 1)), r"normal\[1\] is nan"),
    ]:
        with pytest.raises(InvalidInputError, match=message):
            GroundContact(**(dict(stiffness=1e4, damping=1.0, friction=1.0) | kwargs))


def test_push_impulse_is_exact_for_any_duration():
    """0.4 N s over 12.3 ms at dt = 1 ms: 12 steps of 0.4 / 0.012 N, dv = J / m exactly."""
    mass = 2.0
    model = free_box(mass)
    model.gravity.linear[:] = 0.0
    sim = Simulator(model, 1e-3)
    sim.reset(box_at(1.0, model))
    sim.push_impulse("box", [0.4, 0.0, 0.0], duration=0.0123)
    for _ in range(11):
        sim.step(np.zeros(0))
    assert sim.v[0] == pytest.approx(0.4 / mass * 11 / 12, rel=1e-12)
    sim.step(np.zeros(0))
    sim.step(np.zeros(0))
    assert sim.v[0] == pytest.approx(0.4 / mass, rel=1e-12)


def test_push_through_point_jacobian_matches_newton_on_a_free_box():
    """A push at the centre of a floating box in zero gravity gives dv = J / m, no spin;
    an off-centre push adds the spin r x J of the angular impulse."""
    mass = 2.0
    model = free_box(mass)
    model.gravity.linear[:] = 0.0
    sim = Simulator(model, 1e-3)
    sim.reset(box_at(1.0, model))
    sim.push_impulse("box", [0.4, 0.0, 0.0], duration=0.05)
    for _ in range(100):
        state = sim.step(np.zeros(0))
    assert state.v[:3] == pytest.approx([0.2, 0.0, 0.0], abs=1e-12)
    assert state.v[3:] == pytest.approx(np.zeros(3), abs=1e-12)
    sim.reset(box_at(1.0, model))
    sim.push_impulse("box", [0.4, 0.0, 0.0], duration=0.01, offset=(0.0, 0.0, 0.1))
    for _ in range(10):
        state = sim.step(np.zeros(0))
    inertia = model.inertias[1].inertia[1, 1]
    assert state.v[4] == pytest.approx(0.1 * 0.4 / inertia, rel=2e-2)  # spin about y


def test_floating_base_without_contact_points_is_refused():
    """A floating base under gravity with no contact points would fall through the floor with
    no fall reported: refused with the fix; zero gravity or falls=False mean floating."""
    with pytest.raises(
        InvalidInputError,
        match=r"floating base \(6 unactuated DOFs\) but no "
        r"contact_points.*contact_points=robot.contact_points",
    ):
        Simulator(free_box(), 1e-3)
    Simulator(free_box(), 1e-3, falls=False)
