"""The ``dmpopt`` command: list and run the studies that reproduce the paper."""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path

STUDIES = ("imitation", "constrained", "rl", "recognition", "humanoid", "biped")


def available_studies() -> dict:
    """Study name -> module, for the studies installed with this version."""
    found = {}
    for name in STUDIES:
        try:
            found[name] = importlib.import_module(f"studies.{name}")
        except ModuleNotFoundError as error:
            if error.name != f"studies.{name}":
                raise
    return found


def _summary(module) -> str:
    return (module.__doc__ or "").strip().splitlines()[0]


def _expected(module, quick: bool) -> str:
    seconds = getattr(module, "EXPECTED_SECONDS", {}).get("quick" if quick else "full")
    return f"~{seconds / 60:.0f} min" if seconds and seconds >= 90 else f"~{seconds or '?'} s"


def _list(studies: dict) -> int:
    for name, module in studies.items():
        print(f"{name:12s} {_expected(module, False):>8s}  {_summary(module)}")
    return 0


def _run(studies: dict, names: list[str], out: Path, quick: bool, seed: int) -> int:
    total = sum(
        getattr(studies[n], "EXPECTED_SECONDS", {}).get("quick" if quick else "full", 0)
        for n in names
    )
    print(
        f"running {', '.join(names)} ({'quick' if quick else 'full'}): "
        f"expected about {total / 60:.1f} min on 2 cores; results in {out}"
    )
    from threadpoolctl import threadpool_limits

    results = {}
    for name in names:
        start = time.perf_counter()
        print(f"== {name}: {_summary(studies[name])}")
        # the studies multiply small matrices: one BLAS thread is faster, and on a loaded
        # machine several threads per product cost milliseconds each
        with threadpool_limits(limits=1, user_api="blas"):
            results[name] = studies[name].run(out / name, quick=quick, seed=seed)
        print(f"== {name} done in {time.perf_counter() - start:.1f} s -> {out / name}")
    if len(names) > 1:
        from studies.report import write_report

        print(f"report: {write_report(out, results)}")
    return 0


def main(argv=None) -> int:
    """Entry point of the ``dmpopt`` command."""
    parser = argparse.ArgumentParser(prog="dmpopt", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    study = commands.add_parser("study", help="list or run the studies")
    actions = study.add_subparsers(dest="action", required=True)
    actions.add_parser("list", help="each study, what it shows and how long it takes")
    run = actions.add_parser("run", help="run one study, or all")
    run.add_argument("name", help="a study name from 'dmpopt study list', or 'all'")
    run.add_argument("--out", default="results", type=Path, help="output folder (default: results)")
    run.add_argument("--quick", action="store_true", help="a reduced run (about a minute each)")
    run.add_argument("--seed", default=0, type=int, help="random seed (default: 0)")
    args = parser.parse_args(argv)

    studies = available_studies()
    if args.action == "list":
        return _list(studies)
    names = list(studies) if args.name == "all" else [args.name]
    unknown = [n for n in names if n not in studies]
    if unknown:
        parser.error(f"unknown study {unknown[0]!r}; choose from {', '.join(studies)} or 'all'")
    return _run(studies, names, args.out, args.quick, args.seed)


if __name__ == "__main__":
    sys.exit(main())
