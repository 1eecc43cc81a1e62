r"""ProMPs learned on LASA, obstacle avoidance (two coupling terms against a constrained fit),
and two hands carrying a box with coupled DMPs.

Claim (issue 33): dmpopt's :class:`~dmpopt.ProMP` learns a distribution from LASA's 7
demonstrations per shape, conditions on via-points exactly and predicts held-out
demonstrations; its obstacle coupling terms (:mod:`dmpopt.obstacles`) steer a DMP around an
obstacle online, and the constrained fit with keep-out regions
(:func:`dmpopt.fitting.fit_keep_out`) plans around it with a guaranteed clearance at every
sample.

Set-up (all choices are ours):

* ProMP: :func:`dmpopt.fit_promp` with ``N_BASIS`` basis functions per DOF and its defaults,
  on every LASA shape (positions in mm, each demonstration on its own normalised time);
* ``lasa_reproduction_mm``: RMS distance between the ProMP's mean and the average of the 7
  demonstrations (both at ``N_EVAL`` equally spaced phases), median over the shapes;
* ``via_point_error_mm``: the ProMP conditioned (no observation noise) on demonstration 1's
  start, middle and end positions; largest distance of the conditioned mean to those three
  points, median over shapes (``conditioned_rmse_mm``: RMS distance of that conditioned mean
  to the whole demonstration 1);
* ``heldout_loglik``: leave one demonstration out of 7, fit on the other 6, log-density of
  the left-out one at ``N_EVAL`` phases divided by ``N_EVAL`` [nats per 2-D sample in mm],
  mean over the 7 folds, median over shapes;
* ``fit_ms``, ``condition_ms``: median wall time of the fit on 7 demonstrations and of the
  three conditionings;
* obstacle scenes: a 2-D minimum-jerk line from (0, 0) to (1, 0) m in 1 s, fitted by
  :func:`dmpopt.fit_discrete` (``N_BASIS`` basis functions), with a disc across the line in
  each of ``SCENES``; methods: the steering angle (Hoffmann et al. 2009, published gains
  gamma 1000, beta 20/pi), the dynamic potential field (Park et al. 2008, lambda 1, beta 2),
  both run by :class:`dmpopt.Stepper` at 1 kHz, and the keep-out fit (the disc, ``N_SAMPLES``
  samples, objective ``"forcing"``: closest to the imitation fit's forcing term;
  ``keep_out_position``: objective ``"position"``, closest to the demonstrated positions,
  which hugs the disc with sharp turns) rolled out at 1 kHz; the box scene only for the
  keep-out fit (the coupling terms take spheres);
* per method over the scenes: ``clearance_min_mm`` (signed distance to the disc's surface at
  every 1 ms sample over ``RUN_SECONDS``, smallest over scenes; negative inside),
  ``path_length_ratio`` and ``jerk_ratio`` (path length and RMS jerk against the same DMP
  without obstacle, mean over scenes), ``collisions`` (scenes whose path enters the disc),
  ``goal_error_mm`` (largest distance to the goal at the end), ``time_ms`` (mean wall time
  per scene: the rollout with the term, or the keep-out fit).

Two-hand coupling (``bimanual``): :mod:`dmpopt_studies.bimanual` (its docstring has the set-up):
standing Talos in MuJoCo carries a box held between its grippers by friction, the hands'
Cartesian DMPs perturbed (one slower, one told of a new goal later), coupled by
:class:`dmpopt.bimanual.RelativePoseCoupling` or not; in quick mode the plans only.

movement_primitives 0.9.1's ProMP and obstacle coupling on the same data:
``benchmarks/bench_primitives.py`` (its own venv), numbers in ``docs/primitives.md``.

Run: ``python -m dmpopt_studies.primitives OUT_DIR [--quick]`` (quick: 2 shapes, 1 scene, the
bimanual plans without the robot).
"""

from __future__ import annotations

import time

import numpy as np
from dmpopt_studies.bimanual import bimanual_metrics
from dmpopt_studies.common import (
    Progress,
    command_line,
    median_time,
    output_dir,
    pyplot,
    write_metrics,
)

