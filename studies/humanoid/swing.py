"""The discrete movement: a forehand of the right arm, learned from a demonstration.

A demonstration of six arm joints (two overlapping minimum-jerk submovements: backswing, then
a faster forward swing with follow-through) is learned by one multi-DOF discrete DMP
(:func:`dmpopt.fit_discrete` with its defaults: one canonical system for all joints) and
executed by the standing robot through the same QP controller as the drumming. The same DMP
is then sent to a new goal: the follow-through posture whose hand is ``SWING_FINISH_RAISE``
higher.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dmpopt import DiscreteDMP, Trajectory, fit_discrete

from .controller import build_controller
from .demos import DRUM_JOINTS, arm_joint_names, drumming_posture
from .loop import RunLog, _closed_loop
from .metrics import rms
from .parameters import (
    ARM_JOINTS,
    DT,
    SWING_BACK,
    SWING_BACK_SECONDS,
    SWING_FINISH_RAISE,
    SWING_FOLLOW,
    SWING_FORWARD_SECONDS,
    SWING_FORWARD_START,
)

SWING_JOINTS = arm_joint_names("right")
POSITIONING_JOINTS = SWING_JOINTS[:4]  # shoulder and elbow place the hand for the new goal


def minimum_jerk(times, duration: float) -> np.ndarray:
    """Minimum-jerk progress ``10 s^3 - 15 s^4 + 6 s^5``, ``s = clip(t / duration, 0, 1)``."""
    s = np.clip(np.asarray(times, dtype=float) / duration, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


def swing_keyframes(robot) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ready (the drumming posture's right arm), backswing and follow-through, ``SWING_JOINTS``."""
    ready = drumming_posture(robot)[robot.configuration_indices(list(SWING_JOINTS))]
    columns = [k - 1 for k in ARM_JOINTS]
    return ready, np.asarray(SWING_BACK)[columns], np.asarray(SWING_FOLLOW)[columns]


def demonstrate_swing(robot, dt: float = 0.002) -> Trajectory:
    """The forehand demonstration of ``SWING_JOINTS`` [rad], starting and ending at rest.

    ``ready + (back - ready) m(t; T1) + (follow - back) m(t - t2; T2)`` with ``m`` the
    minimum-jerk progress: the forward swing (``T2``) starts before the backswing (``T1``)
    ends, so the hand turns without stopping.
    """
    ready, back, follow = swing_keyframes(robot)
    end = SWING_FORWARD_START + SWING_FORWARD_SECONDS
    times = np.arange(int(round(end / dt)) + 1) * dt
    positions = (
        ready
        + np.outer(minimum_jerk(times, SWING_BACK_SECONDS), back - ready)
        + np.outer(minimum_jerk(times - SWING_FORWARD_START, SWING_FORWARD_SECONDS), follow - back)
    )
    return Trajectory.from_positions(times, positions)


def learn_swing(demo: Trajectory) -> DiscreteDMP:
    """The library's default discrete fit: 30 bases per joint, one canonical system."""
    return fit_discrete(demo)


