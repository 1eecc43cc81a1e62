"""Cartesian DMPs: position and unit-quaternion orientation (dmpopt.cartesian).

Answer keys: the orientation equations written plainly below in numpy quaternion algebra
(closed-form exponential, logarithm and left Jacobian of SO(3)), integrated in quaternion
variables by scipy's solve_ivp; finite differences of the plan; exact symmetries
(rotation of the demonstration, sign of the quaternions, time scaling).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

import dmpopt
from dmpopt import CartesianDMP, InvalidInputError, ShapeError, fit_cartesian
from dmpopt.cartesian import continuous

# --- quaternion algebra (w, x, y, z), written independently of the library --------------


def qmul(p, q):
    """Hamilton product."""
    pw, pv, qw, qv = p[0], np.asarray(p[1:]), q[0], np.asarray(q[1:])
    return np.concatenate([[pw * qw - pv @ qv], pw * qv + qw * pv + np.cross(pv, qv)])


def qconj(q):
    return np.concatenate([[q[0]], -np.asarray(q[1:])])


def qexp(e):
    """Unit quaternion of the rotation vector e."""
    angle = np.linalg.norm(e)
    if angle == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * e / angle])


def qlog(q):
    """Rotation vector 2 log q, angle in [0, 2 pi)."""
    norm = np.linalg.norm(q[1:])
    return np.zeros(3) if norm == 0.0 else 2 * np.arctan2(norm, q[0]) * q[1:] / norm


def skew(a):
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def left_jacobian(e):
    """J with omega = J(e) de/dt for R = exp([e]): I + (1 - cos)/th^2 K + (th - sin)/th^3 K^2."""
    angle = np.linalg.norm(e)
    if angle < 1e-8:
        return np.eye(3) + 0.5 * skew(e)
    k = skew(e)
    return (
        np.eye(3) + (1 - np.cos(angle)) / angle**2 * k + (angle - np.sin(angle)) / angle**3 * k @ k
    )


def angle_between(p, q):
    """Rotation angle [rad] between unit quaternions (sign-blind), row by row; atan2 of
    the relative quaternion keeps small angles accurate."""
    relative = np.array([qmul(a, qconj(b)) for a, b in zip(np.atleast_2d(p), np.atleast_2d(q))])
    return 2 * np.arctan2(np.linalg.norm(relative[:, 1:], axis=1), np.abs(relative[:, 0]))


def random_unit(rng, n=None):
    q = rng.normal(size=(4,) if n is None else (n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def rotation_matrix(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


# --- the plain system, in quaternion variables -----------------------------------------


def key_rollout(dmp: CartesianDMP, times, goal_changes=()):
    """Eq. (6) and eq. (5) on e = 2 log(q conj(g)), integrated as dq/dt = omega q / 2.

    ``goal_changes``: (time, new goal quaternion) pairs; at each, e is recomputed about the
    new goal (on the side of q) and z carried as an angular velocity, z' = J(e')^-1 J(e) z.
    Translation scaling only (the weights do not change with the goal); goal changes in the
    velocity form only.
    """
    assert dmp.orientation_scaling == "translation"
    assert dmp.form == "velocity" or not goal_changes
    tau, az, bz, av, bv = dmp.tau, dmp.alpha_z, dmp.beta_z, dmp.alpha_v, dmp.beta_v
    weights, centres, widths = dmp.orientation_weights, dmp.centres, dmp.widths

    def forcing(x, v):
        psi = np.exp(-widths * (x - centres) ** 2)
        return weights @ (psi * v / psi.sum())

    def rhs(_, s, goal):
        x, v, q, z = s[0], s[1], s[2:6], s[6:9]
        e = qlog(qmul(q, qconj(goal)))
        canonical = [v / tau, av * (bv * (1 - x) - v) / tau]
        if dmp.form == "velocity":  # eq. (5)
            e_rate, rates = (z + forcing(x, v)) / tau, [az * (bz * (-e) - z) / tau]
        else:  # eq. (10), goal filter r towards e = 0
            r = s[9:12]
            e_rate = z / tau
            rates = [(az * (bz * (r - e) - z) + forcing(x, v)) / tau, dmp.alpha_g * -r / tau]
        omega = left_jacobian(e) @ e_rate
        return np.concatenate([canonical, 0.5 * qmul(np.r_[0.0, omega], q), *rates])

    goal = dmp.goal_orientation
    start_log = qlog(qmul(dmp.start_orientation, qconj(goal)))
    state = np.concatenate(
        [[0.0, 0.0], dmp.start_orientation, tau * dmp.orientation_dmp.start_velocity]
        + ([start_log] if dmp.form == "acceleration" else [])
    )
    edges = [times[0], *[t for t, _ in goal_changes], times[-1]]
    goals = [goal, *[g for _, g in goal_changes]]
    pieces = []
    for k, goal in enumerate(goals):
        if k > 0:  # re-express about the new goal
            q, z = state[2:6], state[6:9]
            old = qlog(qmul(q, qconj(goals[k - 1])))
            goal = goal if goal @ q >= 0 else -goal
            goals[k] = goal
            new = qlog(qmul(q, qconj(goal)))
            state[6:9] = np.linalg.solve(left_jacobian(new), left_jacobian(old) @ z)
        inside = times[(times >= edges[k]) & (times <= edges[k + 1])]
        solution = solve_ivp(
            rhs, (edges[k], edges[k + 1]), state, t_eval=inside, args=(goal,),
            method="DOP853", rtol=1e-11, atol=1e-12,
        )  # fmt: skip
        pieces.append(solution.y.T[: len(inside) - (k < len(goals) - 1)])
        state = solution.y[:, -1].copy()
    return np.vstack(pieces)[:, 2:6]


def random_dmp(rng, n_basis=8, **fields) -> CartesianDMP:
    values = dict(
        position_weights=rng.normal(size=(3, n_basis)),
        orientation_weights=2.0 * rng.normal(size=(3, n_basis)),
        start=rng.normal(size=3),
        goal=rng.normal(size=3),
        start_orientation=random_unit(rng),
        goal_orientation=random_unit(rng),
        tau=0.6,
        centres=np.linspace(0, 1, n_basis),
        widths=np.full(n_basis, 40.0),
    )
    return CartesianDMP(**(values | fields))


def pouring_demo(n=301, duration=2.0):
    """A synthetic pose demonstration: a smooth reach with a tilt about a moving axis."""
    times = np.linspace(0.0, duration, n)
    s = times / duration
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    positions = np.stack([0.4 + 0.2 * s, 0.1 * np.sin(np.pi * s), 0.3 + 0.1 * s**2], axis=1)
    rotations = np.stack([0.3 * s, 1.6 * s, 0.5 * np.sin(np.pi * s)], axis=1)
    start = np.array([0.9, 0.1, -0.3, 0.3])
    start /= np.linalg.norm(start)
    orientations = np.array([qmul(qexp(r), start) for r in rotations])
    return times, positions, orientations


@pytest.fixture(scope="module")
def demo():
    return pouring_demo()


@pytest.fixture(scope="module")
def fitted(demo):
    return fit_cartesian(*demo, n_basis=30)


# --- against the plain system ----------------------------------------------------------


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), form=st.sampled_from(["velocity", "acceleration"]))
def test_rollout_and_stepper_match_the_plain_quaternion_system(seed, form):
    """The orientation plan equals eq. (5) on the logarithm, integrated in quaternions."""
    rng = np.random.default_rng(seed)
    dmp = random_dmp(rng, scaled_start_log_rate=rng.normal(size=3), form=form)
    times = np.arange(0, 1.5 + 1e-9, 0.001)  # RK4: 3.6e-7 rad at 2 ms, 2.2e-8 at 1 ms
    key = key_rollout(dmp, times)
    plan = dmp.rollout(1.5, 0.001)
    assert angle_between(plan.orientations, key).max() < 1e-7
    stepper = dmp.stepper(0.001)
    stepped = [stepper.orientation] + [stepper.step()[3] for _ in times[1:]]
    assert np.abs(np.array(stepped) - plan.orientations).max() < 1e-12


def test_stepper_goal_change_matches_the_plain_system():
    """A goal orientation changed mid-run (and given with the far sign) re-expresses the
    state about the new goal as documented; the plan is the plain system's."""
    rng = np.random.default_rng(2)
    dmp = random_dmp(rng)
    new_goal = random_unit(rng)
    times = np.arange(0, 2.0 + 1e-9, 0.001)
    change = 600
    key = key_rollout(dmp, times, goal_changes=[(times[change], new_goal)])
    stepper = dmp.stepper(0.001)
    stepped = [stepper.orientation]
    for k in range(1, times.size):
        if k == change + 1:
            far = -new_goal if new_goal @ stepper.orientation >= 0 else new_goal
            stepper.set_goal(orientation=far)
        stepped.append(stepper.step()[3])
    assert angle_between(np.array(stepped), key).max() < 1e-7
    assert angle_between(stepped[-1], new_goal)[0] < 1e-3


