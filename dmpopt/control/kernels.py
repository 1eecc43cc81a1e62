r"""Compiled numeric kernels of the inverse-dynamics tick (numba).

A controller tick is a few dozen small dense operations (tens of rows and columns). In NumPy
each costs a call of about a microsecond whatever its size, which is most of the tick; these
kernels run a whole stage as one compiled call. They work in place on the controller's
preallocated arrays, so that its proxsuite QPs read the same Hessians and gradients. Index
arguments are integer arrays; the controller's matrices are C-ordered, Pinocchio's (mass
matrix, Jacobians) are read as Pinocchio returns them (Fortran-ordered). Each kernel is
compiled for the argument types of its first call and cached on disk (``cache=True``); the
controller makes those calls when it is built, so that no tick waits for a compilation.

The maths is that of :mod:`dmpopt.control.inverse_dynamics` and
:mod:`dmpopt.control.tasks`, where each stage is described.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "acceleration_bounds",
    "active_set",
    "all_finite",
    "cholesky_solve",
    "eliminate",
    "eliminated_tick",
    "expand",
    "feasible",
    "joint_space_accelerations",
    "posture_gradient",
    "posture_law",
    "pd_task_rows",
    "reduce_costs",
    "solve_in_place",
    "torques",
]

# Compiled on first call, cached on disk; NumPy semantics for x / 0 (inf or NaN, checked by
# the callers) instead of raising.
_compile = numba.njit(cache=True, nogil=True, error_model="numpy")

# eliminated_tick's outcomes
SOLVED, CONES_VIOLATED, LIMITS_VIOLATED, ILL_CONDITIONED, CHOLESKY_FAILED = range(5)


@_compile
def all_finite(q, v) -> bool:
    """Whether every entry of q and v is finite."""
    for value in q:
        if not math.isfinite(value):
            return False
    for value in v:
        if not math.isfinite(value):
            return False
    return True


@_compile
def acceleration_bounds(bounds, q, v):
    r"""Bounds :math:`l \le \ddot q \le u` that keep joints within their position and
    velocity limits: near a position limit a joint may approach it no faster than a
    critically damped system of time constant h, and its velocity may reach the limit in no
    less than h,

    .. math:: u = \min\big(\tfrac{1}{h^2}(q_{max} - q) - \tfrac{2}{h}\dot q,\;
              \tfrac{1}{h}(\dot q_{max} - \dot q)\big)

    and symmetrically for l. ``bounds`` is (q_index, v_index, position_lower, position_upper,
    velocity_limit, h, lower, upper): the joints' entries in q and v, their limits, and the
    arrays written. Infinite limits give infinite bounds; if l > u (a joint already past a
    limit and moving fast), both become their mean.
    """
    q_index, v_index, position_lower, position_upper, velocity_limit, horizon, lower, upper = bounds
    stiffness, damping, rate = 1.0 / horizon**2, 2.0 / horizon, 1.0 / horizon
    for j in range(q_index.size):
        position, velocity = q[q_index[j]], v[v_index[j]]
        high = min(
            stiffness * (position_upper[j] - position) - damping * velocity,
            rate * (velocity_limit[j] - velocity),
        )
        low = max(
            stiffness * (position_lower[j] - position) - damping * velocity,
            rate * (-velocity_limit[j] - velocity),
        )
        if low > high:
            low = high = 0.5 * (low + high)
        lower[j], upper[j] = low, high


@_compile
def feasible(tau, torque_limit, x, bounds, q, v, margin) -> bool:
    r"""Whether :math:`|\tau_i| \le \tau_{max,i}` and the accelerations x of the bounded
    joints are within their :func:`acceleration_bounds` (computed here) by ``margin``
    (negative: a tolerance); False for a NaN."""
    for i in range(tau.size):
        if not abs(tau[i]) <= torque_limit[i]:
            return False
    acceleration_bounds(bounds, q, v)
    v_index, lower, upper = bounds[1], bounds[6], bounds[7]
    for j in range(v_index.size):
        value = x[v_index[j]]
        if not (lower[j] + margin <= value and value <= upper[j] - margin):
            return False
    return True


@_compile
def posture_law(state, q_index, v_index, q, v):
    r"""PD law of :class:`~dmpopt.control.tasks.PostureTask` on the 7 rows of a state block:
    :math:`\ddot q^* = \ddot q_{ref} + K_p (q_{ref} - q) + K_d (\dot q_{ref} - \dot q)`.

    Rows of ``state``: reference position, velocity, acceleration, stiffness, damping, then
    written: target :math:`\ddot q^*` and error :math:`q_{ref} - q`.
    """
    for j in range(state.shape[1]):
        error = state[0, j] - q[q_index[j]]
        state[6, j] = error
        state[5, j] = (
            state[2, j] + state[3, j] * error + state[4, j] * (state[1, j] - v[v_index[j]])
        )


@_compile
def posture_gradient(state, q_index, v_index, weights, gradient, q, v):
    r"""Posture targets (:func:`posture_law`) and their gradient terms :math:`-w \ddot q^*`,
    summed per velocity index into ``gradient`` (zero elsewhere)."""
    posture_law(state, q_index, v_index, q, v)
    gradient[:] = 0.0
    for j in range(state.shape[1]):
        gradient[v_index[j]] -= weights[j] * state[5, j]


@_compile
def pd_task_rows(
    target, jacobian, components, error, full_jacobian, v, drift, reference_velocity,
    reference_acceleration, stiffness, damping,
):  # fmt: skip
    r"""Rows of a task with the PD law of :mod:`dmpopt.control.tasks`, for the tracked
    ``components`` c of its full (e.g. 6-D) quantity with Jacobian :math:`J` (``full_jacobian``):
    :math:`b_c = a_{ref,c} + K_{p,c}\, e_c + K_{d,c} (v_{ref,c} - (J \dot q)_c)
    - (\dot J \dot q)_c` into ``target`` and row c of :math:`J` into ``jacobian``."""
    for k in range(components.size):
        c = components[k]
        velocity = 0.0
        for j in range(full_jacobian.shape[1]):
            jacobian[k, j] = full_jacobian[c, j]
            velocity += full_jacobian[c, j] * v[j]
        target[k] = (
            reference_acceleration[c]
            + stiffness[c] * error[c]
            + damping[c] * (reference_velocity[c] - velocity)
            - drift[c]
        )


@_compile
def cholesky_solve(matrix, factor, rhs, solution) -> bool:
    r"""``solution`` :math:`= -H^{-1} g` for a symmetric positive definite :math:`H`
    (``matrix``, kept) and :math:`g` (``rhs``), through a Cholesky factorisation written
    into ``factor``. ``rhs`` and ``solution`` may be the same array. False if :math:`H` is
    not positive definite or the result not finite.
    """
    n = matrix.shape[0]
    for i in range(n):
        for k in range(i + 1):
            value = matrix[i, k]
            for m in range(k):
                value -= factor[i, m] * factor[k, m]
            if k < i:
                factor[i, k] = value / factor[k, k]
            elif value > 0.0:
                factor[i, i] = math.sqrt(value)
            else:  # also catches NaN
                return False
    for i in range(n):  # L y = -g
        value = -rhs[i]
        for m in range(i):
            value -= factor[i, m] * solution[m]
        solution[i] = value / factor[i, i]
    total = 0.0
    for i in range(n - 1, -1, -1):  # L^T u = y
        value = solution[i]
        for m in range(i + 1, n):
            value -= factor[m, i] * solution[m]
        solution[i] = value / factor[i, i]
        total += solution[i]
    return math.isfinite(total)


@_compile
def solve_in_place(matrix, rhs) -> bool:
    """``rhs`` := ``matrix``^-1 ``rhs`` by Gaussian elimination with partial pivoting,
    overwriting ``matrix``; False if a pivot is zero or the result not finite. Compiled and
    single-threaded: LAPACK's threads cost more than such a small system on a busy machine.
    """
    n = rhs.size
    for k in range(n):
        pivot = k
        for i in range(k + 1, n):
            if abs(matrix[i, k]) > abs(matrix[pivot, k]):
                pivot = i
        if not abs(matrix[pivot, k]) > 0.0:  # also NaN
            return False
        if pivot != k:
            for j in range(k, n):
                matrix[k, j], matrix[pivot, j] = matrix[pivot, j], matrix[k, j]
            rhs[k], rhs[pivot] = rhs[pivot], rhs[k]
        for i in range(k + 1, n):
            factor = matrix[i, k] / matrix[k, k]
            if factor != 0.0:
                for j in range(k + 1, n):
                    matrix[i, j] -= factor * matrix[k, j]
                rhs[i] -= factor * rhs[k]
    total = 0.0
    for k in range(n - 1, -1, -1):
        value = rhs[k]
        for j in range(k + 1, n):
            value -= matrix[k, j] * rhs[j]
        rhs[k] = value / matrix[k, k]
        total += rhs[k]
    return math.isfinite(total)


@_compile
def joint_space_accelerations(posture, woodbury, q, v, x) -> bool:
    r"""Fixed base, posture tasks on every joint plus ``n_task`` frame-task rows: the
    accelerations ``x`` minimising the QP's cost, by the Woodbury identity

    .. math:: \ddot q = D^{-1} r - (J D^{-1})^\top (W^{-1} + J D^{-1} J^\top)^{-1}
              J D^{-1} r, \qquad r = J^\top W t - p,

    with ``rows[:n_task] = [J | t]``, D the diagonal posture and regularisation weights
    (``inverse_diagonal`` :math:`= D^{-1}`), W the task weights and p the posture gradient
    (:func:`posture_gradient` with the arguments ``posture``). ``woodbury`` is (rows, n_task,
    inverse_diagonal, task_weights, scaled, capacitance, factor, correction), the last four
    scratch arrays. False if the small system fails (not expected: it is positive definite).
    """
    posture_gradient(*posture, q, v)
    gradient = posture[-1]
    rows, n_task, inverse_diagonal, task_weights, scaled, capacitance, factor, correction = woodbury
    nv = x.size
    for i in range(nv):
        x[i] = -gradient[i]
    for k in range(n_task):
        weighted = task_weights[k] * rows[k, nv]
        for i in range(nv):
            x[i] += weighted * rows[k, i]
            scaled[k, i] = rows[k, i] * inverse_diagonal[i]
    if n_task:
        for k in range(n_task):  # capacitance W^-1 + J D^-1 J^T, and J D^-1 r
            for m in range(k + 1):
                value = 0.0
                for i in range(nv):
                    value += scaled[k, i] * rows[m, i]
                capacitance[k, m] = value
                capacitance[m, k] = value
            capacitance[k, k] += 1.0 / task_weights[k]
            value = 0.0
            for i in range(nv):
                value += scaled[k, i] * x[i]
            correction[k] = value
        # correction = -(W^-1 + J D^-1 J^T)^-1 J D^-1 r
        if not cholesky_solve(capacitance, factor, correction, correction):
            return False
    for i in range(nv):
        value = x[i] * inverse_diagonal[i]
        for k in range(n_task):
            value += correction[k] * scaled[k, i]
        x[i] = value
    return True


@_compile
def eliminate(
    rows, n_cost, nv, n_base, mass, bias, force_scale, basic, nonbasic, lu, elimination,
    min_pivot_ratio,
) -> bool:  # fmt: skip
    r"""Solve the base and contact rows for the basic accelerations.

    Fills the base-dynamics rows :math:`[M_b \,|\, -s J_{c,b}^\top \,|\, -h_b]` below the
    contact rows of ``rows`` (``rows[n_cost:]``, :math:`[G \,|\, t]`), then
    :math:`[U_N \,|\, U_c] = G_B^{-1} [G_N \,|\, t]` into ``elimination`` by Gaussian
    elimination with partial pivoting (:math:`G_B` in ``lu``). ``nonbasic`` lists the
    nonbasic columns and then the constant column. False if the smallest pivot is below
    ``min_pivot_ratio`` times the largest (ill-conditioned :math:`G_B`).
    """
    n_con = basic.size
    n_contact = n_con - n_base
    first = n_cost + n_contact  # base-dynamics rows
    width = rows.shape[1]
    for i in range(n_base):  # mass is symmetric and read by columns (Fortran-ordered)
        row = first + i
        for j in range(nv):
            rows[row, j] = mass[j, i]
        for k in range(n_contact):
            rows[row, nv + k] = -force_scale * rows[n_cost + k, i]
        rows[row, width - 1] = -bias[i]
    for i in range(n_con):
        for j in range(n_con):
            lu[i, j] = rows[n_cost + i, basic[j]]
        for j in range(nonbasic.size):
            elimination[i, j] = rows[n_cost + i, nonbasic[j]]
    smallest, largest = np.inf, 0.0
    for k in range(n_con):
        pivot = k
        for i in range(k + 1, n_con):
            if abs(lu[i, k]) > abs(lu[pivot, k]):
                pivot = i
        if pivot != k:
            for j in range(k, n_con):
                lu[k, j], lu[pivot, j] = lu[pivot, j], lu[k, j]
            for j in range(nonbasic.size):
                elimination[k, j], elimination[pivot, j] = elimination[pivot, j], elimination[k, j]
        magnitude = abs(lu[k, k])
        smallest, largest = min(smallest, magnitude), max(largest, magnitude)
        if not magnitude > 0.0:  # also NaN
            return False
        for i in range(k + 1, n_con):
            factor = lu[i, k] / lu[k, k]
            if factor != 0.0:
                for j in range(k + 1, n_con):
                    lu[i, j] -= factor * lu[k, j]
                for j in range(nonbasic.size):
                    elimination[i, j] -= factor * elimination[k, j]
    if smallest < min_pivot_ratio * largest:
        return False
    for k in range(n_con - 1, -1, -1):  # back substitution, all columns at once
        for i in range(k + 1, n_con):
            factor = lu[k, i]
            for j in range(nonbasic.size):
                elimination[k, j] -= factor * elimination[i, j]
        inverse = 1.0 / lu[k, k]
        for j in range(nonbasic.size):
            elimination[k, j] *= inverse
    return True


@_compile
def reduce_costs(
    rows, n_task, basic, nonbasic, elimination, row_scale, basic_scale, posture, diagonal,
    z_matrix, z_target, hessian, gradient,
):  # fmt: skip
    r"""Hessian and gradient over the nonbasic unknowns z, with :math:`x_B = U_c - U_N z`.

    Each task row :math:`[A | t]` becomes :math:`\sqrt{w}\,[A_N - A_B U_N \,|\, t - A_B U_c]`
    and the regularisation of the basic unknowns :math:`-\sqrt{d_B}\,[U_N | U_c]`: the rows
    :math:`[Z | t_z]` (``z_matrix``, ``z_target``); then :math:`H = Z^\top Z +
    \mathrm{diag}(d_N)` and :math:`g = p_N - U_N^\top p_B - Z^\top t_z` with p the posture
    gradient.
    """
    n_con, n_z = basic.size, nonbasic.size - 1
    for r in range(n_task):
        for j in range(n_z):
            z_matrix[r, j] = rows[r, nonbasic[j]]
        target = rows[r, nonbasic[n_z]]
        for i in range(n_con):
            a = rows[r, basic[i]]
            if a != 0.0:
                for j in range(n_z):
                    z_matrix[r, j] -= a * elimination[i, j]
                target -= a * elimination[i, n_z]
        for j in range(n_z):
            z_matrix[r, j] *= row_scale[r]
        z_target[r] = row_scale[r] * target
    for i in range(n_con):
        for j in range(n_z):
            z_matrix[n_task + i, j] = basic_scale[i] * elimination[i, j]
        z_target[n_task + i] = basic_scale[i] * elimination[i, n_z]
    np.dot(z_matrix.T, z_matrix, hessian)
    for i in range(n_z):
        hessian[i, i] += diagonal[i]
        gradient[i] = posture[nonbasic[i]]
    for r in range(z_matrix.shape[0]):
        t = z_target[r]
        for j in range(n_z):
            gradient[j] -= z_matrix[r, j] * t
    for i in range(n_con):
        p = posture[basic[i]]
        if p != 0.0:
            for j in range(n_z):
                gradient[j] -= p * elimination[i, j]


@_compile
def expand(elimination, basic, nonbasic, z, x):
    r"""Unknowns x from the nonbasic ones z: :math:`x_N = z`, :math:`x_B = U_c - U_N z`."""
    n_z = z.size
    for j in range(n_z):
        x[nonbasic[j]] = z[j]
    for i in range(basic.size):
        value = elimination[i, n_z]
        for j in range(n_z):
            value -= elimination[i, j] * z[j]
        x[basic[i]] = value


@_compile
def torques(mass, bias, rows, n_cost, n_base, force_scale, x, tau):
    r"""Unscale the wrenches of x (in place) and read the torques off the equations of
    motion, :math:`\tau = M_a \ddot q + h_a - J_{c,a}^\top f`, with the contact Jacobians
    :math:`J_c` the rows ``rows[n_cost:n_cost + n_f]``."""
    nv = mass.shape[0]
    for k in range(nv, x.size):
        x[k] *= force_scale
    for i in range(tau.size):
        joint = n_base + i
        value = bias[joint]
        for j in range(nv):  # row `joint` of the symmetric, Fortran-ordered mass matrix
            value += mass[j, joint] * x[j]
        for k in range(x.size - nv):
            value -= rows[n_cost + k, joint] * x[nv + k]
        tau[i] = value


@_compile
def eliminated_tick(elimination, reduction, solve, q, v, x, tau) -> int:
    """One tick without inequality rows on the eliminated QP: :func:`eliminate` and
    :func:`reduce_costs` (their arguments as the tuples ``elimination`` and ``reduction``),
    the Cholesky solve for z, the cone check, :func:`expand` and :func:`torques` with the
    torque-limit and acceleration-bound check (:func:`feasible`); ``solve`` is (factor, z,
    cone_matrix, cone_upper, torque_limit, bounds, bound_margin) with ``bounds`` as in
    :func:`acceleration_bounds`.

    Returns SOLVED, CONES_VIOLATED (z, x and the torques are filled), LIMITS_VIOLATED,
    ILL_CONDITIONED (nothing is solved) or CHOLESKY_FAILED (Hessian not positive definite or
    solution not finite; Hessian and gradient are filled).
    """
    if not eliminate(*elimination):
        return ILL_CONDITIONED
    reduce_costs(*reduction)
    rows, n_cost, _, n_base, mass, bias, force_scale, basic, nonbasic, _, matrix, _ = elimination
    hessian, gradient = reduction[-2:]
    factor, z, cone_matrix, cone_upper, torque_limit, bounds, margin = solve
    if not cholesky_solve(hessian, factor, gradient, z):
        return CHOLESKY_FAILED
    expand(matrix, basic, nonbasic, z, x)
    torques(mass, bias, rows, n_cost, n_base, force_scale, x, tau)
    for i in range(cone_matrix.shape[0]):
        value = 0.0
        for j in range(z.size):
            value += cone_matrix[i, j] * z[j]
        if value > cone_upper[i]:
            return CONES_VIOLATED
    if feasible(tau, torque_limit, x, bounds, q, v, margin):
        return SOLVED
    return LIMITS_VIOLATED


@_compile
def active_set(problem, at_upper, at_lower, tolerance, rounds, workspace, x, y, z) -> int:
    r"""Primal-dual active-set iterations (see :func:`dmpopt.control.qp_stages._active_set`)
    as one compiled call: each round assembles the KKT matrix of the active rows in place in
    ``workspace`` and solves it by :func:`solve_in_place`.

    ``problem`` is (H, g, A, b, C, l, u) with A, b of zero rows if there are no equality
    rows; ``workspace`` is (kkt, rhs, values, rows): a flat array of at least
    :math:`(n + n_{eq} + n)^2` entries, and arrays of :math:`n + n_{eq} + n`, :math:`n_{in}`
    and :math:`n_{in}` entries. More active rows than unknowns are dependent. On a certified
    optimum ``x``, ``y`` (equality rows) and ``z`` (every inequality row, 0 if inactive)
    receive it and its multipliers. Returns the number of KKT solves, negative if no set
    verified.
    """
    hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper = problem
    kkt, rhs, values, rows = workspace
    n, n_eq, n_in = hessian.shape[0], eq_matrix.shape[0], in_matrix.shape[0]
    for solves in range(1, rounds + 1):
        n_active = 0
        for i in range(n_in):
            if at_upper[i] or at_lower[i]:
                rows[n_active] = i
                n_active += 1
        m = n_eq + n_active
        size = n + m
        if n_active > n:  # dependent active rows
            return -solves
        matrix = kkt[: size * size].reshape(size, size)
        matrix[:] = 0.0
        matrix[:n, :n] = hessian
        for i in range(n_eq):
            for j in range(n):
                matrix[n + i, j] = eq_matrix[i, j]
                matrix[j, n + i] = eq_matrix[i, j]
            rhs[n + i] = eq_vector[i]
        for k in range(n_active):
            row = rows[k]
            for j in range(n):
                matrix[n + n_eq + k, j] = in_matrix[row, j]
                matrix[j, n + n_eq + k] = in_matrix[row, j]
            rhs[n + n_eq + k] = upper[row] if at_upper[row] else lower[row]
        for j in range(n):
            rhs[j] = -gradient[j]
        if not solve_in_place(matrix, rhs[:size]):  # dependent active rows
            return -solves
        largest = 0.0
        for k in range(n_active):
            largest = max(largest, abs(rhs[n + n_eq + k]))
        slack = 1e-9 * max(1.0, largest)
        wrong = False
        for k in range(n_active):
            row, multiplier = rows[k], rhs[n + n_eq + k]
            if multiplier < -slack if at_upper[row] else multiplier > slack:
                at_upper[row] = at_lower[row] = False  # leaves the active set
                wrong = True
        if wrong:
            continue
        worst, violation = -1, -np.inf
        for i in range(n_in):
            value = 0.0
            for j in range(n):
                value += in_matrix[i, j] * rhs[j]
            values[i] = value
            excess = max(value - upper[i], lower[i] - value)
            if excess > violation or excess != excess:  # NaN: never certified
                worst, violation = i, excess
                if excess != excess:
                    break
        if worst < 0 or violation <= tolerance:  # (False for NaN)
            x[:] = rhs[:n]
            y[:] = rhs[n : n + n_eq]
            z[:] = 0.0
            for k in range(n_active):
                z[rows[k]] = rhs[n + n_eq + k]
            return solves
        at_upper[worst] = values[worst] > upper[worst]
        at_lower[worst] = values[worst] < lower[worst]
    return -rounds
