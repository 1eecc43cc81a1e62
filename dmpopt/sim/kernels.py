r"""Compiled per-step kernels of the simulators (numba).

Around MuJoCo's own step, :class:`dmpopt.sim.MujocoSimulator` writes the plant's torques
(saturation, delay: :func:`apply_torques`), then turns MuJoCo's state into Pinocchio's, reads
the contact forces of the feet, makes the tick's sensor noise and screens the base for a fall.
In NumPy that is a few dozen calls of about a microsecond each, several times MuJoCo's step
itself; here it is :func:`apply_torques` before ``mj_step`` and :func:`settle` after it, which
write into buffers the simulator allocates once (returning new arrays from a compiled call
costs about a microsecond each), both inside the one compiled call that also makes MuJoCo's
step (:func:`dmpopt.sim.kernels_mujoco.advance`), or around the ``mj_step`` of MuJoCo's
Python bindings. The maths is that of
:mod:`dmpopt.sim.mujoco_backend` (coordinates, contacts), :mod:`dmpopt.sim.plant` (the
plant) and :mod:`dmpopt.sim.falls` (the watched base frame), where it is described; the fall
screen flags a step whose measures reach a threshold or come within ``FALL_MARGIN`` of one,
and the simulator then decides with :meth:`dmpopt.sim.falls.FallDetector.check` on the
reference measures, so the compiled measures never decide a fall on their own. Each kernel
is compiled on first use and cached on disk (``cache=True``); the simulator calls them once
when it is built.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "add_noise",
    "apply_torques",
    "composite_base_measure",
    "free_base_measure",
    "pinocchio_state",
    "read_contacts",
    "scale_noise",
    "settle",
    "state_status",
    "to_pinocchio",
    "turn_quaternion",
]

_compile = numba.njit(cache=True, nogil=True, error_model="numpy")

# pinocchio_state's outcomes
STATE_OK, STATE_TOO_FAST, STATE_UNSTABLE = 0, 1, 2


@_compile
def pinocchio_state(qpos, qvel, qpos_index, dof_index, quaternion_start, max_speed, warnings):
    """Pinocchio's ``(q, v)`` of MuJoCo's ``(qpos, qvel)`` (new arrays, :func:`to_pinocchio`),
    and the status of :func:`state_status`."""
    q = np.empty(qpos_index.size)
    v = np.empty(dof_index.size)
    status = state_status(qvel, max_speed, warnings)
    to_pinocchio(qpos, qvel, qpos_index, dof_index, quaternion_start, q, v)
    return q, v, status


@_compile
def state_status(qvel, max_speed, warnings):
    """``STATE_UNSTABLE`` if any of ``warnings`` (counts of MuJoCo's instability warnings) is
    non-zero, else ``STATE_TOO_FAST`` if some ``|qvel_i|`` exceeds ``max_speed`` (or is NaN),
    else ``STATE_OK``."""
    for count in warnings:
        if count > 0:
            return STATE_UNSTABLE
    for i in range(qvel.size):
        if not abs(qvel[i]) <= max_speed:
            return STATE_TOO_FAST
    return STATE_OK


@_compile
def to_pinocchio(qpos, qvel, qpos_index, dof_index, quaternion_start, q, v):
    """Write Pinocchio's ``(q, v)`` of MuJoCo's ``(qpos, qvel)`` into ``q`` and ``v``.

    ``q = qpos[qpos_index]``, ``v = qvel[dof_index]``; with a free base (``quaternion_start``
    >= 0: MuJoCo's (w, x, y, z) at ``qpos[quaternion_start:+4]``) the base's linear velocity
    is rotated from the world to the base frame, ``v[:3] = R^T v[:3]``.
    """
    for i in range(q.size):
        q[i] = qpos[qpos_index[i]]
    for i in range(v.size):
        v[i] = qvel[dof_index[i]]
    if quaternion_start >= 0:
        k = quaternion_start
        rotation = _rotation(qpos[k], qpos[k + 1], qpos[k + 2], qpos[k + 3])
        x, y, z = v[0], v[1], v[2]
        for i in range(3):
            v[i] = rotation[i] * x + rotation[3 + i] * y + rotation[6 + i] * z


@_compile
def _rotation(w, x, y, z):
    """Rotation matrix of the quaternion (w, x, y, z), normalised first; a tuple, row by
    row."""
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    return (
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    )


@_compile
def read_contacts(
    geom, efc_address, frame, position, efc_force, foot_code, foot_points, points, forces,
    in_contact,
):  # fmt: skip
    """Write the contact force (world frame) and contact flag of each contact point.

    Parameters
    ----------
    geom : int array, shape (n_contacts, 2)
        The two geoms of each MuJoCo contact.
    efc_address : int array, shape (n_contacts,)
        Row of each contact's normal force in ``efc_force`` (tangential forces follow).
    frame : array, shape (n_contacts, 9)
        Each contact's frame, rows: the normal (from geom1 to geom2) and two tangents.
    position : array, shape (n_contacts, 3)
        Each contact's position [m].
    efc_force : array
        MuJoCo's constraint forces (elliptic cones: normal and tangential per contact).
    foot_code : int array, shape (n_geoms,)
        0 for a geom of no foot, else ``1 + k`` with ``foot_points[k]`` that geom's points.
    foot_points : int array, shape (n_feet, width)
        The contact points of each foot geom (a sphere's one point, a sole's corners).
    points : array, shape (n_points, 3)
        World positions of the contact points [m].
    forces : ndarray, shape (n_points, 3)
        Written: the sum of the forces on each point [N]: each contact of a foot geom goes to
        the nearest of its points, with the sign of the force on the foot.
    in_contact : ndarray of bool, shape (n_points,)
        Written: whether some contact went to the point.
    """
    forces[:] = 0.0
    in_contact[:] = False
    for c in range(geom.shape[0]):
        code, sign = foot_code[geom[c, 1]], 1.0
        if code == 0:
            code, sign = foot_code[geom[c, 0]], -1.0  # the foot is geom1: the opposite force
        if code == 0 or efc_address[c] < 0:
            continue
        candidates = foot_points[code - 1]
        point = candidates[0]
        if candidates.size > 1:  # the nearest corner of a sole
            best = np.inf
            for j in range(candidates.size):
                k = candidates[j]
                distance = 0.0
                for i in range(3):
                    distance += (points[k, i] - position[c, i]) ** 2
                if distance < best:
                    best, point = distance, k
        address = efc_address[c]
        for i in range(3):
            total = 0.0
            for j in range(3):
                total += efc_force[address + j] * frame[c, 3 * j + i]
            forces[point, i] += sign * total
        in_contact[point] = True


@_compile
def free_base_measure(q, v, joint_rotation, joint_translation, offset_rotation, offset_translation):
    """Height, cosine of the tilt and spin of a frame on a free-flyer base.

    The frame's world placement is ``J M(q) O`` (``J`` the root joint's placement, ``M(q)``
    the free flyer's: position ``q[:3]``, quaternion ``q[3:7]`` as (x, y, z, w), ``O`` the
    frame on the base); returned: its height (z) [m], the z-z entry of its rotation (the
    cosine of the angle between its z axis and the world's) and the norm of the base's
    angular velocity ``v[3:6]`` [rad/s].
    """
    rotation = _rotation(q[6], q[3], q[4], q[5])
    # row 2 of J_R R: the world z row of the base's rotation
    row = (
        joint_rotation[2, 0] * rotation[0]
        + joint_rotation[2, 1] * rotation[3]
        + joint_rotation[2, 2] * rotation[6],
        joint_rotation[2, 0] * rotation[1]
        + joint_rotation[2, 1] * rotation[4]
        + joint_rotation[2, 2] * rotation[7],
        joint_rotation[2, 0] * rotation[2]
        + joint_rotation[2, 1] * rotation[5]
        + joint_rotation[2, 2] * rotation[8],
    )
    height = joint_translation[2]
    for i in range(3):
        height += joint_rotation[2, i] * q[i]
    cosine = 0.0
    for j in range(3):
        height += row[j] * offset_translation[j]
        cosine += row[j] * offset_rotation[j, 2]
    spin = math.sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5])
    return height, cosine, spin


@_compile
def turn_quaternion(q, rotation_vector, out):
    r"""``out[3:7]``: the free flyer's quaternion ``q[3:7]`` (x, y, z, w) turned by the rotation
    vector ``r`` in the base frame, :math:`q \otimes \exp(r / 2)` (the rotation
    :math:`R \exp(\hat r)`), normalised."""
    angle = math.sqrt(rotation_vector[0] ** 2 + rotation_vector[1] ** 2 + rotation_vector[2] ** 2)
    half = 0.5 * angle
    # sin(half) / angle, by its series below 1e-4 rad (error below angle^4 / 3840)
    scale = math.sin(half) / angle if angle > 1e-4 else 0.5 - angle * angle / 48.0
    bx, by, bz = scale * rotation_vector[0], scale * rotation_vector[1], scale * rotation_vector[2]
    bw = math.cos(half)
    ax, ay, az, aw = q[3], q[4], q[5], q[6]
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    w = aw * bw - ax * bx - ay * by - az * bz
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    out[3], out[4], out[5], out[6] = x / norm, y / norm, z / norm, w / norm


@_compile
def apply_torques(tau, base_force, torque_limit, line, ring, out, dofs, n_base):
    """Write the torques the motors apply for the command ``tau`` into ``out[dofs[n_base:]]``
    and ``base_force`` into ``out[dofs[:n_base]]`` (zeros if ``base_force`` is empty).

    Each torque is saturated, ``min(max(tau_i, -limit_i), limit_i)``, then delayed by the
    rows of ``line`` (a ring of the commands in flight; ``ring`` holds the oldest row and
    whether the line is filled: the first command fills it, so it repeats until the line
    turns over). Returns False, and writes nothing, if ``tau`` or ``base_force`` has a
    non-finite entry.
    """
    for x in tau:
        if not math.isfinite(x):
            return False
    for x in base_force:
        if not math.isfinite(x):
            return False
    delay, slot = line.shape[0], ring[0]
    if delay and not ring[1]:
        for row in range(delay):
            for i in range(tau.size):
                line[row, i] = _saturated(tau[i], torque_limit[i])
        ring[1] = 1
    for i in range(tau.size):
        torque = _saturated(tau[i], torque_limit[i])
        if delay:
            torque, line[slot, i] = line[slot, i], torque
        out[dofs[n_base + i]] = torque
    if delay:
        ring[0] = (slot + 1) % delay
    for k in range(n_base):
        out[dofs[k]] = base_force[k] if base_force.size else 0.0
    return True


@_compile
def _saturated(torque, limit):
    """``min(max(torque, -limit), limit)``, as NumPy's ``maximum`` and ``minimum`` pick."""
    lower = -limit
    torque = torque if torque >= lower else lower
    return torque if torque <= limit else limit


@_compile
def scale_noise(noise, nq, nv, free):
    """This tick's measurement noise from its standard normals, in the plant's ``noise``
    array: ``[normals (nq + nv (+ 3 if free)) | q_std (nq) | v_std (nv) | rotation_std (1) |
    q_noise (nq) | v_noise (nv) | rotation_noise (3)]``; noise = std * normal."""
    n_draws = nq + nv + (3 if free else 0)
    q_std, v_std = n_draws, n_draws + nq
    rotation_std = v_std + nv
    q_noise = rotation_std + 1
    v_noise, rotation_noise = q_noise + nq, q_noise + nq + nv
    for i in range(nq):
        noise[q_noise + i] = noise[q_std + i] * noise[i]
    for i in range(nv):
        noise[v_noise + i] = noise[v_std + i] * noise[nq + i]
    if free:
        for i in range(3):
            noise[rotation_noise + i] = noise[rotation_std] * noise[nq + nv + i]


@_compile
def add_noise(q, v, noise, free, q_measured, v_measured):
    """Write the measured state, the true ``(q, v)`` plus the noise of :func:`scale_noise`
    (a free base's orientation turned by the rotation vector, :func:`turn_quaternion`)."""
    nq, nv = q.size, v.size
    q_noise = nq + nv + (3 if free else 0) + nq + nv + 1
    v_noise = q_noise + nq
    for i in range(nq):
        q_measured[i] = q[i] + noise[q_noise + i]
    for i in range(nv):
        v_measured[i] = v[i] + noise[v_noise + i]
    if free:
        turn_quaternion(q, noise[v_noise + nv : v_noise + nv + 3], q_measured)


@_compile
def composite_base_measure(q, v, axes, parts, placement, offset):
    """Height, cosine of the tilt and spin of a frame on a base moved by a composite of
    one-axis joints (the :func:`free_base_measure` numbers).

    The frame's world placement is ``J P_0 M_0(q_0) P_1 M_1(q_1) ... O`` (``J`` the root
    joint's placement, ``P_i`` the parts' placements, ``M_i`` a translation ``q_i`` along or
    a rotation ``q_i`` about part ``i``'s axis, ``O`` the frame on the base); the spin is the
    norm of the base's angular velocity, the sum of each rotating part's axis times ``v_i``.

    Parameters
    ----------
    axes : int array, shape (n_parts,)
        0, 1, 2: translation along x, y, z; 3, 4, 5: rotation about x, y, z.
    parts : array, shape (n_parts, 12)
        Each part's placement: rotation (row-major) then translation.
    placement, offset : array, shape (12,)
        ``J`` and ``O``, laid out as ``parts``.
    """
    rotation = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)  # row by row
    x = y = z = 0.0  # translation
    spin_x = spin_y = spin_z = 0.0
    for k in range(axes.size):
        part = parts[k]
        x, y, z = (
            x + rotation[0] * part[9] + rotation[1] * part[10] + rotation[2] * part[11],
            y + rotation[3] * part[9] + rotation[4] * part[10] + rotation[5] * part[11],
            z + rotation[6] * part[9] + rotation[7] * part[10] + rotation[8] * part[11],
        )
        rotation = _times(rotation, (part[0], part[1], part[2], part[3], part[4], part[5],
                                     part[6], part[7], part[8]))  # fmt: skip
        axis = axes[k] % 3
        if axes[k] < 3:
            x += rotation[axis] * q[k]
            y += rotation[3 + axis] * q[k]
            z += rotation[6 + axis] * q[k]
            continue
        spin_x += rotation[axis] * v[k]
        spin_y += rotation[3 + axis] * v[k]
        spin_z += rotation[6 + axis] * v[k]
        c, s = math.cos(q[k]), math.sin(q[k])
        if axis == 0:
            turn = (1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
        elif axis == 1:
            turn = (c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
        else:
            turn = (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
        rotation = _times(rotation, turn)
    translation = (x, y, z)
    height = placement[11]
    for i in range(3):
        total = translation[i]
        for j in range(3):
            total += rotation[3 * i + j] * offset[9 + j]
        height += placement[6 + i] * total
    cosine = 0.0
    for i in range(3):
        row = 0.0
        for j in range(3):
            row += placement[6 + j] * rotation[3 * j + i]
        cosine += row * offset[3 * i + 2]
    return height, cosine, math.sqrt(spin_x**2 + spin_y**2 + spin_z**2)


@_compile
def _times(a, b):
    """The product of two rotations given as tuples, row by row."""
    return (
        a[0] * b[0] + a[1] * b[3] + a[2] * b[6],
        a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
        a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
        a[3] * b[0] + a[4] * b[3] + a[5] * b[6],
        a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
        a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
        a[6] * b[0] + a[7] * b[3] + a[8] * b[6],
        a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
        a[6] * b[2] + a[7] * b[5] + a[8] * b[8],
    )


# settle's packed arrays (built by MujocoSimulator): the header of ``tables``
(
    N_Q, N_V, N_POINTS, N_GEOMS, N_FEET, WIDTH, N_PARTS, QUATERNION_START, BASE, NOISY,
    N_BASE_DOFS,
) = range(11)  # fmt: skip
TABLES_HEADER = 11
BASE_UNCHECKED, BASE_FREE, BASE_COMPOSITE = 0, 1, 2  # fall checks: none, free flyer, composite
CONSTANTS_HEADER = 29  # max_speed, the 4 fall thresholds, placement (12), offset (12)
FALL_MARGIN = 1e-9  # relative: measures this close to a threshold are checked by the caller


@_compile
def settle(
    qpos, qvel, warnings, geom, efc_address, frame, position, efc_force, site_xpos,
    tables, constants, work, flags, noise, time, last_contact_time,
):  # fmt: skip
    """Everything the MuJoCo simulator reads after ``mj_step``, in one call.

    Checks the state (:func:`state_status`; if not ``STATE_OK``, returns at once and writes
    nothing), writes Pinocchio's state (:func:`to_pinocchio`), the contact points' positions
    (``site_xpos`` rows), forces and flags (:func:`read_contacts`) and which points started
    touching, this tick's sensor noise and measured state (:func:`scale_noise`,
    :func:`add_noise`), and screens for a fall.

    Parameters
    ----------
    qpos, qvel, warnings, geom, efc_address, frame, position, efc_force, site_xpos : array
        MuJoCo's (``warnings``: the counts of its instability warnings).
    tables : int array
        ``[header (TABLES_HEADER) | qpos_index (nq) | dof_index (nv) | point_sites (n_points)
        | foot_code (n_geoms) | foot_points (n_feet * width) | part axes (n_parts)]``, the
        header holding the sizes, the quaternion's start in ``qpos`` (-1: no free base), the
        base kind of the fall checks, whether the plant is noisy and the base's dofs.
    constants : float array
        ``[max_speed, min_height, max_tilt, max_flight_time, max_spin | base placement (12) |
        watched frame's offset (12) | parts' placements (12 * n_parts)]``.
    work : float array
        Written: ``[q | v | forces (3 n_points) | positions (3 n_points) | q_measured |
        v_measured]``.
    flags : bool array
        ``[in_contact (n_points) | started (n_points)]``; ``in_contact`` holds the last
        step's flags when called.
    noise : float array
        The plant's noise array (:func:`scale_noise`).
    time, last_contact_time : float
        MuJoCo's time and the end of the last step with a contact (NaN: none yet) [s].

    Returns
    -------
    status : int
    any_contact : bool
    n_started : int
        How many points started touching in this step.
    check_fall : bool
        Whether a fall measure (height, tilt, flight time, spin) is past its threshold, within
        ``FALL_MARGIN`` (relative) of it, or not finite: the caller then checks exactly.
    """
    status = state_status(qvel, constants[0], warnings)
    if status != STATE_OK:
        return status, False, 0, False
    nq, nv, n_points = tables[N_Q], tables[N_V], tables[N_POINTS]
    n_feet, width, n_parts = tables[N_FEET], tables[WIDTH], tables[N_PARTS]
    at = TABLES_HEADER
    qpos_index, dof_index = tables[at : at + nq], tables[at + nq : at + nq + nv]
    at += nq + nv
    point_sites, foot_code = tables[at : at + n_points], tables[at + n_points :]
    at += n_points + tables[N_GEOMS]
    foot_points = tables[at : at + n_feet * width].reshape(n_feet, width)
    axes = tables[at + n_feet * width : at + n_feet * width + n_parts]
    q, v = work[:nq], work[nq : nq + nv]
    at = nq + nv
    forces = work[at : at + 3 * n_points].reshape(n_points, 3)
    positions = work[at + 3 * n_points : at + 6 * n_points].reshape(n_points, 3)
    at += 6 * n_points
    q_measured, v_measured = work[at : at + nq], work[at + nq : at + nq + nv]
    in_contact, started = flags[:n_points], flags[n_points:]

    quaternion_start = tables[QUATERNION_START]
    to_pinocchio(qpos, qvel, qpos_index, dof_index, quaternion_start, q, v)
    for i in range(n_points):
        started[i] = in_contact[i]  # the last step's, for now
        for j in range(3):
            positions[i, j] = site_xpos[point_sites[i], j]
    read_contacts(
        geom, efc_address, frame, position, efc_force, foot_code, foot_points, positions,
        forces, in_contact,
    )  # fmt: skip
    any_contact, n_started = False, 0
    for i in range(n_points):
        started[i] = in_contact[i] and not started[i]
        any_contact |= in_contact[i]
        n_started += started[i]
    if tables[NOISY]:
        free = quaternion_start >= 0
        scale_noise(noise, nq, nv, free)
        add_noise(q, v, noise, free, q_measured, v_measured)

    base = tables[BASE]
    if base == BASE_UNCHECKED:
        return status, any_contact, n_started, False
    if base == BASE_FREE:
        height, cosine, spin = free_base_measure(
            q, v, constants[5:14].reshape(3, 3), constants[14:17],
            constants[17:26].reshape(3, 3), constants[26:29],
        )  # fmt: skip
    else:
        parts = constants[CONSTANTS_HEADER : CONSTANTS_HEADER + 12 * n_parts].reshape(n_parts, 12)
        height, cosine, spin = composite_base_measure(
            q, v, axes, parts, constants[5:17], constants[17:29]
        )
    last = time if any_contact else last_contact_time
    flight_time = 0.0 if math.isnan(last) else time - last
    tilt = math.acos(min(1.0, max(-1.0, cosine)))
    min_height, max_tilt, max_flight_time, max_spin = constants[1:5]
    check_fall = (
        not math.isfinite(height + tilt + flight_time + spin)
        or _reaches(-height, -min_height)
        or _reaches(tilt, max_tilt)
        or _reaches(flight_time, max_flight_time)
        or _reaches(spin, max_spin)
    )
    return status, any_contact, n_started, check_fall


@_compile
def _reaches(value, bound):
    """``value > bound`` up to ``FALL_MARGIN`` (relative to ``bound``; exact for infinite
    bounds)."""
    if math.isinf(bound):
        return value > bound
    return value > bound - FALL_MARGIN * (1.0 + abs(bound))
