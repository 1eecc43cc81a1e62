"""Dynamics-feasible DMPs: a fast Talos forehand under torque limits and balance (beyond the paper).

Claim evaluated: fitting the DMP weights by sequential QP under the robot's torque limits and
balance (:func:`dmpopt.fitting.fit_weights_dynamics`) gives, at the demonstrated duration, a
plan within every torque limit whose centre of pressure stays inside the feet, where the plain
DMP of the same demonstration exceeds them; and what it costs (shape) against the tools that
keep the shape and give up time: toppra's time-optimal retiming and uniform time scaling, both
under the same torque and velocity limits.

Set-up (all choices are ours): standing Talos (full model), the forehand swing of the right arm
of the humanoid study (:mod:`dmpopt_studies.humanoid.swing`, six joints) demonstrated ``SPEED``
times
faster (0.625 s instead of 1.25 s); the other joints at the drumming posture. Limits: the URDF's
torque limits of the six joints, their velocity limits and position ranges, and the CoP
``COP_MARGIN`` inside the support polygon of both soles with friction ``FRICTION``. Metrics of
each plan by exact inverse dynamics at 1 kHz with the body still (the fit's model): peak torque
use ``|tau| / limit``, the CoP's smallest margin inside the polygon (negative: outside),
duration, and the shape error: the largest distance of the plan's hand path from the
demonstrated one (timing-free, the body at the start posture). Each plan is then executed
standing in MuJoCo on the realistic Talos plant (:func:`dmpopt_robots.plants.talos_realistic`:
armature,
friction, torque saturation, delay, noise) by the humanoid study's controller, for its
duration plus ``HOLD`` seconds: fall, joint tracking RMS, and the QP's relaxed and hold answers.
Beside the four, the same fit asking for ``HEADROOM`` of the torque limits
(``dynamics_feasible_headroom``): room for the controller's feedback and the joints' friction.

Run: ``python -m dmpopt_studies.feasible OUT_DIR [--quick]``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .common import Progress, command_line, pyplot, write_metrics

EXPECTED_SECONDS = {"full": 4, "quick": 2}  # CPU s (dmpopt.cli): main job, 2026-11-28, EPYC
SPEED = 2.0  # the forehand demonstrated this many times faster than the humanoid study's
COP_MARGIN = 0.01  # [m] the CoP at least this far inside the support polygon
FRICTION = 0.7  # the controller's friction coefficient (dmpopt_studies.humanoid.parameters)
HOLD = 0.5  # [s] simulated after each plan's end, holding its last posture
HEADROOM = 0.8  # the extra fit asks for this fraction of the torque limits
METHODS = ("plain_dmp", "toppra", "time_scaling", "dynamics_feasible")
EXTRA = ("dynamics_feasible_headroom",)  # beside the four the issue compares
LABELS = {
    "plain_dmp": "plain DMP",
    "toppra": "toppra retiming",
    "time_scaling": "uniform time scaling",
    "dynamics_feasible": "dynamics-feasible DMP",
    "dynamics_feasible_headroom": f"dynamics-feasible, {HEADROOM:.0%} of limits",
}


def setup():
    """Robot, posture, the fast demonstration, the joints and their limits."""
    from dmpopt_robots import load_talos
    from dmpopt_studies.humanoid.demos import drumming_posture
    from dmpopt_studies.humanoid.swing import SWING_JOINTS, demonstrate_swing

    from dmpopt import Trajectory

    robot = load_talos("full")
    posture = drumming_posture(robot)
    slow = demonstrate_swing(robot, dt=1e-3)
    demo = Trajectory.from_positions(slow.times / SPEED, slow.positions)
    joints = list(SWING_JOINTS)
    q_index, v_index = robot.configuration_indices(joints), robot.velocity_indices(joints)
    limits = {
        "torque": robot.torque_limit[v_index - robot.n_base],
        "velocity": robot.velocity_limit[v_index],
        "lower": robot.position_lower[q_index],
        "upper": robot.position_upper[q_index],
    }
    return robot, posture, demo, SWING_JOINTS, limits


def plans(robot, posture, demo, joints, limits, quick: bool) -> tuple[dict, dict]:
    """The plans (Trajectory at 1 kHz) and the fit's numbers."""
    from dmpopt import fit_discrete
    from dmpopt.fitting import Balance, Bounds, TorqueLimits, fit_weights_dynamics
    from dmpopt.fitting.dynamics import robot_dynamics
    from dmpopt.retiming import retime, time_scaled, uniform_time_scaling

    dmp = fit_discrete(demo)
    plain = dmp.rollout(demo.duration, 1e-3)
    arm = robot_dynamics(robot, joints, posture, TorqueLimits()).model  # 6 DOFs, body still
    retimed = retime(plain, limits["velocity"], robot=arm, torque_limit=limits["torque"])
    factor = uniform_time_scaling(
        plain, limits["velocity"], robot=arm, torque_limit=limits["torque"]
    )
    bounds = Bounds(
        position_lower=limits["lower"], position_upper=limits["upper"], velocity=limits["velocity"]
    )
    begin, cpu_begin = time.perf_counter(), time.process_time()
    fit, report = fit_weights_dynamics(
        demo,
        robot,
        joints,
        posture=posture,
        torque_limits=TorqueLimits(),
        balance=Balance(cop_margin=COP_MARGIN, friction=FRICTION),
        bounds=bounds,
        n_samples=100 if quick else None,
    )
    fit_seconds, fit_cpu = time.perf_counter() - begin, time.process_time() - cpu_begin
    headroom, _ = fit_weights_dynamics(
        demo,
        robot,
        joints,
        posture=posture,
        torque_limits=TorqueLimits(fraction=HEADROOM),
        balance=Balance(cop_margin=COP_MARGIN, friction=FRICTION),
        bounds=bounds,
        n_samples=100 if quick else None,
    )
    info = {
        "sqp_iterations": report.iterations,
        "fit_seconds": fit_seconds,
        "fit_cpu_seconds": fit_cpu,
        "qp_seconds": report.qp_time,
        "status": report.status,
        "n_samples": report.problem.kinematic.plan.times.size,
        "certificate": {
            "sample_grid": report.certificate.samples._asdict(),
            "fine_grid": report.certificate.fine._asdict(),
            "feasible": report.certificate.feasible,
        },
        "time_scaling_factor": factor,
        "toppra_stretch": retimed.stretch,
    }
    return {
        "plain_dmp": plain,
        "toppra": on_control_grid(retimed.trajectory),
        "time_scaling": on_control_grid(time_scaled(plain, factor)),
        "dynamics_feasible": fit.rollout(demo.duration, 1e-3),
        "dynamics_feasible_headroom": headroom.rollout(demo.duration, 1e-3),
    }, info


