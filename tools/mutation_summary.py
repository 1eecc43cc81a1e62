"""Kill score per module of the last mutmut run and the names of the mutants not killed.

Reads mutmut's result files (``mutants/<module>.py.meta``); run from the repository root
after ``mutmut run`` (tools/mutation.sh does both). Timeouts count as killed: the mutant
made the tests run 15 times longer than they should. Mutants named in
``tools/mutation_hand_kills.txt`` count as killed "by hand": a test outside mutmut's test
selection, or one added after the run, was run against them and failed (docs/mutation.md).

    python tools/mutation_summary.py [--all]   # --all also lists the mutants not checked
"""

import json
import sys
from collections import Counter
from pathlib import Path

from mutmut.stats import status_by_exit_code

CAUGHT = ("killed", "timeout", "segfault", "killed by hand")
HAND_KILLS = Path(__file__).with_name("mutation_hand_kills.txt")


def hand_kills() -> set[str]:
    """Names in HAND_KILLS, one per line; '#' starts a comment."""
    if not HAND_KILLS.exists():
        return set()
    lines = (line.split("#", 1)[0].strip() for line in HAND_KILLS.read_text().splitlines())
    return {line for line in lines if line}


def main():
    print(
        f"{'module':32s} {'mutants':>7s} {'killed':>7s} {'timeout':>7s} {'by hand':>7s} "
        f"{'survived':>8s} {'no tests':>8s} {'score':>6s}"
    )
    by_hand, not_killed = hand_kills(), []
    for meta in sorted(Path("mutants").rglob("*.py.meta")):
        codes = json.loads(meta.read_text())["exit_code_by_key"]
        statuses = {name: status_by_exit_code[code] for name, code in codes.items()}
        for name, status in statuses.items():
            if name in by_hand and status not in CAUGHT:
                statuses[name] = "killed by hand"
        counts = Counter(statuses.values())
        checked = sum(n for status, n in counts.items() if status != "not checked")
        caught = sum(counts[status] for status in CAUGHT)
        score = caught / checked if checked else float("nan")
        module = str(meta.relative_to("mutants"))[: -len(".meta")]
        print(
            f"{module:32s} {len(codes):7d} {counts['killed']:7d} {counts['timeout']:7d} "
            f"{counts['killed by hand']:7d} {counts['survived']:8d} {counts['no tests']:8d} "
            f"{score:6.1%}"
        )
        not_killed += [(n, s) for n, s in statuses.items() if s not in CAUGHT]
    for name, status in sorted(not_killed):
        if status != "not checked" or "--all" in sys.argv:
            print(f"    {status:12s} {name}")


if __name__ == "__main__":
    main()
