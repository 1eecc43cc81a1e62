"""Constrained DMPs against minimum jerk and retiming under tight limits on LASA (beyond the paper).

Claim evaluated: fitting DMP weights as a QP under velocity and acceleration bounds (with a
shifted goal) gives plans that respect the bounds at every sample with less jerk than the
unconstrained DMP, where retiming adds jerk; and what it costs (shape, duration). This is
measured per shape against the unconstrained DMP with the same end conditions, beside the
other ways of meeting the bounds: minimum jerk under the bounds through as many
points of the moved demonstration as it can take, toppra's time-optimal retiming of the
unconstrained plan and its uniform tau scaling.

End conditions. A DMP fitted with the library's defaults ends at the goal still moving, while
minimum jerk and retiming end at rest. Both are measured, labelled:

- *rest-to-rest*: every method ends at rest; the DMPs are fitted with zero end velocity and
  acceleration (``end_velocity_tolerance=0``, ``end_acceleration_tolerance=0``); toppra and
  tau scaling time the rest-to-rest unconstrained DMP.
- *ending in motion*: the library's defaults (end velocity free), constrained DMP against
  unconstrained DMP.

Per shape and method: bound violation (largest ``|v| / v_max``, ``|a| / a_max``), shape error
(timing-free path distance to the moved demonstration, as a fraction of its extent),
integrated squared jerk (finite differences), duration, end speed, solve time, and how many
of 31 checkpoints (the moved demonstration at ``i / 32`` of the duration) the plan meets
within 5 % of the extent. Ratios against the unconstrained DMP are summarised by quantiles
over the shapes where every method of the comparison succeeds; infeasible cases are counted
and listed per method.

Run: ``python -m dmpopt_studies.constrained OUT_DIR [--quick]``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from . import lasa
from .common import Progress, command_line, pyplot, write_metrics

EXPECTED_SECONDS = {"full": 14, "quick": 3}  # CPU s (dmpopt.cli): main job, 2026-11-28, EPYC
VELOCITY_FRACTION = 0.8  # bounds: this fraction of the unconstrained plan's peak |v| per DOF
ACCELERATION_FRACTION = 0.6  # ... and of its peak |a|
GOAL_SHIFT = 0.1  # the goal moves by this fraction of the extent along (1, -1)
CHECKPOINT_TOLERANCE = 0.05  # a checkpoint is met within this fraction of the extent (box)
N_CHECKPOINTS = 31  # the moved demonstration at i / 32 of the duration, i = 1..31
COMPARISONS = {
    "rest_to_rest": (
        "dmp_unconstrained_rest",
        ("dmp_constrained_rest", "minimum_jerk", "toppra", "tau_scaled"),
    ),
    "ending_in_motion": ("dmp_unconstrained", ("dmp_constrained",)),
}
LABELS = {
    "dmp_unconstrained": "unconstrained DMP, ends moving",
    "dmp_constrained": "constrained DMP, ends moving",
    "dmp_unconstrained_rest": "unconstrained DMP, rest",
    "dmp_constrained_rest": "constrained DMP, rest",
    "minimum_jerk": "minimum jerk + via-points",
    "toppra": "toppra retiming",
    "tau_scaled": "uniform tau scaling",
}
METHODS = tuple(LABELS)
RATIO_KEYS = ("duration", "shape_error", "integrated_squared_jerk")
TIME_PRESERVING = ("dmp_unconstrained", "dmp_constrained", "dmp_unconstrained_rest")
TIME_PRESERVING += ("dmp_constrained_rest", "minimum_jerk")


def _limit_use(trajectory, bounds) -> float:
    """Largest ``|v| / v_max`` or ``|a| / a_max`` over samples and DOFs (1 is the bound)."""
    v = np.max(np.abs(trajectory.velocities) / bounds.velocity)
    a = np.max(np.abs(trajectory.accelerations) / bounds.acceleration)
    return float(max(v, a))


def _checkpoints(n_samples: int) -> list:
    """Indices of the checkpoints: the samples nearest ``i / 32`` of the duration."""
    fractions = np.arange(1, N_CHECKPOINTS + 1) / (N_CHECKPOINTS + 1)
    return [int(round(f * (n_samples - 1))) for f in fractions]


def _met(positions, target, indices, tolerance) -> int:
    """How many checkpoints ``positions`` passes within the box ``tolerance`` at their time."""
    return int(sum(np.all(np.abs(positions[i] - target[i]) <= tolerance) for i in indices))


def _dyadic_order(n: int) -> list:
    """0..n-1 (n = 2^k - 1) coarse to fine: the middle first, then the quarters, ..."""
    order, step = [], (n + 1) // 2
    while step >= 1:
        order += [i - 1 for i in range(step, n + 1, 2 * step)]
        step //= 2
    return order


def _strongest_minimum_jerk(start, goal, duration, bounds, times, target, indices, tolerance):
    """Minimum jerk under ``bounds`` through every checkpoint it can take while feasible.

    Greedy, coarse to fine (middle, quarters, eighths...): a checkpoint is kept as a box
    via-point (half-width ``tolerance``) if the QP stays feasible with it. Returns
    ``(trajectory, seconds of the whole search, n_via_points)``; raises ``InfeasibleProblem``
    if even the plain rest-to-rest movement breaks the bounds.
    """
    from dmpopt.exceptions import InfeasibleProblem
    from dmpopt.fitting.constrained import ViaPoint
    from dmpopt.fitting.minimum_jerk import minimum_jerk_constrained

    def solve(vias):
        return minimum_jerk_constrained(
            start, goal, duration, bounds=bounds, via_points=vias, n_samples=times.size
        )

    begin = time.perf_counter()
    kept = []
    best, _ = solve(kept)  # no via-point: infeasible means nothing is
    for k in _dyadic_order(len(indices)):
        i = indices[k]
        candidate = kept + [ViaPoint(times[i], target[i], tolerance=tolerance)]
        try:
            best, _ = solve(candidate)
        except InfeasibleProblem:
            continue
        kept = candidate
    return best, time.perf_counter() - begin, len(kept)


def _fit(demo, reference, goal, bounds, rest):
    """A constrained DMP fit (``bounds=None``: only the end conditions); (trajectory, seconds)."""
    from dmpopt.fitting.constrained import build_fitting_problem, solve_fitting_problem

    ends = {"end_velocity_tolerance": 0.0, "end_acceleration_tolerance": 0.0} if rest else {}
    problem = build_fitting_problem(demo, reference=reference, goal=goal, bounds=bounds, **ends)
    _, report = solve_fitting_problem(problem)
    return report.trajectory, report.solve_time


def shape_case(task: tuple) -> dict:
    """Every method on one LASA shape: ``task = (name, n_samples, n_basis)``.

    Returns ``{"shape", "extent", "bounds", "target", "metrics": {method: {...}}, "plans":
    {method: Trajectory}, "failures": [{"method", "error"}]}``.
    """
    from dmpopt.exceptions import DmpoptError
    from dmpopt.fitting.constrained import Bounds, build_fitting_problem
    from dmpopt.fitting.imitation import fit_discrete
    from dmpopt.metrics import integrated_squared_jerk, path_distance
    from dmpopt.retiming import retime, time_scaled, uniform_time_scaling

    name, n_samples, n_basis = task
    demo = lasa.demonstrations(name)[0].resampled(n_samples)
    reference = fit_discrete(demo, n_basis)
    extent = float(np.ptp(demo.positions, axis=0).max())
    goal = demo.positions[-1] + GOAL_SHIFT * extent * np.array([1.0, -1.0])
    free = build_fitting_problem(demo, reference=reference, goal=goal)
    plain = free.rollout(free.dmp)
    bounds = Bounds(
        velocity=VELOCITY_FRACTION * np.abs(plain.velocities).max(0),
        acceleration=ACCELERATION_FRACTION * np.abs(plain.accelerations).max(0),
    )
    target, times = free.target, free.plan.times
    indices = _checkpoints(times.size)
    tolerance = CHECKPOINT_TOLERANCE * extent
    plans, seconds, failures, extra = {"dmp_unconstrained": plain}, {}, [], {}
    seconds["dmp_unconstrained"] = 0.0

    def attempt(method, function):
        try:
            plans[method], seconds[method] = function()
        except DmpoptError as error:
            failures.append({"method": method, "error": str(error)})

    attempt("dmp_constrained", lambda: _fit(demo, reference, goal, bounds, rest=False))
    attempt("dmp_unconstrained_rest", lambda: _fit(demo, reference, goal, None, rest=True))
    attempt("dmp_constrained_rest", lambda: _fit(demo, reference, goal, bounds, rest=True))

    def minimum_jerk():
        trajectory, solve_seconds, n_vias = _strongest_minimum_jerk(
            target[0], goal, demo.duration, bounds, times, target, indices, tolerance
        )
        extra["minimum_jerk"] = {"n_via_points": n_vias}
        return trajectory, solve_seconds

    attempt("minimum_jerk", minimum_jerk)
    if "dmp_unconstrained_rest" in plans:  # toppra and tau scaling time the rest-to-rest plan
        rest = plans["dmp_unconstrained_rest"]

        def toppra():
            result = retime(rest, bounds.velocity, bounds.acceleration)
            return result.trajectory, result.solve_time

        def tau_scaled():
            begin = time.perf_counter()
            factor = uniform_time_scaling(rest, bounds.velocity, bounds.acceleration)
            return time_scaled(rest, factor), time.perf_counter() - begin

        attempt("toppra", toppra)
        attempt("tau_scaled", tau_scaled)
    metrics = {}
    for method, trajectory in plans.items():
        use = _limit_use(trajectory, bounds)
        metrics[method] = {
            "violates": bool(use > 1 + 1e-7),
            "limit_use": use,
            "shape_error": path_distance(trajectory.positions, target) / extent,
            "integrated_squared_jerk": integrated_squared_jerk(trajectory),
            "duration": trajectory.duration,
            "end_speed_mm_s": float(np.linalg.norm(trajectory.velocities[-1])),
            "solve_ms": 1e3 * seconds[method],
            "checkpoints_met": (
                _met(trajectory.positions, target, indices, tolerance)
                if method in TIME_PRESERVING
                else None
            ),
            **extra.get(method, {}),
        }
    return {
        "shape": name,
        "extent_mm": extent,
        "velocity_bound_mm_s": bounds.velocity,
        "acceleration_bound_mm_s2": bounds.acceleration,
        "target": target,
        "metrics": metrics,
        "plans": plans,
        "failures": failures,
    }


def quantiles(values, higher_is_better: bool = False) -> dict:
    """``median``, ``q25``, ``q75``, ``worst`` (the largest, or the smallest if higher is better)
    and the count ``n``."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return {"median": None, "q25": None, "q75": None, "worst": None, "n": 0}
    q25, median, q75 = np.quantile(values, [0.25, 0.5, 0.75])
    worst = values.min() if higher_is_better else values.max()
    return {"median": median, "q25": q25, "q75": q75, "worst": worst, "n": values.size}


