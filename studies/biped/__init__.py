r"""Fig. 7 of the planar biped tested as a claim: does eq. (21) tune the walker to its legs?

Claim of [dmpopt-paper] Section 4.3: four phase-oscillator DMPs on one canonical system,
learned from a demonstrated gait and tracked by joint PD control, drive a planar five-link
biped; with phase resetting at heel strike and the frequency adaptation of eq. (21) "the
frequency gradually increases until it reaches approximately resonance frequency of the
simulated robot legs".

Set-up (all choices are ours, see ``robots/README.md``):

* robot: ``robots/biped.urdf`` (leg 0.6 m, 7 kg, point feet), planar base (x, z, pitch): the
  boom keeps it in the sagittal plane and applies **no pitch torque** (the paper says "planar
  biped" and mentions no boom or torso support; the same group describes its five-link
  biped as fixed to a boom that keeps it in the sagittal plane, nothing about pitch);
* controller: the paper's joint PD cannot walk this robot without a pitch torque on the torso,
  so the walks use the QP inverse-dynamics controller of :mod:`dmpopt.control` (posture task
  on the DMP references, torso-pitch task leaning 0.2 rad, point contacts switched by the
  simulator's heel strikes, Raibert foot placement on the swing hip), see
  :mod:`dmpopt_studies.biped.walker`. The PD's failure is measured, not assumed: the paper's PD at
  several gains, start speeds and DMP amplitudes ("modest tuning of the speed and amplitude")
  without pitch torque (``fig7.pd_without_pitch_torque``); and the paper's PD on DMPs learned
  from the QP walker's own gait (its mean cycle, started in its state at a heel strike, gains
  from the legs' inertia for a 60 rad/s closed loop) from seven starts
  (``fig7.pd_from_demonstration``): the claim test would move to the PD if at least four
  starts walked without a fall;
* simulator: MuJoCo (:class:`dmpopt.sim.MujocoSimulator`, 5 mm spheres at the point feet,
  friction 0.8), 1 ms step; the DMP steps every 4 ms (compiled);
* demonstration: normative sagittal hip and knee angles (Winter 2009, Perry 2010), the left
  leg half a cycle after the right (:mod:`dmpopt_studies.biped.gait`);
* eq. (21): :class:`dmpopt.frequency_adaptation.FrequencyAdaptation` at each heel strike.

The test (:mod:`dmpopt_studies.biped.fig7`): eq. (21) from four starts; beside it the legs'
resonance
estimated without eq. (21): the swing leg linearised (hip held) passive, under the paper's PD
gains and under the QP (:func:`dmpopt.frequency_adaptation.closed_loop_frequencies`), and the least
mechanical cost of transport of a fixed-frequency sweep; and the sceptic's controls from
12 rad/s: gravity and leg length scaled (a resonance-locked frequency moves as
:math:`\sqrt{g / l}`), and controller settings that are not leg dynamics (posture gains,
torso lean, foot-placement gain and target speed; a resonance-locked frequency barely moves).
``fig7.verdict`` is computed from them (:func:`dmpopt_studies.biped.fig7.verdict`).

Phase resetting's effect on robustness (``reset_robustness``) apart from "can it walk": an
arm without resetting does not walk undisturbed from any start (it falls at the first or
second heel strike), so every arm (resetting on and off, adaptation on and off,
:data:`dmpopt_studies.biped.analysis.ARMS`) starts at 12 rad/s and walks a 2 s warm-up with
resetting and adaptation on, the same start-up for all; the arm's own switches apply from the
first heel strike after it. Each arm walks undisturbed over the longest trial for three
start-speed seeds (``walks_undisturbed_by_seed``, the evidence); then the same seeded
randomised disturbances (push at a random phase after the warm-up, masses, slope) for every
arm, with Wilson intervals, a paired McNemar test and a verdict read from the intervals
(:func:`dmpopt_studies.biped.analysis.reset_verdict`: resetting raises or lowers survival only
where the intervals do not overlap). The arms of a trial (and of an undisturbed walk) are the
same walk until the warm-up ends: it is simulated once and continued once per arm
(``walk(arms=...)``), the same bits as four separate walks. ``gait`` puts the long walk's
step length, cadence, Froude number, impact force and double support beside human values.

The frequency a walk settles at is the median of its last 20 heel strikes. The QP walk on the
realistic plant and its plant sweep (docs/plant.md) run in the full study only. ``summary``
and ``captions`` are formatted from the metrics.

Run: ``python -m dmpopt_studies.biped OUT_DIR [--quick]``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from dmpopt_robots import biped as biped_model
from dmpopt_robots.biped import load_biped
from dmpopt_robots.plants import biped_realistic

from dmpopt.parallel import Runner, map_runs

from ..common import Progress, cpu_seconds, write_metrics
from ..plant_sweep import collect, plot_sweep, sweep_cases
from . import fig7, plots
from .analysis import (
    ARMS,
    SURVIVAL,
    Survival,
    TrialRanges,
    cost_of_transport,
    gait_metrics,
    random_disturbances,
    reset_ablation,
    reset_verdict,
    steps_to_within,
    survival_from_runs,
    survived,
    sweep_minimum,
    trial_jobs,
)
from .gait import DEMO_FREQUENCY, demonstration_from_walk, learn_gait, limit_cycle_start
from .summary import captions, summary
from .walker import (
    ADAPTATION_GAIN,
    CONTROL_EVERY,
    DT,
    GAINS,
    LOG_EVERY,
    QP_GAINS,
    Disturbance,
    Gains,
    QPControl,
    WalkLog,
    make_simulator,
    n_moving_bodies,
    walk,
)

__all__ = [
    "ADAPTATION_GAIN",
    "DEMO_FREQUENCY",
    "EXPECTED_SECONDS",
    "learn_gait",
    "limit_cycle_start",
    "main",
    "run",
    "swing_leg_frequencies",
    "walk",
]

# wall seconds on the 2-core machine, 2 workers (`dmpopt study run biped [--quick] --workers 2`,
# measured at a load average of 13-17: quick 284 s, full 1500 s; full-run CPU 562 s, user +
# system with the workers, so about 5 min of two idle cores plus the study's own 17 s)
EXPECTED_SECONDS = {"full": 68, "quick": 43}  # CPU s (dmpopt.cli): main job, 2026-11-28, EPYC
# [rad/s] starts below and above where the QP walker settles (from 4 rad/s it makes one step
# and falls; from 14 and 15 rad/s it falls within 1 s); the controls start at 12
START_FREQUENCIES = (5.0, 8.0, 12.0, 13.5)
MAIN_START = 5.0  # [rad/s] the long walk (gait, figures) starts at the demonstrated frequency
SWEEP = tuple(np.round(np.geomspace(4.0, 16.0, 8), 3))  # [rad/s] fixed frequencies
SWEEP_QUICK = (5.0, 13.0)
TRIAL_START = 12.0  # [rad/s] the robustness trials start near the settled frequency
UNDISTURBED_SEEDS = (0, 1, 2)  # the undisturbed walks of each arm (start-speed seeds)
UNDISTURBED_SEEDS_QUICK = (0,)
N_TRIALS = 10  # randomised trials per arm
RANGES = TrialRanges()
RANGES_QUICK = TrialRanges(warmup=0.5, push_time=(0.6, 0.9), slope_time=(0.5, 0.6))
SURVIVAL_QUICK = Survival(after=1.0, window=0.8)
REALISTIC_SECONDS = 40.0  # [s] the QP walk on the realistic plant
VIDEO_SECONDS_WALK = 4.0  # [s] the clip shows the last seconds of the QP walk
QP_WALK = {"controller": "qp", "boom_pitch_stiffness": 0.0, "boom_pitch_damping": 0.0}
"""The study's walks: the QP controller, the boom applying no pitch torque (:func:`walk`)."""