def on_control_grid(trajectory, dt: float = 1e-3):
    """``trajectory`` sampled every ``dt`` (the controller's tick), linear interpolation."""
    from dmpopt import Trajectory

    times = np.arange(int(np.floor(trajectory.times[-1] / dt + 1e-9)) + 1) * dt
    columns = [
        np.column_stack(
            [np.interp(times, trajectory.times, values[:, d]) for d in range(values.shape[1])]
        )
        for values in (trajectory.positions, trajectory.velocities, trajectory.accelerations)
    ]
    return Trajectory(times, *columns)


def plan_metrics(robot, posture, demo, joints, trajectory, hand_demo, limits) -> dict:
    """Torque use, CoP margin, duration and hand-path shape error of one plan (module notes)."""
    from dmpopt_studies.humanoid.swing import HandKinematics

    from dmpopt.fitting import Balance, TorqueLimits
    from dmpopt.fitting.dynamics import robot_dynamics

    dynamics = robot_dynamics(
        robot, joints, posture, TorqueLimits(), Balance(cop_margin=0.0, friction=FRICTION)
    )
    outputs = dynamics.outputs(trajectory)
    use = np.abs(outputs[:, : len(joints)]) / dynamics.torque_limit
    hand = HandKinematics(robot).plan(posture, trajectory.positions)
    distance = np.linalg.norm(hand[:, None, :] - hand_demo[None, ::4, :], axis=2).min(axis=1)
    speed = np.abs(trajectory.velocities) / limits["velocity"]
    return {
        "torque_use_max": float(use.max()),
        "velocity_use_max": float(speed.max()),
        "time_at_velocity_limit_s": float(
            np.sum(np.gradient(trajectory.times)[speed.max(axis=1) >= 0.99])
        ),
        "torque_use_per_joint": dict(zip(joints, use.max(axis=0).tolist())),
        "cop_margin_min_mm": float(1e3 * dynamics.cop_margin(outputs).min()),
        "friction_use_max": float(dynamics.friction_use(outputs).max()),
        "duration_s": float(trajectory.times[-1] - trajectory.times[0]),
        "shape_error_mm": float(1e3 * distance.max()),
        "series": {
            "times": trajectory.times,
            "torque_use": use.max(axis=1),
            "cop": dynamics.cop(outputs),
        },
        "polygon": dynamics.polygon,
    }


