"""Robustness in MuJoCo: model mismatch, friction, tight torque limits and pushes."""

from __future__ import annotations

import numpy as np

from .controller import mujoco_plant, with_scaled_masses, with_scaled_torque_limits
from .loop import RunLog, run_drumming
from .metrics import rms
from .parameters import (
    CONTROLLER_FRICTION,
    DT,
    FRICTIONS,
    LINK_MASS_SCALES,
    MUJOCO_FRICTION,
    PUSH_BISECTIONS,
    PUSH_DURATION,
    PUSH_LADDER,
    PUSH_LADDER_QUICK,
    PUSH_RUN_SECONDS,
    PUSH_TIME,
    SCENARIO_SECONDS,
    TIGHT_TORQUE,
    VIDEO_FPS,
)


def summary(log: RunLog) -> dict:
    """Fall, tracking and solver activity of one drumming run."""
    return {
        "fell": log.fell,
        "diverged": log.diverged,
        "simulated_s": log.duration,
        "tracking_rms_rad": float(rms(log.actual - log.desired)),
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
        scenarios[f"link_masses_x{scale:g}"] = summary(log)
    for friction in FRICTIONS:
        log = drum(plant=mujoco_plant(friction), friction=min(CONTROLLER_FRICTION, friction))
        scenarios[f"friction_{friction:g}"] = summary(log)
    tight = TIGHT_TORQUE * float(nominal.torque_use.max())
    scenarios["tight_torque_limits"] = {
        "scale_of_urdf_limits": tight,
        **summary(drum(controller_robot=with_scaled_torque_limits(robot, tight))),
    }
    push = push_search(
        lambda push: drum(push=push, duration=PUSH_RUN_SECONDS[mode], record_every=record),
        PUSH_LADDER_QUICK if quick else PUSH_LADDER,
        bisections=0 if quick else PUSH_BISECTIONS,
    )
    scenarios["push_largest_survived"] = {
        "impulse_ns": push["survived_ns"],
        **summary(push["log"]),
    }
    return {"scenarios": scenarios, "push": push}


def loop_summary(log: RunLog) -> dict:
    """Tracking, falls, solver activity and real-time factor of a nominal drumming run."""
    return {
        **summary(log),
        "real_time_factor": log.duration / log.wall_time,
        "real_time_factor_cpu": log.duration / log.cpu_time,
    }


def mujoco_metrics(nominal: RunLog, mujoco: dict) -> dict:
    """The ``mujoco`` object of ``metrics.json``: nominal run, pushes, QP activity, scenarios."""
    push, scenarios = mujoco["push"], mujoco["scenarios"]
    binding = "tight_torque_limits"
    return {
        **loop_summary(nominal),
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
