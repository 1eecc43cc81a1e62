r"""Humanoid drumming and figure-8 with rhythmic DMPs and QP inverse dynamics (Fig. 4, Sec. 4.1).

Claim of [dmpopt-paper] Sections 3.1, 3.6 and 4.1: joint-space rhythmic DMPs learned by
imitation, all on one canonical system, produce bimanual drumming on a humanoid; their desired
positions, velocities and accelerations become torques through an inverse-dynamics model plus
low-gain feedback in real time. Fig. 4 right: changing the amplitude ``A -> 2A``, the time
constant ``tau -> tau / 2`` or the setpoint ``g -> g + 1`` of the right elbow between t = 3 s
and t = 7 s makes the pattern converge quickly to the new limit cycle, with the same shape.

Set-up (all choices are ours):

* robot: Talos (full URDF, 30+ DOFs, nv = 50) standing on its two feet, floating base, 1 ms
  steps, simulated by ``backend``: MuJoCo (default; :class:`dmpopt.sim.MujocoSimulator` from
  the same URDF, a 5 mm sphere at each sole corner on the floor, friction 1, CoM target at
  the start posture) or the native compliant ground (``"native"``: :mod:`dmpopt.sim`,
  semi-implicit Euler, 20 kN/m per sole corner, CoM target lowered by the static
  compression); and the fixed-base upper body (legs and pelvis locked in half-sitting) for
  comparison;
* where the native simulator stays, and why: the fixed-base upper body (a reduced model with
  no URDF of its own, and the controller's timing reference), and one nominal drumming run
  beside MuJoCo's (``native`` in the metrics: tracking, falls and real-time factor of the
  same loop on the other plant, the check that the results do not hang on one contact model);
* MuJoCo scenarios (``mujoco`` in the metrics; each from the drumming start, no change of
  the plan): every link mass and inertia of the controller's model x 0.9 and x 1.1
  (``LINK_MASS_SCALES``); floor friction 0.4 and 0.7 (``FRICTIONS``; the controller's cone
  at ``min(0.7, floor)``); torque limits of the controller at ``TIGHT_TORQUE`` of the
  nominal run's peak use, so that the QP's torque rows bind; forward pushes on the pelvis
  of increasing impulse (``PUSH_LADDER``, then two bisections) until the first fall;
* videos (MuJoCo's offscreen renderer, animated WebP of ``VIDEO_SECONDS``): drumming,
  figure-8 and the largest survived push; skipped in quick mode and without an OpenGL
  context, with the reason in ``videos_skipped``;
* controller: :class:`dmpopt.control.InverseDynamicsController` at 1 kHz (a least-squares
  solve per tick, proxsuite when a friction, CoP or torque row is active) with the
  DMP-driven arm joints as a posture task (plan acceleration as feed-forward, low-gain PD
  ``ARM_STIFFNESS``), a whole-body posture task, and, standing, a CoM task, a pelvis
  orientation task (alternating hands would otherwise roll the pelvis) and two sole contacts;
* drumming demonstration (synthetic, hand-designed, not motion capture): a task-space stick
  stroke per hand -- asymmetric vertical wrist path (quick rebound after the strike, slow
  preparation, fast downstroke), a small fore-aft loop and a wrist flick that leads the
  stroke -- left hand half a period after the right one, mapped to 6 joints per arm
  (shoulder 1-3, elbow 4, wrist 6-7; forearm roll 5 held) by damped least-squares inverse
  kinematics on the full pose of each hand, from a drumming posture with bent elbows (the
  half-sitting straight elbows make vertical hand motions nearly singular);
* DMPs: :func:`dmpopt.fit_rhythmic`, phase oscillator eqs. (11)-(12), 15 basis functions per
  DOF; 11 DOFs on one oscillator and the right elbow on its own one-DOF DMP with the same
  period and start phase, phase-locked to the shared oscillator by a coupling term
  ``ELBOW_PHASE_COUPLING * sin(phi - phi_elbow)`` (switched off while the elbow runs at
  ``tau / 2``), so that ``A``, ``tau`` and ``g`` can change on the elbow alone;
* Fig. 4 right: ``A -> 2A``, ``tau -> tau / 2`` and ``g -> g + 0.1 rad`` (``SETPOINT_SHIFT``;
  ``+1`` of the paper is in unknown units and one radian would leave the joint range) on the
  right elbow from 3 s to 7 s, each in its own standing run; the new A, tau, g are reached
  through a first-order filter (``PARAMETER_FILTER`` = 0.1 s, like the goal filter of
  eq. (10)) because steps in them ask for far more than the 8 N m of the Talos wrist; settle
  times count from the requested change, filter included, to 5 % of the new cycle's range;
* figure-8: a 1:2 Lissajous curve of the right hand in the frontal plane, learned as a
  three-DOF task-space rhythmic DMP and tracked by a hand position task while standing;
* ablations: the controller's model with arms 10 % too heavy (``MASS_ERROR``; the simulator
  and the controller otherwise share the exact model, so tracking is near-perfect), and the
  pelvis orientation task left out.

Quick mode simulates about 40 s in total (3 s of drumming, Fig. 4 runs of 4 s with the change
between 1 s and 3 s, MuJoCo scenarios of 1.5 s, pushes of 10 and 60 N s) and renders no
video.

Run: ``python -m studies.humanoid OUT_DIR [--quick]`` or ``dmpopt study run humanoid``.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicSpline

from dmpopt import RhythmicDMP, Trajectory, fit_rhythmic
from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    PostureTask,
    SoleContact,
)
from dmpopt.exceptions import InvalidInputError, MissingDependency, SimulationDiverged
from dmpopt.sim import GroundContact, Simulator
from robots import load_talos

EXPECTED_SECONDS = {"full": 165, "quick": 90}  # CPU seconds on the 2-core machine (MuJoCo)

DT = 1e-3  # [s] control, DMP and simulation period (1 kHz)
PERIOD = 1.5  # [s] drumming period (one stroke per hand per period; 80 beats per minute)
FIGURE8_PERIOD = 2.0  # [s]
N_BASIS = 15  # basis functions per DOF, as in the paper
ARM_JOINTS = (1, 2, 3, 4, 6, 7)  # Talos arm joints driven by DMPs (6 per arm); 5 is held
ELBOW = "arm_right_4_joint"
CHANGE_START, CHANGE_END = 3.0, 7.0  # [s] Fig. 4 right: modification window
SETPOINT_SHIFT = 0.1  # [rad] "g + 1" of Fig. 4, in a safe unit
ELBOW_PHASE_COUPLING = 2.0  # gain of the elbow's phase lock to the shared oscillator
SETTLE_TOLERANCE = 0.05  # fraction of the new peak-to-peak amplitude
# A, tau and g of the elbow move to their new values through a first-order filter of this
# time constant (like the goal filter of eq. (10)): a step in tau steps the plan's velocity
# and a step in A or g gives plan accelerations of hundreds of rad/s^2 (infinite for tau),
# far beyond the 70 N m elbow and 8 N m wrist of Talos.
PARAMETER_FILTER = 0.1  # [s]

# Drumming posture (bent elbows, hands in front of the belly); arm joints 1..7, left arm.
# The right arm mirrors it (joints 1, 2, 3, 5, 6 change sign).
DRUM_POSTURE_LEFT = (0.35, 0.30, -0.30, -1.45, 0.0, 0.0, 0.0)
STROKE_HEIGHT = 0.09  # [m] vertical travel of the wrist
STROKE_LOOP = 0.015  # [m] fore-aft amplitude of the wrist loop
WRIST_FLICK = 0.15  # [rad] amplitude of the wrist pitch
# Stroke profile over one period (fraction of the cycle, normalised height), strike at 0:
# quick rebound, slow lift to the top, fast downstroke.
HEIGHT_KEYPOINTS = np.array(
    [[0.0, 0.0], [0.1, 0.45], [0.25, 0.8], [0.45, 1.0], [0.65, 0.92], [0.8, 0.6], [0.92, 0.2]]
)
# Wrist pitch (positive: stick down) leads the height: cocked up while rising, snap down.
PITCH_KEYPOINTS = np.array(
    [[0.0, 0.8], [0.1, 0.1], [0.25, -0.6], [0.45, -1.0], [0.65, -0.7], [0.8, 0.0], [0.92, 0.9]]
)
FIGURE8_SIZE = (0.10, 0.06)  # [m] half width (lateral) and half height of the figure-8

ARM_STIFFNESS = 100.0  # [1/s^2] low-gain feedback around the DMP plan (damping critical)
HAND_STIFFNESS = 100.0  # [1/s^2] figure-8 hand task
JOINT_LIMIT_HORIZON = 0.05  # [s] the DMP-driven joints brake for their position/velocity limits
POSTURE_WEIGHT = 1e-2
COM_WEIGHT, BASE_WEIGHT = 10.0, 1.0
GROUND_STIFFNESS = 2e4  # [N/m] per sole corner
FALL_HEIGHT = 0.7  # [m] the pelvis (base_link) has fallen when lower, on either backend
MASS_ERROR = 1.1  # the controller's arms (and hands) are 10 % heavier than the simulated ones

BACKENDS = ("mujoco", "native")
MUJOCO_FRICTION = 1.0  # floor-sole friction coefficient of the nominal MuJoCo runs
CONTROLLER_FRICTION = (
    0.7  # the controller's friction cone (SoleContact default), at most the floor's
)
FRICTIONS = (0.4, 0.7)  # floor friction of the low-friction scenarios (1.0 is the nominal run)
LINK_MASS_SCALES = (0.9, 1.1)  # every link of the controller's model, mass and inertia
TIGHT_TORQUE = 0.8  # torque limits at this fraction of the nominal run's peak torque use
PUSH_TIME = 0.5  # [s] when the push on the pelvis starts
PUSH_DURATION = 0.1  # [s] the impulse is spread over this time
PUSH_LADDER = (10.0, 20.0, 30.0, 40.0, 60.0, 80.0)  # [N s] forward impulses tried, in order
PUSH_LADDER_QUICK = (10.0, 60.0)
PUSH_BISECTIONS = 2  # halvings after the ladder (none in quick mode)
SCENARIO_SECONDS = {"quick": 1.5, "full": 4.0}  # [s] each MuJoCo scenario run
PUSH_RUN_SECONDS = {"quick": 1.5, "full": 2.5}  # [s] each push run (push at PUSH_TIME)
VIDEO_FPS = 20.0
VIDEO_SECONDS = 3.0  # [s] of each clip (from the start of its run)
VIDEO_SIZE = (320, 240)  # [pixels]


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


# ------------------------------------------------------------------------------------ DMPs
@dataclass
class DrumDmps:
    """The learned drumming: 11 DOFs on the shared oscillator and the right elbow on its own."""

    shared: RhythmicDMP  # DRUM_JOINTS without the right elbow
    elbow: RhythmicDMP  # one DOF
    elbow_index: int  # position of the right elbow in DRUM_JOINTS
    start: np.ndarray  # (12,) limit-cycle posture at phase 0 (right-hand strike) [rad]
    start_velocity: np.ndarray  # (12,) limit-cycle velocity at phase 0 [rad/s]


def learn_drumming(demo: Demonstration) -> DrumDmps:
    """Fit the rhythmic DMPs (phase oscillator, ``N_BASIS`` basis functions per DOF)."""
    elbow_index = DRUM_JOINTS.index(ELBOW)
    others = [i for i in range(len(DRUM_JOINTS)) if i != elbow_index]
    joints = demo.joints
    shared_demo = Trajectory(
        joints.times,
        joints.positions[:, others],
        joints.velocities[:, others],
        joints.accelerations[:, others],
    )
    elbow_demo = Trajectory(
        joints.times,
        joints.positions[:, [elbow_index]],
        joints.velocities[:, [elbow_index]],
        joints.accelerations[:, [elbow_index]],
    )
    shared = fit_rhythmic(shared_demo, N_BASIS, period=PERIOD, form="phase")
    elbow = fit_rhythmic(elbow_demo, N_BASIS, period=PERIOD, form="phase")
    start = np.empty(len(DRUM_JOINTS))
    start_velocity = np.empty(len(DRUM_JOINTS))
    for dmp, index in ((shared, others), (elbow, [elbow_index])):
        # Three periods from the demonstrated start: the plan is on its limit cycle at phase 0.
        plan = dmp.rollout(3 * dmp.period, DT, start=joints.positions[0, index])
        start[index], start_velocity[index] = plan.positions[-1], plan.velocities[-1]
    return DrumDmps(shared, elbow, elbow_index, start, start_velocity)


@dataclass(frozen=True)
class Modification:
    """A change of the right elbow's DMP between ``start`` and ``end`` [s] (Fig. 4 right)."""

    name: str  # "none", "amplitude", "frequency" or "setpoint"
    start: float = CHANGE_START
    end: float = CHANGE_END

    @property
    def label(self) -> str:
        """Legend text."""
        return {
            "none": "A: unmodified",
            "amplitude": "B: A -> 2A",
            "frequency": "C: tau -> tau/2",
            "setpoint": f"D: g -> g + {SETPOINT_SHIFT} rad",
        }[self.name]


