"""The compiled kernels of the controller tick against plain NumPy linear algebra."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
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


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16))
def test_eliminated_torque_rows_give_the_torques_and_bounds_over_z(seed):
    """With x_N = z, x_B = U_c - U_N z, the rows over z reproduce tau = M_a qdd + h_a -
    s J_ca^T f and the bounded joints' accelerations, each side moved by the constant."""
    rng = np.random.default_rng(seed)
    nv, n_base, n_force, n_cost = 9, 2, 3, 4
    n_x, n_act = nv + n_force, nv - n_base
    rows = rng.normal(size=(n_cost + n_force + n_base, n_x + 1))
    mass, bias, scale = _spd(rng, nv), rng.normal(size=nv), 7.0
    basic = np.array([0, 1, 3, 5, 8])
    nonbasic = np.append(np.setdiff1d(np.arange(n_x), basic), n_x)
    n_z = nonbasic.size - 1
    elimination = rng.normal(size=(basic.size, n_z + 1))  # [U_N | U_c]
    v_index = np.array([3, 4, 6])  # basic, nonbasic, nonbasic with no lower bound
    lower, upper = np.array([-1.0, -2.0, -np.inf]), np.array([1.0, 2.0, 3.0])
    bounds = kernels.JointBounds(
        np.zeros(3, int), v_index, lower, upper, np.ones(3), 0.1, lower, upper
    )
    limit, cone_upper = rng.uniform(1, 2, size=n_act), rng.normal(size=2)
    n_in = n_act + v_index.size + cone_upper.size
    in_matrix, in_lower, in_upper = np.zeros((n_in, n_z)), np.zeros(n_in), np.zeros(n_in)
    kernels.eliminated_torque_rows(
        kernels.Rows(rows, 0, n_cost, nv, n_base),
        kernels.Dynamics(np.asfortranarray(mass), bias, scale),
        kernels.Split(basic, nonbasic, np.zeros((5, 5)), elimination, 1e-12),
        limit, bounds, np.zeros((n_act, n_z + 1)), in_matrix, in_lower, in_upper, cone_upper,
    )  # fmt: skip
    z = rng.normal(size=n_z)
    x = np.zeros(n_x)
    x[nonbasic[:-1]] = z
    x[basic] = elimination[:, -1] - elimination[:, :-1] @ z
    contact = rows[n_cost : n_cost + n_force, :nv]
    tau = mass[n_base:] @ x[:nv] + bias[n_base:] - scale * contact[:, n_base:].T @ x[nv:]
    # sums of ~30 products of O(10) terms: rounding below 30 * eps * 100 ~ 1e-12
    values = in_matrix @ z
    np.testing.assert_allclose(values[:n_act] + limit - in_upper[:n_act], tau, atol=1e-11)
    np.testing.assert_allclose(values[:n_act] - limit - in_lower[:n_act], tau, atol=1e-11)
    bound_rows = slice(n_act, n_act + 3)
    np.testing.assert_allclose(values[bound_rows] - in_upper[bound_rows], x[v_index] - upper,
                               atol=1e-11)  # fmt: skip
    np.testing.assert_allclose(values[n_act : n_act + 2] - in_lower[n_act : n_act + 2],
                               x[v_index[:2]] - lower[:2], atol=1e-11)  # fmt: skip
    assert in_lower[n_act + 2] == -1e20  # a missing bound stays missing
    np.testing.assert_array_equal(in_upper[n_act + 3 :], cone_upper)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16), n_base=st.sampled_from([0, 2, 6]))