def test_angular_velocity_and_acceleration_match_the_quaternion_path(fitted):
    """omega = 2 vec(dq/dt conj(q)) and its derivative, by central differences."""
    dt = 0.001
    plan = fitted.rollout(2.0, dt)
    q = plan.orientations
    rate = (q[2:] - q[:-2]) / (2 * dt)
    omega = np.array([2 * qmul(r, qconj(p))[1:] for r, p in zip(rate, q[1:-1])])
    scale = np.abs(plan.angular_velocities).max()
    assert np.abs(omega - plan.angular_velocities[1:-1]).max() < 1e-4 * scale
    omega_rate = (plan.angular_velocities[2:] - plan.angular_velocities[:-2]) / (2 * dt)
    scale = np.abs(plan.angular_accelerations).max()
    assert np.abs(omega_rate - plan.angular_accelerations[1:-1]).max() < 1e-3 * scale
    velocity = (plan.positions[2:] - plan.positions[:-2]) / (2 * dt)
    assert np.abs(velocity - plan.velocities[1:-1]).max() < 1e-4 * np.abs(velocity).max()


# --- quaternion properties -------------------------------------------------------------


def test_norm_stays_one_over_a_long_rollout_and_stepping():
    """|q| = 1 to 1e-12 over 60 s of plan and 20 000 online steps of a strong forcing term."""
    dmp = random_dmp(np.random.default_rng(3), orientation_weights=np.full((3, 8), 30.0))
    plan = dmp.rollout(60.0, 0.001)
    assert np.abs(np.linalg.norm(plan.orientations, axis=1) - 1).max() < 1e-12
    stepper = dmp.stepper(0.001)
    worst = 0.0
    for k in range(20_000):
        if k % 5000 == 0:
            stepper.set_goal(orientation=random_unit(np.random.default_rng(k)))
        worst = max(worst, abs(np.linalg.norm(stepper.step()[3]) - 1))
    assert worst < 1e-12


