"""MujocoSimulator.step's reads (dmpopt.sim.kernels.settle) step by step against other paths.

Answer keys, written here: MuJoCo's own ``mj_contactForce`` for each contact, rotated to the
world by its contact frame and summed on the nearest contact point; the coordinate change
with Pinocchio's quaternion; the fall checks of :class:`dmpopt.sim.falls.FallDetector` on
Pinocchio's placement of the watched frame (``BaseFrame.measure``), with the flight time from
the contact history kept here; the seed's normals times the noise's standard deviation for
the measured state; and the simulator's ``state`` property (the plant's ``measure`` and
copies), which takes another path than the step.

Tolerances: forces to 1e-9 of the robot's weight and velocities to 1e-12 (a few roundings of
the same sums in another order); fall values to 1e-12 (Pinocchio's products against the
compiled ones); measured minus true against the noise to two roundings of the state;
everything else exact.
"""

import os

import numpy as np
import pinocchio as pin
import pytest
from dmpopt_robots.biped import BIPED_URDF

from dmpopt.exceptions import SimulationDiverged
from dmpopt.sim import MujocoSimulator, PlantParameters, SensorNoise
from dmpopt.sim.falls import BaseFrame, FallDetector, base_tilt

os.environ.setdefault("MUJOCO_GL", "egl")
mujoco = pytest.importorskip("mujoco")

SIGMA = 1e-3  # every standard deviation of the noisy plant
ROUNDING = 4 * np.finfo(float).eps  # (x + noise) - x against noise: two roundings of |x|
NOISY = PlantParameters(
    damping=0.5,
    torque_limit=30.0,
    delay=2,
    noise=SensorNoise(*([SIGMA] * 6)),
    seed=7,
)


def simulator(robot, name, plant):
    if name == "biped":
        return MujocoSimulator(
            robot.model, BIPED_URDF, contact_points=robot.contact_points,
            fall_frame=robot.torso_frame, plant=plant,
        )  # fmt: skip
    points = [(f, c) for f in robot.foot_frames for c in robot.sole_corners]
    return MujocoSimulator(
        robot.model, robot.source, contact_points=points, fall_frame="base_link",
        fall_height=0.7, plant=plant,
    )  # fmt: skip


def start(robot, name):
    if name == "biped":
        q = pin.neutral(robot.model)
        q[1] = 0.62  # standing on straight legs
        return q
    q = pin.neutral(robot.model)
    q[2] = 1.08
    return q


def pinocchio_state(sim, qpos, qvel):
    """(q, v) of MuJoCo's (qpos, qvel): joints by name; a free base's quaternion reordered to
    (x, y, z, w) and its linear velocity turned to the base frame."""
    model, mj_model = sim.model, sim.mj_model
    q, v = np.empty(model.nq), np.empty(model.nv)
    for joint_id in range(2, model.njoints):
        joint = mj_model.joint(model.names[joint_id])
        q[model.joints[joint_id].idx_q] = qpos[joint.qposadr[0]]
        v[model.joints[joint_id].idx_v] = qvel[joint.dofadr[0]]
    if model.joints[1].shortname() == "JointModelFreeFlyer":
        joint = mj_model.joint(model.names[1])
        a, d = joint.qposadr[0], joint.dofadr[0]
        w, x, y, z = qpos[a + 3 : a + 7]
        q[:7] = [*qpos[a : a + 3], x, y, z, w]
        rotation = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
        v[:6] = [*(rotation.T @ qvel[d : d + 3]), *qvel[d + 3 : d + 6]]
    else:
        for k in range(model.joints[1].nv):
            joint = mj_model.joint(f"{model.names[1]}_{k}")
            q[k], v[k] = qpos[joint.qposadr[0]], qvel[joint.dofadr[0]]
    return q, v


def contact_forces(sim):
    """World forces and flags per contact point from mj_contactForce: the force on geom2 is
    frame^T f (the normal points from geom1 to geom2), on geom1 its opposite; a sole's
    contacts go to its nearest corner."""
    model, data = sim.mj_model, sim.mj_data
    n = len(sim.contact_frames)
    points = np.array([data.site(f"contact_point_{i}").xpos for i in range(n)])
    feet = {}  # geom id -> its contact points
    for i in range(n):
        geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"contact_point_{i}")
        if geom >= 0:
            feet[geom] = [i]
    for name, indices in sim._soles.items():
        feet[model.geom(name).id] = indices
    forces, touching = np.zeros((n, 3)), np.zeros(n, dtype=bool)
    for c in range(data.ncon):
        contact = data.contact[c]
        if contact.efc_address < 0:
            continue
        force = np.zeros(6)
        mujoco.mj_contactForce(model, data, c, force)
        on_geom2 = contact.frame.reshape(3, 3).T @ force[:3]
        for geom, sign in ((contact.geom2, 1.0), (contact.geom1, -1.0)):
            if geom in feet:
                nearest = min(feet[geom], key=lambda i: np.sum((points[i] - contact.pos) ** 2))
                forces[nearest] += sign * on_geom2
                touching[nearest] = True
    return forces, touching, points


