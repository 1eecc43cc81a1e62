"""Reinforcement learning of DMP weights: eNAC vs eREINFORCE and beyond (Fig. 5, Section 4.2).

Claim of the paper: on a 1-DOF acceleration DMP that must move from 0 to 1 in 500 ms
(10 basis functions, weights from zero, 20 roll-outs per update), episodic Natural
Actor-Critic learns a smooth bell-shaped velocity profile after about 150-200 trials and is
about an order of magnitude faster than episodic REINFORCE.

What this study measures (reward and policy: :mod:`dmpopt.learning.tasks`):

* learning curves of every method against trials (every exploratory roll-out counts), as the
  fraction of the achievable improvement from ``w = 0`` to the exact optimum (least squares on
  the affine plan), median and inter-quartile band over the evaluation seeds;
* trials to 95 % and 99 % of that improvement per method, median and spread, with each
  method's step size (or exploration) chosen on separate tuning seeds from a fixed grid;
* the ratio eREINFORCE / eNAC, for the paper's fixed step sizes and for KL-normalised,
  decaying steps, and its dependence on the exploration noise and the batch size;
* the velocity profile of the eNAC policy before learning, after 200 trials and at the end;
* the same methods on a 6-DOF reach and a 2-DOF via-point task.

Run: ``python -m studies.rl OUT_DIR [--quick] [--seed N]``.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np
from tqdm import tqdm

from dmpopt.exceptions import DmpoptError
from dmpopt.learning import (
    make_method,
    multi_dof_reaching_task,
    optimise,
    paper_reaching_task,
    via_point_task,
)

from .common import write_metrics

# Method variants: (method name, fixed options, name of the tuned option, grid).
# Grids of the fixed steps of eNAC scale with 1 / sigma^2 (the natural gradient scales with
# sigma^2); the vanilla gradient's expectation does not depend on sigma.
VARIANTS = {
    "enac": ("enac", {"step_rule": "constant"}, "step_size", (5.0, 10.0, 20.0, 40.0, 80.0)),
    "ereinforce": (
        "ereinforce",
        {"step_rule": "constant"},
        "step_size",
        (10.0, 20.0, 40.0, 80.0, 160.0),
    ),
    "enac_kl": (
        "enac",
        {"step_rule": "kl", "decay": 0.05},
        "step_size",
        (1.0, 3.0, 10.0, 30.0, 100.0),
    ),
    "ereinforce_kl": (
        "ereinforce",
        {"step_rule": "kl", "decay": 0.05},
        "step_size",
        (1.0, 3.0, 10.0, 30.0, 100.0),
    ),
    "pibb": ("pibb", {}, "exploration_std", (5.0, 10.0, 20.0, 40.0)),
    "cmaes": ("cmaes", {}, "exploration_std", (5.0, 10.0, 20.0, 40.0)),
    # CMA-ES with its own default population size 4 + floor(3 ln n) instead of 20 roll-outs
    "cmaes_default_population": ("cmaes", {}, "exploration_std", (5.0, 10.0, 20.0, 40.0)),
}
# variants usable on any task unchanged
SCALE_FREE = ("enac_kl", "ereinforce_kl", "pibb", "cmaes", "cmaes_default_population")
EXPLORATION_STD = 10.0  # sigma of eq. (17) [m/s^2 per 1 ms step], the default noise level
BATCH = 20
EXPECTED_SECONDS = {"full": 340, "quick": 20}  # measured on the 2-core machine


def _options(variant: str, value: float, sigma: float, batch: int, n_params: int = 10) -> dict:
    name, fixed, tuned, _ = VARIANTS[variant]
    options = dict(fixed, n_rollouts=batch)
    if name in ("enac", "ereinforce"):
        # the regression of eq. (19) needs more roll-outs than parameters + 1
        options["n_rollouts"] = max(batch, n_params + 2)
    if variant == "cmaes_default_population":
        options["n_rollouts"] = 4 + int(3 * np.log(n_params))
    if name in ("enac", "ereinforce"):
        options["exploration_std"] = sigma
    if variant == "enac":
        value = value * (EXPLORATION_STD / sigma) ** 2
    options[tuned] = value
    return options


def _run(task, variant, options, seed, n_trials):
    """One learning curve, or None if the run diverged (a too large step)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return optimise(
                make_method(VARIANTS[variant][0], task, seed=seed, **options), task, n_trials
            )
    except (DmpoptError, np.linalg.LinAlgError):
        return None


def _trials(curves, fraction):
    return np.array([c.trials_to(fraction) if c is not None else np.inf for c in curves])