def paired_comparison(cases: list, baseline: str, methods: tuple) -> dict:
    """Per-shape ratios ``method / baseline``, quantiles over the shapes where all succeed.

    ``cases`` holds ``{"shape": name, "metrics": {method: {key: value}}}``; a method missing
    from a case failed there. Every method's quantiles are over the same shapes, listed in
    ``"shapes"``; ``"feasible"`` counts each method's own successes over all shapes.
    """
    everyone = (baseline, *methods)
    common = [c for c in cases if all(m in c["metrics"] for m in everyone)]
    result = {
        "baseline": baseline,
        "shapes": [c["shape"] for c in common],
        "n_shapes": len(common),
        "n_total": len(cases),
        "feasible": {m: sum(m in c["metrics"] for c in cases) for m in everyone},
        "infeasible_shapes": {
            m: [c["shape"] for c in cases if m not in c["metrics"]] for m in everyone
        },
        "ratios": {},
        "shape_error_percent_of_extent": {},
        "end_speed_mm_s": {},
    }
    for method in methods:
        result["ratios"][method] = {
            key: quantiles(
                [c["metrics"][method][key] / c["metrics"][baseline][key] for c in common]
            )
            for key in RATIO_KEYS
        }
    for method in everyone:
        result["end_speed_mm_s"][method] = quantiles(
            [c["metrics"][method]["end_speed_mm_s"] for c in common]
        )
        result["shape_error_percent_of_extent"][method] = quantiles(
            [100 * c["metrics"][method]["shape_error"] for c in common]
        )
    return result


