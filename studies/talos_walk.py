"""Talos steps in place, then walks forward on flat ground in MuJoCo through the QP controller.

Plan (:mod:`dmpopt.locomotion`): footsteps; a ZMP on the stance foot in single support and
moving between the feet in double support; the DCM from it backwards and the LIPM CoM
forwards; swing-foot references from two discrete DMPs fitted once to a demonstrated foot lift
and re-targeted to each step's start and goal foothold.

Control: one :class:`dmpopt.control.InverseDynamicsController` (Talos ``reduced``, 32
actuated joints) with a posture task, the CoM task fed the plan's CoM position, velocity and
acceleration, the pelvis orientation, and, in single support, a swing-foot frame task. In each
double support the swing foot's contact is removed with a ramp (its normal force bound goes to
zero over the double support, while the ZMP plan moves onto the stance foot); at the planned
touchdown it is added back, held at the planned foothold.

Simulation: MuJoCo (:class:`dmpopt.sim.MujocoSimulator`), a 5 mm sphere at each sole corner on
a floor of friction 1, 1 kHz control and simulation; falls as in the humanoid study (pelvis
below 0.7 m).

``python -m studies.talos_walk OUT_DIR [--quick]``; :func:`run_walk` returns the metrics.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    JointImpedance,
    PostureTask,
    SoleContact,
)
from dmpopt.exceptions import SimulationDiverged
from dmpopt.locomotion import fit_swing_dmps, footstep_plan, plan_walk, swing_reference
from dmpopt.parallel import map_runs
from dmpopt.sim import IDEAL, with_armature
from dmpopt.validation import flag
from robots import load_talos
from robots.plants import talos_realistic

from .common import TIME_BUDGET, output_dir, pyplot, write_metrics
from .plant_sweep import collect, plot_sweep, sweep_cases, with_scaled_masses

DT = 1e-3  # [s] control and simulation period
STEP_LENGTH = 0.2  # [m] the moving foot lands this far ahead of the stance foot
SINGLE_SUPPORT = 0.6  # [s]
DOUBLE_SUPPORT = 0.2  # [s] weight transfer: the ZMP moves over, the contact ramps down
FOOT_LIFT = 0.05  # [m] peak swing height
VIDEO_FPS = 10.0
INITIAL_HOLD, FINAL_HOLD = 1.0, 1.0  # [s]
STEPS = {"quick": (1, 3), "full": (2, 10)}  # (in place, forward); a closing step follows
FALL_HEIGHT = 0.7  # [m] the pelvis has fallen when lower
FLOOR_FRICTION = 1.0
POSTURE_WEIGHT, COM_WEIGHT, BASE_WEIGHT, SWING_WEIGHT = 1e-2, 10.0, 1.0, 10.0
COM_STIFFNESS, SWING_STIFFNESS = 50.0, 300.0  # [1/s^2] (damping critical)


@dataclass
class WalkLog:
    """Every tick of a walk (n ticks)."""

    times: np.ndarray  # (n,)
    com: np.ndarray  # (n, 3) measured [m]
    dcm: np.ndarray  # (n, 2) measured c + c'/omega [m]
    feet: np.ndarray  # (n, 2, 3) left, right sole frame positions [m]
    normal_force: np.ndarray  # (n, 2) measured left, right normal forces [N]
    cop_margin: np.ndarray  # (n, 2) measured CoP distance inside each sole [m] (nan unloaded)
    tick_cpu_us: np.ndarray  # (n,)
    fell: bool
    diverged: str | None


def _robot_and_start():
    robot = load_talos("reduced")
    q0 = np.array(robot.reference_configuration)
    return robot, q0


def _sole_positions(robot, data) -> np.ndarray:
    return np.array([data.oMf[robot.model.getFrameId(f)].translation for f in robot.foot_frames])


class Walker:
    """The tasks, the controller and the contact switching of one walk plan.

    ``references(tick)`` sets the task targets and switches the contacts at the plan's
    lift-offs and touchdowns. With ``nominal_plant`` the controller's model carries its
    armature and a :class:`JointImpedance` closes the joint loop (as in the humanoid study).
    """

    def __init__(self, robot, q0, plan, swing_dmps, nominal_plant=None):
        impedance = None
        if nominal_plant is not None:
            robot = with_armature(robot, nominal_plant)
            impedance = JointImpedance.for_plant(robot, DT, nominal_plant)
        self.robot, self.plan, self.swing_dmps = robot, plan, swing_dmps
        data = robot.create_data()
        pin.framesForwardKinematics(robot.model, data, q0)
        self.sole_rotation = {
            f: data.oMf[robot.model.getFrameId(f)].rotation.copy() for f in robot.foot_frames
        }
        actuated = np.sort(
            np.concatenate([robot.configuration_indices([n]) for n in robot.actuated_joint_names])
        )
        posture = PostureTask(robot, weight=POSTURE_WEIGHT, stiffness=10.0)
        posture.set_reference(q0[actuated])
        self.com_task = ComTask(robot, weight=COM_WEIGHT, stiffness=COM_STIFFNESS)
        base = FrameTask(
            robot, "base_link", weight=BASE_WEIGHT, stiffness=50.0, components="orientation"
        )
        self.swing_tasks = {
            f: FrameTask(robot, f, weight=SWING_WEIGHT, stiffness=SWING_STIFFNESS)
            for f in robot.foot_frames
        }
        contacts = [SoleContact(robot, f) for f in robot.foot_frames]
        self.controller = InverseDynamicsController(
            robot,
            [posture, self.com_task, base],
            contacts,
            time_budget=TIME_BUDGET,
            joint_impedance=impedance,
        )
        self._lift_off = np.round(plan.lift_off / DT).astype(int)  # ticks
        self._touchdown = np.round(plan.touchdown / DT).astype(int)
        self._transfer = int(round(DOUBLE_SUPPORT / DT))  # ticks of a double support
        self._next = 0  # the step under way or next
        self._swing = None  # the swing reference (Trajectory) of the step under way

    def _frame(self, step) -> str:
        return f"{step.side}_sole_link"

    def references(self, tick: int) -> None:
        """Targets at tick ``tick`` (time ``tick * DT``); contact and task switches at the
        plan's ticks of release (start of a double support), lift-off and touchdown."""
        plan, controller, steps = self.plan, self.controller, self.plan.footsteps
        position, velocity, acceleration = plan.com(tick * DT)
        self.com_task.set_target(position, velocity, acceleration)
        i = self._next
        if i < len(steps) and tick == self._touchdown[i]:
            step = steps[i]
            frame = self._frame(step)
            controller.remove_task(self.swing_tasks[frame])
            controller.add_contact(frame, pin.SE3(self.sole_rotation[frame], step.goal))
            self._swing, self._next = None, i + 1
        i = self._next  # a double support starts at the touchdown before it
        if i < len(steps) and tick == self._lift_off[i] - self._transfer:
            # The ramp ends half a tick early, so that the controller drops the contact at
            # the lift-off tick, when the swing task comes in (no tick with neither).
            controller.remove_contact(self._frame(steps[i]), max(self._transfer - 0.5, 0.0) * DT)
        if i < len(steps) and tick == self._lift_off[i]:
            step = steps[i]
            self._swing = swing_reference(self.swing_dmps, step.start, step.goal, DT)
            controller.add_task(self.swing_tasks[self._frame(step)])
        if self._swing is not None:
            k = tick - self._lift_off[i]
            task = self.swing_tasks[self._frame(steps[i])]
            velocity, acceleration = np.zeros(6), np.zeros(6)
            velocity[:3], acceleration[:3] = self._swing.velocities[k], self._swing.accelerations[k]
            placement = pin.SE3(self.sole_rotation[task.frame], self._swing.positions[k])
            task.set_target(placement, velocity, acceleration)