class HandKinematics:
    """World and pelvis-frame positions of the right hand for given configurations."""

    def __init__(self, robot):
        self.robot = robot
        self.data = robot.create_data()
        self.hand = robot.model.getFrameId(robot.hand_frames[1])
        self.pelvis = robot.model.getFrameId("base_link")
        self.arm = robot.configuration_indices(list(SWING_JOINTS))

    def __call__(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(world position, position in the pelvis frame) of the hand [m]."""
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        world = self.data.oMf[self.hand].translation.copy()
        return world, self.data.oMf[self.pelvis].actInv(world)

    def plan(self, q_start: np.ndarray, arm_positions: np.ndarray) -> np.ndarray:
        """World hand positions (n, 3) of the arm plan on the start posture (body still)."""
        q = q_start.copy()
        path = np.empty((len(arm_positions), 3))
        for k, arm in enumerate(arm_positions):
            q[self.arm] = arm
            path[k] = self(q)[0]
        return path


def raised_goal(robot, dmp: DiscreteDMP, raise_m: float = SWING_FINISH_RAISE) -> np.ndarray:
    """The follow-through posture with the hand ``raise_m`` higher (same x, y) [rad].

    Gauss-Newton on the hand position over the shoulder and elbow (``POSITIONING_JOINTS``),
    the wrist as in the demonstrated goal.
    """
    kinematics = HandKinematics(robot)
    q = drumming_posture(robot)
    q[kinematics.arm] = dmp.goal
    target = kinematics(q)[0] + np.array([0.0, 0.0, raise_m])
    columns = robot.velocity_indices(list(POSITIONING_JOINTS))
    rows = robot.configuration_indices(list(POSITIONING_JOINTS))
    for _ in range(50):
        error = target - kinematics(q)[0]
        if np.linalg.norm(error) < 1e-9:
            break
        jacobian = pin.computeFrameJacobian(
            robot.model, kinematics.data, q, kinematics.hand, pin.LOCAL_WORLD_ALIGNED
        )[:3, columns]
        q[rows] += np.linalg.lstsq(jacobian, error, rcond=None)[0]
    return q[kinematics.arm]


def run_swing(
    robot, dmp: DiscreteDMP, duration: float, compile=False, build_options=None, **loop
) -> RunLog:
    """Swing the right arm with ``dmp`` for ``duration`` [s] while standing (or fixed base).

    The arm plan feeds the drumming controller's arm posture task (the left arm held at the
    drumming posture). ``extras`` holds the hand's world and pelvis-frame positions each
    tick (``hand_world``, ``hand_pelvis``), and the start configuration (``q_start``).
    ``loop`` as in :func:`dmpopt_studies.humanoid.loop.run_drumming`.
    """
    q_start = drumming_posture(robot)
    arm = robot.configuration_indices(list(SWING_JOINTS))
    q_start[arm] = dmp.start
    v_start = np.zeros(robot.nv)
    v_start[robot.velocity_indices(list(SWING_JOINTS))] = dmp.start_velocity
    controller, task = build_controller(robot, q_start, **(build_options or {}))
    drum = robot.configuration_indices(list(DRUM_JOINTS))
    right = [DRUM_JOINTS.index(name) for name in SWING_JOINTS]
    position, velocity, acceleration = q_start[drum], np.zeros(len(drum)), np.zeros(len(drum))
    stepper = dmp.stepper(DT, compile=compile)
    kinematics = HandKinematics(robot)
    hands, ticks = [], []

    def reference():
        if ticks:
            stepper.step()
        ticks.append(None)
        position[right], velocity[right] = stepper.position, stepper.velocity
        acceleration[right] = stepper.acceleration
        task.set_reference(position, velocity, acceleration)
        return stepper.position.copy()

    def measure(q, data):
        hands.append(kinematics(q))
        return q[arm]

    log = _closed_loop(
        robot, q_start, v_start, controller, reference, measure, duration, None, **loop
    )
    log.extras["hand_world"] = np.array([h[0] for h in hands[: log.times.size]])
    log.extras["hand_pelvis"] = np.array([h[1] for h in hands[: log.times.size]])
    log.extras["q_start"] = q_start
    return log


@dataclass
class SwingRun:
    """One executed swing and its plan's hand path."""

    dmp: DiscreteDMP
    log: RunLog
    plan_hand: np.ndarray  # (n, 3) world hand path of the plan, body at the start posture [m]


def executed_swing(robot, dmp: DiscreteDMP, duration: float, **options) -> SwingRun:
    """Run ``dmp`` on ``robot`` (:func:`run_swing`) with the plan's hand path beside it."""
    log = run_swing(robot, dmp, duration, **options)
    plan_hand = HandKinematics(robot).plan(log.extras["q_start"], log.desired)
    return SwingRun(dmp, log, plan_hand)


def _speed(path: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.gradient(path, DT, axis=0), axis=1)


