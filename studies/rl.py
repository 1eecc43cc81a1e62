"""Reinforcement learning of DMP weights: eNAC vs eREINFORCE and beyond (Fig. 5, Section 4.2).

Claim of the paper: on a 1-DOF acceleration DMP that must move from 0 to 1 in 500 ms
(10 basis functions, weights from zero), episodic Natural Actor-Critic reaches smooth
bell-shaped velocity profiles after about 150-200 trials and is "about one order of
magnitude" faster than episodic REINFORCE.

What this study measures (reward and policy: :mod:`dmpopt.learning.rewards`):

* learning curves of every method against trials (every exploratory roll-out counts), as the
  remaining gap to the exact optimum (least squares on the affine plan) on a log scale,
  median and quartiles over the evaluation seeds; trials to 99 % and 95 % of the achievable
  improvement per method, each method's step (or exploration) tuned on separate seeds;
* the natural gradient's invariance to the scaling of the basis: the policy's feature columns
  are rescaled (same plans, same returns, another parametrisation) so that the Fisher matrix
  has condition numbers from about 12 to 10^4, including the classic layout's ~2170; eNAC's
  trials stay where they are, eREINFORCE's grow (``ratio_vs_conditioning``). eREINFORCE is
  tuned anew at each scaling; eNAC runs with the step tuned on the unscaled task (invariance
  means the same step gives the same plans; re-tuning it picked the same step at all five
  condition numbers and cost ~250 runs, see :func:`_conditioning_sweep`);
* the eREINFORCE / eNAC ratio against the paper's ~10x, with the paper's fixed steps and with
  KL-normalised decaying steps, and how it moves with the exploration noise and batch size;
* whether the learned velocity profile is bell-shaped by a check that ``w = 0`` fails;
* the same methods on a 6-DOF reach and a 2-DOF via-point task.

Run: ``python -m dmpopt_studies.rl OUT_DIR [--quick] [--seed N] [--workers N]``.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from dmpopt.exceptions import DmpoptError
from dmpopt.learning import (
    Exploration,
    make_method,
    multi_dof_reaching_task,
    optimise,
    paper_reaching_task,
    via_point_task,
)
from dmpopt.parallel import Runner, map_runs

from .common import Progress, pyplot, write_metrics

# Method variants: (method name, fixed options, name of the tuned option, grid). A tuned
# value at an edge of its grid is pushed one grid ratio further, up to MAX_EXTENSIONS times;
# one still at the edge is reported as a bound. Grids of the fixed steps of eNAC scale with
# 1 / sigma^2 (the natural gradient scales with sigma^2); the vanilla gradient's does not.
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
        (3.0, 10.0, 30.0, 100.0, 300.0),
    ),
    "pibb": ("pibb", {}, "exploration_std", (5.0, 10.0, 20.0, 40.0)),
    "cmaes": ("cmaes", {}, "exploration_std", (5.0, 10.0, 20.0, 40.0)),
    # CMA-ES with its own default population size 4 + floor(3 ln n) instead of 20 roll-outs
    "cmaes_default_population": ("cmaes", {}, "exploration_std", (5.0, 10.0, 20.0, 40.0)),
}
LABELS = {
    "enac": "eNAC",
    "ereinforce": "eREINFORCE",
    "enac_kl": "eNAC, KL step",
    "ereinforce_kl": "eREINFORCE, KL step",
    "pibb": "PI-BB",
    "cmaes": "CMA-ES",
    "cmaes_default_population": "CMA-ES, own population",
}
MAX_EXTENSIONS = 3
# variants usable on any task unchanged
SCALE_FREE = ("enac_kl", "ereinforce_kl", "pibb", "cmaes", "cmaes_default_population")
GRADIENT_VARIANTS = ("enac", "ereinforce", "enac_kl", "ereinforce_kl")
EXPLORATION_STD = 10.0  # sigma of eq. (17) [acceleration units, per 1 ms step]
BATCH = 20
PAPER_RATIO = 10.0  # "about one order of magnitude faster performance" (Section 4.2)
# Condition number of the Fisher matrix with the classic dcp.m basis layout (centres equally
# spaced in time on a first-order canonical system), measured when issue 17 was filed; the
# default layout of dmpopt.basis gives 111 (measured in every run).
CLASSIC_LAYOUT_CONDITION = 2170.0
CONDITIONING_TARGETS = ("equilibrated", 500.0, CLASSIC_LAYOUT_CONDITION, 10_000.0)
# A bell-shaped velocity profile of a reach: one interior peak, no rebound or reversal above
# 1 % of the peak speed, at rest at the end (5 % of the peak) and arrived (1 % of the distance).
BELL_LIMITS = {"rebound": 0.01, "reversal": 0.01, "end_speed": 0.05, "goal_error": 0.01}
# CPU seconds (user + sys of dmpopt.cli), measured on the shared 2-core machine with a warm
# numba cache: quick 17.5 s in series, full 194 s with the default 2 workers (1,765 runs, load
# 1.4-3.8); the first run after a change to dmpopt.learning compiles its kernels (~40 CPU-s)
EXPECTED_SECONDS = {"full": 66, "quick": 26}  # CPU s (dmpopt.cli): main job, 2026-11-28, EPYC


class ScaledTask:
    """A reward task whose policy features are the task's columns times ``scale``.

    Weights ``v`` of this task are the weights ``scale * v`` of the original one: the plans,
    returns and optimum are the same, only the parametrisation of the policy changes. The
    Fisher matrix becomes ``D F D`` with ``D = diag(scale)``; the natural gradient is invariant
    to this change, the vanilla gradient is not.
    """

    def __init__(self, task, scale):
        self.task = task
        self.scale = np.asarray(scale, dtype=float)
        self.n_dofs, self.n_basis = task.n_dofs, task.n_basis
        self.policy_features = task.policy_features * self.scale
        self.initial_weights = task.initial_weights / self.scale
        self.initial_return = task.initial_return
        self.optimum_return = task.optimum_return

    def evaluate(self, exploration) -> np.ndarray:
        """Per-step rewards of the roll-outs asked for (weights in this parametrisation)."""
        weights = np.asarray(exploration.weights) * self.scale
        return self.task.evaluate(Exploration(weights, exploration.acceleration_noise))

    def returns(self, weights) -> np.ndarray:
        """Returns of noise-free plans with ``weights`` in this parametrisation."""
        return self.task.returns(np.asarray(weights) * self.scale)

    def reward_arrays(self) -> tuple:
        """The task's compiled-reward arrays with the weight rows ``G D`` (scaled rows)."""
        arrays = list(self.task.reward_arrays())
        for index in (1, 3):  # weight rows of the accelerations and positions, (n_basis, ...)
            arrays[index] = arrays[index] * self.scale[:, None]
        arrays[5] = arrays[5] * self.scale  # weight row of the final velocity, (n_basis,)
        return tuple(arrays)