def _tune(task, variant, sigma, batch, seeds, n_trials, progress):
    """Grid value with the fewest median trials to 95 % (then 99 %, then best final)."""
    best_key, best_value = None, None
    for value in VARIANTS[variant][3]:
        options = _options(variant, value, sigma, batch, task.n_dofs * task.n_basis)
        curves = [_run(task, variant, options, s, n_trials) for s in seeds]
        progress.update(len(seeds))
        final = np.median([c.improvement[-1] if c is not None else -np.inf for c in curves])
        key = (np.median(_trials(curves, 0.95)), np.median(_trials(curves, 0.99)), -final)
        if best_key is None or key < best_key:
            best_key, best_value = key, value
    return best_value


def _summary(values):
    finite = np.isfinite(values)
    quartiles = (
        np.percentile(values, [25, 75])
        if finite.all()
        else [
            float(np.percentile(values, 25)) if np.mean(finite) >= 0.25 else None,
            float(np.percentile(values, 75)) if np.mean(finite) >= 0.75 else None,
        ]
    )
    return {
        "median": float(np.median(values)) if np.mean(finite) >= 0.5 else None,
        "q25": None if quartiles[0] is None else float(quartiles[0]),
        "q75": None if quartiles[1] is None else float(quartiles[1]),
        "reached": float(np.mean(finite)),
    }


def _study_task(task, variants, sigma, batch, tuning_seeds, eval_seeds, n_trials, progress):
    """Tune each variant, then run it on the evaluation seeds."""
    results = {}
    for variant in variants:
        value = _tune(task, variant, sigma, batch, tuning_seeds, n_trials, progress)
        options = _options(variant, value, sigma, batch, task.n_dofs * task.n_basis)
        curves = [_run(task, variant, options, s, n_trials) for s in eval_seeds]
        progress.update(len(eval_seeds))
        results[variant] = {"tuned": value, "options": options, "curves": curves}
    return results


def _metrics_of(results):
    out = {}
    for variant, result in results.items():
        curves = result["curves"]
        out[variant] = {
            "tuned_value": result["tuned"],
            "trials_to_95": _summary(_trials(curves, 0.95)),
            "trials_to_99": _summary(_trials(curves, 0.99)),
            "final_improvement_median": float(
                np.median([c.improvement[-1] if c is not None else -np.inf for c in curves])
            ),
            "diverged": int(sum(c is None for c in curves)),
        }
    return out


def _ratio(metrics, numerator, denominator, key="trials_to_95"):
    a, b = metrics[numerator][key]["median"], metrics[denominator][key]["median"]
    return None if a is None or b is None else a / b


def _plot_curves(path, results, title, n_trials):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    grid = np.linspace(0, n_trials, 301)
    for variant, result in results.items():
        curves = [c for c in result["curves"] if c is not None]
        if not curves:
            continue
        values = np.stack(
            [np.interp(grid, c.trials, c.improvement, right=c.improvement[-1]) for c in curves]
        )
        median = np.median(values, axis=0)
        low, high = np.percentile(values, [25, 75], axis=0)
        line = axes[0].plot(grid, median, label=f"{variant} ({len(curves)} seeds)")[0]
        axes[0].fill_between(grid, low, high, color=line.get_color(), alpha=0.2)
        gap = np.clip(1 - values, 1e-5, None)
        axes[1].semilogy(grid, np.median(gap, axis=0), color=line.get_color(), label=variant)
        axes[1].fill_between(
            grid,
            np.percentile(gap, 25, axis=0),
            np.percentile(gap, 75, axis=0),
            color=line.get_color(),
            alpha=0.2,
        )
    axes[0].axhline(0.95, color="k", lw=0.5, ls="--")
    axes[0].set(
        xlabel="trials (roll-outs)",
        ylabel="fraction of achievable improvement",
        ylim=(-0.1, 1.05),
        title=title,
    )
    axes[1].axhline(0.05, color="k", lw=0.5, ls="--")
    axes[1].axhline(0.01, color="k", lw=0.5, ls=":")
    axes[1].set(
        xlabel="trials (roll-outs)",
        ylabel="1 - fraction (median, IQR)",
        title="distance to the exact optimum",
    )
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plot_velocity(path, task, curve, jerk_task):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    times = task.plan.times * 1000
    profiles = {"start (w = 0)": task.initial_weights, "exact optimum": task.optimal_weights}
    if curve is not None:
        profiles["eNAC, 200 trials"] = curve.weights_at(200)
        profiles[f"eNAC, {int(curve.trials[-1])} trials"] = curve.final_weights
    for label, weights in profiles.items():
        plan = task.plan.evaluate(weights)
        axes[0].plot(times, plan[1, :, 0], label=label)
        axes[1].plot(times, plan[0, :, 0], label=label)
    jerk_plan = jerk_task.plan.evaluate(jerk_task.optimal_weights)
    axes[0].plot(times, jerk_plan[1, :, 0], "k:", label="optimum with jerk cost")
    axes[1].plot(times, jerk_plan[0, :, 0], "k:", label="optimum with jerk cost")
    axes[0].set(xlabel="time [ms]", ylabel="velocity", title="velocity profile (Fig. 5)")
    axes[1].set(xlabel="time [ms]", ylabel="position")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _bell_shaped(velocity, tolerance: float = 0.01) -> bool:
    """One interior maximum: no rebound larger than ``tolerance`` of the peak on either side.

    After the peak, the velocity may not rise above its running minimum by more than the
    tolerance; before the peak, the same holds read backwards.
    """
    velocity = np.asarray(velocity)
    peak = int(np.argmax(velocity))
    if not 0 < peak < velocity.size - 1:
        return False
    after = velocity[peak:]
    before = velocity[: peak + 1][::-1]
    rebound = max(
        np.max(after - np.minimum.accumulate(after)), np.max(before - np.minimum.accumulate(before))
    )
    return bool(rebound <= tolerance * velocity[peak])


