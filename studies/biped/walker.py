"""One walk of the planar biped: DMP references, eq. (21), a controller, a simulator.

Two controllers execute the DMPs' joint references:

* ``"qp"``: the QP inverse-dynamics controller (:mod:`dmpopt.control`) with a posture task on
  the four joints (the DMP's position, velocity and acceleration), a torso-pitch task (the
  pitch row of a ``FrameTask`` on the torso, leaning ``QPGains.torso_pitch``) and a point
  contact per foot, switched by the simulator's heel strikes alone, never by the DMP phase:
  a heel strike puts the foot's contact back and, ``lift_phase`` of a step duration
  ``pi / omega`` later, the other foot's contact ramps out (a swing foot has no contact).
  The swing hip's reference is bent towards a Raibert landing angle (``QPGains``), timed
  from the same heel strike: without it the walker, which has no ankles and no boom torque,
  falls within a few steps. With or without phase resetting the contacts switch alike;
* ``"pd"``: the paper's joint PD on the DMP's position and velocity (the baseline).

The boom keeps the robot in the sagittal plane (the planar base); its pitch spring-damper
(``boom_pitch_stiffness``, ``boom_pitch_damping``) is 0 for the claims.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import reduce
from operator import add, mul

import numpy as np
from dmpopt_robots import biped as biped_model

from dmpopt.control import control_loop
from dmpopt.control.inverse_dynamics import DEFAULT_TIME_BUDGET
from dmpopt.exceptions import InvalidInputError
from dmpopt.frequency_adaptation import FrequencyAdaptation, HeelStrikeDetector
from dmpopt.sim import IDEAL, GroundContact, Simulator
from dmpopt.validation import real

from ..branching import Branch as _Branch
from ..branching import BranchFailed
from ..common import TIME_BUDGET
from .gait import limit_cycle_start

DT = 1e-3  # [s] simulation step; the PD law and the QP run every step
CONTROL_EVERY = 4  # the DMP steps every CONTROL_EVERY * DT
COMPILE = True  # compiled DMP step (generated C, cached in ~/.cache/dmpopt)
GROUND = GroundContact(stiffness=1e4, damping=150.0, friction=0.8)
FALL_HEIGHT = 0.35  # [m] the walker has fallen when its torso is lower (0.6 m leg)
LEG_LENGTH = 0.6  # [m] of robots/biped.urdf
ADAPTATION_GAIN = 0.3  # K of eq. (21)
LOG_EVERY = 10  # steps between logged samples
START_SPEEDS = {"qp": 0.8, "pd": 0.35}  # [m/s] forward speed at the first heel strike
CONTROLLERS = ("qp", "pd")
PROGRESS_EVERY = 10.0  # [s] simulated, between the progress messages of a long walk


@dataclass(frozen=True)
class Gains:
    """Joint PD gains of the baseline: stiffness [N m/rad] and damping [N m s/rad]."""

    hip_stiffness: float = 100.0
    hip_damping: float = 3.0
    knee_stiffness: float = 100.0
    knee_damping: float = 3.0


@dataclass(frozen=True)
class QPGains:
    """Task gains of the QP walker (stiffness [1/s^2], damping [1/s], weights [-]).

    ``torso_pitch``: the torso's target pitch [rad], positive leaning forward.
    ``placement_gain`` [s], ``target_speed`` [m/s]: foot placement (Raibert): over its swing
    the swing hip's reference moves from the DMP's towards the angle that lands the foot
    ``v T / 2 + placement_gain (v - target_speed)`` ahead of the hip, with ``v`` the hip's
    forward speed and ``T = pi / omega`` the oscillator's step duration; None: no placement.
    ``lift_phase``: fraction of a step duration ``T`` after the other leg's heel strike at
    which a stance leg's contact starts to ramp out over ``transition_time`` [s].
    """

    posture_stiffness: float = 400.0
    posture_damping: float = 40.0
    posture_weight: float = 1.0
    pitch_stiffness: float = 400.0
    pitch_damping: float = 40.0
    pitch_weight: float = 1000.0
    torso_pitch: float = 0.2
    friction: float = 0.7
    placement_gain: float | None = 0.1
    target_speed: float = 0.6
    lift_phase: float = 0.05
    transition_time: float = 0.03


GAINS = Gains()
QP_GAINS = QPGains()
BOOM_PITCH_STIFFNESS = 500.0  # [N m/rad] the paper's boom (PD reference run only)
BOOM_PITCH_DAMPING = 30.0  # [N m s/rad]


@dataclass(frozen=True)
class Disturbance:
    """What a randomised trial does to the walker (MuJoCo backend).

    Attributes
    ----------
    push_impulse : float
        Forward horizontal impulse on the torso [N s], spread over 0.1 s from ``push_time``.
    push_time : float
        [s]
    mass_scale : tuple of float, optional
        Factor on the mass and inertia of each moving body, in MuJoCo body order (the
        controller keeps the nominal model).
    slope_deg : float
        Ground slope from ``slope_time`` on [deg], positive uphill (gravity tilted backwards).
    slope_time : float
        [s]
    """

    push_impulse: float = 0.0
    push_time: float = 0.0
    mass_scale: tuple | None = None
    slope_deg: float = 0.0
    slope_time: float = 0.0


@dataclass
class WalkLog:
    """What one walk produced (samples every ``log_every`` steps)."""

    times: list = field(default_factory=list)
    q: list = field(default_factory=list)
    desired: list = field(default_factory=list)
    strikes: list = field(default_factory=list)  # (time, leg, x of the foot)
    frequencies: list = field(default_factory=list)
    positive_work: float = 0.0  # [J] actuator work, sum over joints of max(tau qdot, 0) dt
    absolute_work: float = 0.0  # [J] sum of |tau qdot| dt
    fell: bool = False
    diverged: str = ""
    duration: float = 0.0  # [s] simulated
    wall_time: float = 0.0  # [s]
    cpu_time: float = 0.0  # [s] process time, insensitive to other load on the machine
    holds: int = 0  # QP ticks that gave the hold answer (no solution)
    ticks_over_budget: int = 0  # controller ticks over the real-time budget (thread CPU time)
    tick_us_max: float = 0.0  # the slowest controller tick (thread CPU time) [us]
    distance: float = 0.0  # [m]
    double_support_time: float = 0.0  # [s] both feet on the ground, after the first strike
    impact_forces: list = field(default_factory=list)  # [N] peak vertical force per strike
    contact_losses: int = 0  # a stance foot (the last to strike) leaving the ground mid-stance


class PDControl:
    """The paper's joint PD on the DMP's position and velocity, torques saturated."""

    def __init__(self, biped, gains: Gains = GAINS):
        order = biped.velocity_indices("gait") - biped.n_base
        self.index = np.sort(biped.velocity_indices("gait"))
        self.stiffness, self.damping = np.empty(4), np.empty(4)
        self.stiffness[order] = [gains.hip_stiffness, gains.knee_stiffness] * 2
        self.damping[order] = [gains.hip_damping, gains.knee_damping] * 2
        self.limit = np.array(biped.torque_limit)  # model order

    def torques(self, state, position, velocity, acceleration) -> np.ndarray:
        """Joint torques in model order from the references in model order."""
        error = position - state.q[self.index]
        torque = self.stiffness * error + self.damping * (velocity - state.v[self.index])
        return np.clip(torque, -self.limit, self.limit)

    def on_heel_strike(self, leg: int, time: float, frequency: float) -> None:
        """The PD law does not switch."""


#: Whether the biped's QP controller closes the stiff joint loop (JointImpedance) on a realistic
#: plant. It does not: the walk relies on eq. (21) reading the legs' own timing at heel strike,
#: and a stiff joint loop imposes the plan's timing instead, so the adaptation runs away (on the
#: realistic plant: 105 steps, then a fall at 16.7 rad/s; without the loop 150 steps in 40 s, no
#: fall). The nominal armature and the friction feed-forward stay.
JOINT_LOOP = False


class QPControl:
    """QP inverse dynamics with DMP posture, torso pitch and switched point contacts."""

    def __init__(self, biped, gains: QPGains = QP_GAINS, nominal_plant=None):
        import pinocchio as pin

        from dmpopt.control import (
            FrameTask,
            InverseDynamicsController,
            JointImpedance,
            PointContact,
            PostureTask,
        )
        from dmpopt.sim import with_armature

        impedance = None
        if nominal_plant is not None:  # the model carries the armature; friction fed forward
            biped = with_armature(biped, nominal_plant)
            impedance = JointImpedance.for_plant(biped, DT, nominal_plant, feedback=JOINT_LOOP)
        self.gains = gains
        self.frames = tuple(biped.foot_frames)
        self.posture = PostureTask(
            biped,
            weight=gains.posture_weight,
            stiffness=gains.posture_stiffness,
            damping=gains.posture_damping,
        )
        stiffness, damping = np.zeros(6), np.zeros(6)
        stiffness[4], damping[4] = gains.pitch_stiffness, gains.pitch_damping
        self.pitch = FrameTask(
            biped,
            biped.torso_frame,
            weight=gains.pitch_weight,
            stiffness=stiffness,
            damping=damping,
            components=[4],
        )
        upright = self.pitch.target_placement
        self.pitch.set_target(
            pin.SE3(pin.utils.rotate("y", gains.torso_pitch), upright.translation)
        )
        contacts = [
            PointContact(biped, frame, friction_coefficient=gains.friction) for frame in self.frames
        ]
        self.controller = InverseDynamicsController(
            biped,
            [self.posture, self.pitch],
            contacts,
            time_budget=TIME_BUDGET,
            joint_impedance=impedance,
        )
        self.lifted = [False, False]  # contact removed (or ramping out) since the last strike
        self.strike = (0, 0.0)  # (leg, time) of the last heel strike: the walk starts at one
        gait = biped.velocity_indices("gait") - biped.n_base  # model-order slots, gait order
        self.hips, self.knees = gait[[0, 2]], gait[[1, 3]]
        self.thigh, self.shank = biped_model.leg_lengths(biped)
        self.frequency = 1.0
        self._reference = np.empty(biped.n_actuated)
        # per-tick constants as Python values (cheaper to read than numpy scalars)
        self._hips, self._knees = self.hips.tolist(), self.knees.tolist()
        self._lift_phase = gains.lift_phase
        self._placement = gains.placement_gain is not None
        self._leg_geometry = (None, None, None)  # ((leg, knee), length, angle) of the swing leg

    def torques(self, state, position, velocity, acceleration) -> np.ndarray:
        """Torques in model order; lifts the swing leg a little after the other's heel strike."""
        progress = (state.t - self.strike[1]) * self.frequency / math.pi  # of the step, from 0
        lifted = self.lifted
        if not (lifted[0] or lifted[1]) and progress >= self._lift_phase:
            self._lift_after_strike(state)
        reference = self._reference
        reference[:] = position
        if self._placement and (lifted[0] or lifted[1]):
            self._place_swing_foot(state, progress, reference)
        self.posture.set_reference(reference, velocity, acceleration)
        return self.controller.compute_torques(state.q, state.v, state.t)

    def _lift_after_strike(self, state) -> None:
        """Ramp the swing leg's contact out, once the stance foot is on the ground."""
        stance = self.strike[0]
        if state.in_contact[stance]:
            self.controller.remove_contact(
                self.frames[1 - stance], transition_time=self.gains.transition_time
            )
            self.lifted[1 - stance] = True

    def _place_swing_foot(self, state, progress: float, reference: np.ndarray) -> None:
        """Move the swing hip's reference towards the Raibert landing angle over the swing."""
        # in Python floats and the math module (numpy's ufuncs on scalars cost microseconds
        # each); the same bits: numpy's sin, cos, arctan2 and arcsin are the C library's here,
        # and its hypot (not Python's) is kept
        leg = 0 if self.lifted[0] else 1
        speed = float(state.v[0])
        step_duration = math.pi / self.frequency
        reach = 0.5 * speed * step_duration
        reach += self.gains.placement_gain * (speed - self.gains.target_speed)
        knee = reference.item(self._knees[leg])
        if self._leg_geometry[0] != (leg, knee):  # the knee's reference moves every DMP step
            along, across = self.thigh + self.shank * math.cos(knee), self.shank * math.sin(knee)
            length, offset = float(np.hypot(along, across)), math.atan2(across, along)
            self._leg_geometry = (leg, knee), length, offset
        _, length, offset = self._leg_geometry
        landing = math.asin(min(max(reach / length, -0.8), 0.8)) + offset
        hip = self._hips[leg]
        reference[hip] += min(progress, 1.0) * (landing - reference[hip])

    def on_heel_strike(self, leg: int, time: float, frequency: float) -> None:
        """A heel strike at ``time`` [s] puts the foot's contact back, held where it landed,
        and starts the step after which the other leg lifts."""
        self.frequency = frequency
        self.strike = (leg, time)
        if self.lifted[leg]:
            if self.frames[leg] not in self.controller.active_contacts:
                self.controller.add_contact(self.frames[leg])
            self.lifted[leg] = False


