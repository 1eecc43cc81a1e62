"""The study: which runs, in which order, and what it writes (``run``, ``main``)."""

from __future__ import annotations

import time
from dataclasses import dataclass

from dmpopt_robots import load_talos
from dmpopt_robots.plants import talos_realistic

from dmpopt.exceptions import InvalidInputError
from dmpopt.parallel import Runner

from ..common import Progress, cpu_seconds, output_dir, write_metrics
from ..plant_sweep import plot_sweep
from ..talos_walk import keyframes, run_walk
from .controller import mujoco_plant, with_mass_error
from .demos import DRUM_JOINTS, demonstrate_drumming
from .figures import plot, video_clips, write_videos
from .loop import run_drumming, run_figure8
from .metrics import StudyRuns, fit_error, study_metrics
from .parameters import (
    ARM_STIFFNESS,
    BACKENDS,
    CHANGE_END,
    CHANGE_START,
    DT,
    FIGURE8_PERIOD,
    FIGURE8_SIZE,
    HAND_STIFFNESS,
    MASS_ERROR,
    N_BASIS,
    PERIOD,
    SETPOINT_SHIFT,
    STROKE_HEIGHT,
    STROKE_LOOP,
    SWING_BACK,
    SWING_BACK_SECONDS,
    SWING_FINISH_RAISE,
    SWING_FOLLOW,
    SWING_FORWARD_SECONDS,
    SWING_FORWARD_START,
    VIDEO_FPS,
    WRIST_FLICK,
)
from .plan import MODIFICATIONS, Modification, learn_drumming, plan_rollout, stepper_compiles
from .plant import drumming_sweep, plant_comparison
from .robustness import loop_summary, mujoco_metrics, mujoco_scenarios
from .summary import captions, summary_rows
from .swing import (
    SWING_JOINTS,
    demonstrate_swing,
    executed_swing,
    learn_swing,
    raised_goal,
    swing_metrics,
)


@dataclass(frozen=True)
class Durations:
    """Simulated seconds of each run and the Fig. 4 modification window [s]."""

    drum: float
    fixed: float
    figure8: float
    fig4: float
    window: tuple
    sweep: float  # each run of the plant comparison and sweep

    @classmethod
    def of(cls, quick: bool) -> Durations:
        """The quick run's (about 40 s simulated in all) or the full run's."""
        if quick:
            return cls(3.0, 2.0, 4.0, 4.0, (1.0, 3.0), 1.5)
        return cls(10.0, 10.0, 10.0, 10.0, (CHANGE_START, CHANGE_END), 3.0)


def check_backend(backend) -> str:
    """``backend`` if it is one of ``BACKENDS``, else :class:`InvalidInputError`."""
    if backend not in BACKENDS:
        raise InvalidInputError(
            f"backend must be one of {BACKENDS}, got {backend!r}; pass backend='mujoco' "
            "(default) or backend='native' (the compliant-ground simulator of dmpopt.sim)"
        )
    return backend


