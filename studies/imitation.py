"""Imitation on LASA handwriting: reproduction accuracy and new goals (Section 3.4, 3.3).

Claim evaluated: a DMP learned from one demonstration reproduces it accurately, and the same
weights generate the movement towards a new goal while keeping its shape (the invariance of
Section 3.3). Every one of the 30 shapes x 7 demos is fitted with 10, 30 and 100 basis
functions; plans to goals moved by 20 % of the start-goal distance in each axis are compared
with the demonstration rotated and uniformly scaled onto the new start and goal.

Parameters (defaults): velocity form eq. (5), position-space fit, goal scaling "auto",
``dt`` of the data (about 2-3 ms, 1000 samples per demo). Plans start in the demonstrated
initial state (some LASA demos start moving); plans to new goals start with the initial
velocity rotated and scaled like the rest of the demonstration.
"""

from __future__ import annotations

import numpy as np
from tqdm import tqdm

from dmpopt import fit_discrete, reproduction_error, similarity_transform
from dmpopt.exceptions import DmpoptError

from . import lasa
from .common import median_time, output_dir, pyplot, write_metrics

EXPECTED_SECONDS = {"full": 20, "quick": 5}  # measured on the 2-core machine
N_BASIS = (10, 30, 100)
COMPARED = (  # (label, fit options) at 30 basis functions
    ("position, velocity form", {"method": "position", "form": "velocity"}),
    ("position, acceleration form", {"method": "position", "form": "acceleration"}),
    ("least squares on eq. (15)", {"method": "least_squares", "form": "velocity"}),
    ("LWR on eq. (15) (paper)", {"method": "lwr", "form": "velocity"}),
)
GOAL_SHIFT = 0.2


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def shifted_goal(demo) -> np.ndarray:
    """Goal moved by 20 % of the start-goal distance in each axis."""
    start, goal = demo.positions[0], demo.positions[-1]
    return goal + GOAL_SHIFT * np.linalg.norm(goal - start)


def rotated_and_scaled(demo, new_goal: np.ndarray) -> np.ndarray:
    """The demonstration mapped by the rotation and uniform scaling onto ``new_goal``."""
    start = demo.positions[0]
    transform = similarity_transform(demo.positions[-1] - start, new_goal - start)
    return start + (demo.positions - start) @ transform.T


def _mapped_start_velocity(demo, new_goal: np.ndarray) -> np.ndarray:
    start = demo.positions[0]
    transform = similarity_transform(demo.positions[-1] - start, new_goal - start)
    return transform @ demo.velocities[0]


def run(out_dir, quick: bool = False, seed: int = 0) -> dict:
    """Fit every LASA demo, write figures and ``metrics.json``; return the metrics."""
    out = output_dir(out_dir)
    names = lasa.shape_names()
    rng = np.random.default_rng(seed)
    if quick:
        names = sorted(rng.choice(names, size=6, replace=False).tolist())
    demos_per_shape = 2 if quick else 7

    cases = [(name, k) for name in names for k in range(demos_per_shape)]
    rmse = {n: [] for n in N_BASIS}
    compared = {label: [] for label, _ in COMPARED}
    shift_error, paper_shift_error, paper_failures = [], [], 0
    fit_seconds, rollout_seconds, nonfinite = [], [], 0
    reproductions, new_goal_plans = {}, {}
    for name, k in tqdm(cases, desc="imitation", unit="demo"):
        demo = lasa.demonstrations(name)[k]
        dt = demo.duration / (demo.n_steps - 1)
        for n_basis in N_BASIS:
            dmp = fit_discrete(demo, n_basis)
            plan = dmp.rollout(demo.duration, dt, start_velocity=demo.velocities[0])
            nonfinite += int(not np.isfinite(plan.positions).all())
            rmse[n_basis].append(_rmse(plan.positions, demo.positions))
            if n_basis == 30:
                fit_seconds.append(median_time(lambda: fit_discrete(demo, 30), repeats=3))
                rollout_seconds.append(median_time(lambda: dmp.rollout(demo.duration, dt), 3))
                reproductions[(name, k)] = plan.positions
                goal = shifted_goal(demo)
                velocity = _mapped_start_velocity(demo, goal)
                moved = dmp.with_goal(goal).rollout(demo.duration, dt, start_velocity=velocity)
                nonfinite += int(not np.isfinite(moved.positions).all())
                reference = rotated_and_scaled(demo, goal)
                shift_error.append(_rmse(moved.positions, reference))
                new_goal_plans[(name, k)] = (moved.positions, reference, None)
                try:
                    paper = fit_discrete(demo, 30, goal_scaling="paper")
                    paper_plan = (
                        paper.with_goal(goal)
                        .rollout(demo.duration, dt, start_velocity=velocity)
                        .positions
                    )
                    paper_shift_error.append(_rmse(paper_plan, reference))
                    new_goal_plans[(name, k)] = (moved.positions, reference, paper_plan)
                except DmpoptError:
                    paper_failures += 1
        for label, options in COMPARED:
            dmp = fit_discrete(demo, 30, **options)
            compared[label].append(reproduction_error(dmp, demo))

    metrics = {
        "n_demos": len(cases),
        "rmse_mm": {n: float(np.median(rmse[n])) for n in N_BASIS},
        "rmse_mm_max": {n: float(np.max(rmse[n])) for n in N_BASIS},
        "rmse_mm_by_method_30": {
            label: {"median": float(np.median(v)), "max": float(np.max(v))}
            for label, v in compared.items()
        },
        "goal_shift_error_mm": {
            "median": float(np.median(shift_error)),
            "worst": float(np.max(shift_error)),
        },
        "goal_shift_error_mm_paper_scaling": {
            "median": float(np.median(paper_shift_error)) if paper_shift_error else None,
            "worst": float(np.max(paper_shift_error)) if paper_shift_error else None,
            "fits_refused": paper_failures,
        },
        "nonfinite": nonfinite,
        "fit_ms_median": 1e3 * float(np.median(fit_seconds)),
        "rollout_ms_median": 1e3 * float(np.median(rollout_seconds)),
    }
    _figures(out, names, reproductions, new_goal_plans, rmse)
    parameters = {
        "n_basis": N_BASIS,
        "goal_shift": GOAL_SHIFT,
        "shapes": names,
        "demos_per_shape": demos_per_shape,
        "form": "velocity",
        "method": "position",
    }
    return write_metrics(out, "imitation", metrics, parameters, seed, quick)


