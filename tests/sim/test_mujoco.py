"""Tests of the MuJoCo backend: the same robot as Pinocchio's, state conversion, contacts,
pushes, falls, the standing Talos under the inverse-dynamics controller, rendering, bad inputs.

The answer key of the model tests is Pinocchio on the same URDF: frame placements and
velocities, the mass matrix (CRBA) and the bias forces (RNEA) must match MuJoCo's after the
coordinate change written out here independently of the backend.
"""

import os
import sys

import numpy as np
import pinocchio as pin
import pytest
from dmpopt_robots import load_talos
from dmpopt_robots.biped import BIPED_URDF, load_biped
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.exceptions import (
    FileFormatError,
    InvalidInputError,
    MissingDependency,
    ResourceLimitError,
    ShapeError,
    SimulationDiverged,
)
from dmpopt.sim import (
    GroundContact,
    MujocoSimulator,
    PlantParameters,
    Simulator,
    render_animation,
    render_frame,
)
from dmpopt.sim.mujoco_backend import shadow_map_size

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; read when mujoco is imported
mujoco = pytest.importorskip("mujoco")

GRAVITY = 9.81


@pytest.fixture(scope="module")
def talos_sim(talos):
    points = [(f, c) for f in talos.foot_frames for c in talos.sole_corners]
    return MujocoSimulator(talos.model, talos.source, contact_points=points)


def random_state(model, seed, height=1.0):
    """A configuration inside the joint limits (margin 0.05 rad) and a random velocity."""
    rng = np.random.default_rng(seed)
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    lower = np.where(np.abs(lower) < 1e10, lower, -1) + 0.05  # URDFs write no limit as 1e308
    upper = np.where(np.abs(upper) < 1e10, upper, 1) - 0.05
    q = pin.randomConfiguration(model, np.minimum(lower, upper), np.maximum(lower, upper))
    if model.joints[1].shortname() == "JointModelFreeFlyer":
        q[:3] = rng.normal(size=3) + [0, 0, height]
        quaternion = rng.normal(size=4)
        q[3:7] = quaternion / np.linalg.norm(quaternion)
    return q, rng.normal(size=model.nv)


def coordinate_change(sim, q):
    """T with qvel_mujoco = T v_pinocchio, built from MuJoCo's joint table by name."""
    model, mj_model = sim.model, sim.mj_model
    T = np.zeros((mj_model.nv, model.nv))
    for joint_id in range(1, model.njoints):
        joint, name = model.joints[joint_id], model.names[joint_id]
        if joint.shortname() == "JointModelFreeFlyer":
            address = mj_model.joint(name).dofadr[0]
            T[address : address + 3, :3] = pin.Quaternion(q[3:7]).toRotationMatrix()
            T[address + 3 : address + 6, 3:6] = np.eye(3)
        elif joint.shortname() == "JointModelComposite":
            for k in range(joint.nv):
                T[mj_model.joint(f"{name}_{k}").dofadr[0], joint.idx_v + k] = 1.0
        else:
            T[mj_model.joint(name).dofadr[0], joint.idx_v] = 1.0
    return T


