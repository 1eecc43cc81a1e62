"""Two-hand coupling (dmpopt.bimanual): answer keys written here, not by the library.

* the coupled relative position error of two DMPs with the same forcing term solves the
  linear system of the module docstring, whose closed form is written below;
* the error and the coupling terms are equivariant under a rigid motion of both hands
  (the relative pose does not change; the terms turn with the motion);
* the orientation error agrees with a rotation vector computed from quaternions written here.
"""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt import CartesianDMP
from dmpopt.bimanual import (
    BimanualStepper,
    RelativePoseCoupling,
    matrix_quaternion,
    rotation_matrix,
)
from dmpopt.exceptions import InvalidInputError

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
ALPHA, BETA = 25.0, 25.0 / 4.0  # the DMP defaults alpha_z, beta_z = alpha_z / 4


def hand_dmp(weights, start, goal, tau):
    """A Cartesian DMP of fixed (identity) orientation and the given position weights."""
    return CartesianDMP(
        position_weights=weights,
        orientation_weights=np.zeros_like(weights),
        start=start,
        goal=goal,
        start_orientation=IDENTITY,
        goal_orientation=IDENTITY,
        tau=tau,
        centres=np.linspace(0.0, 1.0, weights.shape[1]),
        widths=np.full(weights.shape[1], 50.0),
    )


def closed_form(times, e0, v0, tau, k, d):
    r"""Solution of :math:`\tau^2 \ddot e + (\alpha\tau + d\tau^2)\dot e + (\alpha\beta +
    k\tau^2) e = 0`, :math:`e(0) = e_0`, :math:`\dot e(0) = v_0`: its value and first two
    derivatives at ``times``, and :math:`c_0 = \alpha\beta + k\tau^2`. Overdamped: two real
    roots; critically damped (the DMP alone, :math:`\beta = \alpha / 4`): one double root."""
    c1, c0 = ALPHA * tau + d * tau**2, ALPHA * BETA + k * tau**2
    discriminant = c1**2 - 4.0 * tau**2 * c0
    t = times[:, None]
    if discriminant <= 1e-12 * c1**2:  # e = (a + b t) exp(r t)
        r = -c1 / (2 * tau**2)
        a, b = e0, v0 - r * e0
        growth = np.exp(r * t)
        e = (a + b * t) * growth
        rate = (b + r * (a + b * t)) * growth
        acceleration = (2 * r * b + r**2 * (a + b * t)) * growth
        return e, rate, acceleration, c0
    root = np.sqrt(discriminant)
    r1, r2 = (-c1 + root) / (2 * tau**2), (-c1 - root) / (2 * tau**2)
    b = (v0 - r1 * e0) / (r2 - r1)  # e = a exp(r1 t) + b exp(r2 t)
    a = e0 - b
    e = a * np.exp(r1 * t) + b * np.exp(r2 * t)
    rate = a * r1 * np.exp(r1 * t) + b * r2 * np.exp(r2 * t)
    acceleration = a * r1**2 * np.exp(r1 * t) + b * r2**2 * np.exp(r2 * t)
    return e, rate, acceleration, c0


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10_000), k=st.sampled_from([300.0, 1000.0]), share=st.floats(0, 1))
def test_relative_position_error_solves_the_linear_system(seed, k, share):
    """Same forcing and tau, goals r* apart, the right start off by e0: the relative error is
    the closed form of the coupled linear system (module docstring)."""
    rng = np.random.default_rng(seed)
    weights = rng.normal(0.0, 50.0, (3, 10))
    tau, dt = 2.0, 1e-3
    offset = np.array([0.0, -0.3, 0.0])  # r*, right hand 0.3 m to the right
    e0 = rng.normal(0.0, 0.02, 3)
    start, goal = rng.normal(0.0, 0.2, 3), rng.normal(0.0, 0.2, 3)
    left = hand_dmp(weights, start, goal, tau)
    right = hand_dmp(weights, start + offset + e0, goal + offset, tau)
    coupling = RelativePoseCoupling(offset, IDENTITY, stiffness=k, share=share)
    pair = BimanualStepper(left, right, coupling, dt)
    n = 1000
    errors = np.empty((n, 3))
    for i in range(n):
        errors[i] = pair.right.position - pair.left.position - offset
        pair.step()
    times = np.arange(n) * dt
    expected, rate, acceleration, c0 = closed_form(times, e0, np.zeros(3), tau, k, coupling.damping)
    # The coupling is held over each step (zero-order hold) while RK4 integrates the rest
    # (error O(dt^4), negligible): the held term differs from the continuous one by at most
    # dt * max|d/dt (k e + d de/dt)| = dt * max|k de/dt + d d2e/dt2| (from the closed form).
    # That perturbation of tau^2 e'' enters the same overdamped system, whose impulse response
    # is positive with integral 1 / c0 (its static gain): e moves by at most
    # tau^2 dt max|...| / c0; a factor 2 covers the feedback of the discrete solution's own
    # difference (first order in dt).
    held = np.abs(k * rate + coupling.damping * acceleration).max()
    bound = 2.0 * tau**2 * dt * held / c0
    assert np.abs(errors - expected).max() <= bound
    uncoupled, *_ = closed_form(times, e0, np.zeros(3), tau, 0.0, 0.0)
    assert bound < 0.2 * np.abs(uncoupled - expected).max()  # the coupling's effect is larger


