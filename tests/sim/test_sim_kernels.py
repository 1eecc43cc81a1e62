"""dmpopt.sim.kernels against Pinocchio and against the formulas written out here.

Each kernel replaces a few NumPy or Pinocchio calls of the simulators' step; the answer keys
are those calls (Pinocchio's SE3 products and exp3) or the contact-force rotation written
plainly. Tolerances: a few float64 roundings of unit-size quantities (1e-12).
"""

import numpy as np
import pinocchio as pin
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.sim.falls import BaseFrame
from dmpopt.sim.kernels import (
    STATE_OK,
    STATE_TOO_FAST,
    STATE_UNSTABLE,
    free_base_measure,
    pinocchio_state,
    read_contacts,
    turn_quaternion,
)

TOLERANCE = 1e-12  # a few roundings of unit-size numbers

vectors = st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).map(np.array)
quaternions = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(
    lambda x: np.linalg.norm(x) > 0.1
)


def _free_flyer_q(position, quaternion) -> np.ndarray:
    coeffs = np.asarray(quaternion, dtype=float)
    return np.r_[position, coeffs / np.linalg.norm(coeffs)]


@settings(max_examples=30, deadline=None)
@given(quaternions, vectors, st.floats(1e-9, 1.0))
def test_turned_quaternion_is_the_rotation_times_exp3(quaternion, axis, size):
    """R(out) = R(q) exp3(r) (Pinocchio), for tiny and large rotation vectors r."""
    q = _free_flyer_q(np.zeros(3), quaternion)
    r = size * axis
    out = q.copy()
    turn_quaternion(q, r, out)
    expected = pin.Quaternion(q[3:7]).toRotationMatrix() @ pin.exp3(r)
    np.testing.assert_allclose(pin.Quaternion(out[3:7]).toRotationMatrix(), expected, atol=1e-12)
    assert abs(np.linalg.norm(out[3:7]) - 1.0) < TOLERANCE


@settings(max_examples=30, deadline=None)
@given(vectors, quaternions, vectors, vectors, quaternions, vectors)
def test_free_base_measure_is_pinocchios_placement(position, quaternion, speed, spin, turn, shift):
    """Height, tilt and spin of a frame on a free flyer, as BaseFrame.measure (Pinocchio's
    joint placement times M(q) times the frame) gives them."""
    model = pin.Model()
    placement = pin.SE3(pin.Quaternion(*_free_flyer_q(np.zeros(3), turn)[[6, 3, 4, 5]]), shift)
    joint = model.addJoint(0, pin.JointModelFreeFlyer(), placement, "root_joint")
    model.appendBodyToJoint(joint, pin.Inertia.FromSphere(1.0, 0.1), pin.SE3.Identity())
    offset = pin.SE3(pin.Quaternion(*_free_flyer_q(np.zeros(3), quaternion)[[6, 3, 4, 5]]), speed)
    model.addFrame(pin.Frame("watched", joint, 0, offset, pin.FrameType.OP_FRAME))
    base = BaseFrame(model, "watched")
    q = _free_flyer_q(position, quaternion)
    v = np.r_[speed, spin]
    placement, expected_spin = base.measure(q, v)
    height, cosine, spin_norm = free_base_measure(
        q, v, model.jointPlacements[1].rotation, model.jointPlacements[1].translation,
        offset.rotation, offset.translation,
    )  # fmt: skip
    assert abs(height - placement.translation[2]) < TOLERANCE
    assert abs(cosine - placement.rotation[2, 2]) < TOLERANCE
    assert abs(spin_norm - np.linalg.norm(spin)) < TOLERANCE
    assert abs(spin_norm - expected_spin) < TOLERANCE


def test_pinocchio_state_permutes_rotates_and_flags():
    """q = qpos[index]; v = qvel[index] with the free base's linear velocity R^T v; the status
    says unstable before too fast, and NaN counts as too fast."""
    rng = np.random.default_rng(0)
    qpos, qvel = rng.normal(size=9), rng.normal(size=8)
    qpos[2:6] /= np.linalg.norm(qpos[2:6])  # MuJoCo's (w, x, y, z) at 2
    qpos_index, dof_index = np.array([0, 1, 7, 3, 4, 5, 2, 8, 6]), np.array([0, 1, 2, 7, 3, 4])
    none = np.zeros(3, dtype=np.int32)
    q, v, status = pinocchio_state(qpos, qvel, qpos_index, dof_index, 2, 10.0, none)
    w, x, y, z = qpos[2:6]
    rotation = pin.Quaternion(w, x, y, z).toRotationMatrix()
    np.testing.assert_array_equal(q, qpos[qpos_index])
    np.testing.assert_allclose(v[:3], rotation.T @ qvel[:3], atol=TOLERANCE)
    np.testing.assert_array_equal(v[3:], qvel[dof_index[3:]])
    assert status == STATE_OK
    qvel[5] = np.nan
    assert pinocchio_state(qpos, qvel, qpos_index, dof_index, 2, 10.0, none)[2] == STATE_TOO_FAST
    warned = np.array([0, 1, 0], dtype=np.int32)
    assert pinocchio_state(qpos, qvel, qpos_index, dof_index, 2, 10.0, warned)[2] == STATE_UNSTABLE


def test_contact_forces_go_to_the_nearest_point_in_the_world_frame():
    """Two soles' contacts and a point foot's: force = sign * frame^T f_local, summed on the
    nearest corner of the sole (the sphere's own point), sign -1 when the foot is geom1."""
    rng = np.random.default_rng(1)
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 5, 0]], dtype=float)
    foot_code = np.array([0, 1, 2, 0])  # geom 0 the floor, 1 a sole, 2 the point foot
    foot_points = np.array([[0, 1, 2, 3], [4, 4, 4, 4]])
    geom = np.array([[0, 1], [0, 1], [1, 0], [0, 2], [0, 3]], dtype=np.int32)
    position = np.array([[0.9, 0.1, 0], [0.95, 0.05, 0], [0.1, 0.8, 0], [5, 5, 0], [9, 9, 0]])
    frames = np.array([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(5)])
    efc_force = rng.normal(size=15)
    efc_address = np.array([0, 3, 6, 9, 12], dtype=np.int32)
    forces, in_contact = np.full((5, 3), np.nan), np.ones(5, dtype=bool)  # overwritten
    read_contacts(
        geom, efc_address, frames.reshape(5, 9), position, efc_force, foot_code, foot_points,
        points, forces, in_contact,
    )  # fmt: skip
    world = [frames[c].T @ efc_force[3 * c : 3 * c + 3] for c in range(5)]
    expected = np.zeros((5, 3))
    expected[1] = world[0] + world[1]  # both nearest to the corner (1, 0)
    expected[2] = -world[2]  # the sole is geom1 here
    expected[4] = world[3]
    np.testing.assert_allclose(forces, expected, atol=TOLERANCE)
    np.testing.assert_array_equal(in_contact, [False, True, True, False, True])
