"""pytest plugin for mutation runs (loaded by tools/mutation.sh, not by ordinary runs).

The symbolic systems are built once and memoised (``functools.lru_cache``). A mutant of a
function used while building them would otherwise never be seen: mutmut forks each run
from a process whose caches hold systems built from the original code, and it maps tests
to functions in one process where only the first test builds each system. So the caches
of every dmpopt module are emptied at the start of each session and, while mutmut maps
tests to functions, before each test. Hypothesis does not shrink (a killed mutant needs no
minimal example) and keeps no database.
"""

import functools
import os
import sys

from hypothesis import Phase, settings

settings.register_profile(
    "mutation", phases=[Phase.explicit, Phase.reuse, Phase.generate], database=None
)
settings.load_profile("mutation")


def clear_caches() -> None:
    """Empty the memoised functions and recalled answers of every loaded dmpopt module."""
    recall = sys.modules.get("dmpopt.fitting._recall")
    for name, module in list(sys.modules.items()):
        if name == "dmpopt" or name.startswith("dmpopt."):
            for value in list(vars(module).values()):
                if isinstance(value, functools._lru_cache_wrapper):
                    value.cache_clear()
                elif recall is not None and isinstance(value, recall.Recall):
                    value.clear()


def pytest_sessionstart(session):
    clear_caches()


def pytest_runtest_setup(item):
    if os.environ.get("MUTANT_UNDER_TEST") == "stats":
        clear_caches()
