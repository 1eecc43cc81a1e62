"""Kill score per module of the last mutmut run and the names of the mutants not killed.

Reads mutmut's result files (``mutants/<module>.py.meta``); run from the repository root
after ``mutmut run`` (tools/mutation.sh does both). Timeouts count as killed: the mutant
made the tests run 15 times longer than they should. Two lists kept beside this script
complete mutmut's verdicts (docs/mutation.md explains each entry):

- ``mutation_hand_kills.txt``: mutants killed "by hand", by a test outside mutmut's test
  selection or added after the run, run against them and failing;
- ``mutation_verdicts.txt``: survivors that no test can kill, as ``NAME CLASS``:
  ``equivalent`` (no input tells them apart), ``unreachable`` (a defensive branch no input
  reaches), ``work-only`` (only the solver's path and iteration counts change, the answer is
  certified either way) or ``removed`` (the dead code they mutated was deleted after the run).

"score" is caught / mutants; "score*" leaves out the equivalent, unreachable and removed
mutants (the usual definition of a mutation score); work-only mutants count as not killed
in both.

    python tools/mutation_summary.py [--all]   # --all also lists the mutants not checked
"""

import json
import sys
from collections import Counter
from pathlib import Path

from mutmut.stats import status_by_exit_code

CAUGHT = ("killed", "timeout", "segfault", "killed by hand")
UNKILLABLE = ("equivalent", "unreachable", "removed")
HERE = Path(__file__).parent


def _entries(name: str) -> list[list[str]]:
    """Lines of a list beside this script, split into words; '#' starts a comment."""
    path = HERE / name
    if not path.exists():
        return []
    lines = (line.split("#", 1)[0].split() for line in path.read_text().splitlines())
    return [words for words in lines if words]


def main():
    by_hand = {words[0] for words in _entries("mutation_hand_kills.txt")}
    verdicts = {words[0]: words[1] for words in _entries("mutation_verdicts.txt")}
    columns = ("killed", "timeout", "segfault", "killed by hand", "equivalent", "unreachable",
               "removed", "work-only", "survived")  # fmt: skip
    print(f"{'module':32s} {'mutants':>7s} " + " ".join(f"{c[:8]:>8s}" for c in columns)
          + f" {'score':>6s} {'score*':>6s}")  # fmt: skip
    not_killed = []
    for meta in sorted(Path("mutants").rglob("*.py.meta")):
        codes = json.loads(meta.read_text())["exit_code_by_key"]
        statuses = {name: status_by_exit_code[code] for name, code in codes.items()}
        for name, status in statuses.items():
            if status in CAUGHT or status == "not checked":
                continue
            if name in by_hand:
                statuses[name] = "killed by hand"
            elif name in verdicts and status == "survived":
                statuses[name] = verdicts[name]
        counts = Counter(statuses.values())
        if counts["not checked"] == len(codes):
            continue
        caught = sum(counts[status] for status in CAUGHT)
        unkillable = sum(counts[status] for status in UNKILLABLE)
        score = caught / len(codes) if codes else float("nan")
        textbook = caught / (len(codes) - unkillable) if len(codes) > unkillable else float("nan")
        module = str(meta.relative_to("mutants"))[: -len(".meta")]
        print(f"{module:32s} {len(codes):7d} " + " ".join(f"{counts[c]:8d}" for c in columns)
              + f" {score:6.1%} {textbook:6.1%}")  # fmt: skip
        not_killed += [(n, s) for n, s in statuses.items() if s not in CAUGHT]
    for name, status in sorted(not_killed):
        if status != "not checked" or "--all" in sys.argv:
            print(f"    {status:12s} {name}")


if __name__ == "__main__":
    main()