def assert_same_robot(sim, q, v):
    """Frames, frame velocities, mass matrix and bias forces: Pinocchio vs MuJoCo."""
    model, mj_model, mj_data = sim.model, sim.mj_model, sim.mj_data
    data = model.createData()
    sim.reset(q, v)
    mujoco.mj_forward(mj_model, mj_data)
    pin.forwardKinematics(model, data, q, v)
    pin.updateFramePlacements(model, data)
    bodies = [f for f in model.frames if f.type == pin.FrameType.BODY and f.name != "universe"]
    assert len(bodies) > 3
    for frame in bodies:
        body = mj_model.body(frame.name).id
        placement = data.oMf[model.getFrameId(frame.name)]
        rotation = mj_data.xmat[body].reshape(3, 3)
        np.testing.assert_allclose(mj_data.xpos[body], placement.translation, atol=1e-9)
        np.testing.assert_allclose(rotation, placement.rotation, atol=1e-9)
        velocity = pin.getFrameVelocity(model, data, model.getFrameId(frame.name), pin.LOCAL)
        mj_velocity = np.empty(6)  # (angular, linear) of the body frame, local axes
        mujoco.mj_objectVelocity(mj_model, mj_data, mujoco.mjtObj.mjOBJ_XBODY, body, mj_velocity, 1)
        np.testing.assert_allclose(mj_velocity[3:], velocity.linear, atol=1e-8)
        np.testing.assert_allclose(mj_velocity[:3], velocity.angular, atol=1e-8)
    T = coordinate_change(sim, q)
    mass = np.zeros((mj_model.nv, mj_model.nv))
    mujoco.mj_fullM(mj_model, mj_data, mass)
    crba = pin.crba(model, data, q)
    crba = np.triu(crba) + np.triu(crba, 1).T
    np.testing.assert_allclose(T.T @ mass @ T, crba, atol=1e-6 * np.abs(crba).max())
    # T depends on q: qacc_mj = T a_pin + dT/dt v, so b_pin = T^T (b_mj + M_mj dT/dt v), where
    # dT/dt v = (R (omega x v_linear), 0, ...) for a free flyer (0 for one-axis joints).
    t_dot_v = np.zeros(mj_model.nv)
    if model.joints[1].shortname() == "JointModelFreeFlyer":
        t_dot_v[:3] = T[:3, :3] @ np.cross(v[3:6], v[:3])
    rnea = pin.rnea(model, data, q, v, np.zeros(model.nv))
    bias = T.T @ (mj_data.qfrc_bias + mass @ t_dot_v)
    np.testing.assert_allclose(bias, rnea, atol=1e-6 * np.abs(rnea).max())


# ------------------------------------------------------------------------- same robot
@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_talos_is_the_same_robot_in_both(talos_sim, seed):
    """Talos (full URDF, free flyer): placements and velocities of every link, M and the bias
    forces agree with Pinocchio to 1e-6 relative at random states."""
    assert_same_robot(talos_sim, *random_state(talos_sim.model, seed))


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_planar_biped_is_the_same_robot_in_both(seed):
    """The planar biped (composite x, z, pitch base) agrees with Pinocchio as well."""
    biped = load_biped()
    sim = MujocoSimulator(biped.model, BIPED_URDF, contact_points=biped.contact_points)
    assert_same_robot(sim, *random_state(biped.model, seed))


def test_fixed_base_talos_is_the_same_robot_in_both(talos):
    """Talos built without a free flyer (root link welded to the world) agrees as well."""
    model = pin.buildModelFromUrdf(talos.source)
    sim = MujocoSimulator(model, talos.source)
    assert sim.n_base_dofs == 0
    assert_same_robot(sim, *random_state(model, 5))


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_state_round_trip(talos_sim, seed):
    """reset(q, v) then state gives back q (normalised quaternion) and v."""
    q, v = random_state(talos_sim.model, seed)
    q[3:7] *= 3.0  # an unnormalised quaternion is the same orientation
    state = talos_sim.reset(q, v)
    expected = q.copy()
    expected[3:7] /= 3.0
    np.testing.assert_allclose(state.q, expected, atol=1e-12)
    np.testing.assert_allclose(state.v, v, atol=1e-12)


def test_one_step_follows_pinocchio_forward_dynamics(talos_sim):
    """In the air, one step under random torques, base force and a push: v_joints and the base
    angular velocity (local) move by dt * ABA(q, v, f + J^T push); the base linear velocity,
    stored in the world frame by MuJoCo, moves by dt * (a_linear + omega x v_linear) in the
    start frame."""
    sim, model = talos_sim, talos_sim.model
    data = model.createData()
    q, v = random_state(model, 3, height=3.0)
    rng = np.random.default_rng(4)
    tau, base_force, push = rng.normal(size=model.nv - 6), rng.normal(size=6) * 10, [40, -20, 30]
    offset = np.array([0.1, -0.2, 0.05])
    sim.reset(q, v)
    sim.push("arm_left_4_link", push, duration=0.01, offset=offset)
    state = sim.step(tau, base_force=base_force)
    assert not state.in_contact.any()
    pin.computeJointJacobians(model, data, q)
    frame = model.frames[model.getFrameId("arm_left_4_link")]
    point = pin.SE3(np.eye(3), frame.placement.act(offset))
    jacobian = pin.getFrameJacobian(model, data, frame.parentJoint, point, pin.LOCAL_WORLD_ALIGNED)
    force = np.r_[base_force, tau] + jacobian[:3].T @ push
    acceleration = pin.aba(model, data, q, v, force)
    expected = v + sim.dt * acceleration
    np.testing.assert_allclose(state.v[3:], expected[3:], rtol=1e-9, atol=1e-9)
    start, end = (pin.Quaternion(x[3:7]).toRotationMatrix() for x in (q, state.q))
    linear = end.T @ start @ (v[:3] + sim.dt * (acceleration[:3] + np.cross(v[3:6], v[:3])))
    np.testing.assert_allclose(state.v[:3], linear, rtol=1e-9, atol=1e-9)


