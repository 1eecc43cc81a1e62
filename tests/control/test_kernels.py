"""The compiled kernels of the controller tick against plain NumPy linear algebra."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.control import kernels


def _spd(rng, n: int) -> np.ndarray:
    a = rng.normal(size=(n, n))
    return a @ a.T + 0.1 * np.eye(n)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 40), n_rows=st.integers(0, 20), seed=st.integers(0, 2**16))
def test_solve_in_place_solves_kkt_systems(n, n_rows, seed):
    """A KKT matrix [[H, E^T], [E, 0]] (indefinite: pivoting needed) is solved as by NumPy;
    a singular one (a repeated row of E) is refused."""
    rng = np.random.default_rng(seed)
    n_rows = min(n_rows, n)
    rows = rng.normal(size=(n_rows, n))
    kkt = np.block([[_spd(rng, n), rows.T], [rows, np.zeros((n_rows, n_rows))]])
    rhs = rng.normal(size=n + n_rows)
    expected = np.linalg.solve(kkt, rhs)
    solution, matrix = rhs.copy(), kkt.copy()
    assert kernels.solve_in_place(matrix, solution)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(solution, expected, atol=1e-9 * np.linalg.cond(kkt) * scale)
    if n_rows >= 2:
        kkt[-1, :] = kkt[n, :]  # the last constraint row repeats the first
        kkt[:, -1] = kkt[:, n]
        assert not kernels.solve_in_place(kkt, rhs.copy())


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 40), seed=st.integers(0, 2**16))
def test_cholesky_solve_matches_numpy(n, seed):
    rng = np.random.default_rng(seed)
    matrix, rhs = _spd(rng, n), rng.normal(size=n)
    kept, factor, solution = matrix.copy(), np.zeros((n, n)), np.zeros(n)
    assert kernels.cholesky_solve(matrix, factor, rhs, solution)
    expected = -np.linalg.solve(matrix, rhs)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(
        solution, expected, rtol=0, atol=1e-9 * np.linalg.cond(matrix) * scale
    )
    np.testing.assert_array_equal(matrix, kept)  # the matrix is kept, the factor separate
    np.testing.assert_allclose(np.tril(factor) @ np.tril(factor).T, matrix, atol=1e-10 * n)


def test_cholesky_solve_rejects_indefinite_and_nan():
    factor, solution = np.zeros((2, 2)), np.zeros(2)
    assert not kernels.cholesky_solve(np.diag([1.0, -1.0]), factor, np.ones(2), solution)
    assert not kernels.cholesky_solve(np.eye(2), factor, np.array([1.0, np.nan]), solution)
    assert not kernels.cholesky_solve(np.diag([np.nan, 1.0]), factor, np.ones(2), solution)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16))
def test_eliminate_solves_the_basic_block(seed):
    """Rows [G | t] below n_cost cost rows; G_B^-1 [G_N | t] with the base-dynamics rows."""
    rng = np.random.default_rng(seed)
    nv, n_base, n_force, n_cost = 9, 2, 3, 4
    n_x = nv + n_force
    rows = rng.normal(size=(n_cost + n_force + n_base, n_x + 1))
    mass, bias, scale = _spd(rng, nv), rng.normal(size=nv), 7.0
    basic = np.array([0, 1, 3, 5, 8])
    nonbasic = np.append(np.setdiff1d(np.arange(n_x), basic), n_x)
    lu, elimination = np.zeros((5, 5)), np.zeros((5, nonbasic.size))
    assert kernels.eliminate(
        kernels.Rows(rows, 0, n_cost, nv, n_base),
        kernels.Dynamics(np.asfortranarray(mass), bias, scale),
        kernels.Split(basic, nonbasic, lu, elimination, 1e-12),
    )
    dynamics = rows[n_cost + n_force :]
    np.testing.assert_array_equal(dynamics[:, :nv], mass[:n_base])
    np.testing.assert_array_equal(
        dynamics[:, nv:n_x], -scale * rows[n_cost : n_cost + n_force, :n_base].T
    )
    np.testing.assert_array_equal(dynamics[:, n_x], -bias[:n_base])
    constraints = rows[n_cost:]
    expected = np.linalg.solve(constraints[:, basic], constraints[:, nonbasic])
    np.testing.assert_allclose(elimination, expected, atol=1e-9 * np.abs(expected).max())


def test_eliminate_refuses_a_singular_basic_block():
    rows = np.zeros((3, 4))
    rows[1] = [1.0, 2.0, 0.0, 1.0]
    rows[2] = [2.0, 4.0, 1.0, 0.0]  # basic columns 0, 1 proportional
    ok = kernels.eliminate(
        kernels.Rows(rows, 0, 1, 3, 0),
        kernels.Dynamics(np.eye(3, order="F"), np.zeros(3), 1.0),
        kernels.Split(np.array([0, 1]), np.array([2, 3]), np.zeros((2, 2)), np.zeros((2, 2)), 1e-9),
    )
    assert not ok


def test_posture_gradient_sums_overlapping_tasks():
    """Two tasks on the same joint: -w1 qdd1* - w2 qdd2* at that joint, zero elsewhere."""
    state = np.zeros((7, 2))
    state[0] = [0.3, 0.1]  # reference positions
    state[3] = [4.0, 9.0]  # stiffness
    q, v = np.array([0.0, 0.2]), np.zeros(3)
    gradient = np.full(4, np.nan)
    stack = kernels.PostureStack(
        state, np.array([1, 1]), np.array([2, 2]), np.array([1.0, 3.0]), gradient
    )
    kernels.posture_gradient(stack, q, v)
    np.testing.assert_allclose(state[6], [0.1, -0.1])  # errors
    np.testing.assert_allclose(state[5], [0.4, -0.9])  # targets Kp e
    np.testing.assert_allclose(gradient, [0.0, 0.0, -(1.0 * 0.4 + 3.0 * -0.9), 0.0])


@pytest.mark.parametrize("n_task", [0, 3])
def test_joint_space_accelerations_minimise_the_cost(n_task):
    """D + J^T W J solved by Woodbury equals the dense solve."""
    rng = np.random.default_rng(n_task)
    nv = 7
    rows = rng.normal(size=(n_task, nv + 1))
    weights = rng.uniform(0.5, 2.0, size=n_task)
    state = np.zeros((7, nv))
    state[0], state[3] = rng.normal(size=nv), 10.0
    posture_weights = rng.uniform(0.5, 2.0, size=nv)
    gradient = np.zeros(nv)
    diagonal = posture_weights + 1e-6
    posture = kernels.PostureStack(state, np.arange(nv), np.arange(nv), posture_weights, gradient)
    woodbury = kernels.Woodbury(
        1.0 / diagonal, weights, np.zeros((n_task, nv)), np.zeros((n_task, n_task)),
        np.zeros((n_task, n_task)), np.zeros(n_task),
    )  # fmt: skip
    q, v, x = np.zeros(nv), rng.normal(size=nv), np.zeros(nv)
    layout = kernels.Rows(rows, n_task, n_task, nv, 0)
    assert kernels.joint_space_accelerations(posture, layout, woodbury, q, v, x)
    jacobian, target = rows[:, :nv], rows[:, nv]
    hessian = np.diag(diagonal) + jacobian.T @ (weights[:, None] * jacobian)
    expected = np.linalg.solve(hessian, jacobian.T @ (weights * target) - gradient)
    np.testing.assert_allclose(x, expected, atol=1e-12)
