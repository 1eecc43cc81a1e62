"""dmpopt's CartesianDMP against movement_primitives' CartesianDMP on the same pose demos.

Run: python benchmarks/bench_cartesian.py [--mp-python PATH] [--repeats N]

movement_primitives (0.9.1, Ude et al. 2014's quaternion DMP, Euler steps of ``int_dt``) is
not a dependency of dmpopt: it runs in a worker process of the interpreter ``--mp-python``
(default: this one), e.g. a separate environment made with
``python -m venv venv-mp && venv-mp/bin/pip install movement-primitives==0.9.1``.

For each synthetic demonstration (2 s, 401 samples), both libraries fit 30 basis functions
per dimension with their defaults (alpha = 25, beta = 6.25) and roll out at the demo's
5 ms step; reported:

- reproduction error of position [mm] and orientation [deg], RMS and max over the samples;
- a goal change (goal moved by 10 cm and turned by 30 degrees): error at the end of the
  demonstrated duration ``T``, at ``1.5 T`` and at ``3.5 T`` (dmpopt's settling time), and
  the path distortion: how far the plan moves, at most, against how far the goal moved
  (``max_t |y'(t) - y(t)| / |g' - g|``, the same in angle for the orientation; 1 for a plan
  that follows the goal without overshoot);
- fit and rollout time, median of ``--repeats`` (after a first call, whose time is shown
  apart for dmpopt: it builds the CasADi functions; dmpopt's rollouts are timed with a new
  ``tau`` each time, so no cached response matrix serves them).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

N_BASIS = 30
DURATION = 2.0
N_SAMPLES = 401
GOAL_SHIFT = np.array([0.06, -0.08, 0.0])  # 10 cm
GOAL_TURN = np.radians(30.0) * np.array([0.0, 0.6, 0.8])  # 30 degrees
RUN = 3.5
"""Plans run for this many times the demonstrated duration (dmpopt's settling time here)."""


def qmul(p, q):
    """Hamilton product of quaternions (w, x, y, z)."""
    pw, pv, qw, qv = p[0], p[1:], q[0], q[1:]
    return np.concatenate([[pw * qw - pv @ qv], pw * qv + qw * pv + np.cross(pv, qv)])


def qexp(rotation):
    angle = np.linalg.norm(rotation)
    if angle == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * rotation / angle])


def demos() -> dict:
    """Synthetic pose demonstrations: (times, positions (n, 3), quaternions (n, 4))."""
    times = np.linspace(0.0, DURATION, N_SAMPLES)
    s = times / DURATION
    smooth = 10 * s**3 - 15 * s**4 + 6 * s**5
    start = np.array([0.9, 0.1, -0.3, 0.3]) / np.linalg.norm([0.9, 0.1, -0.3, 0.3])
    pour = (
        np.stack([0.4 + 0.2 * smooth, 0.1 * np.sin(np.pi * smooth), 0.3 + 0.1 * smooth**2], 1),
        np.stack([0.3 * smooth, 1.6 * smooth, 0.5 * np.sin(np.pi * smooth)], 1),
    )
    wipe = (
        np.stack([0.5 + 0.05 * smooth, 0.15 * np.sin(3 * np.pi * smooth), 0.2 + 0 * s], 1),
        np.stack([0.4 * np.sin(3 * np.pi * smooth), 0.2 * smooth, 0.3 * smooth], 1),
    )
    return {
        name: (times, positions, np.array([qmul(qexp(r), start) for r in rotations]))
        for name, (positions, rotations) in {"pour": pour, "wipe": wipe}.items()
    }


def angles(p, q):
    """Rotation angle [deg] between rows of unit quaternions (sign-blind)."""
    dots = np.clip(np.abs(np.sum(p * q, axis=1)), 0.0, 1.0)
    return np.degrees(2 * np.arccos(dots))


def median_ms(function, repeats):
    samples = []
    for k in range(repeats):
        start = time.perf_counter()
        function(k)
        samples.append(time.perf_counter() - start)
    return 1e3 * float(np.median(samples))


# --- movement_primitives (worker process) ----------------------------------------------


def mp_worker(inputs: Path, outputs: Path, repeats: int) -> None:
    from movement_primitives.dmp import CartesianDMP

    data = np.load(inputs)
    times, poses, goal = data["times"], data["poses"], data["goal"]
    dt = times[1] - times[0]

    def fitted():
        dmp = CartesianDMP(execution_time=times[-1], dt=dt, n_weights_per_dim=N_BASIS)
        dmp.imitate(times, poses)
        return dmp

    dmp = fitted()
    plan = dmp.open_loop(run_t=RUN * times[-1])[1]
    dmp.configure(goal_y=goal)
    moved = dmp.open_loop(run_t=RUN * times[-1])[1]
    fit_ms = median_ms(lambda _: fitted(), repeats)
    rollout_ms = median_ms(lambda _: dmp.open_loop(), repeats)
    np.savez(outputs, plan=plan, moved=moved, fit_ms=fit_ms, rollout_ms=rollout_ms)


