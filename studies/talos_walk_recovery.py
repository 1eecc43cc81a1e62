"""The Talos walk pushed and on uneven ground (MuJoCo, realistic plant;
:mod:`dmpopt_studies.talos_walk`).

- Push recovery: an impulse on the pelvis ``PUSH_DELAY`` after the lift-off of step
  ``PUSH_STEP`` (the first forward step, the left foot swinging; 30 % into its single
  support), forward (+x), backward (-x) or lateral (+y, towards the swinging foot), spread
  over ``PUSH_DURATION``. A run survives if the robot walks the plan to its end without a
  fall and stands still ``SETTLE_TIME`` after it (the CoM's horizontal speed averaged over the
  last ``STILL_WINDOW`` below ``STILL_SPEED``): a robot still stumbling when a fixed window
  after the push ran out had counted as surviving. The largest survived impulse is found by
  bisection on ``[0, PUSH_RANGE]`` and reported as a bound ("at least X N s": the largest
  impulse tried and survived; survival is not monotone in the impulse, so a bound holds for
  the impulses tried), with the balance feedback (DCM feedback, step adjustment and timing,
  shortened double supports, crossing steps: :class:`talos_walk.Walker`) and without (the
  CoM tracks the plan). Quick mode: two lateral trials with the feedback.
- Uneven ground: an unplanned step down (the robot starts on a ``STEP_HEIGHT`` platform whose
  edge lies between two footholds), step up (a box of that height ahead) and a ``SLOPE``
  (2 degrees, rising from the same place), with forward
  steps of ``TERRAIN_STEP_LENGTH``; the footholds' horizontal distance from their adjusted
  targets.
"""

from __future__ import annotations

import numpy as np
from dmpopt_robots.plants import talos_realistic

from dmpopt.parallel import Runner, map_runs

from . import talos_walk as walk
from .branching import Branch

PUSH_STEP, PUSH_DELAY = 1, 0.18  # the step and the time after its lift-off [s] of a push
SETTLE_TIME = 1.0  # [s] after the (re-timed) plan's end, standing
STILL_WINDOW, STILL_SPEED = 0.2, 0.05  # [s], [m/s] standing still at the end
PUSH_DIRECTIONS = {"forward": (1.0, 0.0, 0.0), "backward": (-1.0, 0.0, 0.0),
                   "lateral": (0.0, 1.0, 0.0)}  # fmt: skip
PUSH_RANGE = {"forward": 160.0, "backward": 160.0, "lateral": 80.0}  # [N s] bisection interval
PUSH_TRIALS = {"quick": 2, "full": 3}  # bisection steps (full: range / 8 resolution)
QUICK_PUSHES = (20.0, 40.0)  # [N s] the quick mode's two lateral trials
STEP_HEIGHT = 0.04  # [m] the unplanned step down and up
TERRAIN_STEP_LENGTH = 0.25  # [m] footholds clear of the edge at x = EDGE
EDGE = 0.36  # [m] the platform's (step down), the box's (step up) or the slope's edge
SLOPE = 0.035  # [rad] (2 degrees) the slope, ascending along x


def pushed_walks(feedback: bool, n_trials: int, choose) -> list[bool]:
    """``n_trials`` pushed walks (with or without the ``feedback``), the impulse [N s, a
    world-frame vector] of each ``choose(earlier)``, from whether the trials before it
    survived (a list of bools); whether each survived. The walks are the same up to the
    push: it is simulated once and continued once per trial from there
    (:class:`dmpopt_studies.branching.Branch`: the same bits as a trial walked from the
    start)."""
    robot, q0 = walk._robot_and_start()
    plan, swing_dmps = walk.build_plan(robot, q0, quick=True)
    plant = talos_realistic(robot)
    walker = walk.Walker(robot, q0, plan, swing_dmps, plant, feedback=feedback)
    branch = Branch(n_trials)

    def impulse():  # at the push: arm k >= 1 is trial k (the children run first), arm 0 the last
        trial = branch.arm() or n_trials
        return choose([branch.children[k] for k in range(1, trial)])

    push = (PUSH_STEP, PUSH_DELAY, impulse)
    try:
        log, _, _ = walk.simulate(
            robot, q0, walker, walk_duration(plan), 0, plant, push=push, feet=False
        )
        survived = not (log.fell or log.diverged) and stands_still(log.times, log.com)
    except BaseException:
        branch.abandon()  # a trial's process ends here
        raise
    outcomes = branch.logs(survived)
    return outcomes[1:] + outcomes[:1]


def walk_duration(plan) -> float:
    """The plan's duration and ``SETTLE_TIME`` [s], with room for step timing: a pushed walk's
    re-timed steps may end up to one step later than planned."""
    return plan.duration + walk.SINGLE_SUPPORT + walk.DOUBLE_SUPPORT + SETTLE_TIME