from dmpopt import Trajectory, fit_discrete, fit_keep_out, fit_promp
from dmpopt.fitting import minimum_jerk
from dmpopt.obstacles import Box, PotentialField, Sphere, SteeringAngle, clearance, run_coupled

EXPECTED_SECONDS = {"full": 17, "quick": 5}  # CPU s (dmpopt.cli): main job, 2026-11-28, EPYC
N_BASIS = 20
N_EVAL = 100
QUICK_SHAPES = ("Angle", "GShape")
DT = 1e-3  # [s]
RUN_SECONDS = 2.0  # [s] twice the demonstration: the coupled runs arrive late
N_SAMPLES = 1001  # over the demo's 1 s: the 1 ms grid of the steppers
SCENES = (  # disc centre [m] and radius [m], across the straight line y = 0
    ((0.5, 0.03), 0.10),
    ((0.35, -0.02), 0.06),
    ((0.6, 0.005), 0.12),
)
BOX_SCENE = ((0.5, 0.03), (0.05, 0.10))  # centre and half-widths [m]
METHODS = ("steering_angle", "potential_field", "keep_out", "keep_out_position")
KEEP_OUT_OBJECTIVES = {"keep_out": "forcing", "keep_out_position": "position"}


# -- ProMP on LASA ---------------------------------------------------------------------------


def phases_of(demo: Trajectory) -> np.ndarray:
    """Normalised time of each sample of ``demo``, 0 to 1."""
    return (demo.times - demo.times[0]) / demo.duration


def at_phases(demo: Trajectory, phases: np.ndarray) -> np.ndarray:
    """Positions of ``demo`` interpolated at normalised times ``phases``."""
    own = phases_of(demo)
    return np.column_stack([np.interp(phases, own, demo.positions[:, d]) for d in range(2)])


def promp_metrics(demos) -> dict:
    """The ProMP metrics of one LASA shape (module docstring)."""
    phases = np.linspace(0.0, 1.0, N_EVAL)
    promp = fit_promp(demos, N_BASIS)
    times = phases * promp.duration
    average = np.mean([at_phases(demo, phases) for demo in demos], axis=0)
    reproduction = np.sqrt(np.mean(np.sum((promp.mean_positions(times) - average) ** 2, axis=1)))
    target = demos[0]
    points = [(0.0, target.positions[0]), (0.5, at_phases(target, np.array([0.5]))[0])]
    points.append((1.0, target.positions[-1]))

    def condition():
        conditioned = promp
        for phase, point in points:
            conditioned = conditioned.condition(phase * promp.duration, position=point)
        return conditioned

    conditioned = condition()
    via = max(
        np.linalg.norm(conditioned.mean_positions([phase * promp.duration])[0] - point)
        for phase, point in points
    )
    difference = conditioned.mean_positions(times) - at_phases(target, phases)
    loglik = []
    for k in range(len(demos)):
        rest = [demo for j, demo in enumerate(demos) if j != k]
        held = demos[k]
        sampled = Trajectory.from_positions(phases * held.duration, at_phases(held, phases))
        loglik.append(fit_promp(rest, N_BASIS).log_likelihood(sampled) / N_EVAL)
    return {
        "reproduction_mm": float(reproduction),
        "via_point_error_mm": float(via),
        "conditioned_rmse_mm": float(np.sqrt(np.mean(np.sum(difference**2, axis=1)))),
        "heldout_loglik": float(np.mean(loglik)),
        "fit_ms": 1e3 * median_time(lambda: fit_promp(demos, N_BASIS), 5),
        "condition_ms": 1e3 * median_time(condition, 5),
    }


# -- obstacles -------------------------------------------------------------------------------


def line_demo() -> Trajectory:
    """The scenes' demonstration: a minimum-jerk line from (0, 0) to (1, 0) m in 1 s."""
    return minimum_jerk(np.zeros(2), np.array([1.0, 0.0]), 1.0, 0.002)


def path_length(positions: np.ndarray) -> float:
    """Length of the polyline through ``positions`` [m]."""
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())