def execute(robot, posture, joints, trajectory) -> dict:
    """The plan (sampled every tick) played by the humanoid study's controller on MuJoCo's
    realistic Talos."""
    from dmpopt_robots.plants import talos_realistic
    from dmpopt_studies.humanoid.controller import build_controller, mujoco_plant
    from dmpopt_studies.humanoid.demos import DRUM_JOINTS
    from dmpopt_studies.humanoid.loop import _closed_loop
    from dmpopt_studies.humanoid.parameters import DT

    realistic = talos_realistic(robot)
    q_start = posture.copy()
    arm = robot.configuration_indices(list(joints))
    q_start[arm] = trajectory.positions[0]
    v_start = np.zeros(robot.nv)
    v_start[robot.velocity_indices(list(joints))] = trajectory.velocities[0]
    controller, task = build_controller(robot, q_start, com_sink=0.0, nominal_plant=realistic)
    drum = robot.configuration_indices(list(DRUM_JOINTS))
    right = [DRUM_JOINTS.index(name) for name in joints]
    position, velocity, acceleration = q_start[drum], np.zeros(len(drum)), np.zeros(len(drum))
    n_plan = trajectory.n_steps
    ticks = []

    def reference():
        k = min(len(ticks), n_plan - 1)
        ticks.append(None)
        holding = len(ticks) > n_plan
        position[right] = trajectory.positions[k]
        velocity[right] = 0.0 if holding else trajectory.velocities[k]
        acceleration[right] = 0.0 if holding else trajectory.accelerations[k]
        task.set_reference(position, velocity, acceleration)
        return trajectory.positions[k].copy()

    def measure(q, data):
        return q[arm]

    duration = trajectory.times[-1] + HOLD
    log = _closed_loop(
        robot, q_start, v_start, controller, reference, measure, duration, None,
        plant=mujoco_plant(parameters=realistic),
    )  # fmt: skip
    error = log.actual - log.desired
    return {
        "fell": bool(log.fell or log.diverged is not None),
        "tracking_rms_rad": float(np.sqrt(np.mean(error**2))),
        "qp_relaxed": int(controller.stats.n_relaxed),
        "qp_hold": int(controller.stats.n_fallbacks),
        "applied_torque_use_max": float(log.torque_use.max()),
        "simulated_s": float(log.duration),
        "dt": DT,
    }