@lru_cache(maxsize=4)
def _base_task(name: str):
    makers = {
        "paper": paper_reaching_task,
        "six_dof": multi_dof_reaching_task,
        "via_point": via_point_task,
    }
    return makers[name]()


@lru_cache(maxsize=16)
def _task(key):
    """Task by key: ``(name, None)`` or ``(name, scale)`` with ``scale`` a tuple."""
    name, scale = key
    task = _base_task(name)
    return task if scale is None else ScaledTask(task, scale)


def fisher_condition(features) -> float:
    """Condition number of the policy's Fisher matrix ``Phi^T Phi / sigma^2`` (any sigma)."""
    features = np.asarray(features)
    return float(np.linalg.cond(features.T @ features))


def column_scaling(features, condition: float) -> tuple[float, ...]:
    """Scale ``exp(-l u_i)``, ``u_i = i / (n - 1)``, giving the Fisher ``condition`` number.

    The geometric ramp shrinks the later basis functions (``l >= 0``); ``condition`` must
    not be below the unscaled features' one.
    """
    gram = np.asarray(features).T @ np.asarray(features)
    ramp = np.linspace(0.0, 1.0, gram.shape[0])

    def excess(length):
        scale = np.exp(-length * ramp)
        return np.log(np.linalg.cond(scale[:, None] * gram * scale)) - np.log(condition)

    length = 0.0 if excess(0.0) >= 0 else brentq(excess, 0.0, 20.0, xtol=1e-10)
    return tuple(float(s) for s in np.exp(-length * ramp))


def equilibrated_scaling(features) -> tuple[float, ...]:
    """Scale making every feature column as long as the longest (Jacobi scaling)."""
    norms = np.linalg.norm(np.asarray(features), axis=0)
    return tuple(float(s) for s in norms.max() / norms)


def _options(variant: str, value: float, sigma: float, batch: int, n_params: int) -> dict:
    name, fixed, tuned, _ = VARIANTS[variant]
    options = dict(fixed, n_rollouts=batch)
    if name in ("enac", "ereinforce"):
        # the regression of eq. (19) needs more roll-outs than parameters + 1
        options["n_rollouts"] = max(batch, n_params + 2)
        options["exploration_std"] = sigma
    if variant == "cmaes_default_population":
        options["n_rollouts"] = 4 + int(3 * np.log(n_params))
    if variant == "enac":
        value = value * (EXPLORATION_STD / sigma) ** 2
    options[tuned] = float(value)
    return options


def learn(job):
    """One learning curve for ``(task key, variant, options, seed, n_trials)``.

    None if the run diverged (a too large step). Module-level for :func:`map_runs`.
    """
    key, variant, options, seed, n_trials = job
    task = _task(key)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            method = make_method(VARIANTS[variant][0], task, seed=seed, **options)
            return optimise(method, task, n_trials)
    except (DmpoptError, np.linalg.LinAlgError):
        return None


def _trials(curves, fraction):
    return np.array([c.trials_to(fraction) if c is not None else np.inf for c in curves])


def _final(curves) -> float:
    return float(np.median([c.improvement[-1] if c is not None else -np.inf for c in curves]))


def _tuning_key(curves):
    """Fewest median trials to 99 %, then to 95 %, then the best final improvement."""
    return (np.median(_trials(curves, 0.99)), np.median(_trials(curves, 0.95)), -_final(curves))


def _grid(variant: str, key) -> list[float]:
    """Grid of ``variant`` on task ``key``: the vanilla fixed step follows the scaling.

    The vanilla gradient moves the original weights by ``D^2 g``: its grid is multiplied by
    ``lambda_max(F) / lambda_max(D F D)`` so that it starts near the stable steps.
    """
    grid = np.array(VARIANTS[variant][3])
    name, scale = key
    if variant == "ereinforce" and scale is not None:
        features = _base_task(name).policy_features
        gram = features.T @ features
        scaled = np.asarray(scale)[:, None] * gram * np.asarray(scale)
        grid = grid * np.linalg.eigvalsh(gram)[-1] / np.linalg.eigvalsh(scaled)[-1]
    return [float(v) for v in grid]