def _figures(out, names, reproductions, new_goal_plans, rmse) -> None:
    plt = pyplot()
    columns = 6
    rows = int(np.ceil(len(names) / columns))
    fig, axes = plt.subplots(rows, columns, figsize=(2.2 * columns, 2.2 * rows))
    for ax, name in zip(np.ravel(axes), names):
        for (shape, k), positions in reproductions.items():
            if shape == name:
                demo = lasa.demonstrations(name)[k]
                ax.plot(*demo.positions.T, color="0.6", lw=2.5)
                ax.plot(*positions.T, color="C0", lw=0.8)
        ax.set_title(name, fontsize=8)
        ax.set_xticks([]), ax.set_yticks([])
        ax.set_aspect("equal", "datalim")
    for ax in np.ravel(axes)[len(names) :]:
        ax.axis("off")
    fig.suptitle("LASA: demonstrations (grey) and DMP reproductions, 30 basis functions")
    fig.tight_layout()
    fig.savefig(out / "reproductions.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 4, figsize=(12, 3.4))
    chosen = list(new_goal_plans)[:: max(1, len(new_goal_plans) // 4)][:4]
    for ax, key in zip(axes, chosen):
        demo = lasa.demonstrations(key[0])[key[1]]
        plan, reference, paper = new_goal_plans[key]
        ax.plot(*demo.positions.T, color="0.6", lw=2, label="demonstration")
        if paper is not None:
            ax.plot(*paper.T, "--", color="C3", lw=1, label="paper's per-axis scaling")
        ax.plot(*reference.T, color="C1", lw=3, alpha=0.5, label="rotated + scaled demo")
        ax.plot(*plan.T, color="C0", lw=1, label="DMP to the new goal")
        ax.plot(*plan[-1], "k*", ms=8)
        ax.set_title(key[0], fontsize=9)
        ax.set_aspect("equal", "datalim")
    axes[0].legend(fontsize=7)
    fig.suptitle("New goals: goal moved by 20 % of the start-goal distance in each axis")
    fig.tight_layout()
    fig.savefig(out / "new_goals.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.boxplot([rmse[n] for n in N_BASIS], tick_labels=[str(n) for n in N_BASIS])
    ax.set_yscale("log")
    ax.set_xlabel("basis functions per DOF")
    ax.set_ylabel("reproduction RMSE [mm]")
    ax.set_title("LASA reproduction error over all demos")
    fig.tight_layout()
    fig.savefig(out / "rmse_vs_basis.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    import sys

    print(run(sys.argv[1] if len(sys.argv) > 1 else "results/imitation"))