def swing_leg_frequencies(biped, dmp, frequency: float) -> dict:
    """Swing-leg natural frequencies [rad/s] linearised at mid-swing of the right leg.

    The robot stands on its left foot at the DMP's posture of phase 3 pi / 2 (right leg in
    mid-swing), base and stance leg held; the right hip and knee move under: no torque
    (passive double pendulum), the PD baseline's gains, and the QP controller (its posture
    task held at that posture, torso upright, left contact only).
    """
    from dmpopt.frequency_adaptation import closed_loop_frequencies

    plan = dmp.with_tau(1.0 / frequency).rollout(duration=3.75 * 2 * np.pi / frequency, dt=DT)
    height = biped_model.leg_length(biped)
    q = biped_model.configuration(biped, 0.0, height, 0.0, plan.positions[-1])
    q[1] -= biped_model.foot_positions(biped, q)[1, 1]  # left foot on the ground
    swing = biped.velocity_indices("gait")[:2]  # right hip, right knee
    slots = swing - biped.n_base
    gains = np.array([[GAINS.hip_stiffness, GAINS.hip_damping]] * 2)
    gains[1] = GAINS.knee_stiffness, GAINS.knee_damping

    def pd(moved, v):
        return -gains[:, 0] * (moved[swing] - q[swing]) - gains[:, 1] * v[swing]

    qp = QPControl(biped)
    qp.controller.remove_contact(biped.foot_frames[0])
    qp.posture.set_reference(q[np.sort(biped.velocity_indices("gait"))])

    def inverse_dynamics(moved, v):
        return qp.controller.compute_torques(moved, v, 0.0)[slots]

    frequencies = {
        name: closed_loop_frequencies(biped.model, q, swing, law).tolist()
        for name, law in (
            ("passive", lambda moved, v: np.zeros(2)),
            ("pd_baseline", pd),
            ("qp_controller", inverse_dynamics),
        )
    }
    straight = biped_model.swing_leg_natural_frequency(biped, 0.0)
    frequencies["passive_knee_locked_straight"] = straight
    return frequencies