def test_converges_to_the_goal_orientation(fitted, demo):
    """The default plan ends at the demonstrated goal, and at a new goal after with_goal."""
    plan = fitted.rollout()
    assert angle_between(plan.orientations[-1], demo[2][-1])[0] < 1e-4
    assert np.linalg.norm(plan.positions[-1] - demo[1][-1]) < 1e-5
    new_goal = qmul(qexp(np.array([0.2, -0.5, 0.3])), demo[2][-1])
    moved = fitted.with_goal(position=[0.5, 0.2, 0.1], orientation=new_goal).rollout()
    assert angle_between(moved.orientations[-1], new_goal)[0] < 1e-4
    assert np.linalg.norm(moved.positions[-1] - [0.5, 0.2, 0.1]) < 1e-4
    assert np.abs(moved.angular_velocities[-1]).max() < 1e-3


def test_reproduces_the_demonstration(fitted, demo):
    times, positions, orientations = demo
    plan = fitted.rollout(times[-1], times[1] - times[0])
    assert np.linalg.norm(plan.positions - positions, axis=1).max() < 1e-4  # 0.1 mm
    assert np.degrees(angle_between(plan.orientations, orientations).max()) < 0.01


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_rotating_the_demonstration_rotates_the_plan(demo, seed):
    """p -> R p + t and q -> r q on the whole demonstration give the plan rotated alike."""
    rng = np.random.default_rng(seed)
    times, positions, orientations = demo
    r, shift = random_unit(rng), rng.normal(size=3)
    rotation = rotation_matrix(r)
    moved = fit_cartesian(
        times, positions @ rotation.T + shift, [qmul(r, q) for q in orientations], n_basis=20
    )
    original = fit_cartesian(times, positions, orientations, n_basis=20)
    plan, plan_moved = original.rollout(dt=0.004), moved.rollout(dt=0.004)
    assert np.abs(plan.positions @ rotation.T + shift - plan_moved.positions).max() < 1e-9
    rotated = np.array([qmul(r, q) for q in plan.orientations])
    assert angle_between(rotated, plan_moved.orientations).max() < 1e-9
    omega = plan.angular_velocities @ rotation.T
    assert np.abs(omega - plan_moved.angular_velocities).max() < 1e-9