def _figure(out: Path, metrics: dict, series: dict, polygon) -> None:
    plt = pyplot()
    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for name in METHODS + EXTRA:
        data = series[name]
        left.plot(data["times"], data["torque_use"], label=LABELS[name])
        right.plot(1e3 * data["cop"][:, 0], 1e3 * data["cop"][:, 1], label=LABELS[name])
    left.axhline(1.0, color="k", lw=0.8, ls="--")
    left.set_xlabel("time [s]")
    left.set_ylabel("peak torque use |tau| / limit (six arm joints)")
    left.legend(fontsize=8)
    hull = np.array(_corners(polygon))
    right.fill(1e3 * hull[:, 0], 1e3 * hull[:, 1], color="0.9", zorder=0, label="support polygon")
    right.set_xlabel("CoP x [mm]")
    right.set_ylabel("CoP y [mm]")
    right.set_aspect("equal")
    right.legend(fontsize=8)
    figure.suptitle(f"Talos forehand at {SPEED:g}x speed: torque use and CoP per method")
    figure.tight_layout()
    figure.savefig(out / "feasible.png", dpi=120)
    plt.close(figure)


def _corners(polygon) -> list:
    """Vertices of the polygon ``a.p <= b`` (consecutive edges of a convex hull intersect)."""
    angles = np.arctan2(polygon[:, 1], polygon[:, 0])
    edges = polygon[np.argsort(angles)]
    corners = []
    for first, second in zip(edges, np.roll(edges, -1, axis=0)):
        corners.append(np.linalg.solve(np.array([first[:2], second[:2]]), [first[2], second[2]]))
    return corners


def _lines(metrics: dict) -> list:
    """One line per method, every number from ``metrics`` (printed by :func:`main`)."""
    methods = metrics["methods"]
    rows = []
    for name in METHODS + EXTRA:
        m, e = methods[name], methods[name]["executed"]
        executed = (
            e["skipped"]
            if "skipped" in e
            else f"MuJoCo: fell {e['fell']}, tracking {e['tracking_rms_rad']:.4f} rad, relaxed "
            f"{e['qp_relaxed']}, hold {e['qp_hold']}"
        )
        rows.append(
            f"{LABELS[name]:24s} torque use {m['torque_use_max']:.3f}, CoP margin "
            f"{m['cop_margin_min_mm']:6.1f} mm, {m['duration_s']:.3f} s, shape error "
            f"{m['shape_error_mm']:5.1f} mm; {executed}"
        )
    return rows


def _summary(metrics: dict) -> list:
    """The report's rows (claim, paper, dmpopt, anchor, verdict), numbers from ``metrics``."""
    m = metrics["methods"]
    plain, fit, toppra, scaled = (m[k] for k in METHODS[:1] + METHODS[3:] + METHODS[1:3])
    held = fit["torque_use_max"] <= 1.0 and fit["cop_margin_min_mm"] >= 0.0
    rows = [
        {
            "claim": "the dynamics-feasible DMP holds the torque limits and keeps the CoP in the "
            "feet at the demonstrated duration",
            "paper": "beyond the paper",
            "dmpopt": f"torque use {fit['torque_use_max']:.3f}, CoP margin "
            f"{fit['cop_margin_min_mm']:.1f} mm, {fit['duration_s']:.3f} s "
            f"({metrics['sqp_iterations']} SQP iterations, {metrics['fit']['fit_cpu_seconds']:.2f} "
            f"s CPU, {metrics['fit_seconds']:.1f} s wall)",
            "anchor": f"plain DMP: torque use {plain['torque_use_max']:.2f}, CoP margin "
            f"{plain['cop_margin_min_mm']:.0f} mm",
            "verdict": "holds" if held else "fails",
        },
        {
            "claim": "where retiming is the better tool",
            "paper": "beyond the paper",
            "dmpopt": f"shape error {fit['shape_error_mm']:.1f} mm at {fit['duration_s']:.3f} s",
            "anchor": f"toppra: {toppra['shape_error_mm']:.1f} mm (the plain DMP's path) at "
            f"{toppra['duration_s']:.3f} s, CoP margin {toppra['cop_margin_min_mm']:.0f} mm; "
            f"time scaling {scaled['duration_s']:.3f} s, CoP margin "
            f"{scaled['cop_margin_min_mm']:.0f} mm",
            "verdict": "retiming keeps the shape"
            + (" (and here is even faster)" if toppra["duration_s"] < fit["duration_s"] else "")
            + " but knows no balance; the fit keeps the duration and the CoP, bending the path",
        },
    ]
    if "fell" in fit["executed"]:
        fell = [k for k in METHODS + EXTRA if m[k]["executed"]["fell"]]
        runs = ", ".join(
            f"{LABELS[k]} {m[k]['executed']['tracking_rms_rad']:.3f} rad"
            + (" (fell)" if m[k]["executed"]["fell"] else "")
            for k in METHODS + EXTRA
        )
        rows.append(
            {
                "claim": "executed standing on the realistic MuJoCo plant",
                "paper": "beyond the paper",
                "dmpopt": f"joint tracking RMS: {runs}",
                "anchor": "falls, relaxed and hold answers of the controller: "
                + ", ".join(
                    f"{m[k]['executed']['fell']:d}/{m[k]['executed']['qp_relaxed']}/"
                    f"{m[k]['executed']['qp_hold']}"
                    for k in METHODS + EXTRA
                ),
                "verdict": (
                    "no method fell: the whole-body controller balances what the body-still "
                    "model calls unbalanced"
                    if not fell
                    else "fell: " + ", ".join(LABELS[k] for k in fell)
                ),
            }
        )
    return rows


