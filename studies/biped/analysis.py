"""What the walks are judged by: cost of transport, survival, Wilson intervals, sweeps."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dmpopt.exceptions import InvalidInputError
from dmpopt.parallel import map_runs

from .walker import FALL_HEIGHT, Disturbance, WalkLog, n_moving_bodies, walk

WILSON_Z = 1.959963984540054  # two-sided 95 % normal quantile
SETTLED_STRIKES = 20  # heel strikes that define the converged frequency (their median)


def converged_frequency(frequencies, window: int = SETTLED_STRIKES) -> float:
    """Median of the last ``window`` frequencies of a walk [rad/s]."""
    return float(np.median(np.asarray(frequencies, dtype=float)[-window:]))


def steps_to_within(
    frequencies, tolerance: float = 0.02, window: int = SETTLED_STRIKES
) -> int | str:
    """Heel strikes until the frequency stays within ``tolerance`` of its converged value.

    The converged value is the median of the last ``window`` strikes. When the frequency
    has not stayed inside for the whole last ``window`` strikes, the walk was too short to
    see it settle: the result is the bound ``"at least N"`` (a string, N the strike after
    its last one outside), not a number.
    """
    frequencies = np.asarray(frequencies, dtype=float)
    inside = np.abs(frequencies / converged_frequency(frequencies, window) - 1.0) <= tolerance
    outside = np.flatnonzero(~inside)
    settled = 0 if outside.size == 0 else int(outside[-1] + 1)
    if settled > frequencies.size - window:
        return f"at least {settled}"
    return settled


def cost_of_transport(log: WalkLog, mass: float, gravity: float = 9.81) -> float | None:
    """Mechanical cost of transport, positive actuator work / (m g |distance|) [-]."""
    if log.distance == 0.0:
        return None
    return log.positive_work / (mass * gravity * abs(log.distance))


def wilson_interval(successes: int, n: int, z: float = WILSON_Z) -> tuple[float, float]:
    r"""Wilson score interval of a binomial proportion (95 % by default).

    .. math:: \frac{\hat p + z^2/2n \pm z\sqrt{\hat p(1-\hat p)/n + z^2/4n^2}}{1 + z^2/n}
    """
    if not (isinstance(n, (int, np.integer)) and n >= 1 and 0 <= successes <= n):
        raise InvalidInputError(f"need 0 <= successes <= n and n >= 1, got {successes}/{n}")
    p = successes / n
    centre = p + z**2 / (2 * n)
    half = z * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2))
    scale = 1 + z**2 / n
    low = 0.0 if successes == 0 else (centre - half) / scale  # exact ends, not 1e-17
    high = 1.0 if successes == n else (centre + half) / scale
    return low, high


@dataclass(frozen=True)
class Survival:
    """The rule a walk must meet after its push to count as survived.

    In the last ``window`` seconds of the walk (which ends ``after`` seconds after the push):
    no fall, at least ``min_strikes`` heel strikes alternating between the legs, a mean
    forward speed in ``[min_speed, max_speed]`` [m/s] and the torso at least
    ``min_height`` [m] above the ground throughout.
    """

    after: float = 2.5
    window: float = 1.5
    min_strikes: int = 2
    min_speed: float = 0.05
    max_speed: float = 1.5
    min_height: float = FALL_HEIGHT + 0.1

    def survived(self, log: WalkLog) -> bool:
        """Whether ``log`` (sampled with its ``times`` and ``q``) meets the rule."""
        if log.fell or not log.times:
            return False
        end = log.times[-1]
        strikes = [leg for t, leg, _ in log.strikes if t >= end - self.window]
        if len(strikes) < self.min_strikes or any(a == b for a, b in zip(strikes, strikes[1:])):
            return False
        times = np.asarray(log.times)
        late = times >= end - self.window
        q = np.asarray(log.q)[late]
        speed = (q[-1, 0] - q[0, 0]) / (times[late][-1] - times[late][0])
        return bool(self.min_speed <= speed <= self.max_speed and q[:, 1].min() >= self.min_height)


SURVIVAL = Survival()
ARMS = {  # (reset_phase, adapt)
    "reset_and_adapt": (True, True),
    "adapt_only": (False, True),
    "reset_only": (True, False),
    "neither": (False, False),
}
"""The arms of the ablation, phase resetting on and off with the adaptation on and off. Each
walks with the same controller, whose contacts switch on the simulator's heel strikes
(:class:`~dmpopt_studies.biped.walker.QPControl`) in every arm. ``reset_and_adapt``: at each heel
strike the oscillator's phase is reset, eq. (21) first line, and its frequency adapted, eq.
(21) second line. ``adapt_only`` switches off the phase reset (the oscillator keeps its own
phase, its frequency still adapts to the measured steps). ``reset_only`` switches off the
adaptation (the frequency stays where it is). ``neither`` switches off both; nothing else
differs. In the study's trials every arm first walks the same warm-up with both on
(:class:`TrialRanges`), since an arm without resetting cannot start walking on its own. The
phase-resetting ablation compares the arms in pairs with the adaptation in the same state
(:data:`RESET_PAIRS`)."""
RESET_PAIRS = {  # adaptation state -> (arm with resetting, arm without)
    "adaptation_on": ("reset_and_adapt", "adapt_only"),
    "adaptation_off": ("reset_only", "neither"),
}


@dataclass(frozen=True)
class TrialRanges:
    """Ranges of the randomised disturbances (uniform draws) and the trials' warm-up.

    Every arm walks its first ``warmup`` seconds with phase resetting and adaptation on (the
    walker's start-up, the same in every arm, ``walk(warmup=...)``); the arm's own switches
    apply from then on, and the slope and the push come after the warm-up.
    """

    warmup: float = 2.0  # [s] about 8 heel strikes from 12 rad/s
    push_impulse: tuple = (0.0, 4.0)  # [N s] forward, on the torso
    push_time: tuple = (2.5, 3.5)  # [s] (about four steps: a random phase of the gait)
    mass_scale: tuple = (0.9, 1.1)  # factor on each body's mass and inertia
    slope_deg: tuple = (-3.0, 3.0)  # [deg] ground slope from slope_time, positive uphill
    slope_time: tuple = (2.0, 3.0)  # [s]

    def __post_init__(self):
        for name in ("push_time", "slope_time"):
            low, high = getattr(self, name)
            if not self.warmup <= low <= high:
                raise InvalidInputError(
                    f"{name} must be a range (low, high) starting at or after warmup = "
                    f"{self.warmup:g} s, got {(low, high)}; move it after the warm-up"
                )


def random_disturbances(biped, n: int, seed: int, ranges: TrialRanges) -> list[Disturbance]:
    """``n`` seeded draws of push, masses and slope (the same set for every arm)."""
    rng = np.random.default_rng(seed)
    n_bodies = n_moving_bodies(biped)
    return [
        Disturbance(
            push_impulse=float(rng.uniform(*ranges.push_impulse)),
            push_time=float(rng.uniform(*ranges.push_time)),
            mass_scale=tuple(rng.uniform(*ranges.mass_scale, n_bodies).tolist()),
            slope_deg=float(rng.uniform(*ranges.slope_deg)),
            slope_time=float(rng.uniform(*ranges.slope_time)),
        )
        for _ in range(n)
    ]


def survived(job: tuple) -> list[tuple[bool, int, int, float, float]]:
    """One randomised trial in every arm, an independent run of :func:`survival_by_arm`: for
    each arm (order of :data:`ARMS`) whether the walker survived, its QP hold answers, its
    ticks over 5 ms, its slowest tick [us] and its process CPU time [s]. The arms walk the
    same warm-up, simulated once (``walk(arms=...)``)."""
    rule, walk_options = job
    return [
        (rule.survived(log), log.holds, log.ticks_over_budget, log.tick_us_max, log.cpu_time)
        for log in walk(**walk_options)
    ]


def trial_jobs(
    biped, dmp, frequency, disturbances, controller="qp", rule=SURVIVAL, **walk_on
) -> list[tuple]:
    """The randomised trials of :func:`survival_by_arm`, one per disturbance, each the input
    of one independent run of :func:`survived` (every arm of :data:`ARMS`)."""
    return [
        (
            rule,
            dict(
                biped=biped,
                dmp=dmp,
                duration=disturbance.push_time + rule.after,
                frequency=frequency,
                arms=tuple(ARMS.values()),
                controller=controller,
                disturbance=disturbance,
                seed=k,
                **walk_on,
            ),
        )
        for k, disturbance in enumerate(disturbances)
    ]


def survival_from_runs(runs: list, n_trials: int) -> dict:
    """Survival rate of each arm with its Wilson CI from the results of :func:`survived` on
    :func:`trial_jobs` (``n_trials`` of them, each with every arm)."""
    if len(runs) != n_trials:
        raise InvalidInputError(f"expected {n_trials} trials' results, got {len(runs)}")
    results = {}
    for i, name in enumerate(ARMS):
        arm = [trial[i] for trial in runs]
        outcomes = [run[0] for run in arm]
        n, count = len(outcomes), int(sum(outcomes))
        low, high = wilson_interval(count, n)
        results[name] = {
            "rate": count / n,
            "ci95_wilson": [low, high],
            "survived": count,
            "n": n,
            "outcomes": outcomes,
            "qp_holds": int(sum(run[1] for run in arm)),
            "ticks_over_budget": int(sum(run[2] for run in arm)),
            "tick_us_max": float(max(run[3] for run in arm)),
            "cpu_s": float(sum(run[4] for run in arm)),
        }
    return results


def survival_by_arm(
    biped,
    dmp,
    frequency,
    disturbances,
    controller="qp",
    rule=SURVIVAL,
    progress=None,
    runner=None,
    **walk_on,
) -> dict:
    """Survival rate of each arm of :data:`ARMS` over ``disturbances`` with its Wilson CI.

    Every (arm, trial) walk is an independent run, executed where ``runner`` says
    (:mod:`dmpopt.parallel`; default: in series). A trial at the edge of a fall can end
    differently in another process: proxsuite is not bitwise reproducible across processes.
    """
    jobs = trial_jobs(biped, dmp, frequency, disturbances, controller, rule, **walk_on)
    if progress:
        progress(f"{len(ARMS) * len(jobs)} randomised trials ({len(ARMS)} arms x {len(jobs)})")
    runs = map_runs(survived, jobs, runner, label="biped trials")
    return survival_from_runs(runs, len(disturbances))


def reset_ablation(survival: dict) -> dict:
    """Phase resetting on against off over the same trials, per adaptation state.

    For each pair of :data:`RESET_PAIRS`: both rates, their difference, the trials survived
    only with resetting and only without, and the exact two-sided McNemar p-value of those
    discordant counts (a binomial test at 1/2).
    """
    from scipy.stats import binomtest

    results = {}
    for state, (with_reset, without) in RESET_PAIRS.items():
        pairs = list(zip(survival[with_reset]["outcomes"], survival[without]["outcomes"]))
        only_with = sum(a and not b for a, b in pairs)
        only_without = sum(b and not a for a, b in pairs)
        discordant = only_with + only_without
        results[state] = {
            "with_reset": with_reset,
            "without_reset": without,
            "rate_with_reset": survival[with_reset]["rate"],
            "rate_without_reset": survival[without]["rate"],
            "difference": survival[with_reset]["rate"] - survival[without]["rate"],
            "survived_only_with_reset": only_with,
            "survived_only_without_reset": only_without,
            "n": len(pairs),
            "mcnemar_p": binomtest(only_with, discordant).pvalue if discordant else 1.0,
            "effect": interval_effect(
                survival[with_reset]["ci95_wilson"], survival[without]["ci95_wilson"]
            ),
        }
    return results


def interval_effect(with_reset, without_reset) -> str:
    """What two survival intervals say about resetting: ``"raises survival"`` when the
    interval with resetting lies wholly above the one without, ``"lowers survival"`` when
    wholly below, else ``"not resolved"`` (they overlap)."""
    if with_reset[0] > without_reset[1]:
        return "raises survival"
    if with_reset[1] < without_reset[0]:
        return "lowers survival"
    return "not resolved"


def reset_verdict(ablation: dict, walks_undisturbed: dict) -> str:
    """One sentence on phase resetting's effect on robustness, from the Wilson intervals.

    ``ablation``: :func:`reset_ablation`'s result; ``walks_undisturbed``: arm -> whether it
    walked undisturbed in every undisturbed walk. With an arm that does not walk undisturbed
    the comparison is undecided (it would measure whether the walker walks at all).
    """
    failing = [arm for arm, walked in walks_undisturbed.items() if not walked]
    if failing:
        return (
            "undecided: " + ", ".join(failing) + " does not walk undisturbed, so survival "
            "would measure whether it walks at all"
        )
    parts = [
        f"adaptation {state.split('_')[1]}: {row['rate_with_reset']:.0%} survive with resetting, "
        f"{row['rate_without_reset']:.0%} without (n = {row['n']}), {row['effect']}"
        for state, row in ablation.items()
    ]
    effects = {row["effect"] for row in ablation.values()}
    outcome = effects.pop() if len(effects) == 1 else "mixed"
    return f"{outcome}: " + "; ".join(parts) + " (95 % Wilson intervals, overlap = not resolved)"


def sweep_minimum(rows: list[dict], flat: float = 0.05) -> dict:
    """The cheapest frequency of a sweep and the band of frequencies within ``flat`` of it.

    ``bound``: None, or when the cheapest frequency is the sweep's lowest or highest, the
    bound it gives (``"at most 4 rad/s (sweep's edge)"``): the minimum may lie beyond."""
    walked = [row for row in rows if row["cost_of_transport"] is not None]
    if not walked:
        return {"min_cost_of_transport_frequency": None}
    best = min(walked, key=lambda row: row["cost_of_transport"])
    near = [
        row["frequency"]
        for row in walked
        if row["cost_of_transport"] <= (1 + flat) * best["cost_of_transport"]
    ]
    tried = [row["frequency"] for row in rows]
    edge = {min(tried): "at most", max(tried): "at least"}.get(best["frequency"])
    return {
        "min_cost_of_transport_frequency": best["frequency"],
        "min_cost_of_transport": best["cost_of_transport"],
        f"within_{flat:.0%}_of_min_rad_s": [min(near), max(near)],
        "bound": None if edge is None else f"{edge} {best['frequency']:g} rad/s (sweep's edge)",
    }


#: Human walking at preferred speed, normalised (dimensionless): step length / leg length and
#: cadence x sqrt(l / g) for a 0.9 m leg at 0.7 m steps and 1.8 steps/s (Winter 2009, Ch. 1;
#: Perry & Burnfield 2010, Ch. 1), Froude number v^2 / (g l) (Alexander 1989, about 0.25),
#: the first peak of the vertical ground force in body weights (Winter 2009: 1.1-1.2) and the
#: double-support share of the gait cycle (Perry & Burnfield 2010: two periods of about 10 %).
HUMAN_GAIT = {
    "step_length_per_leg_length": 0.78,
    "cadence_froude_normalised": 0.55,
    "froude_number": 0.25,
    "impact_force_per_body_weight": 1.15,
    "double_support_fraction": 0.2,
}


def gait_metrics(log: WalkLog, leg_length: float, mass: float, gravity: float = 9.81) -> dict:
    """Normalised gait numbers of a walk, beside :data:`HUMAN_GAIT`.

    Over the walk's heel strikes after the first two: step length (distance between the
    landing points of successive strikes) / ``leg_length``, cadence (steps per second) x
    sqrt(l / g), Froude number v^2 / (g l) of the mean speed, the mean peak vertical force in
    the 50 ms after a strike / body weight, the share of time with both feet on the ground and
    the stance foot's contact losses per step. Empty without three strikes.
    """
    strikes = log.strikes[2:]
    if len(strikes) < 2:
        return {}
    times = np.array([t for t, _, _ in strikes])
    places = np.array([x for _, _, x in strikes])
    cadence = (len(strikes) - 1) / (times[-1] - times[0])
    speed = (places[-1] - places[0]) / (times[-1] - times[0])
    weight = mass * gravity
    walk = {
        "step_length_per_leg_length": float(np.mean(np.abs(np.diff(places))) / leg_length),
        "cadence_froude_normalised": float(cadence * np.sqrt(leg_length / gravity)),
        "froude_number": float(speed**2 / (gravity * leg_length)),
        "impact_force_per_body_weight": float(np.mean(log.impact_forces[2:]) / weight),
        "double_support_fraction": log.double_support_time / (log.duration - log.strikes[0][0]),
        "stance_contact_losses_per_step": log.contact_losses / len(log.strikes),
    }
    return {"walker": walk, "human": HUMAN_GAIT}