def run(out_dir, quick: bool = False, seed: int = 0, backend: str = "mujoco", runner=None) -> dict:
    """Run the study, write the figures and ``metrics.json`` into ``out_dir``; return metrics.

    ``backend`` simulates the standing robot: "mujoco" (default; also runs the model-mismatch,
    friction, torque-limit and push scenarios, a native run for comparison, and the videos)
    or "native". ``runner`` (:class:`dmpopt.parallel.Runner`, default serial) runs the
    independent MuJoCo scenarios and pushes. The study is deterministic; ``seed`` is
    recorded only.
    """
    backend = check_backend(backend)
    runner = runner or Runner()
    out = output_dir(out_dir)
    durations = Durations.of(quick)
    progress = Progress("humanoid")
    start_wall, start_cpu = time.perf_counter(), cpu_seconds()

    progress("drumming demonstration (inverse kinematics) and rhythmic DMPs")
    demo = demonstrate_drumming()
    dmps = learn_drumming(demo)
    compile = stepper_compiles(dmps)
    floating = load_talos("full")
    study = simulate(floating, dmps, durations, backend, quick, compile, progress, runner)

    metrics = study_metrics(floating, dmps, study)
    metrics.update(demo_ik_error=demo.ik_error, dmp_fit_error_rad=fit_error(dmps, demo))
    metrics.update(dmp_step_compiled=compile, backend=backend)
    metrics["discrete_swing"] = swing_metrics(floating, study.swing_demo, study.swings)
    metrics["native"] = loop_summary(study.native)
    on_mujoco = backend == "mujoco"
    if on_mujoco:
        metrics["mujoco"] = mujoco_metrics(study.runs["none"], study.mujoco)
        metrics["plant"] = plant_comparison(
            floating, dmps, compile, study.runs["none"], quick, progress, durations.sweep
        )
        progress("plant sweep: drumming")
        metrics["plant_sweep"] = drumming_sweep(
            floating, dmps, durations.sweep, compile, quick, runner
        )
        plot_sweep(metrics["plant_sweep"], "tracking_rms_rad", "drumming RMS [rad]",
                   out / "plant_sweep.png", log_y=True)  # fmt: skip
        progress("Talos walk (reduced model): steps in place, then forward")
        metrics["walk"] = run_walk(out, quick, runner)
    skip = "quick run" if quick else None if on_mujoco else "native backend (videos need MuJoCo)"
    clips = video_clips(floating, study) if skip is None else {}
    progress("figures" + ("" if skip else " and videos"))
    metrics["videos"], metrics["videos_skipped"] = write_videos(out, clips, skip)
    if metrics["videos_skipped"]:
        print(f"videos skipped: {metrics['videos_skipped']}")
    if "humanoid_swing.webp" in metrics["videos"]:
        keyframes(out / "humanoid_swing.webp", out / "swing_keyframes.png")
    plot(out, dmps, demo, study)
    metrics["parallel"] = runner.record()
    metrics["summary"] = summary_rows(metrics)
    metrics["captions"] = captions(metrics)
    metrics["cpu_seconds"] = cpu_seconds() - start_cpu  # with the forked push trials
    metrics["wall_seconds"] = time.perf_counter() - start_wall
    return write_metrics(out, "humanoid", metrics, _parameters(durations), seed, quick)


def simulate(
    robot, dmps, durations: Durations, backend: str, quick: bool, compile: bool, progress, runner
):
    """Every closed-loop run of the study on the standing ``robot``, as :class:`StudyRuns`."""
    on_mujoco = backend == "mujoco"
    realistic = talos_realistic(robot)  # the plant, and what the controller believes of it
    standing = {
        "compile": compile,
        "build_options": {"com_sink": 0.0, "nominal_plant": realistic} if on_mujoco else None,
        "plant": mujoco_plant(parameters=realistic) if on_mujoco else None,
    }
    record = int(round(1.0 / (VIDEO_FPS * DT))) if on_mujoco and not quick else 0
    modifications = [Modification(m.name, *durations.window) for m in MODIFICATIONS]
    runs, plans = {}, {}
    for modification in modifications:
        name = modification.name
        duration = durations.drum if name == "none" else durations.fig4
        progress(f"drumming, Fig. 4 {modification.label} ({duration:g} s simulated)")
        plans[name] = plan_rollout(dmps, durations.fig4, modification)
        runs[name] = run_drumming(
            robot,
            dmps,
            duration,
            modification,
            record_every=record if name == "none" else 0,
            **standing,
        )
    progress("drumming: fixed base, heavier arms in the model, no pelvis task; figure-8")
    # The fixed-base upper body is a reduced model with locked legs (no URDF of its own):
    # it stays on the native simulator, as the controller's timing reference.
    fixed = load_talos("full", fixed_base=True)
    fixed_log = run_drumming(fixed, dmps, durations.fixed, None, compile=compile)
    # Ablations: a controller model with heavier arms, and no pelvis orientation task.
    heavier_arms = with_mass_error(robot, MASS_ERROR)
    wrong_model = run_drumming(
        robot, dmps, durations.drum, None, controller_robot=heavier_arms, **standing
    )
    no_base_task = run_drumming(robot, dmps, durations.drum, None, base_task=False, **standing)
    figure8, _ = run_figure8(robot, durations.figure8, record_every=record, **standing)
    progress("discrete forehand swing: demonstrated goal and a higher finish")
    swing_demo = demonstrate_swing(robot)
    swing_dmp = learn_swing(swing_demo)
    swings = {
        name: executed_swing(robot, dmp, dmp.settling_time, record_every=record, **standing)
        for name, dmp in (
            ("demonstrated_goal", swing_dmp),
            ("new_goal", swing_dmp.with_goal(raised_goal(robot, swing_dmp))),
        )
    }
    native, mujoco = runs["none"], None
    if on_mujoco:
        progress("drumming on the native simulator; MuJoCo scenarios and pushes")
        native = run_drumming(robot, dmps, durations.drum, None, compile=compile)
        mujoco = mujoco_scenarios(dmps, runs["none"], quick, compile, runner)
    return StudyRuns(
        modifications,
        plans,
        runs,
        fixed_log,
        wrong_model,
        no_base_task,
        figure8,
        native,
        mujoco,
        durations.fig4,
        swing_demo,
        swings,
    )