def run(out_dir, quick: bool = False, seed: int = 0) -> dict:
    """Run the study, write figures and ``metrics.json`` to ``out_dir``, return the metrics."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    n_eval, n_tune = (6, 2) if quick else (20, 5)
    n_trials = 2000 if quick else 3000
    eval_seeds = [seed + i for i in range(n_eval)]
    tuning_seeds = [seed + 10_000 + i for i in range(n_tune)]
    sigmas, batches = ((3.0, 30.0), (BATCH,)) if quick else ((3.0, 10.0, 30.0), (15, 20, 50))
    settings = [(s, b) for s in sigmas for b in batches if (s, b) != (EXPLORATION_STD, BATCH)]
    extra_seeds = eval_seeds[: max(3, n_eval // 2)]
    dependence_seeds = extra_seeds if quick else eval_seeds

    task = paper_reaching_task()
    extra_tasks = (
        {} if quick else {"six_dof": multi_dof_reaching_task(), "via_point": via_point_task()}
    )
    total = sum(len(v[3]) * n_tune + n_eval for v in VARIANTS.values())
    total += len(settings) * sum(
        len(VARIANTS[v][3]) * n_tune + len(dependence_seeds)
        for v in ("enac", "ereinforce", "enac_kl", "ereinforce_kl")
    )
    total += len(extra_tasks) * sum(
        len(VARIANTS[v][3]) * n_tune + len(extra_seeds) for v in SCALE_FREE
    )
    progress = tqdm(total=total, desc="rl study (runs)", unit="run")

    # The paper's task ------------------------------------------------------------------
    results = _study_task(
        task, VARIANTS, EXPLORATION_STD, BATCH, tuning_seeds, eval_seeds, n_trials, progress
    )
    method_metrics = _metrics_of(results)

    # Dependence of the REINFORCE / NAC ratio on noise and batch ----------------------
    dependence = []
    for sigma, batch in settings:
        pairs = ("enac", "ereinforce", "enac_kl", "ereinforce_kl")
        part = _metrics_of(
            _study_task(
                task, pairs, sigma, batch, tuning_seeds, dependence_seeds, n_trials, progress
            )
        )
        dependence.append(
            {
                "exploration_std": sigma,
                "n_rollouts": batch,
                "trials_to_95": {k: v["trials_to_95"]["median"] for k, v in part.items()},
                "trials_to_99": {k: v["trials_to_99"]["median"] for k, v in part.items()},
                "ratio_fixed_step_95": _ratio(part, "ereinforce", "enac"),
                "ratio_kl_step_95": _ratio(part, "ereinforce_kl", "enac_kl"),
                "ratio_fixed_step_99": _ratio(part, "ereinforce", "enac", "trials_to_99"),
                "ratio_kl_step_99": _ratio(part, "ereinforce_kl", "enac_kl", "trials_to_99"),
            }
        )

    # Beyond one joint ------------------------------------------------------------------
    extra_metrics = {}
    for name, extra in extra_tasks.items():
        extra_results = _study_task(
            extra, SCALE_FREE, EXPLORATION_STD, BATCH, tuning_seeds, extra_seeds, n_trials, progress
        )
        extra_metrics[name] = {
            "n_dofs": extra.n_dofs,
            "optimum_return": extra.optimum_return,
            "initial_return": extra.initial_return,
            "methods": _metrics_of(extra_results),
        }
        _plot_curves(
            out / f"rl_curves_{name}.png",
            extra_results,
            f"{name}: {extra.n_dofs} DOFs, 20 roll-outs/update",
            n_trials,
        )
    progress.close()

    # Figures and velocity profiles ---------------------------------------------------
    _plot_curves(out / "rl_curves.png", results, "Fig. 5 task: 1 DOF, 0 -> 1 in 500 ms", n_trials)
    enac_curves = [c for c in results["enac"]["curves"] if c is not None]
    typical = None
    if enac_curves:
        finals = np.array([c.improvement[-1] for c in enac_curves])
        typical = enac_curves[int(np.argsort(finals)[len(finals) // 2])]
    jerk_task = paper_reaching_task(jerk_weight=1e-5)
    _plot_velocity(out / "rl_velocity.png", task, typical, jerk_task)

    velocity_start = task.plan.evaluate(task.initial_weights)[1, :, 0]
    velocity_optimum = task.plan.evaluate(task.optimal_weights)[1, :, 0]
    velocity_200 = (
        task.plan.evaluate(typical.weights_at(200))[1, :, 0] if typical is not None else None
    )
    velocity_end = (
        task.plan.evaluate(typical.final_weights)[1, :, 0] if typical is not None else None
    )
    trials_95 = {v: m["trials_to_95"]["median"] for v, m in method_metrics.items()}
    trials_99 = {v: m["trials_to_99"]["median"] for v, m in method_metrics.items()}
    finite = {v: t for v, t in trials_95.items() if t is not None}
    metrics = {
        "figure": "Fig. 5 (Section 4.2): eNAC vs eREINFORCE on a 1-DOF acceleration DMP",
        "quick": quick,
        "seed": seed,
        "n_eval_seeds": n_eval,
        "n_tuning_seeds": n_tune,
        "trial_budget": n_trials,
        "exploration_std": EXPLORATION_STD,
        "n_rollouts": BATCH,
        "reward": (
            "R = -1000 (y(T)-g)^2 - ydot(T)^2 - 1e-3 * sum_k yddot_k^2 dt "
            "(acceleration integral over the n-1 held commands); optional jerk term"
        ),
        "optimum_return": task.optimum_return,
        "initial_return": task.initial_return,
        "trials_to_95": trials_95,
        "trials_to_99": trials_99,
        "methods": method_metrics,
        "ratio_ereinforce_over_enac_95": _ratio(method_metrics, "ereinforce", "enac"),
        "ratio_ereinforce_over_enac_99": _ratio(
            method_metrics, "ereinforce", "enac", "trials_to_99"
        ),
        "ratio_ereinforce_kl_over_enac_kl_95": _ratio(method_metrics, "ereinforce_kl", "enac_kl"),
        "ratio_ereinforce_kl_over_enac_kl_99": _ratio(
            method_metrics, "ereinforce_kl", "enac_kl", "trials_to_99"
        ),
        "best_method_95": min(finite, key=finite.get) if finite else None,
        "ratio_dependence": dependence,
        "velocity_bell_shaped": {
            "start": _bell_shaped(velocity_start),
            "enac_200_trials": None if velocity_200 is None else _bell_shaped(velocity_200),
            "enac_end": None if velocity_end is None else _bell_shaped(velocity_end),
            "optimum": _bell_shaped(velocity_optimum),
        },
        "enac_end_improvement": None if typical is None else float(typical.improvement[-1]),
        "other_tasks": extra_metrics,
    }
    metrics["wall_time_s"] = time.perf_counter() - started
    parameters = {
        "n_eval_seeds": n_eval,
        "n_tuning_seeds": n_tune,
        "trial_budget": n_trials,
        "exploration_std": EXPLORATION_STD,
        "n_rollouts": BATCH,
    }
    return write_metrics(out, "rl", metrics, parameters, seed, quick)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    metrics = run(args.out_dir, quick=args.quick, seed=args.seed)
    print(
        json.dumps(
            {
                k: metrics[k]
                for k in (
                    "optimum_return",
                    "trials_to_95",
                    "trials_to_99",
                    "ratio_ereinforce_over_enac_95",
                    "wall_time_s",
                )
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