# ----------------------------------------------------------------------- contacts, pushes
def test_push_impulse_changes_momentum_by_the_impulse(talos_sim):
    """Free-floating Talos: linear momentum changes by the impulse plus m g t (Newton).

    Euler steps in joint coordinates let the momentum drift by O(dt) while the limp limbs
    flail (0.2 N s here; 0.02 N s at dt = 1e-4); one step more or less of the push would be
    0.6 N s."""
    sim, model = talos_sim, talos_sim.model
    q = np.array(load_talos("full").reference_configuration)
    q[2] = 3.0
    sim.reset(q)
    impulse = np.array([30.0, -12.0, 5.0])
    sim.push_impulse("torso_2_link", impulse, duration=0.05, offset=(0.1, 0.2, 0.3))
    n = 50  # the push's duration
    for _ in range(n):
        state = sim.step(np.zeros(sim.n_actuated))
    mass = pin.computeTotalMass(model)
    momentum = pin.computeCentroidalMomentum(model, model.createData(), state.q, state.v).linear
    expected = impulse + mass * np.array([0, 0, -GRAVITY]) * n * sim.dt
    np.testing.assert_allclose(momentum, expected, atol=0.3)


@pytest.mark.parametrize("duration", [4e-4, 0.0])
def test_a_push_too_short_to_act_is_refused_as_natively(talos_sim, duration):
    """One push rule for both backends: a push must last at least half a step, else it would
    never act (MuJoCo used to drop a 0.4 ms push silently)."""
    talos_sim.reset(np.array(load_talos("full").reference_configuration))
    with pytest.raises(InvalidInputError, match="duration"):
        talos_sim.push_impulse("torso_2_link", [1.0, 0.0, 0.0], duration=duration)
    assert talos_sim._pushes == []


def test_touchdown_at_free_fall_time_then_fall(talos, talos_sim):
    """Dropped 2 cm with zero torque, each sole corner touches down at sqrt(2 h / g) for its
    height h (one step of tolerance); the limp robot then falls, and stepping on is refused."""
    points = [(f, c) for f in talos.foot_frames for c in talos.sole_corners]
    sim = MujocoSimulator(talos.model, talos.source, contact_points=points)
    q = np.array(talos.reference_configuration)
    q[2] += 0.02
    state = sim.reset(q)
    heights = state.contact_positions[:, 2]
    assert not state.in_contact.any()
    touchdown = np.full(len(points), np.nan)
    while np.isnan(touchdown).any() and state.t < 0.2:
        state = sim.step(np.zeros(sim.n_actuated))
        for event in state.touchdowns:
            touchdown[event.point] = event.time
    assert not state.fallen
    expected = np.sqrt(2 * heights / GRAVITY)
    np.testing.assert_allclose(touchdown, expected, atol=1.5 * sim.dt)
    while not state.fallen and state.t < 2.0:
        state = sim.step(np.zeros(sim.n_actuated))
    assert state.fallen and state.fall.time == state.t
    with pytest.raises(InvalidInputError, match=r"step\(\) after the robot fell at t = "):
        sim.step(np.zeros(sim.n_actuated))
    assert not sim.reset(q).fallen


# ------------------------------------------------------------------------- falls, both backends
def both_backends(talos, points, **falls):
    """The native simulator (compliant ground if there are points) and MuJoCo, same options."""
    ground = GroundContact(stiffness=2e4, damping=300.0, friction=1.0) if points else None
    return {
        "native": Simulator(talos.model, 1e-3, points, ground, **falls),
        "mujoco": MujocoSimulator(talos.model, talos.source, 1e-3, points, **falls),
    }


def fall_of(sim, q, limit=3.0):
    state = sim.reset(q)
    while not state.fallen and state.t < limit:
        state = sim.step(np.zeros(sim.n_actuated))
    return state.fall