def _summary(log: WalkLog, mass: float) -> dict:
    """Steps, fall, distance, speed, final frequency, cost and real-time factor of a walk."""
    return {
        "steps_walked": len(log.strikes),
        "fell": log.fell,
        "fall_reason": log.diverged,
        "simulated_time_s": log.duration,
        "distance_m": log.distance,
        "speed_m_per_s": log.distance / log.duration if log.duration else 0.0,
        "frequency_final": log.frequencies[-1],
        "cost_of_transport": cost_of_transport(log, mass),
        "real_time_factor_cpu": log.duration / log.cpu_time,
        "qp_holds": log.holds,
        "ticks_over_budget": log.ticks_over_budget,
        "tick_us_max": log.tick_us_max,
    }


def _qp_walk(duration: float, backend: str, plant, **options) -> WalkLog:
    """The QP walk from ``MAIN_START`` without pitch torque for ``duration`` [s] on ``plant``
    (:class:`dmpopt.sim.PlantParameters`), the controller believing the realistic preset
    (:func:`dmpopt_robots.plants.biped_realistic`); ``options`` go to :func:`walk`. The reality
    gap's walks: the realistic plant's and each case of its plant sweep."""
    biped = load_biped()
    _, dmp = learn_gait()
    return walk(
        biped, dmp, duration, MAIN_START, **QP_WALK, backend=backend, plant=plant,
        nominal_plant=biped_realistic(biped), **options,
    )  # fmt: skip


def _plant_case(case) -> dict:
    """One QP walk of the plant sweep: steps and fall. A link-mass case ``mass`` (the model's
    links x ``mass``) gives the plant's moving bodies ``1 / mass`` of their mass instead."""
    duration, plant, mass, backend = case
    disturbance = None
    if mass != 1.0:
        n_bodies = n_moving_bodies(load_biped())
        disturbance = Disturbance(mass_scale=(1.0 / mass,) * n_bodies)
    log = _qp_walk(duration, backend, plant, disturbance=disturbance)
    return {
        "steps": len(log.strikes),
        "fell": log.fell,
        "simulated_s": log.duration,
        "cpu_s": log.cpu_time,
    }