def stands_still(times, com) -> bool:
    """Whether the CoM's horizontal speed, averaged over the last ``STILL_WINDOW`` of the
    log (``times`` [s], ``com`` (n, 3) [m]), is below ``STILL_SPEED``."""
    last = np.searchsorted(times, times[-1] - STILL_WINDOW)
    moved = np.linalg.norm(com[-1, :2] - com[last, :2])
    return bool(moved < STILL_SPEED * (times[-1] - times[last]))


def push_bisections(case) -> list[dict]:
    """Largest survived impulse in each of ``PUSH_DIRECTIONS`` for ``case = (feedback,
    n_trials)`` by bisection on ``[0, PUSH_RANGE]`` (``n_trials`` each, the directions one
    after the other in one :func:`pushed_walks`): per direction ``survived_ns`` (the bound)
    and ``fell_ns`` (the smallest that fell, None if none did), with every trial."""
    feedback, n_trials = case
    directions = list(PUSH_DIRECTIONS)

    def choose(earlier):
        direction = directions[len(earlier) // n_trials]
        own = earlier[len(earlier) - len(earlier) % n_trials :]  # this direction's trials
        return _bisection(direction, own)[3] * np.array(PUSH_DIRECTIONS[direction])

    outcomes = pushed_walks(feedback, n_trials * len(directions), choose)
    results = []
    for d, direction in enumerate(directions):
        low, fell, trials, _ = _bisection(direction, outcomes[d * n_trials : (d + 1) * n_trials])
        results.append({"survived_ns": low, "fell_ns": fell, "trials": trials})
    return results


def _bisection(direction: str, outcomes: list) -> tuple:
    """The bisection on ``[0, PUSH_RANGE]`` after trials with these ``outcomes`` (survived
    or not): the largest survived impulse, the smallest that fell (or None), the trials
    ``(impulse, survived)`` and the next impulse to try [N s]."""
    low, high, fell, trials = 0.0, PUSH_RANGE[direction], None, []
    impulse = high / 2
    for survived in outcomes:
        trials.append((impulse, survived))
        if survived:
            low = impulse
        else:
            high = fell = impulse
        impulse = 0.5 * (low + high)
    return low, fell, trials, impulse


def push_recovery(quick: bool, runner=None) -> dict:
    """The push-recovery bounds with and without the feedback (module docstring)."""
    if quick:
        n = len(QUICK_PUSHES)
        lateral = np.array(PUSH_DIRECTIONS["lateral"])
        survived = pushed_walks(True, n, lambda earlier: QUICK_PUSHES[len(earlier)] * lateral)
        bound = max((i for i, ok in zip(QUICK_PUSHES, survived) if ok), default=0.0)
        return {
            "lateral_ns": bound, "forward_ns": None, "backward_ns": None,
            "without_feedback": {"lateral_ns": None, "forward_ns": None, "backward_ns": None},
            "trials": {"lateral": list(zip(QUICK_PUSHES, survived))},
            "quick": True,
        }  # fmt: skip
    n = PUSH_TRIALS["full"]
    feedbacks = (True, False)
    per_feedback = map_runs(
        push_bisections, [(f, n) for f in feedbacks], runner, label="walk push bisection"
    )
    cases = [(d, feedback) for feedback in feedbacks for d in PUSH_DIRECTIONS]
    results = [result for results in per_feedback for result in results]
    out = {"without_feedback": {}, "trials": {}}
    for (direction, feedback), result in zip(cases, results):
        target = out if feedback else out["without_feedback"]
        target[f"{direction}_ns"] = result["survived_ns"]
        out["trials"][f"{direction}{'' if feedback else '_without_feedback'}"] = result["trials"]
    return out


def terrain_boxes(kind: str):
    """MuJoCo boxes of ``kind`` "step_down" (a platform under the start, its edge at EDGE) or
    "step_up" (a box from EDGE on) or "slope" (rising at SLOPE from EDGE on), and the
    start's height above the floor [m]."""
    h = STEP_HEIGHT
    if kind == "step_down":
        return [((EDGE / 2 - 1.0, 0.0, h / 2), (1.0 + EDGE / 2, 1.0, h / 2))], h
    if kind == "step_up":
        return [((EDGE + 1.5, 0.0, h / 2), (1.5, 1.0, h / 2))], 0.0
    if kind == "slope":  # a 1 cm thick slab whose top face rises from the floor at EDGE
        normal = np.array([-np.sin(SLOPE), 0.0, np.cos(SLOPE)])  # pitch -SLOPE: ascending
        top = np.array([EDGE + np.cos(SLOPE), 0.0, np.sin(SLOPE)])
        return [(top - 0.01 * normal, (1.0, 1.0, 0.01), -SLOPE)], 0.0
    raise ValueError(f"kind must be 'step_down', 'step_up' or 'slope', got {kind!r}")


def terrain_trial(kind: str) -> dict:
    """The quick walk over ``kind`` ground, unplanned: ``fell``, the height, and the largest
    horizontal distance of a landed foot from its adjusted target [mm] (the slope's
    ``height_m`` is its rise under the last foothold)."""
    robot, q0 = walk._robot_and_start()
    boxes, lift = terrain_boxes(kind)
    q0 = q0.copy()
    q0[2] += lift
    plan, swing_dmps = walk.build_plan(robot, q0, quick=True, step_length=TERRAIN_STEP_LENGTH)
    plant = talos_realistic(robot)
    walker = walk.Walker(robot, q0, plan, swing_dmps, plant)
    log, _, _ = walk.simulate(robot, q0, walker, plan.duration, 0, plant, boxes=boxes, feet=False)
    errors = [
        np.linalg.norm(r.landed[:2] - r.target[:2]) for r in walker.records if r.landed is not None
    ]
    landed = [r.landed[2] - lift for r in walker.records if r.landed is not None]
    return {
        "height_m": STEP_HEIGHT if kind != "slope" else round(float(max(landed, default=0.0)), 4),
        "fell": bool(log.fell or log.diverged),
        "steps_landed": len(errors),
        "steps_planned": len(plan.footsteps),
        "foothold_error_max_mm": 1e3 * float(max(errors, default=np.nan)),
        "foothold_heights_mm": [round(1e3 * z, 1) for z in landed],
        "touchdowns_from_contact": sum(r.from_contact for r in walker.records),
    }


def uneven_ground(runner=None) -> dict:
    """Step down, step up and slope (module docstring)."""
    kinds = ["step_down", "step_up", "slope"]
    return dict(zip(kinds, map_runs(terrain_trial, kinds, runner, label="walk terrain")))


def push_video(out_dir, direction: str = "lateral", impulse: float = 40.0) -> dict:
    """Render the walk pushed by ``impulse`` [N s] ``direction`` with the feedback into
    ``out_dir/talos_walk_push.webp`` (and five keyframes); the run's outcome and the steps'
    targets and footholds. Needs an OpenGL context (``MUJOCO_GL=egl``)."""
    from dmpopt.exceptions import MissingDependency
    from dmpopt.sim import render_animation

    from .common import output_dir

    out = output_dir(out_dir)
    robot, q0 = walk._robot_and_start()
    plan, swing_dmps = walk.build_plan(robot, q0, quick=True)
    plant = talos_realistic(robot)
    walker = walk.Walker(robot, q0, plan, swing_dmps, plant)
    push = (PUSH_STEP, PUSH_DELAY, impulse * np.array(PUSH_DIRECTIONS[direction]))
    record = int(round(1.0 / (2 * walk.VIDEO_FPS * walk.DT)))
    log, simulator, frames = walk.simulate(robot, q0, walker, plan.duration, record, plant, push)
    result = {
        "direction": direction, "impulse_ns": impulse, "fell": bool(log.fell),
        "targets": [np.round(r.target, 3).tolist() for r in walker.records],
        "landed": [None if r.landed is None else np.round(r.landed, 3).tolist()
                   for r in walker.records],
        "video": None,
    }  # fmt: skip
    try:
        render_animation(simulator, frames, out / "talos_walk_push.webp",
                         fps=2 * walk.VIDEO_FPS, width=320, height=240, distance=2.5)  # fmt: skip
        walk.keyframes(out / "talos_walk_push.webp", out / "talos_walk_push_keyframes.png", 6)
        result["video"] = "talos_walk_push.webp"
        result["keyframes"] = "talos_walk_push_keyframes.png"
    except MissingDependency as error:
        result["video_skipped"] = str(error)
    return result


def main(argv=None) -> None:
    """``python -m dmpopt_studies.talos_walk_recovery OUT_DIR [--quick]``: pushes and uneven
    ground."""
    import argparse
    import json

    from .common import write_metrics

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", nargs="?", default="results/talos_walk_recovery")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--only", choices=("push", "terrain", "video", "arms"), default=None)
    parser.add_argument("--workers", type=int, default=1, help="processes for the runs")
    args = parser.parse_args(argv)
    runner = Runner(workers=args.workers)
    metrics = {}
    if args.only in (None, "push"):
        metrics["push_recovery"] = push_recovery(args.quick, runner)
    if args.only in (None, "terrain"):
        metrics.update(uneven_ground(runner))
    if args.only == "arms":  # also part of the study's full run (talos_walk.run_walk)
        metrics["arm_swing"] = walk.arm_swing_effect(runner)
    if args.only in (None, "video"):
        metrics["push_video"] = push_video(args.out_dir)
    write_metrics(args.out_dir, "talos_walk_recovery", metrics, {}, seed=0, quick=args.quick)
    print(json.dumps(metrics, indent=2))


if __name__ == "__main__":
    main()