def head_to_head(cases: list, method: str, others: tuple) -> dict:
    """Per-shape ratios ``method / other`` over the shapes where both succeed, per other."""
    result = {}
    for other in others:
        both = [c for c in cases if method in c["metrics"] and other in c["metrics"]]
        result[other] = {
            key: quantiles([c["metrics"][method][key] / c["metrics"][other][key] for c in both])
            for key in RATIO_KEYS
        }
        result[other]["faster_than_the_method"] = sum(
            c["metrics"][other]["duration"] < c["metrics"][method]["duration"] for c in both
        )
    return result


def _per_method(cases, key, function) -> dict:
    values = {m: [c["metrics"][m][key] for c in cases if m in c["metrics"]] for m in METHODS}
    return {m: function(v) if v else None for m, v in values.items()}


def _spread(q: dict, spec: str = ".2g", unit: str = "") -> str:
    """``median (q25-q75, worst w)``, each formatted with ``spec`` (whole numbers from 100)."""

    def f(value):
        return f"{value:{'.0f' if abs(value) >= 100 else spec}}{unit}"

    return f"{f(q['median'])} (q25-q75 {f(q['q25'])}-{f(q['q75'])}, worst {f(q['worst'])})"


def _summary(metrics: dict) -> list:
    """The opening table, every number formatted from ``metrics``."""
    rest = metrics["comparisons"]["rest_to_rest"]
    motion = metrics["comparisons"]["ending_in_motion"]
    versus = metrics["constrained_dmp_versus"]
    n, total = rest["n_shapes"], metrics["n_shapes"]
    feasible, violating = metrics["feasible"], metrics["violating_shapes"]
    use = metrics["limit_use"]
    infeasible = rest["infeasible_shapes"]["dmp_constrained_rest"]

    def ratio(comparison, method, key):
        return _spread(
            comparison["ratios"][method][key], ".2f" if key == "duration" else ".2g", "x"
        )

    def median(comparison, method, key):
        return comparison["ratios"][method][key]["median"]

    jerk = {m: median(rest, m, "integrated_squared_jerk") for m in COMPARISONS["rest_to_rest"][1]}
    shape_vs_toppra = versus["toppra"]["shape_error"]["median"]
    shape_vs_mj = versus["minimum_jerk"]["shape_error"]["median"]
    duration = versus["toppra"]["duration"]
    faster = versus["toppra"]["faster_than_the_method"]
    mj = metrics["minimum_jerk_via_points"]
    met = mj["checkpoints_met_dmp_constrained_rest"]
    end = motion["end_speed_mm_s"]
    at_rest = max(q["worst"] for q in rest["end_speed_mm_s"].values())
    shape_percent = rest["shape_error_percent_of_extent"]
    return [
        {
            "claim": "integrated squared jerk / unconstrained DMP, rest-to-rest",
            "paper": "not in the paper",
            "dmpopt": f"{ratio(rest, 'dmp_constrained_rest', 'integrated_squared_jerk')}, "
            f"{n} shapes; per shape {versus['toppra']['integrated_squared_jerk']['median']:.2g}x "
            "toppra's",
            "anchor": f"toppra {ratio(rest, 'toppra', 'integrated_squared_jerk')}; minimum jerk "
            f"{ratio(rest, 'minimum_jerk', 'integrated_squared_jerk')}",
            "verdict": (
                "beyond the paper: smoother than retiming"
                if jerk["dmp_constrained_rest"] < jerk["toppra"]
                else "retiming is smoother"
            )
            + (
                "; minimum jerk smoother still"
                if jerk["minimum_jerk"] < jerk["dmp_constrained_rest"]
                else ""
            ),
        },
        {
            "claim": "integrated squared jerk / unconstrained DMP, ending in motion (defaults)",
            "paper": "not in the paper",
            "dmpopt": f"{ratio(motion, 'dmp_constrained', 'integrated_squared_jerk')}, "
            f"{motion['n_shapes']} shapes",
            "anchor": "none: minimum jerk and toppra end at rest (row above)",
            "verdict": "beyond the paper"
            if median(motion, "dmp_constrained", "integrated_squared_jerk") < 1
            else "no smoother",
        },
        {
            "claim": "the constrained DMP holds velocity and acceleration bounds at every sample",
            "paper": "not in the paper",
            "dmpopt": f"{violating['dmp_constrained_rest']} of {feasible['dmp_constrained_rest']} "
            f"rest-to-rest fits violate a bound; infeasible on {len(infeasible)} of {total} "
            f"({', '.join(infeasible) or 'none'}); the unconstrained DMP violates on "
            f"{violating['dmp_unconstrained_rest']} of {feasible['dmp_unconstrained_rest']} "
            f"(limit use {use['dmp_unconstrained']['median']:.3g} ending in motion, "
            f"{use['dmp_unconstrained_rest']['median']:.3g} median and "
            f"{use['dmp_unconstrained_rest']['worst']:.3g} worst rest-to-rest: it brakes at "
            "the end)",
            "anchor": f"toppra {violating['toppra']} of {feasible['toppra']}, minimum jerk "
            f"{violating['minimum_jerk']} of {feasible['minimum_jerk']}",
            "verdict": "beyond the paper",
        },
        {
            "claim": "shape error (path distance to the moved demonstration) / unconstrained DMP",
            "paper": "not in the paper",
            "dmpopt": f"{ratio(rest, 'dmp_constrained_rest', 'shape_error')}; "
            f"{shape_percent['dmp_constrained_rest']['median']:.2g} % of the extent median",
            "anchor": f"toppra {ratio(rest, 'toppra', 'shape_error')}, "
            f"{shape_percent['toppra']['median']:.2g} %; minimum jerk "
            f"{ratio(rest, 'minimum_jerk', 'shape_error')}, "
            f"{shape_percent['minimum_jerk']['median']:.2g} %",
            "verdict": f"trails toppra: {shape_vs_toppra:.0f}x its shape error per shape; "
            f"{shape_vs_mj:.2g}x minimum jerk's",
        },
        {
            "claim": "duration / unconstrained DMP (the DMPs keep the demonstrated duration)",
            "paper": "not in the paper",
            "dmpopt": "1x by construction",
            "anchor": f"toppra {ratio(rest, 'toppra', 'duration')}, faster on {faster} of "
            f"{duration['n']} shapes; tau scaling {ratio(rest, 'tau_scaled', 'duration')}",
            "verdict": f"toppra is faster on {faster} of {duration['n']} shapes"
            if faster
            else "toppra is never faster",
        },
        {
            "claim": "end speed with the library's defaults (end velocity free) [mm/s]",
            "paper": "not in the paper",
            "dmpopt": f"constrained {_spread(end['dmp_constrained'])}; unconstrained "
            f"{_spread(end['dmp_unconstrained'])}",
            "anchor": f"minimum jerk, toppra, tau scaling and the rest-to-rest fits: below "
            f"{at_rest:.0e} mm/s",
            "verdict": "labelled: both end conditions reported",
        },
        {
            "claim": f"checkpoints of the moved demonstration met within 5 % of the extent (of "
            f"{N_CHECKPOINTS})",
            "paper": "not in the paper",
            "dmpopt": f"constrained DMP (rest) {met['median']:.0f} median, fewest "
            f"{met['worst']:.0f}, without via-points",
            "anchor": f"minimum jerk takes {mj['n_via_points']['median']:.0f} as via-points "
            f"(median, fewest {mj['n_via_points']['worst']:.0f}), feasible on "
            f"{feasible['minimum_jerk']} of {total}",
            "verdict": "minimum jerk meets more checkpoints, strays further between them"
            if shape_vs_mj < 1
            else "minimum jerk meets more checkpoints and keeps the shape better",
        },
    ]