def _study_task(key, variants, sigma, batch, seeds, n_trials, runner, progress, fixed=None):
    """Tune each variant on the tuning seeds, then run it on the evaluation seeds.

    ``seeds`` is ``(tuning_seeds, eval_seeds)``. All runs of a stage go through one
    :func:`map_runs` call. ``fixed`` maps variants to ``(value, edge)`` tuned elsewhere: they
    run on the evaluation seeds only, with that value.
    """
    tuning_seeds, eval_seeds = seeds
    fixed = fixed or {}
    n_params = _task(key).n_dofs * _task(key).n_basis
    tried = {v: {} for v in variants if v not in fixed}
    pending = {v: _grid(v, key) for v in tried}
    for round_ in range(MAX_EXTENSIONS + 1):
        jobs = [(v, x, s) for v, values in pending.items() for x in values for s in tuning_seeds]
        progress(f"{key[0]}: tuning round {round_ + 1}, {len(jobs)} runs")
        curves = map_runs(
            learn,
            [
                (key, v, _options(v, value, sigma, batch, n_params), s, n_trials)
                for v, value, s in jobs
            ],
            runner,
        )
        for (v, value, _), curve in zip(jobs, curves):
            tried[v].setdefault(value, []).append(curve)
        pending = {}
        for v in tried:
            best, edge = _best(tried[v])
            values = sorted(tried[v])
            if edge and round_ < MAX_EXTENSIONS:
                ratio = values[1] / values[0] if edge == "lower" else values[-1] / values[-2]
                pending[v] = [best / ratio if edge == "lower" else best * ratio]
        if not pending:
            break
    results = {}
    jobs = []
    for v in variants:
        best, edge = fixed[v] if v in fixed else _best(tried[v])
        options = _options(v, best, sigma, batch, n_params)
        results[v] = {
            "tuned": best,
            "edge": edge,
            "tried": [best] if v in fixed else sorted(tried[v]),
            "options": options,
        }
        jobs += [(v, (key, v, options, s, n_trials)) for s in eval_seeds]
    progress(f"{key[0]}: {len(jobs)} evaluation runs")
    curves = map_runs(learn, [job for _, job in jobs], runner)
    for v in variants:
        results[v]["curves"] = [c for (name, _), c in zip(jobs, curves) if name == v]
    return results


def _best(tried: dict) -> tuple[float, str | None]:
    """Best tried value and the grid edge it sits on (``"lower"``, ``"upper"`` or None)."""
    values = sorted(tried)
    best = min(values, key=lambda value: _tuning_key(tried[value]))
    edge = "lower" if best == values[0] else "upper" if best == values[-1] else None
    return best, edge


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
        "median": float(np.median(values)) if np.isfinite(np.median(values)) else None,
        "q25": None if quartiles[0] is None else float(quartiles[0]),
        "q75": None if quartiles[1] is None else float(quartiles[1]),
        "reached": float(np.mean(finite)),
    }


def _metrics_of(results):
    out = {}
    for variant, result in results.items():
        curves = result["curves"]
        out[variant] = {
            "tuned_value": result["tuned"],
            "tuned_option": VARIANTS[variant][2],
            # a value still at the grid's edge after the extensions is only a bound
            "tuned_at_edge": result["edge"],
            "tried_values": result["tried"],
            "n_rollouts": result["options"]["n_rollouts"],
            "trials_to_99": _summary(_trials(curves, 0.99)),
            "trials_to_95": _summary(_trials(curves, 0.95)),
            "final_improvement_median": _final(curves),
            "diverged": int(sum(c is None for c in curves)),
        }
    return out


def _ratio(metrics, numerator, denominator, key, budget):
    """Median trials of ``numerator`` over ``denominator``, and whether it is a lower bound.

    A numerator that did not reach the fraction within the budget on most seeds gives the
    bound ``budget / denominator``.
    """
    a, b = metrics[numerator][key]["median"], metrics[denominator][key]["median"]
    if b is None:
        return None, False
    if a is None:
        return budget / b, True
    return a / b, False


def bell_check(velocity, position, start: float, goal: float) -> dict:
    """Whether a 1-DOF reach has a bell-shaped velocity profile, with the measured margins.

    Passes when the speed has one interior peak with no rebound (after the peak, no rise
    above the running minimum; before it, the same read backwards) and no reversal larger
    than ``BELL_LIMITS`` of the peak speed, ends at rest (final speed within 5 % of the peak)
    and arrives (final position within 1 % of ``|goal - start|``). The unforced plan
    (``w = 0``) ends still moving and short of the goal, so it fails.
    """
    velocity, position = np.asarray(velocity, float), np.asarray(position, float)
    peak = int(np.argmax(velocity))
    speed = float(velocity[peak])
    if not (0 < peak < velocity.size - 1 and speed > 0):
        return {"passed": False, "peak_index": peak}
    after, before = velocity[peak:], velocity[: peak + 1][::-1]
    rebound = max(
        np.max(after - np.minimum.accumulate(after)), np.max(before - np.minimum.accumulate(before))
    )
    measured = {
        "rebound": float(rebound) / speed,
        "reversal": max(0.0, -float(np.min(velocity))) / speed,
        "end_speed": abs(float(velocity[-1])) / speed,
        "goal_error": abs(float(position[-1]) - goal) / abs(goal - start),
    }
    passed = all(measured[name] <= limit for name, limit in BELL_LIMITS.items())
    return {"passed": bool(passed), "peak_index": peak, **measured}


