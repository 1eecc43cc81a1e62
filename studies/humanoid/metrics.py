"""The study's metrics: Fig. 4 settle times, tracking, balance, limits and controller timing."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .demos import DRUM_JOINTS, Demonstration
from .loop import RunLog
from .parameters import (
    DT,
    ELBOW,
    JOINT_LIMIT_HORIZON,
    MASS_ERROR,
    PARAMETER_FILTER,
    PERIOD,
    SETPOINT_SHIFT,
    SETTLE_TOLERANCE,
)
from .plan import (
    DrumDmps,
    Modification,
    elbow_limit_cycle,
    ideal_elbow,
    plan_rollout,
    settle_time,
)

GROUPS = {"left_arm": slice(0, 6), "right_arm": slice(6, 12)}  # columns of DRUM_JOINTS


@dataclass
class StudyRuns:
    """Every run of the study (standing ones on the chosen backend)."""

    modifications: list  # Fig. 4: "none" first, then the three changes of the right elbow
    plans: dict  # modification name -> plan_rollout of the DMPs alone
    runs: dict  # modification name -> RunLog of the standing robot
    fixed: RunLog  # fixed-base upper body, native simulator
    wrong_model: RunLog  # controller model with heavier arms (MASS_ERROR)
    no_base_task: RunLog  # without the pelvis orientation task
    figure8: RunLog
    native: RunLog  # nominal drumming on the native simulator (runs["none"] on that backend)
    mujoco: dict | None  # robustness.mujoco_scenarios, on the MuJoCo backend only
    fig4_duration: float  # [s] each Fig. 4 run
    swing_demo: object = None  # Trajectory: the forehand demonstration (swing.py)
    swings: dict = field(default_factory=dict)  # "demonstrated_goal", "new_goal" -> SwingRun

    @property
    def standing(self) -> list:
        """The runs whose tracking, torques and falls are the headline numbers."""
        return list(self.runs.values()) + [self.figure8]

    @property
    def everything(self) -> list:
        """Every closed-loop run except the native comparison and the MuJoCo scenarios."""
        return self.standing + [self.fixed, self.wrong_model, self.no_base_task]


def rms(error: np.ndarray, axis=None):
    """Root mean square of ``error`` (over ``axis``)."""
    return np.sqrt(np.mean(np.square(error), axis=axis))


def fit_error(dmps: DrumDmps, demo: Demonstration) -> float:
    """Largest joint difference [rad] between one period of the learned limit cycle (after
    two periods of the plan) and the demonstrated cycle, at the demonstration's samples."""
    reproduction = plan_rollout(dmps, 3 * PERIOD)["positions"][-int(round(PERIOD / DT)) - 1 :]
    demo_cycle = demo.joints.positions[: demo.joints.n_steps // 2 + 1]
    n_demo = demo_cycle.shape[0]
    resampled = reproduction[np.linspace(0, reproduction.shape[0] - 1, n_demo).round().astype(int)]
    return float(np.abs(resampled - demo_cycle).max())


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


def fig4_metrics(dmps: DrumDmps, study: StudyRuns) -> dict:
    """Settle times of the plan and of the robot's elbow after each Fig. 4 change.

    The robot and ``plan`` take the change as a step (as in the paper); ``plan_filtered``
    is the plan alone with the change passed through a ``PARAMETER_FILTER`` first-order
    filter, for comparison with the filtered set-up of earlier versions.
    """
    elbow, end = dmps.elbow_index, study.fig4_duration
    fig4 = {}
    for modification in study.modifications[1:]:
        name = modification.name
        plan, log = study.plans[name], study.runs[name]
        plan_elbow = plan["positions"][:, elbow]
        elbow_error = log.actual[:, elbow] - log.desired[:, elbow]
        filtered_change = replace(modification, filter=PARAMETER_FILTER)
        filtered = plan_rollout(dmps, end, filtered_change)
        fig4[name] = {
            "plan": _settling(
                dmps, modification, plan["times"], plan_elbow, plan["elbow_phase"], end
            ),
            "plan_filtered": _settling(
                dmps,
                filtered_change,
                filtered["times"],
                filtered["positions"][:, elbow],
                filtered["elbow_phase"],
                end,
            ),
            "robot": _settling(
                dmps, modification, log.times, log.actual[:, elbow], log.elbow_phase, end
            ),
            "frequency_settle_s": _frequency_settle(plan, modification)
            if name == "frequency"
            else None,
            "elbow_tracking_rms_rad": float(rms(elbow_error)),
            "elbow_tracking_max_rad": float(np.abs(elbow_error).max()),
            "fell": log.fell,
        }
    return fig4


def timing_metrics(study: StudyRuns) -> dict:
    """Controller time per tick and real-time factors (floating and fixed base)."""
    fixed, standing = study.fixed, study.standing
    all_ticks_cpu = np.concatenate([log.tick_cpu_us for log in study.runs.values()])
    all_ticks_wall = np.concatenate([log.tick_wall_us for log in study.runs.values()])
    simulated = sum(log.duration for log in standing)
    return {
        "tick_us_median": float(np.median(all_ticks_cpu)),
        "tick_us_p99": float(np.percentile(all_ticks_cpu, 99)),
        "tick_clock": "CPU time of the thread (time.thread_time_ns) around compute_torques; "
        "floating-base full Talos (nv = 50), two sole contacts, all drumming runs",
        "tick_us_wall_median": float(np.median(all_ticks_wall)),
        "tick_us_wall_p99": float(np.percentile(all_ticks_wall, 99)),
        "tick_us_fixed_base_median": float(np.median(fixed.tick_cpu_us)),
        "tick_us_fixed_base_p99": float(np.percentile(fixed.tick_cpu_us, 99)),
        "tick_us_fixed_base_wall_median": float(np.median(fixed.tick_wall_us)),
        "tick_us_fixed_base_wall_p99": float(np.percentile(fixed.tick_wall_us, 99)),
        "real_time_factor": simulated / sum(log.wall_time for log in standing),
        "real_time_factor_cpu": simulated / sum(log.cpu_time for log in standing),
        "real_time_factor_fixed_base": fixed.duration / fixed.wall_time,
        "real_time_factor_fixed_base_cpu": fixed.duration / fixed.cpu_time,
        "real_time_factor_note": "simulated time / time of the whole loop (DMP step, "
        "controller, simulator step, logging); > 1 is faster than real time",
    }


def tracking_metrics(study: StudyRuns) -> dict:
    """Joint tracking of the drumming (standing and fixed base) and hand tracking of the 8."""
    error = study.runs["none"].actual - study.runs["none"].desired
    fixed_error = study.fixed.actual - study.fixed.desired
    hand_error = np.linalg.norm(study.figure8.actual - study.figure8.desired, axis=1)
    return {
        "tracking_rms_rad": float(rms(error)),
        "tracking_max_rad": float(np.abs(error).max()),
        "tracking_rms_rad_per_group": {g: float(rms(error[:, s])) for g, s in GROUPS.items()},
        "tracking_rms_rad_per_joint": dict(zip(DRUM_JOINTS, rms(error, axis=0))),
        "tracking_rms_rad_fixed_base": float(rms(fixed_error)),
        "tracking_rms_rad_fixed_base_per_group": {
            g: float(rms(fixed_error[:, s])) for g, s in GROUPS.items()
        },
        "figure8_rms_mm": float(1e3 * rms(hand_error)),
        "figure8_max_mm": float(1e3 * hand_error.max()),
    }


def limit_metrics(robot, study: StudyRuns) -> dict:
    """Peak torque use (over the standing runs) and the drumming joints' position margin."""
    torque_use = np.max([log.torque_use for log in study.standing], axis=0)
    drum_q = robot.configuration_indices(list(DRUM_JOINTS))
    lower, upper = robot.position_lower[drum_q], robot.position_upper[drum_q]
    position_margin = np.min(
        [
            np.minimum(log.actual - lower, upper - log.actual).min(axis=0)
            for log in study.runs.values()
        ],
        axis=0,
    )
    names = robot.actuated_joint_names
    return {
        "torque_limit_use_max": float(torque_use.max()),
        "torque_limit_use_joint": names[int(np.argmax(torque_use))],
        "torque_limit_use_per_group": {
            group: float(torque_use[np.isin(names, joints)].max())
            for group, joints in robot.joint_groups.items()
        },
        "position_limit_margin_rad": float(position_margin.min()),
        "position_limit_margin_joint": DRUM_JOINTS[int(np.argmin(position_margin))],
        "position_limit_margin_note": "closest approach of the drumming joints to a position "
        "limit; the controller bounds their accelerations to keep them within their position "
        f"and velocity limits (joint_limit_horizon {JOINT_LIMIT_HORIZON} s)",
    }


def ablation_metrics(study: StudyRuns) -> dict:
    """Balance while drumming, without the pelvis task and with a wrong arm mass."""
    drum, no_base, wrong = study.runs["none"], study.no_base_task, study.wrong_model
    return {
        "base_roll_pitch_yaw_ptp_deg": np.degrees(np.ptp(drum.base[:, 3:], axis=0)),
        "com_excursion_mm": 1e3 * np.ptp(drum.com, axis=0),
        "without_base_task": {
            "base_roll_pitch_yaw_ptp_deg": np.degrees(np.ptp(no_base.base[:, 3:], axis=0)),
            "tracking_rms_rad": float(rms(no_base.actual - no_base.desired)),
            "fell": no_base.fell,
        },
        "with_arm_mass_error": {
            "scale": MASS_ERROR,
            "tracking_rms_rad": float(rms(wrong.actual - wrong.desired)),
            "tracking_max_rad": float(np.abs(wrong.actual - wrong.desired).max()),
            "tracking_rms_rad_per_group": {
                g: float(rms(wrong.actual[:, s] - wrong.desired[:, s])) for g, s in GROUPS.items()
            },
            "base_roll_pitch_yaw_ptp_deg": np.degrees(np.ptp(wrong.base[:, 3:], axis=0)),
            "fell": wrong.fell,
        },
    }


def solver_metrics(study: StudyRuns) -> dict:
    """Falls, divergences and how the controller's QP was solved, over every run."""
    everything = study.everything
    n_ticks = sum(log.times.size for log in everything)
    return {
        "fell": any(log.fell for log in study.standing),
        "diverged": [log.diverged for log in everything if log.diverged],
        "n_ticks": int(n_ticks),
        "n_cold_restarts": int(sum(log.n_cold_restarts for log in everything)),
        "n_fallbacks": int(sum(log.n_fallbacks for log in everything)),
        "direct_solve_fraction": float(sum(log.n_direct for log in everything) / n_ticks),
        "direct_solve_note": "fraction of ticks without an active inequality row, solved by "
        "one Cholesky factorisation (or in closed form on the fixed base) instead of proxsuite",
    }


def study_metrics(robot, dmps: DrumDmps, study: StudyRuns) -> dict:
    """Every metric of the closed-loop runs (``robot``: the standing Talos)."""
    fig4 = fig4_metrics(dmps, study)
    onset = [fig4[n]["robot"]["onset_s"] for n in fig4]
    elbow_speed = float(robot.model.velocityLimit[robot.velocity_indices([ELBOW])[0]])
    return {
        **timing_metrics(study),
        **tracking_metrics(study),
        "settle_time_s": None if None in onset else float(max(onset)),
        "settle_time_note": f"robot elbow within {SETTLE_TOLERANCE:.0%} of the new limit "
        "cycle's peak-to-peak amplitude after a step change (no filter, as in the paper), "
        f"worst of A x2, tau/2, g + {SETPOINT_SHIFT:g} rad; fig4.<change>.plan is the DMP "
        "alone, fig4.<change>.plan_filtered the DMP with a "
        f"{PARAMETER_FILTER:g} s filter on the change",
        "setpoint_shift_rad": SETPOINT_SHIFT,
        "setpoint_shift_note": f"the paper's g + 1 taken in radians (its joint angles; it "
        "prints no unit); the elbow's limit cycle is "
        f"{np.ptp(elbow_limit_cycle(dmps)(np.linspace(0, 2 * np.pi, 721))):.3f} rad peak to "
        f"peak and stays inside the elbow's range after the shift",
        "setpoint_velocity_bound_s": SETPOINT_SHIFT / elbow_speed,
        "setpoint_velocity_bound_note": f"shift / elbow velocity limit ({elbow_speed:g} "
        "rad/s): no controller within the limit moves the elbow's cycle faster",
        "fig4": fig4,
        **limit_metrics(robot, study),
        **ablation_metrics(study),
        **solver_metrics(study),
    }