class _Measured:
    """What a control law reads of a state whose plant measures with noise or a delay: its
    time and contact flags, and the measured ``q`` and ``v`` (one object, refilled each tick,
    instead of a new state per tick)."""

    __slots__ = ("t", "q", "v", "in_contact")


def walk(
    biped,
    dmp,
    duration: float,
    frequency: float,
    adapt: bool = True,
    reset_phase: bool = True,
    controller: str = "pd",
    boom_pitch_stiffness: float = BOOM_PITCH_STIFFNESS,
    boom_pitch_damping: float = BOOM_PITCH_DAMPING,
    disturbance: Disturbance | None = None,
    push_impulse: float = 0.0,
    push_time: float = 0.0,
    seed: int = 0,
    log_every: int = LOG_EVERY,
    backend: str = "mujoco",
    amplitude: float = 1.0,
    start_speed: float | None = None,
    progress=None,
    plant=None,
    nominal_plant=None,
    urdf=None,
    qp_gains: QPGains = QP_GAINS,
    pd_gains: Gains = GAINS,
    warmup: float = 0.0,
    start_pitch: float = 0.0,
    arms=None,
) -> WalkLog | list[WalkLog]:
    """Simulate the walker for ``duration`` [s] from the demonstrated gait at ``frequency``.

    The robot starts at the right heel strike of the DMP's limit cycle (``amplitude``: the
    DMPs' amplitude A of eq. (11)) with a forward speed of ``start_speed`` [m/s] (default
    ``START_SPEEDS[controller]`` times :math:`\\sqrt{g l / (9.81 \\cdot 0.6)}` for a model with
    another gravity ``g`` or leg length ``l``: the same Froude number) plus a seeded
    perturbation of +-0.02 m/s.
    ``push_impulse`` [N s] at ``push_time`` is a shorthand for
    ``Disturbance(push_impulse, push_time)``. The DMP steps at ``CONTROL_EVERY * DT``; the
    controller (``"qp"`` or ``"pd"``) and the simulator (``"mujoco"`` or ``"native"``) at
    ``DT``. ``progress``: called with a message every ``PROGRESS_EVERY`` simulated seconds.
    ``plant`` (:class:`dmpopt.sim.PlantParameters`, default ideal) is the simulated robot's
    joints, actuators and sensors; the controller reads the measured state. With
    ``nominal_plant`` the QP controller's model carries its armature and a
    :class:`dmpopt.control.JointImpedance` closes the joint loop. ``urdf``: the URDF ``biped``
    was loaded from (default ``robots/biped.urdf``; a leg-scaled copy for the leg-length
    control); the simulated gravity is the model's (:func:`dmpopt_robots.biped.load_biped`), so the
    QP's model and the plant agree. ``qp_gains``, ``pd_gains``: the controller's gains.
    ``warmup`` [s]: heel strikes before it reset the phase and adapt the frequency whatever
    ``reset_phase`` and ``adapt`` say (a start-up shared by the arms of an ablation); those
    switches apply from the first heel strike at or after it.
    ``start_pitch`` [rad]: the torso's pitch at the start (positive leaning forward).

    ``arms``: a sequence of ``(reset_phase, adapt)`` pairs instead of ``reset_phase`` and
    ``adapt``: walks that differ only in these switches are the same walk up to the first
    heel strike at or after ``warmup``, so it is simulated once and then continued once per
    arm; returns one log per arm, each the same bits as ``walk`` with that arm's switches
    (see :class:`_Branch`). Each log's ``cpu_time`` is its own continuation plus an equal
    share of the walk before the branch.
    """
    if controller not in CONTROLLERS:
        raise InvalidInputError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
    warmup = real("warmup", warmup, minimum=0.0)
    start_pitch = real("start_pitch", start_pitch, minimum=-1.0, maximum=1.0)
    if disturbance is None:
        disturbance = Disturbance(push_impulse, push_time)
    rng = np.random.default_rng(seed)
    if start_speed is None:
        froude = gravity(biped) * biped_model.leg_length(biped) / (9.81 * LEG_LENGTH)
        start_speed = START_SPEEDS[controller] * np.sqrt(froude)
    dmp = dmp.with_amplitude(amplitude)
    start_position, start_velocity = limit_cycle_start(dmp, frequency, DT)
    stepper = dmp.stepper(
        CONTROL_EVERY * DT, start=start_position, start_velocity=start_velocity, compile=COMPILE
    )
    stepper.set_tau(1.0 / frequency)
    height = biped_model.leg_length(biped)
    q = biped_model.configuration(biped, 0.0, height, start_pitch, stepper.position)
    q[1] -= biped_model.foot_positions(biped, q)[:, 1].min()
    sim = make_simulator(biped, backend, plant, urdf)
    _perturb_masses(sim, disturbance)
    v = np.zeros(biped.model.nv)
    v[0] = start_speed + rng.uniform(-0.02, 0.02)
    state = sim.reset(q, v)
    if controller == "qp":
        law = QPControl(biped, qp_gains, nominal_plant=nominal_plant)
    else:
        law = PDControl(biped, pd_gains)
    law.frequency = frequency
    order = biped.velocity_indices("gait") - biped.n_base  # model-order slots, gait order
    joints = np.sort(biped.velocity_indices("gait")).tolist()
    budget_us = 1e6 * DEFAULT_TIME_BUDGET
    measured = _Measured()
    detector = HeelStrikeDetector(min_swing_time=0.1)
    contact = detector.last_contact
    # before ``warmup`` every walk resets and adapts (its start-up); the arm's switches after
    arms = ((reset_phase, adapt),) if arms is None else tuple(arms)
    if not arms or any(len(arm) != 2 for arm in arms):
        raise InvalidInputError(f"arms must be (reset_phase, adapt) pairs, got {arms!r}")
    reset_phase, adapt = arms[0]
    adaptation = FrequencyAdaptation(
        frequency, ADAPTATION_GAIN, reset_phase or warmup > 0, adapt or warmup > 0
    )
    branch = _Branch(len(arms))
    log = WalkLog(frequencies=[frequency])
    base_force = np.zeros(3)
    desired, desired_velocity, desired_acceleration = np.empty(4), np.empty(4), np.empty(4)
    positive_work = absolute_work = 0.0
    slow, slowest = 0, 0.0
    impact = [None, 0.0, True]  # leg, time and contact of the last heel strike's foot
    n_steps = int(round(duration / DT))
    push_step = int(round(disturbance.push_time / DT)) if disturbance.push_impulse else -1
    slope_step = int(round(disturbance.slope_time / DT)) if disturbance.slope_deg else -1
    progress_steps = int(round(PROGRESS_EVERY / DT))
    start, cpu_start = time.perf_counter(), time.process_time()
    try:
        with control_loop():
            for k in range(n_steps):
                if k == push_step:
                    sim.push_impulse(biped.torso_frame, [disturbance.push_impulse, 0, 0], 0.1)
                if k == slope_step:
                    _tilt_gravity(sim, disturbance.slope_deg)
                if k % CONTROL_EVERY == 0:
                    position, velocity, acceleration = stepper.step()
                    desired[order], desired_velocity[order] = position, velocity
                    desired_acceleration[order] = acceleration
                begin = time.thread_time_ns()
                sensed = state  # the state itself when the plant measures without noise
                if state.q_measured is not state.q or state.v_measured is not state.v:
                    sensed = measured
                    measured.t, measured.in_contact = state.t, state.in_contact
                    measured.q, measured.v = state.q_measured, state.v_measured
                torque = law.torques(sensed, desired, desired_velocity, desired_acceleration)
                tick_us = (time.thread_time_ns() - begin) / 1e3
                if tick_us > budget_us:
                    slow += 1
                if tick_us > slowest:
                    slowest = tick_us
                # the per-tick arithmetic in Python floats (numpy's operators on scalars and
                # small vectors cost microseconds each), the same operations in the same order
                velocities = state.v.tolist()  # a list: the state's arrays stay unheld
                pitch, pitch_rate = state.q.item(2), velocities[2]
                base_force[2] = -boom_pitch_stiffness * pitch - boom_pitch_damping * pitch_rate
                state = sim.step(torque, base_force)
                # p_i = tau_i qdot_i; power = sum p_i from 0.0 in order (numpy's dot of these
                # few terms: BLAS's plain loop), |p| = sum |p_i| (numpy's sum, in order)
                products = list(map(mul, torque.tolist(), [velocities[i] for i in joints]))
                power = reduce(add, products, 0.0)
                work = sum(map(abs, products))
                absolute_work += work
                positive_work += 0.5 * (work + power)  # sum of max(p_i, 0) = (|p| + p) / 2
                flags = state.in_contact
                left, right = touching = flags.tolist()  # Python bools: cheap to compare
                if impact[0] is not None:
                    _record_gait(log, state, touching, impact)
                if (left != contact[0] or right != contact[1]) and (
                    state.touchdowns or not (left and right)
                ):  # else the detector would find nothing: the flags it saw last
                    strike = detector.update(state.t, flags, state.contact_positions)
                    contact = detector.last_contact
                    if strike is not None:
                        if strike.time >= warmup:
                            arm = branch.arm()  # here the arms part (one process each)
                            adaptation.reset_phase, adaptation.adapt = arms[arm]
                        phase, new_frequency = adaptation.on_heel_strike(strike)
                        law.on_heel_strike(strike.leg, strike.time, new_frequency)
                        if phase is not None:
                            stepper.reset_phase(phase)
                        stepper.set_tau(1.0 / new_frequency)
                        log.strikes.append((strike.time, strike.leg, float(strike.position[0])))
                        log.impact_forces.append(0.0)
                        impact[:] = strike.leg, strike.time, True
                if progress and k and k % progress_steps == 0:
                    progress(f"{state.t:.0f} of {duration:g} s simulated")
                if k % log_every == 0:
                    log.times.append(state.t)
                    log.q.append(state.q.copy())  # a copy: the simulator recycles the state
                    log.desired.append(desired[order])
                if state.fall is not None:
                    log.fell, log.diverged = True, state.fall.reason
                    break
    except BranchFailed:  # not a fall: the walk could not be continued per arm
        branch.abandon()
        raise
    except Exception as error:  # SimulationDiverged counts as a fall, with the reason kept
        log.fell, log.diverged = True, f"{type(error).__name__}: {error}"
    except BaseException:
        branch.abandon()  # a forked arm's process ends here (e.g. Ctrl-C)
        raise
    log.wall_time = time.perf_counter() - start
    if controller == "qp":
        log.holds = law.controller.stats.n_fallbacks
    log.ticks_over_budget, log.tick_us_max = int(slow), slowest
    log.cpu_time = branch.cpu_time(cpu_start)
    log.positive_work, log.absolute_work = DT * positive_work, DT * absolute_work
    log.duration = sim.t
    log.distance = float(sim.q[0] - q[0])
    log.frequencies = adaptation.frequencies
    return log if len(arms) == 1 else branch.logs(log)