def test_quaternion_signs_do_not_change_the_plan(demo):
    """A demonstration with q and -q mixed gives the same plan, and a goal given as -g the
    same plan as g (no long way round)."""
    times, positions, orientations = demo
    signs = np.where(np.random.default_rng(4).random(len(times)) < 0.5, -1.0, 1.0)
    plan = fit_cartesian(times, positions, orientations, n_basis=20).rollout(dt=0.004)
    flipped = fit_cartesian(times, positions, orientations * signs[:, None], n_basis=20)
    assert np.abs(flipped.rollout(dt=0.004).orientations - plan.orientations).max() < 1e-12
    goal = qmul(qexp(np.array([0.0, 0.0, 2.5])), orientations[0])
    near = flipped.with_goal(orientation=goal).rollout(dt=0.004)
    far = flipped.with_goal(orientation=-goal).rollout(dt=0.004)
    assert np.abs(near.orientations - far.orientations).max() == 0.0
    # the short way: the angle to the goal never exceeds the start's
    start_angle = angle_between(orientations[0], goal)[0]
    assert angle_between(near.orientations, goal).max() <= start_angle + 0.3


def test_continuous_signs():
    rng = np.random.default_rng(5)
    path = np.array([qexp(np.array([0.0, 0.0, a])) for a in np.linspace(0, 5.0, 50)])
    flipped = path * np.where(rng.random(50) < 0.5, -1.0, 1.0)[:, None]
    made = continuous(flipped)
    assert np.all(np.sum(made[1:] * made[:-1], axis=1) > 0) and made[0, 0] >= 0
    assert np.allclose(np.abs(np.sum(made * path, axis=1)), 1.0)


def test_time_scaling(fitted):
    """tau -> 2 tau: the same plan on a time axis twice as long (Section 3.3)."""
    plan = fitted.rollout(2.0, 0.002)
    slow = fitted.with_tau(2 * fitted.tau).rollout(4.0, 0.004)
    assert np.abs(slow.orientations - plan.orientations).max() < 1e-12
    assert np.abs(2 * slow.angular_velocities - plan.angular_velocities).max() < 1e-10


def test_stepper_follows_rollout_and_position_goal(fitted):
    """The stepper integrates the rollout's system; set_goal(position) maps the forcing
    term as with_goal does (the start velocity, already under way, is not remapped)."""
    dt = 0.004
    moved = fitted.with_goal(position=[0.7, 0.0, 0.5])
    plan = moved.rollout(3.0, dt, start_velocity=fitted.position_dmp.start_velocity)
    stepper = fitted.stepper(dt)
    stepper.set_goal(position=[0.7, 0.0, 0.5])
    steps = [stepper.step() for _ in range(plan.times.size - 1)]
    assert np.abs(np.array([s[0] for s in steps]) - plan.positions[1:]).max() < 1e-12
    assert np.abs(np.array([s[4] for s in steps]) - plan.angular_velocities[1:]).max() < 1e-10


