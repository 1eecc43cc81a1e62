#!/usr/bin/env bash
# Mutation testing of the core modules: docs/mutation.md. From anywhere:
#   tools/mutation.sh                       # every mutant of [tool.mutmut] only_mutate
#   tools/mutation.sh "dmpopt.stepper*"     # only some mutants (mutmut's name globs)
# Needs mutmut >= 3.8 (pip install -e .[dev]); MUTMUT overrides the executable.
set -euo pipefail
cd "$(dirname "$0")/.."
export PYTHONPATH="$PWD/tools${PYTHONPATH:+:$PYTHONPATH}"
"${MUTMUT:-mutmut}" run --max-children "${MAX_CHILDREN:-2}" "$@"
"${PYTHON:-python}" tools/mutation_summary.py