def test_without_coupling_the_error_follows_the_dmp_alone():
    """Uncoupled (k = 0, d = 0: the DMP's own spring only) the same closed form holds: the
    error decays with the DMP's time scale, slower than coupled."""
    weights = np.zeros((3, 10))
    tau, dt, n = 0.8, 1e-3, 400
    e0 = np.array([0.02, 0.0, -0.01])
    left = hand_dmp(weights, np.zeros(3), np.ones(3), tau)
    right = hand_dmp(weights, e0, np.ones(3), tau)
    free = RelativePoseCoupling(np.zeros(3), IDENTITY, stiffness=0.0)
    coupled = RelativePoseCoupling(np.zeros(3), IDENTITY, stiffness=1000.0)
    final = {}
    for name, coupling in (("free", free), ("coupled", coupled)):
        pair = BimanualStepper(left, right, coupling, dt)
        for _ in range(n):
            pair.step()
        final[name] = pair.right.position - pair.left.position
    times = np.array([n * dt])
    expected, *_ = closed_form(times, e0, np.zeros(3), tau, 0.0, 0.0)
    # no coupling: RK4 alone, O(dt^4) per unit time; 1e-9 of the 0.02 m start is far above
    np.testing.assert_allclose(final["free"], expected[0], atol=1e-9)
    assert np.linalg.norm(final["coupled"]) < 0.25 * np.linalg.norm(final["free"])


def random_rotation(rng) -> np.ndarray:
    quaternion = rng.normal(size=4)
    return quaternion / np.linalg.norm(quaternion)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_error_and_terms_are_equivariant_under_a_common_rigid_motion(seed):
    """Moving both hands by one rigid motion (R, t) leaves the relative pose error's size
    unchanged and turns the error and every coupling term by R."""
    rng = np.random.default_rng(seed)
    coupling = RelativePoseCoupling(
        rng.normal(size=3), random_rotation(rng), stiffness=300.0, share=rng.uniform()
    )
    states = [
        (rng.normal(size=3), rng.normal(size=3), random_rotation(rng), rng.normal(size=3))
        for _ in range(2)
    ]
    motion, shift = rotation_matrix(random_rotation(rng)), rng.normal(size=3)

    def moved(state):
        position, velocity, orientation, angular = state
        turned = matrix_quaternion(motion @ rotation_matrix(orientation))
        return motion @ position + shift, motion @ velocity, turned, motion @ angular

    before = coupling.accelerations(*states)
    after = coupling.accelerations(*(moved(s) for s in states))
    for term, moved_term in zip(before, after):
        np.testing.assert_allclose(moved_term, motion @ term, atol=1e-9)
    error = coupling.error(states[0][::2], states[1][::2])
    moved_error = coupling.error(moved(states[0])[::2], moved(states[1])[::2])
    for part, moved_part in zip(error, moved_error):
        np.testing.assert_allclose(moved_part, motion @ part, atol=1e-9)


def quaternion_product(p, q):
    """Hamilton product of (w, x, y, z) quaternions, written here."""
    pw, pv, qw, qv = p[0], np.asarray(p[1:]), q[0], np.asarray(q[1:])
    return np.r_[pw * qw - pv @ qv, pw * qv + qw * pv + np.cross(pv, qv)]


def test_orientation_error_is_the_rotation_vector_of_the_relative_error():
    """e_o = 2 log(q_R conj(q_L q*)) computed from quaternions here: angle 2 atan2(|v|, w)
    along v, for a known 0.3 rad turn about z of the right hand beyond the grasp."""
    rng = np.random.default_rng(3)
    left, relative = random_rotation(rng), random_rotation(rng)
    turn = np.array([np.cos(0.15), 0.0, 0.0, np.sin(0.15)])  # 0.3 rad about world z
    right = quaternion_product(turn, quaternion_product(left, relative))
    coupling = RelativePoseCoupling(np.zeros(3), relative)
    _, rotation = coupling.error((np.zeros(3), left), (np.zeros(3), right))
    np.testing.assert_allclose(rotation, [0.0, 0.0, 0.3], atol=1e-12)