MODIFICATIONS = tuple(Modification(n) for n in ("none", "amplitude", "frequency", "setpoint"))


class DrumPlan:
    """Online drumming plan: steps both DMPs each tick and applies a :class:`Modification`.

    ``position, velocity, acceleration`` (shape (12,), ``DRUM_JOINTS`` order) are the plan at
    the current time; :meth:`step` advances by ``dt``. Both DMPs start on their limit cycle
    at phase 0 (the right-hand strike).
    """

    def __init__(self, dmps: DrumDmps, dt: float = DT, modification=None, compile=False):
        self.dmps = dmps
        self.dt = dt
        self.modification = modification or Modification("none")
        i = dmps.elbow_index
        self._others = np.array([k for k in range(len(DRUM_JOINTS)) if k != i])
        self._elbow = i
        start, velocity, others = dmps.start, dmps.start_velocity, self._others
        self.shared = dmps.shared.stepper(
            dt, start=start[others], start_velocity=velocity[others], compile=compile
        )
        self.elbow = dmps.elbow.stepper(
            dt, start=start[[i]], start_velocity=velocity[[i]], compile=compile
        )
        self.time = 0.0
        self._parameters = self._targets(False)
        self.position = np.empty(len(DRUM_JOINTS))
        self.velocity = np.empty(len(DRUM_JOINTS))
        self.acceleration = np.empty(len(DRUM_JOINTS))
        self._gather()

    def _gather(self) -> None:
        for stepper, index in ((self.shared, self._others), (self.elbow, [self._elbow])):
            self.position[index] = stepper.position
            self.velocity[index] = stepper.velocity
            self.acceleration[index] = stepper.acceleration

    def _targets(self, active: bool) -> np.ndarray:
        """Elbow (amplitude, time constant, setpoint) requested at this time."""
        name, elbow = self.modification.name, self.dmps.elbow
        return np.array(
            [
                elbow.amplitude * (2.0 if active and name == "amplitude" else 1.0),
                elbow.tau / (2.0 if active and name == "frequency" else 1.0),
                elbow.setpoint[0] + (SETPOINT_SHIFT if active and name == "setpoint" else 0.0),
            ]
        )

    def step(self) -> None:
        """Advance both DMPs by ``dt``; the elbow's A, tau, g follow the modification."""
        mod = self.modification
        active = mod.name != "none" and mod.start <= self.time + 1e-9 < mod.end
        target = self._targets(active)
        if np.any(target != self._parameters):
            self._parameters += (target - self._parameters) * min(1.0, self.dt / PARAMETER_FILTER)
            close = np.abs(target - self._parameters) < 1e-9
            self._parameters[close] = target[close]
            amplitude, tau, setpoint = self._parameters
            self.elbow.set_amplitude(amplitude)
            self.elbow.set_tau(tau)
            self.elbow.set_setpoint([setpoint])
        # Phase lock to the shared oscillator, except while the elbow runs at its own tau.
        locked = abs(self._parameters[1] - self.dmps.elbow.tau) < 1e-6
        coupling = ELBOW_PHASE_COUPLING * np.sin(self.shared.phase - self.elbow.phase)
        self.shared.step()
        self.elbow.step(canonical_coupling=coupling if locked else 0.0)
        self.time += self.dt
        self._gather()

    @property
    def phase(self) -> float:
        """Phase of the shared oscillator [rad]."""
        return self.shared.phase

    @property
    def elbow_phase(self) -> float:
        """Phase of the right elbow's oscillator [rad]."""
        return self.elbow.phase