def rms_jerk(positions: np.ndarray, dt: float) -> float:
    """RMS norm of the third finite difference of ``positions`` over ``dt^3`` [m/s^3]."""
    jerk = np.diff(positions, n=3, axis=0) / dt**3
    return float(np.sqrt(np.mean(np.sum(jerk**2, axis=1))))


def plan(method: str, dmp, demo: Trajectory, region) -> tuple[np.ndarray, float]:
    """Positions at 1 ms over ``RUN_SECONDS`` with ``method`` around ``region``, and the
    wall time of the rollout (coupling terms) or of the fit (keep-out) [s]."""
    n_steps = int(round(RUN_SECONDS / DT))
    begin = time.perf_counter()
    if method in KEEP_OUT_OBJECTIVES:
        objective = KEEP_OUT_OBJECTIVES[method]
        fitted, _ = fit_keep_out(demo, [region], N_BASIS, n_samples=N_SAMPLES, objective=objective)
        elapsed = time.perf_counter() - begin
        velocity = np.zeros(2)
        return fitted.rollout(RUN_SECONDS, DT, start_velocity=velocity).positions, elapsed
    if method == "none":
        coupling = lambda position, velocity: np.zeros(2)  # noqa: E731
    elif method == "steering_angle":
        coupling = SteeringAngle(region)
    else:
        coupling = PotentialField(region)
    positions = run_coupled(dmp.stepper(DT), coupling, n_steps).positions
    return positions, time.perf_counter() - begin


def obstacle_metrics(scenes) -> tuple[dict, dict]:
    """Metrics per method over ``scenes`` (module docstring), and the paths for the figure."""
    demo = line_demo()
    dmp = fit_discrete(demo, N_BASIS)
    reference, _ = plan("none", dmp, demo, None)
    goal = demo.positions[-1]
    results, paths = {}, {"none": reference}
    regions = [Sphere(centre, radius) for centre, radius in scenes]
    for method in METHODS:
        rows = []
        for k, region in enumerate(regions):
            positions, elapsed = plan(method, dmp, demo, region)
            if k == 0:
                paths[method] = positions
            rows.append(
                (
                    clearance(positions, region).min(),
                    path_length(positions) / path_length(reference),
                    rms_jerk(positions, DT) / rms_jerk(reference, DT),
                    np.linalg.norm(positions[-1] - goal),
                    elapsed,
                )
            )
        rows = np.array(rows)
        results[method] = {
            "clearance_min_mm": 1e3 * float(rows[:, 0].min()),
            "path_length_ratio": float(rows[:, 1].mean()),
            "jerk_ratio": float(rows[:, 2].mean()),
            "collisions": int(np.sum(rows[:, 0] < 0.0)),
            "goal_error_mm": 1e3 * float(rows[:, 3].max()),
            "time_ms": 1e3 * float(rows[:, 4].mean()),
        }
    box = Box(*BOX_SCENE)
    positions, elapsed = plan("keep_out", dmp, demo, box)
    paths["keep_out_box"] = positions
    results["keep_out_box"] = {
        "clearance_min_mm": 1e3 * float(clearance(positions, box).min()),
        "path_length_ratio": path_length(positions) / path_length(reference),
        "jerk_ratio": rms_jerk(positions, DT) / rms_jerk(reference, DT),
        "collisions": int(clearance(positions, box).min() < 0.0),
        "goal_error_mm": 1e3 * float(np.linalg.norm(positions[-1] - goal)),
        "time_ms": 1e3 * elapsed,
    }
    return results, paths


# -- the study -------------------------------------------------------------------------------