def _parameters(durations: Durations) -> dict:
    """The set-up recorded in ``metrics.json``."""
    return {
        "robot": "talos full (example-robot-data), floating base + fixed-base upper body",
        "dt_s": DT,
        "period_s": PERIOD,
        "n_basis": N_BASIS,
        "drum_joints": DRUM_JOINTS,
        "modification_window_s": durations.window,
        "setpoint_shift_rad": SETPOINT_SHIFT,
        "fig4_changes": "steps (no filter)",
        "arm_stiffness": ARM_STIFFNESS,
        "hand_stiffness": HAND_STIFFNESS,
        "durations_s": {
            "drumming": durations.drum,
            "fig4_each": durations.fig4,
            "fixed_base": durations.fixed,
            "figure8": durations.figure8,
        },
        "stroke": {"height_m": STROKE_HEIGHT, "loop_m": STROKE_LOOP, "wrist_rad": WRIST_FLICK},
        "figure8_size_m": FIGURE8_SIZE,
        "figure8_period_s": FIGURE8_PERIOD,
        "swing": {
            "joints": SWING_JOINTS,
            "backswing_rad": SWING_BACK,
            "follow_through_rad": SWING_FOLLOW,
            "backswing_s": SWING_BACK_SECONDS,
            "forward_swing_start_s": SWING_FORWARD_START,
            "forward_swing_s": SWING_FORWARD_SECONDS,
            "new_goal_finish_raise_m": SWING_FINISH_RAISE,
        },
    }


def main(argv=None) -> None:
    """Command line: ``python -m dmpopt_studies.humanoid OUT_DIR [--quick] [--seed N]``."""
    import argparse
    import json

    from . import __doc__ as claim

    parser = argparse.ArgumentParser(description=claim.splitlines()[0])
    parser.add_argument("out_dir", nargs="?", default="results/humanoid")
    parser.add_argument("--quick", action="store_true", help="a few simulated seconds")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--backend", choices=BACKENDS, default="mujoco")
    parser.add_argument("--workers", type=int, default=1, help="processes for the scenarios")
    args = parser.parse_args(argv)
    runner = Runner(args.workers)
    metrics = run(
        args.out_dir, quick=args.quick, seed=args.seed, backend=args.backend, runner=runner
    )
    print(json.dumps({k: metrics[k] for k in SUMMARY_KEYS if k in metrics}, indent=1))


SUMMARY_KEYS = (  # what main() prints
    "tick_us_median",
    "tick_us_p99",
    "tick_us_fixed_base_median",
    "tick_us_fixed_base_p99",
    "real_time_factor",
    "real_time_factor_cpu",
    "tracking_rms_rad",
    "figure8_rms_mm",
    "settle_time_s",
    "discrete_swing",
    "torque_limit_use_max",
    "position_limit_margin_rad",
    "fell",
    "n_cold_restarts",
    "n_fallbacks",
    "direct_solve_fraction",
    "native",
    "mujoco",
    "videos",
)