def plan_rollout(dmps: DrumDmps, duration: float, modification=None, dt: float = DT) -> dict:
    """The drumming plan alone (no robot): times, positions (n, 12), elbow phase (n,)."""
    plan = DrumPlan(dmps, dt, modification)
    n = int(round(duration / dt)) + 1
    positions = np.empty((n, len(DRUM_JOINTS)))
    elbow_phase = np.empty(n)
    for k in range(n):
        positions[k] = plan.position
        elbow_phase[k] = plan.elbow_phase
        if k < n - 1:
            plan.step()
    return {"times": np.arange(n) * dt, "positions": positions, "elbow_phase": elbow_phase}


def elbow_limit_cycle(dmps: DrumDmps, dt: float = DT):
    """The elbow's unmodified limit cycle as a function of its phase: ``y(phi)`` callable.

    The plan starts on the limit cycle (phase 0), so one period of the rollout is the cycle.
    """
    elbow, i = dmps.elbow, [dmps.elbow_index]
    plan = elbow.rollout(
        elbow.period + 2 * dt, dt, start=dmps.start[i], start_velocity=dmps.start_velocity[i]
    )
    phase = plan.times / elbow.tau  # tau * phidot = 1
    values = plan.positions[:, 0]

    def cycle(phi):
        return np.interp(np.mod(phi, 2 * np.pi), phase, values)

    return cycle


def ideal_elbow(dmps: DrumDmps, modification: Modification, times, elbow_phase) -> np.ndarray:
    """The new limit cycle the elbow should follow: ``g' + (A'/A) (y(phi) - g)``.

    ``y(phi)`` is the unmodified limit cycle at the elbow oscillator's actual phase, so the
    frequency change is accounted for by the phase itself.
    """
    cycle = elbow_limit_cycle(dmps)
    g = float(dmps.elbow.setpoint[0])
    window = (times >= modification.start) & (times < modification.end)
    scale = np.where(window & (modification.name == "amplitude"), 2.0, 1.0)
    shift = np.where(window & (modification.name == "setpoint"), SETPOINT_SHIFT, 0.0)
    return g + shift + scale * (cycle(elbow_phase) - g)


def settle_time(times, actual, ideal, start, end, tolerance) -> float | None:
    """Time after ``start`` from which ``|actual - ideal| <= tolerance`` until ``end`` [s].

    None if the error never stays within the tolerance before ``end``.
    """
    window = (times >= start) & (times < end)
    error = np.abs(actual[window] - ideal[window])
    outside = np.flatnonzero(error > tolerance)
    if outside.size == 0:
        return 0.0
    last = outside[-1]
    if last == error.size - 1:
        return None
    return float(times[window][last + 1] - start)


# ------------------------------------------------------------------------ closed loop
def build_controller(
    robot,
    q_start: np.ndarray,
    arm_joints=DRUM_JOINTS,
    hand=None,
    base_task: bool = True,
    com_sink: float | None = None,
    friction: float = CONTROLLER_FRICTION,
):
    """Inverse-dynamics controller holding ``q_start``; returns it and the DMP-driven task.

    The driven task is a :class:`PostureTask` on ``arm_joints`` (drumming) or, with ``hand``
    a frame name, a position :class:`FrameTask` on that hand (figure-8). ``base_task=False``
    leaves out the pelvis orientation task (to show why it is needed). The driven joints (the
    hand's arm for the figure-8) are kept within their position and velocity limits.
    ``com_sink`` [m] lowers the CoM target (default: the compliant ground's static
    compression, :func:`_sink`); ``friction`` is the soles' friction coefficient.
    """
    actuated = np.sort(
        np.concatenate([robot.configuration_indices([n]) for n in robot.actuated_joint_names])
    )
    posture = PostureTask(robot, weight=POSTURE_WEIGHT, stiffness=10.0)
    posture.set_reference(q_start[actuated])
    if hand is None:
        driven = PostureTask(robot, list(arm_joints), weight=1.0, stiffness=ARM_STIFFNESS)
        driven.set_reference(q_start[robot.configuration_indices(list(arm_joints))])
    else:
        driven = FrameTask(robot, hand, weight=1.0, stiffness=HAND_STIFFNESS, components="position")
        data = robot.create_data()
        pin.framesForwardKinematics(robot.model, data, q_start)
        driven.set_target(data.oMf[robot.model.getFrameId(hand)].translation.copy())
    tasks = [posture, driven]
    limited = list(arm_joints)  # the joints the plan moves
    if hand is not None:  # hold the other arm (the CoM task would otherwise swing it)
        limited, other = ("right_arm", "left_arm") if "right" in hand else ("left_arm", "right_arm")
        hold = PostureTask(robot, other, weight=1.0, stiffness=ARM_STIFFNESS)
        hold.set_reference(q_start[robot.configuration_indices(other)])
        tasks.append(hold)
    contacts = []
    if robot.floating_base:
        com = ComTask(robot, weight=COM_WEIGHT, stiffness=50.0)
        # The simulation starts with the soles pressed into the compliant ground.
        sink = _sink(robot) if com_sink is None else com_sink
        com.set_target(pin.centerOfMass(robot.model, robot.create_data(), q_start) - [0, 0, sink])
        base = FrameTask(
            robot, "base_link", weight=BASE_WEIGHT, stiffness=50.0, components="orientation"
        )
        tasks += [com, base] if base_task else [com]
        contacts = [SoleContact(robot, f, friction_coefficient=friction) for f in robot.foot_frames]
    controller = InverseDynamicsController(
        robot, tasks, contacts, joint_limit_horizon=JOINT_LIMIT_HORIZON, limited_joints=limited
    )
    return controller, driven


def make_simulator(robot, q_start: np.ndarray):
    """Simulator (compliant ground under the sole corners if standing) and its start state."""
    if not robot.floating_base:
        return Simulator(robot.model, DT), q_start.copy()
    points = [(f, c) for f in robot.foot_frames for c in robot.sole_corners]
    simulator = Simulator(
        robot.model,
        DT,
        contact_points=points,
        ground=GroundContact(stiffness=GROUND_STIFFNESS, damping=300.0, friction=1.0),
        fall_frame="base_link",
        fall_height=FALL_HEIGHT,
    )
    q0 = q_start.copy()
    q0[2] -= _sink(robot)
    return simulator, q0


def _sink(robot) -> float:
    """Static compression of the ground under the standing robot [m]."""
    n_points = len(robot.foot_frames) * len(robot.sole_corners)
    return pin.computeTotalMass(robot.model) * 9.81 / n_points / GROUND_STIFFNESS


def mujoco_plant(friction: float = MUJOCO_FRICTION):
    """A ``plant(robot, q_start) -> (simulator, q0)`` simulating in MuJoCo.

    MuJoCo's floor touches a 5 mm sphere at each sole corner (the URDF collision meshes touch
    nothing), with Coulomb ``friction``; the same fall options as :func:`make_simulator`, so
    the same thresholds (:mod:`dmpopt.sim.falls`). The robot starts with the soles on the
    floor: MuJoCo's contacts sink by about a millimetre.
    """
    from dmpopt.sim import MujocoSimulator

    def plant(robot, q_start):
        if not robot.floating_base:
            return MujocoSimulator(robot.model, robot.source, DT), q_start.copy()
        points = [(f, c) for f in robot.foot_frames for c in robot.sole_corners]
        simulator = MujocoSimulator(
            robot.model,
            robot.source,
            DT,
            points,
            friction,
            fall_frame="base_link",
            fall_height=FALL_HEIGHT,
        )
        return simulator, q_start.copy()

    return plant


def with_scaled_masses(robot, scale: float):
    """A copy of ``robot`` whose every link (pelvis included) has mass and inertia x ``scale``."""
    model = pin.Model(robot.model)
    for joint_id in range(1, model.njoints):
        inertia = model.inertias[joint_id]
        model.inertias[joint_id] = pin.Inertia(
            inertia.mass * scale, inertia.lever, inertia.inertia * scale
        )
    return dataclasses.replace(robot, model=model, name=f"{robot.name}_all_mass_x{scale:g}")