def test_acceleration_form_converges_after_goal_change(demo):
    dmp = fit_cartesian(*demo, n_basis=20, form="acceleration")
    goal = qmul(qexp(np.array([0.4, 0.0, -0.4])), demo[2][-1])
    stepper = dmp.stepper(0.002)
    previous = stepper.orientation
    for k in range(3000):
        if k == 400:
            stepper.set_goal(orientation=goal)
        q = stepper.step()[3]
        assert angle_between(q, previous)[0] < 0.02  # no jump at the change
        previous = q
    assert angle_between(previous, goal)[0] < 1e-3


def test_save_load_round_trip(fitted, tmp_path):
    loaded = dmpopt.load(dmpopt.save(fitted, tmp_path / "pose"))
    assert isinstance(loaded, CartesianDMP)
    for name in ("position_weights", "orientation_weights", "goal_orientation", "centres"):
        assert np.array_equal(getattr(loaded, name), getattr(fitted, name))
    assert loaded.orientation_scaling == fitted.orientation_scaling
    plan, again = fitted.rollout(dt=0.01), loaded.rollout(dt=0.01)
    assert np.array_equal(plan.orientations, again.orientations)


# --- bad inputs ------------------------------------------------------------------------


def test_bad_demonstrations_are_refused_by_name(demo):
    times, positions, orientations = demo
    bad = orientations.copy()
    bad[3] *= 1.1
    with pytest.raises(InvalidInputError, match=r"orientations\[3\] has norm 1.1.*normalise"):
        fit_cartesian(times, positions, bad)
    with pytest.raises(
        ShapeError,
        match=r"positions has shape \(301, 2\), expected \(301, 3\) \(301 3-D positions\)",
    ):
        fit_cartesian(times, positions[:, :2], orientations)
    with pytest.raises(ShapeError, match=r"orientations has shape \(301, 3\)"):
        fit_cartesian(times, positions, orientations[:, 1:])
    with pytest.raises(ShapeError, match=r"orientations has shape \(300, 4\)"):
        fit_cartesian(times, positions, orientations[1:])
    nan = orientations.copy()
    nan[7, 2] = np.nan
    with pytest.raises(InvalidInputError, match=r"orientations\[7, 2\] is nan"):
        fit_cartesian(times, positions, nan)
    nan = positions.copy()
    nan[5, 0] = np.inf
    with pytest.raises(InvalidInputError, match=r"positions\[5, 0\] is inf"):
        fit_cartesian(times, nan, orientations)
    with pytest.raises(InvalidInputError, match="times must be strictly increasing"):
        fit_cartesian(times[::-1], positions, orientations)
    turn = np.array([qexp(np.array([0.0, 0.0, a])) for a in np.linspace(0, 4.0, len(times))])
    with pytest.raises(InvalidInputError, match="orientations turn by 229.2 degrees"):
        fit_cartesian(times, positions, turn)
    with pytest.raises(InvalidInputError, match="n_basis"):
        fit_cartesian(times, positions, orientations, n_basis=0)


