"""Apply one mutmut mutant to the working tree, to check by hand that a test kills it.

    python tools/apply_mutant.py NAME [--mutants DIR]   # then run the test, then
    git checkout dmpopt/                                 # to restore the sources

``mutmut show NAME`` prints the mutated function as a diff whose lines are indented as in a
top-level function; this script finds the removed lines inside that function of the source
file and puts the added lines there, at the source's indentation. Run it from the repository
whose sources should change; ``--mutants`` names the directory of the mutmut run (default:
the current one) when the run lives elsewhere.
"""

import argparse
import os
import subprocess
import sys
from pathlib import Path


def mutant_diff(name: str, run_directory: Path) -> list[str]:
    shown = subprocess.run(
        ["mutmut", "show", name], cwd=run_directory, capture_output=True, text=True, check=True
    )
    return shown.stdout.splitlines()


def function_name(name: str) -> str:
    """``dmpopt.a.xǁClassǁmethod__mutmut_3`` -> ``method``; ``dmpopt.a.x_function__mutmut_3``
    -> ``function``."""
    stem = name.rsplit(".", 1)[1].rsplit("__mutmut_", 1)[0]
    return stem.rsplit("ǁ", 1)[1] if "ǁ" in stem else stem[2:]


def apply(name: str, run_directory: Path) -> Path:
    lines = mutant_diff(name, run_directory)
    path = Path(lines[1].removeprefix("--- ").strip())
    body = [line for line in lines[3:] if line[:1] in "-+ "]
    removed = [line[1:] for line in body if line.startswith("-")]
    added = [line[1:] for line in body if line.startswith("+")]
    source = path.read_text().splitlines()
    start = next(
        i for i, line in enumerate(source)
        if line.lstrip().startswith((f"def {function_name(name)}(",
                                     f"async def {function_name(name)}("))
    )  # fmt: skip
    shown_indent = len(removed[0]) - len(removed[0].lstrip()) if removed else 0
    for i in range(start, len(source) - len(removed) + 1):
        window = source[i : i + len(removed)]
        if [s.strip() for s in window] == [r.strip() for r in removed]:
            indent = len(window[0]) - len(window[0].lstrip()) - shown_indent
            source[i : i + len(removed)] = [" " * indent + a if a.strip() else a for a in added]
            path.write_text("\n".join(source) + "\n")
            return path
    sys.exit(f"{name}: the removed lines were not found in {path}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name")
    parser.add_argument("--mutants", type=Path, default=Path(os.getcwd()))
    arguments = parser.parse_args()
    print(f"applied to {apply(arguments.name, arguments.mutants)}")


if __name__ == "__main__":
    main()
