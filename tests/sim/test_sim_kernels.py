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
    FALL_MARGIN,
    STATE_OK,
    STATE_TOO_FAST,
    STATE_UNSTABLE,
    _reaches,
    apply_torques,
    composite_base_measure,
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


PARTS = [pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ,
         pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ]  # fmt: skip


def _placement(rng) -> pin.SE3:
    quaternion = rng.normal(size=4)
    return pin.SE3(pin.Quaternion(*(quaternion / np.linalg.norm(quaternion))), rng.normal(size=3))


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(0, 5), min_size=1, max_size=4), st.integers(0, 2**32 - 1))
def test_composite_base_measure_is_pinocchios_placement(axes, seed):
    """Height, tilt cosine and spin of a frame on a composite of one-axis joints with random
    placements, as BaseFrame.measure (Pinocchio's composite joint) gives them."""
    rng = np.random.default_rng(seed)
    composite, parts = pin.JointModelComposite(), []
    for axis in axes:
        placement = _placement(rng)
        composite.addJoint(PARTS[axis](), placement)
        parts.append(np.r_[placement.rotation.ravel(), placement.translation])
    model = pin.Model()
    root = _placement(rng)
    joint = model.addJoint(0, composite, root, "root_joint")
    model.appendBodyToJoint(joint, pin.Inertia.FromSphere(1.0, 0.1), pin.SE3.Identity())
    offset = _placement(rng)
    model.addFrame(pin.Frame("watched", joint, 0, offset, pin.FrameType.OP_FRAME))
    q, v = rng.normal(size=len(axes)), rng.normal(size=len(axes))
    placement, spin = BaseFrame(model, "watched").measure(q, v)
    height, cosine, spin_norm = composite_base_measure(
        q, v, np.array(axes), np.array(parts),
        np.r_[root.rotation.ravel(), root.translation],
        np.r_[offset.rotation.ravel(), offset.translation],
    )  # fmt: skip
    assert abs(height - placement.translation[2]) < TOLERANCE * (1 + abs(height))
    assert abs(cosine - placement.rotation[2, 2]) < TOLERANCE
    assert abs(spin_norm - spin) < TOLERANCE * (1 + spin)


@settings(max_examples=40, deadline=None)
@given(
    st.integers(0, 3),
    st.lists(st.floats(-50.0, 50.0), min_size=3, max_size=3),
    st.booleans(),
    st.integers(0, 2**32 - 1),
)
def test_applied_torques_are_the_clipped_commands_delay_ticks_late(delay, limits, force, seed):
    """Each tick's torque is the command of ``delay`` ticks before (the first command while
    the line fills), clipped to [-limit, limit] (inf: none), written at the dofs; the base
    force (or zeros) at the base dofs; a non-finite entry writes nothing."""
    rng = np.random.default_rng(seed)
    limit = np.where(np.array(limits) > 0, np.abs(limits), np.inf)
    line, ring = np.zeros((delay, 3)), np.zeros(2, dtype=np.int64)
    dofs = np.array([4, 0, 1, 3, 2])  # base dofs 4, 0; joints 1, 3, 2
    commands = rng.normal(scale=40.0, size=(8, 3))
    for k, tau in enumerate(commands):
        base = rng.normal(size=2) if force else np.zeros(0)
        out = np.full(5, np.nan)
        assert apply_torques(tau, base, limit, line, ring, out, dofs, 2)
        late = commands[max(k - delay, 0)]
        np.testing.assert_array_equal(out[[1, 3, 2]], np.minimum(np.maximum(late, -limit), limit))
        np.testing.assert_array_equal(out[[4, 0]], base if force else 0.0)
    before = line.copy(), ring.copy()
    out = np.zeros(5)
    assert not apply_torques(np.array([0.0, np.nan, 0.0]), np.zeros(0), limit, line, ring, out,
                             dofs, 2)  # fmt: skip
    assert not apply_torques(np.zeros(3), np.array([np.inf, 0.0]), limit, line, ring, out, dofs, 2)
    np.testing.assert_array_equal(out, 0.0)
    np.testing.assert_array_equal(line, before[0])
    np.testing.assert_array_equal(ring, before[1])


def test_fall_screen_flags_a_bound_it_reaches_or_nearly_reaches():
    """value > bound, or within FALL_MARGIN (relative) below it: checked exactly by the
    simulator; clearly below: not; an infinite bound: exactly."""
    for bound in (0.7, -3.0, 5.718):
        near = bound - 0.5 * FALL_MARGIN * (1 + abs(bound))
        assert _reaches(np.nextafter(bound, np.inf), bound)
        assert _reaches(bound, bound)
        assert _reaches(near, bound)
        assert not _reaches(bound - 2 * FALL_MARGIN * (1 + abs(bound)), bound)
    assert not _reaches(1e300, np.inf) and _reaches(-1e300, -np.inf)