def _pd_from_demonstration(biped, qp_walk, quick: bool, backend: str, seed: int):
    """The PD walks on DMPs learned from ``qp_walk``'s mean gait cycle: their jobs for
    :func:`fig7.walk_job` by start frequency, the start state and the cycle's period [s]
    (:func:`~dmpopt_studies.biped.gait.demonstration_from_walk`)."""
    after = 0.3 if quick else fig7.PD_DEMO_AFTER
    gait_index = biped.velocity_indices("gait")
    demonstration, period, start = demonstration_from_walk(qp_walk, gait_index, after)
    job = {
        "controller": "pd",
        "boom_pitch_stiffness": 0.0,
        "boom_pitch_damping": 0.0,
        "backend": backend,
        "seed": seed,
        "log_every": LOG_EVERY,
        "pd_gains": fig7.pd_gains_from_inertia(biped, fig7.PD_CLOSED_LOOP, fig7.PD_DAMPING_RATIO),
        "amplitude": fig7.PD_AMPLITUDE,
        "start_pitch": start["pitch"],
        "start_speed": start["speed"],
        "duration": 1.5 if quick else fig7.PD_DEMO_DURATION,
        "demonstration": (demonstration.times, demonstration.positions, period),
    }
    starts = fig7.PD_DEMO_STARTS[4:5] if quick else fig7.PD_DEMO_STARTS
    return {frequency: {**job, "frequency": frequency} for frequency in starts}, start, period


def _realistic_walk(job) -> dict:
    """The QP walk on the realistic plant (an independent run): steps, fall, final frequency."""
    duration, realistic, backend, seed = job
    log = _qp_walk(duration, backend, realistic, seed=seed, log_every=10**9)
    return {
        "steps_walked": len(log.strikes),
        "fell": log.fell,
        "duration_s": log.duration,
        "frequency_final": log.frequencies[-1],
        "cpu_s": log.cpu_time,
    }


_RUNS = {"walk": fig7.walk_job, "trial": survived, "realistic": _realistic_walk}


def _run(item):
    """One independent run of the study's batch: ``(kind, input)``."""
    kind, job = item
    return _plant_case(job) if kind == "plant" else _RUNS[kind](job)


def _expected_seconds(item) -> float:
    """Simulated seconds a run of the batch may take (its length), to start the longest first."""
    kind, job = item
    if kind == "walk":
        return job["duration"] * len(job.get("arms", (None,)))
    if kind == "trial":  # every arm, the warm-up once
        return job[1]["duration"] * len(job[1]["arms"])
    return job[0]


def _pd_row(attempt, log) -> dict:
    stiffness, damping, speed, amplitude = attempt
    return {
        "stiffness_N_m_per_rad": stiffness,
        "damping_N_m_s_per_rad": damping,
        "start_speed_m_per_s": speed,
        "amplitude": amplitude,
        "fell": log.fell,
        "fall_reason": log.diverged,
        "simulated_s": log.duration,
        "heel_strikes": len(log.strikes),
    }