def run(out_dir, quick: bool = False, seed: int = 0) -> dict:
    """Run the study, write the figures and ``metrics.json`` into ``out_dir``; return them."""
    from dmpopt_studies.lasa import demonstrations, shape_names

    progress = Progress("primitives")
    out = output_dir(out_dir)
    start_cpu = time.process_time()
    names = list(QUICK_SHAPES) if quick else shape_names()
    per_shape = {}
    for name in names:
        progress(f"ProMP on {name}")
        per_shape[name] = promp_metrics(demonstrations(name))
    keys = ("reproduction_mm", "via_point_error_mm", "conditioned_rmse_mm", "heldout_loglik")
    keys += ("fit_ms", "condition_ms")
    medians = {key: float(np.median([m[key] for m in per_shape.values()])) for key in keys}
    promp = {"lasa_reproduction_mm": medians.pop("reproduction_mm"), **medians}
    promp["n_shapes"] = len(names)
    progress("obstacle scenes")
    scenes = SCENES[:1] if quick else SCENES
    obstacles, paths = obstacle_metrics(scenes)
    metrics = {"promp": promp, "promp_per_shape": per_shape, "obstacles": obstacles}
    metrics["bimanual"] = bimanual_metrics(out, quick, progress)
    plot(out, demonstrations(names[0]), paths, scenes[0])
    metrics["summary"] = summary(metrics)
    metrics["captions"] = CAPTIONS
    metrics["cpu_seconds"] = time.process_time() - start_cpu
    parameters = {"n_basis": N_BASIS, "n_eval": N_EVAL, "shapes": names, "scenes": scenes}
    parameters |= {"box_scene": BOX_SCENE, "run_seconds": RUN_SECONDS, "n_samples": N_SAMPLES}
    return write_metrics(out, "primitives", metrics, parameters, seed, quick)


CAPTIONS = {
    "primitives_promp": "A ProMP learned from LASA's 7 demonstrations of one shape: mean and "
    "two standard deviations, samples, and the mean conditioned on demonstration 1's start, "
    "middle and end, which passes through the three points.",
    "primitives_obstacles": "A straight DMP plan across a disc: the steering-angle and "
    "potential-field coupling terms bend it online; the keep-out fit plans around the disc "
    "(and a box) with the clearance held at every sample.",
    "primitives_bimanual": "Talos carries a box held between its grippers by friction; the "
    "left hand's plan is slower and learns of the new goal (grey line) later. Coupled (blue) "
    "the hands' relative pose holds and the box is carried; uncoupled (red) the grasp opens "
    "and the box falls (right: its height). Dashed: the plans; solid: the robot's hands.",
}


def summary(metrics: dict) -> list[dict]:
    """The study's opening table, formatted from its metrics."""
    promp, obstacles = metrics["promp"], metrics["obstacles"]
    anchor = "movement_primitives 0.9.1: benchmarks/bench_primitives.py (docs/primitives.md)"

    def line(method):
        row = obstacles[method]
        return (
            f"{method}: clearance {row['clearance_min_mm']:.3g} mm, length x"
            f"{row['path_length_ratio']:.3f}, jerk x{row['jerk_ratio']:.2f}, "
            f"{row['collisions']} collisions"
        )

    return [
        {
            "claim": "a ProMP learned from 7 LASA demonstrations per shape",
            "paper": "not in the paper (Paraschos et al. 2013)",
            "dmpopt": f"mean within {promp['lasa_reproduction_mm']:.3g} mm of the demos' "
            f"average; held-out {promp['heldout_loglik']:.3g} nats/sample; fit "
            f"{promp['fit_ms']:.2g} ms",
            "anchor": anchor,
            "verdict": "beyond the paper",
        },
        {
            "claim": "conditioning on via-points passes through them",
            "paper": "not in the paper",
            "dmpopt": f"{promp['via_point_error_mm']:.2g} mm off the points",
            "anchor": anchor,
            "verdict": "beyond the paper",
        },
        bimanual_row(metrics["bimanual"]),
        {
            "claim": "obstacle avoidance: coupling terms online, keep-out fit offline",
            "paper": "not in the paper",
            "dmpopt": "; ".join(line(method) for method in METHODS),
            "anchor": anchor,
            "verdict": "beyond the paper",
        },
    ]