def with_scaled_torque_limits(robot, scale: float):
    """A copy of ``robot`` whose torque limits are multiplied by ``scale``."""
    limit = np.asarray(robot.torque_limit, dtype=float) * scale
    return dataclasses.replace(robot, torque_limit=limit, name=f"{robot.name}_torque_x{scale:.3g}")


@dataclass
class RunLog:
    """What one closed-loop run produced (every tick)."""

    times: np.ndarray
    desired: np.ndarray  # (n, n_dofs) plan: joints [rad] or hand position [m]
    actual: np.ndarray  # (n, n_dofs) measured counterpart
    elbow_phase: np.ndarray  # (n,) drumming only
    base: np.ndarray  # (n, 6) pelvis position [m] and roll, pitch, yaw [rad]
    com: np.ndarray  # (n, 3) [m]
    torque_use: np.ndarray  # (n_actuated,) max over the run of |tau| / limit
    torque_peak: np.ndarray  # (n,) max over the joints of |tau| / limit, each tick
    tick_wall_us: np.ndarray  # (n,) compute_torques, wall clock
    tick_cpu_us: np.ndarray  # (n,) compute_torques, CPU time of the thread
    wall_time: float  # [s] the whole loop (plan, controller, simulator, logging)
    cpu_time: float  # [s] process time of the whole loop
    fell: bool
    n_cold_restarts: int
    n_fallbacks: int
    n_direct: int  # ticks solved without proxsuite (no inequality row active)
    n_torque_limited: int = 0  # ticks whose QP needed the torque-limit rows
    diverged: str | None = None  # SimulationDiverged message: the run stopped, not a fall
    extras: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Simulated time [s]."""
        return float(self.times.size * DT)

    @property
    def qp_active_fraction(self) -> float:
        """Fraction of the ticks with an active inequality row (solved by proxsuite)."""
        return 1.0 - self.n_direct / self.times.size


def _closed_loop(
    robot,
    q_start,
    v_start,
    controller,
    reference,
    measure,
    duration,
    progress,
    plant=None,
    push=None,
    record_every: int = 0,
):
    """Run ``duration`` seconds from ``(q_start, v_start)``; stop early at a fall.

    ``reference()`` advances the plan (not on the first tick), sets the task targets and
    returns the plan; ``measure(q, data)`` returns the tracked quantity. ``plant(robot,
    q_start)`` makes the simulator and its start configuration (default
    :func:`make_simulator`); ``push = (time, impulse)`` pushes the pelvis with a world-frame
    impulse [N s] spread over ``PUSH_DURATION``; with ``record_every`` > 0 the configuration
    of every ``record_every``-th tick goes to ``extras["frames"]`` (and the simulator to
    ``extras["simulator"]``, for rendering). A diverging simulation also stops the run but is
    no fall: ``RunLog.diverged`` keeps its message.
    """
    simulator, q0 = (plant or make_simulator)(robot, q_start)
    state = simulator.reset(q0, v_start)
    push_tick = -1 if push is None else int(round(push[0] / DT))
    frames = []
    n = int(round(duration / DT))
    data = robot.create_data()
    first = reference()
    desired = np.empty((n, first.size))
    actual = np.empty_like(desired)
    base = np.zeros((n, 6))
    com = np.zeros((n, 3))
    tick_wall = np.empty(n)
    tick_cpu = np.empty(n)
    torque_use = np.zeros(robot.n_actuated)
    torque_peak = np.empty(n)
    ratio = np.empty(robot.n_actuated)
    limit = np.asarray(robot.torque_limit)
    fell, diverged = False, None
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(n):
        if k == push_tick:
            simulator.push_impulse("base_link", push[1], duration=PUSH_DURATION)
        if record_every and k % record_every == 0:
            frames.append(state.q.copy())
        desired[k] = reference() if k else first
        begin, cpu_begin = time.perf_counter_ns(), time.thread_time_ns()
        tau = controller.compute_torques(state.q, state.v)
        tick_cpu[k] = time.thread_time_ns() - cpu_begin
        tick_wall[k] = time.perf_counter_ns() - begin
        np.divide(np.abs(tau), limit, out=ratio)
        np.maximum(torque_use, ratio, out=torque_use)
        torque_peak[k] = ratio.max()
        actual[k] = measure(state.q, data)
        if robot.floating_base:
            base[k, :3] = state.q[:3]
            base[k, 3:] = pin.rpy.matrixToRpy(pin.Quaternion(state.q[3:7]).toRotationMatrix())
            com[k] = pin.centerOfMass(robot.model, data, state.q)
        try:
            state = simulator.step(tau)
            fell = state.fallen
        except SimulationDiverged as error:
            diverged = str(error)
        stop = fell or diverged is not None
        if progress is not None and (k % 100 == 99 or k == n - 1 or stop):
            progress.update(k % 100 + 1)
        if stop:
            n = k + 1
            break
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return RunLog(
        times=np.arange(n) * DT,
        desired=desired[:n],
        actual=actual[:n],
        elbow_phase=np.zeros(n),
        base=base[:n],
        com=com[:n],
        torque_use=torque_use,
        torque_peak=torque_peak[:n],
        tick_wall_us=tick_wall[:n] / 1e3,
        tick_cpu_us=tick_cpu[:n] / 1e3,
        wall_time=wall,
        cpu_time=cpu,
        fell=fell,
        n_cold_restarts=controller.stats.n_cold_restarts,
        n_fallbacks=controller.stats.n_fallbacks,
        n_direct=controller.stats.n_direct,
        n_torque_limited=controller.stats.n_torque_limited,
        diverged=diverged,
        extras={"frames": frames, "simulator": simulator} if record_every else {},
    )


def run_drumming(
    robot,
    dmps: DrumDmps,
    duration: float,
    modification=None,
    progress=None,
    compile=False,
    controller_robot=None,
    base_task: bool = True,
    build=build_controller,
    build_options=None,
    **loop,
) -> RunLog:
    """Drum for ``duration`` [s] with the learned DMPs on ``robot`` (floating or fixed base).

    ``controller_robot`` (default ``robot``) is the model the controller believes in, e.g.
    :func:`with_mass_error` of ``robot``; the simulator always uses ``robot``. ``build`` makes
    the controller and its driven task, with :func:`build_controller`'s signature (another
    controller can be compared on the same loop), and extra keywords ``build_options``.
    ``loop`` (``plant``, ``push``, ``record_every``) goes to the closed loop, see
    :func:`_closed_loop`.
    """
    q_start = drumming_posture(robot)
    q_indices = robot.configuration_indices(list(DRUM_JOINTS))
    q_start[q_indices] = dmps.start
    v_start = np.zeros(robot.nv)
    v_start[robot.velocity_indices(list(DRUM_JOINTS))] = dmps.start_velocity
    controller, task = build(
        controller_robot or robot, q_start, base_task=base_task, **(build_options or {})
    )
    plan = DrumPlan(dmps, DT, modification, compile=compile)
    phases = []

    def reference():
        if phases:
            plan.step()
        phases.append(plan.elbow_phase)
        task.set_reference(plan.position, plan.velocity, plan.acceleration)
        return plan.position

    def measure(q, data):
        return q[q_indices]

    log = _closed_loop(
        robot, q_start, v_start, controller, reference, measure, duration, progress, **loop
    )
    log.elbow_phase = np.array(phases[: log.times.size])
    return log


def with_mass_error(robot, scale: float, groups=("left_arm", "right_arm")):
    """A copy of ``robot`` whose links moved by ``groups`` (and all links after them: the
    hands and grippers) have mass and inertia multiplied by ``scale``."""
    model = pin.Model(robot.model)
    first = [model.getJointId(j) for g in groups for j in robot.joint_groups[g]]
    for joint_id in range(1, model.njoints):
        ancestors = set(model.supports[joint_id])
        if ancestors & set(first):
            inertia = model.inertias[joint_id]
            model.inertias[joint_id] = pin.Inertia(
                inertia.mass * scale, inertia.lever, inertia.inertia * scale
            )
    return dataclasses.replace(robot, model=model, name=f"{robot.name}_mass_x{scale:g}")


# ---------------------------------------------------------------------------- figure-8
def figure8_demonstration(center: np.ndarray, n_per_period: int = 400, periods: int = 2):
    """Hand positions of a 1:2 Lissajous figure-8 in the frontal (y, z) plane [m]."""
    times = np.arange(periods * n_per_period + 1) * FIGURE8_PERIOD / n_per_period
    angle = 2 * np.pi * times / FIGURE8_PERIOD
    positions = np.tile(np.asarray(center, dtype=float), (times.size, 1))
    positions[:, 1] += FIGURE8_SIZE[0] * np.sin(angle)
    positions[:, 2] += FIGURE8_SIZE[1] * np.sin(2 * angle)
    return Trajectory.from_positions(times, positions)


def run_figure8(
    robot,
    duration: float,
    progress=None,
    compile=False,
    build=build_controller,
    build_options=None,
    **loop,
):
    """Draw the figure-8 with the right hand: task-space DMP tracked by a hand position task.

    Returns the run log (desired and actual hand positions) and the fitted DMP. ``build``,
    ``build_options`` and ``loop`` as in :func:`run_drumming`.
    """
    hand = robot.hand_frames[1]
    q_start = drumming_posture(robot)
    data = robot.create_data()
    pin.framesForwardKinematics(robot.model, data, q_start)
    frame_id = robot.model.getFrameId(hand)
    center = data.oMf[frame_id].translation.copy()
    dmp = fit_rhythmic(figure8_demonstration(center), N_BASIS, period=FIGURE8_PERIOD)
    # Start on the limit cycle at phase 0 (the centre of the 8, where the hand is), with the
    # right-arm joint velocities that give the plan's hand velocity.
    cycle = dmp.rollout(3 * dmp.period, DT, start=center)
    start, start_velocity = cycle.positions[-1], cycle.velocities[-1]
    stepper = dmp.stepper(DT, start=start, start_velocity=start_velocity, compile=compile)
    arm = robot.velocity_indices("right_arm")
    jacobian = pin.computeFrameJacobian(
        robot.model, data, q_start, frame_id, pin.LOCAL_WORLD_ALIGNED
    )[:3, arm]
    v_start = np.zeros(robot.nv)
    v_start[arm] = np.linalg.pinv(jacobian) @ start_velocity
    controller, task = build(robot, q_start, hand=hand, **(build_options or {}))
    ticks = []

    def reference():
        if ticks:
            stepper.step()
        ticks.append(None)
        position, velocity, acceleration = stepper.position, stepper.velocity, stepper.acceleration
        task.set_target(
            position, velocity=np.r_[velocity, 0, 0, 0], acceleration=np.r_[acceleration, 0, 0, 0]
        )
        return position

    def measure(q, data):
        pin.framesForwardKinematics(robot.model, data, q)
        return data.oMf[frame_id].translation.copy()

    log = _closed_loop(
        robot, q_start, v_start, controller, reference, measure, duration, progress, **loop
    )
    return log, dmp


# ------------------------------------------------------------------------------- study
def _rms(error: np.ndarray, axis=None):
    return np.sqrt(np.mean(np.square(error), axis=axis))


def _stepper_compiles(dmps: DrumDmps) -> bool:
    """Whether the compiled DMP step is available (needs a C compiler)."""
    return dmps.elbow.stepper(DT, start=dmps.start[[dmps.elbow_index]], compile=True).compiled


def _settling(dmps, modification, times, actual, phase, end_time) -> dict:
    """Settle times [s] at the onset and at the end of the modification window."""
    ideal = ideal_elbow(dmps, modification, times, phase)
    window = (times >= modification.start) & (times < modification.end)
    after = times >= modification.end
    tolerance_on = SETTLE_TOLERANCE * np.ptp(ideal[window])
    tolerance_off = SETTLE_TOLERANCE * np.ptp(ideal[after])
    return {
        "onset_s": settle_time(
            times, actual, ideal, modification.start, modification.end, tolerance_on
        ),
        "revert_s": settle_time(times, actual, ideal, modification.end, end_time, tolerance_off),
        "tolerance_rad": tolerance_on,
        "error_max_in_window_after_1s_rad": float(
            np.abs(actual - ideal)[window & (times >= modification.start + 1.0)].max()
        ),
    }


def _frequency_settle(plan: dict, modification: Modification) -> float | None:
    """Time for the elbow oscillator's frequency to come within 5 % of twice its value [s]."""
    times, phase = plan["times"], plan["elbow_phase"]
    rate = np.gradient(phase, times)
    before = rate[(times > modification.start - 0.5) & (times < modification.start)].mean()
    inside = (times >= modification.start) & (times < modification.end)
    far = np.flatnonzero(np.abs(rate[inside] - 2 * before) > 0.05 * 2 * before)
    if far.size == 0:
        return 0.0
    if far[-1] == inside.sum() - 1:
        return None
    return float(times[inside][far[-1] + 1] - modification.start)


