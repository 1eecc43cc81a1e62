"""Constrained DMPs vs minimum jerk vs retiming under tight limits on LASA (beyond the paper).

Claim evaluated: fitting DMP weights as a QP under velocity/acceleration bounds (with a
shifted goal) gives plans that respect the bounds at every sample, keep the demonstrated
shape closer than a minimum-jerk movement through a few of its points, and keep the
duration that time-optimal retiming (toppra) or uniform tau scaling give up. For each LASA
shape: the unconstrained DMP, the constrained DMP, constrained minimum jerk (through 3
points of the moved demonstration within 5 % of its extent,
same bounds), the toppra retiming of the unconstrained
plan and its uniform tau scaling are compared on bound violation, shape error (timing-free
path distance to the moved demonstration), integrated squared jerk (finite differences),
duration and solve time. Failures (infeasible requests) are counted and listed.

Run: ``python -m studies.constrained OUT_DIR [--quick]``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from . import lasa
from .common import write_metrics

EXPECTED_SECONDS = {"full": 25, "quick": 2}  # measured on the 2-core machine
METHODS = (
    "dmp_unconstrained",
    "dmp_constrained",
    "minimum_jerk",
    "dmp_retimed_toppra",
    "dmp_tau_scaled",
)


def _violates(trajectory, bounds, tolerance=1e-7):
    v = np.max(np.abs(trajectory.velocities) / bounds.velocity)
    a = np.max(np.abs(trajectory.accelerations) / bounds.acceleration)
    return bool(max(v, a) > 1 + tolerance), float(max(v, a))


def run(out_dir, quick: bool = False, seed: int = 0) -> dict:
    """Run the study, write figures and metrics.json into ``out_dir``, return the metrics."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from tqdm import tqdm

    from dmpopt.exceptions import DmpoptError
    from dmpopt.fitting.constrained import (
        Bounds,
        ViaPoint,
        build_fitting_problem,
        solve_fitting_problem,
    )
    from dmpopt.fitting.imitation import fit_discrete
    from dmpopt.fitting.minimum_jerk import minimum_jerk_constrained
    from dmpopt.metrics import integrated_squared_jerk, path_distance
    from dmpopt.retiming import retime, time_scaled, uniform_time_scaling

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    names = lasa.shape_names()
    if quick:
        names = list(rng.choice(names, size=4, replace=False))
    n_samples, n_basis = (250, 20) if quick else (1000, 30)
    velocity_fraction, acceleration_fraction = 0.8, 0.6

    cases, failures, examples = [], [], []
    for name in tqdm(names, desc="LASA shapes"):
        demo = lasa.demonstrations(name)[0].resampled(n_samples)
        reference = fit_discrete(demo, n_basis)
        extent = float(np.ptp(demo.positions, axis=0).max())
        goal = demo.positions[-1] + 0.1 * extent * np.array([1.0, -1.0])
        free = build_fitting_problem(demo, reference=reference, goal=goal)
        plain = free.rollout(free.dmp)
        bounds = Bounds(
            velocity=velocity_fraction * np.abs(plain.velocities).max(0),
            acceleration=acceleration_fraction * np.abs(plain.accelerations).max(0),
        )
        target = free.target
        case = {"shape": name}
        plans = {"dmp_unconstrained": (plain, 0.0)}
        try:
            problem = build_fitting_problem(demo, reference=reference, goal=goal, bounds=bounds)
            _, report = solve_fitting_problem(problem)
            plans["dmp_constrained"] = (report.trajectory, report.solve_time)
        except DmpoptError as error:
            failures.append({"shape": name, "method": "dmp_constrained", "error": str(error)})
        try:
            k = [n_samples // 4, n_samples // 2, 3 * n_samples // 4]
            vias = [ViaPoint(free.plan.times[i], target[i], tolerance=0.05 * extent) for i in k]
            trajectory, report = minimum_jerk_constrained(
                target[0], goal, demo.duration, bounds=bounds, via_points=vias, n_samples=n_samples
            )
            plans["minimum_jerk"] = (trajectory, report.solve_time)
        except DmpoptError as error:
            failures.append({"shape": name, "method": "minimum_jerk", "error": str(error)})
        try:
            begin = time.perf_counter()
            result = retime(plain, bounds.velocity, bounds.acceleration)
            plans["dmp_retimed_toppra"] = (result.trajectory, time.perf_counter() - begin)
        except DmpoptError as error:
            failures.append({"shape": name, "method": "dmp_retimed_toppra", "error": str(error)})
        begin = time.perf_counter()
        factor = uniform_time_scaling(plain, bounds.velocity, bounds.acceleration)
        plans["dmp_tau_scaled"] = (time_scaled(plain, factor), time.perf_counter() - begin)
        for method, (trajectory, seconds) in plans.items():
            violates, use = _violates(trajectory, bounds)
            case[method] = {
                "violates": violates,
                "limit_use": use,
                "shape_error": path_distance(trajectory.positions, target) / extent,
                "integrated_squared_jerk": integrated_squared_jerk(trajectory),
                "duration": trajectory.duration,
                "solve_ms": 1e3 * seconds,
            }
        cases.append(case)
        if len(examples) < 4:
            examples.append((name, target, plans))

    def collect(method, key):
        return [c[method][key] for c in cases if method in c]

    metrics = {
        "claim": "constrained DMP fits respect velocity/acceleration bounds at every sample "
        "while keeping the shape and the duration",
        "quick": quick,
        "n_shapes": len(cases),
        "n_samples": n_samples,
        "n_basis": n_basis,
        "bounds": {
            "velocity_fraction_of_unconstrained_peak": velocity_fraction,
            "acceleration_fraction_of_unconstrained_peak": acceleration_fraction,
            "goal_shift_fraction_of_extent": 0.1,
        },
        "violation_fraction": {
            m: float(np.mean(collect(m, "violates"))) if collect(m, "violates") else None
            for m in METHODS
        },
        "failure_fraction": {m: 1 - len(collect(m, "violates")) / len(cases) for m in METHODS},
        "solve_ms_median": {
            m: float(np.median(collect(m, "solve_ms"))) for m in METHODS if collect(m, "solve_ms")
        },
        "shape_error_median": {
            m: float(np.median(collect(m, "shape_error")))
            for m in METHODS
            if collect(m, "shape_error")
        },
        "integrated_squared_jerk_median": {
            m: float(np.median(collect(m, "integrated_squared_jerk")))
            for m in METHODS
            if collect(m, "integrated_squared_jerk")
        },
        "duration_median": {
            m: float(np.median(collect(m, "duration"))) for m in METHODS if collect(m, "duration")
        },
        "failures": failures,
        "cases": cases,
    }

    # figure 1: paths of a few shapes
    figure, axes = plt.subplots(1, len(examples), figsize=(4 * len(examples), 4), squeeze=False)
    for axis, (name, target, plans) in zip(axes[0], examples):
        axis.plot(target[:, 0], target[:, 1], "k--", lw=2, label="moved demo")
        for method, (trajectory, _) in plans.items():
            if method in ("dmp_retimed_toppra", "dmp_tau_scaled"):
                continue  # same path as the unconstrained DMP
            axis.plot(trajectory.positions[:, 0], trajectory.positions[:, 1], label=method)
        axis.set_title(name)
        axis.set_aspect("equal")
    axes[0][0].legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(out / "constrained_paths.png", dpi=120)
    plt.close(figure)
    # figure 2: speed profiles of the first shape
    name, target, plans = examples[0]
    figure, axis = plt.subplots(figsize=(7, 4))
    for method, (trajectory, _) in plans.items():
        axis.plot(trajectory.times, np.linalg.norm(trajectory.velocities, axis=1), label=method)
    axis.set_xlabel("time [s]")
    axis.set_ylabel("speed [mm/s]")
    axis.set_title(f"{name}: speed profiles")
    axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(out / "constrained_speed.png", dpi=120)
    plt.close(figure)
    # figure 3: violation fraction per method
    figure, axis = plt.subplots(figsize=(7, 4))
    values = [metrics["violation_fraction"][m] or 0.0 for m in METHODS]
    axis.bar(range(len(METHODS)), values)
    axis.set_xticks(range(len(METHODS)), METHODS, rotation=20, fontsize=7)
    axis.set_ylabel("fraction of shapes violating a bound")
    figure.tight_layout()
    figure.savefig(out / "constrained_violations.png", dpi=120)
    plt.close(figure)

    parameters = {
        "n_samples": n_samples,
        "n_basis": n_basis,
        "velocity_fraction": velocity_fraction,
        "acceleration_fraction": acceleration_fraction,
        "shapes": names,
    }
    return write_metrics(out, "constrained", metrics, parameters, seed, quick)


def main(argv=None) -> None:
    """Command line: ``OUT_DIR [--quick]``."""
    argv = sys.argv[1:] if argv is None else argv
    out = argv[0] if argv and not argv[0].startswith("--") else "out/constrained"
    metrics = run(out, quick="--quick" in argv)
    for key in (
        "violation_fraction",
        "failure_fraction",
        "shape_error_median",
        "integrated_squared_jerk_median",
        "duration_median",
        "solve_ms_median",
    ):
        print(key, json.dumps(metrics[key]))


if __name__ == "__main__":
    main()