def test_expand_and_torques_follow_the_equations_of_motion(seed, n_base):
    """x_N = z, x_B = U_c - U_N z (expand), then the wrenches scaled by s and
    tau = M_a qdd + h_a - s J_ca^T f (torques), written out with NumPy; 5 basic unknowns and
    7 to 11 torques: the kernels' blocks of four rows and their remainders."""
    rng = np.random.default_rng(seed)
    nv, n_force, n_cost = 13, 3, 4
    n_x = nv + n_force
    rows = rng.normal(size=(n_cost + n_force + n_base, n_x + 1))
    mass, bias, scale = _spd(rng, nv), rng.normal(size=nv), 7.0
    basic = np.array([0, 1, 3, 5, 8])
    nonbasic = np.append(np.setdiff1d(np.arange(n_x), basic), n_x)
    elimination = rng.normal(size=(basic.size, nonbasic.size))  # [U_N | U_c]
    z = rng.normal(size=nonbasic.size - 1)
    x, tau = np.zeros(n_x), np.zeros(nv - n_base)
    kernels.expand(kernels.Split(basic, nonbasic, np.zeros((5, 5)), elimination, 1e-12), z, x)
    expected = np.zeros(n_x)
    expected[nonbasic[:-1]] = z
    expected[basic] = elimination[:, -1] - elimination[:, :-1] @ z
    # sums of ~15 products of O(1) terms: rounding below 15 * eps * 10 ~ 1e-13
    np.testing.assert_allclose(x, expected, rtol=0, atol=1e-12)
    kernels.torques(
        kernels.Rows(rows, 0, n_cost, nv, n_base),
        kernels.Dynamics(np.asfortranarray(mass), bias, scale), x, tau,
    )  # fmt: skip
    contact = rows[n_cost : n_cost + n_force, :nv]
    forces = scale * expected[nv:]
    np.testing.assert_allclose(x[nv:], forces, rtol=1e-15)  # unscaled in place
    expected_tau = mass[n_base:] @ expected[:nv] + bias[n_base:] - contact[:, n_base:].T @ forces
    # ~16 products of O(10 * 7) terms: rounding below 16 * eps * 1e3 ~ 4e-12
    np.testing.assert_allclose(tau, expected_tau, rtol=0, atol=1e-10)


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


def _ill_conditioned_spd(rng, n: int, condition: float) -> np.ndarray:
    basis, _ = np.linalg.qr(rng.normal(size=(n, n)))
    return (basis * np.logspace(0, np.log10(condition), n)) @ basis.T


@settings(max_examples=30, deadline=None)
@given(n=st.integers(2, 40), n_eq=st.integers(0, 6), n_in=st.integers(0, 20),
       seed=st.integers(0, 2**16))  # fmt: skip
def test_active_set_kkt_solve_has_a_backward_stable_residual(n, n_eq, n_in, seed):
    """A QP built around a chosen optimum: x*, multipliers nu > 0 on upper-bound rows at
    their bound (all active) and any on equality rows, g = -H x* - E^T nu, H of condition
    1e7 (as Talos's QPs). From that active set the certificate takes one KKT solve (the
    Cholesky-Schur path with iterative refinement) and its KKT residuals are those of a
    backward-stable solve, |H x + E^T nu + g| and |E x - e| <= 1e-12 of the terms' size; x is
    x* to eps * cond(KKT). (The refinement itself is needed for Talos's QPs at tolerance
    1e-10: without it test_solution_satisfies_equations_of_motion cycles between active sets
    and holds.)"""
    from dmpopt.control.qp_stages import _active_set

    rng = np.random.default_rng(seed)
    n_eq, n_in = min(n_eq, n), min(n_in, n - min(n_eq, n))
    hessian = _ill_conditioned_spd(rng, n, 1e7)
    eq_matrix, in_matrix = rng.normal(size=(n_eq, n)), rng.normal(size=(n_in, n))
    optimum = rng.normal(size=n)
    y, z = rng.normal(size=n_eq), rng.uniform(0.5, 2.0, size=n_in)
    gradient = -hessian @ optimum - eq_matrix.T @ y - in_matrix.T @ z
    upper = in_matrix @ optimum
    problem = (hessian, gradient, eq_matrix, eq_matrix @ optimum, in_matrix,
               np.full(n_in, -1e20), upper)  # fmt: skip
    at_upper, at_lower = np.ones(n_in, bool), np.zeros(n_in, bool)
    duals = (np.zeros(n_eq), np.zeros(n_in))
    x, solves = _active_set(problem, at_upper, at_lower, 1e-9, 3, duals)
    assert solves == 1 and x is not None
    rows = np.vstack([eq_matrix, in_matrix])
    nu = np.concatenate(duals)
    size = np.abs(hessian) @ np.abs(x) + np.abs(rows.T) @ np.abs(nu) + np.abs(gradient)
    assert np.all(np.abs(hessian @ x + rows.T @ nu + gradient) <= 1e-12 * size.max())
    targets = np.r_[problem[3], upper]
    scale = (np.abs(rows) @ np.abs(x)).max(initial=0.0)
    assert np.all(np.abs(rows @ x - targets) <= 1e-12 * scale)
    kkt = np.block([[hessian, rows.T], [rows, np.zeros((len(rows), len(rows)))]])
    bound = 1e-15 * np.linalg.cond(kkt) * max(1.0, np.abs(optimum).max())
    np.testing.assert_allclose(x, optimum, rtol=0, atol=max(bound, 1e-13))