def test_both_backends_derive_the_same_thresholds(talos):
    """Base 1.083 m above the lowest sole corner with straight legs (the answer key, computed
    here from the frame placements): min height h / 2, flight sqrt(h / g), spin sqrt(2 g / h)."""
    points = [(f, c) for f in talos.foot_frames for c in talos.sole_corners]
    data = talos.model.createData()
    pin.framesForwardKinematics(talos.model, data, pin.neutral(talos.model))
    corners = [data.oMf[talos.model.getFrameId(f)].act(np.array(c)) for f, c in points]
    height = data.oMi[1].translation[2] - min(c[2] for c in corners)
    expected = (0.5 * height, np.pi / 4, np.sqrt(height / GRAVITY), np.sqrt(2 * GRAVITY / height))
    for sim in both_backends(talos, points).values():
        detector = sim.fall_detector
        thresholds = (
            detector.min_height,
            detector.max_tilt,
            detector.max_flight_time,
            detector.max_spin,
        )
        np.testing.assert_allclose(thresholds, expected, rtol=1e-9)
    for sim in both_backends(talos, points, fall_frame="base_link", fall_height=0.7).values():
        assert sim.fall_detector.min_height == 0.7
        assert sim.fall_detector.max_spin == pytest.approx(expected[3])


@pytest.mark.parametrize("drop", [0.1, 0.5])
def test_both_backends_flag_a_free_fall_at_the_free_fall_time(talos, drop):
    """No contact points (nothing to land on), ``fall_height`` = start height - d: both flag a
    height fall after sqrt(2 d / g), within a step and a half."""
    q = np.array(talos.reference_configuration)
    q[2] = 2.0
    for name, sim in both_backends(talos, [], fall_height=2.0 - drop).items():
        fall = fall_of(sim, q)
        assert fall is not None and fall.cause == "height", name
        assert fall.time == pytest.approx(np.sqrt(2 * drop / GRAVITY), abs=1.5e-3), name


@pytest.mark.parametrize("lift", [0.0, 0.5])
def test_limp_talos_falls_the_same_way_on_both_backends(talos, lift):
    """Zero torques from the standing posture (or dropped ``lift`` metres onto its soles): the
    knees give way, the base sinks below h / 2 on both backends, within 20 ms of each other;
    then both refuse to step on."""
    points = [(f, c) for f in talos.foot_frames for c in talos.sole_corners]
    q = np.array(talos.reference_configuration)
    q[2] += lift
    falls = {}
    for name, sim in both_backends(talos, points).items():
        falls[name] = fall_of(sim, q)
        assert falls[name] is not None, name
        assert falls[name].value < falls[name].threshold == sim.fall_detector.min_height
        with pytest.raises(InvalidInputError, match=r"step\(\) after the robot fell"):
            sim.step(np.zeros(sim.n_actuated))
    assert falls["native"].cause == falls["mujoco"].cause == "height"
    assert falls["mujoco"].time == pytest.approx(falls["native"].time, abs=0.02)


# ------------------------------------------------------------------------- closed loop
@pytest.fixture(scope="module")
def drumming():
    from dmpopt_studies import humanoid

    return humanoid, humanoid.learn_drumming(humanoid.demonstrate_drumming())


def stand_and_drum(talos, humanoid, dmps, seconds):
    """The humanoid study's controller and DMP plan closing the loop on MuJoCo."""
    q0 = humanoid.drumming_posture(talos)
    q0[talos.configuration_indices(list(humanoid.DRUM_JOINTS))] = dmps.start
    v0 = np.zeros(talos.nv)
    v0[talos.velocity_indices(list(humanoid.DRUM_JOINTS))] = dmps.start_velocity
    controller, task = humanoid.build_controller(talos, q0)
    plan = humanoid.DrumPlan(dmps, humanoid.DT)
    points = [(f, c) for f in talos.foot_frames for c in talos.sole_corners]
    sim = MujocoSimulator(talos.model, talos.source, humanoid.DT, points, fall_frame="base_link")
    state = sim.reset(q0, v0)
    joints = talos.configuration_indices(list(humanoid.DRUM_JOINTS))
    errors, vertical, fell = [], [], False
    for k in range(int(round(seconds / humanoid.DT))):
        if k:
            plan.step()
        task.set_reference(plan.position, plan.velocity, plan.acceleration)
        state = sim.step(controller.compute_torques(state.q, state.v))
        errors.append(state.q[joints] - plan.position)
        vertical.append(state.contact_forces[:, 2].sum())
        fell = fell or state.fallen
    return np.array(errors), np.array(vertical), fell, plan


