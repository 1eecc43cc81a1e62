"""Time-optimal retiming: limits respected, same path, faster than uniform scaling."""

import numpy as np
import pinocchio as pin
import pytest

from dmpopt.exceptions import InvalidInputError
from dmpopt.fitting.constrained import ViaPoint
from dmpopt.fitting.minimum_jerk import minimum_jerk_via_points
from dmpopt.metrics import path_distance
from dmpopt.retiming import retime, time_scaled, uniform_time_scaling


def plan():
    return minimum_jerk_via_points(
        [0.0, 0.0], [1.0, 0.5], 1.0, [ViaPoint(0.5, [0.3, 0.9])], n_samples=301
    )


def planar_arm():
    """Two revolute joints about z, unit links with point masses, gravity along -y."""
    model = pin.Model()
    parent = 0
    for i in range(2):
        placement = pin.SE3(np.eye(3), np.array([1.0 if i else 0.0, 0.0, 0.0]))
        parent = model.addJoint(parent, pin.JointModelRZ(), placement, f"joint{i}")
        inertia = pin.Inertia.FromSphere(1.0, 0.05)
        at_tip = pin.SE3(np.eye(3), np.array([1.0, 0, 0]))
        model.appendBodyToJoint(parent, inertia.se3Action(at_tip), pin.SE3.Identity())
    model.gravity.linear = np.array([0.0, -9.81, 0.0])
    return model


def test_retimed_plan_respects_limits_and_follows_the_path():
    """Velocity and acceleration limits hold on the dense result; the path is unchanged."""
    original = plan()
    velocity = np.array([1.0, 1.5])
    acceleration = np.array([4.0, 6.0])
    result = retime(original, velocity, acceleration, dt=0.002)
    traj = result.trajectory
    assert np.all(np.abs(traj.velocities) <= velocity * (1 + 1e-9))
    assert np.all(np.abs(traj.accelerations) <= acceleration * (1 + 1e-9))
    assert path_distance(traj.positions, original.positions) < 1e-3
    np.testing.assert_allclose(traj.positions[[0, -1]], original.positions[[0, -1]], atol=1e-9)
    uniform = uniform_time_scaling(original, velocity, acceleration) * original.duration
    assert result.duration <= uniform


def test_uniform_scaling_makes_the_limits_exactly_tight():
    """After the returned factor the binding limit is reached exactly."""
    original = plan()
    factor = uniform_time_scaling(original, [1.0, 1.5], [4.0, 6.0])
    scaled = time_scaled(original, factor)
    use = max(
        np.max(np.abs(scaled.velocities) / [1.0, 1.5]),
        np.max(np.abs(scaled.accelerations) / [4.0, 6.0]),
    )
    np.testing.assert_allclose(use, 1.0, rtol=1e-12)


def test_torque_limits_hold_on_a_pinocchio_arm():
    """rnea torques of the retimed plan stay within the limits (and gravity fits)."""
    model = planar_arm()
    data = model.createData()
    original = plan()
    limit = np.array([60.0, 25.0])
    result = retime(original, robot=model, torque_limit=limit, dt=0.002)
    traj = result.trajectory
    torques = np.array(
        [
            pin.rnea(model, data, q, v, a)
            for q, v, a in zip(traj.positions, traj.velocities, traj.accelerations)
        ]
    )
    assert np.all(np.abs(torques) <= limit * (1 + 1e-6))
    uniform = uniform_time_scaling(original, robot=model, torque_limit=limit) * original.duration
    assert result.duration <= uniform * (1 + 1e-6)


def test_missing_limits_are_refused():
    """Retiming without any limit is an error."""
    with pytest.raises(InvalidInputError, match="give at least one of"):
        retime(plan())