def check_backend(backend) -> str:
    """``backend`` if it is one of ``BACKENDS``, else :class:`InvalidInputError`."""
    if backend not in BACKENDS:
        raise InvalidInputError(
            f"backend must be one of {BACKENDS}, got {backend!r}; pass backend='mujoco' "
            "(default) or backend='native' (the compliant-ground simulator of dmpopt.sim)"
        )
    return backend


def _summary(log: RunLog) -> dict:
    """Fall, tracking and solver activity of one drumming run."""
    return {
        "fell": log.fell,
        "diverged": log.diverged,
        "simulated_s": log.duration,
        "tracking_rms_rad": float(_rms(log.actual - log.desired)),
        "tracking_max_rad": float(np.abs(log.actual - log.desired).max()),
        "qp_active_fraction": log.qp_active_fraction,
        "torque_limited_fraction": log.n_torque_limited / log.times.size,
        "torque_limit_use_max": float(log.torque_use.max()),
    }


def push_search(drum, ladder, bisections: int) -> dict:
    """Largest forward impulse on the pelvis [N s] survived while drumming.

    ``drum(push=(time, impulse))`` runs one pushed drumming run. The impulses of ``ladder``
    (increasing) are tried until the first fall, then ``bisections`` halvings between the
    largest survived and the smallest fatal impulse. A run that diverged did not survive and
    bounds the search like a fall, but is reported as ``diverged``, not as a fall. Assumes
    survival is monotonic in the impulse (checked only at the points tried). Returns the
    bounds, every impulse tried and the run of the largest survived push (or of the first
    failure if none was survived).
    """
    tried, survived, fatal, shown = [], 0.0, None, None

    def attempt(impulse):
        log = drum(push=(PUSH_TIME, np.array([impulse, 0.0, 0.0])))
        tried.append({"impulse_ns": impulse, "fell": log.fell, "diverged": log.diverged})
        return log, log.fell or log.diverged is not None

    for impulse in ladder:
        log, failed = attempt(impulse)
        if failed:
            fatal, shown = impulse, shown or log
            break
        survived, shown = impulse, log
    for _ in range(bisections if fatal is not None else 0):
        impulse = 0.5 * (survived + fatal)
        log, failed = attempt(impulse)
        if failed:
            fatal = impulse
        else:
            survived, shown = impulse, log
    return {"survived_ns": survived, "fell_ns": fatal, "tried": tried, "log": shown}


