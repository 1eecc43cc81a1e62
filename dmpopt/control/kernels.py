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
from typing import NamedTuple

import numba
import numpy as np

__all__ = [
    "Checks",
    "ComItem",
    "Dynamics",
    "FrameItems",
    "JointBounds",
    "KktWorkspace",
    "PostureStack",
    "QpArrays",
    "ReducedCosts",
    "Rows",
    "Split",
    "Woodbury",
    "acceleration_bounds",
    "active_set",
    "base_map",
    "all_finite",
    "cholesky_solve",
    "eliminate",
    "eliminated_tick",
    "eliminated_torque_rows",
    "entry_point",
    "expand",
    "feasible",
    "joint_space_accelerations",
    "map_rows",
    "posture_gradient",
    "posture_law",
    "pd_task_rows",
    "com_rows",
    "com_task_rows",
    "frame_rows",
    "frame_task_rows",
    "reference_status",
    "sole_rows",
    "stacked_rows",
    "Binding",
    "reduce_costs",
    "solve_in_place",
    "torque_rows",
    "torques",
]


class JointBounds(NamedTuple):
    """Arguments of :func:`acceleration_bounds`: the bounded joints' entries in q and v, their
    limits [rad, rad/s], the horizon h [s], and the bounds l, u [rad/s^2] written."""

    q_index: np.ndarray
    v_index: np.ndarray
    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity_limit: np.ndarray
    horizon: float
    lower: np.ndarray
    upper: np.ndarray


class PostureStack(NamedTuple):
    """The posture tasks stacked: ``state`` (7, n) rows of :func:`posture_law`, their joints'
    entries in q and v, their weights, and the gradient over x written by
    :func:`posture_gradient`."""

    state: np.ndarray
    q_index: np.ndarray
    v_index: np.ndarray
    weights: np.ndarray
    gradient: np.ndarray


class Rows(NamedTuple):
    r"""The QP's linear rows :math:`[A \,|\, t]` over x (``matrix``): ``n_task`` task rows,
    then up to ``n_cost`` the base regularisation, then the contact rows, then the base
    dynamics; ``nv`` accelerations and ``n_base`` base coordinates."""

    matrix: np.ndarray
    n_task: int
    n_cost: int
    nv: int
    n_base: int


class Dynamics(NamedTuple):
    """The model terms of a tick (mass matrix, bias forces, Fortran-ordered as Pinocchio gives
    them) and the scale of the wrench unknowns (the robot's weight [N])."""

    mass: np.ndarray
    bias: np.ndarray
    force_scale: float


class Split(NamedTuple):
    r"""The basic unknowns of the elimination and its result: ``basic`` and ``nonbasic``
    columns of x (the constant column last), :math:`G_B` factored in ``lu``,
    :math:`[U_N \,|\, U_c]` in ``elimination``, and the smallest accepted pivot ratio."""

    basic: np.ndarray
    nonbasic: np.ndarray
    lu: np.ndarray
    elimination: np.ndarray
    min_pivot_ratio: float


class ReducedCosts(NamedTuple):
    r"""The least-squares cost over z of :func:`reduce_costs`: square roots of the task
    weights per row and :math:`-\sqrt{d_B}`, the posture gradient over x and the diagonal
    :math:`d_N`, then the arrays written (rows :math:`[Z | t_z]`, Hessian, gradient)."""

    row_scale: np.ndarray
    basic_scale: np.ndarray
    posture: np.ndarray
    diagonal: np.ndarray
    matrix: np.ndarray
    target: np.ndarray
    hessian: np.ndarray
    gradient: np.ndarray


class Checks(NamedTuple):
    """What :func:`eliminated_tick` solves into and checks: the Cholesky factor and z
    written, the cone rows over z, the torque limits and the joint bounds with their
    margin (negative: a tolerance)."""

    factor: np.ndarray
    z: np.ndarray
    cone_matrix: np.ndarray
    cone_upper: np.ndarray
    torque_limit: np.ndarray
    bounds: JointBounds
    margin: float


class Woodbury(NamedTuple):
    """Arguments of :func:`joint_space_accelerations` besides the rows: :math:`D^{-1}`, the
    task weights, and scratch arrays."""

    inverse_diagonal: np.ndarray
    task_weights: np.ndarray
    scaled: np.ndarray
    capacitance: np.ndarray
    factor: np.ndarray
    correction: np.ndarray


class QpArrays(NamedTuple):
    """A QP (H, g, A, b, C, l, u) for :func:`active_set`; A, b with zero rows if it has no
    equality rows."""

    hessian: np.ndarray
    gradient: np.ndarray
    eq_matrix: np.ndarray
    eq_vector: np.ndarray
    in_matrix: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


class KktWorkspace(NamedTuple):
    """Scratch arrays of :func:`active_set`: a flat KKT matrix, its right-hand side, the
    inequality rows' values, the active rows' indices, and in ``previous`` the multipliers
    of the last proximal iteration (:func:`_dependent_kkt_solve`), :math:`L^{-1} g` and the
    residuals of :func:`_refine` (n + m, n and n + m entries, m = n_eq + min(n, n_in))."""

    kkt: np.ndarray
    rhs: np.ndarray
    values: np.ndarray
    rows: np.ndarray
    previous: np.ndarray


# Compiled on first call, cached on disk; NumPy semantics for x / 0 (inf or NaN, checked by
# the callers) instead of raising.
_compile = numba.njit(cache=True, nogil=True, error_model="numpy")


def entry_point(kernel, *arguments):
    """The compiled code of ``kernel`` for the numba types of ``arguments`` (compiled, or
    loaded from the disk cache, if needed), to be called without numba's type dispatch.

    numba's dispatch types each argument on every call; for a named structure (a NamedTuple
    such as :class:`Rows`) it does so field by field in Python, about a microsecond per
    structure. A controller's arrays never change type (it passes its own float64 arrays,
    sized once), so it binds its kernels once and calls them directly. Only arguments of the
    types given here may be passed to the result: call ``kernel`` itself for any other. An
    argument may be given as its numba type instead (e.g. :func:`with_open_layout`).
    """
    return kernel.compile(
        tuple(a if isinstance(a, numba.types.Type) else numba.typeof(a) for a in arguments)
    )