def run_movement_primitives(python: str, times, positions, quaternions, goal, repeats):
    with tempfile.TemporaryDirectory() as folder:
        inputs, outputs = Path(folder) / "in.npz", Path(folder) / "out.npz"
        np.savez(inputs, times=times, poses=np.hstack([positions, quaternions]), goal=goal)
        command = [python, __file__, "--worker", str(inputs), str(outputs)]
        subprocess.run([*command, "--repeats", str(repeats)], check=True)
        with np.load(outputs) as result:
            return {name: result[name] for name in result.files}


# --- dmpopt ----------------------------------------------------------------------------


def run_dmpopt(times, positions, quaternions, goal, repeats, goal_scaling="auto"):
    from dmpopt import fit_cartesian

    dt = times[1] - times[0]
    start = time.perf_counter()
    dmp = fit_cartesian(times, positions, quaternions, N_BASIS, goal_scaling=goal_scaling)
    first = dmp.rollout(RUN * times[-1], dt)
    cold_ms = 1e3 * (time.perf_counter() - start)
    moved = dmp.with_goal(goal[:3], goal[3:]).rollout(RUN * times[-1], dt)
    fit_ms = median_ms(lambda _: fit_cartesian(times, positions, quaternions, N_BASIS), repeats)
    rollout_ms = median_ms(
        lambda k: dmp.with_tau(dmp.tau * (1 + 1e-9 * (k + 1))).rollout(times[-1], dt), repeats
    )
    return {
        "plan": np.hstack([first.positions, first.orientations]),
        "moved": np.hstack([moved.positions, moved.orientations]),
        "fit_ms": fit_ms,
        "rollout_ms": rollout_ms,
        "cold_ms": cold_ms,
    }


# --- comparison ------------------------------------------------------------------------


def metrics(result, times, positions, quaternions, goal) -> dict:
    n = times.size
    plan, moved = result["plan"], result["moved"]
    position_error = 1e3 * np.linalg.norm(plan[:n, :3] - positions, axis=1)
    angle_error = angles(plan[:n, 3:], quaternions)
    at_t, later = n - 1, round(1.5 * (n - 1))
    goal_shift = 1e3 * np.linalg.norm(goal[:3] - positions[-1])
    goal_turn = angles(goal[None, 3:], quaternions[-1:])[0]
    goal_rows = np.tile(goal[3:], (len(moved), 1))
    return {
        "position RMS [mm]": np.sqrt(np.mean(position_error**2)),
        "position max [mm]": position_error.max(),
        "orientation RMS [deg]": np.sqrt(np.mean(angle_error**2)),
        "orientation max [deg]": angle_error.max(),
        **{
            f"new goal: position error at {label} [mm]": 1e3
            * np.linalg.norm(moved[k, :3] - goal[:3])
            for label, k in (("T", at_t), ("1.5 T", later), (f"{RUN} T", -1))
        },
        **{
            f"new goal: orientation error at {label} [deg]": angles(moved[[k], 3:], goal_rows[:1])[
                0
            ]
            for label, k in (("T", at_t), ("1.5 T", later), (f"{RUN} T", -1))
        },
        "new goal: position distortion [1]": 1e3
        * np.linalg.norm(moved[:, :3] - plan[:, :3], axis=1).max()
        / goal_shift,
        "new goal: orientation distortion [1]": angles(moved[:, 3:], plan[:, 3:]).max() / goal_turn,
        "fit [ms]": float(result["fit_ms"]),
        "rollout [ms]": float(result["rollout_ms"]),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--mp-python", default=sys.executable, help="python with movement_primitives"
    )
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    parser.add_argument("--worker", nargs=2, type=Path, help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.worker:
        return mp_worker(*arguments.worker, arguments.repeats)
    from threadpoolctl import threadpool_limits

    table = {}
    with threadpool_limits(limits=1, user_api="blas"):
        for name, (times, positions, quaternions) in demos().items():
            goal = np.concatenate(
                [positions[-1] + GOAL_SHIFT, qmul(qexp(GOAL_TURN), quaternions[-1])]
            )
            case = (times, positions, quaternions, goal)
            ours = run_dmpopt(*case, arguments.repeats)
            translated = run_dmpopt(*case, arguments.repeats, goal_scaling="translation")
            theirs = run_movement_primitives(arguments.mp_python, *case, arguments.repeats)
            table[name] = {
                "dmpopt": metrics(ours, *case),
                "dmpopt translation": metrics(translated, *case),
                "movement_primitives": metrics(theirs, *case),
            }
            table[name]["dmpopt"]["first fit + rollout [ms]"] = ours["cold_ms"]
    columns = ("dmpopt", "dmpopt translation", "movement_primitives")
    print(
        "| demo | metric | dmpopt (goal_scaling auto) | dmpopt (translation) "
        "| movement_primitives 0.9.1 |"
    )
    print("|---|---|---:|---:|---:|")
    for name, libraries in table.items():
        for metric in libraries["dmpopt"]:
            values = [libraries[column].get(metric) for column in columns]
            cells = " | ".join("" if value is None else f"{value:.4g}" for value in values)
            print(f"| {name} | {metric} | {cells} |")
    if arguments.json:
        arguments.json.write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