def mujoco_scenarios(robot, dmps, nominal: RunLog, quick: bool, compile: bool, bar) -> dict:
    """Model mismatch, friction, tight torque limits and pushes, all in MuJoCo.

    ``nominal`` is the unmodified MuJoCo drumming run (its peak torque use sets the tight
    torque limits). Returns the scenario summaries, the push search and the push run.
    """
    mode = "quick" if quick else "full"
    duration = SCENARIO_SECONDS[mode]
    record = int(round(1.0 / (VIDEO_FPS * DT)))

    def drum(plant=None, controller_robot=None, friction=CONTROLLER_FRICTION, **loop):
        return run_drumming(
            robot,
            dmps,
            loop.pop("duration", duration),
            None,
            bar,
            compile=compile,
            controller_robot=controller_robot,
            build_options={"com_sink": 0.0, "friction": friction},
            plant=plant or mujoco_plant(),
            **loop,
        )

    scenarios = {}
    for scale in LINK_MASS_SCALES:
        log = drum(controller_robot=with_scaled_masses(robot, scale))
        scenarios[f"link_masses_x{scale:g}"] = _summary(log)
    for friction in FRICTIONS:
        log = drum(plant=mujoco_plant(friction), friction=min(CONTROLLER_FRICTION, friction))
        scenarios[f"friction_{friction:g}"] = _summary(log)
    tight = TIGHT_TORQUE * float(nominal.torque_use.max())
    scenarios["tight_torque_limits"] = {
        "scale_of_urdf_limits": tight,
        **_summary(drum(controller_robot=with_scaled_torque_limits(robot, tight))),
    }
    push = push_search(
        lambda push: drum(push=push, duration=PUSH_RUN_SECONDS[mode], record_every=record),
        PUSH_LADDER_QUICK if quick else PUSH_LADDER,
        bisections=0 if quick else PUSH_BISECTIONS,
    )
    scenarios["push_largest_survived"] = {
        "impulse_ns": push["survived_ns"],
        **_summary(push["log"]),
    }
    return {"scenarios": scenarios, "push": push}


def write_videos(out, clips: dict, skip_reason: str | None = None) -> tuple[list, str | None]:
    """Render ``clips`` (name -> (MujocoSimulator, configurations, camera distance [m])).

    Each becomes ``out / (name + ".webp")`` (at most 5 MB). Returns the file names written
    and why the others were skipped: ``skip_reason`` if given (nothing is rendered), or the
    :class:`MissingDependency` message (no OpenGL context, no Pillow), else None.
    """
    if skip_reason is not None:
        return [], skip_reason
    from dmpopt.sim import render_animation

    written = []
    width, height = VIDEO_SIZE
    for name, (simulator, frames, distance) in clips.items():
        try:
            path = render_animation(
                simulator, frames, out / f"{name}.webp", VIDEO_FPS, width, height, distance
            )
        except MissingDependency as error:
            return written, str(error)
        written.append(path.name)
    return written, None