def test_each_part_is_fit_discretes_fit_of_its_path():
    """Answer key: a turn about z by angles a_k has the rotation vectors (0, 0, a_k - a_T)
    about the goal, written out; the position part is fit_discrete's fit of the positions and
    the orientation part fit_discrete's fit of those vectors, with fit_discrete's defaults
    (n_basis, gains) and the same goal scaling, start velocity and reference."""
    times = np.linspace(0.0, 1.0, 201)
    s = times / times[-1]
    angles = 2.5 * (10 * s**3 - 15 * s**4 + 6 * s**5) - 0.4 * np.sin(np.pi * s)
    turn = np.array([qexp(np.array([0.0, 0.0, a])) for a in angles])
    positions = np.c_[np.sin(2 * s), s**2, 0.3 * s]
    fitted = fit_cartesian(times, positions, turn)
    position = dmpopt.fit_discrete(dmpopt.Trajectory.from_positions(times, positions))
    log = np.c_[np.zeros((len(times), 2)), angles - angles[-1]]
    rotation = dmpopt.fit_discrete(dmpopt.Trajectory.from_positions(times, log))
    assert fitted.n_basis == position.n_basis
    assert (fitted.alpha_z, fitted.alpha_v) == (position.alpha_z, position.alpha_v)
    np.testing.assert_array_equal(fitted.position_weights, position.weights)
    # the rotation vectors: within 1e-15 of the key (quaternion product and logarithm rounding)
    np.testing.assert_allclose(fitted.orientation_weights, rotation.weights, rtol=1e-9, atol=1e-9)
    assert fitted.position_scaling == position.goal_scaling
    assert fitted.orientation_scaling == rotation.goal_scaling
    np.testing.assert_array_equal(fitted.scaled_start_velocity, position.scaled_start_velocity)
    np.testing.assert_allclose(
        fitted.scaled_start_log_rate, rotation.scaled_start_velocity, rtol=1e-9, atol=1e-12
    )
    # other gains reach both parts and the DMP
    gains = {"alpha_z": 30.0, "alpha_v": 12.0}
    fitted = fit_cartesian(times, positions, turn, **gains)
    position = dmpopt.fit_discrete(dmpopt.Trajectory.from_positions(times, positions), **gains)
    assert (fitted.alpha_z, fitted.alpha_v) == (30.0, 12.0)
    np.testing.assert_array_equal(fitted.position_weights, position.weights)


def test_a_demonstration_resting_at_its_goal_fits():
    """The last fifth of the samples hold the goal orientation (a rotation vector of zero
    length before the last sample): the fit is finite and the plan ends at the goal."""
    times = np.linspace(0.0, 1.0, 201)
    s = np.minimum(times / 0.8, 1.0)
    turn = np.array([qexp(np.array([0.2, -0.5, 1.0]) * (1 - (1 - a) ** 3)) for a in s])
    fitted = fit_cartesian(times, np.c_[s, s, s], turn)
    assert np.all(np.isfinite(fitted.orientation_weights))
    plan = fitted.rollout()
    assert np.degrees(angle_between(plan.orientations[-1:], turn[-1:]).max()) < 0.1


def test_a_half_turn_exactly_is_accepted():
    """Every sample at most a half turn from the goal is accepted: a turn of exactly 180
    degrees about x (its angle pi within rounding) fits, and its plan reaches the goal."""
    times = np.linspace(0.0, 1.0, 201)
    s = times / times[-1]
    turn = np.array([qexp(np.array([np.pi * (10 * a**3 - 15 * a**4 + 6 * a**5), 0, 0])) for a in s])
    plan = fit_cartesian(times, np.zeros((len(times), 3)), turn).rollout()
    assert np.degrees(angle_between(plan.orientations[-1:], turn[-1:]).max()) < 0.1


@pytest.mark.parametrize("degrees", [361.0, 540.0, 900.0])
def test_a_turn_beyond_a_half_turn_is_measured_along_the_path(demo, degrees):
    """Answer key: samples of a turn by `degrees` about one tilted axis, written with qexp;
    the refusal states the angle turned (once 361 degrees was reported as 359, and turns of
    540-900 degrees, whose ends are 180 or 0 degrees apart, were accepted)."""
    times, positions, _ = demo
    axis = np.array([0.3, 0.4, np.sqrt(0.75)])
    fractions = np.linspace(0.0, 1.0, len(times))
    turn = np.array([qexp(np.radians(degrees) * s * axis) for s in fractions])
    message = (
        f"orientations turn by {degrees:.1f} degrees along the path from the first sample to "
        "the last (the goal), more than a half turn: a Cartesian DMP turns to its goal the "
        "short way (at most 180 degrees from every sample); split the demonstration"
    )
    with pytest.raises(InvalidInputError) as error:
        fit_cartesian(times, positions, turn)
    assert str(error.value) == message