def with_open_layout(arrays: tuple, positions) -> numba.types.Type:
    """The numba type of the tuple ``arrays`` with the memory layout of the arrays at
    ``positions`` left open ("A"): contiguous arrays and strided views alike pass.

    numba compiles a kernel anew for each layout of its arguments (the active-set iterations:
    about 20 CPU-seconds each time, in every fresh install); a kernel bound by
    :func:`entry_point` to this type is compiled once for both.
    """
    types = [numba.typeof(a) for a in arrays]
    for i in positions:
        types[i] = types[i].copy(layout="A")
    return numba.types.BaseTuple.from_types(types)


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

    and symmetrically for l, written into ``bounds.lower`` and ``bounds.upper``
    (:class:`JointBounds`). Infinite limits give infinite bounds; if l > u (a joint already
    past a limit and moving fast), both become their mean.
    """
    q_index, v_index, lower, upper = bounds.q_index, bounds.v_index, bounds.lower, bounds.upper
    position_lower, position_upper = bounds.position_lower, bounds.position_upper
    velocity_limit, horizon = bounds.velocity_limit, bounds.horizon
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
    v_index, lower, upper = bounds.v_index, bounds.lower, bounds.upper
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
def posture_gradient(posture, q, v):
    r"""Posture targets (:func:`posture_law`) of a :class:`PostureStack` and their gradient
    terms :math:`-w \ddot q^*`, summed per velocity index into ``posture.gradient`` (zero
    elsewhere)."""
    state, v_index, gradient = posture.state, posture.v_index, posture.gradient
    weights = posture.weights
    posture_law(state, posture.q_index, v_index, q, v)
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
def com_task_rows(
    target, jacobian, components, error, target_position, com, full_jacobian, v, drift,
    reference_velocity, reference_acceleration, stiffness, damping,
):  # fmt: skip
    r"""A :class:`~dmpopt.control.tasks.ComTask`'s error :math:`e = c_{ref} - c` and its rows
    (:func:`pd_task_rows`)."""
    for i in range(3):
        error[i] = target_position[i] - com[i]
    pd_task_rows(
        target, jacobian, components, error, full_jacobian, v, drift, reference_velocity,
        reference_acceleration, stiffness, damping,
    )  # fmt: skip


# Rotation angles closer to pi than this [rad] are left to Pinocchio's log3 (the axis is then
# read from the symmetric part of R, not from R - R^T as below).
_NEAR_PI = 1e-3


@_compile
def _log3(r, out) -> bool:
    r"""The rotation vector :math:`\log_3(R)` of the rotation matrix ``r`` into ``out[0:3]``.

    With :math:`a = (R_{21} - R_{12}, R_{02} - R_{20}, R_{10} - R_{01}) = 2 \sin\theta\, u`
    (u the unit axis), :math:`\theta = \operatorname{atan2}(|a|/2, (\mathrm{tr} R - 1)/2)` and
    :math:`\log_3 R = \theta\, a / |a|` (below 1e-4 rad :math:`\tfrac12 (1 + \theta^2/6)\, a`,
    its Taylor series). False, with nothing written, if :math:`\theta > \pi - 10^{-3}`: |a|
    then carries too few digits of the axis."""
    ax, ay, az = r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    theta = math.atan2(0.5 * norm, 0.5 * (r[0, 0] + r[1, 1] + r[2, 2] - 1.0))
    if theta > math.pi - _NEAR_PI:
        return False
    if theta < 1e-4:
        factor = 0.5 * (1.0 + theta * theta / 6.0)
    else:
        factor = theta / norm
    out[0] = factor * ax
    out[1] = factor * ay
    out[2] = factor * az
    return True


@_compile
def _frame_jacobian(joint_jacobians, columns, rotation, translation, local, out):
    r"""A frame's Jacobian into the ``columns`` (those of the joints supporting it) of ``out``
    from the joint Jacobians :math:`J = (J_v; J_\omega)` in world axes at the world origin
    (``data.J``, filled by ``computeAllTerms``): at the frame origin p, world axes
    (``LOCAL_WORLD_ALIGNED``) :math:`(J_v + J_\omega \times p;\, J_\omega)`, frame axes
    (``local``) those rotated by :math:`R^\top`. The other columns of ``out`` stay as they are
    (zero)."""
    px, py, pz = translation[0], translation[1], translation[2]
    for k in range(columns.size):
        c = columns[k]
        wx, wy, wz = joint_jacobians[3, c], joint_jacobians[4, c], joint_jacobians[5, c]
        vx = joint_jacobians[0, c] + wy * pz - wz * py
        vy = joint_jacobians[1, c] + wz * px - wx * pz
        vz = joint_jacobians[2, c] + wx * py - wy * px
        if local:
            for i in range(3):
                out[i, c] = rotation[0, i] * vx + rotation[1, i] * vy + rotation[2, i] * vz
                out[i + 3, c] = rotation[0, i] * wx + rotation[1, i] * wy + rotation[2, i] * wz
        else:
            out[0, c], out[1, c], out[2, c] = vx, vy, vz
            out[3, c], out[4, c], out[5, c] = wx, wy, wz


@_compile
def frame_task_rows(
    target, jacobian, components, error, target_rotation, target_translation, rotation,
    translation, joint_jacobians, columns, full_jacobian, v, drift, reference_velocity,
    reference_acceleration, stiffness, damping, position, orientation,
) -> bool:  # fmt: skip
    r"""A :class:`~dmpopt.control.tasks.FrameTask`'s error :math:`e = (p_{ref} - p,\;
    \log_3(R_{ref} R^\top))` (the parts tracked: ``position``, ``orientation``) and its rows
    (:func:`pd_task_rows`), with the frame Jacobian (world axes) first written into
    ``full_jacobian`` (:func:`_frame_jacobian`). False, with only that Jacobian written, if the
    rotation error is within 1e-3 rad of pi (see :func:`_log3`): the caller then computes
    the error with Pinocchio."""
    _frame_jacobian(joint_jacobians, columns, rotation, translation, False, full_jacobian)
    if orientation:
        relative = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                relative[i, j] = (
                    target_rotation[i, 0] * rotation[j, 0]
                    + target_rotation[i, 1] * rotation[j, 1]
                    + target_rotation[i, 2] * rotation[j, 2]
                )
        if not _log3(relative, error[3:]):
            return False
    if position:
        for i in range(3):
            error[i] = target_translation[i] - translation[i]
    pd_task_rows(
        target, jacobian, components, error, full_jacobian, v, drift, reference_velocity,
        reference_acceleration, stiffness, damping,
    )  # fmt: skip
    return True


@_compile
def sole_rows(
    target, jacobian, components, error, reference_rotation, reference_translation, rotation,
    translation, joint_jacobians, columns, full_jacobian, v, drift, zero, stiffness, damping,
) -> bool:  # fmt: skip
    r"""A :class:`~dmpopt.control.contacts.SoleContact`'s error :math:`e = \log_6(M^{-1}
    M_{ref})` (linear part first) and its rows (:func:`pd_task_rows`, zero reference motion).

    With :math:`M^{-1} M_{ref} = (R_r, p_r) = (R^\top R_{ref}, R^\top (p_{ref} - p))`,
    :math:`\omega = \log_3 R_r` and :math:`\theta = |\omega|`, the linear part is
    :math:`V^{-1} p_r`, :math:`V^{-1} = I - \tfrac12 [\omega]_\times + \alpha
    [\omega]_\times^2`, :math:`\alpha = (1 - \theta \sin\theta / (2 (1 - \cos\theta)))
    / \theta^2` (its series :math:`1/12 + \theta^2/720` below 1e-3 rad). The frame Jacobian
    (frame axes) is first written into ``full_jacobian`` (:func:`_frame_jacobian`). False,
    with only that Jacobian written, if :math:`\theta` is within 1e-3 rad of pi (see
    :func:`_log3`)."""
    _frame_jacobian(joint_jacobians, columns, rotation, translation, True, full_jacobian)
    relative = np.empty((3, 3))
    offset = np.empty(3)
    for i in range(3):
        offset[i] = 0.0
        for j in range(3):
            relative[i, j] = (
                rotation[0, i] * reference_rotation[0, j]
                + rotation[1, i] * reference_rotation[1, j]
                + rotation[2, i] * reference_rotation[2, j]
            )
    for i in range(3):
        for k in range(3):
            offset[i] += rotation[k, i] * (reference_translation[k] - translation[k])
    if not _log3(relative, error[3:]):
        return False
    wx, wy, wz = error[3], error[4], error[5]
    theta2 = wx * wx + wy * wy + wz * wz
    theta = math.sqrt(theta2)
    if theta < 1e-3:
        alpha = 1.0 / 12.0 + theta2 / 720.0
    else:
        half = 0.5 * theta
        # 1 - cos(theta) = 2 sin^2(theta / 2), without cancellation
        alpha = (1.0 - theta * math.sin(theta) / (4.0 * math.sin(half) ** 2)) / theta2
    px, py, pz = offset[0], offset[1], offset[2]
    # w x p and w x (w x p)
    cx, cy, cz = wy * pz - wz * py, wz * px - wx * pz, wx * py - wy * px
    ccx, ccy, ccz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx
    error[0] = px - 0.5 * cx + alpha * ccx
    error[1] = py - 0.5 * cy + alpha * ccy
    error[2] = pz - 0.5 * cz + alpha * ccz
    pd_task_rows(
        target, jacobian, components, error, full_jacobian, v, drift, zero, zero, stiffness,
        damping,
    )  # fmt: skip
    return True


# A tick computes the rows of its frame tasks, sole contacts and CoM task in one compiled call
# (stacked_rows): numba unboxes each argument of a call (a few tenths of a microsecond per
# array) and each Pinocchio getter costs a Python call, so the call reads the joint placements,
# velocities and accelerations through views of the Pinocchio data made once, and each item
# keeps its inputs and outputs in a few arrays made once.


@_compile
def _frame_placement(joint_rotation, joint_translation, placement, rotation, translation):
    """A frame's placement :math:`{}^oM_f = {}^oM_i\\, {}^iM_f` from its parent joint's
    (``joint_rotation``, ``joint_translation``) and its placement in the joint [R | p]
    (``placement``, 3 x 4), into ``rotation``, ``translation``."""
    for a in range(3):
        for b in range(3):
            rotation[a, b] = (
                joint_rotation[a, 0] * placement[0, b]
                + joint_rotation[a, 1] * placement[1, b]
                + joint_rotation[a, 2] * placement[2, b]
            )
        translation[a] = joint_translation[a] + (
            joint_rotation[a, 0] * placement[0, 3]
            + joint_rotation[a, 1] * placement[1, 3]
            + joint_rotation[a, 2] * placement[2, 3]
        )


@_compile
def _shifted(rotation, transposed, motion, placement, out):
    r"""A joint's spatial motion :math:`(v, \omega)` (joint axes, ``motion``) at a frame's
    origin :math:`p` (``placement[:, 3]``), rotated by R (``rotation``, or its transpose):
    :math:`(R (v + \omega \times p),\, R \omega)` into ``out``."""
    px, py, pz = placement[0, 3], placement[1, 3], placement[2, 3]
    wx, wy, wz = motion[3], motion[4], motion[5]
    lx = motion[0] + (wy * pz - wz * py)
    ly = motion[1] + (wz * px - wx * pz)
    lz = motion[2] + (wx * py - wy * px)
    for a in range(3):
        if transposed:
            r0, r1, r2 = rotation[0, a], rotation[1, a], rotation[2, a]
        else:
            r0, r1, r2 = rotation[a, 0], rotation[a, 1], rotation[a, 2]
        out[a] = r0 * lx + r1 * ly + r2 * lz
        out[3 + a] = r0 * wx + r1 * wy + r2 * wz


@_compile
def frame_rows(
    out, jacobians, indices, gains, reference_rotation, reference_translation, joint_rotation,
    joint_translation, joint_velocity, joint_acceleration, placement, sole, joint_jacobians, v,
) -> bool:  # fmt: skip
    r"""The rows of a :class:`~dmpopt.control.tasks.FrameTask` (:func:`frame_task_rows`) or,
    with ``sole``, of a :class:`~dmpopt.control.contacts.SoleContact` (:func:`sole_rows`),
    from the item's arrays and its frame's parent joint in the Pinocchio data.

    Item: ``out`` = (target (m), error (6)), ``jacobians`` = (rows (m, nv), frame Jacobian
    (6, nv)), ``indices`` = (tracked components (m, sorted), supporting columns), ``gains``
    rows :math:`K_p, K_d` (and :math:`v_{ref}, a_{ref}` of a frame task), the reference
    rotation and translation. Joint (``data.oMi``, ``data.v``, ``data.a`` of the frame's
    parent joint, the velocities in joint axes, linear part first): the frame's placement is
    :math:`{}^oM_i\, {}^iM_f` (``placement`` = :math:`{}^iM_f` as [R | p]); the drift of a
    sole is its spatial acceleration in frame axes, :math:`{}^iM_f^{-1} a_i`, that of a frame
    task its classical acceleration in world axes, :math:`a_p + \omega \times v_p` with
    :math:`(v_p, \omega)`, :math:`a_p` the joint's velocity and acceleration at the frame
    origin in world axes (Pinocchio's ``getFrameAcceleration`` and
    ``getFrameClassicalAcceleration``, :math:`\ddot q = 0`). False near a half turn, as the
    row kernels.
    """
    m = out.size - 6
    rotation, translation = np.empty((3, 3)), np.empty(3)
    _frame_placement(joint_rotation, joint_translation, placement, rotation, translation)
    drift = np.empty(6)
    if sole:  # iM_f^-1 a = (R_f^T (a_v - p_f x a_w), R_f^T a_w)
        _shifted(placement, True, joint_acceleration, placement, drift)
        zero = np.zeros(6)
        return sole_rows(
            out[:6], jacobians[:6], indices[:6], out[6:], reference_rotation,
            reference_translation, rotation, translation, joint_jacobians, indices[6:],
            jacobians[6:], v, drift, zero, gains[0], gains[1],
        )  # fmt: skip
    velocity = np.empty(6)
    _shifted(joint_rotation, False, joint_velocity, placement, velocity)
    _shifted(joint_rotation, False, joint_acceleration, placement, drift)
    wx, wy, wz = velocity[3], velocity[4], velocity[5]
    drift[0] += wy * velocity[2] - wz * velocity[1]
    drift[1] += wz * velocity[0] - wx * velocity[2]
    drift[2] += wx * velocity[1] - wy * velocity[0]
    rows = indices[:m]
    return frame_task_rows(
        out[:m], jacobians[:m], rows, out[m:], reference_rotation, reference_translation,
        rotation, translation, joint_jacobians, indices[m:], jacobians[m:], v, drift, gains[2],
        gains[3], gains[0], gains[1], rows[0] < 3, rows[m - 1] >= 3,
    )  # fmt: skip


@_compile
def com_rows(out, jacobian, gains, com, com_jacobian, drift, v):
    r""":func:`com_task_rows` of a :class:`~dmpopt.control.tasks.ComTask` from its packed
    arrays: ``out`` = (target (3), error (3)), ``gains`` rows :math:`K_p, K_d, \dot c_{ref},
    \ddot c_{ref}, c_{ref}` (5, 3); ``drift`` the CoM acceleration at zero joint
    acceleration."""
    com_task_rows(
        out[:3], jacobian, np.arange(3), out[3:], gains[4], com, com_jacobian, v, drift, gains[2],
        gains[3], gains[0], gains[1],
    )  # fmt: skip


class FrameItems(NamedTuple):
    """The frame tasks and sole contacts of a QP for :func:`stacked_rows`: per item (tuples,
    one entry per item) the arguments of :func:`frame_rows` up to the placement, the joint's
    views of the Pinocchio data included; then ``placements`` (n, 3, 4), ``soles`` (n,) and
    ``destinations`` (n,), each item's first row in the QP's rows, and ``joint_jacobians``
    (``data.J``)."""

    outs: tuple
    jacobians: tuple
    indices: tuple
    gains: tuple
    reference_rotations: tuple
    reference_translations: tuple
    joint_rotations: tuple
    joint_translations: tuple
    joint_velocities: tuple
    joint_accelerations: tuple
    placements: np.ndarray
    soles: np.ndarray
    destinations: np.ndarray
    joint_jacobians: np.ndarray


class ComItem(NamedTuple):
    """A CoM task for :func:`stacked_rows`: the arguments of :func:`com_rows` but v (those of
    the Pinocchio data as views: ``data.com[0]``, ``data.Jcom``, ``data.acom[0]``), and the
    task's first row in the QP's rows."""

    out: np.ndarray
    jacobian: np.ndarray
    gains: np.ndarray
    com: np.ndarray
    com_jacobian: np.ndarray
    drift: np.ndarray
    destination: int


@_compile
def _copy_rows(out, jacobian, m, rows, destination):
    """An item's m rows [J | b] (``jacobian[:m]``, ``out[:m]``) into ``rows`` from row
    ``destination`` (columns :math:`\\ddot q` and the last)."""
    last = rows.shape[1] - 1
    for k in range(m):
        for j in range(jacobian.shape[1]):
            rows[destination + k, j] = jacobian[k, j]
        rows[destination + k, last] = out[k]


@_compile
def stacked_rows(frames, com, blocks, posture, rows, q, v) -> bool:
    """The rows of a tick's items in one call: the frame tasks and sole contacts of
    ``frames`` (:class:`FrameItems`, :func:`frame_rows`) and the CoM task ``com``
    (:class:`ComItem`, :func:`com_rows`), each into its own arrays and into ``rows`` (the QP's
    rows [A | t], :class:`Rows`); then the posture tasks' ``blocks`` (their (7, n) arrays)
    copied side by side into ``posture.state`` and :func:`posture_gradient`. ``frames``,
    ``com`` and ``blocks`` may be None (none of them). False if a frame item's rotation error
    is near a half turn (see :func:`frame_rows`; the other items are filled)."""
    done = True
    if frames is not None:
        for i in range(len(frames.outs)):
            out, jacobians = frames.outs[i], frames.jacobians[i]
            if frame_rows(
                out, jacobians, frames.indices[i], frames.gains[i],
                frames.reference_rotations[i], frames.reference_translations[i],
                frames.joint_rotations[i], frames.joint_translations[i],
                frames.joint_velocities[i], frames.joint_accelerations[i],
                frames.placements[i], frames.soles[i], frames.joint_jacobians, v,
            ):  # fmt: skip
                _copy_rows(out, jacobians, out.size - 6, rows, frames.destinations[i])
            else:
                done = False
    if com is not None:
        com_rows(com.out, com.jacobian, com.gains, com.com, com.com_jacobian, com.drift, v)
        _copy_rows(com.out, com.jacobian, 3, rows, com.destination)
    if blocks is not None:
        state, column = posture.state, 0
        for block in blocks:
            for i in range(block.shape[0]):
                for j in range(block.shape[1]):
                    state[i, column + j] = block[i, j]
            column += block.shape[1]
        posture_gradient(posture, q, v)
    return done


@_compile
def is_placement(homogeneous) -> bool:
    """Whether a 4 x 4 homogeneous matrix is finite with a rotation block R such that
    ``np.allclose(R.T @ R, np.eye(3), atol=1e-6)`` (its default rtol 1e-5): each entry of
    :math:`R^\top R` within :math:`10^{-6} + 10^{-5} |I_{ij}|` of the identity's. Each entry
    is summed in the order ``a_0 b_0 + a_1 b_1 + a_2 b_2``, which may round one unit apart
    from a BLAS product; the tolerances are ten orders of magnitude wider."""
    for i in range(4):
        for j in range(4):
            if not math.isfinite(homogeneous[i, j]):
                return False
    for i in range(3):
        for j in range(3):
            product = (
                homogeneous[0, i] * homogeneous[0, j]
                + homogeneous[1, i] * homogeneous[1, j]
                + homogeneous[2, i] * homogeneous[2, j]
            )
            identity = 1.0 if i == j else 0.0
            if not abs(product - identity) <= 1e-6 + 1e-5 * identity:
                return False
    return True


@_compile
def reference_status(value, lower, upper) -> int:
    """0 if every entry of ``value`` is finite and within [lower, upper]; 1 if one is NaN or
    infinite; 2 if all are finite but one is outside its bounds."""
    status = 0
    for j in range(value.size):
        x = value[j]
        if not math.isfinite(x):
            return 1
        if x < lower[j] or x > upper[j]:
            status = 2
    return status


class Binding:
    """``kernel``'s compiled code (:func:`entry_point`) for the argument types of a caller's
    calls, kept per ``key``: the one argument that may change type between its calls (the
    state ``v`` a task's caller passes); every other argument must keep its type.

    A task's rows are computed into its own arrays from Pinocchio's results, whose types are
    fixed; only the caller's state can differ. A few bindings are kept (one per controller
    contact set using the task); beyond eight, all are forgotten.
    """

    __slots__ = ("kernel", "_codes")

    def __init__(self, kernel):
        self.kernel = kernel
        self._codes = {}

    def __call__(self, key, *arguments):
        """Call the kernel with ``arguments``; ``key`` is among them, by identity."""
        # The entries hold their keys, so an identity found is that of the same live object.
        entry = self._codes.get(id(key))
        if entry is None:
            if len(self._codes) >= 8:
                self._codes.clear()
            entry = self._codes[id(key)] = (key, entry_point(self.kernel, *arguments))
        return entry[1](*arguments)


@_compile
def cholesky_solve(matrix, factor, rhs, solution) -> bool:
    r"""``solution`` :math:`= -H^{-1} g` for a symmetric positive definite :math:`H`
    (``matrix``, kept) and :math:`g` (``rhs``), through a Cholesky factorisation written
    into ``factor``. ``rhs`` and ``solution`` may be the same array. False if :math:`H` is
    not positive definite or the result not finite.
    """
    n = matrix.shape[0]
    if not _cholesky(matrix, factor):
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
def joint_space_accelerations(posture, rows, woodbury, q, v, x) -> bool:
    r"""Fixed base, posture tasks on every joint plus ``n_task`` frame-task rows: the
    accelerations ``x`` minimising the QP's cost, by the Woodbury identity

    .. math:: \ddot q = D^{-1} r - (J D^{-1})^\top (W^{-1} + J D^{-1} J^\top)^{-1}
              J D^{-1} r, \qquad r = J^\top W t - p,

    with the task rows ``rows.matrix[:n_task] = [J | t]`` (:class:`Rows`), D the diagonal
    posture and regularisation weights (``woodbury.inverse_diagonal`` :math:`= D^{-1}`), W
    the task weights and p the posture gradient (:func:`posture_gradient` of ``posture``).
    False if the small system fails (not expected: it is positive definite).
    """
    posture_gradient(posture, q, v)
    gradient = posture.gradient
    n_task, inverse_diagonal = rows.n_task, woodbury.inverse_diagonal
    task_weights = woodbury.task_weights
    scaled, capacitance, factor = woodbury.scaled, woodbury.capacitance, woodbury.factor
    correction, rows = woodbury.correction, rows.matrix
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
def eliminate(layout, dynamics, split) -> bool:
    r"""Solve the base and contact rows for the basic accelerations.

    Fills the base-dynamics rows :math:`[M_b \,|\, -s J_{c,b}^\top \,|\, -h_b]` below the
    contact rows of ``layout.matrix`` (from row ``n_cost``, :math:`[G \,|\, t]`;
    :class:`Rows`, :class:`Dynamics`), then :math:`[U_N \,|\, U_c] = G_B^{-1} [G_N \,|\, t]`
    into ``split.elimination`` by Gaussian elimination with partial pivoting (:math:`G_B` in
    ``split.lu``; :class:`Split`). False if the smallest pivot is below
    ``split.min_pivot_ratio`` times the largest (ill-conditioned :math:`G_B`).
    """
    rows, n_cost, nv, n_base = layout.matrix, layout.n_cost, layout.nv, layout.n_base
    mass, bias, force_scale = dynamics.mass, dynamics.bias, dynamics.force_scale
    basic, nonbasic, lu, elimination = split.basic, split.nonbasic, split.lu, split.elimination
    min_pivot_ratio = split.min_pivot_ratio
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
def reduce_costs(layout, split, costs):
    r"""Hessian and gradient over the nonbasic unknowns z, with :math:`x_B = U_c - U_N z`.

    Each task row :math:`[A | t]` becomes :math:`\sqrt{w}\,[A_N - A_B U_N \,|\, t - A_B U_c]`
    and the regularisation of the basic unknowns :math:`-\sqrt{d_B}\,[U_N | U_c]`: the rows
    :math:`[Z | t_z]` (``costs.matrix``, ``costs.target``; :class:`ReducedCosts`); then
    :math:`H = Z^\top Z + \mathrm{diag}(d_N)` and :math:`g = p_N - U_N^\top p_B - Z^\top t_z`
    with p the posture gradient.
    """
    rows, n_task = layout.matrix, layout.n_task
    basic, nonbasic, elimination = split.basic, split.nonbasic, split.elimination
    row_scale, basic_scale, posture = costs.row_scale, costs.basic_scale, costs.posture
    diagonal, z_matrix, z_target = costs.diagonal, costs.matrix, costs.target
    hessian, gradient = costs.hessian, costs.gradient
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
def expand(split, z, x):
    r"""Unknowns x from the nonbasic ones z: :math:`x_N = z`, :math:`x_B = U_c - U_N z`
    (:class:`Split`)."""
    elimination, basic, nonbasic = split.elimination, split.basic, split.nonbasic
    n_z = z.size
    for j in range(n_z):
        x[nonbasic[j]] = z[j]
    n_con = basic.size
    i = 0
    while i + 3 < n_con:  # four rows at once, each summed in its own order (as below)
        a0, a1 = elimination[i, n_z], elimination[i + 1, n_z]
        a2, a3 = elimination[i + 2, n_z], elimination[i + 3, n_z]
        for j in range(n_z):
            value = z[j]
            a0 -= elimination[i, j] * value
            a1 -= elimination[i + 1, j] * value
            a2 -= elimination[i + 2, j] * value
            a3 -= elimination[i + 3, j] * value
        x[basic[i]], x[basic[i + 1]], x[basic[i + 2]], x[basic[i + 3]] = a0, a1, a2, a3
        i += 4
    for r in range(i, n_con):
        value = elimination[r, n_z]
        for j in range(n_z):
            value -= elimination[r, j] * z[j]
        x[basic[r]] = value


@_compile
def torques(layout, dynamics, x, tau):
    r"""Unscale the wrenches of x (in place) and read the torques off the equations of
    motion, :math:`\tau = M_a \ddot q + h_a - J_{c,a}^\top f`, with the contact Jacobians
    :math:`J_c` the contact rows of ``layout`` (:class:`Rows`, :class:`Dynamics`)."""
    rows, n_cost, n_base = layout.matrix, layout.n_cost, layout.n_base
    mass, bias, force_scale = dynamics.mass, dynamics.bias, dynamics.force_scale
    nv = mass.shape[0]
    for k in range(nv, x.size):
        x[k] *= force_scale
    n_act, n_force = tau.size, x.size - nv
    i = 0
    while i + 3 < n_act:  # four joints at once, each summed in its own order (as below)
        joint = n_base + i
        a0, a1, a2, a3 = bias[joint], bias[joint + 1], bias[joint + 2], bias[joint + 3]
        for j in range(nv):
            value = x[j]
            a0 += mass[j, joint] * value
            a1 += mass[j, joint + 1] * value
            a2 += mass[j, joint + 2] * value
            a3 += mass[j, joint + 3] * value
        for k in range(n_force):
            value = x[nv + k]
            a0 -= rows[n_cost + k, joint] * value
            a1 -= rows[n_cost + k, joint + 1] * value
            a2 -= rows[n_cost + k, joint + 2] * value
            a3 -= rows[n_cost + k, joint + 3] * value
        tau[i], tau[i + 1], tau[i + 2], tau[i + 3] = a0, a1, a2, a3
        i += 4
    for r in range(i, n_act):
        joint = n_base + r
        value = bias[joint]
        for j in range(nv):  # row `joint` of the symmetric, Fortran-ordered mass matrix
            value += mass[j, joint] * x[j]
        for k in range(n_force):
            value -= rows[n_cost + k, joint] * x[nv + k]
        tau[r] = value


@_compile
def base_map(dynamics, contact_rows, base_rhs, factor, solution) -> bool:
    r"""The base rows solved for the base accelerations, :math:`\ddot q_b = X_y y - X_c`:
    ``solution`` :math:`[X_y | X_c] = M_{bb}^{-1} [-M_{ba} \,|\, s J_{cb}^\top \,|\, h_b]`
    (n_base x (n + 1)), with the right-hand side written into ``base_rhs`` and the Cholesky
    factor of :math:`M_{bb}` into ``factor``; ``contact_rows`` holds the contact rows over x.
    False (``base_rhs`` filled, ``solution`` not) if :math:`M_{bb}` is not positive
    definite."""
    mass, bias, force_scale = dynamics.mass, dynamics.bias, dynamics.force_scale
    n_base, width = solution.shape[0], solution.shape[1]
    n_contact = contact_rows.shape[0]
    n_act = width - 1 - n_contact
    for i in range(n_base):
        for j in range(n_act):  # -M_ba, read by columns of the symmetric, Fortran-ordered M
            base_rhs[i, j] = -mass[n_base + j, i]
        for k in range(n_contact):
            base_rhs[i, n_act + k] = force_scale * contact_rows[k, i]
        base_rhs[i, width - 1] = bias[i]
    if not _cholesky(mass[:n_base, :n_base], factor):
        return False
    for j in range(width):
        column = base_rhs[:, j]
        for i in range(n_base):
            solution[i, j] = column[i]
        _forward(factor, solution[:, j])
        _backward(factor, solution[:, j])
    return True


@_compile
def map_rows(used, n_cost, row_scale, solution, mapped):
    r"""The rows :math:`[A_b | A_y | t]` of ``used`` (task and base-regularisation rows,
    then contact rows) over y, :math:`[A_y + A_b X_y \,|\, t + A_b X_c]` with ``solution``
    :math:`[X_y | X_c]` of :func:`base_map` (no rows on a fixed base), the first ``n_cost``
    scaled by ``row_scale``, into ``mapped``."""
    n_base, width = solution.shape[0], solution.shape[1]
    for r in range(used.shape[0]):
        scale = row_scale[r, 0] if r < n_cost else 1.0
        for j in range(width):
            value = used[r, n_base + j]
            for b in range(n_base):
                value += used[r, b] * solution[b, j]
            mapped[r, j] = scale * value


@_compile
def torque_rows(dynamics, base_map, contact, torque_limit, bounds, torque, in_matrix, lower, upper):
    r"""The torques as rows over y, :math:`\tau = [M_{ab} X_y + [M_{aa} \,|\,
    -s J_{ca}^\top] \,|\, M_{ab} X_c - h_a]` with :math:`\ddot q_b = X_y y - X_c`
    (``base_map`` :math:`[X_y | X_c]`, n_base x (n + 1); none on a fixed base), into
    ``torque``; their limits as rows ``[0, n_act)`` of the inequality rows ``in_matrix``,
    ``lower``, ``upper``, followed by the acceleration bounds of ``bounds`` (a
    :class:`JointBounds`, clipped to :math:`\pm 10^{20}`, proxsuite's "no bound").
    ``contact`` holds :math:`J_{ca}` (the contact rows over the actuated joints)."""
    mass, bias, force_scale = dynamics.mass, dynamics.bias, dynamics.force_scale
    n_base = base_map.shape[0]
    n_act, n = torque.shape[0], torque.shape[1] - 1
    for i in range(n_act):
        a = n_base + i
        for j in range(n + 1):
            value = 0.0
            for b in range(n_base):  # M_ab: row a of the symmetric, Fortran-ordered matrix
                value += mass[b, a] * base_map[b, j]
            torque[i, j] = value
        for j in range(n_act):
            torque[i, j] += mass[n_base + j, a]
        for k in range(n - n_act):
            torque[i, n_act + k] -= force_scale * contact[k, i]
        torque[i, n] -= bias[a]
        for j in range(n):
            in_matrix[i, j] = torque[i, j]
        lower[i] = torque[i, n] - torque_limit[i]
        upper[i] = torque[i, n] + torque_limit[i]
    for j in range(bounds.lower.size):
        lower[n_act + j] = min(max(bounds.lower[j], -1e20), 1e20)
        upper[n_act + j] = min(max(bounds.upper[j], -1e20), 1e20)


@_compile
def eliminated_torque_rows(
    layout, dynamics, split, torque_limit, bounds, torque, in_matrix, lower, upper, cone_upper
):  # fmt: skip
    r"""The torque-limit and acceleration-bound rows over the nonbasic unknowns z of
    :func:`eliminate` (:math:`x_B = U_c - U_N z`), for the QP over z with every inequality
    row (no equality rows: the base and contact rows are eliminated).

    The torques over x are :math:`\tau = T x + h_a`, :math:`T = [M_a \,|\, -s J_{c,a}^\top]`
    (:func:`torques`), so over z :math:`\tau = (T_N - T_B U_N) z + T_B U_c + h_a`; written
    into ``torque`` ([rows | constant], n_act x (n_z + 1)) and as rows ``[0, n_act)`` of
    ``in_matrix``, ``lower``, ``upper`` with the limits :math:`\pm\tau_{max}` moved by the
    constant. Then the acceleration bounds of ``bounds`` (:class:`JointBounds`, clipped to
    :math:`\pm 10^{20}`, proxsuite's "no bound"): a nonbasic joint's row is its unit row, a
    basic joint's :math:`-U_{N,b}` with the bounds moved by :math:`-U_{c,b}`. The cone rows
    that follow in ``in_matrix`` are constant; their upper bounds are copied from
    ``cone_upper`` (a contact's normal-force limit changes during a transition)."""
    rows, n_cost, nv, n_base = layout.matrix, layout.n_cost, layout.nv, layout.n_base
    mass, bias, force_scale = dynamics.mass, dynamics.bias, dynamics.force_scale
    basic, nonbasic, elimination = split.basic, split.nonbasic, split.elimination
    n_con, n_z = basic.size, nonbasic.size - 1
    n_act = torque.shape[0]
    for i in range(n_act):
        a = n_base + i
        constant = bias[a]
        for j in range(n_z):  # T_N, T_B U_N subtracted below
            column = nonbasic[j]
            if column < nv:  # row a of the symmetric, Fortran-ordered mass matrix
                torque[i, j] = mass[column, a]
            else:
                torque[i, j] = -force_scale * rows[n_cost + column - nv, a]
        for b in range(n_con):
            column = basic[b]
            if column < nv:
                coefficient = mass[column, a]
            else:
                coefficient = -force_scale * rows[n_cost + column - nv, a]
            if coefficient != 0.0:
                for j in range(n_z):
                    torque[i, j] -= coefficient * elimination[b, j]
                constant += coefficient * elimination[b, n_z]
        torque[i, n_z] = constant
        for j in range(n_z):
            in_matrix[i, j] = torque[i, j]
        lower[i] = -torque_limit[i] - constant
        upper[i] = torque_limit[i] - constant
    v_index = bounds.v_index
    for k in range(v_index.size):
        row = n_act + k
        low = min(max(bounds.lower[k], -1e20), 1e20)
        high = min(max(bounds.upper[k], -1e20), 1e20)
        for j in range(n_z):
            in_matrix[row, j] = 0.0
        shift = 0.0
        for j in range(n_z):
            if nonbasic[j] == v_index[k]:
                in_matrix[row, j] = 1.0
        for b in range(n_con):
            if basic[b] == v_index[k]:
                for j in range(n_z):
                    in_matrix[row, j] = -elimination[b, j]
                shift = elimination[b, n_z]
        # a missing bound (+-1e20) stays missing
        lower[row] = low - shift if low > -1e20 else low
        upper[row] = high - shift if high < 1e20 else high
    first = n_act + v_index.size
    for c in range(cone_upper.size):
        upper[first + c] = cone_upper[c]


@_compile
def eliminated_tick(layout, dynamics, split, costs, checks, q, v, x, tau) -> int:
    """One tick without inequality rows on the eliminated QP: :func:`eliminate` and
    :func:`reduce_costs`, the Cholesky solve for z, the cone check, :func:`expand` and
    :func:`torques` with the torque-limit and acceleration-bound check (:func:`feasible`),
    all as in :class:`Checks`.

    Returns SOLVED, CONES_VIOLATED (z, x and the torques are filled), LIMITS_VIOLATED,
    ILL_CONDITIONED (nothing is solved) or CHOLESKY_FAILED (Hessian not positive definite or
    solution not finite; Hessian and gradient are filled).
    """
    if not eliminate(layout, dynamics, split):
        return ILL_CONDITIONED
    reduce_costs(layout, split, costs)
    z, cone_matrix, cone_upper = checks.z, checks.cone_matrix, checks.cone_upper
    if not cholesky_solve(costs.hessian, checks.factor, costs.gradient, z):
        return CHOLESKY_FAILED
    expand(split, z, x)
    torques(layout, dynamics, x, tau)
    for i in range(cone_matrix.shape[0]):
        value = 0.0
        for j in range(z.size):
            value += cone_matrix[i, j] * z[j]
        if value > cone_upper[i]:
            return CONES_VIOLATED
    if feasible(tau, checks.torque_limit, x, checks.bounds, q, v, checks.margin):
        return SOLVED
    return LIMITS_VIOLATED


@_compile
def _kkt_solve(problem, at_upper, rows, n_active, kkt, rhs, regularization, previous) -> bool:
    r"""Assemble the KKT matrix of the equality rows and the active rows ``rows[:n_active]``
    of ``problem`` (a :class:`QpArrays`) in ``kkt`` and solve it into ``rhs``: x, then the
    multipliers :math:`\nu`. With ``regularization`` :math:`\delta > 0`, the proximal system

    .. math:: \begin{bmatrix} H & E^\top \\ E & -\delta I \end{bmatrix}
              \begin{bmatrix} x \\ \nu \end{bmatrix} = \begin{bmatrix} -g \\ e - \delta
              \nu_{prev} \end{bmatrix}

    with :math:`\nu_{prev}` = ``previous``, which is regular for dependent rows too. False if
    the matrix is singular or the result not finite."""
    hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper = problem
    n, n_eq = hessian.shape[0], eq_matrix.shape[0]
    size = n + n_eq + n_active
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
    if regularization > 0.0:
        for i in range(n, size):
            matrix[i, i] = -regularization
            rhs[i] -= regularization * previous[i]
    return solve_in_place(matrix, rhs[:size])


@_compile
def _dependent_kkt_solve(problem, at_upper, rows, n_active, kkt, rhs, previous) -> bool:
    r"""The KKT solve of :func:`_kkt_solve` for active rows that may be dependent (its
    matrix singular): proximal iterations :math:`\nu_{prev} \leftarrow \nu` of the
    regularised system from :math:`\nu_{prev} = 0`, :math:`\delta = 10^{-12}` of the largest
    Hessian diagonal entry (at least 1). For independent rows each iteration shrinks the
    residual :math:`E x - e` by :math:`\delta / (\delta + \sigma^2)` (:math:`\sigma^2` an
    eigenvalue of :math:`E H^{-1} E^\top`); dependent rows that are consistent keep the
    multipliers they start with. True if after ``_PROXIMAL_STEPS`` the rows hold to 1e-12
    of their scale: then x is the exact optimum over the active rows and :math:`\nu` one of
    its multiplier vectors. Deterministic: the same rows give the same bits."""
    hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper = problem
    n, n_eq = hessian.shape[0], eq_matrix.shape[0]
    size = n + n_eq + n_active
    largest = 1.0
    for j in range(n):
        largest = max(largest, abs(hessian[j, j]))
    regularization = 1e-12 * largest
    previous[:size] = 0.0
    for _ in range(_PROXIMAL_STEPS):
        if not _kkt_solve(problem, at_upper, rows, n_active, kkt, rhs, regularization, previous):
            return False
        previous[n:size] = rhs[n:size]
    for i in range(n_eq + n_active):  # the rows hold?
        value, scale = 0.0, 1.0
        for j in range(n):
            a = eq_matrix[i, j] if i < n_eq else in_matrix[rows[i - n_eq], j]
            value += a * rhs[j]
            scale = max(scale, abs(a * rhs[j]))
        if i < n_eq:
            target = eq_vector[i]
        else:
            row = rows[i - n_eq]
            target = upper[row] if at_upper[row] else lower[row]
        if not abs(value - target) <= 1e-12 * max(scale, abs(target)):
            return False
    return True


_PROXIMAL_STEPS = 4


@_compile
def _cholesky(matrix, factor) -> bool:
    r"""Lower Cholesky factor of the symmetric positive definite ``matrix`` (its lower triangle
    is read) into the lower triangle of ``factor`` (which may be ``matrix``); False if it is
    not positive definite (or holds a NaN).

    Column by column; each entry is :math:`l_{ik} = (a_{ik} - l_{i0} l_{k0} - l_{i1} l_{k1} -
    \dots) / l_{kk}`, summed in that order. The entries of a column are independent, so four
    rows are summed at once, each in its own accumulator: four chains of additions in flight
    instead of one (Talos's 44 x 44 Hessian: 13-14 -> 7-9 us alone), with the bits and the verdict
    (the first non-positive pivot) of one entry at a time.
    """
    n = matrix.shape[0]
    for k in range(n):
        value = matrix[k, k]
        for m in range(k):
            value -= factor[k, m] * factor[k, m]
        if not value > 0.0:  # also NaN
            return False
        pivot = math.sqrt(value)
        factor[k, k] = pivot
        i = k + 1
        while i + 3 < n:
            a0, a1 = matrix[i, k], matrix[i + 1, k]
            a2, a3 = matrix[i + 2, k], matrix[i + 3, k]
            for m in range(k):
                column = factor[k, m]
                a0 -= factor[i, m] * column
                a1 -= factor[i + 1, m] * column
                a2 -= factor[i + 2, m] * column
                a3 -= factor[i + 3, m] * column
            factor[i, k], factor[i + 1, k] = a0 / pivot, a1 / pivot
            factor[i + 2, k], factor[i + 3, k] = a2 / pivot, a3 / pivot
            i += 4
        for r in range(i, n):
            value = matrix[r, k]
            for m in range(k):
                value -= factor[r, m] * factor[k, m]
            factor[r, k] = value / pivot
    return True


@_compile
def _forward(factor, vector):
    """``vector`` := L^-1 ``vector`` for the lower triangle L of ``factor``."""
    _forward_from(factor, vector, 0)


@_compile
def _forward_from(factor, vector, start):
    """:func:`_forward` of a ``vector`` whose entries before ``start`` are zero (they stay
    zero; the same bits as from 0: the skipped terms are exact zeros)."""
    for i in range(start, vector.size):
        value = vector[i]
        for m in range(start, i):
            value -= factor[i, m] * vector[m]
        vector[i] = value / factor[i, i]


@_compile
def _schur_solve(
    problem, at_upper, rows, n_active, factor, shifted, work, schur, rhs, residual
) -> bool:
    r"""The KKT solve of :func:`_kkt_solve` through the Cholesky factor :math:`H = L L^\top`
    (``factor``, made once for all rounds) and the Schur complement of the active rows E:
    with :math:`W = L^{-1} E^\top` and :math:`h = L^{-1} g` (``shifted``),

    .. math:: W^\top W \nu = -(e + W^\top h), \qquad x = -L^{-\top}(h + W \nu),

    about a third of the work of the LU of the whole KKT matrix, then
    ``_REFINEMENT_STEPS`` steps of :func:`_refine`. ``work`` (rows of :math:`W^\top`),
    ``schur`` and ``residual`` (n + m entries) are scratch. False if :math:`W^\top W` is not
    positive definite (dependent active rows) or the result not finite."""
    hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper = problem
    n, n_eq = hessian.shape[0], eq_matrix.shape[0]
    m = n_eq + n_active
    for k in range(m):
        row = work[k]
        if k < n_eq:
            for j in range(n):
                row[j] = eq_matrix[k, j]
            target = eq_vector[k]
        else:
            active = rows[k - n_eq]
            for j in range(n):
                row[j] = in_matrix[active, j]
            target = upper[active] if at_upper[active] else lower[active]
        start = 0  # rows of joint bounds and contact cones start with zeros
        while start < n and row[start] == 0.0:
            start += 1
        _forward_from(factor, row, start)
        value = target
        for j in range(n):
            value += row[j] * shifted[j]
        rhs[n + k] = -value
        for i in range(k + 1):
            other = work[i]
            value = 0.0
            for j in range(n):
                value += row[j] * other[j]
            schur[k, i] = value
    if not _cholesky(schur[:m, :m], schur[:m, :m]):
        return False
    nu = rhs[n : n + m]
    _forward(schur[:m, :m], nu)
    _backward(schur[:m, :m], nu)
    for j in range(n):
        value = shifted[j]
        for k in range(m):
            value += work[k, j] * nu[k]
        rhs[j] = -value
    _backward(factor, rhs[:n])  # L^T x = -(h + W nu)
    for _ in range(_REFINEMENT_STEPS):
        _refine(problem, at_upper, rows, n_active, factor, work, schur, rhs, residual)
    total = 0.0
    for k in range(n + m):
        total += rhs[k]
    return math.isfinite(total)


_REFINEMENT_STEPS = 2


@_compile
def _backward(factor, vector):
    """``vector`` := L^-T ``vector`` for the lower triangle L of ``factor``."""
    n = vector.size
    for i in range(n - 1, -1, -1):
        value = vector[i]
        for k in range(i + 1, n):
            value -= factor[k, i] * vector[k]
        vector[i] = value / factor[i, i]


@_compile
def _refine(problem, at_upper, rows, n_active, factor, work, schur, rhs, residual):
    r"""One step of iterative refinement of the KKT solution (x, :math:`\nu`) in ``rhs``
    by :func:`_schur_solve`'s factors: the residuals :math:`r_1 = -g - H x - E^\top \nu`,
    :math:`r_2 = e - E x` (in ``residual``) and the correction
    :math:`S\,d\nu = W^\top L^{-1} r_1 - r_2`, :math:`dx = L^{-\top}(L^{-1} r_1 - W d\nu)`.
    The Schur complement solve loses accuracy with the condition of H (1e-10 relative for
    Talos's QPs, against 1e-14 for the LU of the KKT matrix); a step recovers it."""
    hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper = problem
    n, n_eq = hessian.shape[0], eq_matrix.shape[0]
    m = n_eq + n_active
    r1, r2 = residual[:n], residual[n : n + m]
    for i in range(n):
        value = -gradient[i]
        for j in range(n):
            value -= hessian[i, j] * rhs[j]
        r1[i] = value
    for k in range(m):
        nu = rhs[n + k]
        if k < n_eq:
            value = eq_vector[k]
            for j in range(n):
                value -= eq_matrix[k, j] * rhs[j]
                r1[j] -= nu * eq_matrix[k, j]
        else:
            active = rows[k - n_eq]
            value = upper[active] if at_upper[active] else lower[active]
            for j in range(n):
                value -= in_matrix[active, j] * rhs[j]
                r1[j] -= nu * in_matrix[active, j]
        r2[k] = value
    _forward(factor, r1)
    for k in range(m):
        value = -r2[k]
        for j in range(n):
            value += work[k, j] * r1[j]
        r2[k] = value
    _forward(schur[:m, :m], r2)
    _backward(schur[:m, :m], r2)
    for j in range(n):
        value = r1[j]
        for k in range(m):
            value -= work[k, j] * r2[k]
        r1[j] = value
    _backward(factor, r1)
    for j in range(n):
        rhs[j] += r1[j]
    for k in range(m):
        rhs[n + k] += r2[k]


@_compile
def active_set(problem, at_upper, at_lower, tolerance, rounds, workspace, x, y, z) -> int:
    r"""Primal-dual active-set iterations (see :func:`dmpopt.control.qp_stages._active_set`)
    as one compiled call: each round solves the KKT system of the active rows through the
    Cholesky factor of H, made once for all rounds, and the Schur complement of the active
    rows (:func:`_schur_solve`); if that fails (dependent active rows, e.g. equality rows
    that are all zero), the KKT matrix is assembled in place in ``workspace`` and solved by
    :func:`solve_in_place`, or if singular by the proximal iterations of
    :func:`_dependent_kkt_solve`.

    ``problem`` holds the fields of a :class:`QpArrays` and ``workspace`` those of a
    :class:`KktWorkspace` (as plain tuples, or those NamedTuples): a flat array
    of at least :math:`(n + n_{eq} + n)^2` entries, arrays of :math:`n + n_{eq} + n`,
    :math:`n_{in}` and :math:`n_{in}` entries, and one of :math:`3 (n + n_{eq} + n)`. On a certified
    optimum ``x``, ``y`` (equality rows) and ``z`` (every inequality row, 0 if inactive)
    receive it and its multipliers. Returns the number of KKT solves, negative if no set
    verified.
    """
    # unpacked by position: plain tuples are passed (numba types them faster than NamedTuples)
    hessian, gradient, eq_matrix, eq_vector, in_matrix, lower, upper = problem
    kkt, rhs, values, rows, previous = workspace
    n, n_eq, n_in = hessian.shape[0], eq_matrix.shape[0], in_matrix.shape[0]
    # kkt holds L (n x n), then the rows of W^T (m_max x n), then W^T W (m_max x m_max), for
    # the Schur solve; the LU fallback overwrites it all (factored = False).
    m_max = n_eq + min(n, n_in)
    factor = kkt[: n * n].reshape(n, n)
    work = kkt[n * n : n * n + m_max * n].reshape(m_max, n)
    schur = kkt[n * n + m_max * n : n * n + m_max * n + m_max * m_max].reshape(m_max, m_max)
    size = n + m_max  # previous: proximal multipliers, then h = L^-1 g, then residuals
    shifted = previous[size : size + n]
    residual = previous[size + n :]
    factored, definite = False, True
    for solves in range(1, rounds + 1):
        n_active = 0
        for i in range(n_in):
            if at_upper[i] or at_lower[i]:
                rows[n_active] = i
                n_active += 1
        if n_active > n:  # dependent active rows, more than the workspace holds
            return -solves
        if definite and not factored:
            factored = definite = _cholesky(hessian, factor)
            if factored:
                for j in range(n):
                    shifted[j] = gradient[j]
                _forward(factor, shifted)
        solved = factored and _schur_solve(
            problem, at_upper, rows, n_active, factor, shifted, work, schur, rhs, residual
        )
        if not solved:  # dependent rows (or H not positive definite): LU of the KKT matrix
            factored = False
            if not _kkt_solve(problem, at_upper, rows, n_active, kkt, rhs, 0.0, previous):
                if not _dependent_kkt_solve(problem, at_upper, rows, n_active, kkt, rhs, previous):
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