def bimanual_row(bimanual: dict) -> dict:
    """The summary row of the two-hand carry."""
    coupled, uncoupled = bimanual["coupled"], bimanual["uncoupled"]
    if "relative_pose_error_mm" in coupled:
        numbers = (
            f"robot's hands' relative pose moves {coupled['relative_pose_error_mm']:.3g} mm / "
            f"{coupled['relative_pose_error_deg']:.2g} deg coupled against "
            f"{uncoupled['relative_pose_error_mm']:.3g} mm / "
            f"{uncoupled['relative_pose_error_deg']:.2g} deg uncoupled; box drop "
            f"{coupled['box_drop_mm']:.3g} mm against {uncoupled['box_drop_mm']:.4g} mm"
        )
    else:
        numbers = (
            f"plans' relative error {coupled['plan_relative_error_mm']:.3g} mm coupled against "
            f"{uncoupled['plan_relative_error_mm']:.3g} mm uncoupled (quick: no robot)"
        )
    return {
        "claim": "a two-hand coupling holds the hands' relative pose: Talos carries a box",
        "paper": "not in the paper (Gams et al. 2014)",
        "dmpopt": numbers,
        "anchor": "studies/bimanual.py; movement_primitives' dual Cartesian DMP",
        "verdict": "beyond the paper",
    }


def plot(out, demos, paths: dict, scene) -> None:
    """primitives_promp.png and primitives_obstacles.png."""
    plt = pyplot()
    promp = fit_promp(demos, N_BASIS)
    times = np.linspace(0.0, promp.duration, 200)
    mean, covariances = promp.mean_positions(times), promp.position_covariances(times)
    target = demos[0]
    middle = at_phases(target, np.array([0.5]))[0]
    conditioned = promp
    for phase, point in ((0.0, target.positions[0]), (0.5, middle), (1.0, target.positions[-1])):
        conditioned = conditioned.condition(phase * promp.duration, position=point)
    figure, axes = plt.subplots(1, 2, figsize=(10, 4))
    for demo in demos:
        axes[0].plot(*demo.positions.T, color="grey", lw=0.8)
    for sample in promp.sample_trajectories(times, 5, rng=0):
        axes[0].plot(*sample.T, color="tab:blue", lw=0.5, alpha=0.5)
    axes[0].plot(*mean.T, color="tab:blue", lw=2, label="mean (samples thin)")
    axes[0].plot(*conditioned.mean_positions(times).T, color="tab:red", lw=2, label="conditioned")
    axes[0].plot(*np.array([target.positions[0], middle, target.positions[-1]]).T, "ko")
    axes[0].set(xlabel="x [mm]", ylabel="y [mm]", title="ProMP (grey: demonstrations)")
    axes[0].legend(fontsize=8)
    for d, name in enumerate("xy"):
        std = np.sqrt(covariances[:, d, d])
        axes[1].fill_between(times, mean[:, d] - 2 * std, mean[:, d] + 2 * std, alpha=0.3)
        axes[1].plot(times, mean[:, d], label=f"{name} mean +- 2 std")
    axes[1].set(xlabel="time [s]", ylabel="position [mm]")
    axes[1].legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(out / "primitives_promp.png", dpi=120)
    figure, axis = plt.subplots(figsize=(8, 3.5))
    (cx, cy), radius = scene
    axis.add_patch(plt.Circle((cx, cy), radius, color="grey", alpha=0.4))
    (bx, by), (hx, hy) = BOX_SCENE
    axis.add_patch(plt.Rectangle((bx - hx, by - hy), 2 * hx, 2 * hy, fill=False, ls=":"))
    for name, positions in paths.items():
        axis.plot(*positions.T, label=name.replace("_", " "))
    axis.set(xlabel="x [m]", ylabel="y [m]", aspect="equal", title="obstacle avoidance")
    axis.legend(fontsize=7, loc="lower right")
    figure.tight_layout()
    figure.savefig(out / "primitives_obstacles.png", dpi=120)
    plt.close("all")


def main(argv=None) -> None:
    metrics = command_line(run, __doc__, argv)
    print(metrics["promp"])
    for method, row in metrics["obstacles"].items():
        print(method, row)
    for name in ("coupled", "uncoupled"):
        print("bimanual", name, metrics["bimanual"][name])


if __name__ == "__main__":
    main()
