"""Kill score per module of the last mutmut run and the names of the mutants not killed.

Reads mutmut's result files (``mutants/<module>.py.meta``); run from the repository root
after ``mutmut run`` (tools/mutation.sh does both). Timeouts count as killed: the mutant
made the tests run 15 times longer than they should.

    python tools/mutation_summary.py
"""

import json
from collections import Counter
from pathlib import Path

from mutmut.stats import status_by_exit_code

CAUGHT = ("killed", "timeout", "segfault")


def main():
    print(
        f"{'module':32s} {'mutants':>7s} {'killed':>7s} {'timeout':>7s} {'survived':>8s} "
        f"{'no tests':>8s} {'score':>6s}"
    )
    not_killed = []
    for meta in sorted(Path("mutants").rglob("*.py.meta")):
        codes = json.loads(meta.read_text())["exit_code_by_key"]
        statuses = {name: status_by_exit_code[code] for name, code in codes.items()}
        counts = Counter(statuses.values())
        checked = sum(n for status, n in counts.items() if status != "not checked")
        caught = sum(counts[status] for status in CAUGHT)
        score = caught / checked if checked else float("nan")
        module = str(meta.relative_to("mutants"))[: -len(".meta")]
        print(
            f"{module:32s} {len(codes):7d} {counts['killed']:7d} {counts['timeout']:7d} "
            f"{counts['survived']:8d} {counts['no tests']:8d} {score:6.1%}"
        )
        not_killed += [(n, s) for n, s in statuses.items() if s not in CAUGHT]
    for name, status in sorted(not_killed):
        print(f"    {status:12s} {name}")


if __name__ == "__main__":
    main()