def _plan(quick: bool, backend: str, seed: int) -> dict:
    """Every walk of the first batch, by name: Fig. 7's starts, the scaling and controller
    controls, the fixed-frequency sweep, the paper's PD without pitch torque, and the
    undisturbed walks of each arm at the candidate starts of the robustness trials."""
    base = {**QP_WALK, "backend": backend, "seed": seed, "log_every": LOG_EVERY}
    converge = 1.5 if quick else 20.0  # [s] Fig. 7's starts (the one from MAIN_START: main)
    control = 1.5 if quick else 15.0  # [s] each control walk
    jobs = {}
    for start in START_FREQUENCIES:
        jobs[("start", start)] = {**base, "duration": converge, "frequency": start}
    jobs[("start", MAIN_START)]["duration"] = 3.0 if quick else converge  # the main walk
    for factor in fig7.GRAVITY_FACTORS[:1] if quick else fig7.GRAVITY_FACTORS:
        jobs[("gravity", factor)] = {
            **base,
            "duration": control,
            "gravity_factor": factor,
            "frequency": fig7.CONTROL_START,
        }
    for factor in fig7.LEG_FACTORS[1:] if quick else fig7.LEG_FACTORS:
        jobs[("legs", factor)] = {
            **base,
            "duration": control,
            "leg_factor": factor,
            "frequency": fig7.CONTROL_START,
        }
    names = fig7.INSENSITIVITY_QUICK if quick else fig7.INSENSITIVITY_FULL
    for name in names:
        jobs[("setting", name)] = {
            **base,
            "duration": control,
            "qp_overrides": fig7.INSENSITIVITY[name],
            "frequency": fig7.CONTROL_START,
        }
    for frequency in SWEEP_QUICK if quick else SWEEP:
        jobs[("sweep", frequency)] = {
            **base,
            "duration": 1.5 if quick else 4.0,
            "frequency": frequency,
            "adapt": False,
            "log_every": 10**9,
        }
    for attempt in fig7.PD_ATTEMPTS_QUICK if quick else fig7.PD_ATTEMPTS:
        stiffness, damping, speed, amplitude = attempt
        gains = Gains(stiffness, damping, stiffness, damping)
        jobs[("pd", attempt)] = {
            **base,
            "controller": "pd",
            "pd_gains": gains,
            "start_speed": speed,
            "amplitude": amplitude,
            "duration": 1.5 if quick else 3.0,
            "frequency": MAIN_START,
        }
    rule, ranges = (SURVIVAL_QUICK, RANGES_QUICK) if quick else (SURVIVAL, RANGES)
    for walk_seed in UNDISTURBED_SEEDS_QUICK if quick else UNDISTURBED_SEEDS:
        jobs[("undisturbed", walk_seed)] = {  # every arm, the warm-up walked once
            **base,
            "seed": walk_seed,
            "duration": ranges.push_time[1] + rule.after,  # the longest trial
            "frequency": TRIAL_START,
            "arms": tuple(ARMS.values()),
            "warmup": ranges.warmup,
        }
    return jobs


def _by_arm(logs: dict) -> dict:
    """``logs`` with each undisturbed run (a log per arm) as one entry per arm,
    ``("undisturbed", arm, seed)``, in the order of :data:`ARMS` for each seed."""
    expanded = {}
    for key, log in logs.items():
        if key[0] == "undisturbed":
            expanded.update({("undisturbed", arm, key[1]): each for arm, each in zip(ARMS, log)})
        else:
            expanded[key] = log
    return expanded