def _bell_of(task, weights) -> dict:
    plan = task.plan.evaluate(weights)
    return bell_check(plan[1, :, 0], plan[0, :, 0], float(task.dmp.start[0]), task.dmp.goal[0])


def _legend_label(variant, metrics):
    m = metrics[variant]
    return f"{LABELS[variant]} ({m['n_rollouts']} roll-outs/update)"


def _plot_curves(path, results, metrics, title, n_trials):
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    grid = np.linspace(0, n_trials, 301)
    for variant, result in results.items():
        curves = [c for c in result["curves"] if c is not None]
        if not curves:
            continue
        values = np.stack(
            [np.interp(grid, c.trials, c.improvement, right=c.improvement[-1]) for c in curves]
        )
        gap = np.clip(1 - values, 1e-5, None)
        label = _legend_label(variant, metrics)
        line = axes[0].semilogy(grid, np.median(gap, axis=0), label=label)[0]
        low, high = np.percentile(gap, [25, 75], axis=0)
        axes[0].fill_between(grid, low, high, color=line.get_color(), alpha=0.15)
        axes[1].plot(grid, np.median(values, axis=0), color=line.get_color())
        low, high = np.percentile(values, [25, 75], axis=0)
        axes[1].fill_between(grid, low, high, color=line.get_color(), alpha=0.15)
    axes[0].axhline(0.05, color="k", lw=0.6, ls="--")
    axes[0].axhline(0.01, color="k", lw=0.6, ls=":")
    axes[0].set(
        xlabel="trials (exploratory roll-outs)",
        ylabel="remaining gap to the optimum (1 - fraction)",
        ylim=(1e-4, 2),
        title="gap, log scale (-- 95 %, : 99 %)",
    )
    axes[1].axhline(0.95, color="k", lw=0.6, ls="--")
    axes[1].axhline(0.99, color="k", lw=0.6, ls=":")
    axes[1].set(
        xlabel="trials (exploratory roll-outs)",
        ylabel="fraction of the achievable improvement",
        ylim=(-0.1, 1.05),
        title="fraction, linear scale",
    )
    axes[1].legend(*axes[0].get_legend_handles_labels(), fontsize=7, loc="lower right")
    n_seeds = max(len(result["curves"]) for result in results.values())
    fig.suptitle(f"{title}: median and quartiles over {n_seeds} seeds", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _plot_conditioning(path, sweep, budget):
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    conditions = np.array([point["condition_number"] for point in sweep])
    styles = {"enac": ("C0", "o"), "ereinforce": ("C1", "s")}
    styles.update({"enac_kl": ("C2", "^"), "ereinforce_kl": ("C3", "v")})
    for variant, (colour, marker) in styles.items():
        if variant not in sweep[0]["trials_to_95"]:
            continue
        trials = np.array([point["trials_to_95"][variant] or np.nan for point in sweep])
        axes[0].loglog(conditions, trials, color=colour, marker=marker, label=LABELS[variant])
        missed = np.isnan(trials)
        if missed.any():
            axes[0].scatter(
                conditions[missed],
                np.full(missed.sum(), budget),
                color=colour,
                marker=marker,
                facecolors="none",
                s=60,
            )
    axes[0].axhline(budget, color="k", lw=0.6, ls=":")
    axes[0].set(
        xlabel="condition number of the Fisher matrix",
        ylabel="trials to 95 % (median)",
        title=f"open markers: not reached in {budget} trials",
    )
    for suffix, colour, label in (("", "C1", "fixed steps"), ("_kl", "C3", "KL steps")):
        ratios = [point.get(f"ratio{suffix}_95") for point in sweep]
        if all(r is None for r in ratios):
            continue
        values = np.array([np.nan if r is None else r for r in ratios])
        bounds = np.array([point.get(f"ratio{suffix}_95_is_lower_bound", False) for point in sweep])
        axes[1].loglog(conditions, values, color=colour, marker="o", label=label)
        if bounds.any():
            axes[1].scatter(
                conditions[bounds],
                values[bounds],
                color=colour,
                marker="^",
                s=70,
                label=f"{label}: lower bound",
            )
    axes[1].axhline(PAPER_RATIO, color="k", lw=0.8, ls="--", label="paper: about 10x")
    axes[1].axhline(1.0, color="0.5", lw=0.6)
    axes[1].set(
        xlabel="condition number of the Fisher matrix",
        ylabel="eREINFORCE / eNAC trials to 95 %",
        title="ratio against the conditioning",
    )
    for axis in axes:
        for value, text in (
            (sweep_default(sweep), "default"),
            (CLASSIC_LAYOUT_CONDITION, "classic"),
        ):
            axis.axvline(value, color="0.6", lw=0.6, ls="-.")
            axis.text(
                value,
                0.02,
                text,
                transform=axis.get_xaxis_transform(),
                fontsize=7,
                ha="center",
                va="bottom",
                rotation=90,
                backgroundcolor="w",
            )
    axes[0].legend(fontsize=7, loc="upper left")
    axes[1].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def sweep_default(sweep) -> float:
    """Condition number of the default (unscaled) layout in a sweep."""
    return next(p["condition_number"] for p in sweep if p["scaling"] == "none")


def _plot_velocity(path, task, profiles, jerk_task):
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    times = task.plan.times * 1000
    for label, weights in profiles.items():
        plan = task.plan.evaluate(weights)
        axes[0].plot(times, plan[1, :, 0], label=label)
        axes[1].plot(times, plan[0, :, 0], label=label)
    jerk_plan = jerk_task.plan.evaluate(jerk_task.optimal_weights)
    axes[0].plot(times, jerk_plan[1, :, 0], "k:", label="exact optimum with a jerk cost")
    axes[1].plot(times, jerk_plan[0, :, 0], "k:")
    axes[0].set(xlabel="time [ms]", ylabel="velocity [goal distances/s]", title="velocity")
    axes[1].axhline(1.0, color="0.6", lw=0.6)
    axes[1].set(xlabel="time [ms]", ylabel="position [goal distances]", title="position")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _point(scaling: str, condition: float, metrics: dict, budget: int) -> dict:
    """One conditioning of the sweep: medians per variant and the ratios."""
    pairs = {"": ("ereinforce", "enac"), "_kl": ("ereinforce_kl", "enac_kl")}
    point = {
        "scaling": scaling,
        "condition_number": condition,
        "trials_to_99": {v: m["trials_to_99"]["median"] for v, m in metrics.items()},
        "trials_to_95": {v: m["trials_to_95"]["median"] for v, m in metrics.items()},
        "tuned_value": {v: m["tuned_value"] for v, m in metrics.items()},
        "tuned_at_edge": {v: m["tuned_at_edge"] for v, m in metrics.items()},
    }
    for suffix, (numerator, denominator) in pairs.items():
        if numerator not in metrics:
            continue
        for fraction in ("99", "95"):
            key = f"trials_to_{fraction}"
            value, bound = _ratio(metrics, numerator, denominator, key, budget)
            point[f"ratio{suffix}_{fraction}"] = value
            point[f"ratio{suffix}_{fraction}_is_lower_bound"] = bound
    return point


def _conditioning_sweep(native_metrics, variants, targets, seeds, n_trials, runner, progress):
    """The paper task with rescaled feature columns, sorted by the Fisher condition number.

    ``targets``: Fisher condition numbers of the geometric ramps, and ``"equilibrated"`` for
    columns of equal length. The unscaled point reuses the main runs (same seeds, same grids).

    The vanilla-gradient variants are tuned anew at each scaling (their best step moves with
    it). The natural-gradient ones run on the evaluation seeds with the step tuned on the
    unscaled task: the natural gradient is invariant to the scaling, so the same step gives
    the same plans up to rounding (``test_natural_gradient_is_invariant_to_the_feature_
    scaling``), and re-tuning them picked the same step at every scaling (main job
    2026-11-27: 80 and 10 at all five condition numbers, 330 and 140 trials to 95 %) for
    about 250 runs. What is measured is the invariance itself: the same step, other
    parametrisations, the same trials.
    """
    features = _base_task("paper").policy_features
    scalings = [
        ("equilibrated columns", equilibrated_scaling(features))
        if target == "equilibrated"
        else (f"geometric ramp, target {target:g}", column_scaling(features, target))
        for target in targets
    ]
    native = {v: native_metrics[v] for v in variants}
    points = [_point("none", fisher_condition(features), native, n_trials)]
    fixed = {
        v: (native[v]["tuned_value"], native[v]["tuned_at_edge"])
        for v in variants
        if VARIANTS[v][0] == "enac"
    }
    for label, scale in scalings:
        progress(f"conditioning: {label}")
        results = _study_task(
            ("paper", scale),
            variants,
            EXPLORATION_STD,
            BATCH,
            seeds,
            n_trials,
            runner,
            progress,
            fixed,
        )
        point = _point(label, fisher_condition(features * scale), _metrics_of(results), n_trials)
        point["column_scale"] = list(scale)
        points.append(point)
    return sorted(points, key=lambda point: point["condition_number"])


def _dependence(settings, seeds, n_trials, runner, progress):
    """The four gradient variants, tuned anew, at other noise levels and batch sizes."""
    out = []
    for sigma, batch in settings:
        progress(f"ratio dependence: sigma {sigma:g}, {batch} roll-outs/update")
        metrics = _metrics_of(
            _study_task(
                ("paper", None), GRADIENT_VARIANTS, sigma, batch, seeds, n_trials, runner, progress
            )
        )
        point = _point("none", 0.0, metrics, n_trials)
        del point["scaling"], point["condition_number"]
        out.append({"exploration_std": sigma, "n_rollouts": batch, **point})
    return out


def _typical(curves):
    """The curve with the median final improvement (None if all diverged)."""
    curves = [c for c in curves if c is not None]
    if not curves:
        return None
    finals = np.array([c.improvement[-1] for c in curves])
    return curves[int(np.argsort(finals)[len(finals) // 2])]


def _velocity_profiles(task, typical):
    profiles = {"start (w = 0)": task.initial_weights}
    if typical is not None:
        profiles["eNAC after 200 trials"] = typical.weights_at(200)
        profiles[f"eNAC after {int(typical.trials[-1])} trials"] = typical.final_weights
    profiles["exact optimum"] = task.optimal_weights
    return profiles


def _trials_text(summary: dict, budget: int) -> str:
    if summary["median"] is None:
        return f"> {budget} ({summary['reached']:.0%} of seeds reached it)"
    if summary["q25"] is None or summary["q75"] is None:
        return f"{summary['median']:.0f}"
    return f"{summary['median']:.0f} (quartiles {summary['q25']:.0f}-{summary['q75']:.0f})"


def _ratio_text(value, bound) -> str:
    if value is None:
        return "n/a"
    return f"{'>= ' if bound else ''}{value:.1f}x"


def _point_ratio(point, key: str = "ratio_95") -> str:
    return _ratio_text(point[key], point[f"{key}_is_lower_bound"])


def _edge_text(metrics) -> str:
    edges = [
        f"{LABELS[v]} {m['tuned_option']} {'>=' if m['tuned_at_edge'] == 'upper' else '<='} "
        f"{m['tuned_value']:g}"
        for v, m in metrics.items()
        if m["tuned_at_edge"]
    ]
    return "; ".join(edges)


def _summary_rows(metrics: dict) -> list[dict]:
    """The opening table, every number formatted from ``metrics``."""
    budget = metrics["trial_budget"]
    methods, ratios = metrics["methods"], metrics["ratio_ereinforce_over_enac"]
    others = {v: methods[v]["trials_to_99"]["median"] for v in ("pibb", "cmaes")}
    others = {v: t for v, t in others.items() if t is not None}
    anchor = (
        ", ".join(f"{LABELS[v]} {t:.0f}" for v, t in sorted(others.items(), key=lambda i: i[1]))
        + " trials to 99 %"
        if others
        else "none reached 99 %"
    )
    enac95 = methods["enac"]["trials_to_95"]["median"]
    kl95 = methods["enac_kl"]["trials_to_95"]["median"]
    rows = [
        {
            "claim": "eNAC learns the 1-DOF reach (Fig. 5): trials to 99 % of the achievable "
            "improvement",
            "paper": "converges smoothly; good profiles after about 150-200 trials",
            "dmpopt": f"eNAC {_trials_text(methods['enac']['trials_to_99'], budget)} to 99 %, "
            f"{_trials_text(methods['enac']['trials_to_95'], budget)} to 95 %; with KL steps "
            f"{_trials_text(methods['enac_kl']['trials_to_99'], budget)} and "
            f"{_trials_text(methods['enac_kl']['trials_to_95'], budget)}; median of "
            f"{metrics['n_eval_seeds']} seeds",
            "anchor": anchor,
            "verdict": "reproduced (95 % within 200 trials)"
            if enac95 is not None and enac95 <= 200
            else "reproduced with KL steps (95 % within 200 trials); fixed steps tuned for 99 % "
            "are slower to 95 %"
            if kl95 is not None and kl95 <= 200
            else "trails the paper: 95 % takes more than 200 trials",
        }
    ]
    ratio99 = _ratio_text(ratios["fixed_step_99"], ratios["fixed_step_99_is_lower_bound"])
    ratio95 = _ratio_text(ratios["fixed_step_95"], ratios["fixed_step_95_is_lower_bound"])
    kl99 = _ratio_text(ratios["kl_step_99"], ratios["kl_step_99_is_lower_bound"])
    kl95 = _ratio_text(ratios["kl_step_95"], ratios["kl_step_95_is_lower_bound"])
    native = next(p for p in metrics["ratio_vs_conditioning"] if p["scaling"] == "none")
    best = max(
        (ratios["fixed_step_99"] or 0.0, ratios["fixed_step_95"] or 0.0, ratios["kl_step_99"] or 0)
    )
    rows.append(
        {
            "claim": "eNAC is about 10x faster than eREINFORCE (same policy, same roll-outs)",
            "paper": f"about {PAPER_RATIO:.0f}x",
            "dmpopt": f"{ratio99} to 99 %, {ratio95} to 95 % (fixed steps); {kl99} to 99 %, "
            f"{kl95} to 95 % (KL steps); eREINFORCE "
            f"{_trials_text(methods['ereinforce']['trials_to_99'], budget)} to 99 %",
            "anchor": "none measured",
            "verdict": "reproduced"
            if best >= 0.5 * PAPER_RATIO
            else f"trails the paper: the default basis is well conditioned (Fisher condition "
            f"number {native['condition_number']:.0f}), see the next row",
        }
    )
    sweep = metrics["ratio_vs_conditioning"]
    enac = [p["trials_to_95"]["enac"] for p in sweep]
    classic = min(
        sweep, key=lambda p: abs(np.log(p["condition_number"] / CLASSIC_LAYOUT_CONDITION))
    )
    worst = sweep[-1]
    flat = all(t is not None for t in enac) and max(enac) <= 1.1 * min(enac)
    rows.append(
        {
            "claim": "the natural gradient is invariant to the scaling of the basis "
            "(rescaled feature columns, same plans)",
            "paper": "the natural gradient follows the Riemannian structure (Section 3.5); "
            "not measured",
            "dmpopt": f"eNAC {min(enac):.0f}-{max(enac):.0f} trials to 95 % for condition "
            f"numbers {sweep[0]['condition_number']:.0f}-{worst['condition_number']:.0f}; "
            f"eREINFORCE / eNAC {_point_ratio(native)} at {native['condition_number']:.0f} "
            f"(default), {_point_ratio(classic)} at {classic['condition_number']:.0f} "
            f"(classic layout), {_point_ratio(worst)} at {worst['condition_number']:.0f}"
            + (
                f"; with KL steps {_point_ratio(native, 'ratio_kl_95')}, "
                f"{_point_ratio(classic, 'ratio_kl_95')}, {_point_ratio(worst, 'ratio_kl_95')}"
                if "ratio_kl_95" in native
                else ""
            )
            if all(t is not None for t in enac)
            else "eNAC did not reach 95 % at every conditioning",
            "anchor": "eREINFORCE (vanilla gradient) on the same scalings",
            "verdict": "beyond the paper: invariance measured, eNAC flat"
            if flat
            else "not reproduced: eNAC's trials move with the scaling",
        }
    )
    bell = metrics["velocity_bell_shaped"]
    start = bell["start"]
    rows.append(
        {
            "claim": "smooth bell-shaped velocity profile (peak, at rest, arrived)",
            "paper": "after about 150-200 trials",
            "dmpopt": f"eNAC after 200 trials: {_passed(bell['enac_200_trials'])}; at the end: "
            f"{_passed(bell['enac_end'])}; w = 0 fails (ends at "
            f"{start.get('end_speed', 0):.0%} of its peak speed, "
            f"{start.get('goal_error', 0):.0%} short)",
            "anchor": f"exact optimum: {_passed(bell['optimum'])}",
            "verdict": "reproduced"
            if bell["enac_200_trials"] and bell["enac_200_trials"]["passed"]
            else "reproduced later than the paper"
            if bell["enac_end"] and bell["enac_end"]["passed"]
            else "not reproduced",
        }
    )
    for name, task in metrics["other_tasks"].items():
        rows.append(
            {
                "claim": f"{name.replace('_', ' ')} task ({task['n_dofs']} DOFs): trials to "
                "95 % / 99 %",
                "paper": "not in the paper",
                "dmpopt": _other_task_text(task["methods"], budget),
                "anchor": "none measured",
                "verdict": "beyond the paper",
            }
        )
    edges = _edge_text(methods)
    if edges:
        rows.append(
            {
                "claim": "tuned values inside their grids",
                "paper": "not in the paper",
                "dmpopt": f"at the edge after {MAX_EXTENSIONS} extensions (bounds): {edges}",
                "anchor": "none measured",
                "verdict": "bound only",
            }
        )
    return rows


def _other_task_text(methods: dict, budget: int) -> str:
    """The three methods fastest to 95 %: "CMA-ES 240 / > 3000"."""

    def text(value):
        return f"> {budget}" if value is None else f"{value:.0f}"

    def order(variant):
        summary = methods[variant]["trials_to_95"]
        return np.inf if summary["median"] is None else summary["median"]

    fastest = sorted(methods, key=order)[:3]
    return ", ".join(
        f"{LABELS[v]} {text(methods[v]['trials_to_95']['median'])} / "
        f"{text(methods[v]['trials_to_99']['median'])}"
        for v in fastest
    )


def _passed(check) -> str:
    return "n/a" if check is None else "passes" if check["passed"] else "fails"


def _captions(metrics: dict) -> dict:
    methods = metrics["methods"]
    rollouts = ", ".join(f"{LABELS[v]} {m['n_rollouts']}" for v, m in methods.items())
    captions = {
        "rl_curves": "Left: the remaining gap to the exact optimum on a log scale, where the "
        "methods separate (dashed 95 %, dotted 99 %); right: the same curves as the fraction of "
        f"the achievable improvement. Steps tuned for the fewest trials to 99 % on separate "
        f"seeds. Roll-outs per update: {rollouts}.",
        "rl_conditioning": "The same task with the policy's feature columns rescaled: eNAC's "
        "trials stay flat (the natural gradient is invariant), eREINFORCE's grow with the "
        "Fisher condition number; right, their ratio against the paper's ~10x.",
        "rl_velocity": "Velocity and position of the eNAC policy (median seed) before learning, "
        "after 200 trials and at the end, against the exact optimum; w = 0 is bell-like but "
        "ends moving and short of the goal.",
    }
    for name, task in metrics["other_tasks"].items():
        rollouts = ", ".join(f"{LABELS[v]} {m['n_rollouts']}" for v, m in task["methods"].items())
        captions[f"rl_curves_{name}"] = (
            f"{name.replace('_', ' ')} task, {task['n_dofs']} DOFs: gap to the exact optimum "
            f"(log) and fraction of the improvement. Roll-outs per update: {rollouts}."
        )
    return captions


def run(out_dir, quick: bool = False, seed: int = 0, runner: Runner | None = None) -> dict:
    """Run the study, write figures and ``metrics.json`` to ``out_dir``, return the metrics.

    ``runner`` (:class:`dmpopt.parallel.Runner`) decides where the independent runs go; the
    results do not depend on it.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    runner = runner or Runner()
    progress = Progress("rl")
    started = time.perf_counter()
    n_eval, n_tune = (6, 2) if quick else (20, 5)
    n_trials = 2000 if quick else 3000
    eval_seeds = [seed + i for i in range(n_eval)]
    tuning_seeds = [seed + 10_000 + i for i in range(n_tune)]
    seeds = (tuning_seeds, eval_seeds)
    settings = () if quick else ((3.0, BATCH), (30.0, BATCH), (EXPLORATION_STD, 15), (10.0, 50))
    sweep_variants = ("enac", "ereinforce") if quick else GRADIENT_VARIANTS
    targets = CONDITIONING_TARGETS[2:] if quick else CONDITIONING_TARGETS
    # secondary parts: half the evaluation seeds (and 3 tuning seeds on the bigger tasks)
    half = (tuning_seeds, eval_seeds[: n_eval // 2])
    extra_seeds = (tuning_seeds[:3], eval_seeds[: n_eval // 2])
    extra_tasks = () if quick else ("six_dof", "via_point")

    # The paper's task ------------------------------------------------------------------
    task = _base_task("paper")
    results = _study_task(
        ("paper", None), VARIANTS, EXPLORATION_STD, BATCH, seeds, n_trials, runner, progress
    )
    method_metrics = _metrics_of(results)
    sweep = _conditioning_sweep(
        method_metrics, sweep_variants, targets, seeds, n_trials, runner, progress
    )
    dependence = _dependence(settings, half, n_trials, runner, progress)

    # Beyond one joint ------------------------------------------------------------------
    extra_metrics, extra_results = {}, {}
    for name in extra_tasks:
        extra = _base_task(name)
        extra_results[name] = _study_task(
            (name, None),
            SCALE_FREE,
            EXPLORATION_STD,
            BATCH,
            extra_seeds,
            n_trials,
            runner,
            progress,
        )
        extra_metrics[name] = {
            "n_dofs": extra.n_dofs,
            "optimum_return": extra.optimum_return,
            "initial_return": extra.initial_return,
            "methods": _metrics_of(extra_results[name]),
        }

    # Velocity profiles ---------------------------------------------------------------------
    typical = _typical(results["enac"]["curves"])
    profiles = _velocity_profiles(task, typical)
    checks = {label: _bell_of(task, weights) for label, weights in profiles.items()}
    main_ratios = _point("none", 0.0, method_metrics, n_trials)
    metrics = {
        "figure": "Fig. 5 (Section 4.2): eNAC vs eREINFORCE on a 1-DOF acceleration DMP",
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
        "trials_to_99": {v: m["trials_to_99"]["median"] for v, m in method_metrics.items()},
        "trials_to_95": {v: m["trials_to_95"]["median"] for v, m in method_metrics.items()},
        "methods": method_metrics,
        "ratio_ereinforce_over_enac": {
            "paper": PAPER_RATIO,
            "paper_text": "about one order of magnitude (Section 4.2, Fig. 5)",
            **{
                key.replace("ratio_kl", "kl_step").replace("ratio", "fixed_step"): value
                for key, value in main_ratios.items()
                if key.startswith("ratio")
            },
        },
        "ratio_vs_conditioning": sweep,
        "classic_layout_condition": CLASSIC_LAYOUT_CONDITION,
        "ratio_dependence": dependence,
        "velocity_bell_limits": BELL_LIMITS,
        "velocity_bell_shaped": {
            "start": checks["start (w = 0)"],
            "enac_200_trials": checks.get("eNAC after 200 trials"),
            "enac_end": None if typical is None else checks[list(profiles)[2]],
            "optimum": checks["exact optimum"],
        },
        "enac_end_improvement": None if typical is None else float(typical.improvement[-1]),
        "other_tasks": extra_metrics,
    }
    metrics["summary"] = _summary_rows(metrics)
    metrics["captions"] = _captions(metrics)

    progress("figures")
    title = "Fig. 5 task, 1 DOF, 0 -> 1 in 500 ms"
    _plot_curves(out / "rl_curves.png", results, method_metrics, title, n_trials)
    for name, extra_result in extra_results.items():
        title = f"{name.replace('_', ' ')} task, {extra_metrics[name]['n_dofs']} DOFs"
        _plot_curves(
            out / f"rl_curves_{name}.png",
            extra_result,
            extra_metrics[name]["methods"],
            title,
            n_trials,
        )
    _plot_conditioning(out / "rl_conditioning.png", sweep, n_trials)
    _plot_velocity(out / "rl_velocity.png", task, profiles, paper_reaching_task(jerk_weight=1e-5))
    metrics["parallel"] = runner.record()
    metrics["wall_time_s"] = time.perf_counter() - started
    parameters = {
        "n_eval_seeds": n_eval,
        "n_tuning_seeds": n_tune,
        "trial_budget": n_trials,
        "exploration_std": EXPLORATION_STD,
        "n_rollouts": BATCH,
        "conditioning_targets": targets,
        "max_grid_extensions": MAX_EXTENSIONS,
    }
    return write_metrics(out, "rl", metrics, parameters, seed, quick)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=1, help="local processes (default 1)")
    args = parser.parse_args()
    if args.workers < 1:
        parser.error(f"--workers must be >= 1 (1 runs in series), got {args.workers}")
    metrics = run(args.out_dir, quick=args.quick, seed=args.seed, runner=Runner(args.workers))
    keys = ("trials_to_99", "trials_to_95", "ratio_ereinforce_over_enac", "wall_time_s")
    print(json.dumps({k: metrics[k] for k in keys}, indent=2))
    for point in metrics["ratio_vs_conditioning"]:
        print(
            f"condition {point['condition_number']:8.0f}: trials to 95 % "
            f"{point['trials_to_95']}, ratio {point['ratio_95']}"
        )


if __name__ == "__main__":
    main()
