"""The parts of a rollout's response matrices (dmpopt.symbolic): CasADi expressions evaluated
on arrays, the transformation system as matrices, the canonical step and its stages."""

import casadi as ca
import numpy as np
import problems
import pytest

from dmpopt import symbolic
from dmpopt.basis import discrete_basis, rhythmic_basis

EPS = np.finfo(float).eps
DISCRETE_GAINS = list(problems.DISCRETE_GAINS)
CASES = problems.FORMS_AND_KERNELS


def _problem(form, kernel, n_points=300, seed=0):
    """Centres, widths, target, gains and random canonical states of a 7-basis system."""
    rng = np.random.default_rng(seed)
    if form in ("velocity", "acceleration"):
        centres, widths = discrete_basis(7, tuple(DISCRETE_GAINS))
        gains = np.array(DISCRETE_GAINS + [12.5] * (form == "acceleration"))
        points = np.vstack([rng.uniform(-0.1, 1.1, n_points), rng.uniform(-1.0, 3.0, n_points)])
    else:
        centres, widths = rhythmic_basis(7, kernel)
        gains = np.array([25.0, 6.25, 10.0] + [2.0] * (form == "energy"))
        points = np.vstack([rng.uniform(-10, 10, n_points), rng.uniform(-2.0, 2.0, n_points)])
    return centres, widths, 1.3, gains, points


@pytest.mark.parametrize("form, kernel", CASES)
def test_array_function_equals_casadi_for_every_form_and_kernel(form, kernel):
    """The features and their rates evaluated on arrays equal CasADi's own evaluation, point by
    point: +, -, *, / round alike, and numpy's and the C library's exp, cos, sin, atan2 are each
    within 1 ulp, so the at most ~40 operations behind a value differ by < 100 eps of it."""
    centres, widths, target, gains, points = _problem(form, kernel)
    signature = symbolic.Signature(form, 1, 7, kernel)
    for function, shared in (
        (symbolic.feature_function(signature), (centres, widths)),
        (symbolic.feature_rate_function(signature), (centres, widths, target, gains)),
    ):
        arrays = symbolic.array_function(function)(points, *shared, n_points=points.shape[1])
        casadi = function.map(points.shape[1])(points, *shared)
        for got, expected in zip(arrays, [casadi] if function.n_out() == 1 else casadi):
            expected = expected.full().T
            scale = np.abs(expected).max()
            np.testing.assert_allclose(got, expected, rtol=0, atol=100 * EPS * scale)


def test_array_function_in_chunks_equals_one_pass(monkeypatch):
    """Points evaluated in chunks (here of 64: 150 points in three) give the same numbers as
    all at once: the same operations on the same numbers."""
    centres, widths, target, gains, points = _problem("phase", "von_mises", n_points=150)
    function = symbolic.array_function(
        symbolic.feature_rate_function(symbolic.Signature("phase", 1, 7, "von_mises"))
    )
    whole = function(points, centres, widths, target, gains, n_points=150)
    monkeypatch.setattr(symbolic.ArrayFunction, "work_size", 1)  # chunks of the minimum, 64
    chunked = function(points, centres, widths, target, gains, n_points=150)
    for got, expected in zip(chunked, whole):
        np.testing.assert_array_equal(got, expected)


def test_array_function_names_an_operation_it_cannot_evaluate():
    x = ca.SX.sym("x")
    with pytest.raises(NotImplementedError, match="^erf: CasADi operation 33 has no numpy"):
        symbolic.ArrayFunction(ca.Function("erf", [x], [ca.erf(x)]))


def _plain_rates(form, state, goal, forcing, alpha_z, beta_z, alpha_g):
    """Eq. (5) (``velocity``, ``phase``, ``energy``) or eq. (10) (``acceleration``), tau = 1."""
    if form == "acceleration":
        y, z, r = state
        return np.array([z, alpha_z * (beta_z * (r - y) - z) + forcing, alpha_g * (goal - r)])
    y, z = state
    return np.array([z + forcing, alpha_z * (beta_z * (goal - y) - z)])


