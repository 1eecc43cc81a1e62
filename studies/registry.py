"""The studies that the ``dmpopt`` command lists and runs, and the page it writes after them.

dmpopt never imports this package by name: ``pyproject.toml`` declares :func:`available` and
:func:`dmpopt_studies.report.write_report` under the entry-point group ``dmpopt.studies``, and the
command loads them from there (:func:`dmpopt.cli.entry_point`). Adding a study is one name in
:data:`STUDIES` (and its module).
"""

from __future__ import annotations

import importlib

STUDIES = (
    "imitation",
    "constrained",
    "rl",
    "recognition",
    "humanoid",
    "biped",
    "cartesian",
    "primitives",
    "feasible",
)
"""Every study, in the order ``dmpopt study list`` shows and ``run all`` runs them."""


def available() -> dict:
    """Study name -> module, for the studies installed with this version (a study whose
    module is missing is left out; an error inside one is raised)."""
    found = {}
    for name in STUDIES:
        try:
            found[name] = importlib.import_module(f"{__package__}.{name}")
        except ModuleNotFoundError as error:
            if error.name != f"{__package__}.{name}":
                raise
    return found