def swing_run_metrics(robot, run: SwingRun) -> dict:
    """Tracking, hand path, speed, balance and limits of one executed swing."""
    log, plan_hand = run.log, run.plan_hand
    error = log.actual - log.desired
    hand = log.extras["hand_world"]
    start_kinematics = HandKinematics(robot)
    q_plan = log.extras["q_start"].copy()
    plan_pelvis = np.empty_like(plan_hand)
    for k, arm in enumerate(log.desired):
        q_plan[start_kinematics.arm] = arm
        plan_pelvis[k] = start_kinematics(q_plan)[1]
    path_error = np.linalg.norm(hand - plan_hand, axis=1)
    arm_error = np.linalg.norm(log.extras["hand_pelvis"] - plan_pelvis, axis=1)
    plan_speed, speed = _speed(plan_hand), _speed(hand)
    velocity = np.gradient(log.actual, DT, axis=0)
    v_limit = robot.model.velocityLimit[robot.velocity_indices(list(SWING_JOINTS))]
    com = log.com - log.com[0]
    return {
        "fell": log.fell,
        "diverged": log.diverged,
        "simulated_s": log.duration,
        "joint_tracking_rms_rad": float(rms(error)),
        "joint_tracking_max_rad": float(np.abs(error).max()),
        "hand_path_rms_mm": float(1e3 * rms(path_error)),
        "hand_path_max_mm": float(1e3 * path_error.max()),
        "hand_path_in_pelvis_frame_rms_mm": float(1e3 * rms(arm_error)),
        "hand_path_in_pelvis_frame_max_mm": float(1e3 * arm_error.max()),
        "peak_hand_speed_m_s": float(speed.max()),
        "peak_hand_speed_plan_m_s": float(plan_speed.max()),
        "contact_point_m": hand[int(np.argmax(speed))],
        "contact_point_plan_m": plan_hand[int(np.argmax(plan_speed))],
        "finish_m": hand[-1],
        "finish_plan_m": plan_hand[-1],
        "com_excursion_mm": 1e3 * np.ptp(log.com, axis=0),
        "com_displacement_max_mm": float(1e3 * np.linalg.norm(com, axis=1).max()),
        "joint_speed_peak_fraction_of_limit": float((np.abs(velocity) / v_limit).max()),
        "torque_limit_use_max": float(log.torque_use.max()),
    }


def swing_metrics(robot, demo: Trajectory, runs: dict) -> dict:
    """The ``discrete_swing`` object: the demonstrated goal's run first, the new goal's after.

    ``runs`` maps "demonstrated_goal" and "new_goal" to :class:`SwingRun`.
    """
    dmp = runs["demonstrated_goal"].dmp
    reproduction = dmp.rollout(demo.duration, demo.times[1] - demo.times[0])
    demonstrated = swing_run_metrics(robot, runs["demonstrated_goal"])
    moved = swing_run_metrics(robot, runs["new_goal"])
    moved["finish_raise_plan_mm"] = 1e3 * (
        moved["finish_plan_m"][2] - demonstrated["finish_plan_m"][2]
    )
    moved["finish_raise_executed_mm"] = 1e3 * (moved["finish_m"][2] - demonstrated["finish_m"][2])
    moved["contact_height_change_mm"] = 1e3 * (
        moved["contact_point_m"][2] - demonstrated["contact_point_m"][2]
    )
    moved["goal_rad"] = runs["new_goal"].dmp.goal
    return {
        **demonstrated,
        "fell": demonstrated["fell"] or moved["fell"],
        "joints": list(SWING_JOINTS),
        "n_basis": dmp.n_basis,
        "goal_scaling": dmp.goal_scaling,
        "demo_duration_s": demo.duration,
        "fit_error_max_rad": float(np.abs(reproduction.positions - demo.positions).max()),
        "demo_peak_joint_speed_fraction_of_limit": float(
            (
                np.abs(demo.velocities)
                / robot.model.velocityLimit[robot.velocity_indices(list(SWING_JOINTS))]
            ).max()
        ),
        "new_goal": moved,
        "note": "standing Talos in the study's backend; tracking over the six DMP-driven "
        "right-arm joints; hand path error: world hand vs the plan's hand on the start "
        "posture (includes the body's balance motion), and in the pelvis frame (the arm "
        "alone); contact point: hand position at peak hand speed; new goal: the "
        f"follow-through posture with the hand {1e3 * SWING_FINISH_RAISE:.0f} mm higher",
    }