@pytest.mark.parametrize("form", ["velocity", "acceleration", "phase", "energy"])
def test_transformation_matrices_are_the_plain_rk4_step_and_outputs(form):
    """S s + S_g g + S_f (f_1..f_4) is the classical RK4 step of eq. (5) or (10) written out
    with the forcing term f_j at stage j, and O s + O_g g + O_f (f, fdot) are y, ydot and yddot
    (the time derivative of ydot with f changing at fdot); a few roundings apart."""
    rng = np.random.default_rng(3)
    gains = {"velocity": [20.0, 5.0, 25.0, 6.25], "acceleration": [20.0, 5.0, 25.0, 6.25, 9.0]}
    gains = np.array(gains.get(form, [20.0, 5.0, 10.0] + [2.0] * (form == "energy")))
    alpha_z, beta_z = gains[:2]
    alpha_g = gains[4] if form == "acceleration" else 0.0
    n = 3 if form == "acceleration" else 2
    dt, goal = 0.01, rng.normal()
    state, stage_forcing, forcing = rng.normal(size=n), rng.normal(size=4), rng.normal(size=2)
    matrices = symbolic.transformation_matrices(form)(dt=dt, gains=gains)
    matrices = {name: value.full() for name, value in matrices.items()}

    def rate(x, f):
        return _plain_rates(form, x, goal, f, alpha_z, beta_z, alpha_g)

    k1 = rate(state, stage_forcing[0])
    k2 = rate(state + dt / 2 * k1, stage_forcing[1])
    k3 = rate(state + dt / 2 * k2, stage_forcing[2])
    k4 = rate(state + dt * k3, stage_forcing[3])
    expected = state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    got = matrices["step"] @ state + matrices["step_goal"][:, 0] * goal
    got += matrices["step_forcing"] @ stage_forcing
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-13 * np.abs(expected).max())

    now = rate(state, forcing[0])
    if form == "acceleration":  # ydot = z, yddot = zdot
        velocity, acceleration = state[1], now[1]
    else:  # ydot = z + f, yddot = zdot + fdot
        velocity, acceleration = now[0], now[1] + forcing[1]
    expected = np.array([state[0], velocity, acceleration])
    got = matrices["output"] @ state + matrices["output_goal"][:, 0] * goal
    got += matrices["output_forcing"] @ forcing
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-13 * np.abs(expected).max())


def _plain_canonical_rate(form, x, target, gains):
    """Eqs. (6) (normalised), (11) and (13) uncoupled, tau = 1."""
    if form in ("velocity", "acceleration"):  # xdot = v, vdot = alpha_v (beta_v (1 - x) - v)
        return np.array([x[1], gains[2] * (gains[3] * (1 - x[0]) - x[1])])
    if form == "phase":  # phidot = 1, rdot = alpha_r (A - r)
        return np.array([1.0, gains[2] * (target - x[1])])
    energy = 0.5 * (x[1] ** 2 + gains[3] ** 2 * x[0] ** 2)  # xdot = v, vdot = ...
    return np.array([x[1], -gains[2] * (energy - target) * x[1] - gains[3] ** 2 * x[0]])


@pytest.mark.parametrize("form", ["velocity", "acceleration", "phase", "energy"])
def test_canonical_step_and_its_stages_are_plain_rk4(form):
    """The canonical step and the four states at which it evaluates its rate (the states at
    which the whole step evaluates the features) are RK4 written out; a few roundings."""
    rng = np.random.default_rng(4)
    gains = {"velocity": DISCRETE_GAINS, "acceleration": DISCRETE_GAINS + [12.5]}
    gains = np.array(gains.get(form, [25.0, 6.25, 10.0] + [2.0] * (form == "energy")))
    target, dt = 1.3, 0.01
    function = symbolic.canonical_step_function(symbolic.Signature(form, 1, 3, "gaussian"))
    for state in rng.normal(size=(5, 2)):
        k1 = _plain_canonical_rate(form, state, target, gains)
        second = state + dt / 2 * k1
        k2 = _plain_canonical_rate(form, second, target, gains)
        third = state + dt / 2 * k2
        k3 = _plain_canonical_rate(form, third, target, gains)
        fourth = state + dt * k3
        k4 = _plain_canonical_rate(form, fourth, target, gains)
        following = state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        got = function(canonical=state, dt=dt, canonical_target=target, gains=gains)
        np.testing.assert_allclose(got["next_canonical"].full()[:, 0], following, atol=1e-13)
        stages = np.column_stack([state, second, third, fourth])
        np.testing.assert_allclose(got["stages"].full(), stages, rtol=0, atol=1e-13)


