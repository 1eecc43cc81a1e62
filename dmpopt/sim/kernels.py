r"""Compiled per-step kernels of the simulators (numba).

After MuJoCo's own step, :class:`dmpopt.sim.MujocoSimulator` turns MuJoCo's state into
Pinocchio's, reads the contact forces of the feet and measures the base for the fall checks.
In NumPy that is a few dozen calls of about a microsecond each, several times MuJoCo's step
itself; these kernels do each part in one compiled call. The maths is that of
:mod:`dmpopt.sim.mujoco_backend` (coordinates, contacts) and :mod:`dmpopt.sim.falls` (the
watched base frame), where it is described. Each kernel is compiled on first use and cached
on disk (``cache=True``); the simulator calls them once when it is built.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["free_base_measure", "pinocchio_state", "read_contacts", "turn_quaternion"]

_compile = numba.njit(cache=True, nogil=True, error_model="numpy")

# pinocchio_state's outcomes
STATE_OK, STATE_TOO_FAST, STATE_UNSTABLE = 0, 1, 2


@_compile
def pinocchio_state(qpos, qvel, qpos_index, dof_index, quaternion_start, max_speed, warnings):
    """Pinocchio's ``(q, v)`` of MuJoCo's ``(qpos, qvel)``, and a status: ``STATE_UNSTABLE``
    if any of ``warnings`` (counts of MuJoCo's instability warnings) is non-zero, else
    ``STATE_TOO_FAST`` if some ``|qvel_i|`` exceeds ``max_speed`` (or is NaN), else ``STATE_OK``.

    ``q = qpos[qpos_index]``, ``v = qvel[dof_index]``; with a free base (``quaternion_start``
    >= 0: MuJoCo's (w, x, y, z) at ``qpos[quaternion_start:+4]``) the base's linear velocity
    is rotated from the world to the base frame, ``v[:3] = R^T v[:3]``.
    """
    q = np.empty(qpos_index.size)
    v = np.empty(dof_index.size)
    status = STATE_OK
    for count in warnings:
        if count > 0:
            status = STATE_UNSTABLE
    for i in range(qvel.size):
        if not abs(qvel[i]) <= max_speed and status == STATE_OK:
            status = STATE_TOO_FAST
    for i in range(q.size):
        q[i] = qpos[qpos_index[i]]
    for i in range(v.size):
        v[i] = qvel[dof_index[i]]
    if quaternion_start >= 0:
        k = quaternion_start
        rotation = _rotation(qpos[k], qpos[k + 1], qpos[k + 2], qpos[k + 3])
        x, y, z = v[0], v[1], v[2]
        for i in range(3):
            v[i] = rotation[0, i] * x + rotation[1, i] * y + rotation[2, i] * z
    return q, v, status


@_compile
def _rotation(w, x, y, z):
    """Rotation matrix of the quaternion (w, x, y, z), normalised first."""
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    rotation = np.empty((3, 3))
    rotation[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    rotation[0, 1] = 2.0 * (x * y - w * z)
    rotation[0, 2] = 2.0 * (x * z + w * y)
    rotation[1, 0] = 2.0 * (x * y + w * z)
    rotation[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    rotation[1, 2] = 2.0 * (y * z - w * x)
    rotation[2, 0] = 2.0 * (x * z - w * y)
    rotation[2, 1] = 2.0 * (y * z + w * x)
    rotation[2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return rotation


@_compile
def read_contacts(geom, efc_address, frame, position, efc_force, foot_code, foot_points, points):
    """Contact force (world frame) and contact flag of each contact point.

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

    Returns
    -------
    forces : ndarray, shape (n_points, 3)
        Sum of the forces on each point [N]: each contact of a foot geom goes to the nearest
        of its points, with the sign of the force on the foot.
    in_contact : ndarray of bool, shape (n_points,)
    """
    forces = np.zeros(points.shape)
    in_contact = np.zeros(points.shape[0], dtype=np.bool_)
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
    return forces, in_contact


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
    row = np.empty(3)
    for j in range(3):
        row[j] = (
            joint_rotation[2, 0] * rotation[0, j]
            + joint_rotation[2, 1] * rotation[1, j]
            + joint_rotation[2, 2] * rotation[2, j]
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