@pytest.mark.parametrize("name", ["biped", "talos"])
def test_each_step_reads_what_mujoco_and_pinocchio_give(name, biped, talos):
    """A limp robot under random torques (saturated, delayed, noisy plant), pushed, until it
    falls: every step's state against the answer keys of the module notes."""
    robot = biped if name == "biped" else talos
    sim = simulator(robot, name, NOISY)
    state = sim.reset(start(robot, name))
    watched = BaseFrame(robot.model, robot.torso_frame if name == "biped" else "base_link")
    weight = pin.computeTotalMass(robot.model) * 9.81
    normals = np.random.default_rng(NOISY.seed)
    free = name == "talos"
    n_draws = robot.model.nq + robot.model.nv + (3 if free else 0)
    normals.standard_normal(n_draws)  # the reset's tick
    last_contact = 0.0 if state.in_contact.any() else None
    rng = np.random.default_rng(3)
    fell, touchdowns = False, 0
    for k in range(700):
        if k == 50:
            sim.push_impulse(robot.torso_frame if name == "biped" else "base_link", [4, 0, 0])
        state = sim.step(rng.normal(scale=5.0, size=sim.n_actuated))
        q, v = pinocchio_state(sim, sim.mj_data.qpos, sim.mj_data.qvel)
        np.testing.assert_array_equal(state.q, q)
        np.testing.assert_allclose(state.v, v, rtol=0, atol=1e-12 * (1 + np.abs(v).max()))
        forces, touching, points = contact_forces(sim)
        np.testing.assert_allclose(state.contact_forces, forces, rtol=0, atol=1e-9 * weight)
        np.testing.assert_array_equal(state.in_contact, touching)
        np.testing.assert_array_equal(state.contact_positions, points)
        touchdowns += len(state.touchdowns)
        draws = normals.standard_normal(n_draws)
        nq, nv = robot.model.nq, robot.model.nv
        joints = slice(7, nq) if free else slice(0, nq)
        np.testing.assert_allclose(
            state.q_measured[joints] - state.q[joints], SIGMA * draws[joints],
            rtol=0, atol=ROUNDING * (1 + np.abs(state.q).max()),
        )  # fmt: skip
        np.testing.assert_allclose(
            state.v_measured - state.v, SIGMA * draws[nq : nq + nv],
            rtol=0, atol=ROUNDING * (1 + np.abs(state.v).max()),
        )  # fmt: skip
        if free:
            turned = pin.Quaternion(state.q[3:7]).toRotationMatrix() @ pin.exp3(
                SIGMA * draws[nq + nv :]
            )
            measured = pin.Quaternion(state.q_measured[3:7]).toRotationMatrix()
            np.testing.assert_allclose(measured, turned, atol=1e-12)
        again = sim.state  # the property's path
        for field in ("q", "v", "contact_forces", "in_contact", "contact_positions",
                      "q_measured", "v_measured"):  # fmt: skip
            np.testing.assert_array_equal(getattr(again, field), getattr(state, field))
        t = state.t
        if touching.any():
            last_contact = t
        placement, spin = watched.measure(state.q, state.v)
        expected = sim.fall_detector.check(
            t, placement.translation[2], base_tilt(placement.rotation),
            0.0 if last_contact is None else t - last_contact, spin,
        )  # fmt: skip
        assert (state.fall is None) == (expected is None), (k, state.fall, expected)
        if expected is not None:
            assert (state.fall.time, state.fall.cause) == (expected.time, expected.cause)
            assert abs(state.fall.value - expected.value) < 1e-12
            fell = True
            break
    assert fell and touchdowns and k > 50  # the run covered a push, touchdowns and a fall


def test_a_fall_right_at_a_threshold_is_decided_as_the_detector_decides(biped):
    """Floating still without gravity, the biped's torso stays at height h; with min_height
    h no fall (h is not below h), with the next float above h a fall; a detector set after
    the build takes effect."""
    sim = MujocoSimulator(
        biped.model, BIPED_URDF, contact_points=biped.contact_points,
        fall_frame=biped.torso_frame,
    )  # fmt: skip
    sim.mj_model.opt.gravity[:] = 0.0
    q = start(biped, "biped")
    q[1] = 2.0  # in the air
    height = BaseFrame(biped.model, biped.torso_frame).measure(q, np.zeros(3))[0].translation[2]
    for min_height, falls in ((height, False), (np.nextafter(height, np.inf), True)):
        sim.fall_detector = FallDetector(min_height=min_height, max_tilt=np.inf)
        sim.reset(q)
        state = sim.step(np.zeros(sim.n_actuated))
        np.testing.assert_array_equal(state.q, q)  # nothing moved
        assert state.fallen == falls, (min_height, height, state.fall)