def run(
    out_dir,
    quick: bool = False,
    seed: int = 0,
    backend: str = "mujoco",
    runner=None,
    reality_gap: bool = True,
) -> dict:
    """Run the study; write ``metrics.json`` and the figures to ``out_dir``; return metrics.

    ``reality_gap``: in a full run, also the QP walk on the realistic plant and its plant
    sweep (:mod:`dmpopt_studies.plant_sweep`); a quick run never has them.

    The walks are independent runs, executed where ``runner`` says (:mod:`dmpopt.parallel`;
    default: in series), with the same bits in series, in worker processes and on Ray: the
    QPs the controller's warm active set does not certify are decided by DAQP, whose answers
    do not depend on where its buffers lie (:mod:`dmpopt.control.qp_stages`; the quick run's
    walks made 435 DAQP solves and no proxsuite one).
    """
    from dmpopt_studies.humanoid import VIDEO_FPS, check_backend, write_videos

    backend = check_backend(backend)
    cpu_start = cpu_seconds()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    progress = Progress("biped")
    runner = runner or Runner()
    progress("learning the gait; compiling the DMP step (cached after the first run)")
    biped = load_biped()
    _, dmp = learn_gait()
    plan = _plan(quick, backend, seed)
    rule, ranges = (SURVIVAL_QUICK, RANGES_QUICK) if quick else (SURVIVAL, RANGES)
    n_trials = 1 if quick else N_TRIALS
    disturbances = random_disturbances(biped, n_trials, seed, ranges)
    trials = trial_jobs(
        biped,
        dmp,
        TRIAL_START,
        disturbances,
        rule=rule,
        **QP_WALK,
        backend=backend,
        warmup=ranges.warmup,
    )
    runs = [("walk", job) for job in plan.values()] + [("trial", job) for job in trials]
    gap = reality_gap and not quick  # the realistic plant's walk and sweep (docs/plant.md)
    if gap:
        realistic = biped_realistic(biped)
        cases = sweep_cases(realistic, quick)
        runs.append(("realistic", (REALISTIC_SECONDS, realistic, backend, seed)))
        runs += [("plant", (8.0, plant, mass, backend)) for _, _, plant, mass in cases]
    progress(
        f"{len(runs)} walks: Fig. 7's starts, controls, sweep, PD, undisturbed arms, "
        f"{len(ARMS) * len(trials)} randomised trials ({len(ARMS)} arms x {n_trials})"
        + (", the realistic plant's walk and sweep" if gap else "")
    )
    # the longest first, so that no worker is left with a long walk at the end
    order = sorted(range(len(runs)), key=lambda i: -_expected_seconds(runs[i]))
    done = map_runs(_run, [runs[i] for i in order], runner, label="walks")
    results = [None] * len(runs)
    for i, result in zip(order, done):
        results[i] = result
    logs = _by_arm(dict(zip(plan, results[: len(plan)])))
    survival = survival_from_runs(results[len(plan) : len(plan) + len(trials)], n_trials)

    def rows(kind):
        return {key[1]: fig7.settled(log) for key, log in logs.items() if key[0] == kind}

    by_start = {key[1]: log for key, log in logs.items() if key[0] == "start"}
    main_walk = by_start[MAIN_START]
    starts = rows("start")
    baseline_row = starts[fig7.CONTROL_START]
    baseline = baseline_row["frequency_settled"]
    gravity = {1.0: baseline_row, **rows("gravity")}
    legs = {1.0: baseline_row, **rows("legs")}
    settings = rows("setting")

    sweep = [
        fig7.sweep_row(key[1], log, biped.mass) for key, log in logs.items() if key[0] == "sweep"
    ]
    minimum = sweep_minimum(sweep)
    progress("swing leg linearised")
    swing = swing_leg_frequencies(biped, dmp, baseline)
    resonance = {
        "swing leg, passive": swing["passive"][0],
        "swing leg, PD-loaded": swing["pd_baseline"][0],
        "swing leg, QP-loaded": swing["qp_controller"][0],
        "min CoT sweep": minimum["min_cost_of_transport_frequency"],
    }
    physical = {
        "passive swing leg": resonance["swing leg, passive"],
        "least cost of transport": resonance["min CoT sweep"],
    }
    verdict = fig7.verdict(starts, gravity, legs, settings, baseline, physical)
    pd_rows = [_pd_row(key[1], log) for key, log in logs.items() if key[0] == "pd"]
    pd_jobs, pd_start, period = _pd_from_demonstration(
        biped, by_start[fig7.CONTROL_START], quick, backend, seed
    )
    progress(f"{len(pd_jobs)} PD walks on the DMPs learned from the QP walker's gait")
    pd_logs = map_runs(fig7.walk_job, list(pd_jobs.values()), runner, label="PD walks")
    pd_from_demonstration = fig7.pd_demonstration_summary(
        {start: fig7.settled(log) for start, log in zip(pd_jobs, pd_logs)},
        next(iter(pd_jobs.values()))["pd_gains"],
        pd_start,
        period,
    )

    undisturbed = {arm: {} for arm in ARMS}
    for key, log in logs.items():
        if key[0] == "undisturbed":
            undisturbed[key[1]][key[2]] = fig7.walks_undisturbed(log, rule)
    walking = {arm: all(seeds.values()) for arm, seeds in undisturbed.items()}
    ablation = reset_ablation(survival)
    reset_robustness = {
        "verdict": reset_verdict(ablation, walking),
        "start_frequency_rad_s": TRIAL_START,
        "warmup_s": ranges.warmup,
        "design": (
            f"every arm starts at {TRIAL_START:g} rad/s and walks its first {ranges.warmup:g} s "
            "with phase resetting and adaptation on (the same start-up); from then on its own "
            "switches apply; pushes and slopes come after the warm-up"
        ),
        "walks_undisturbed_by_seed": {
            arm: {str(s): ok for s, ok in seeds.items()} for arm, seeds in undisturbed.items()
        },
        "all_arms_walk_undisturbed": all(walking.values()),
        "arms": {
            name: {k: v for k, v in arm.items() if k != "outcomes"}
            for name, arm in survival.items()
        },
        "phase_reset_ablation": ablation,
        "rule": rule.__dict__,
        "ranges": ranges.__dict__,
        "outcomes": {name: arm["outcomes"] for name, arm in survival.items()},
    }
    gait = gait_metrics(main_walk, biped_model.leg_length(biped), biped.mass)

    metrics = {
        "fig7": {
            "controller": "qp",
            "why_not_pd": (
                "the paper's joint PD cannot walk this point-footed biped without a pitch "
                "torque on the torso: every attempt in pd_without_pitch_torque fell"
                if all(row["fell"] for row in pd_rows)
                else "some PD attempts walked (pd_without_pitch_torque); the QP is kept"
            )
            + "; "
            + pd_from_demonstration["sentence"],
            "gains": {"qp": QP_GAINS.__dict__, "pd_loaded_estimate": GAINS.__dict__},
            "closed_loop_leg_frequencies_rad_s": swing,
            "frequency_final_by_start": {f"{s:g}": r["frequency_final"] for s, r in starts.items()},
            "frequency_settled_by_start": {
                f"{s:g}": r["frequency_settled"] for s, r in starts.items()
            },
            "fell_by_start": {f"{s:g}": r["fell"] for s, r in starts.items()},
            "resonance_estimates_rad_s": resonance,
            "gravity_scaling": {f"{f:g}": r["frequency_settled"] for f, r in gravity.items()},
            "leg_length_scaling": {f"{f:g}": r["frequency_settled"] for f, r in legs.items()},
            "insensitivity": {
                "baseline": baseline,
                **{name: r["frequency_settled"] for name, r in settings.items()},
            },
            "control_walks": {
                "start_rad_s": fig7.CONTROL_START,
                "gravity": {f"{f:g}": r for f, r in gravity.items()},
                "leg_length": {f"{f:g}": r for f, r in legs.items()},
                "settings": settings,
            },
            "verdict": verdict["sentence"],
            "verdict_numbers": verdict,
            "pd_without_pitch_torque": pd_rows,
            "pd_from_demonstration": pd_from_demonstration,
        },
        "reset_robustness": reset_robustness,
        "gait": gait,
        "fixed_frequency_sweep": sweep,
        "min_cost_of_transport_sweep": minimum,
        "main_walk": _summary(main_walk, biped.mass),
        "start_frequency": MAIN_START,
        "frequency_vs_step_by_start": {f"{s:g}": log.frequencies for s, log in by_start.items()},
        "steps_to_2pct_by_start": {
            f"{s:g}": steps_to_within(log.frequencies) for s, log in by_start.items()
        },
        "controller": "qp_inverse_dynamics",
        "boom_pitch_stiffness_N_m_per_rad": 0.0,
        "parallel": runner.record(),
        "real_time_factor_cpu": main_walk.duration / main_walk.cpu_time,
        "sim_step_s": DT,
        "dmp_step_s": CONTROL_EVERY * DT,
        "backend": backend,
    }
    cpu = {
        kind: sum(log.cpu_time for key, log in logs.items() if key[0] == kind)
        for kind in dict.fromkeys(key[0] for key in logs)
    }
    cpu["trials"] = sum(arm["cpu_s"] for arm in survival.values())
    cpu["pd_from_demonstration"] = sum(log.cpu_time for log in pd_logs)
    if gap:
        real_walk = results[len(plan) + len(trials)]
        plant_sweep = collect(cases, results[len(plan) + len(trials) + 1 :])
        metrics["plant_realistic"] = {
            **{k: v for k, v in real_walk.items() if k != "cpu_s"},
            "parameters": realistic.describe(biped.actuated_joint_names),
        }
        metrics["plant_sweep"] = plant_sweep
        cpu["realistic_plant_walk"] = real_walk["cpu_s"]
        cpu["plant_sweep"] = sum(row["cpu_s"] for rows in plant_sweep.values() for row in rows)
        plot_sweep(plant_sweep, "steps", "steps in 8 s", out_dir / "plant_sweep.png")
    clips = {}
    if backend == "mujoco" and not quick:
        every = max(1, int(round(1.0 / (VIDEO_FPS * DT * LOG_EVERY))))
        frames = np.asarray(main_walk.q)[::every][-int(VIDEO_SECONDS_WALK * VIDEO_FPS) :]
        clips["biped_walking"] = (make_simulator(biped, "mujoco"), frames, 2.0)
    skip = "quick run" if quick else None if backend == "mujoco" else "native backend"
    if clips:
        progress("video of the walk")
    metrics["videos"], metrics["videos_skipped"] = write_videos(out_dir, clips, skip)
    progress("figures")
    plots.frequency_figure(
        out_dir / "biped_frequency.png",
        {s: log.frequencies for s, log in by_start.items()},
        sweep,
        resonance,
        minimum.get("within_5%_of_min_rad_s"),
    )
    plots.controls_figure(out_dir / "biped_controls.png", baseline, gravity, legs, settings)
    plots.survival_figure(out_dir / "biped_survival.png", survival, ranges)
    plots.joints_figure(out_dir / "biped_joints.png", biped, main_walk)
    speed = main_walk.distance / max(main_walk.duration, DT)
    plots.stick_figure(out_dir / "biped_stick_figure.png", biped, main_walk, speed)
    parameters = {
        "start_frequencies_rad_s": START_FREQUENCIES,
        "adaptation_gain": ADAPTATION_GAIN,
        "qp_gains": QP_GAINS.__dict__,
        "pd_gains": GAINS.__dict__,
        "sweep_rad_s": SWEEP_QUICK if quick else SWEEP,
        "n_trials_per_arm": n_trials,
        "trial_start_rad_s": TRIAL_START,
        "walks": len(logs),
    }
    cpu["walks_total"] = sum(cpu.values())
    cpu["study_process"] = cpu_seconds() - cpu_start
    metrics["cpu_seconds"] = {
        **{k: round(v, 1) for k, v in cpu.items()},
        "note": (
            "process CPU time inside each walk by kind, summed over the workers, and the "
            "study's own process and the arms its walks forked (learning, swing leg, figures, "
            "video; the walks too when they run in series); worker start-up and imports not "
            "included"
        ),
    }
    metrics["summary"] = summary(metrics)
    metrics["captions"] = captions(metrics)
    progress("done")
    return write_metrics(out_dir, "biped", metrics, parameters, seed, quick)


def main(argv=None) -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--backend", choices=("mujoco", "native"), default="mujoco")
    args = parser.parse_args(argv)
    metrics = run(args.out_dir, quick=args.quick, seed=args.seed, backend=args.backend)
    fig7_keys = (
        "controller",
        "frequency_settled_by_start",
        "resonance_estimates_rad_s",
        "gravity_scaling",
        "leg_length_scaling",
        "insensitivity",
        "verdict",
    )
    shown = {
        "fig7": {k: metrics["fig7"][k] for k in fig7_keys},
        "reset_robustness": metrics["reset_robustness"]["arms"],
        "gait": metrics["gait"],
        "main_walk": metrics["main_walk"],
    }
    print(json.dumps(shown, indent=2))