def test_canonical_trajectory_in_blocks_equals_step_by_step():
    """The trajectory taken 256 steps per call (over three calls, the last past the end)
    equals the canonical step called once per step, bit for bit."""
    signature = symbolic.Signature("energy", 1, 3, "von_mises")
    gains, n_steps, dt, start = np.array([25.0, 6.25, 10.0, 2.0]), 600, 0.003, (0.4, -0.2)
    samples, stages = symbolic.canonical_trajectory(signature, n_steps, dt, start, 1.3, gains)
    step = symbolic.canonical_step_function(signature)
    state = np.array(start)
    for k in range(n_steps - 1):
        np.testing.assert_array_equal(samples[:, k], state)
        got = step(canonical=state, dt=dt, canonical_target=1.3, gains=gains)
        np.testing.assert_array_equal(stages[:, :, k], got["stages"].full().T)
        state = got["next_canonical"].full()[:, 0]
    np.testing.assert_array_equal(samples[:, -1], state)


@pytest.mark.parametrize("n_steps", [1, 2, 3, 17, 101])
def test_linear_states_in_blocks_equal_the_plain_recurrence(n_steps):
    """x_{k+1} = A x_k + u_k for several columns, in blocks of about sqrt(n_steps) (17 steps:
    4 blocks of 4 with 3 of padding), equals the recurrence stepped plainly: both sum the same
    products in another order, within n_steps x 4 eps of the largest state (A is stable)."""
    rng = np.random.default_rng(5)
    step = np.array([[0.9, 0.2], [-0.3, 0.8]])
    first, inputs = rng.normal(size=(2, 3)), rng.normal(size=(n_steps - 1, 2, 3))
    expected = [first]
    for u in inputs:
        expected.append(step @ expected[-1] + u)
    expected = np.array(expected).transpose(1, 0, 2)
    length, padded = symbolic.linear_blocks(n_steps)
    assert padded >= n_steps and padded % length == 0
    states = np.zeros((2, padded, 3))
    states[:, : n_steps - 1] = inputs.transpose(1, 0, 2)
    got = symbolic.linear_states(step, first, states, length)[:, :n_steps]
    bound = 4 * n_steps * EPS * np.abs(expected).max()
    np.testing.assert_allclose(got, expected, rtol=0, atol=bound)


def test_the_numba_source_writes_infinite_and_nan_constants_by_name():
    """Constants inf, -inf and nan (not finite, so not written by repr) give the values CasADi
    gives, when the generated source runs as plain Python."""
    import math

    x = ca.SX.sym("x")
    function = ca.Function("f", [x], [ca.vertcat(x + math.inf, x * -math.inf, x + math.nan, 2 * x)])
    namespace = {"math": math, "np": np}
    exec(symbolic.numba_source(function, "f"), namespace)
    got = namespace["f"](1.5)
    expected = function(1.5).full().ravel()
    assert got[:2] == (math.inf, -math.inf) and tuple(expected[:2]) == got[:2]
    assert math.isnan(got[2]) and math.isnan(expected[2]) and got[3] == expected[3] == 3.0


def test_the_array_function_is_casadis_function_at_every_point():
    """ArrayFunction against CasADi's own evaluation point by point, over 300 points in chunks
    of 100 (a work size of 100 sz_w + 1): an if_else (CasADi's if-else-zero), products and a
    square root of a shared scalar input (evaluated on floats), exp and sin on the arrays.
    Tolerance: numpy's exp and sin may differ from the C library's by an ulp (class
    docstring), so 4 eps relative to each output's size."""
    x, y, c = ca.SX.sym("x"), ca.SX.sym("y", 2), ca.SX.sym("c")
    outputs = ca.vertcat(
        ca.if_else(x > 0, ca.sin(x) * y[0], 0), c * c + 2 * c, ca.exp(-x * x) * y[1], ca.sqrt(c) * x
    )
    function = ca.Function("f", [x, y, c], [outputs])
    array = symbolic.ArrayFunction(function)
    array.work_size = 100 * function.sz_w() + 1
    rng = np.random.default_rng(5)
    xs, ys, shared = np.linspace(-2.0, 2.0, 300), rng.normal(size=(2, 300)), 0.7
    (got,) = array(xs[None], ys, [shared], n_points=300)
    expected = np.array([function(xs[k], ys[:, k], shared).full().ravel() for k in range(300)])
    assert not np.any(got[xs <= 0, 0]) and np.all(got[:, 1] == 0.7 * 0.7 + 2 * 0.7)
    scale = np.abs(expected).max(axis=0)
    assert np.all(np.abs(got - expected) <= 4 * np.finfo(float).eps * scale)
