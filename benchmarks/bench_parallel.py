"""Overhead of dmpopt.parallel per run: local processes and Ray, against a run in series.

    python benchmarks/bench_parallel.py                  # local processes and a local Ray
    python benchmarks/bench_parallel.py --ray auto       # a running cluster (docs/cluster.md)
    python benchmarks/bench_parallel.py --biped-trials 6 # and the biped study's trials
    python benchmarks/bench_parallel.py --compare results-serial results-default results-ray
    python benchmarks/bench_parallel.py --proxsuite      # proxsuite's answer and the heap

A run is a call of a function that returns at once, so the time per run is the backend's
cost: sending the input, scheduling, and collecting the result. Two measures: one run at a
time (latency, what a single slow trial pays) and a batch of runs (what a sweep pays per run).

``--compare DIR DIR...`` instead compares the ``metrics.json`` of the same studies run into
different output folders (e.g. ``dmpopt study run all --workers 1 --out DIR``, the default,
``--ray``): every value must be bitwise the same, except those that measure time or say where
the runs went (:data:`NOT_RESULTS`). It prints each study's count of compared values and each
difference, and exits 1 if there is any. The quick studies without a robot, in a few CPU
minutes::

    S="imitation constrained rl recognition cartesian primitives feasible"
    dmpopt study run $S --quick --workers 1 --out serial   # one process, in series
    dmpopt study run $S --quick --out default              # side by side, one per core
    dmpopt study run $S --quick --ray --out ray
    python benchmarks/bench_parallel.py --compare serial default ray

``--proxsuite`` shows why runs that solve QPs with proxsuite can differ in the last bits
between serial, process and Ray runs: the same dense QP (same input arrays), solved by QP
objects built after heap allocations of other sizes, gives answers that differ by ~1e-12
(proxsuite's vectorised kernels depend on where its own buffers lie; 64-byte aligned inputs
do not change that), while the same heap state gives the same bits. Which QPs a run solves
after which allocations depends on what ran before in its process. The controller's answers
do not carry these bits (dmpopt.control.qp_stages: an answer is the KKT solution of an
active set guessed from a converged proxsuite answer, with a margin; an unconverged one,
whose iterates can part far more on a near-infeasible QP, guesses nothing).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

from dmpopt.parallel import Runner, map_runs

NOT_RESULTS = re.compile(
    r"(^|\.)(parallel|versions)(\.|$)|wall|cpu|seconds|_(us|ms)($|\.|_)|real_time_factor|"
    r"ticks_over|over_budget|elapsed|duration_s$|timing"
)
"""Paths of metric values that are measurements of time or of where the runs went."""
# "fit 57 ms", "0.76x real time" in a summary line
_TIMES_IN_TEXT = re.compile(r"[-+.e\d]+ ?(ms|us|s|x real time)\b")


def _comparable(value):
    return _TIMES_IN_TEXT.sub("<time>", value) if isinstance(value, str) else value


def _leaves(value, path=""):
    """(dotted path, value) of every leaf of a metrics record."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _leaves(item, f"{path}.{key}" if path else str(key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from _leaves(item, f"{path}[{i}]")
    else:
        yield path, value


def compare(folders) -> int:
    """Print the differing result values of the studies in ``folders``; their count."""
    folders = [Path(f) for f in folders]
    studies = sorted(
        p.parent.name for p in folders[0].glob("*/metrics.json")
        if all((f / p.parent.name / "metrics.json").is_file() for f in folders[1:])
    )  # fmt: skip
    differences = 0
    for study in studies:
        records = [json.loads((f / study / "metrics.json").read_text()) for f in folders]
        leaves = [dict(_leaves(r)) for r in records]
        keys = [k for k in leaves[0] if not NOT_RESULTS.search(k)]
        changed = []
        for key in keys:
            values = [_comparable(leaf.get(key, "<missing>")) for leaf in leaves]
            if any(v != values[0] for v in values[1:]):
                changed.append((key, values))
        extra = set().union(*(set(leaf) for leaf in leaves[1:])) - set(leaves[0])
        changed += [(k, [leaf.get(k, "<missing>") for leaf in leaves]) for k in sorted(extra)
                    if not NOT_RESULTS.search(k)]  # fmt: skip
        print(f"{study:12s} {len(keys):6d} values compared, {len(changed)} differ")
        for key, values in changed[:40]:
            print(f"    {key}: " + " | ".join(repr(v) for v in values))
        differences += len(changed)
    return differences