IMPACT_WINDOW = 0.05  # [s] after a heel strike in which its peak vertical force is taken


def _record_gait(log: WalkLog, state, in_contact: list, impact: list) -> None:
    """Double support, the impact force of the last heel strike and stance-foot contact losses.

    ``in_contact``: ``state.in_contact`` as a list of bools; ``impact``: [leg, time, in
    contact] of the last heel strike's leg (the stance leg), updated.
    """
    leg, time, was_in_contact = impact
    if leg is None:
        return
    if in_contact[0] and in_contact[1]:
        log.double_support_time += DT
    if state.t - time <= IMPACT_WINDOW:
        log.impact_forces[-1] = max(log.impact_forces[-1], float(state.contact_forces[leg, 2]))
    touching = in_contact[leg]
    log.contact_losses += was_in_contact and not touching
    impact[2] = touching


def _perturb_masses(sim, disturbance: Disturbance) -> None:
    """Scale the simulated bodies' masses and inertias (MuJoCo only)."""
    if disturbance.mass_scale is None:
        return
    if not hasattr(sim, "mj_model"):
        raise InvalidInputError("mass_scale needs the MuJoCo backend; pass backend='mujoco'")
    import mujoco

    moving = np.flatnonzero(sim.mj_model.body_mass > 0)
    scale = np.asarray(disturbance.mass_scale, dtype=float)
    if scale.shape != moving.shape:
        raise InvalidInputError(
            f"mass_scale has {scale.size} factors, expected {moving.size} (one per moving body)"
        )
    sim.mj_model.body_mass[moving] *= scale
    sim.mj_model.body_inertia[moving] *= scale[:, None]
    mujoco.mj_setConst(sim.mj_model, sim.mj_data)