def run(out_dir, quick: bool = False, seed: int = 0, backend: str = "mujoco") -> dict:
    """Run the study, write the figures and ``metrics.json`` into ``out_dir``; return metrics.

    ``backend`` simulates the standing robot: "mujoco" (default; also runs the model-mismatch,
    friction, torque-limit and push scenarios, a native run for comparison, and the videos)
    or "native". The study is deterministic; ``seed`` is recorded only.
    """
    from tqdm import tqdm

    from .common import output_dir, write_metrics

    backend = check_backend(backend)
    out = output_dir(out_dir)
    on_mujoco = backend == "mujoco"
    plant = mujoco_plant() if on_mujoco else None
    options = {"com_sink": 0.0} if on_mujoco else None
    record = int(round(1.0 / (VIDEO_FPS * DT))) if on_mujoco else 0
    drum_duration, fixed_duration, figure8_duration = (3.0, 2.0, 4.0) if quick else (10.0,) * 3
    window = (1.0, 3.0) if quick else (CHANGE_START, CHANGE_END)
    fig4_duration = 4.0 if quick else 10.0
    start_wall, start_cpu = time.perf_counter(), time.process_time()

    demo = demonstrate_drumming()
    dmps = learn_drumming(demo)
    compile = _stepper_compiles(dmps)
    reproduction = plan_rollout(dmps, 3 * PERIOD)["positions"][-int(round(PERIOD / DT)) - 1 :]
    demo_cycle = demo.joints.positions[: demo.joints.n_steps // 2 + 1]
    n_demo = demo_cycle.shape[0]
    resampled = reproduction[np.linspace(0, reproduction.shape[0] - 1, n_demo).round().astype(int)]
    fit_error = float(np.abs(resampled - demo_cycle).max())

    floating = load_talos("full")
    fixed = load_talos("full", fixed_base=True)
    modifications = [Modification(m.name, *window) for m in MODIFICATIONS]
    total = fig4_duration * 3 + 3 * drum_duration + fixed_duration + figure8_duration
    if on_mujoco:  # the native comparison, five scenarios, at most this many pushes
        mode = "quick" if quick else "full"
        pushes = len(PUSH_LADDER_QUICK) if quick else len(PUSH_LADDER) + PUSH_BISECTIONS
        total += drum_duration + 5 * SCENARIO_SECONDS[mode] + pushes * PUSH_RUN_SECONDS[mode]
    runs, plans = {}, {}
    bar_format = "{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} simulated s [{elapsed}]"
    ticks = int(round(total / DT))
    with tqdm(total=ticks, desc="humanoid", bar_format=bar_format, unit_scale=DT) as bar:
        for modification in modifications:
            duration = drum_duration if modification.name == "none" else fig4_duration
            plans[modification.name] = plan_rollout(dmps, fig4_duration, modification)
            runs[modification.name] = run_drumming(
                floating,
                dmps,
                duration,
                modification,
                bar,
                compile=compile,
                build_options=options,
                plant=plant,
                record_every=record if modification.name == "none" else 0,
            )
        # The fixed-base upper body is a reduced model with locked legs (no URDF of its own):
        # it stays on the native simulator, as the controller's timing reference.
        fixed_log = run_drumming(fixed, dmps, fixed_duration, None, bar, compile=compile)
        # Ablations: a controller model with heavier arms, and no pelvis orientation task.
        wrong_model = run_drumming(
            floating,
            dmps,
            drum_duration,
            None,
            bar,
            compile=compile,
            controller_robot=with_mass_error(floating, MASS_ERROR),
            build_options=options,
            plant=plant,
        )
        no_base_task = run_drumming(
            floating,
            dmps,
            drum_duration,
            None,
            bar,
            compile=compile,
            base_task=False,
            build_options=options,
            plant=plant,
        )
        figure8_log, figure8_dmp = run_figure8(
            floating,
            figure8_duration,
            bar,
            compile=compile,
            build_options=options,
            plant=plant,
            record_every=record,
        )
        native = runs["none"]
        if on_mujoco:
            native = run_drumming(floating, dmps, drum_duration, None, bar, compile=compile)
            mujoco = mujoco_scenarios(floating, dmps, runs["none"], quick, compile, bar)

    # ------------------------------------------------------------------ metrics
    drum = runs["none"]
    error = drum.actual - drum.desired
    groups = {"left_arm": slice(0, 6), "right_arm": slice(6, 12)}
    fixed_error = fixed_log.actual - fixed_log.desired
    hand_error = np.linalg.norm(figure8_log.actual - figure8_log.desired, axis=1)
    standing = list(runs.values()) + [figure8_log]
    torque_use = np.max([log.torque_use for log in standing], axis=0)
    # Distance of the DMP-driven joints to their position limits, over the drumming runs.
    drum_q = floating.configuration_indices(list(DRUM_JOINTS))
    lower, upper = floating.position_lower[drum_q], floating.position_upper[drum_q]
    position_margin = np.min(
        [np.minimum(log.actual - lower, upper - log.actual).min(axis=0) for log in runs.values()],
        axis=0,
    )
    names = floating.actuated_joint_names
    torque_groups = {
        group: float(torque_use[np.isin(names, joints)].max())
        for group, joints in floating.joint_groups.items()
    }
    fig4 = {}
    for modification in modifications[1:]:
        name = modification.name
        plan, log = plans[name], runs[name]
        elbow = dmps.elbow_index
        fig4[name] = {
            "plan": _settling(
                dmps,
                modification,
                plan["times"],
                plan["positions"][:, elbow],
                plan["elbow_phase"],
                fig4_duration,
            ),
            "robot": _settling(
                dmps, modification, log.times, log.actual[:, elbow], log.elbow_phase, fig4_duration
            ),
            "frequency_settle_s": _frequency_settle(plan, modification)
            if name == "frequency"
            else None,
            "elbow_tracking_rms_rad": float(_rms(log.actual[:, elbow] - log.desired[:, elbow])),
            "elbow_tracking_max_rad": float(
                np.abs(log.actual[:, elbow] - log.desired[:, elbow]).max()
            ),
            "fell": log.fell,
        }
    onset = [fig4[n]["robot"]["onset_s"] for n in fig4]
    everything = standing + [fixed_log, wrong_model, no_base_task]
    all_ticks_cpu = np.concatenate([log.tick_cpu_us for log in runs.values()])
    all_ticks_wall = np.concatenate([log.tick_wall_us for log in runs.values()])
    simulated = sum(log.duration for log in standing)
    metrics = {
        "tick_us_median": float(np.median(all_ticks_cpu)),
        "tick_us_p99": float(np.percentile(all_ticks_cpu, 99)),
        "tick_clock": "CPU time of the thread (time.thread_time_ns) around compute_torques; "
        "floating-base full Talos (nv = 50), two sole contacts, all drumming runs",
        "tick_us_wall_median": float(np.median(all_ticks_wall)),
        "tick_us_wall_p99": float(np.percentile(all_ticks_wall, 99)),
        "tick_us_fixed_base_median": float(np.median(fixed_log.tick_cpu_us)),
        "tick_us_fixed_base_p99": float(np.percentile(fixed_log.tick_cpu_us, 99)),
        "tick_us_fixed_base_wall_median": float(np.median(fixed_log.tick_wall_us)),
        "tick_us_fixed_base_wall_p99": float(np.percentile(fixed_log.tick_wall_us, 99)),
        "real_time_factor": simulated / sum(log.wall_time for log in standing),
        "real_time_factor_cpu": simulated / sum(log.cpu_time for log in standing),
        "real_time_factor_fixed_base": fixed_log.duration / fixed_log.wall_time,
        "real_time_factor_fixed_base_cpu": fixed_log.duration / fixed_log.cpu_time,
        "real_time_factor_note": "simulated time / time of the whole loop (DMP step, "
        "controller, simulator step, logging); > 1 is faster than real time",
        "tracking_rms_rad": float(_rms(error)),
        "tracking_max_rad": float(np.abs(error).max()),
        "tracking_rms_rad_per_group": {g: float(_rms(error[:, s])) for g, s in groups.items()},
        "tracking_rms_rad_per_joint": dict(zip(DRUM_JOINTS, _rms(error, axis=0))),
        "tracking_rms_rad_fixed_base": float(_rms(fixed_error)),
        "tracking_rms_rad_fixed_base_per_group": {
            g: float(_rms(fixed_error[:, s])) for g, s in groups.items()
        },
        "figure8_rms_mm": float(1e3 * _rms(hand_error)),
        "figure8_max_mm": float(1e3 * hand_error.max()),
        "settle_time_s": None if None in onset else float(max(onset)),
        "settle_time_note": f"robot elbow within {SETTLE_TOLERANCE:.0%} of the new limit "
        "cycle's peak-to-peak amplitude after the change, worst of A x2, tau/2, g + "
        f"{SETPOINT_SHIFT} rad",
        "fig4": fig4,
        "torque_limit_use_max": float(torque_use.max()),
        "torque_limit_use_joint": names[int(np.argmax(torque_use))],
        "torque_limit_use_per_group": torque_groups,
        "position_limit_margin_rad": float(position_margin.min()),
        "position_limit_margin_joint": DRUM_JOINTS[int(np.argmin(position_margin))],
        "position_limit_margin_note": "closest approach of the drumming joints to a position "
        "limit; the controller bounds their accelerations to keep them within their position "
        f"and velocity limits (joint_limit_horizon {JOINT_LIMIT_HORIZON} s)",
        "fell": any(log.fell for log in standing),
        "diverged": [log.diverged for log in everything if log.diverged],
        "base_roll_pitch_yaw_ptp_deg": np.degrees(np.ptp(drum.base[:, 3:], axis=0)),
        "com_excursion_mm": 1e3 * np.ptp(drum.com, axis=0),
        "without_base_task": {
            "base_roll_pitch_yaw_ptp_deg": np.degrees(np.ptp(no_base_task.base[:, 3:], axis=0)),
            "tracking_rms_rad": float(_rms(no_base_task.actual - no_base_task.desired)),
            "fell": no_base_task.fell,
        },
        "with_arm_mass_error": {
            "scale": MASS_ERROR,
            "tracking_rms_rad": float(_rms(wrong_model.actual - wrong_model.desired)),
            "tracking_max_rad": float(np.abs(wrong_model.actual - wrong_model.desired).max()),
            "tracking_rms_rad_per_group": {
                g: float(_rms(wrong_model.actual[:, s] - wrong_model.desired[:, s]))
                for g, s in groups.items()
            },
            "base_roll_pitch_yaw_ptp_deg": np.degrees(np.ptp(wrong_model.base[:, 3:], axis=0)),
            "fell": wrong_model.fell,
        },
        "n_ticks": int(sum(log.times.size for log in everything)),
        "n_cold_restarts": int(sum(log.n_cold_restarts for log in everything)),
        "n_fallbacks": int(sum(log.n_fallbacks for log in everything)),
        "direct_solve_fraction": float(
            sum(log.n_direct for log in everything) / sum(log.times.size for log in everything)
        ),
        "direct_solve_note": "fraction of ticks without an active inequality row, solved by "
        "one Cholesky factorisation (or in closed form on the fixed base) instead of proxsuite",
        "demo_ik_error": demo.ik_error,
        "dmp_fit_error_rad": fit_error,
        "dmp_step_compiled": compile,
        "cpu_seconds": time.process_time() - start_cpu,
        "wall_seconds": time.perf_counter() - start_wall,
    }
    parameters = {
        "robot": "talos full (example-robot-data), floating base + fixed-base upper body",
        "dt_s": DT,
        "period_s": PERIOD,
        "n_basis": N_BASIS,
        "drum_joints": DRUM_JOINTS,
        "modification_window_s": window,
        "setpoint_shift_rad": SETPOINT_SHIFT,
        "arm_stiffness": ARM_STIFFNESS,
        "hand_stiffness": HAND_STIFFNESS,
        "durations_s": {
            "drumming": drum_duration,
            "fig4_each": fig4_duration,
            "fixed_base": fixed_duration,
            "figure8": figure8_duration,
        },
        "stroke": {"height_m": STROKE_HEIGHT, "loop_m": STROKE_LOOP, "wrist_rad": WRIST_FLICK},
        "figure8_size_m": FIGURE8_SIZE,
        "figure8_period_s": FIGURE8_PERIOD,
    }
    metrics["backend"] = backend
    metrics["native"] = _loop_summary(native)
    clips = {}
    if on_mujoco:
        metrics["mujoco"] = _mujoco_metrics(runs["none"], mujoco)
        frames = int(VIDEO_SECONDS * VIDEO_FPS)
        push_log = mujoco["push"]["log"]
        clips = {
            "humanoid_drumming": (
                runs["none"].extras["simulator"],
                runs["none"].extras["frames"][:frames],
                3.0,
            ),
            "humanoid_figure8": (
                figure8_log.extras["simulator"],
                figure8_log.extras["frames"][:frames],
                3.0,
            ),
            "humanoid_push": (push_log.extras["simulator"], push_log.extras["frames"], 3.5),
        }
    skip = "quick run" if quick else None if on_mujoco else "native backend (videos need MuJoCo)"
    metrics["videos"], metrics["videos_skipped"] = write_videos(out, clips, skip)
    if metrics["videos_skipped"]:
        print(f"videos skipped: {metrics['videos_skipped']}")
    _plot(out, dmps, demo, modifications, plans, runs, fixed_log, figure8_log, no_base_task)
    metrics["cpu_seconds"] = time.process_time() - start_cpu
    metrics["wall_seconds"] = time.perf_counter() - start_wall
    return write_metrics(out, "humanoid", metrics, parameters, seed, quick)


def _loop_summary(log: RunLog) -> dict:
    """Tracking, falls, solver activity and real-time factor of a nominal drumming run."""
    return {
        **_summary(log),
        "real_time_factor": log.duration / log.wall_time,
        "real_time_factor_cpu": log.duration / log.cpu_time,
    }


def _mujoco_metrics(nominal: RunLog, mujoco: dict) -> dict:
    """The ``mujoco`` object of ``metrics.json``: nominal run, pushes, QP activity, scenarios."""
    push, scenarios = mujoco["push"], mujoco["scenarios"]
    binding = "tight_torque_limits"
    return {
        **_loop_summary(nominal),
        "floor_friction": MUJOCO_FRICTION,
        "push_survived_ns": push["survived_ns"],
        "push_fell_ns": push["fell_ns"],
        "push_tried_ns": push["tried"],
        "push_note": f"forward impulse on the pelvis spread over {PUSH_DURATION} s from "
        f"t = {PUSH_TIME} s while drumming; ladder, then bisection. "
        + (
            "No impulse tried was fatal: push_survived_ns is only a lower bound (search capped). "
            if push["fell_ns"] is None
            else ""
        )
        + "A run that diverged (push_tried_ns[].diverged, the message) ends the search like a "
        "fall but is not counted as one",
        "qp_active_fraction_nominal": nominal.qp_active_fraction,
        "qp_active_fraction": scenarios[binding]["qp_active_fraction"],
        "qp_active_scenario": binding,
        "qp_active_note": "fraction of controller ticks with an active inequality row "
        "(torque limit, friction cone, centre of pressure, joint limit), solved by proxsuite; "
        "the others are direct least-squares solves (ControllerStats.n_direct)",
        "scenarios": scenarios,
    }


# ----------------------------------------------------------------------------- figures
def _plot(out, dmps, demo, modifications, plans, runs, fixed_log, figure8_log, no_base_task):
    from .common import pyplot

    plt = pyplot()
    elbow = dmps.elbow_index

    # Fig. 4 right: the right elbow under each modification.
    figure, axes = plt.subplots(len(modifications), 1, figsize=(9, 9), sharex=True)
    base = plans["none"]
    for ax, modification in zip(axes, modifications):
        plan, log = plans[modification.name], runs[modification.name]
        ax.plot(
            base["times"],
            base["positions"][:, elbow],
            "--",
            color="0.6",
            lw=1,
            label="unmodified pattern",
        )
        ax.plot(plan["times"], plan["positions"][:, elbow], color="C0", lw=1.2, label="DMP plan")
        ax.plot(log.times, log.actual[:, elbow], color="C3", lw=0.8, label="Talos (simulated)")
        if modification.name != "none":
            ax.axvspan(modification.start, modification.end, color="C1", alpha=0.12)
        ax.set_ylabel("right elbow [rad]")
        ax.set_title(modification.label, loc="left", fontsize=9)
    axes[0].legend(loc="upper right", fontsize=8, ncol=3)
    axes[-1].set_xlabel("time [s]")
    figure.suptitle("Fig. 4 right: right-elbow DMP modified in the shaded window")
    figure.tight_layout()
    figure.savefig(out / "fig4_elbow.png", dpi=120)
    plt.close(figure)

    # Drumming joint tracking (floating base, unmodified).
    drum = runs["none"]
    figure, axes = plt.subplots(6, 2, figsize=(10, 10), sharex=True)
    shown = drum.times <= 3.0
    for j, name in enumerate(DRUM_JOINTS):
        ax = axes[j % 6, j // 6]
        ax.plot(drum.times[shown], drum.desired[shown, j], color="C0", lw=1.2, label="plan")
        ax.plot(drum.times[shown], drum.actual[shown, j], "--", color="C3", lw=1, label="robot")
        ax.set_title(
            f"{name}  rms {1e3 * _rms(drum.actual[:, j] - drum.desired[:, j]):.2f} mrad",
            fontsize=8,
            loc="left",
        )
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    figure.suptitle("Drumming on standing Talos: DMP plan and joint angles [rad]")
    figure.tight_layout()
    figure.savefig(out / "drumming_tracking.png", dpi=110)
    plt.close(figure)

    # Demonstration: the task-space stroke and the joint trajectories from IK.
    figure, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    times = demo.joints.times
    axes[0].plot(times, demo.hand_targets[:, 0, 2], label="left wrist height [m]")
    axes[0].plot(times, demo.hand_targets[:, 1, 2], label="right wrist height [m]")
    axes[0].plot(
        times,
        0.1 * demo.hand_pitch[:, 1] + demo.hand_targets[:, 1, 2].mean(),
        ":",
        label="right wrist pitch (x0.1 rad, offset)",
    )
    axes[0].set_xlabel("time [s]")
    axes[0].legend(fontsize=7)
    axes[0].set_title("task-space stroke", fontsize=9)
    axes[1].plot(times, demo.joints.positions[:, 6:])
    axes[1].set_xlabel("time [s]")
    axes[1].set_title("right-arm joints from IK [rad] (demonstration)", fontsize=9)
    figure.tight_layout()
    figure.savefig(out / "demonstration.png", dpi=110)
    plt.close(figure)

    # Figure-8 hand path.
    figure, ax = plt.subplots(figsize=(5, 4.5))
    ax.plot(
        figure8_log.desired[:, 1],
        figure8_log.desired[:, 2],
        color="C0",
        lw=1.5,
        label="task-space DMP plan",
    )
    ax.plot(
        figure8_log.actual[:, 1],
        figure8_log.actual[:, 2],
        "--",
        color="C3",
        lw=1,
        label="right hand (simulated)",
    )
    ax.set_xlabel("y [m]")
    ax.set_ylabel("z [m]")
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    ax.set_title("Figure-8 with the right hand, Talos standing", fontsize=9)
    figure.tight_layout()
    figure.savefig(out / "figure8.png", dpi=120)
    plt.close(figure)

    # Base orientation and CoM while drumming.
    figure, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for k, label in enumerate(("roll", "pitch", "yaw")):
        axes[0].plot(drum.times, np.degrees(drum.base[:, 3 + k] - drum.base[0, 3 + k]), label=label)
    roll = np.degrees(no_base_task.base[:, 3] - no_base_task.base[0, 3])
    axes[0].plot(no_base_task.times, roll, ":", color="C0", label="roll, no pelvis task")
    axes[0].set_ylabel("pelvis orientation change [deg]")
    axes[0].legend(fontsize=8)
    for k, label in enumerate("xyz"):
        axes[1].plot(drum.times, 1e3 * (drum.com[:, k] - drum.com[0, k]), label=f"CoM {label}")
    axes[1].set_ylabel("CoM displacement [mm]")
    axes[1].set_xlabel("time [s]")
    axes[1].legend(fontsize=8)
    figure.suptitle("Standing balance while drumming (floating base, two sole contacts)")
    figure.tight_layout()
    figure.savefig(out / "base_com.png", dpi=110)
    plt.close(figure)

    # Controller time per tick.
    figure, ax = plt.subplots(figsize=(7, 4))
    floating = np.concatenate([log.tick_cpu_us for log in runs.values()])
    top = np.percentile(np.r_[floating, fixed_log.tick_cpu_us], 99.5)
    bins = np.linspace(0, top, 80)
    ax.hist(fixed_log.tick_cpu_us, bins, alpha=0.6, label="fixed-base upper body (nv = 32)")
    ax.hist(floating, bins, alpha=0.6, label="floating base, 2 contacts (nv = 50)")
    ax.axvline(1000.0, color="k", lw=0.8)
    ax.set_xlabel("compute_torques CPU time per tick [us] (1 kHz budget: 1000 us)")
    ax.set_ylabel("ticks")
    ax.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(out / "tick_times.png", dpi=110)
    plt.close(figure)


def main(argv=None) -> None:
    """Command line: ``python -m studies.humanoid OUT_DIR [--quick] [--seed N]``."""
    import argparse
    import json

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", nargs="?", default="results/humanoid")
    parser.add_argument("--quick", action="store_true", help="a few simulated seconds")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--backend", choices=BACKENDS, default="mujoco")
    args = parser.parse_args(argv)
    metrics = run(args.out_dir, quick=args.quick, seed=args.seed, backend=args.backend)
    keys = (
        "tick_us_median",
        "tick_us_p99",
        "tick_us_fixed_base_median",
        "tick_us_fixed_base_p99",
        "real_time_factor",
        "real_time_factor_cpu",
        "tracking_rms_rad",
        "figure8_rms_mm",
        "settle_time_s",
        "torque_limit_use_max",
        "position_limit_margin_rad",
        "fell",
        "n_cold_restarts",
        "n_fallbacks",
        "direct_solve_fraction",
        "native",
        "mujoco",
        "videos",
    )
    print(json.dumps({k: metrics[k] for k in keys if k in metrics}, indent=1))


if __name__ == "__main__":
    main()