def make_simulator(robot, plant=IDEAL):
    """MuJoCo with the soles (left then right) on the floor and ``plant``'s joints, actuators
    and sensors."""
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
    )


def _foot_loads(state, robot, data) -> tuple[np.ndarray, np.ndarray]:
    """Measured normal force of each foot [N] and its CoP's distance inside the sole [m]."""
    n_corners = len(robot.sole_corners)
    forces = state.contact_forces.reshape(2, n_corners, 3)
    points = state.contact_positions.reshape(2, n_corners, 3)
    normal = forces[:, :, 2].sum(axis=1)
    margin = np.full(2, np.nan)
    corners = np.asarray(robot.sole_corners)
    for foot, frame in enumerate(robot.foot_frames):
        if normal[foot] > 1.0:
            cop = forces[foot, :, 2] @ points[foot] / normal[foot]
            local = data.oMf[robot.model.getFrameId(frame)].actInv(cop)
            margin[foot] = min(
                local[0] - corners[:, 0].min(), corners[:, 0].max() - local[0],
                local[1] - corners[:, 1].min(), corners[:, 1].max() - local[1],
            )  # fmt: skip
    return normal, margin


def simulate(robot, q0, walker, duration: float, record_every: int = 0, plant=IDEAL):
    """Run the walk in MuJoCo on ``plant`` for ``duration`` seconds; stop at a fall."""
    simulator = make_simulator(robot, plant)
    state = simulator.reset(q0)
    data = robot.create_data()
    omega = 1.0 / walker.plan.time_constant
    n = int(round(duration / DT))
    com, dcm = np.zeros((n, 3)), np.zeros((n, 2))
    feet = np.zeros((n, 2, 3))
    normal, margin = np.zeros((n, 2)), np.zeros((n, 2))
    tick = np.zeros(n)
    frames = []
    fell, diverged = False, None
    for k in range(n):
        t = k * DT
        walker.references(k)
        begin = time.thread_time_ns()
        tau = walker.controller.compute_torques(state.q_measured, state.v_measured, t)
        tick[k] = (time.thread_time_ns() - begin) / 1e3
        com[k] = pin.centerOfMass(robot.model, data, state.q, state.v)
        dcm[k] = com[k, :2] + data.vcom[0][:2] / omega
        pin.updateFramePlacements(robot.model, data)
        feet[k] = _sole_positions(robot, data)
        normal[k], margin[k] = _foot_loads(state, robot, data)
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
    log = WalkLog(
        np.arange(n) * DT, com[:n], dcm[:n], feet[:n], normal[:n], margin[:n], tick[:n],
        fell, diverged,
    )  # fmt: skip
    return log, simulator, frames


