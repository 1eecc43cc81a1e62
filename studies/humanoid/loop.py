"""The closed loop: plan, controller and simulator each tick, and what a run produced."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from dmpopt import fit_rhythmic
from dmpopt.control import control_loop
from dmpopt.exceptions import SimulationDiverged

from .controller import build_controller, make_simulator
from .demos import DRUM_JOINTS, drumming_posture, figure8_demonstration
from .parameters import DT, FIGURE8_PERIOD, N_BASIS, PUSH_DURATION
from .plan import DrumDmps, DrumPlan


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
    qp_torque_use: np.ndarray  # (n_actuated,) the same of the QP's torques (before a joint loop)
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
    configurations = np.empty((n, robot.model.nq))  # base pose and CoM come from them after
    torques = np.empty((n, 2, robot.n_actuated))  # sent, and the QP's (before a joint loop)
    tick_wall = np.empty(n)
    tick_cpu = np.empty(n)
    fell, diverged = False, None
    wall0, cpu0 = time.perf_counter(), time.process_time()
    with control_loop():
        for k in range(n):
            if k == push_tick:
                simulator.push_impulse("base_link", push[1], duration=PUSH_DURATION)
            if record_every and k % record_every == 0:
                frames.append(state.q.copy())
            desired[k] = reference() if k else first
            begin, cpu_begin = time.perf_counter_ns(), time.thread_time_ns()
            tau = controller.compute_torques(state.q_measured, state.v_measured)
            tick_cpu[k] = time.thread_time_ns() - cpu_begin
            tick_wall[k] = time.perf_counter_ns() - begin
            torques[k, 0] = tau
            torques[k, 1] = getattr(controller, "torques", tau)
            actual[k] = measure(state.q, data)
            configurations[k] = state.q
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
    # The logs the loop does not feed back, from the configurations and torques of its ticks
    # (outside the loop, where the model's data stay in the cache: the same numbers).
    ratios = np.abs(torques[:n]) / np.asarray(robot.torque_limit)
    base, com = _base_and_com(robot, configurations[:n])
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return RunLog(
        times=np.arange(n) * DT,
        desired=desired[:n],
        actual=actual[:n],
        elbow_phase=np.zeros(n),
        base=base[:n],
        com=com[:n],
        torque_use=ratios[:, 0].max(axis=0, initial=0.0),
        qp_torque_use=ratios[:, 1].max(axis=0, initial=0.0),
        torque_peak=ratios[:, 0].max(axis=1),
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


def _base_and_com(robot, configurations) -> tuple[np.ndarray, np.ndarray]:
    """Pelvis position and roll, pitch, yaw [m, rad], (n, 6), and CoM [m], (n, 3), of each
    configuration (zeros on a fixed base)."""
    n = configurations.shape[0]
    base, com = np.zeros((n, 6)), np.zeros((n, 3))
    if robot.floating_base:
        data = robot.create_data()
        for k, q in enumerate(configurations):
            base[k, :3] = q[:3]
            base[k, 3:] = pin.rpy.matrixToRpy(pin.Quaternion(q[3:7]).toRotationMatrix())
            com[k] = pin.centerOfMass(robot.model, data, q)
    return base, com


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
    _, start_velocity = dmp.limit_cycle_state(0.0, DT)
    stepper = dmp.stepper(DT, on_limit_cycle=True, compile=compile)
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
