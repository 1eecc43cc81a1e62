"""Talos steps in place, then walks forward on flat ground in MuJoCo through the QP controller.

Plan (:mod:`dmpopt.walk_plan`): footsteps; a ZMP on the stance foot in single support and
moving between the feet in double support; the DCM from it backwards and the LIPM CoM
forwards; swing-foot references from two discrete DMPs fitted once to a demonstrated foot lift
(up, over and down) and re-targeted to each step's start and goal foothold.

Control: one :class:`dmpopt.control.InverseDynamicsController` (Talos ``reduced``, 32
actuated joints) with a posture task, the CoM task fed the plan's CoM position, velocity and
acceleration, the pelvis orientation, and, in single support, a swing-foot frame task. In each
double support the swing foot's contact is removed with a ramp (its normal force bound goes to
zero over the double support, while the ZMP plan moves onto the stance foot); it is added
back when MuJoCo reports the sole on the ground, where it landed, and the balance feedback
(DCM feedback, step adjustment) keeps the walk up when pushed or on unplanned ground
(:class:`Walker`).

Simulation: MuJoCo (:class:`dmpopt.sim.MujocoSimulator`), a 5 mm sphere at each sole corner on
a floor of friction 1, 1 kHz control and simulation; falls as in the humanoid study (pelvis
below 0.7 m).

``python -m dmpopt_studies.talos_walk OUT_DIR [--quick]``; :func:`run_walk` returns the metrics.
"""

from __future__ import annotations

import bisect
import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from dmpopt_robots import load_talos
from dmpopt_robots.plants import talos_realistic

from dmpopt import balance
from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    JointImpedance,
    PostureTask,
    SoleContact,
)
from dmpopt.exceptions import SimulationDiverged
from dmpopt.fitting import fit_rhythmic
from dmpopt.frequency_adaptation import heel_strike_phase
from dmpopt.parallel import map_runs
from dmpopt.sim import IDEAL, with_armature
from dmpopt.trajectory import Trajectory
from dmpopt.validation import flag
from dmpopt.walk_plan import fit_swing_dmps, footstep_plan, plan_walk, quintic

from .common import TIME_BUDGET, output_dir, pyplot, write_metrics
from .plant_sweep import collect, plot_sweep, sweep_cases, with_scaled_masses

DT = 1e-3  # [s] control and simulation period
STEP_LENGTH = 0.2  # [m] the moving foot lands this far ahead of the stance foot
SINGLE_SUPPORT = 0.6  # [s]
DOUBLE_SUPPORT = 0.2  # [s] weight transfer: the ZMP moves over, the contact ramps down
FOOT_LIFT = 0.08  # [m] swing height (the foot is over its foothold at half of it)
SWING_DESCENT = 0.4  # the fractions of the swing spent rising and coming down (fit_swing_dmps)
VIDEO_FPS = 10.0
INITIAL_HOLD, FINAL_HOLD = 1.0, 1.0  # [s]
STEPS = {"quick": (1, 3), "full": (2, 10)}  # (in place, forward); a closing step follows
FALL_HEIGHT = 0.7  # [m] the pelvis has fallen when lower
FLOOR_FRICTION = 1.0
POSTURE_WEIGHT, COM_WEIGHT, BASE_WEIGHT, SWING_WEIGHT = 1e-2, 10.0, 1.0, 10.0
COM_STIFFNESS, SWING_STIFFNESS = 50.0, 300.0  # [1/s^2] (damping critical)
DCM_GAIN = 5.0  # [1/s] the DCM error decays as exp(-DCM_GAIN t) (dmpopt.balance)
SUPPORT_MARGIN = 0.015  # [m] the commanded ZMP stays this far inside the soles
ADJUST_EVERY = 20  # [ticks] the capture-point foothold is recomputed at 50 Hz in a swing
ADJUST_STOP = 0.2  # [s] and not in the last 0.2 s before the planned touchdown (the foot is then
# over its foothold, fit_swing_dmps: a later goal it could not reach before it lands)
ADJUST_DEADBAND = 0.03  # [m] a predicted DCM error at touchdown below this keeps the foothold
TIMING_THRESHOLD = 0.1  # [m] and one above this may shorten the step (step timing adaptation)
REACH_FORWARD, REACH_BACKWARD = 0.4, -0.25  # [m] swing-foot reach along x from the stance foot
REACH_LATERAL = (0.15, 0.3)  # [m] its lateral distance from the stance foot (no crossing)
CROSSING = -0.05  # [m] a crossing step's lateral distance, allowed where the soles keep apart
FOOT_CLEARANCE = 0.02  # [m] by this much (balance.polygons_overlap)
TOUCHDOWN_RAMP = 0.03  # [s] the landed foot's normal-force bound ramps up over this
SEARCH_SPEED, SEARCH_DEPTH = 0.4, 0.1  # [m/s], [m] a late foot goes down to find the ground
SHORTEST_REMAINING = 0.15  # [s] step timing adaptation lands the foot no sooner than this
SHORTEST_SWING = 0.3  # [s] and no sooner than this after lift-off
SHORTEST_CORRECTION = 0.15  # [s] a step adjustment moves the swinging foot over at least this
SHORTEST_TRANSFER = 0.05  # [s] a double support after a step that could not catch the DCM
MIN_SWING = 0.2  # [s] a contact counts as touchdown this long after lift-off, once airborne
ARM_SWING_JOINTS = ("arm_left_4_joint", "arm_right_4_joint")  # elbows: axes about world y
ARM_SWING_AMPLITUDE = 0.25  # [rad] each elbow's swing about its posture, arms in anti-phase
SETTLED_SPEED = 0.02  # [m/s] a landed sole slower than this has come to rest
SETTLED_ANGULAR_SPEED = 0.1  # [rad/s] and turning slower than this lies on the ground
PUSH_DURATION = 0.1  # [s] a push's impulse is spread over this
_NO_CORRECTION = ((0.0, 0.0),) * 3  # Walker._correction_at's before any step adjustment


@dataclass
class WalkLog:
    """Every tick of a walk (n ticks)."""

    times: np.ndarray  # (n,)
    com: np.ndarray  # (n, 3) measured [m]
    dcm: np.ndarray  # (n, 2) measured c + c'/omega [m]
    feet: np.ndarray  # (n, 2, 3) left, right sole frame positions [m]
    normal_force: np.ndarray  # (n, 2) measured left, right normal forces [N]
    cop_margin: np.ndarray  # (n, 2) measured CoP distance inside each sole [m] (nan unloaded)
    yaw_moment: np.ndarray  # (n,) measured vertical moment of the ground on the soles [N m]
    reference_com: np.ndarray  # (n, 2) the plan's CoM when the tick ran (it is re-planned) [m]
    reference_dcm: np.ndarray  # (n, 2) the plan's DCM when the tick ran [m]
    tick_cpu_us: np.ndarray  # (n,)
    fell: bool
    diverged: str | None


def _robot_and_start():
    robot = load_talos("reduced")
    q0 = np.array(robot.reference_configuration)
    return robot, q0


def _sole_ids(robot) -> list:
    """The frame ids of the soles, left then right."""
    return [robot.model.getFrameId(f) for f in robot.foot_frames]


def _sole_positions(data, sole_ids) -> np.ndarray:
    return np.array([data.oMf[i].translation for i in sole_ids])


@dataclass
class StepRecord:
    """What happened to one step: when its foot left and reached the ground [s], where it
    was sent (the swing's last target, after step adjustment) and where it landed [m]."""

    side: str
    lift_off: float
    touchdown: float | None = None
    target: np.ndarray | None = None
    landed: np.ndarray | None = None
    from_contact: bool = False