def _figures(out: Path, examples: list, cases: list, metrics: dict) -> dict:
    plt = pyplot()
    colours = dict(zip(METHODS, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    # paths of a few shapes; toppra and tau scaling follow the rest-to-rest DMP's path
    shown = ("dmp_unconstrained", "dmp_constrained", "dmp_unconstrained_rest")
    shown += ("dmp_constrained_rest", "minimum_jerk")
    figure, axes = plt.subplots(1, len(examples), figsize=(3.2 * len(examples), 3.6))
    axes = np.atleast_1d(axes)
    for axis, case in zip(axes, examples):
        target = case["target"]
        axis.plot(target[:, 0], target[:, 1], "k--", lw=2, label="moved demonstration")
        for method in shown:
            if method in case["plans"]:
                p = case["plans"][method].positions
                label = LABELS[method]
                if method == "dmp_unconstrained_rest":
                    label += " (= toppra, tau-scaled path)"
                axis.plot(p[:, 0], p[:, 1], color=colours[method], lw=1.2, label=label)
        axis.set_title(case["shape"], fontsize=9)
        axis.set_xlabel("x [mm]")
        axis.set_aspect("equal", adjustable="datalim")
    axes[0].set_ylabel("y [mm]")
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncol=3, fontsize=7, frameon=False)
    figure.tight_layout(rect=(0, 0.14, 1, 1))
    figure.savefig(out / "constrained_paths.png", dpi=110)
    plt.close(figure)
    # speed profiles of the first example
    case = examples[0]
    figure, axis = plt.subplots(figsize=(7, 3.6))
    for method, trajectory in case["plans"].items():
        speed = np.linalg.norm(trajectory.velocities, axis=1)
        axis.plot(trajectory.times, speed, color=colours[method], label=LABELS[method])
    axis.set_xlabel("time [s]")
    axis.set_ylabel("speed [mm/s]")
    axis.set_title(f"{case['shape']}: speed profiles")
    axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(out / "constrained_speed.png", dpi=110)
    plt.close(figure)
    _violations_figure(plt, out, cases, colours)
    _ratios_figure(plt, out, metrics, colours)
    return _captions(metrics, examples)


def _violations_figure(plt, out: Path, cases: list, colours: dict) -> None:
    """Limit use of every shape and method; infeasible cases as crosses above the plot."""
    figure, axis = plt.subplots(figsize=(8, 3.8))
    rng = np.random.default_rng(0)  # horizontal jitter only
    top = max(c["metrics"][m]["limit_use"] for c in cases for m in c["metrics"]) * 1.15
    for i, method in enumerate(METHODS):
        uses = [c["metrics"][method]["limit_use"] for c in cases if method in c["metrics"]]
        jitter = i + rng.uniform(-0.2, 0.2, len(uses))
        axis.scatter(jitter, uses, s=14, color=colours[method], alpha=0.8)
        failed = len(cases) - len(uses)
        if failed:
            axis.scatter(
                i + rng.uniform(-0.2, 0.2, failed), [top] * failed, marker="x", color="red", s=30
            )
        axis.annotate(
            f"{failed} infeasible",
            (i, top),
            xytext=(0, 8),
            textcoords="offset points",
            ha="center",
            fontsize=7,
            color="red" if failed else "grey",
        )
    axis.axhline(1.0, color="k", lw=1, ls="--", label="bound")
    axis.scatter([], [], marker="x", color="red", label="infeasible (no plan)")
    axis.set_ylim(0, top * 1.12)
    axis.set_xticks(range(len(METHODS)), [LABELS[m] for m in METHODS], rotation=25, ha="right")
    axis.tick_params(axis="x", labelsize=7)
    axis.set_ylabel("limit use: max |v|/v_max, |a|/a_max")
    axis.legend(fontsize=7, loc="center right")
    figure.tight_layout()
    figure.savefig(out / "constrained_violations.png", dpi=110)
    plt.close(figure)


def _ratios_figure(plt, out: Path, metrics: dict, colours: dict) -> None:
    """Per-shape ratios against the unconstrained DMP, rest-to-rest, over the common shapes."""
    rest = metrics["comparisons"]["rest_to_rest"]
    methods = COMPARISONS["rest_to_rest"][1]
    titles = {
        "integrated_squared_jerk": "integrated squared jerk",
        "shape_error": "shape error",
        "duration": "duration",
    }
    figure, axes = plt.subplots(1, 3, figsize=(9.5, 3.6))
    for axis, key in zip(axes, titles):
        axis.set_yscale("linear" if key == "duration" else "log")
        for i, method in enumerate(methods):
            values = rest["per_shape"][method][key]
            axis.scatter(
                i + np.linspace(-0.15, 0.15, len(values)), values, s=10, color=colours[method]
            )
            axis.hlines(np.median(values), i - 0.3, i + 0.3, color="k", lw=2)
        axis.axhline(1.0, color="grey", lw=1, ls=":")
        axis.set_title(titles[key], fontsize=9)
        axis.set_xticks(range(len(methods)), [LABELS[m] for m in methods], rotation=30, ha="right")
        axis.tick_params(axis="x", labelsize=7)
    axes[0].set_ylabel("ratio to the unconstrained DMP [-]")
    axes[0].plot([], [], color="k", lw=2, label="median over shapes")
    axes[0].plot([], [], color="grey", lw=1, ls=":", label="unconstrained DMP (1x)")
    figure.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=2, fontsize=7)
    figure.tight_layout(rect=(0, 0.07, 1, 1))
    figure.savefig(out / "constrained_ratios.png", dpi=110)
    plt.close(figure)