def test_standing_talos_drums_on_mujoco(talos, drumming):
    """1 s of drumming, standing on MuJoCo contacts: no fall, arm tracking RMS < 1 mrad and
    max < 5 mrad (the arms move through ~0.3 rad; the native simulator gives 0.17 and 0.7 mrad),
    the ground carries the weight on average (within 3 %)."""
    humanoid, dmps = drumming
    errors, vertical, fell, plan = stand_and_drum(talos, humanoid, dmps, 1.0)
    assert not fell
    assert np.sqrt(np.mean(errors**2)) < 1e-3
    assert np.abs(errors).max() < 5e-3
    weight = pin.computeTotalMass(talos.model) * GRAVITY
    assert abs(vertical.mean() / weight - 1) < 0.03


@pytest.mark.slow
def test_standing_talos_drums_for_five_seconds(talos, drumming):
    """5 s: no fall and the same tracking bound."""
    humanoid, dmps = drumming
    errors, _, fell, _ = stand_and_drum(talos, humanoid, dmps, 5.0)
    assert not fell
    assert np.sqrt(np.mean(errors**2)) < 1e-3


# -------------------------------------------------------------------------- rendering
def test_render_animation_writes_frames(talos, talos_sim, tmp_path):
    """Three configurations become a three-frame GIF under the size bound."""
    q = np.array(talos.reference_configuration)
    bent = q.copy()
    bent[talos.configuration_indices(["arm_left_4_joint"])] = -0.5
    configurations = [q, bent, q]
    shadow_size = talos_sim.mj_model.vis.quality.shadowsize
    try:
        path = render_animation(talos_sim, configurations, tmp_path / "a.gif", width=64, height=48)
    except MissingDependency as error:
        pytest.skip(f"no offscreen rendering here: {error}")
    assert talos_sim.mj_model.vis.quality.shadowsize == shadow_size  # the model left as it was
    from PIL import Image

    with Image.open(path) as image:
        assert image.n_frames == 3 and image.size == (64, 48)
    assert path.stat().st_size < 5_000_000
    with pytest.raises(ResourceLimitError, match="max_bytes"):
        render_animation(talos_sim, [q], tmp_path / "b.webp", width=64, height=48, max_bytes=10)


@given(width=st.integers(1, 5000), height=st.integers(1, 5000))
def test_shadow_map_is_the_power_of_two_just_above_twice_the_frame(width, height):
    """The shadow map's side: a power of two in [2 L, 4 L), L the longer side of the frame."""
    size, longest = shadow_map_size(width, height), max(width, height)
    assert size & (size - 1) == 0
    assert 2 * longest <= size < 4 * longest


_STILLS = """
import sys
import numpy as np
import pinocchio as pin
from dmpopt.exceptions import MissingDependency
from dmpopt.sim import MujocoSimulator, render_frame
from dmpopt_robots import load_talos

talos, out = load_talos("full"), sys.argv[1]
sim = MujocoSimulator(talos.model, talos.source, contact_points=talos.contact_points)
q = np.array(talos.reference_configuration)
data = talos.create_data()
pin.framesForwardKinematics(talos.model, data, q)
hand = data.oMf[talos.model.getFrameId("gripper_left_base_link")].translation
camera = dict(width=64, height=48, distance=0.8, elevation=-20.0)
try:
    render_frame(sim, q, f"{out}/f.png", target="gripper_left_base_link", **camera)
except MissingDependency as error:
    print("skip:", error)
    sys.exit(0)
render_frame(sim, q, f"{out}/p.png", target=hand, **camera)
render_frame(sim, q, f"{out}/t.png", target=hand, azimuth=45.0, **camera)
wide = dict(width=64, height=48, distance=3.0, azimuth=135.0)
render_frame(sim, q, f"{out}/shaded.png", **wide)
render_frame(sim, q, f"{out}/plain.png", shadows=False, **wide)
"""