# ------------------------------------------------------------------------------- the study
def walk_sweep(quick: bool, runner=None) -> dict:
    """``plant_sweep`` of the walk (the quick plan's four steps and a closing one per case):
    steps taken and falls against each plant parameter (:mod:`studies.plant_sweep`), the runs
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
    log, _, _ = simulate(robot, q0, walker, plan.duration, 0, plant)
    result = walk_metrics(log, plan, robot, 1.0)
    return {k: result[k] for k in ("steps_taken", "steps_planned", "fell")}


def build_plan(robot, q0, quick: bool):
    """Footsteps, the CoM/DCM plan and the swing DMPs from the robot's start posture."""
    data = robot.create_data()
    pin.framesForwardKinematics(robot.model, data, q0)
    com = pin.centerOfMass(robot.model, data, q0)
    left, right = _sole_positions(robot, data)
    n_in_place, n_forward = STEPS["quick" if quick else "full"]
    steps = footstep_plan(left, right, n_in_place, n_forward, STEP_LENGTH)
    plan = plan_walk(steps, com, com[2], SINGLE_SUPPORT, DOUBLE_SUPPORT, INITIAL_HOLD, FINAL_HOLD)
    return plan, fit_swing_dmps(SINGLE_SUPPORT, 2 * STEP_LENGTH, FOOT_LIFT)


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


