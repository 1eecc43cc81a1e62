"""The reality gap: drumming on the ideal and the realistic plant, the control design's parts,
and the sweep of each plant parameter to the point of failure."""

from __future__ import annotations

import numpy as np
from dmpopt_robots.plants import talos_realistic

from dmpopt.parallel import map_runs
from dmpopt.sim import IDEAL

from ..plant_sweep import collect, sweep_cases, with_scaled_masses
from .controller import mujoco_plant
from .loop import run_drumming
from .parameters import DT

#: Ablation of the control design on the realistic plant: which parts the controller uses.
DESIGNS = {
    "rigid_model": (),
    "armature": ("armature",),
    "armature_feedforward": ("armature", "feedforward"),
    "impedance_only": ("impedance",),
    "full": ("armature", "feedforward", "impedance"),
}


def drum_summary(log, duration: float | None = None) -> dict:
    """Joint tracking of a drumming run and whether it fell, over its first ``duration`` [s]
    (default: all of it). The first seconds of a longer run are the run of that duration: a
    run does not depend on how long it will last."""
    n = log.times.size if duration is None else min(log.times.size, int(round(duration / DT)))
    error = log.desired[:n] - log.actual[:n]
    ended = n == log.times.size  # a fall or divergence stops the run at its last tick
    return {
        "tracking_rms_rad": float(np.sqrt(np.mean(error**2))),
        "tracking_max_rad": float(np.abs(error).max()),
        "fell": bool(ended and (log.fell or log.diverged is not None)),
        "simulated_s": n * DT,
    }


def _drum(robot, dmps, duration, compile, plant, nominal, coping=DESIGNS["full"], plant_robot=None):
    options = {"com_sink": 0.0, "nominal_plant": nominal, "coping": coping}
    log = run_drumming(
        plant_robot or robot,
        dmps,
        duration,
        None,
        compile=compile,
        controller_robot=robot,
        build_options=options,
        plant=mujoco_plant(parameters=plant),
    )
    return drum_summary(log)


def plant_comparison(
    robot, dmps, compile: bool, realistic_log, quick: bool, progress, duration: float
):
    """``plant`` metrics: the ideal plant with the rigid-body controller (the earlier default),
    the realistic plant with the study's controller (the first ``duration`` seconds of
    ``realistic_log``), and the design's ablation on the realistic plant (in a quick run only
    the rigid-body controller beside the full design), each ``duration`` [s] long.

    ``duration`` is the plant sweep's (two drumming periods in a full run): the designs'
    tracking differs by factors of 2 to 200 and none falls. RMS errors over 10 s (the main
    job of 2026-11-27) and over 3 s (this setting), mrad: ideal plant 0.136 / 0.135, full
    design 0.180 / 0.183, armature and feed-forward 1.18 / 1.15, joint loop alone 2.54 /
    2.52, armature 26.6 / 26.8, rigid model 35.6 / 38.0; the same ranking, for 15 s
    simulated instead of 50 s (31 CPU-s there).
    """
    preset = talos_realistic(robot)
    progress("reality gap: drumming on the ideal plant, and each part of the control design")
    ideal = _drum(robot, dmps, duration, compile, IDEAL, None)
    designs = ("rigid_model",) if quick else [name for name in DESIGNS if name != "full"]
    ablation = {
        name: _drum(robot, dmps, duration, compile, preset, preset, DESIGNS[name])
        for name in designs
    }
    realistic = drum_summary(realistic_log, duration)
    ablation["full"] = realistic
    return {
        "ideal": ideal,
        "realistic": {**realistic, "parameters": preset.describe(robot.actuated_joint_names)},
        "design_ablation": ablation,
        "design": "controller model with the nominal armature; nominal damping and Coulomb "
        "friction fed forward; JointImpedance around the QP's accelerations (bandwidth "
        "0.25 / ((delay + 1) dt), inertia 1 / (M^-1)_jj)",
    }


def drumming_sweep(robot, dmps, duration: float, compile: bool, quick: bool, runner) -> dict:
    """``plant_sweep`` of drumming: tracking and falls against each plant parameter (the runs
    go where ``runner`` says)."""
    preset = talos_realistic(robot)
    cases = sweep_cases(preset, quick)
    inputs = [(robot, dmps, duration, compile, plant, mass) for _, _, plant, mass in cases]
    return collect(cases, map_runs(_sweep_case, inputs, runner, label="plant sweep, drumming"))


def _sweep_case(case) -> dict:
    robot, dmps, duration, compile, plant, mass = case
    believed = robot if mass == 1.0 else with_scaled_masses(robot, mass)
    return _drum(
        believed, dmps, duration, compile, plant, talos_realistic(robot), plant_robot=robot
    )