def test_render_frame_camera_follows_a_frame(talos, talos_sim, tmp_path):
    """A PNG still looking at a hand equals the still looking at the hand's world position
    (Pinocchio's forward kinematics, computed in the script); another azimuth is another
    picture; a still without shadows is lighter. The stills are rendered in a process of their
    own: after the rest of the suite had made its renderers, a new OpenGL context in the same
    process once aborted it."""
    import subprocess

    from PIL import Image

    run = subprocess.run(
        [sys.executable, "-c", _STILLS, str(tmp_path)], capture_output=True, text=True, timeout=600
    )
    assert run.returncode == 0, run.stderr[-2000:]
    if run.stdout.startswith("skip:"):
        pytest.skip(f"no offscreen rendering here: {run.stdout}")
    images = [np.asarray(Image.open(tmp_path / name)) for name in ("f.png", "p.png", "t.png")]
    assert images[0].shape == (48, 64, 3)
    np.testing.assert_array_equal(images[0], images[1])
    assert np.abs(images[0].astype(int) - images[2]).mean() > 1.0
    q = np.array(talos.reference_configuration)
    with pytest.raises(InvalidInputError, match="target='hand' is not a frame of the model"):
        render_frame(talos_sim, q, tmp_path / "x.png", target="hand")
    with pytest.raises(InvalidInputError, match=r"must end in \.png"):
        render_frame(talos_sim, q, tmp_path / "x.gif")
    with pytest.raises(InvalidInputError, match="shadows must be True or False"):
        render_frame(talos_sim, q, tmp_path / "x.png", shadows="no")
    # Shadows take light away: without them the picture holds more light in total and the
    # floor the robot shades (at least 50 of 3072 pixels) is brighter by more than 30 grey
    # levels; a renderer that ignored ``shadows`` would give the same picture twice.
    shaded, plain = (
        np.asarray(Image.open(tmp_path / name)).astype(int).sum(axis=2)
        for name in ("shaded.png", "plain.png")
    )
    assert (plain - shaded).sum() > 0
    assert (plain - shaded > 30).sum() >= 50


def test_render_without_gl_context_says_why(talos_sim, monkeypatch, tmp_path):
    """A renderer that cannot get an OpenGL context becomes MissingDependency with the reason."""

    def no_context(*args, **kwargs):
        raise RuntimeError("eglInitialize failed")

    monkeypatch.setattr(mujoco, "Renderer", no_context)
    q = talos_sim.state.q
    with pytest.raises(MissingDependency, match="OpenGL.*eglInitialize failed"):
        render_animation(talos_sim, [q], tmp_path / "a.webp")


# -------------------------------------------------------------------------- bad inputs
def test_bad_simulator_arguments(talos, talos_sim):
    """Each bad constructor argument is named in the error."""
    model, urdf = talos.model, talos.source
    for dt in (0.0, -1e-3, np.nan, "fast"):
        with pytest.raises(InvalidInputError, match="dt must be"):
            MujocoSimulator(model, urdf, dt=dt)
    with pytest.raises(InvalidInputError, match="frame 'no_foot' is not in the model"):
        MujocoSimulator(model, urdf, contact_points=[("no_foot", (0, 0, 0))])
    with pytest.raises(InvalidInputError, match="contact_points must be a sequence"):
        MujocoSimulator(model, urdf, contact_points=None)
    with pytest.raises(InvalidInputError, match=r"contact_points must hold \(frame_name"):
        MujocoSimulator(model, urdf, contact_points=["left_sole_link"])
    with pytest.raises(ShapeError, match="offset of contact point 'left_sole_link'"):
        MujocoSimulator(model, urdf, contact_points=[("left_sole_link", (0, 0))])
    with pytest.raises(InvalidInputError, match="friction must be"):
        MujocoSimulator(model, urdf, friction=-1)
    with pytest.raises(InvalidInputError, match="damping must be"):
        MujocoSimulator(model, urdf, plant=PlantParameters(damping=np.inf))
    with pytest.raises(InvalidInputError, match="plant must be a PlantParameters"):
        MujocoSimulator(model, urdf, plant={"damping": 1.0})
    with pytest.raises(InvalidInputError, match="armature pattern 'leg_\\*_9' matches no"):
        MujocoSimulator(model, urdf, plant=PlantParameters(armature={"leg_*_9": 0.1}))
    with pytest.raises(InvalidInputError, match="urdf '/no/such.urdf' is not a file"):
        MujocoSimulator(model, "/no/such.urdf")
    with pytest.raises(InvalidInputError, match="model must be a pinocchio.Model.*robot.model"):
        MujocoSimulator(talos, urdf)
    with pytest.raises(InvalidInputError, match="falls must be True, False or a FallDetector"):
        MujocoSimulator(model, urdf, falls="base_link")
    with pytest.raises(
        InvalidInputError, match="fall_frame: frame 'no_such_frame' is not in the model"
    ):
        MujocoSimulator(model, urdf, fall_frame="no_such_frame")
    with pytest.raises(InvalidInputError, match="fall_frame 'left_sole_link' is not on the base"):
        MujocoSimulator(model, urdf, fall_frame="left_sole_link")
    with pytest.raises(InvalidInputError, match="fall_height must be a finite height"):
        MujocoSimulator(model, urdf, fall_height=float("nan"))
    with pytest.raises(InvalidInputError, match="fall_frame or fall_height given with falls=Fa"):
        MujocoSimulator(model, urdf, falls=False, fall_height=0.5)