def _tilt_gravity(sim, slope_deg: float) -> None:
    """A ground sloping ``slope_deg`` uphill: gravity tilted backwards by that angle."""
    if not hasattr(sim, "mj_model"):
        raise InvalidInputError("slope_deg needs the MuJoCo backend; pass backend='mujoco'")
    angle = np.radians(slope_deg)
    magnitude = np.linalg.norm(sim.mj_model.opt.gravity)
    sim.mj_model.opt.gravity[:] = magnitude * np.array([-np.sin(angle), 0.0, -np.cos(angle)])


def n_moving_bodies(biped) -> int:
    """How many factors ``Disturbance.mass_scale`` needs (bodies with mass in MuJoCo)."""
    return len(make_simulator(biped, "mujoco").mj_model.body_mass.nonzero()[0])


def fall_height(biped) -> float:
    """Torso height below which the walker has fallen [m]: ``FALL_HEIGHT`` for the 0.6 m leg,
    in proportion to the leg length of a leg-scaled biped."""
    return FALL_HEIGHT * biped_model.leg_length(biped) / LEG_LENGTH


def gravity(biped) -> float:
    """Magnitude of the model's gravity [m/s^2] (the plant simulates the same)."""
    return float(np.linalg.norm(biped.model.gravity.linear))


def make_simulator(biped, backend: str, plant=None, urdf=None):
    """The walker's simulator on ``backend``: "mujoco" or "native" (compliant ``GROUND``).

    Both flag a fall when the torso is below :func:`fall_height` (the other thresholds derived
    from the biped, :mod:`dmpopt.sim.falls`) and simulate the model's gravity. ``urdf``: the
    file ``biped`` was loaded from (default ``robots/biped.urdf``).
    """
    from dmpopt_studies.humanoid import check_backend

    if check_backend(backend) == "native":
        return Simulator(
            biped.model,
            DT,
            biped.contact_points,
            GROUND,
            n_base_dofs=3,
            fall_frame=biped.torso_frame,
            fall_height=fall_height(biped),
            plant=plant or IDEAL,
        )
    from dmpopt_robots.biped import BIPED_URDF

    from dmpopt.sim import MujocoSimulator

    sim = MujocoSimulator(
        biped.model,
        urdf or BIPED_URDF,
        DT,
        biped.contact_points,
        friction=GROUND.friction,
        fall_frame=biped.torso_frame,
        fall_height=fall_height(biped),
        plant=plant or IDEAL,
    )
    sim.mj_model.opt.gravity[:] = biped.model.gravity.linear
    return sim