def _statistic(function, values, *args) -> float | None:
    return float(function(values, *args)) if values.size else None


def walk_metrics(log: WalkLog, plan, robot, wall: float) -> dict:
    r"""What a reader needs to judge the walk.

    - ``steps_taken``: steps whose sole is within 5 cm of its planned foothold 0.1 s after
      the planned touchdown (of ``steps_planned``); ``foothold_error_max_mm`` the largest
      such distance.
    - ``steps_in_place``, ``steps_forward``: planned steps of zero and positive length (the
      last forward one brings the feet side by side).
    - ``distance_m``: forward displacement of the measured CoM from start to end.
    - ``tick_us_*``: CPU time of the calling thread per ``compute_torques`` [us], over the
      whole walk and over the single-support ticks (one foot in the air); ``ticks_over_2ms``
      counts the ticks in which the controller built the QP of a new contact set.
    - ``com_error_*``, ``dcm_error_*``: horizontal distance of the measured CoM and DCM
      (:math:`c + \dot c / \omega`) from the plan [mm].
    - ``foot_slip_max_mm``: largest horizontal drift of a sole while it stands (from 50 ms
      after it is set down until it lifts off).
    - ``stance_normal_force_min_*``, ``stance_cop_margin_min_mm``: the smallest measured
      (MuJoCo) normal force on the stance sole in single support [N and fraction of the
      weight], and the smallest distance of its centre of pressure to the sole's edge.
    - ``swing_foot_normal_force_max_n``: largest force on the swinging sole, 50 ms after
      lift-off until 50 ms before touchdown (0: it does not scuff).
    """
    t = log.times
    planned_com = plan.com(t)[0]
    com_error = np.linalg.norm(log.com[:, :2] - planned_com[:, :2], axis=1)
    dcm_error = np.linalg.norm(log.dcm - plan.dcm(t), axis=1)
    landed, foothold_errors = 0, []
    for step, touchdown in zip(plan.footsteps, plan.touchdown):
        k = int(round((touchdown + 0.1) / DT))
        if k >= t.size:
            break
        error = np.linalg.norm(
            log.feet[k, robot.foot_frames.index(f"{step.side}_sole_link")] - step.goal
        )
        foothold_errors.append(error)
        landed += error < 0.05
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
    forward = [s.length for s in plan.footsteps if s.length > 0]
    single = np.array([plan.phase(time)[0] == "single" for time in t])
    return {
        "steps_planned": len(plan.footsteps),
        "steps_in_place": sum(s.length == 0 for s in plan.footsteps),
        "steps_forward": sum(s.length > 0 for s in plan.footsteps),
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
    metrics = walk_metrics(log, plan, robot, wall)
    stats = walker.controller.stats  # how each tick was answered
    metrics.update(
        qp_answers={
            "direct": stats.n_direct, "solved": stats.n_solved, "relaxed": stats.n_relaxed,
            "hold": stats.n_fallbacks,
        }
    )  # fmt: skip
    metrics["plant"] = realistic.name
    metrics["plant_realistic"] = {k: metrics[k] for k in ("steps_taken", "steps_planned", "fell")}
    ideal_log, _, _ = simulate(robot, q0, Walker(robot, q0, plan, swing_dmps), plan.duration)
    ideal = walk_metrics(ideal_log, plan, robot, 1.0)
    metrics["plant_ideal"] = {
        k: ideal[k] for k in ("steps_taken", "steps_planned", "fell", "foothold_error_max_mm")
    }
    metrics["plant_sweep"] = walk_sweep(quick, runner)
    plot_sweep(metrics["plant_sweep"], "steps_taken", "steps taken", out / "walk_plant_sweep.png")
    plot_walk(log, plan, robot, out / "talos_walk.png")
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
    """Command line: ``python -m studies.talos_walk OUT_DIR [--quick]``."""
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