def test_floating_base_without_contact_points_is_refused(talos):
    """MuJoCo too refuses a standing robot with nothing under its feet, naming the fix."""
    with pytest.raises(InvalidInputError, match="but no contact_points: it would fall through"):
        MujocoSimulator(talos.model, talos.source)


def test_model_and_urdf_must_be_the_same_robot(talos):
    """Another robot's URDF, a model with other masses, a locked-joint model: named errors."""
    biped = load_biped()
    with pytest.raises(InvalidInputError, match="disagree on joints"):
        MujocoSimulator(biped.model, talos.source)
    heavier = pin.Model(talos.model)
    inertia = heavier.inertias[5]
    heavier.inertias[5] = pin.Inertia(inertia.mass * 1.1, inertia.lever, inertia.inertia * 1.1)
    with pytest.raises(InvalidInputError, match="not the same robot"):
        MujocoSimulator(heavier, talos.source, falls=False)
    upper_body = load_talos("full", fixed_base=True)
    with pytest.raises(InvalidInputError, match="in the URDF only .*leg_left_1_joint"):
        MujocoSimulator(upper_body.model, talos.source)


def test_unresolved_mesh_package_names_package_dirs(talos, tmp_path):
    """A package:// mesh that is not under package_dirs is a FileFormatError naming them."""
    with pytest.raises(FileFormatError, match="package_dirs"):
        MujocoSimulator(talos.model, talos.source, package_dirs=[tmp_path])


def test_bad_state_torque_and_push_arguments(talos_sim):
    """reset, step and push name the argument, the expected shape and what arrived."""
    sim = talos_sim
    nq, nv, na = sim.model.nq, sim.model.nv, sim.n_actuated
    with pytest.raises(ShapeError, match=rf"q has shape \(3,\), expected \({nq},\)"):
        sim.reset(np.zeros(3))
    q = np.zeros(nq)
    with pytest.raises(InvalidInputError, match="base quaternion"):
        sim.reset(q)
    q[6] = 1.0
    with pytest.raises(InvalidInputError, match=r"v\[\d+\] is nan"):
        sim.reset(q, np.full(nv, np.nan))
    sim.reset(q)
    with pytest.raises(ShapeError, match=rf"torques has shape \(2,\), expected \({na},\)"):
        sim.step(np.zeros(2))
    tau = np.zeros(na)
    tau[4] = np.nan
    with pytest.raises(InvalidInputError, match=r"torques must be finite; entries \[4\]"):
        sim.step(tau)
    with pytest.raises(ShapeError, match=r"base_force has shape \(2,\), expected \(6,\)"):
        sim.step(np.zeros(na), base_force=[1, 2])
    with pytest.raises(ShapeError, match=r"force has shape \(2,\)"):
        sim.push("base_link", [1, 2], 0.1)
    with pytest.raises(InvalidInputError, match="duration must be"):
        sim.push("base_link", [1, 2, 3], 0.0)
    with pytest.raises(InvalidInputError, match="frame 'hand' is not in the model"):
        sim.push_impulse("hand", [1, 2, 3])
    with pytest.raises(InvalidInputError, match="must end in .webp or .gif"):
        render_animation(sim, [sim.state.q], "video.mp4")
    with pytest.raises(ShapeError, match="configurations has shape"):
        render_animation(sim, np.zeros((2, 3)), "video.gif")
    with pytest.raises(InvalidInputError, match=r"configurations must be finite; rows \[1\]"):
        render_animation(sim, [sim.state.q, np.full(nq, np.nan)], "video.gif")
    with pytest.raises(InvalidInputError, match="directory '/no/such' does not exist"):
        render_animation(sim, [sim.state.q], "/no/such/video.gif")


