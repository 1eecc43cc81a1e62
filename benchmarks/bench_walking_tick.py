"""Controller tick time in the Talos walk of :mod:`dmpopt_studies.talos_walk` (MuJoCo, 1 kHz).

Runs the walk ``--repeats`` times (quick: one step in place, three forward and a closing
step; ``--full``: two in place, ten forward) and times every ``compute_torques`` call by the
CPU time of the calling thread. Printed, over all ticks and split by phase: the median, the
99th percentile and the maximum [us], the number of ticks over 2 ms (the controller builds
the QP of a contact set the first time the set is used, inside that tick: a walk meets three),
and the number of falls. The single-support ticks (one foot in the
air, swing-foot frame task on) are the ones to put beside TSID's walking tick
(``benchmarks/tsid_baseline.py``).

Run: ``python benchmarks/bench_walking_tick.py [--full] [--repeats 3]``.
"""

import argparse

import numpy as np
from dmpopt_studies import talos_walk


def walk_ticks(full: bool):
    """The tick CPU times [us] of one walk, its phase per tick and whether it fell."""
    robot, q0 = talos_walk._robot_and_start()
    plan, swing_dmps = talos_walk.build_plan(robot, q0, quick=not full)
    walker = talos_walk.Walker(robot, q0, plan, swing_dmps)
    log, _, _ = talos_walk.simulate(robot, q0, walker, plan.duration)
    single = np.array([plan.phase(t)[0] == "single" for t in log.times])
    return log.tick_cpu_us, single, log.fell


def _row(name: str, ticks: np.ndarray) -> str:
    return (
        f"{name:<16}{ticks.size:>8}{np.median(ticks):>10.1f}{np.percentile(ticks, 99):>10.1f}"
        f"{ticks.max():>10.1f}{np.count_nonzero(ticks > 2000):>10}"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="the study's full walk")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    ticks, single, falls = [], [], 0
    for _ in range(args.repeats):
        t, s, fell = walk_ticks(args.full)
        ticks.append(t)
        single.append(s)
        falls += fell
    ticks, single = np.concatenate(ticks), np.concatenate(single)
    print(f"{args.repeats} walks ({'full' if args.full else 'quick'}), falls: {falls}")
    print(f"{'ticks [us CPU]':<16}{'n':>8}{'median':>10}{'p99':>10}{'max':>10}{'> 2 ms':>10}")
    print(_row("all", ticks))
    print(_row("single support", ticks[single]))
    print(_row("double support", ticks[~single]))


if __name__ == "__main__":
    main()