def test_a_fall_detector_of_its_own_is_asked_every_step(biped):
    """A FallDetector subclass may check differently: the step asks it every step."""

    class Impatient(FallDetector):
        def check(self, time, height, tilt, flight_time, spin):
            return None if time < 0.0035 else super().check(time, 1e9, 0.0, 0.0, 0.0)

    detector = Impatient(min_height=2e9)
    sim = MujocoSimulator(
        biped.model, BIPED_URDF, contact_points=biped.contact_points, falls=detector
    )
    sim.reset(start(biped, "biped"))
    times = []
    while not sim.fallen:
        times.append(sim.step(np.zeros(sim.n_actuated)).t)
    assert times == pytest.approx([0.001, 0.002, 0.003, 0.004])


def test_a_step_that_raises_leaves_the_noise_sequence_as_it_was(biped):
    """Too fast (max_speed lowered after the build): the step raises before making its noise,
    so the next step measures with the normals the failed one would have used."""
    noisy = PlantParameters(noise=SensorNoise(joint_position=SIGMA), seed=5)
    sim = MujocoSimulator(biped.model, BIPED_URDF, contact_points=biped.contact_points,
                          plant=noisy)  # fmt: skip
    sim.reset(start(biped, "biped"))
    normals = np.random.default_rng(noisy.seed)
    n_draws = biped.model.nq + biped.model.nv
    normals.standard_normal(n_draws)  # the reset's tick
    sim.step(np.zeros(sim.n_actuated))
    normals.standard_normal(n_draws)
    sim.max_speed = 1e-9
    with pytest.raises(SimulationDiverged, match="max_speed"):
        sim.step(np.zeros(sim.n_actuated))
    sim.max_speed = 1e3
    state = sim.step(np.zeros(sim.n_actuated))
    joints = slice(3, biped.model.nq)
    np.testing.assert_allclose(
        state.q_measured[joints] - state.q[joints],
        SIGMA * normals.standard_normal(n_draws)[joints],
        rtol=0,
        atol=ROUNDING * (1 + np.abs(state.q).max()),
    )


@pytest.mark.parametrize("name", ["biped", "talos"])
def test_each_state_is_mujocos_own_step_under_the_plant_written_here(name, biped, talos):
    """Answer key: MuJoCo's ``mj_step`` through its Python bindings on a copy of the ideal
    simulator's model, given here each actuated joint's armature, damping and friction loss
    (its constants recomputed, ``mj_setConst``) and driven by the plant's law written here:
    each command saturated to [-limit, limit], applied ``delay`` steps later (the first one
    until then), at the joint's dof of ``qfrc_applied``; the biped's base force at its base
    dofs as it is. A limp robot under random torques, through touchdowns: every state's ``q``
    and MuJoCo's whole ``qpos``, ``qvel`` and time must be the key's bit for bit (the same
    floating-point operations on the same numbers)."""
    import copy

    robot = biped if name == "biped" else talos
    armature, damping, friction, limit, delay = 0.05, 0.5, 0.3, 10.0, 3
    plant = PlantParameters(
        armature=armature, damping=damping, friction=friction, torque_limit=limit, delay=delay
    )
    sim = simulator(robot, name, plant)
    key_model = copy.deepcopy(simulator(robot, name, PlantParameters()).mj_model)
    names = list(robot.model.names[2:])  # the actuated joints, in the order of tau
    dofs = [key_model.joint(n).dofadr[0] for n in names]
    key_model.dof_armature[dofs] = armature
    key_model.dof_damping[dofs] = damping
    key_model.dof_frictionloss[dofs] = friction
    key = mujoco.MjData(key_model)
    mujoco.mj_setConst(key_model, key)
    sim.reset(start(robot, name))
    key.qpos[:], key.qvel[:], key.time = sim.mj_data.qpos, sim.mj_data.qvel, sim.mj_data.time
    mujoco.mj_forward(key_model, key)
    if name == "biped":  # the planar base's three joints
        base = [key_model.joint(f"{robot.model.names[1]}_{k}").dofadr[0] for k in range(3)]
    rng = np.random.default_rng(11)
    commands, touched = [], False
    for k in range(300 if name == "biped" else 150):
        commands.append(rng.normal(scale=15.0, size=sim.n_actuated))
        force = rng.normal(size=3) if name == "biped" else None
        state = sim.step(commands[-1], force)
        key.qfrc_applied[dofs] = np.clip(commands[max(k - delay, 0)], -limit, limit)
        if force is not None:
            key.qfrc_applied[base] = force
        mujoco.mj_step(key_model, key)
        for mine, theirs in ((sim.mj_data.qpos, key.qpos), (sim.mj_data.qvel, key.qvel)):
            assert mine.tobytes() == theirs.tobytes(), k
        assert state.t == key.time
        assert state.q.tobytes() == pinocchio_state(sim, key.qpos, key.qvel)[0].tobytes()
        touched |= bool(state.in_contact.any())
    assert touched
