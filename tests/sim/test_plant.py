"""The plant (dmpopt.sim.plant) in both simulators, and the joint loop that copes with it.

Answer keys: a one-joint rotor about the vertical (gravity does not act on it) whose dynamics
with armature, damping, friction, saturation and delay are written plainly here and stepped
with each simulator's integration rule; the Talos contact geometry against the floor height.
"""

from __future__ import annotations

import os
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
from dmpopt_robots import load_talos
from dmpopt_robots.plants import biped_realistic, talos_realistic

from dmpopt.control import JointImpedance
from dmpopt.exceptions import InvalidInputError
from dmpopt.sim import IDEAL, MujocoSimulator, PlantParameters, SensorNoise, Simulator

os.environ.setdefault("MUJOCO_GL", "egl")
mujoco = pytest.importorskip("mujoco")

DT = 1e-3
INERTIA = 0.05  # [kg m^2] of the rotor link about its (vertical) joint axis
ROTOR = f"""<robot name="rotor">
  <link name="base"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0"
    iyz="0"/></inertial></link>
  <link name="arm"><inertial><origin xyz="0 0 0"/><mass value="1"/>
    <inertia ixx="0.03" iyy="0.03" izz="{INERTIA}" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="spin" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 0 1"/><limit lower="-100" upper="100" effort="10" velocity="100"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def rotor(tmp_path_factory):
    path = tmp_path_factory.mktemp("rotor") / "rotor.urdf"
    path.write_text(ROTOR)
    return pin.buildModelFromUrdf(str(path)), path


def simulators(rotor, plant):
    model, path = rotor
    return {
        "native": Simulator(model, DT, plant=plant),
        "mujoco": MujocoSimulator(model, path, DT, plant=plant),
    }


def run(simulator, torques):
    """Velocities after each step under the torque sequence, from rest."""
    simulator.reset(np.zeros(1))
    return np.array([simulator.step([tau]).v[0] for tau in torques])


def plain_rotor(torques, armature=0.0, damping=0.0, implicit=False):
    """The rotor's velocity recurrence written out: semi-implicit Euler; MuJoCo's implicitfast
    takes the damping implicitly: (m + dt b) dv = dt (tau - b v)."""
    m = INERTIA + armature
    v, out = 0.0, []
    for tau in torques:
        v += DT * (tau - damping * v) / (m + (DT * damping if implicit else 0.0))
        out.append(v)
    return np.array(out)


@pytest.mark.parametrize("backend", ["native", "mujoco"])
def test_armature_and_damping_follow_the_rotor_equation(rotor, backend):
    """(I + I_a) dv/dt = tau - b v, stepped as each simulator steps (rounding: 1e-12 rad/s)."""
    torques = np.full(300, 0.4)
    plant = PlantParameters(armature=0.02, damping=0.3)
    got = run(simulators(rotor, plant)[backend], torques)
    expected = plain_rotor(torques, 0.02, 0.3, implicit=backend == "mujoco")
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("backend", ["native", "mujoco"])
def test_delay_shifts_the_torque_by_whole_ticks_and_saturation_clips_it(rotor, backend):
    """The torque acts `delay` ticks late (the first command held meanwhile) and clipped to the
    limit: the velocity equals the rotor equation driven by the shifted, clipped sequence."""
    rng = np.random.default_rng(3)
    torques = rng.uniform(-3.0, 3.0, 200)
    plant = PlantParameters(delay=4, torque_limit=1.0)
    got = run(simulators(rotor, plant)[backend], torques)
    shifted = np.r_[np.full(4, torques[0]), torques[:-4]]
    np.testing.assert_allclose(got, plain_rotor(np.clip(shifted, -1, 1)), rtol=0, atol=1e-12)


def test_native_coulomb_friction_slows_by_its_torque_beyond_its_band(rotor):
    """Sliding, friction takes f_c off the torque: dv = dt (tau - f_c) / I."""
    sim = simulators(rotor, PlantParameters(friction=0.1))["native"]
    got = run(sim, np.full(200, 0.3))
    band = DT * 0.1 / INERTIA  # v_s, the documented regularisation
    sliding = got > band
    expected = plain_rotor(np.full(200, 0.3 - 0.1))
    assert sliding[5:].all()
    np.testing.assert_allclose(np.diff(got[sliding]), np.diff(expected[sliding]), atol=1e-12)


def test_mujoco_coulomb_friction_holds_below_and_slows_above_its_torque(rotor):
    """Below f_c the joint sticks (MuJoCo's frictionloss is a soft constraint: it creeps at a
    small fraction of the frictionless speed); above it the net torque is tau - f_c."""
    sim = simulators(rotor, PlantParameters(friction=0.2))["mujoco"]
    free = plain_rotor(np.full(1000, 0.1))[-1]
    assert abs(run(sim, np.full(1000, 0.1))[-1]) < 0.01 * free
    slipping = run(sim, np.full(1000, 0.4))[-1]
    assert slipping == pytest.approx(plain_rotor(np.full(1000, 0.2))[-1], rel=0.02)


def test_sensor_noise_is_seeded_and_has_its_standard_deviation(rotor):
    """Same seed, same readings; measured - true has the given std (2000 samples: the
    estimate's relative error is about 1/sqrt(2 n) = 1.6 %, so 5 sigma is 8 %); the truth is
    untouched."""
    noise = SensorNoise(joint_position=0.01, joint_velocity=0.2)
    readings = []
    for _ in range(2):
        sim = simulators(rotor, PlantParameters(noise=noise, seed=7))["mujoco"]
        sim.reset(np.zeros(1))
        states = [sim.step([0.0]) for _ in range(2000)]
        readings.append(np.array([[s.q_measured[0] - s.q[0], s.v_measured[0] - s.v[0]]
                                  for s in states]))  # fmt: skip
        assert all(s.q[0] == 0.0 and s.v[0] == 0.0 for s in states)
    np.testing.assert_array_equal(readings[0], readings[1])
    np.testing.assert_allclose(readings[0].std(axis=0), [0.01, 0.2], rtol=0.08)


def test_free_flyer_orientation_noise_keeps_a_unit_quaternion():
    """Base orientation noise rotates the measured base by a small rotation of the given std
    (angle std sqrt(3) sigma for a rotation vector of three N(0, sigma) entries)."""
    talos = load_talos("reduced")
    plant = PlantParameters(noise=SensorNoise(base_orientation=0.002))
    sim = MujocoSimulator(talos.model, talos.source, DT, plant=plant, falls=False)
    q = talos.reference_configuration.copy()
    q[2] += 1.0  # in the air
    sim.reset(q)
    angles, norms = [], []
    for _ in range(500):
        state = sim.step(np.zeros(talos.n_actuated))
        measured, true = pin.Quaternion(state.q_measured[3:7]), pin.Quaternion(state.q[3:7])
        norms.append(np.linalg.norm(state.q_measured[3:7]))
        angles.append(measured.angularDistance(true))
    np.testing.assert_allclose(norms, 1.0, atol=1e-12)
    rms = np.sqrt(np.mean(np.square(angles)))
    assert rms == pytest.approx(np.sqrt(3) * 0.002, rel=0.15)  # 500 samples: 5 sigma ~ 15 %


def test_parameters_per_joint_pattern_scaling_and_errors():
    names = ("leg_1", "leg_2", "arm_1")
    plant = PlantParameters(armature={"*": 0.1, "arm_*": 0.02}, delay=2)
    np.testing.assert_array_equal(plant.values("armature", names), [0.1, 0.1, 0.02])
    np.testing.assert_array_equal(plant.values("torque_limit", names), [np.inf] * 3)
    scaled = plant.scaled(armature=3.0, noise=2.0)
    np.testing.assert_allclose(scaled.values("armature", names), [0.3, 0.3, 0.06])
    assert scaled.delay == 2 and IDEAL.is_ideal and not plant.is_ideal
    with pytest.raises(InvalidInputError, match="damping must be a finite number >= 0"):
        PlantParameters(damping=-1.0)
    with pytest.raises(InvalidInputError, match="delay must be a whole number of ticks"):
        PlantParameters(delay=1.5)
    with pytest.raises(InvalidInputError, match="friction pattern 'hand_\\*' matches no"):
        PlantParameters(friction={"hand_*": 1.0}).values("friction", names)
    with pytest.raises(InvalidInputError, match="noise.joint_velocity must be"):
        SensorNoise(joint_velocity=np.nan)
    with pytest.raises(InvalidInputError, match="scaled\\(\\) got 'mass'"):
        plant.scaled(mass=2.0)


def test_presets_cover_every_actuated_joint():
    talos = load_talos("full")
    preset = talos_realistic(talos)
    names = talos.actuated_joint_names
    assert (preset.values("armature", names) > 0).all()
    assert (preset.values("friction", names) > 0).all()
    np.testing.assert_array_equal(preset.values("torque_limit", names), talos.torque_limit)
    from dmpopt_robots.biped import load_biped

    biped = load_biped()
    assert biped_realistic(biped).values("armature", biped.actuated_joint_names).max() < 0.01


def test_a_fallen_talos_lies_on_the_floor():
    """With the body colliding, a limp robot ends on the floor, not through it: every body
    origin above -3 cm (a link's origin can sit a few cm inside its collision mesh) after
    3 s; with only the soles colliding it sank through."""
    talos = load_talos("reduced")
    points = [(f, c) for f in talos.foot_frames for c in talos.sole_corners]
    heights = {}
    for collide in (True, False):
        sim = MujocoSimulator(talos.model, talos.source, DT, points, falls=False,
                              body_collisions=collide)  # fmt: skip
        sim.reset(talos.reference_configuration)
        for _ in range(3000):
            sim.step(np.zeros(talos.n_actuated))
        heights[collide] = sim.mj_data.xpos[1:, 2].min()
    assert heights[True] > -0.03
    assert heights[False] < -0.5


def test_the_soles_corner_forces_carry_the_robot_by_the_momentum_balance():
    """A Talos holding its posture on its box soles: the corner forces are the whole vertical
    contact force, so dt sum(F_z) - N dt m g = m (v_com,z(N) - v_com,z(0)) (the vertical
    momentum balance; joint torques are internal). MuJoCo's Newton solver stops at its
    tolerance (opt.tolerance 1e-8 on the cost), which leaves the balance 2e-6 of the impulse off
    here; the bound allows 1e-5."""
    talos = load_talos("reduced")
    points = [(f, c) for f in talos.foot_frames for c in talos.sole_corners]
    sim = MujocoSimulator(talos.model, talos.source, DT, points)
    state = sim.reset(talos.reference_configuration)
    data = talos.model.createData()
    inertia = np.diag(pin.crba(talos.model, data, talos.reference_configuration))[6:]
    impulse, velocities = 0.0, []
    for k in range(400):
        error = talos.reference_configuration[7:] - state.q[7:]
        hold = inertia * (900.0 * error - 60.0 * state.v[6:])
        gravity = pin.computeGeneralizedGravity(talos.model, data, state.q)[6:]
        if k == 200:
            pin.centerOfMass(talos.model, data, state.q, state.v)
            velocities.append(data.vcom[0][2])
        state = sim.step(gravity + hold)
        if k >= 200:
            impulse += DT * state.contact_forces[:, 2].sum()
    pin.centerOfMass(talos.model, data, state.q, state.v)
    velocities.append(data.vcom[0][2])
    assert not state.fallen and state.in_contact.all()
    gravity_impulse = 200 * DT * talos.mass * 9.81
    change = talos.mass * (velocities[1] - velocities[0])
    assert impulse - gravity_impulse == pytest.approx(change, abs=1e-5 * gravity_impulse)


def test_joint_impedance_gains_come_from_the_apparent_inertia_and_the_delay():
    """K = m w^2, D = 2 zeta m w with m = 1 / (M^-1)_jj and w = 0.25 / ((d + 1) dt)."""
    talos = load_talos("reduced")
    loop = JointImpedance(talos, DT, delay=2, damping_ratio=0.8)
    mass = pin.crba(talos.model, talos.model.createData(), talos.reference_configuration)
    mass = np.triu(mass) + np.triu(mass, 1).T
    m = 1.0 / np.diag(np.linalg.inv(mass))[6:]
    omega = 0.25 / (3 * DT)
    np.testing.assert_allclose(loop.stiffness, m * omega**2, rtol=1e-12)
    np.testing.assert_allclose(loop.damping_gain, 2 * 0.8 * m * omega, rtol=1e-12)


def test_joint_impedance_holds_friction_to_its_static_deflection(rotor):
    """A rotor tracking a sinusoid on a plant with Coulomb friction f: the QP's torque alone
    (the exact rigid model) lets friction pull it far off; with the joint loop the error stays
    within 2 f / K, the peak response of a critically damped loop of stiffness K to the 2 f step
    of a friction reversal. (The pull towards the measured state is made slow here, T = 100 s:
    its own effect is the next test's.)"""
    model, path = rotor
    friction = 0.05
    robot = SimpleNamespace(
        n_base=0, n_actuated=1, model=model, reference_configuration=np.zeros(1),
        torque_limit=np.array([10.0]), actuated_joint_names=("spin",),
    )  # fmt: skip
    errors = {}
    for with_loop in (False, True):
        loop = JointImpedance(robot, DT, delay=0, time_constant=100.0)
        sim = MujocoSimulator(model, path, DT, plant=PlantParameters(friction=friction))
        state = sim.reset(np.zeros(1), np.array([2.0]))
        worst = 0.0
        for k in range(3000):
            t = k * DT
            a_ref = -4.0 * np.sin(2.0 * t)
            tau = np.array([INERTIA * a_ref])
            if with_loop:
                tau = loop.torques(state.q, state.v, np.array([a_ref]), tau)
            state = sim.step(tau)
            worst = max(worst, abs(state.q[0] - np.sin(2.0 * (t + DT))))
        errors[with_loop] = worst
    assert errors[True] <= 2 * friction / loop.stiffness[0]
    assert errors[False] > 10 * errors[True]


def test_joint_impedance_desired_state_is_pulled_to_the_measured_one(rotor):
    """With no acceleration asked, a joint held 1 rad away from where the loop started: the
    desired state closes the gap as (1 - dt/T)^n, so the torque is K (q_d - q) =
    -K (1 - dt/T)^n after n ticks (the desired velocity stays 0)."""
    model, _ = rotor
    robot = SimpleNamespace(
        n_base=0, n_actuated=1, model=model, reference_configuration=np.zeros(1),
        torque_limit=np.array([1e9]), actuated_joint_names=("spin",),
    )  # fmt: skip
    loop = JointImpedance(robot, DT, delay=1, time_constant=0.2)
    zero = np.zeros(1)
    assert loop.torques(zero, zero, zero, zero)[0] == 0.0
    one = np.ones(1)
    torques = [loop.torques(one, zero, zero, zero)[0] for _ in range(50)]
    gap = (1 - DT / 0.2) ** np.arange(50)  # the torque uses the desired state before its update
    np.testing.assert_allclose(torques, -loop.stiffness[0] * gap, rtol=1e-12)


def test_joint_impedance_feeds_the_nominal_friction_forward(rotor):
    """Without feedback (bandwidth 0), the torque is the QP's plus b v_d + f_c tanh(v_d / v_s)
    with v_d the integrated desired speed (v_s = 0.05 rad/s), clipped to the torque limit."""
    model, _ = rotor
    robot = SimpleNamespace(
        n_base=0, n_actuated=1, model=model, reference_configuration=np.zeros(1),
        torque_limit=np.array([0.5]), actuated_joint_names=("spin",),
    )  # fmt: skip
    plant = PlantParameters(damping=0.3, friction=0.2, delay=1)
    loop = JointImpedance.for_plant(robot, DT, plant, feedback=False, time_constant=1e6)
    assert loop.bandwidth == 0.0 and loop.stiffness[0] == 0.0
    zero, speed = np.zeros(1), 0.01
    v_desired, got, expected = speed, [], []
    loop.torques(zero, np.array([speed]), zero, zero)  # starts the desired state at v
    for k in range(20):
        accel = np.array([0.5 * k])
        v_desired = v_desired + DT * accel[0] - (DT / 1e6) * (v_desired - speed)
        got.append(loop.torques(zero, np.array([speed]), accel, np.array([0.1]))[0])
        expected.append(min(0.1 + 0.3 * v_desired + 0.2 * np.tanh(v_desired / 0.05), 0.5))
    np.testing.assert_allclose(got[1:], expected[:-1], rtol=1e-12)
