"""The drumming and figure-8 demonstrations: task-space patterns mapped to joints by IK."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from dmpopt_robots import load_talos
from scipy.interpolate import CubicSpline

from dmpopt import Trajectory

from .parameters import (
    ARM_JOINTS,
    DRUM_POSTURE_LEFT,
    FIGURE8_PERIOD,
    FIGURE8_SIZE,
    HEIGHT_KEYPOINTS,
    PERIOD,
    PITCH_KEYPOINTS,
    STROKE_HEIGHT,
    STROKE_LOOP,
    WRIST_FLICK,
)


# ----------------------------------------------------------------------------------- robot
def arm_joint_names(side: str) -> tuple[str, ...]:
    """The six DMP-driven joints of one arm, ``side`` in {"left", "right"}."""
    return tuple(f"arm_{side}_{k}_joint" for k in ARM_JOINTS)


DRUM_JOINTS = arm_joint_names("left") + arm_joint_names("right")


def drumming_posture(robot) -> np.ndarray:
    """Half-sitting with the arms in the drumming posture, shape (nq,)."""
    q = np.array(robot.reference_configuration)
    mirror = np.array([-1, -1, -1, 1, -1, -1, 1], dtype=float)
    for side, signs in (("left", np.ones(7)), ("right", mirror)):
        for k in range(7):
            index = robot.configuration_indices([f"arm_{side}_{k + 1}_joint"])[0]
            q[index] = signs[k] * DRUM_POSTURE_LEFT[k]
    return q


# --------------------------------------------------------------------------- demonstration
def _periodic(keypoints: np.ndarray) -> CubicSpline:
    x = np.r_[keypoints[:, 0], 1.0]
    y = np.r_[keypoints[:, 1], keypoints[0, 1]]
    return CubicSpline(x, y, bc_type="periodic")


def stroke(cycle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Wrist offset [m], shape (n, 3), and wrist pitch [rad], shape (n,), of one hand.

    ``cycle`` is the fraction of the period (0 at the strike). The offset is relative to the
    hand position in the drumming posture (world axes: x forward, z up).
    """
    cycle = np.asarray(cycle, dtype=float) % 1.0
    height = _periodic(HEIGHT_KEYPOINTS)(cycle)
    offset = np.zeros((cycle.size, 3))
    offset[:, 0] = STROKE_LOOP * np.sin(2 * np.pi * cycle)
    offset[:, 2] = STROKE_HEIGHT * (height - 0.5)
    pitch = WRIST_FLICK * _periodic(PITCH_KEYPOINTS)(cycle)
    return offset, pitch


def _rotation_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def inverse_kinematics(model, data, q, frame_id, target, q_indices, v_indices, iterations=50):
    """Damped least-squares (Levenberg-Marquardt) IK of one frame's pose, in place on ``q``.

    Returns the final pose error norm (``log6``, metres and radians mixed).
    """
    error_norm = np.inf
    for _ in range(iterations):
        pin.framesForwardKinematics(model, data, q)
        error = pin.log6(data.oMf[frame_id].actInv(target)).vector
        error_norm = float(np.linalg.norm(error))
        if error_norm < 1e-10:
            break
        jacobian = pin.computeFrameJacobian(model, data, q, frame_id, pin.LOCAL)[:, v_indices]
        damping = 1e-6 + 1e-3 * error_norm
        step = np.linalg.solve(
            jacobian.T @ jacobian + damping * np.eye(len(v_indices)), jacobian.T @ error
        )
        q[q_indices] += step
    return error_norm


@dataclass
class Demonstration:
    """The drumming demonstration: joint trajectories and the task-space pattern they realise."""

    joints: Trajectory  # DRUM_JOINTS order, two periods
    hand_targets: np.ndarray  # (n_steps, 2, 3) wrist positions, left then right [m]
    hand_pitch: np.ndarray  # (n_steps, 2) [rad]
    ik_error: float  # largest pose error of the IK [m or rad]


def demonstrate_drumming(n_per_period: int = 250, periods: int = 2) -> Demonstration:
    """Joint-space drumming demonstration from the task-space stroke by inverse kinematics."""
    robot = load_talos("full", fixed_base=True)
    model, data = robot.model, robot.create_data()
    q = drumming_posture(robot)
    pin.framesForwardKinematics(model, data, q)
    frames = [model.getFrameId(f) for f in robot.hand_frames]  # left, right
    nominal = [data.oMf[f].copy() for f in frames]
    times = np.arange(periods * n_per_period + 1) * PERIOD / n_per_period
    cycle = times / PERIOD
    positions = np.empty((times.size, len(DRUM_JOINTS)))
    targets = np.empty((times.size, 2, 3))
    pitches = np.empty((times.size, 2))
    worst = 0.0
    for hand, (side, lag) in enumerate((("left", 0.5), ("right", 0.0))):
        names = arm_joint_names(side)
        q_indices = robot.configuration_indices(names)
        v_indices = robot.velocity_indices(names)
        offsets, pitch = stroke(cycle - lag)
        q_hand = q.copy()
        for k in range(times.size):
            target = pin.SE3(
                _rotation_y(pitch[k]) @ nominal[hand].rotation,
                nominal[hand].translation + offsets[k],
            )
            worst = max(
                worst,
                inverse_kinematics(model, data, q_hand, frames[hand], target, q_indices, v_indices),
            )
            positions[k, 6 * hand : 6 * hand + 6] = q_hand[q_indices]
            targets[k, hand] = target.translation
            pitches[k, hand] = pitch[k]
    return Demonstration(Trajectory.from_positions(times, positions), targets, pitches, worst)


# ---------------------------------------------------------------------------- figure-8
def figure8_demonstration(center: np.ndarray, n_per_period: int = 400, periods: int = 2):
    """Hand positions of a 1:2 Lissajous figure-8 in the frontal (y, z) plane [m]."""
    times = np.arange(periods * n_per_period + 1) * FIGURE8_PERIOD / n_per_period
    angle = 2 * np.pi * times / FIGURE8_PERIOD
    positions = np.tile(np.asarray(center, dtype=float), (times.size, 1))
    positions[:, 1] += FIGURE8_SIZE[0] * np.sin(angle)
    positions[:, 2] += FIGURE8_SIZE[1] * np.sin(2 * angle)
    return Trajectory.from_positions(times, positions)