def test_an_excursion_beyond_a_half_turn_from_the_goal_is_refused(demo):
    """Out to 300 degrees and back to 60 about z: the sample at 300 is 240 from the goal,
    though the first and last samples are 60 degrees apart."""
    times, positions, _ = demo
    n = len(times)
    angles = np.r_[np.linspace(0.0, 300.0, n // 2), np.linspace(300.0, 60.0, n - n // 2)]
    turn = np.array([qexp(np.radians([0.0, 0.0, a])) for a in angles])
    with pytest.raises(
        InvalidInputError, match=rf"turn by 240.0 degrees .* orientations\[{n // 2 - 1}\]"
    ):
        fit_cartesian(times, positions, turn)
    # a smooth turn out to 171 degrees and back to 60: at most 111 from the goal, accepted
    s = np.linspace(0.0, 1.0, n)
    back = np.array([qexp(np.radians([0.0, 0.0, a])) for a in 60 * s + 140 * np.sin(np.pi * s)])
    plan = fit_cartesian(times, positions, back, n_basis=30).rollout(times[-1], times[1])
    # fit error 0.018 degrees (30 bases); a wrapped logarithm puts plans 158-176 degrees off
    assert np.degrees(angle_between(plan.orientations, back).max()) < 0.1


def test_a_cartesian_stepper_too_large_to_build_is_refused_before_building():
    """6 DOFs x 30000 bases: 30000 x (48 kB + 6 x 8 kB) = 2.68 GiB estimated for the
    symbolic step, beyond the 2 GiB budget (dmpopt.symbolic.STEP_BYTES_PER_FEATURE)."""
    dmp = random_dmp(np.random.default_rng(0), n_basis=30000)
    with pytest.raises(dmpopt.ResourceLimitError) as error:
        dmp.stepper()
    assert str(error.value).startswith(
        "the symbolic step of 6 DOFs x 30000 basis features (a stepper's) needs about "
        f"{30000 * 96e3 / 1024**3:.3g} GiB; dmpopt allows at most 2 GiB"
    )


def test_bad_fields_and_goals_are_refused_by_name(fitted):
    rng = np.random.default_rng(6)
    with pytest.raises(InvalidInputError, match=r"start_orientation has norm 2"):
        random_dmp(rng, start_orientation=[2.0, 0, 0, 0])
    with pytest.raises(ShapeError, match=r"goal_orientation has shape \(3,\), expected \(4,\)"):
        random_dmp(rng, goal_orientation=[1.0, 0, 0])
    with pytest.raises(ShapeError, match=r"orientation_weights has shape \(3, 5\), expected"):
        random_dmp(rng, orientation_weights=np.zeros((3, 5)))
    with pytest.raises(ShapeError, match=r"position_weights has shape \(2, 8\), expected \(3"):
        random_dmp(rng, position_weights=np.zeros((2, 8)))
    with pytest.raises(InvalidInputError, match="orientation_reference"):
        random_dmp(rng, orientation_scaling="rotation")
    with pytest.raises(InvalidInputError, match="orientation_scaling must be one of"):
        random_dmp(rng, orientation_scaling="spin")
    with pytest.raises(InvalidInputError, match="tau must be"):
        fitted.with_tau(-1.0)
    with pytest.raises(InvalidInputError, match=r"orientation has norm 0"):
        fitted.with_goal(orientation=[0.0, 0, 0, 0])
    with pytest.raises(InvalidInputError, match=r"orientation\[1\] is nan"):
        fitted.with_goal(orientation=[1.0, np.nan, 0, 0])
    with pytest.raises(ShapeError, match="start_angular_velocity has shape"):
        fitted.rollout(start_angular_velocity=[1.0, 2.0])
    stepper = fitted.stepper(0.002)
    with pytest.raises(InvalidInputError, match=r"orientation has norm 0.5"):
        stepper.set_goal(orientation=[0.5, 0, 0, 0])
    with pytest.raises(ShapeError, match=r"position has shape \(2,\)"):
        stepper.set_goal(position=[1.0, 2.0])
    with pytest.raises(InvalidInputError, match="dt = 100 s is beyond the stability limit"):
        fitted.stepper(100.0)
    with pytest.raises(InvalidInputError, match="dmp must be a CartesianDMP"):
        dmpopt.CartesianStepper("not a dmp")


# --- on the robot ----------------------------------------------------------------------


def test_cartesian_study_quick(tmp_path):
    """Talos stands and its hand follows the pose plan, replayed and re-aimed online."""
    from dmpopt_studies import cartesian

    metrics = cartesian.run(tmp_path, quick=True)
    assert metrics["fell"] is False and metrics["new_goal"]["fell"] is False
    assert metrics["quaternion_norm_error_max"] < 1e-12
    assert metrics["position_rmse_mm"] < 1.0 and metrics["orientation_rmse_deg"] < 0.5
    assert metrics["hand_tracking_mm"] < 1.0 and metrics["hand_tracking_deg"] < 0.5
    assert metrics["new_goal"]["hand_tracking_mm"] < 2.0
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [
        "cartesian_plan.png",
        "cartesian_tracking.png",
    ]
    assert set(metrics["captions"]) == {"cartesian_plan", "cartesian_tracking"}
    rows = metrics["summary"]
    assert all(set(row) == {"claim", "paper", "dmpopt", "anchor", "verdict"} for row in rows)
    hand = f"{metrics['hand_tracking_mm']:.2g} mm"  # the table quotes this run's numbers
    assert any(row["dmpopt"].startswith(hand) for row in rows)


def test_stepper_set_tau_scales_time(fitted):
    """set_tau(2 tau) from the start: the plan of with_tau(2 tau), sampled at twice dt."""
    slow = fitted.with_tau(2 * fitted.tau).rollout(4.0, 0.004)
    stepper = fitted.stepper(0.004)
    stepper.set_tau(2 * fitted.tau)
    stepped = [stepper.step()[3] for _ in range(slow.times.size - 1)]
    assert np.abs(np.array(stepped) - slow.orientations[1:]).max() < 1e-12
    with pytest.raises(InvalidInputError, match="tau must be a finite number > 0"):
        stepper.set_tau(np.nan)
    with pytest.raises(InvalidInputError, match="beyond the stability limit"):
        stepper.set_tau(1e-4)


def test_compiled_stepper_gives_the_same_plan(fitted):
    compiled, plain = fitted.stepper(0.004, compile=True), fitted.stepper(0.004)
    for k in range(300):
        if k == 100:
            for stepper in (compiled, plain):
                stepper.set_goal([0.5, 0.0, 0.4], [1.0, 0.0, 0.0, 0.0])
        first, second = compiled.step(), plain.step()
    assert all(np.allclose(a, b, rtol=0, atol=1e-12) for a, b in zip(first, second))


@pytest.mark.parametrize("angle", [1e-9, 1e-4, 0.5, np.pi, 6.0, 2 * np.pi - 1e-3, 2 * np.pi - 1e-4])
def test_log_of_every_angle(angle):
    """e = 2 log(q conj(g)) is the rotation vector, from near zero to near a full turn (the
    long way round, w < 0), against the plain formula; at a full turn it is refused."""
    from dmpopt.cartesian import orientation_log

    rng = np.random.default_rng(7)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    goal = random_unit(rng)
    q = qmul(np.r_[np.cos(angle / 2), np.sin(angle / 2) * axis], goal)
    assert np.allclose(orientation_log(q, goal), angle * axis, rtol=1e-9, atol=1e-12)
    assert np.allclose(qlog(qmul(q, qconj(goal))), angle * axis, rtol=1e-9, atol=1e-12)
    with pytest.raises(InvalidInputError, match=r"start\[0\] is a full turn"):
        orientation_log(-goal, goal, "start")