@settings(max_examples=20, deadline=None)
@given(n=st.integers(2, 30), n_eq=st.integers(0, 6), n_in=st.integers(1, 12),
       seed=st.integers(0, 2**16))  # fmt: skip
def test_a_stages_workspace_solves_views_and_rows_with_leading_zeros(n, n_eq, n_in, seed):
    """A stage's ActiveSetWorkspace (made once, its kernel bound to the arrays' types) on the
    problem as a stage holds it: equality rows a strided view of a wider array, active rows
    that start with zeros (joint-bound rows e_j, cone rows on the wrench columns only). The
    answer key is the chosen optimum x* (as in the test above): the KKT residuals of a
    backward-stable solve and x* to eps * cond(KKT); refilling the arrays in place and
    solving again reads the new values."""
    from dmpopt.control.qp_stages import ActiveSetWorkspace, _active_set

    rng = np.random.default_rng(seed)
    n_eq, n_in = min(n_eq, n - 1), min(n_in, n - min(n_eq, n - 1))
    hessian = _ill_conditioned_spd(rng, n, 1e7)
    wide = np.zeros((n_eq, n + 3))
    eq_matrix, eq_vector = wide[:, :n], wide[:, n]  # views, as a stage's contact rows
    in_matrix = rng.normal(size=(n_in, n))
    starts = np.sort(rng.choice(n, size=n_in, replace=False))  # distinct: independent rows
    for row, start in zip(in_matrix, starts):
        row[:start] = 0.0
    gradient, upper = np.zeros(n), np.zeros(n_in)
    problem = (hessian, gradient, eq_matrix, eq_vector, in_matrix, np.full(n_in, -1e20), upper)
    workspace = ActiveSetWorkspace(problem)
    for _ in range(2):  # the arrays refilled in place between solves
        eq_matrix[:] = rng.normal(size=(n_eq, n))
        optimum = rng.normal(size=n)
        y, z = rng.normal(size=n_eq), rng.uniform(0.5, 2.0, size=n_in)
        gradient[:] = -hessian @ optimum - eq_matrix.T @ y - in_matrix.T @ z
        upper[:] = in_matrix @ optimum
        eq_vector[:] = eq_matrix @ optimum
        rows = np.vstack([eq_matrix, in_matrix])
        kkt = np.block([[hessian, rows.T], [rows, np.zeros((len(rows), len(rows)))]])
        # A backward-stable solve's multipliers are within ~eps cond(KKT) |(x, nu)| of the
        # chosen ones (>= 0.5): nearer-dependent rows (random rows with few nonzeros can
        # reach cond 1e14 here) may rightly lose their sign, and the set its certificate.
        size = max(np.abs(optimum).max(), np.abs(z).max(), np.abs(y).max(initial=0.0))
        assume(1e-15 * np.linalg.cond(kkt) * size < 0.5)
        at_upper, at_lower = np.ones(n_in, bool), np.zeros(n_in, bool)
        x, solves = _active_set(
            problem, at_upper, at_lower, 1e-9, 3, workspace.duals, workspace
        )  # fmt: skip
        assert solves == 1 and x is not None
        nu = np.concatenate(workspace.duals)
        size = np.abs(hessian) @ np.abs(x) + np.abs(rows.T) @ np.abs(nu) + np.abs(gradient)
        assert np.all(np.abs(hessian @ x + rows.T @ nu + gradient) <= 1e-12 * size.max())
        scale = (np.abs(rows) @ np.abs(x)).max(initial=0.0)
        assert np.all(np.abs(rows @ x - np.r_[eq_vector, upper]) <= 1e-12 * scale)
        bound = 1e-15 * np.linalg.cond(kkt) * max(1.0, np.abs(optimum).max())
        np.testing.assert_allclose(x, optimum, rtol=0, atol=max(bound, 1e-13))