class Walker:
    """The tasks, the controller, the contact switching and the balance feedback of a walk.

    ``references(tick, state)`` sets the task targets from the measured ``state`` (a
    :class:`dmpopt.sim.SimState`) and switches the contacts:

    - release (start of a double support) and lift-off at the plan's times;
    - touchdown when the simulator reports the swinging sole in contact (after half the
      swing), early or late: the contact is added at the measured sole position with a force
      ramp, and the plan is re-timed (:meth:`WalkPlan.with_touchdown`: a late foot shifts
      the rest of the walk, an early one, met by higher ground, keeps the next lift-off) and
      moved to the landed foothold, its height carried into the later footholds
      (:meth:`WalkPlan.with_goal`). A foot still in the air at the planned touchdown keeps
      going down at ``SEARCH_SPEED``. The joint loop's desired state restarts at the
      measured one at touchdown and once the landed sole is at rest (``SETTLED_SPEED``, at
      the latest after ``TOUCHDOWN_RAMP``, :meth:`_settle`). The sole may roll onto the
      ground while it settles; at rest on three corners or more its contact holds it as it
      lies, and its tilt orients the next swinging sole (:meth:`_conform`). The CoM height
      follows the ground under the plan's ZMP (:meth:`_ground_offset`). The swing is over
      its foothold while still half ``FOOT_LIFT`` high (:func:`fit_swing_dmps`), so that
      higher ground is met on the foothold, not on an edge;
    - with ``feedback``: the DCM feedback of :mod:`dmpopt.balance` on the commanded ZMP,
      clipped to the support polygon of the feet in contact, gives the CoM its LIPM
      acceleration; during each swing the capture-point foothold is recomputed from the
      measured DCM every ``ADJUST_EVERY`` ticks (once it moves the foothold by
      ``ADJUST_DEADBAND`` or more), within the reachable box; the swinging foot is moved
      onto it by a quintic added to the swing DMP's output (:func:`dmpopt.walk_plan.quintic`,
      over by the swing's horizontal arrival), and a shorter step speeds the DMPs up
      (:meth:`dmpopt.stepper.Stepper.set_tau`). The box lets the foot cross past the stance
      foot's line by up to ``-CROSSING`` where the soles keep ``FOOT_CLEARANCE`` apart
      (:meth:`_uncross`). A touchdown with the DCM outside both soles shortens the double
      support before the next step, down to ``SHORTEST_TRANSFER``, as far as that step needs
      to catch the DCM in reach (:meth:`_retime_transfer`). Without the feedback the CoM task
      tracks the plan's CoM (the open-loop walk).

    With ``nominal_plant`` the controller's model carries its armature and a
    :class:`JointImpedance` closes the joint loop (as in the humanoid study).
    """

    def __init__(
        self, robot, q0, plan, swing_dmps, nominal_plant=None, feedback=True, arm_swing=None
    ):
        impedance = None
        if nominal_plant is not None:
            robot = with_armature(robot, nominal_plant)
            impedance = JointImpedance.for_plant(robot, DT, nominal_plant)
        self.robot, self.plan, self.swing_dmps = robot, plan, swing_dmps
        self.feedback = feedback
        self.omega = 1.0 / plan.time_constant
        self._omega_squared = self.omega**2  # [1/s^2] balance.lipm_acceleration's
        self._feedback_gain = 1.0 + DCM_GAIN / self.omega  # balance.dcm_feedback_zmp's
        self.data = robot.create_data()  # the measured state's kinematics
        pin.framesForwardKinematics(robot.model, self.data, q0)
        self._placements_stale = False  # self.data.oMf is the measured state's (_placement)
        self.sole_rotation = {
            f: self.data.oMf[robot.model.getFrameId(f)].rotation.copy() for f in robot.foot_frames
        }  # as planned, on level ground
        self._tilt = np.eye(3)  # the ground's tilt under the last sole that came to rest
        self._conforming = None  # (foot, frame) landed, its ground's tilt not yet measured
        self._ground = {f: self.data.oMf[robot.model.getFrameId(f)].translation[2]
                        for f in robot.foot_frames}  # fmt: skip
        self._level = dict(self._ground)  # [m] where each foot last landed
        self._frame_ids = [robot.model.getFrameId(f) for f in robot.foot_frames]
        self._com_height = pin.centerOfMass(robot.model, self.data, q0)[2]  # [m] world
        corners = np.asarray(robot.sole_corners)[:, :2]
        self._polygon_corners = corners - SUPPORT_MARGIN * np.sign(corners)
        actuated = np.sort(
            np.concatenate([robot.configuration_indices([n]) for n in robot.actuated_joint_names])
        )
        posture = PostureTask(robot, weight=POSTURE_WEIGHT, stiffness=10.0)
        posture.set_reference(q0[actuated])
        self.posture, self._posture_reference = posture, q0[actuated].copy()
        self._arm_stepper = None
        if arm_swing is not None:  # a rhythmic DMP on the elbows, phase-locked to the gait
            names = list(robot.actuated_joint_names)
            self._arm_joints = [names.index(j) for j in ARM_SWING_JOINTS]
            self._arm_stepper = arm_swing.stepper(DT, on_limit_cycle=True)
        self.com_task = ComTask(robot, weight=COM_WEIGHT, stiffness=COM_STIFFNESS)
        base = FrameTask(
            robot, "base_link", weight=BASE_WEIGHT, stiffness=50.0, components="orientation"
        )
        self.swing_tasks = {
            f: FrameTask(robot, f, weight=SWING_WEIGHT, stiffness=SWING_STIFFNESS)
            for f in robot.foot_frames
        }
        contacts = [SoleContact(robot, f) for f in robot.foot_frames]
        self._contacts = {c.frame: c for c in contacts}
        tasks = [posture, self.com_task, base]
        self.controller = InverseDynamicsController(
            robot, tasks, contacts, time_budget=TIME_BUDGET, joint_impedance=impedance
        )
        for swinging, standing in (robot.foot_frames, robot.foot_frames[::-1]):
            # the single supports' QPs, built now rather than in the tick that switches
            self.controller.prepare([standing])
            self.controller.prepare([standing], [*tasks, self.swing_tasks[swinging]])
        self._transfer = DOUBLE_SUPPORT  # [s] a double support
        self._next = 0  # the step under way or next
        self._released = False  # the next step's foot is being unloaded
        self._settling = None  # (foot, touchdown tick) of a landed foot not yet at rest
        self._swing = None  # (horizontal, vertical) DMP steppers of the step under way
        self._reference = plan  # the plan at the lift-off of the step under way
        self.records: list[StepRecord] = []
        self.zmp_command = np.zeros(2)  # the last commanded ZMP [m]
        self._polygon_key, self._polygon, self._polygon_rows = None, None, []
        self._offsets = (None, {})  # _ground_offset's plan and its segments' grounds

    def _frame(self, step) -> str:
        return f"{step.side}_sole_link"

    def _measure(self, state):
        """CoM [m] and CoM velocity [m/s] of the measured state (its sole placements when
        :meth:`_placement` asks: most ticks do not)."""
        pin.centerOfMass(self.robot.model, self.data, state.q_measured, state.v_measured)
        self._placements_stale = True
        return self.data.com[0], self.data.vcom[0]

    def _placement(self, foot: int):
        """The measured placement of sole ``foot`` (0 left, 1 right), a pinocchio.SE3 (a
        view into the walker's data: valid in this tick)."""
        if self._placements_stale:
            pin.updateFramePlacements(self.robot.model, self.data)
            self._placements_stale = False
        return self.data.oMf[self._frame_ids[foot]]

    def references(self, tick: int, state) -> None:
        """Targets and contact switches at tick ``tick`` (time ``tick * DT``) from the
        measured ``state``."""
        t = tick * DT
        com, com_velocity = self._measure(state)
        if self._settling is not None:
            self._settle(tick)
        if self._conforming is not None:
            self._conform(state)
        steps = self.plan.footsteps
        i = self._next
        if self._swing is not None:
            self._swinging(i, t, state, com, com_velocity)
        i = self._next
        if i < len(steps) and self._swing is None:
            if not self._released and t >= self.plan.lift_off[i] - self._transfer - DT / 2:
                # The ramp ends half a tick early, so that the controller drops the contact at
                # the lift-off tick, when the swing task comes in (no tick with neither).
                transfer = max(self._transfer - 0.5 * DT, 0.0)
                self.controller.remove_contact(self._frame(steps[i]), transfer)
                self._released = True
            if t >= self.plan.lift_off[i] - DT / 2:
                self._lift_off(i, t)
        self._com_targets(t, com, com_velocity)
        if self._arm_stepper is not None:
            self._swing_arms()

    def _settle(self, tick: int) -> None:
        """Once the landed sole has come to rest (or at the end of its force ramp), the joint
        loop's desired state restarts at the measured one. It integrates the QP's motion,
        which followed the swing down past the point where the ground stopped the foot (an
        early touchdown still descending, or a late one feeling for the ground): kept, the
        landed leg's stiff joint loop goes on pushing it into the floor, carries the whole
        weight on it and lifts the other, standing foot off in the double support."""
        foot, touchdown = self._settling
        self._placement(foot)  # (the frames of this tick's state)
        velocity = pin.getFrameVelocity(
            self.robot.model, self.data, self._frame_ids[foot], pin.LOCAL_WORLD_ALIGNED
        )
        elapsed = (tick - touchdown) * DT
        if np.linalg.norm(velocity.linear) < SETTLED_SPEED or elapsed >= TOUCHDOWN_RAMP:
            self.controller.joint_impedance.reset()
            self._settling = None

    def _conform(self, state) -> None:
        """Once a landed sole is at rest with three corners or more down, it lies on the
        ground: its contact holds it as it lies (not level as planned, which on a slope
        would keep it on an edge), and its tilt (:func:`dmpopt.balance.ground_tilt`)
        orients the next swinging sole, so that it lands flat on ground that goes on the
        same way."""
        foot, frame = self._conforming
        placement = self._placement(foot)
        velocity = pin.getFrameVelocity(
            self.robot.model, self.data, self._frame_ids[foot], pin.LOCAL_WORLD_ALIGNED
        )
        down = np.count_nonzero(state.in_contact.reshape(2, -1)[foot])
        if (
            down >= 3
            and np.linalg.norm(velocity.linear) < SETTLED_SPEED
            and np.linalg.norm(velocity.angular) < SETTLED_ANGULAR_SPEED
        ):
            self._tilt = balance.ground_tilt(placement.rotation[:, 2])
            self._contacts[frame].reference_placement = placement.copy()
            self._conforming = None
            return
        # until then the sole may roll onto the ground: its held attitude is the measured one
        reference = self._contacts[frame].reference_placement
        if reference is not None:
            reference.rotation = placement.rotation

    def _swing_arms(self) -> None:
        position, velocity, acceleration = self._arm_stepper.step()
        reference = self._posture_reference.copy()
        velocities, accelerations = np.zeros_like(reference), np.zeros_like(reference)
        reference[self._arm_joints] += position
        velocities[self._arm_joints], accelerations[self._arm_joints] = velocity, acceleration
        self.posture.set_reference(reference, velocities, accelerations)

    def _lift_off(self, i: int, t: float) -> None:
        step = self.plan.footsteps[i]
        dmps = self.swing_dmps
        self._swing = tuple(
            dmp.replace(start=step.start[axes], goal=step.goal[axes]).stepper(DT, compile=True)
            for dmp, axes in ((dmps.horizontal, slice(0, 2)), (dmps.vertical, slice(2, 3)))
        )
        self._reference, self._lift_tick = self.plan, int(round(t / DT))
        self._touchdown_target = float(self.plan.touchdown[i])
        self._airborne = False  # the sole has been seen out of contact in this swing
        self._swing_tau = dmps.horizontal.tau
        self._target = step.goal.copy()
        frame = self._frame(step)
        self._swing_rotation = self._tilt @ self.sole_rotation[frame]
        if self._conforming is not None and self._conforming[1] == frame:
            self._conforming = None  # lifted before it came to rest
        self.records.append(StepRecord(step.side, t, target=self._target))
        self.controller.add_task(self.swing_tasks[frame])
        self._correction = None  # (start [s], duration [s], start state, offset) of _correction_at
        self._set_swing_target(i, t, first=True)

    def _swinging(self, i, t, state, com, com_velocity) -> None:
        """One tick of step ``i``'s swing: touchdown from contact, step adjustment, the swing
        target."""
        step = self.plan.footsteps[i]
        frame = self._frame(step)
        foot = self.robot.foot_frames.index(frame)
        lift_off = self.plan.lift_off[i]
        in_contact = state.in_contact.reshape(2, -1)[foot].any()
        self._airborne |= not in_contact and t - lift_off >= MIN_SWING / 2
        if self._airborne and in_contact and t - lift_off >= MIN_SWING:
            self._touchdown(i, t, frame, foot)
            if self.feedback:
                self._retime_transfer(i, t, com, com_velocity)
            return
        if t >= self.plan.touchdown[i] - DT / 2:  # late: the single support goes on
            self.plan = self.plan.with_touchdown(i, t + DT)
        if (
            self.feedback
            and t < self._touchdown_target - ADJUST_STOP
            and (int(round(t / DT)) - self._lift_tick) % ADJUST_EVERY == 0
        ):
            self._adjust_step(i, t, com, com_velocity)
        self._set_swing_target(i, t, late=max(t - self._touchdown_target, 0.0))

    def _adjust_step(self, i, t, com, com_velocity) -> None:
        """Step adjustment from the measured DCM (:mod:`dmpopt.balance`): the DCM predicted
        at touchdown with the stance sole's ZMP doing what it can (``recovery_zmp``); if
        that leaves a large error, the time to touchdown shortened as far as needed to keep
        the capture-point foothold in reach (the swing DMPs sped up); then that foothold,
        clipped to the box (their goal)."""
        reference = self._reference
        step = reference.footsteps[i]
        xi = balance.dcm(com[:2], com_velocity[:2], self.omega)
        lower, upper = self._reach(step)
        zmp_reference, dcm_reference = reference.zmp_and_dcm(t)
        end = reference.dcm(reference.touchdown[i])
        remaining = self._touchdown_target - t
        # the ankle first: the ZMP that would cancel the DCM error, as far as the sole allows
        zmp = balance.recovery_zmp(
            xi, dcm_reference, zmp_reference, self._support_polygon(), self.omega, remaining
        )
        error = balance.predict_dcm(xi, zmp, self.omega, remaining) - end
        shortened = remaining
        if np.linalg.norm(error) > TIMING_THRESHOLD:  # pushed: land sooner if out of reach
            shortest = max(SHORTEST_REMAINING, self.plan.lift_off[i] + SHORTEST_SWING - t)
            shortened = balance.capture_time(
                xi, zmp, self.omega, end - step.goal[:2], lower, upper,
                min(shortest, remaining), remaining,
            )  # fmt: skip
        foothold = balance.capture_foothold(
            xi, zmp, self.omega, shortened, end, step.goal[:2], lower, upper
        )
        foothold = self._uncross(step, foothold)
        faster = shortened < remaining - DT
        small = np.linalg.norm(foothold - step.goal[:2]) < ADJUST_DEADBAND
        if small and np.allclose(self._target[:2], step.goal[:2]):
            return  # a small error: the ZMP feedback alone handles it
        if np.linalg.norm(foothold - self._target[:2]) < 1e-3 and not faster:
            return
        self._target = np.append(foothold, step.goal[2])
        self.records[-1].target = self._target
        if faster:
            self._swing_tau *= shortened / remaining
            for stepper in self._swing:
                stepper.set_tau(self._swing_tau)
            self._touchdown_target = t + shortened
        # the foot is moved onto the new foothold by a quintic added to the swing DMP (whose
        # own goal change would be followed too slowly: a 0.1 m change 0.3 s before the
        # touchdown leaves it 28 mm short), over by the swing's horizontal arrival
        lift_off = self.plan.lift_off[i]
        arrival = self._touchdown_target - 0.5 * SWING_DESCENT * (self._touchdown_target - lift_off)
        self._correction = (
            t, max(arrival - t, SHORTEST_CORRECTION), self._correction_at(t),
            self._target[:2] - step.goal[:2],
        )  # fmt: skip
        self.plan = reference.with_goal(i, self._target)
        if self._touchdown_target != reference.touchdown[i]:
            self.plan = self.plan.with_touchdown(i, self._touchdown_target)

    def _correction_at(self, t: float):
        """Position, velocity and acceleration [m, m/s, m/s^2] added to the swing DMP's
        horizontal output at ``t`` by step adjustment (zero before any)."""
        if self._correction is None:
            return np.zeros(2), np.zeros(2), np.zeros(2)
        start, duration, state, offset = self._correction
        return quintic(*state, offset, duration, t - start)

    def _set_swing_target(self, i: int, t: float, first: bool = False, late: float = 0.0):
        if first:
            outputs = [(s.position, s.velocity, s.acceleration) for s in self._swing]
        else:
            outputs = [s.step() for s in self._swing]
        # on floats: the horizontal DMP's x, y and the vertical one's z of each output, the
        # step adjustment's correction added to x and y (zero without one)
        (position, velocity, acceleration), (height, rise, lift) = (
            [a.tolist() for a in output] for output in outputs
        )
        added = _NO_CORRECTION if self._correction is None else self._correction_at(t)
        (x, y), (vx, vy), (ax, ay) = (
            (a + b for a, b in zip(total, more))
            for total, more in zip((position, velocity, acceleration), added)
        )
        (z,), (vz,), (az,) = height, rise, lift
        if late > 0.0:  # feel for the ground: down at SEARCH_SPEED, at most SEARCH_DEPTH
            z -= min(SEARCH_SPEED * late, SEARCH_DEPTH)
            vz = -SEARCH_SPEED if SEARCH_SPEED * late < SEARCH_DEPTH else 0.0
            az = 0.0
        position, velocity, acceleration = (
            np.array([x, y, z]), np.array([vx, vy, vz]), np.array([ax, ay, az])
        )  # fmt: skip
        task = self.swing_tasks[self._frame(self.plan.footsteps[i])]
        # the sole's attitude is set at lift-off and kept through the swing: later ticks set
        # the position alone (and the linear velocity and acceleration, the angular ones zero)
        target = pin.SE3(self._swing_rotation, position) if first else position
        task.set_target(target, velocity, acceleration)

    def _touchdown(self, i: int, t: float, frame: str, foot: int) -> None:
        """The swinging foot reported in contact: its contact comes in (with a force ramp)
        at the measured placement; the plan shifts to the touchdown time and foothold."""
        # held where it landed, oriented as it was sent (the measured attitude at the first
        # touch is the impact's: held, it would keep the sole on an edge); once at rest on
        # the ground, as it lies (_conform)
        landed = self._placement(foot).translation.copy()
        placement = pin.SE3(self._swing_rotation, landed)
        self.controller.remove_task(self.swing_tasks[frame])
        self.controller.add_contact(frame, placement, TOUCHDOWN_RAMP)
        if self.controller.joint_impedance is not None:
            self._settling = (foot, int(round(t / DT)))
            self.controller.joint_impedance.reset()
        self._conforming = (foot, frame)
        self._level[frame] = landed[2]
        self._offsets = (None, {})  # _ground_offset's grounds changed
        early = t < self.plan.touchdown[i] - DT / 2  # higher ground: the rhythm is kept
        self.plan = self.plan.with_touchdown(i, t, shift_later=not early).with_goal(i, landed)
        record = self.records[-1]
        record.touchdown, record.landed, record.from_contact = t, landed, True
        if self._arm_stepper is not None:  # eq. (21): the arms' oscillator at heel strike
            self._arm_stepper.reset_phase(heel_strike_phase(foot))
        self._swing, self._released, self._next = None, False, i + 1
        self._transfer = DOUBLE_SUPPORT

    def _retime_transfer(self, i: int, t: float, com, com_velocity) -> None:
        """After step ``i``'s touchdown with the measured DCM outside the support polygon of
        both feet (no ankle torque can stop it: it is not 0-step capturable [Koolen2012]_),
        the double support before the next step shortened if that step could not catch the
        DCM otherwise (:func:`dmpopt.balance.transfer_time`): after a hurried step the DCM
        keeps running away while the weight moves over."""
        j = i + 1
        steps = self.plan.footsteps
        if j >= len(steps):
            return
        xi = balance.dcm(com[:2], com_velocity[:2], self.omega)
        if self._inside_both_soles(xi):
            return
        step = steps[j]
        lower, upper = self._reach(step)
        planned = float(self.plan.lift_off[j] - t)
        swing = float(self.plan.touchdown[j] - self.plan.lift_off[j])
        transfer = balance.transfer_time(
            xi - self.plan.dcm(t), step.goal[:2], self.omega, lower, upper, swing,
            min(SHORTEST_TRANSFER, planned), planned,
        )  # fmt: skip
        if transfer < planned - DT:
            self.plan = self.plan.with_lift_off(j, t + transfer)
            self._transfer = transfer

    def _uncross(self, step, foothold) -> np.ndarray:
        """``foothold`` [m], or, if its sole would come within ``FOOT_CLEARANCE`` of the
        standing sole (:func:`dmpopt.balance.polygons_overlap`), the nearest foothold of the
        box without crossing: a crossing step is taken only where the feet pass each
        other, ahead or behind."""
        stance = 1 - self.robot.foot_frames.index(self._frame(step))
        placement = self._placement(stance)
        swing = self._tilt @ self.sole_rotation[self._frame(step)]
        outline = self._sole_outline(swing, foothold)
        standing = self._sole_outline(placement.rotation, placement.translation[:2])
        if not balance.polygons_overlap(outline, standing, FOOT_CLEARANCE):
            return foothold
        return np.clip(foothold, *self._reach(step, crossing=False))

    def _sole_outline(self, rotation, position) -> np.ndarray:
        """The sole's corners [m] (counter-clockwise) seen from above, the sole frame at
        ``position`` (x, y) with ``rotation``."""
        corners = (rotation @ np.asarray(self.robot.sole_corners).T).T[:, :2]
        return balance.convex_hull(corners + position)

    def _inside_both_soles(self, point) -> bool:
        """Whether ``point`` [m] lies in the convex hull of both soles (shrunk by
        ``SUPPORT_MARGIN``)."""
        local = np.column_stack([self._polygon_corners, np.zeros(len(self._polygon_corners))])
        placements = [self._placement(foot) for foot in (0, 1)]
        corners = [(p.rotation @ local.T).T[:, :2] + p.translation[:2] for p in placements]
        hull = balance.convex_hull(np.vstack(corners))
        return bool(np.allclose(balance.clip_to_polygon(point, hull), point, atol=0.0))

    def _reach(self, step, crossing: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """The box [m] the swinging foot of ``step`` can reach from its stance foot: with
        ``crossing``, past the stance foot's line by up to ``-CROSSING`` (a crossing step,
        :meth:`_uncross` keeps the soles apart)."""
        inner = CROSSING if crossing else REACH_LATERAL[0]
        lateral = np.array([inner, REACH_LATERAL[1]]) * (1.0 if step.side == "left" else -1.0)
        lower = step.stance[:2] + np.array([REACH_BACKWARD, lateral.min()])
        upper = step.stance[:2] + np.array([REACH_FORWARD, lateral.max()])
        return lower, upper

    def _com_targets(self, t: float, com, com_velocity) -> None:
        """The CoM task: the LIPM acceleration of the commanded ZMP (feedback), or the
        plan's CoM (open loop); the height follows the plan above the stance ground."""
        offset, rate = self._ground_offset(t)
        height = self._com_height + offset
        if not self.feedback:
            self.reference_com = self.plan.com(t)[0][:2]
            self.reference_dcm = self.plan.dcm(t)
            position, velocity, acceleration = self.plan.com(t)
            position[2], velocity[2] = height, rate
            self.com_task.set_target(position, velocity, acceleration)
            return
        # balance.dcm, dcm_feedback_zmp, clip_to_polygon and lipm_acceleration, each bit, on
        # the floats of one tick (a call with their checks on arrays of two took ~5 us each)
        zx, zy, dx, dy, reference_x, reference_y = self.plan.values_at(t)[:6]
        self.reference_com, self.reference_dcm = (reference_x, reference_y), (dx, dy)
        x, y, _ = com.tolist()
        vx, vy, _ = com_velocity.tolist()
        omega, gain = self.omega, self._feedback_gain
        xi_x, xi_y = x + vx / omega, y + vy / omega
        zx, zy = zx + gain * (xi_x - dx), zy + gain * (xi_y - dy)
        polygon = self._support_polygon()
        if polygon is not None and not self._inside_polygon(zx, zy):
            zx, zy = balance.clip_to_polygon(np.array([zx, zy]), polygon).tolist()
        self.zmp_command = np.array([zx, zy])
        square = self._omega_squared
        self.com_task.set_target(
            np.array([x, y, height]),
            np.array([vx, vy, rate]),
            np.array([square * (x - zx), square * (y - zy), 0.0]),
        )

    def _inside_polygon(self, px: float, py: float) -> bool:
        """Whether the point lies in the support polygon (:meth:`_support_polygon`, not
        None): the test of :func:`dmpopt.balance.clip_to_polygon`, which returns it then."""
        rows = self._polygon_rows
        return len(rows) >= 3 and min(balance.edge_signs(px, py, rows)) >= 0.0

    def _support_polygon(self):
        """Convex hull of the soles in contact (shrunk by ``SUPPORT_MARGIN``), or None; kept
        while the contact set is the same (a standing foot does not move)."""
        active = self.controller.active_contacts
        if self._polygon_key != active:
            corners = []
            for foot, frame in enumerate(self.robot.foot_frames):
                if frame in active:
                    placement = self._placement(foot)
                    local = np.column_stack([self._polygon_corners, np.zeros(4)])
                    corners.append(
                        (placement.rotation @ local.T).T[:, :2] + placement.translation[:2]
                    )
            self._polygon_key = active
            self._polygon = balance.convex_hull(np.vstack(corners)) if corners else None
            self._polygon_rows = [] if self._polygon is None else self._polygon.tolist()
        return self._polygon

    def _ground_offset(self, t: float) -> tuple[float, float]:
        """Height [m] of the ground under the plan's ZMP relative to the start, and its rate
        [m/s]: each foot's ground is where it last landed (an unplanned step down or up, or a
        slope, lowers or raises the CoM with it), and in a double support the height moves
        linearly from the foot being unloaded to the one being loaded, as the ZMP does (a
        live measurement would feed a rising, unloading foot back into the CoM height)."""
        plan, segments = self._offsets
        if plan is not self.plan:  # (a new plan, or a foot landed: _touchdown)
            plan, segments = self.plan, {"times": self.plan.knot_times.tolist()}
            self._offsets = plan, segments
        times = segments["times"]
        k = min(max(bisect.bisect_right(times, t) - 1, 0), len(times) - 2)
        segment = segments.get(k)
        if segment is None:
            segment = segments[k] = self._ground_segment(plan, k)
        low, high, start, span = segment
        if span <= 0.0 or low == high:
            return low, 0.0
        fraction = min(max((t - start) / span, 0.0), 1.0)
        return low + fraction * (high - low), (high - low) / span

    def _ground_segment(self, plan, k: int) -> tuple:
        """:meth:`_ground_offset`'s ground under ZMP knots ``k`` and ``k + 1`` [m], the
        segment's start [s] and length [s]."""
        level = {side: self._level[f] - self._ground[f]
                 for side, f in zip(("left", "right"), self.robot.foot_frames)}  # fmt: skip
        times, steps = plan.knot_times, plan.footsteps

        def knot(j: int) -> float:  # the ground under the ZMP knot j
            step = (j - 2) // 2
            if step < 0 or step >= len(steps):  # standing: the ZMP between the feet
                return 0.5 * (level["left"] + level["right"])
            return level["right" if steps[step].side == "left" else "left"]

        return knot(k), knot(k + 1), float(times[k]), float(times[k + 1] - times[k])


def make_simulator(robot, plant=IDEAL, boxes=()):
    """MuJoCo with the soles (left then right) on the floor, ``boxes`` on it (see
    :class:`dmpopt.sim.MujocoSimulator`) and ``plant``'s joints, actuators and sensors."""
    from dmpopt.sim import MujocoSimulator

    points = [(f, c) for f in robot.foot_frames for c in robot.sole_corners]
    return MujocoSimulator(
        robot.model,
        robot.source,
        DT,
        points,
        FLOOR_FRICTION,
        fall_frame="base_link",
        fall_height=FALL_HEIGHT,
        plant=plant,
        boxes=boxes,
    )


def _sole_bounds(robot) -> tuple:
    """The sole's extent in its frame: smallest and largest x, smallest and largest y [m]."""
    corners = np.asarray(robot.sole_corners)
    return corners[:, 0].min(), corners[:, 0].max(), corners[:, 1].min(), corners[:, 1].max()


def _foot_loads(forces, points, data, sole_ids, bounds) -> tuple[np.ndarray, np.ndarray, float]:
    """Measured normal force of each foot [N], its CoP's distance inside the sole [m], and
    the vertical moment of the contact forces about each sole frame's origin, summed [N m]
    (``forces``, ``points``: a :class:`dmpopt.sim.SimState`'s ``contact_forces`` and
    ``contact_positions``; ``sole_ids``: :func:`_sole_ids`; ``bounds``:
    :func:`_sole_bounds`; ``data``: with the frame placements of that state)."""
    forces = forces.reshape(2, -1, 3)
    points = points.reshape(2, -1, 3)
    normal = forces[:, :, 2].sum(axis=1)
    margin = np.full(2, np.nan)
    x_min, x_max, y_min, y_max = bounds
    yaw = 0.0
    for foot, frame_id in enumerate(sole_ids):
        placement = data.oMf[frame_id]
        arms = points[foot] - placement.translation
        yaw += float(np.sum(arms[:, 0] * forces[foot, :, 1] - arms[:, 1] * forces[foot, :, 0]))
        if normal[foot] > 1.0:
            cop = forces[foot, :, 2] @ points[foot] / normal[foot]
            local = placement.actInv(cop)
            margin[foot] = min(
                local[0] - x_min, x_max - local[0], local[1] - y_min, y_max - local[1]
            )
    return normal, margin, yaw


def simulate(
    robot,
    q0,
    walker,
    duration: float,
    record_every: int = 0,
    plant=IDEAL,
    push=None,
    boxes=(),
    feet: bool = True,
    loads: bool = True,
):
    """Run the walk in MuJoCo on ``plant`` (and ``boxes`` on the floor) for ``duration``
    seconds; stop at a fall. ``push = (step, delay, impulse)``: a world-frame impulse [N s]
    on the pelvis, spread over ``PUSH_DURATION``, ``delay`` seconds after the lift-off of
    step ``step`` (a fixed phase of its single support); the impulse may be a function,
    called at that tick before the push, that returns it (the pushed walks of
    :mod:`dmpopt_studies.talos_walk_recovery` part there). ``feet`` False leaves the feet's
    logs (positions, loads, CoP margins, yaw moment) NaN, for a run judged without them
    (they do not feed back: the walk is the same); ``loads`` False the loads, CoP margins
    and yaw moment alone."""
    simulator = make_simulator(robot, plant, boxes)
    pushed = push is None
    state = simulator.reset(q0)
    data = robot.create_data()
    omega = 1.0 / walker.plan.time_constant
    n = int(round(duration / DT))
    com, dcm = np.zeros((n, 3)), np.zeros((n, 2))
    reference_com, reference_dcm = np.zeros((n, 2)), np.zeros((n, 2))
    measure_feet, feet = flag("feet", feet), np.full((n, 2, 3), np.nan)
    measure_loads = measure_feet and flag("loads", loads)
    normal, margin, yaw = np.full((n, 2), np.nan), np.full((n, 2), np.nan), np.full(n, np.nan)
    tick = np.zeros(n)
    frames = []
    sole_ids, bounds = _sole_ids(robot), _sole_bounds(robot)
    # what the loop does not feed back is computed after it, from each tick's state (there
    # the model's data stay in the cache; the same numbers)
    configurations, velocities = np.empty((n, robot.model.nq)), np.empty((n, robot.model.nv))
    contact_forces = np.empty((n, *state.contact_forces.shape)) if measure_loads else None
    contact_points = np.empty((n, *state.contact_positions.shape)) if measure_loads else None
    fell, diverged = False, None
    for k in range(n):
        t = k * DT
        records = walker.records
        if not pushed and len(records) > push[0] and t >= records[push[0]].lift_off + push[1]:
            impulse = push[2]() if callable(push[2]) else push[2]
            simulator.push_impulse("base_link", impulse, duration=PUSH_DURATION)
            pushed = True
        walker.references(k, state)
        reference_com[k], reference_dcm[k] = walker.reference_com, walker.reference_dcm
        begin = time.thread_time_ns()
        tau = walker.controller.compute_torques(state.q_measured, state.v_measured, t)
        tick[k] = (time.thread_time_ns() - begin) / 1e3
        configurations[k], velocities[k] = state.q, state.v
        if measure_loads:
            contact_forces[k], contact_points[k] = state.contact_forces, state.contact_positions
        if record_every and k % record_every == 0:
            frames.append(state.q.copy())
        try:
            state = simulator.step(tau)
        except SimulationDiverged as error:
            diverged = str(error)
        fell = state.fallen
        if fell or diverged:
            n = k + 1
            break
    for k in range(n):
        com[k] = pin.centerOfMass(robot.model, data, configurations[k], velocities[k])
        dcm[k] = com[k, :2] + data.vcom[0][:2] / omega
        if measure_feet:
            pin.updateFramePlacements(robot.model, data)
            feet[k] = _sole_positions(data, sole_ids)
            if measure_loads:
                normal[k], margin[k], yaw[k] = _foot_loads(
                    contact_forces[k], contact_points[k], data, sole_ids, bounds
                )
    log = WalkLog(
        np.arange(n) * DT, com[:n], dcm[:n], feet[:n], normal[:n], margin[:n], yaw[:n],
        reference_com[:n], reference_dcm[:n], tick[:n],
        fell, diverged,
    )  # fmt: skip
    return log, simulator, frames


# ------------------------------------------------------------------------------- the study
def walk_sweep(quick: bool, runner=None) -> dict:
    """``plant_sweep`` of the walk (the quick plan's four steps and a closing one per case):
    steps taken and falls against each plant parameter (:mod:`dmpopt_studies.plant_sweep`), the runs
    where ``runner`` says."""
    robot, _ = _robot_and_start()
    cases = sweep_cases(talos_realistic(robot), quick)
    inputs = [(plant, mass) for _, _, plant, mass in cases]
    return collect(cases, map_runs(_sweep_case, inputs, runner, label="plant sweep, walk"))


def _sweep_case(case) -> dict:
    plant, mass = case
    robot, q0 = _robot_and_start()
    plan, swing_dmps = build_plan(robot, q0, quick=True)
    walker = Walker(with_scaled_masses(robot, mass), q0, plan, swing_dmps, talos_realistic(robot))
    log, _, _ = simulate(robot, q0, walker, plan.duration, 0, plant, loads=False)
    return _step_counts(log, walker, robot)


def build_plan(robot, q0, quick: bool, step_length: float = STEP_LENGTH):
    """Footsteps, the CoM/DCM plan and the swing DMPs from the robot's start posture."""
    data = robot.create_data()
    pin.framesForwardKinematics(robot.model, data, q0)
    com = pin.centerOfMass(robot.model, data, q0)
    left, right = _sole_positions(data, _sole_ids(robot))
    n_in_place, n_forward = STEPS["quick" if quick else "full"]
    steps = footstep_plan(left, right, n_in_place, n_forward, step_length)
    height = com[2] - left[2]  # above the ground the robot stands on
    plan = plan_walk(steps, com, height, SINGLE_SUPPORT, DOUBLE_SUPPORT, INITIAL_HOLD, FINAL_HOLD)
    return plan, fit_swing_dmps(SINGLE_SUPPORT, 2 * step_length, FOOT_LIFT, SWING_DESCENT)


def fit_arm_swing(period: float = 2 * (SINGLE_SUPPORT + DOUBLE_SUPPORT)):
    """The arm swing as a rhythmic DMP (2 DOFs: the offsets of ``ARM_SWING_JOINTS`` from the
    posture) fitted to a demonstrated anti-phase cosine of ``period`` [s], counter to the legs:
    at the left heel strike (phase 0, the left foot ahead) the left elbow is at +amplitude
    (its hand furthest back: a positive elbow angle moves the hand backwards) and the right
    at -amplitude. (A quarter period earlier, the left elbow at its mean at the left heel
    strike, the yaw moment on the soles rose by 11 % instead of falling by 10 %.)"""
    times = np.linspace(0.0, 2 * period, 401)
    wave = ARM_SWING_AMPLITUDE * np.cos(2 * np.pi * times / period)
    demo = Trajectory.from_positions(times, np.column_stack([wave, -wave]))
    return fit_rhythmic(demo, 10, period=period)


def _contact_runs(log: WalkLog, plan, foot: int):
    """Tick ranges in which foot 0 (left) or 1 (right) stands on the ground as planned."""
    side = ("left", "right")[foot]
    swings = [(a, b) for s, a, b in zip(plan.footsteps, plan.lift_off, plan.touchdown)
              if s.side == side]  # fmt: skip
    edges = [0.0] + [t for swing in swings for t in swing] + [log.times[-1] + DT]
    ticks = np.round(np.array(edges) / DT).astype(int)
    return [
        (a, min(b, log.times.size)) for a, b in zip(ticks[::2], ticks[1::2]) if a < log.times.size
    ]


def _rms(values) -> float:
    return np.sqrt(np.mean(values**2))


def _statistic(function, values, *args) -> float | None:
    return float(function(values, *args)) if values.size else None


def _footholds(log: WalkLog, plan, robot, records) -> tuple[int, list]:
    """The steps whose sole is within 5 cm (horizontally) of its target 0.1 s after its
    touchdown, and each such distance [m] (:func:`walk_metrics`)."""
    landed, foothold_errors = 0, []
    targets = [step.goal for step in plan.footsteps] if records is None else [
        r.target for r in records
    ]  # fmt: skip
    for step, touchdown, target in zip(plan.footsteps, plan.touchdown, targets):
        k = int(round((touchdown + 0.1) / DT))
        if k >= log.times.size:
            break
        foot = log.feet[k, robot.foot_frames.index(f"{step.side}_sole_link")]
        error = np.linalg.norm((foot - target)[:2])
        foothold_errors.append(error)
        landed += error < 0.05
    return landed, foothold_errors


def _step_counts(log: WalkLog, walker, robot, errors: bool = False) -> dict:
    """:func:`walk_metrics`' ``steps_taken``, ``steps_planned`` and ``fell`` (and, with
    ``errors``, ``foothold_error_max_mm``) of a walk logged without the feet's loads."""
    landed, distances = _footholds(log, walker.plan, robot, walker.records)
    counts = {
        "steps_taken": int(landed), "steps_planned": len(walker.plan.footsteps),
        "fell": bool(log.fell),
    }  # fmt: skip
    if errors:
        counts["foothold_error_max_mm"] = 1e3 * float(max(distances, default=np.nan))
    return counts


def walk_metrics(log: WalkLog, plan, robot, wall: float, records=None) -> dict:
    r"""What a reader needs to judge the walk (``plan``: the walker's final plan, with the
    touchdown times and footholds as they happened; ``records``: its :class:`StepRecord`).

    - ``steps_taken``: steps whose sole is within 5 cm (horizontally) of its target 0.1 s
      after its touchdown (of ``steps_planned``); ``foothold_error_max_mm`` the largest such
      distance. The target is the swing's last goal (after step adjustment) when
      ``records`` are given, else the plan's foothold.
    - ``steps_in_place``, ``steps_forward``: steps that moved their foot less and more than
      half ``STEP_LENGTH`` (the last forward one brings the feet side by side).
    - ``distance_m``: forward displacement of the measured CoM from start to end.
    - ``tick_us_*``: CPU time of the calling thread per ``compute_torques`` [us], over the
      whole walk and over the single-support ticks (one foot in the air); ``ticks_over_2ms``
      counts the ticks in which the controller built the QP of a new contact set.
    - ``com_error_*``, ``dcm_error_*``: horizontal distance of the measured CoM and DCM
      (:math:`c + \dot c / \omega`) from the plan in use at that tick (it is re-planned at
      each touchdown and step adjustment) [mm].
    - ``foot_slip_max_mm``: largest horizontal drift of a sole while it stands (from 50 ms
      after it is set down until it lifts off).
    - ``stance_normal_force_min_*``, ``stance_cop_margin_min_mm``: the smallest measured
      (MuJoCo) normal force on the stance sole in single support [N and fraction of the
      weight], and the smallest distance of its centre of pressure to the sole's edge.
    - ``swing_foot_normal_force_max_n``: largest force on the swinging sole, 50 ms after
      lift-off until 50 ms before touchdown (0: it does not scuff).
    """
    t = log.times
    com_error = np.linalg.norm(log.com[:, :2] - log.reference_com, axis=1)
    dcm_error = np.linalg.norm(log.dcm - log.reference_dcm, axis=1)
    landed, foothold_errors = _footholds(log, plan, robot, records)
    slip, stance_force, cop_margin, swing_force = [], [], [], []
    for foot in (0, 1):
        for a, b in _contact_runs(log, plan, foot):
            a_settled = min(a + 50, b)  # 50 ms after touchdown
            if b > a_settled:
                moved = log.feet[a_settled:b, foot, :2] - log.feet[a_settled, foot, :2]
                slip.append(np.linalg.norm(moved, axis=1).max())
    for step, start, end in zip(plan.footsteps, plan.lift_off, plan.touchdown):
        a, b = int(round(start / DT)), min(int(round(end / DT)), t.size)
        if b <= a:
            break
        swing = robot.foot_frames.index(f"{step.side}_sole_link")
        stance_force.append(log.normal_force[a:b, 1 - swing].min())
        cop_margin.append(np.nanmin(log.cop_margin[a:b, 1 - swing]))
        swing_force.append(log.normal_force[a + 50 : b - 50, swing].max(initial=0.0))
    weight = pin.computeTotalMass(robot.model) * 9.81
    # a step "in place" moved less than half a step (its foothold is where it landed)
    moved = [abs(s.length) >= 0.5 * STEP_LENGTH for s in plan.footsteps]
    forward = [s.length for s, m in zip(plan.footsteps, moved) if m]
    single = np.array([plan.phase(time)[0] == "single" for time in t])
    return {
        "steps_planned": len(plan.footsteps),
        "steps_in_place": moved.count(False),
        "steps_forward": moved.count(True),
        "steps_taken": int(landed),
        "distance_m": float(log.com[-1, 0] - log.com[0, 0]),
        "distance_planned_m": float(plan.com(plan.duration)[0][0] - plan.com(0.0)[0][0]),
        "fell": bool(log.fell),
        "diverged": log.diverged,
        "simulated_s": float(t[-1] + DT),
        "tick_us_median": float(np.median(log.tick_cpu_us)),
        "tick_us_p99": float(np.percentile(log.tick_cpu_us, 99)),
        "tick_us_max": float(log.tick_cpu_us.max()),
        # None when the walk ended before its first single support (a sweep's failing plant)
        "tick_us_single_support_median": _statistic(np.median, log.tick_cpu_us[single]),
        "tick_us_single_support_p99": _statistic(np.percentile, log.tick_cpu_us[single], 99),
        "ticks_over_2ms": int(np.count_nonzero(log.tick_cpu_us > 2000)),
        "real_time_factor": float((t[-1] + DT) / wall),
        "step_length_m": STEP_LENGTH,
        "stride_m": float(max(forward, default=0.0)),
        "step_time_s": SINGLE_SUPPORT + DOUBLE_SUPPORT,
        "single_support_s": SINGLE_SUPPORT,
        "double_support_s": DOUBLE_SUPPORT,
        "foot_lift_m": FOOT_LIFT,
        "com_error_rms_mm": 1e3 * float(np.sqrt(np.mean(com_error**2))),
        "com_error_max_mm": 1e3 * float(com_error.max()),
        "dcm_error_rms_mm": 1e3 * float(np.sqrt(np.mean(dcm_error**2))),
        "dcm_error_max_mm": 1e3 * float(dcm_error.max()),
        "foothold_error_max_mm": 1e3 * float(max(foothold_errors, default=np.nan)),
        "foot_slip_max_mm": 1e3 * float(max(slip, default=np.nan)),
        "stance_normal_force_min_n": float(min(stance_force, default=np.nan)),
        "stance_normal_force_min_fraction": float(min(stance_force, default=np.nan) / weight),
        "stance_cop_margin_min_mm": 1e3 * float(min(cop_margin, default=np.nan)),
        "swing_foot_normal_force_max_n": float(max(swing_force, default=np.nan)),
        "yaw_moment_rms_nm": _statistic(_rms, log.yaw_moment[single]),
    }


def plot_walk(log: WalkLog, plan, robot, path) -> None:
    """Footsteps, CoM and DCM from above and over time (plan vs measured), foot heights."""
    plt = pyplot()
    t = log.times
    com, dcm, zmp = plan.com(t)[0], plan.dcm(t), plan.zmp(t)
    fig = plt.figure(figsize=(13, 7.5))
    grid = fig.add_gridspec(2, 3, height_ratios=(1.0, 1.2))
    top = fig.add_subplot(grid[0, :])
    axes = [fig.add_subplot(grid[1, k]) for k in range(3)]
    corners = np.asarray(robot.sole_corners)
    x0, x1 = corners[:, 0].min(), corners[:, 0].max()
    y0, y1 = corners[:, 1].min(), corners[:, 1].max()
    holds = [(s.goal, s.side) for s in plan.footsteps] + [
        (log.feet[0, 0], "left"), (log.feet[0, 1], "right")
    ]  # fmt: skip
    for goal, side in holds:
        colour = "tab:blue" if side == "left" else "tab:red"
        top.add_patch(plt.Rectangle((goal[0] + x0, goal[1] + y0), x1 - x0, y1 - y0,
                                    fill=False, ec=colour, lw=0.8))  # fmt: skip
    top.plot(zmp[:, 0], zmp[:, 1], ":", c="grey", label="ZMP plan")
    top.plot(com[:, 0], com[:, 1], c="k", label="CoM plan")
    top.plot(log.com[:, 0], log.com[:, 1], "--", c="tab:green", label="CoM measured")
    top.plot(dcm[:, 0], dcm[:, 1], c="tab:orange", label="DCM plan")
    top.plot(log.dcm[:, 0], log.dcm[:, 1], "--", c="tab:purple", label="DCM measured")
    top.set(xlabel="x [m]", ylabel="y [m]", title="From above (soles: planned footholds)")
    top.set_aspect("equal")
    top.legend(fontsize=7, ncol=5, loc="upper center", bbox_to_anchor=(0.5, -0.25))
    for ax, axis, name in ((axes[0], 0, "x"), (axes[1], 1, "y")):
        ax.plot(t, zmp[:, axis], ":", c="grey", label="ZMP plan")
        ax.plot(t, com[:, axis], c="k", label="CoM plan")
        ax.plot(t, log.com[:, axis], "--", c="tab:green", label="CoM measured")
        ax.plot(t, dcm[:, axis], c="tab:orange", label="DCM plan")
        ax.plot(t, log.dcm[:, axis], "--", c="tab:purple", label="DCM measured")
        ax.set(xlabel="t [s]", ylabel=f"{name} [m]", title=f"{name} over time")
    feet = axes[2]
    for foot, colour in ((0, "tab:blue"), (1, "tab:red")):
        feet.plot(t, 1e3 * log.feet[:, foot, 2], c=colour, label=f"{robot.foot_frames[foot]} z")
    for start, end in zip(plan.lift_off, plan.touchdown):
        feet.axvspan(start, end, color="0.9")
    feet.set(xlabel="t [s]", ylabel="sole height [mm]", title="Feet (grey: single support)")
    feet.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _arm_swing_walk(with_arms: bool) -> dict:
    robot, q0 = _robot_and_start()
    plan, swing_dmps = build_plan(robot, q0, quick=True)
    plant = talos_realistic(robot)
    arms = fit_arm_swing() if with_arms else None
    walker = Walker(robot, q0, plan, swing_dmps, plant, arm_swing=arms)
    log, _, _ = simulate(robot, q0, walker, plan.duration, 0, plant)
    return walk_metrics(log, walker.plan, robot, 1.0, walker.records)


def arm_swing_effect(runner=None) -> dict:
    """The quick walk with and without the arm swing (:func:`fit_arm_swing`, phase-locked at
    each touchdown): the RMS of the vertical ground moment on the soles in single support
    [N m], and whether each fell."""
    with_arms, without = map_runs(_arm_swing_walk, [True, False], runner, label="arm swing")
    return {
        "yaw_moment_rms_with": with_arms["yaw_moment_rms_nm"],
        "yaw_moment_rms_without": without["yaw_moment_rms_nm"],
        "fell_with": with_arms["fell"], "fell_without": without["fell"],
        "steps_taken_with": with_arms["steps_taken"],
    }  # fmt: skip


def keyframes(animation, path, n: int = 5) -> None:
    """Side by side, ``n`` frames evenly spread over a rendered animation."""
    from PIL import Image

    with Image.open(animation) as video:
        frames = []
        for index in np.linspace(0, video.n_frames - 1, n).round().astype(int):
            video.seek(int(index))
            frames.append(video.convert("RGB"))
    width, height = frames[0].size
    strip = Image.new("RGB", (n * width, height))
    for k, frame in enumerate(frames):
        strip.paste(frame, (k * width, 0))
    strip.save(path)


def run_walk(out_dir, quick: bool = False, runner=None) -> dict:
    """Plan and simulate the walk; write ``talos_walk.png`` (and, unless ``quick``, a rendered
    ``talos_walk.webp`` and its ``talos_walk_keyframes.png`` when an OpenGL context exists)
    into ``out_dir``; return the metrics."""
    quick = flag("quick", quick)
    out = output_dir(out_dir)
    robot, q0 = _robot_and_start()
    plan, swing_dmps = build_plan(robot, q0, quick)
    realistic = talos_realistic(robot)
    walker = Walker(robot, q0, plan, swing_dmps, realistic)
    record = 0 if quick else int(round(1.0 / (VIDEO_FPS * DT)))
    wall = time.perf_counter()
    log, simulator, frames = simulate(robot, q0, walker, plan.duration, record, realistic)
    wall = time.perf_counter() - wall
    metrics = walk_metrics(log, walker.plan, robot, wall, walker.records)
    metrics["touchdown_from_contact"] = all(r.from_contact for r in walker.records)
    stats = walker.controller.stats  # how each tick was answered
    metrics.update(
        qp_answers={
            "direct": stats.n_direct, "solved": stats.n_solved, "relaxed": stats.n_relaxed,
            "hold": stats.n_fallbacks,
        }
    )  # fmt: skip
    metrics["plant"] = realistic.name
    metrics["plant_realistic"] = {k: metrics[k] for k in ("steps_taken", "steps_planned", "fell")}
    ideal_walker = Walker(robot, q0, plan, swing_dmps)
    ideal_log, _, _ = simulate(robot, q0, ideal_walker, plan.duration, loads=False)
    metrics["plant_ideal"] = _step_counts(ideal_log, ideal_walker, robot, errors=True)
    metrics["plant_sweep"] = walk_sweep(quick, runner)
    from .talos_walk_recovery import push_recovery, uneven_ground

    metrics["push_recovery"] = push_recovery(quick, runner)
    metrics["arm_swing"] = None if quick else arm_swing_effect(runner)
    if quick:
        metrics["step_down"] = metrics["step_up"] = metrics["slope"] = None
    else:
        metrics.update(uneven_ground(runner))
    plot_sweep(metrics["plant_sweep"], "steps_taken", "steps taken", out / "walk_plant_sweep.png")
    plot_walk(log, walker.plan, robot, out / "talos_walk.png")
    metrics["figure"] = "talos_walk.png"
    metrics["video"], metrics["video_skipped"] = None, "quick run" if quick else None
    if frames:
        from dmpopt.exceptions import MissingDependency
        from dmpopt.sim import render_animation

        try:
            render_animation(simulator, frames, out / "talos_walk.webp", fps=VIDEO_FPS,
                             width=320, height=240, distance=2.5)  # fmt: skip
            metrics["video"] = "talos_walk.webp"
            keyframes(out / "talos_walk.webp", out / "talos_walk_keyframes.png")
            metrics["keyframes"] = "talos_walk_keyframes.png"
        except MissingDependency as error:
            metrics["video_skipped"] = str(error)
    return metrics


def main(argv=None) -> None:
    """Command line: ``python -m dmpopt_studies.talos_walk OUT_DIR [--quick]``."""
    import argparse
    import json

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", nargs="?", default="results/talos_walk")
    parser.add_argument("--quick", action="store_true", help="one step in place, three forward")
    args = parser.parse_args(argv)
    metrics = run_walk(args.out_dir, quick=args.quick)
    parameters = {
        "step_length_m": STEP_LENGTH, "single_support_s": SINGLE_SUPPORT,
        "double_support_s": DOUBLE_SUPPORT, "foot_lift_m": FOOT_LIFT,
        "steps": STEPS["quick" if args.quick else "full"], "dt_s": DT,
    }  # fmt: skip
    write_metrics(args.out_dir, "talos_walk", metrics, parameters, seed=0, quick=args.quick)
    print(json.dumps(metrics, indent=2))


if __name__ == "__main__":
    main()