def _captions(metrics: dict, examples: list) -> dict:
    rest = metrics["comparisons"]["rest_to_rest"]
    versus = metrics["constrained_dmp_versus"]
    return {
        "constrained_paths": "Paths of "
        + ", ".join(c["shape"] for c in examples)
        + " with the goal moved (dashed: the moved demonstration): the constrained DMPs cut the "
        "corners they cannot take within the bounds; toppra and tau scaling keep the "
        "unconstrained path exactly; minimum jerk strays between its via-points.",
        "constrained_speed": f"Speed of every plan on {examples[0]['shape']}: the DMP defaults "
        "end moving, the others at rest; the unconstrained rest-to-rest DMP brakes hard at the "
        "end, toppra rides the bounds, tau scaling is uniformly slow.",
        "constrained_violations": "Limit use of every shape (dot) and method; above 1 the plan "
        "breaks a bound; red crosses (counted above) are shapes where the method found no plan.",
        "constrained_ratios": f"Per-shape ratios to the unconstrained rest-to-rest DMP on the "
        f"{rest['n_shapes']} shapes where every method succeeds (bar: median): the constrained "
        f"DMP has {versus['toppra']['integrated_squared_jerk']['median']:.2g}x toppra's jerk "
        f"and {versus['toppra']['shape_error']['median']:.2g}x its shape error (medians per "
        "shape); durations change only with retiming.",
    }