def test_exploding_torques_raise_simulation_diverged(talos_sim, monkeypatch, tmp_path):
    """Torques of 1e12 N m: SimulationDiverged naming the time, never a silent MuJoCo reset."""
    monkeypatch.chdir(tmp_path)  # MuJoCo logs its warning to MUJOCO_LOG.TXT in the cwd
    talos_sim.reset(talos_sim.state.q)
    with pytest.raises(SimulationDiverged, match="at t = "):
        talos_sim.step(np.full(talos_sim.n_actuated, 1e12))


def test_missing_mujoco_names_the_extra(talos, monkeypatch):
    """Without the mujoco package: MissingDependency naming the dmpopt[mujoco] extra."""
    monkeypatch.setitem(sys.modules, "mujoco", None)
    with pytest.raises(MissingDependency, match=r"dmpopt\[mujoco\]"):
        MujocoSimulator(talos.model, talos.source)


def test_planar_biped_walks_on_mujoco_as_on_the_native_simulator():
    """The walking study's gait (DMPs, PD, boom, frequency adaptation) on MuJoCo for 4 s: no
    fall, and distance and heel strikes within 15 % / one strike of the native simulator's."""
    from dmpopt_studies import biped as study

    biped = load_biped()
    _, dmp = study.learn_gait()

    native = study.walk(biped, dmp, 4.0, study.DEMO_FREQUENCY, backend="native")
    on_mujoco = study.walk(biped, dmp, 4.0, study.DEMO_FREQUENCY, backend="mujoco")
    assert not native.fell and not on_mujoco.fell, on_mujoco.diverged
    assert native.distance > 1.0
    assert abs(on_mujoco.distance / native.distance - 1) < 0.15
    assert abs(len(on_mujoco.strikes) - len(native.strikes)) <= 1


def test_boxes_on_the_floor_are_ground_where_they_stand():
    """A 4 cm box, and a 0.1 rad slope: a vertical ray (MuJoCo's own ray casting) meets the
    box top at 4 cm and the slope on the plane through the tilted box's top face (written
    here from its centre and normal); bad boxes are named."""
    import mujoco

    biped = load_biped()
    h, pitch = 0.04, 0.1
    boxes = [((1.0, 0.0, h / 2), (0.2, 0.5, h / 2)), ((3.0, 0.0, 0.05), (0.5, 0.5, 0.01), pitch)]
    sim = MujocoSimulator(biped.model, BIPED_URDF, contact_points=biped.contact_points,
                          boxes=boxes)  # fmt: skip
    geom = np.zeros(1, dtype=np.int32)
    mujoco.mj_forward(sim.mj_model, sim.mj_data)  # world geometry placed

    def ground(x):  # the ray runs beside the planar biped (y = 0.3)
        return 5.0 - mujoco.mj_ray(sim.mj_model, sim.mj_data, np.array([x, 0.3, 5.0]),
                                   np.array([0.0, 0.0, -1.0]), None, 1, -1, geom)  # fmt: skip

    assert ground(1.0) == pytest.approx(h, abs=1e-9)
    assert ground(2.0) == pytest.approx(0.0, abs=1e-9)
    # the top face of the tilted box: the plane through (3, 0, 0) + R_y(pitch) (0, 0, 0.01)
    normal = np.array([np.sin(pitch), 0.0, np.cos(pitch)])
    top = np.array([3.0, 0.0, 0.05]) + 0.01 * normal
    x = 3.2
    expected = top[2] - normal[0] * (x - top[0]) / normal[2]
    assert ground(x) == pytest.approx(expected, abs=1e-9)
    with pytest.raises(InvalidInputError, match=r"boxes\[0\] half_sizes must be > 0"):
        MujocoSimulator(biped.model, BIPED_URDF, contact_points=biped.contact_points,
                        boxes=[((0, 0, 0), (0.1, 0.0, 0.1))])  # fmt: skip
    with pytest.raises(InvalidInputError, match=r"boxes\[0\] must be"):
        MujocoSimulator(biped.model, BIPED_URDF, contact_points=biped.contact_points,
                        boxes=[((0, 0, 0),)])  # fmt: skip