def test_workspaces_of_strided_and_contiguous_equality_rows_share_one_compiled_code():
    """A stage's equality rows are a strided view in some QPs, arrays of their own in others
    (or absent): every workspace binds the same compiled code (numba compiles a kernel anew
    for each memory layout, ~20 CPU-s for the active-set iterations), and each solves its
    own problem: x* = -H^-1 (g + A^T y) with A x* = b, written here with NumPy."""
    from dmpopt.control.qp_stages import ActiveSetWorkspace, _active_set

    rng = np.random.default_rng(5)
    n, n_eq = 6, 2
    hessian, gradient = _spd(rng, n), rng.normal(size=n)
    wide = rng.normal(size=(n_eq, n + 1))
    bound = (np.zeros((1, n)), np.full(1, -1e20), np.full(1, 1e20))  # an inactive row
    problems = [
        (hessian, gradient, wide[:, :n], wide[:, n], *bound),  # strided view
        (hessian, gradient, wide[:, :n].copy(), wide[:, n].copy(), *bound),  # contiguous
        (hessian, gradient, None, None, *bound),  # none
    ]
    codes = set()
    for problem in problems:
        workspace = ActiveSetWorkspace(problem)
        codes.add(id(workspace._code))
        x, _ = _active_set(problem, np.zeros(1, bool), np.zeros(1, bool), 1e-9, 3,
                           workspace.duals, workspace)  # fmt: skip
        if problem[2] is None:
            kkt, rhs = hessian, -gradient
        else:
            a, b = problem[2], problem[3]
            kkt = np.block([[hessian, a.T], [a, np.zeros((n_eq, n_eq))]])
            rhs = np.r_[-gradient, b]
        solution = np.linalg.solve(kkt, rhs)
        # two backward-stable solves differ by at most ~eps cond(KKT) |solution| each
        bound = 2 * len(rhs) * 2.3e-16 * np.linalg.cond(kkt) * np.abs(solution).max()
        np.testing.assert_allclose(x, solution[:n], rtol=0, atol=bound)
    assert len(codes) == 1


def test_active_set_solves_dependent_active_rows():
    """Equality rows that are all zero (a fixed base's contact rows) and an active row that
    repeats another make the KKT matrix singular: the certificate still holds, with x the
    optimum of the independent rows (NumPy on the reduced KKT system)."""
    from dmpopt.control.qp_stages import _active_set

    rng = np.random.default_rng(3)
    n = 8
    hessian, gradient = _spd(rng, n), rng.normal(size=n)
    eq_matrix = np.zeros((3, n))
    row = rng.normal(size=n)
    in_matrix = np.vstack([row, row])  # the same row twice, both at their upper bound
    x_free = np.linalg.solve(hessian, -gradient)
    upper = np.full(2, row @ x_free - 1.0)  # binding: the free optimum violates it
    problem = (hessian, gradient, eq_matrix, np.zeros(3), in_matrix, np.full(2, -1e20), upper)
    at_upper, at_lower = np.ones(2, bool), np.zeros(2, bool)
    x, solves = _active_set(problem, at_upper, at_lower, 1e-9, 3)
    assert x is not None
    kkt = np.block([[hessian, row[:, None]], [row[None, :], np.zeros((1, 1))]])
    expected = np.linalg.solve(kkt, np.r_[-gradient, upper[0]])[:n]
    np.testing.assert_allclose(x, expected, rtol=0, atol=1e-10 * np.abs(expected).max())