def run(out_dir, quick: bool = False, seed: int = 0, runner=None) -> dict:
    """Run the study, write figures and metrics.json into ``out_dir``, return the metrics."""
    from dmpopt.exceptions import InvalidInputError
    from dmpopt.parallel import Runner, map_runs
    from dmpopt.validation import integer

    seed = integer("seed", seed, minimum=0)
    if runner is not None and not isinstance(runner, Runner):
        raise InvalidInputError(
            f"runner must be a dmpopt.parallel.Runner or None, got {type(runner).__name__}; "
            "pass Runner(workers=2) for two processes"
        )
    runner = runner or Runner()
    progress = Progress("constrained")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    names = lasa.shape_names()
    if quick:
        names = sorted(rng.choice(names, size=4, replace=False).tolist())
    n_samples, n_basis = (250, 20) if quick else (1000, 30)
    tasks = [(name, n_samples, n_basis) for name in names]
    progress(f"{len(tasks)} shapes")
    cases = map_runs(shape_case, tasks, runner, label="shapes")  # one pool: no idle core
    progress("paired statistics and figures")
    comparisons = {}
    for variant, (baseline, methods) in COMPARISONS.items():
        comparison = paired_comparison(cases, baseline, methods)
        common = [c for c in cases if c["shape"] in comparison["shapes"]]
        comparison["per_shape"] = {
            m: {
                k: [c["metrics"][m][k] / c["metrics"][baseline][k] for c in common]
                for k in RATIO_KEYS
            }
            for m in methods
        }
        comparisons[variant] = comparison
    with_mj = [c for c in cases if "minimum_jerk" in c["metrics"]]
    others = ("toppra", "minimum_jerk", "tau_scaled")
    metrics = {
        "claim": "constrained DMP fits hold velocity/acceleration bounds at every sample; "
        "per shape, against the unconstrained DMP, they lower jerk where retiming raises it",
        "quick": quick,
        "n_shapes": len(cases),
        "n_samples": n_samples,
        "n_basis": n_basis,
        "bounds": {
            "velocity_fraction_of_unconstrained_peak": VELOCITY_FRACTION,
            "acceleration_fraction_of_unconstrained_peak": ACCELERATION_FRACTION,
            "goal_shift_fraction_of_extent": GOAL_SHIFT,
        },
        "labels": LABELS,
        "comparisons": comparisons,
        "constrained_dmp_versus": head_to_head(cases, "dmp_constrained_rest", others),
        "feasible": {m: sum(m in c["metrics"] for c in cases) for m in METHODS},
        "violating_shapes": _per_method(cases, "violates", lambda v: int(np.sum(v))),
        "limit_use": _per_method(cases, "limit_use", quantiles),
        "solve_ms_median": _per_method(cases, "solve_ms", lambda v: float(np.median(v))),
        "minimum_jerk_via_points": {
            "n_checkpoints": N_CHECKPOINTS,
            "tolerance_fraction_of_extent": CHECKPOINT_TOLERANCE,
            "n_via_points": quantiles(
                [c["metrics"]["minimum_jerk"]["n_via_points"] for c in with_mj], True
            ),
            **{
                f"checkpoints_met_{m}": quantiles(
                    [c["metrics"][m]["checkpoints_met"] for c in cases if m in c["metrics"]], True
                )
                for m in TIME_PRESERVING
            },
        },
        "failures": [dict(shape=c["shape"], **f) for c in cases for f in c["failures"]],
        "cases": [
            {k: c[k] for k in ("shape", "extent_mm", "velocity_bound_mm_s", "metrics")}
            | {"acceleration_bound_mm_s2": c["acceleration_bound_mm_s2"]}
            for c in cases
        ],
        "parallel": runner.record(),
    }
    metrics["summary"] = _summary(metrics)
    examples = [c for c in cases if len(c["plans"]) == len(METHODS)][:4] or cases[:4]
    metrics["captions"] = _figures(out, examples, cases, metrics)
    progress("done")
    parameters = {
        "n_samples": n_samples,
        "n_basis": n_basis,
        "velocity_fraction": VELOCITY_FRACTION,
        "acceleration_fraction": ACCELERATION_FRACTION,
        "shapes": names,
    }
    return write_metrics(out, "constrained", metrics, parameters, seed, quick)


def main(argv=None) -> None:
    metrics = command_line(run, __doc__, argv)
    for row in metrics["summary"]:
        print(" | ".join(row[k] for k in ("claim", "paper", "dmpopt", "anchor", "verdict")))
    print("feasible", json.dumps(metrics["feasible"]))


if __name__ == "__main__":
    main()