def test_the_grasp_is_held_without_any_term():
    """Poses at the grasp give zero error and zero terms (from_poses inverts the error)."""
    rng = np.random.default_rng(4)
    left, right = random_rotation(rng), random_rotation(rng)
    pl, pr = rng.normal(size=3), rng.normal(size=3)
    coupling = RelativePoseCoupling.from_poses(pl, left, pr, right)
    zero = np.zeros(3)
    for term in coupling.accelerations((pl, zero, left, zero), (pr, zero, right, zero)):
        np.testing.assert_allclose(term, 0.0, atol=1e-12)


def test_bad_input_is_refused_with_the_argument_named():
    with pytest.raises(InvalidInputError, match="share"):
        RelativePoseCoupling(np.zeros(3), IDENTITY, share=1.5)
    dmp = hand_dmp(np.zeros((3, 5)), np.zeros(3), np.ones(3), 1.0)
    with pytest.raises(InvalidInputError, match="hand must be 'left' or 'right', got 'middle'"):
        BimanualStepper(dmp, dmp, None).set_goal("middle", position=np.zeros(3))
    with pytest.raises(InvalidInputError, match="right must be a CartesianDMP"):
        BimanualStepper(dmp, "dmp", None)


def test_jacobian_inverse_inverts_the_library_log_jacobian():
    """left_jacobian_inverse(e) times the library's J(e) (automatic differentiation of the
    exponential map, dmpopt.symbolic) is the identity, also near e = 0 (the series)."""
    from dmpopt.bimanual import left_jacobian_inverse
    from dmpopt.symbolic import orientation_function

    rng = np.random.default_rng(5)
    for e in [rng.normal(size=3) for _ in range(5)] + [np.array([1e-6, -2e-6, 0.0])]:
        jacobian = orientation_function()(e, np.zeros(3), np.zeros(3), IDENTITY)[3].full()
        np.testing.assert_allclose(left_jacobian_inverse(e) @ jacobian, np.eye(3), atol=1e-9)


def test_damping_acts_on_the_time_derivative_of_the_error():
    """With stiffness 0 the left term is (1 - share) d times the rate of the error: compared
    with central differences of e_p(t) and of R_e(t) (omega_e = vee(dR_e/dt R_e^T)) along
    hands turning and moving at known rates (second-order differences, h = 1e-5 s: error
    O(h^2) times the third derivative, below 1e-6 here)."""
    rng = np.random.default_rng(6)
    relative = random_rotation(rng)
    coupling = RelativePoseCoupling(
        rng.normal(size=3), relative, stiffness=0.0, damping=1.0, angular_stiffness=0.0,
        angular_damping=1.0, share=0.0,
    )  # fmt: skip
    p0, v = [rng.normal(size=3) for _ in range(2)], [rng.normal(size=3) for _ in range(2)]
    q0, w = [random_rotation(rng) for _ in range(2)], [rng.normal(size=3) for _ in range(2)]

    def pose(i, t):  # constant world velocity and angular velocity
        turn = matrix_quaternion(pin.exp3(w[i] * t) @ rotation_matrix(q0[i]))
        return p0[i] + v[i] * t, turn

    def error_rotation(t):
        left, right = rotation_matrix(pose(0, t)[1]), rotation_matrix(pose(1, t)[1])
        return right @ (left @ rotation_matrix(relative)).T

    h = 1e-5
    rate = coupling.error(pose(0, h), pose(1, h))[0] - coupling.error(pose(0, -h), pose(1, -h))[0]
    rate /= 2 * h
    spin = (error_rotation(h) - error_rotation(-h)) / (2 * h) @ error_rotation(0.0).T
    states = [(p0[i], v[i], q0[i], w[i]) for i in range(2)]
    linear, angular, _, _ = coupling.accelerations(*states)
    np.testing.assert_allclose(linear, rate, atol=1e-6)
    np.testing.assert_allclose(angular, [spin[2, 1], spin[0, 2], spin[1, 0]], atol=1e-6)