def proxsuite_heap(n: int = 44, n_eq: int = 12, n_in: int = 40, builds: int = 12) -> float:
    """Largest difference between proxsuite's answers to one QP, each from a QP object built
    after one more heap block of a random size (the blocks are kept alive)."""
    import proxsuite

    rng = np.random.default_rng(0)
    root = rng.normal(size=(n, n))
    problem = (
        root @ root.T + np.eye(n), rng.normal(size=n), rng.normal(size=(n_eq, n)),
        rng.normal(size=n_eq), rng.normal(size=(n_in, n)), np.full(n_in, -0.1),
        np.full(n_in, 0.1),
    )  # fmt: skip
    answers, kept = [], []
    for _ in range(builds):
        kept.append(np.empty(int(rng.integers(1, 3000))))
        qp = proxsuite.proxqp.dense.QP(n, n_eq, n_in)
        qp.settings.eps_abs = 1e-9
        qp.init(*problem)
        qp.solve()
        answers.append(qp.results.x.copy())
        kept.append(qp)
    return max(float(np.abs(x - answers[0]).max()) for x in answers)


def _echo(x):
    return x


def overhead(runner: Runner, batch: int = 400, single: int = 20) -> dict:
    """Median seconds per run: one at a time, and in a batch of ``batch`` runs."""
    map_runs(_echo, range(4), runner)  # start the workers before timing
    alone = []
    for i in range(single):
        start = time.perf_counter()
        map_runs(_echo, [i], runner)
        alone.append(time.perf_counter() - start)
    start = time.perf_counter()
    map_runs(_echo, range(batch), runner)
    return {
        "one_at_a_time_ms": 1e3 * np.median(alone),
        "in_a_batch_ms": 1e3 * (time.perf_counter() - start) / batch,
    }


def biped_trials(runner: Runner, n_trials: int) -> float:
    """Wall seconds of the biped study's randomised trials (4 arms x ``n_trials`` walks)."""
    from dmpopt_robots.biped import load_biped
    from dmpopt_studies.biped import RANGES
    from dmpopt_studies.biped.analysis import random_disturbances, survival_by_arm
    from dmpopt_studies.biped.gait import learn_gait

    biped, (_, dmp) = load_biped(), learn_gait()
    qp = {"controller": "qp", "boom_pitch_stiffness": 0.0, "boom_pitch_damping": 0.0}
    disturbances = random_disturbances(biped, n_trials, 0, RANGES)
    start = time.perf_counter()
    survival_by_arm(biped, dmp, 13.3, disturbances, runner=runner, **qp)
    return time.perf_counter() - start


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ray", default="local", help="'local', 'auto' or HOST:PORT")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--biped-trials",
        type=int,
        default=0,
        help="also time the biped study's randomised trials (4 arms x N walks) per backend",
    )
    parser.add_argument(
        "--compare", nargs="+", metavar="DIR", help="compare the metrics of these result folders"
    )
    parser.add_argument(
        "--proxsuite", action="store_true", help="proxsuite's answer against the heap state"
    )
    args = parser.parse_args(argv)
    if args.proxsuite:
        worst = proxsuite_heap()
        print(f"one QP, same inputs, QP objects built at 12 heap states: answers differ by "
              f"up to {worst:.1e}")  # fmt: skip
        return
    if args.compare:
        sys.exit(1 if compare(args.compare) else 0)
    runners = {
        "serial": Runner(progress=False),
        f"processes ({args.workers})": Runner(workers=args.workers, progress=False),
        f"ray {args.ray}": Runner(workers=args.workers, ray=args.ray, progress=False),
    }
    print(f"{'backend':22s} {'one at a time [ms]':>20s} {'in a batch [ms/run]':>20s}", end="")
    print(f" {'biped trials [s]':>18s}" if args.biped_trials else "")
    for name, runner in runners.items():
        with runner:
            result = overhead(runner)
            trials = biped_trials(runner, args.biped_trials) if args.biped_trials else None
        print(
            f"{name:22s} {result['one_at_a_time_ms']:20.3f} {result['in_a_batch_ms']:20.3f}", end=""
        )
        print(f" {trials:18.1f}" if trials is not None else "")


if __name__ == "__main__":
    main()