def run(out_dir, quick: bool = False, seed: int = 0) -> dict:
    """Run the study, write feasible.png and metrics.json into ``out_dir``, return the metrics."""
    progress = Progress("feasible")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    robot, posture, demo, joints, limits = setup()
    progress("plans: plain DMP, toppra, time scaling, dynamics-feasible fit")
    trajectories, fit = plans(robot, posture, demo, joints, limits, quick)
    from dmpopt_studies.humanoid.swing import HandKinematics

    hand_demo = HandKinematics(robot).plan(posture, demo.positions)
    methods, series, polygon = {}, {}, None
    for name in METHODS + EXTRA:
        progress(f"{LABELS[name]}: metrics and MuJoCo run")
        values = plan_metrics(robot, posture, demo, joints, trajectories[name], hand_demo, limits)
        series[name], polygon = values.pop("series"), values.pop("polygon")
        values["executed"] = (
            {"skipped": "quick mode: no MuJoCo runs"}
            if quick
            else execute(robot, posture, joints, trajectories[name])
        )
        methods[name] = values
    metrics = {
        "claim": "at the demonstrated duration, the dynamics-feasible DMP holds Talos's torque "
        "limits and keeps the CoP in the feet where the plain DMP does not; retiming and time "
        "scaling keep the shape and give up time",
        "speed": SPEED,
        "demo_duration_s": demo.duration,
        "joints": list(joints),
        "torque_limit_nm": limits["torque"],
        "velocity_limit_rad_s": limits["velocity"],
        "cop_margin_requested_mm": 1e3 * COP_MARGIN,
        "methods": methods,
        "sqp_iterations": fit.pop("sqp_iterations"),
        "fit_seconds": fit.pop("fit_seconds"),
        "fit": fit,
        "labels": LABELS,
        "wall_seconds": time.perf_counter() - start,
    }
    metrics["summary"] = _summary(metrics)
    metrics["captions"] = {
        "feasible": "left: peak torque use over the six arm joints per method (1 is the limit); "
        "right: the CoP path in the support polygon of both soles (body-still model)"
    }
    _figure(out, metrics, series, polygon)
    progress("done")
    parameters = {
        "speed": SPEED,
        "cop_margin": COP_MARGIN,
        "friction": FRICTION,
        "hold_s": HOLD,
        "headroom": HEADROOM,
        "quick": quick,
    }
    return write_metrics(out, "feasible", metrics, parameters, seed, quick)


def main(argv=None) -> None:
    metrics = command_line(run, __doc__, argv)
    print("\n".join(_lines(metrics)))
    print(f"SQP iterations {metrics['sqp_iterations']}, fit {metrics['fit_seconds']:.2f} s")


if __name__ == "__main__":
    main()
