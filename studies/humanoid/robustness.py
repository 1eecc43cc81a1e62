"""Robustness in MuJoCo: model mismatch, friction, tight torque limits and pushes."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from dmpopt_robots import load_talos
from dmpopt_robots.plants import talos_realistic

from dmpopt.control.inverse_dynamics import DEFAULT_TIME_BUDGET
from dmpopt.parallel import map_runs

from ..plant_sweep import with_scaled_masses
from .controller import mujoco_plant, with_scaled_torque_limits
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


def _slow_ticks(log: RunLog) -> int:
    """Ticks whose CPU time exceeded the controller's default (real-time) budget."""
    return int(np.count_nonzero(log.tick_cpu_us > 1e6 * DEFAULT_TIME_BUDGET))


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
        "qp_holds": log.n_fallbacks,
        "ticks_over_budget": _slow_ticks(log),
        "tick_us_max": float(log.tick_cpu_us.max()),
    }


@dataclass(frozen=True)
class Scenario:
    """One independent MuJoCo drumming run from the drumming start (picklable, for workers).

    ``mass_scale`` scales every link of the controller's model, ``torque_scale`` its torque
    limits; ``friction`` is the floor's (the controller's cone at ``min(0.7, friction)``);
    ``push_ns`` a forward impulse on the pelvis at ``PUSH_TIME``; ``record`` keeps the
    configurations for a video.
    """

    dmps: object  # DrumDmps
    duration: float
    compile: bool = False
    mass_scale: float | None = None
    torque_scale: float | None = None
    friction: float = MUJOCO_FRICTION
    push_ns: float | None = None
    record: bool = False


@lru_cache(maxsize=1)
def _talos():
    return load_talos("full")


def run_scenario(scenario: Scenario) -> RunLog:
    """Run one :class:`Scenario` (a module-level function for :func:`dmpopt.parallel.map_runs`).

    The simulator is left out of the returned log (it does not cross processes); the
    recorded configurations are kept.
    """
    robot = _talos()
    controller_robot = robot
    if scenario.mass_scale is not None:
        controller_robot = with_scaled_masses(controller_robot, scenario.mass_scale)
    if scenario.torque_scale is not None:
        controller_robot = with_scaled_torque_limits(controller_robot, scenario.torque_scale)
    push = None if scenario.push_ns is None else (PUSH_TIME, np.array([scenario.push_ns, 0, 0]))
    plant = talos_realistic(robot)
    log = run_drumming(
        robot,
        scenario.dmps,
        scenario.duration,
        compile=scenario.compile,
        controller_robot=controller_robot,
        build_options={
            "com_sink": 0.0,
            "friction": min(CONTROLLER_FRICTION, scenario.friction),
            "nominal_plant": plant,
        },
        plant=mujoco_plant(scenario.friction, plant),
        push=push,
        record_every=int(round(1.0 / (VIDEO_FPS * DT))) if scenario.record else 0,
    )
    log.extras.pop("simulator", None)
    return log


def push_search(attempt, ladder, bisections: int) -> dict:
    """Largest forward impulse on the pelvis [N s] survived while drumming.

    ``attempt(impulses)`` runs one pushed drumming run per impulse (independent runs) and
    returns their logs in order. Every impulse of ``ladder`` (increasing) is run; the largest
    one below the first failure is survived, the first failure is fatal; then ``bisections``
    halvings between the two, one run each. A run that diverged did not survive and bounds
    the search like a fall, but is reported as ``diverged``, not as a fall. The ladder's
    runs above the first failure stay in ``tried``, so that a non-monotonic survival shows.
    Returns the bounds, every impulse tried and the run of the largest survived push (or of
    the first failure if none was survived).
    """
    tried = []

    def run(impulses):
        logs = attempt(list(impulses))
        for impulse, log in zip(impulses, logs):
            tried.append(
                {
                    "impulse_ns": impulse,
                    "fell": log.fell,
                    "diverged": log.diverged,
                    "qp_holds": log.n_fallbacks,
                    "ticks_over_budget": _slow_ticks(log),
                }
            )
        return [(log, log.fell or log.diverged is not None) for log in logs]

    survived, fatal, shown = 0.0, None, None
    for impulse, (log, failed) in zip(ladder, run(ladder)):
        if failed:
            fatal, shown = impulse, shown or log
            break
        survived, shown = impulse, log
    for _ in range(bisections if fatal is not None else 0):
        impulse = 0.5 * (survived + fatal)
        [(log, failed)] = run([impulse])
        if failed:
            fatal = impulse
        else:
            survived, shown = impulse, log
    return {"survived_ns": survived, "fell_ns": fatal, "tried": tried, "log": shown}


def mujoco_scenarios(dmps, nominal: RunLog, quick: bool, compile: bool, runner=None) -> dict:
    """Model mismatch, friction, tight torque limits and pushes, all in MuJoCo.

    ``nominal`` is the unmodified MuJoCo drumming run (its peak torque use sets the tight
    torque limits). The runs go through :func:`dmpopt.parallel.map_runs` with ``runner``.
    Returns the scenario summaries, the push search and the push run.
    """
    mode = "quick" if quick else "full"
    base = Scenario(dmps, SCENARIO_SECONDS[mode], compile)
    tight = TIGHT_TORQUE * float(nominal.qp_torque_use.max())  # the QP's own, before the joint loop
    names = [f"link_masses_x{scale:g}" for scale in LINK_MASS_SCALES]
    names += [f"friction_{friction:g}" for friction in FRICTIONS] + ["tight_torque_limits"]
    runs = [replace(base, mass_scale=scale) for scale in LINK_MASS_SCALES]
    runs += [replace(base, friction=friction) for friction in FRICTIONS]
    runs.append(replace(base, torque_scale=tight))
    scenarios = {n: summary(log) for n, log in zip(names, map_runs(run_scenario, runs, runner))}
    scenarios["tight_torque_limits"] = {
        "scale_of_urdf_limits": tight,
        **scenarios["tight_torque_limits"],
    }
    pushed = replace(base, duration=PUSH_RUN_SECONDS[mode], record=True)
    push = push_search(
        lambda impulses: map_runs(
            run_scenario, [replace(pushed, push_ns=i) for i in impulses], runner
        ),
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
        f"t = {PUSH_TIME} s while drumming; the whole ladder (independent runs), then "
        "bisection below its first failure. "
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