def _hat(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _exp(w: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """exp of the twist (u, w): Rodrigues' rotation and V u (Murray, Li & Sastry, eq. 2.36)."""
    theta, hat = np.linalg.norm(w), _hat(w)
    if theta < 1e-2:  # Taylor series: the closed forms cancel (error ~eps / theta^2)
        t2 = theta**2
        a, b, c = 1 - t2 / 6 + t2**2 / 120, 0.5 - t2 / 24 + t2**2 / 720, 1 / 6 - t2 / 120
    else:
        a, b = np.sin(theta) / theta, (1 - np.cos(theta)) / theta**2
        c = (theta - np.sin(theta)) / theta**3
    return np.eye(3) + a * hat + b * hat @ hat, (np.eye(3) + b * hat + c * hat @ hat) @ u


# The axis is read from R - R^T, entries with rounding errors ~eps: relative error
# ~2 eps / sin(theta) <= 2.2e-13 for theta <= pi - 2e-3, times theta <= pi (1e-12), plus the
# rounding of the answer key's own exp (1e-15).
_LOG_TOLERANCE = 1e-11


@settings(max_examples=60, deadline=None)
@given(
    angle=st.one_of(st.floats(0.0, 1e-3), st.floats(0.0, np.pi - 2e-3)),
    seed=st.integers(0, 2**16),
)
def test_frame_task_rows_rotation_error_is_the_log(angle, seed):
    """R_ref R^T = exp([w]) gives the error w (the log of the answer key's exp), the position
    error p_ref - p, the frame Jacobian at p in world axes (J_v + J_w x p; J_w) on the
    supporting joints' columns, and the PD rows b = a_ref + Kp e + Kd (v_ref - J v) - drift."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    w = angle * axis / np.linalg.norm(axis)
    reference, _ = _exp(rng.normal(size=3), np.zeros(3))
    rotation = _exp(w, np.zeros(3))[0].T @ reference  # R_ref R^T = exp(w)
    p_ref, p = rng.normal(size=3), rng.normal(size=3)
    joints, columns = rng.normal(size=(6, 5)), np.array([0, 2, 3])
    full = np.zeros((6, 5))
    full[:, columns] = joints[:, columns]
    full[:3, columns] += np.cross(joints[3:, columns].T, p).T
    v, drift = rng.normal(size=5), rng.normal(size=6)
    v_ref, a_ref, kp, kd = (rng.uniform(0, 2, size=6) for _ in range(4))
    rows = np.array([1, 3, 4, 5])
    target, jacobian, error, written = np.zeros(4), np.zeros((4, 5)), np.zeros(6), np.zeros((6, 5))
    assert kernels.frame_task_rows(
        target, jacobian, rows, error, reference, p_ref, rotation, p, joints, columns, written,
        v, drift, v_ref, a_ref, kp, kd, True, True,
    )  # fmt: skip
    np.testing.assert_allclose(written, full, rtol=0, atol=1e-14)
    np.testing.assert_allclose(error[3:], w, rtol=0, atol=_LOG_TOLERANCE)
    np.testing.assert_allclose(error[:3], p_ref - p, rtol=0, atol=1e-15)
    expected = a_ref + kp * error + kd * (v_ref - full @ v) - drift
    np.testing.assert_allclose(target, expected[rows], rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(jacobian, full[rows], rtol=0, atol=1e-14)


@settings(max_examples=60, deadline=None)
@given(
    angle=st.one_of(st.floats(0.0, 2e-3), st.floats(0.0, np.pi - 2e-3)),
    seed=st.integers(0, 2**16),
)
def test_sole_rows_error_is_the_log6(angle, seed):
    """M^-1 M_ref = exp6(nu) gives the error nu = (u, w), linear part first; the frame
    Jacobian in frame axes R^T (J_v + J_w x p; J_w)."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    w, u = angle * axis / np.linalg.norm(axis), rng.uniform(-1, 1, size=3)
    rotation_e, translation_e = _exp(w, u)
    reference, _ = _exp(rng.normal(size=3), np.zeros(3))
    p_ref = rng.normal(size=3)
    rotation = reference @ rotation_e.T  # M = M_ref exp6(nu)^-1
    p = p_ref - rotation @ translation_e
    error, zero, joints, written = (
        np.zeros(6),
        np.zeros(6),
        rng.normal(size=(6, 2)),
        np.zeros((6, 2)),
    )
    assert kernels.sole_rows(
        np.zeros(6), np.zeros((6, 2)), np.arange(6), error, reference, p_ref, rotation, p,
        joints, np.array([1]), written, np.zeros(2), zero, zero, np.ones(6), zero,
    )  # fmt: skip
    linear = joints[:3, 1] + np.cross(joints[3:, 1], p)
    np.testing.assert_allclose(written[:, 0], 0.0, rtol=0, atol=0)
    np.testing.assert_allclose(
        written[:, 1], np.r_[rotation.T @ linear, rotation.T @ joints[3:, 1]], rtol=0, atol=1e-13
    )
    np.testing.assert_allclose(error, np.r_[u, w], rtol=0, atol=_LOG_TOLERANCE)


def test_rotation_errors_near_pi_are_left_to_the_caller():
    """Within 1e-3 rad of a half turn the kernels write no error and return False."""
    rotation = _exp(np.array([0.0, 0.0, np.pi - 1e-4]), np.zeros(3))[0]
    error = np.full(6, 7.0)
    none = np.zeros(0, dtype=np.int64)
    assert not kernels.frame_task_rows(
        np.zeros(6), np.zeros((6, 1)), np.arange(6), error, rotation, np.zeros(3), np.eye(3),
        np.zeros(3), np.zeros((6, 1)), none, np.zeros((6, 1)), np.zeros(1), np.zeros(6),
        np.zeros(6), np.zeros(6), np.ones(6), np.ones(6), True, True,
    )  # fmt: skip
    assert not kernels.sole_rows(
        np.zeros(6), np.zeros((6, 1)), np.arange(6), error, rotation, np.zeros(3), np.eye(3),
        np.zeros(3), np.zeros((6, 1)), none, np.zeros((6, 1)), np.zeros(1), np.zeros(6),
        np.zeros(6), np.ones(6), np.ones(6),
    )  # fmt: skip
    np.testing.assert_array_equal(error, 7.0)


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    log_scale=st.floats(-9.0, -3.0),
    bad=st.sampled_from([None, np.nan, np.inf, -np.inf]),
)
def test_is_placement_is_numpys_orthonormality_check(seed, log_scale, bad):
    """The check of a target placement against the NumPy expression it replaces:
    finite, and np.allclose(R^T R, I, atol=1e-6) (rtol 1e-5), on rotations perturbed by noise
    from 1e-9 to 1e-3 (both sides of the tolerance) and on entries made NaN or infinite.
    Cases within 1e-12 of the tolerance are skipped: the kernel's sums may round one unit
    apart from BLAS's product (its docstring)."""
    rng = np.random.default_rng(seed)
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    homogeneous = np.eye(4)
    homogeneous[:3, :3] = rotation + 10.0**log_scale * rng.normal(size=(3, 3))
    homogeneous[:3, 3] = rng.normal(size=3)
    if bad is not None:
        homogeneous[rng.integers(0, 3), rng.integers(0, 4)] = bad
    r = homogeneous[:3, :3]
    with np.errstate(invalid="ignore"):
        gram = r.T @ r
        margin = np.abs(gram - np.eye(3)) - (1e-6 + 1e-5 * np.eye(3))
    assume(not np.isfinite(margin).all() or np.abs(margin).min() > 1e-12)
    expected = bool(np.isfinite(homogeneous).all() and np.allclose(gram, np.eye(3), atol=1e-6))
    assert kernels.is_placement(homogeneous) is expected