def test_a_free_box_falls_freely_then_rests_on_the_floor():
    """A FreeBox in the MuJoCo scene (dmpopt.sim.mujoco_backend) is a free body outside the
    robot's coordinates: released 0.3 m above the floor it falls as z0 - g t^2 / 2 (MuJoCo
    integrates gravity exactly up to the step's first-order error, g dt t = 1e-3 m here),
    then rests with its centre at its half height (contact penetration of MuJoCo's soft
    contact, below 2 mm for a 1 kg box); the robot's mass check ignores it and reset puts it
    back."""
    mujoco = pytest.importorskip("mujoco")
    del mujoco
    from dmpopt_robots.biped import BIPED_URDF, load_biped

    from dmpopt.sim.mujoco_backend import FreeBox, MujocoSimulator

    biped = load_biped()
    half, start = 0.05, np.array([2.0, 0.0, 0.35])
    box = FreeBox("box", (half, half, half), 1.0, tuple(start))
    sim = MujocoSimulator(
        biped.model, BIPED_URDF, contact_points=biped.contact_points, falls=False,
        free_bodies=[box],
    )  # fmt: skip
    q = pin.neutral(biped.model)
    sim.reset(q)
    np.testing.assert_allclose(sim.free_body_qpos, [*start, 1.0, 0.0, 0.0, 0.0])
    dt, g = sim.dt, 9.81
    torque = np.zeros(sim.n_actuated)
    for _ in range(200):  # 0.2 s: 0.196 m of fall, still in the air
        sim.step(torque)
    t = 200 * dt
    assert sim.free_body_qpos[2] == pytest.approx(start[2] - g * t**2 / 2, abs=g * dt * t)
    for _ in range(800):
        sim.step(torque)
    assert sim.free_body_qpos[2] == pytest.approx(half, abs=2e-3)
    sim.reset(q)
    np.testing.assert_allclose(sim.free_body_qpos[:3], start)
    with pytest.raises(InvalidInputError, match="repeat or are links of the robot"):
        MujocoSimulator(biped.model, BIPED_URDF, free_bodies=[box, box], falls=False)


def test_relative_angle_about_one_axis_solves_the_linear_system():
    """Both hands turn about the world z axis only (goals the same orientation, the right
    hand starting 0.2 rad further): rotations about one axis commute and J(e) acts as the
    identity along it, so the relative angle obeys the same linear system with k_o, d_o.
    Bound as in the position test (zero-order hold of the coupling)."""
    tau, dt, n, k = 2.0, 1e-3, 400, 1000.0
    weights = np.zeros((3, 10))
    left = hand_dmp(weights, np.zeros(3), np.zeros(3), tau)
    angle0 = 0.2
    turned = np.array([np.cos(angle0 / 2), 0.0, 0.0, np.sin(angle0 / 2)])
    right = left.with_start(orientation=turned)
    coupling = RelativePoseCoupling(np.zeros(3), IDENTITY, angular_stiffness=k, share=0.3)
    pair = BimanualStepper(left, right, coupling, dt)
    angles = np.empty(n)
    for i in range(n):
        _, rotation = coupling.error(pair.state("left")[::2], pair.state("right")[::2])
        np.testing.assert_allclose(rotation[:2], 0.0, atol=1e-12)  # about z only
        angles[i] = rotation[2]
        pair.step()
    times = np.arange(n) * dt
    expected, rate, acceleration, c0 = closed_form(
        times, np.array([angle0]), np.zeros(1), tau, k, coupling.angular_damping
    )
    held = np.abs(k * rate + coupling.angular_damping * acceleration).max()
    bound = 2.0 * tau**2 * dt * held / c0
    assert np.abs(angles - expected[:, 0]).max() <= bound
    uncoupled, *_ = closed_form(times, np.array([angle0]), np.zeros(1), tau, 0.0, 0.0)
    assert bound < 0.2 * np.abs(uncoupled - expected).max()


@pytest.mark.slow
def test_talos_carries_the_box_with_coupled_hands():
    """The study's carry (studies/bimanual.py), coupled: standing Talos in MuJoCo holds the
    box by friction and lifts it. Answer key: the carry's set-up, the box should end
    LIFT + NEW_GOAL_SHIFT[2] above its start; the coupled plans hold the relative pose, so
    the box ends within 2 cm of that (the grippers' tracking, a few millimetres, and the
    squeeze's give)."""
    pytest.importorskip("mujoco")
    from dmpopt_robots import load_talos
    from dmpopt_studies import bimanual

    robot = load_talos("full")
    run = bimanual.carry(robot, bimanual.carry_setup(robot), True, 3.0)
    assert not run["fell"]
    assert run["box_drop_mm"] < 20.0
    assert run["plan_relative_error_mm"] < 5.0
