"""Helpers shared by the studies: output folders, metrics files, figures, timing."""

from __future__ import annotations

import json
import platform
import time
from importlib import metadata
from pathlib import Path

import numpy as np

PACKAGES = ("dmpopt", "numpy", "scipy", "casadi", "pin", "proxsuite", "toppra", "matplotlib")


def output_dir(out_dir) -> Path:
    """Create (if needed) and return the study's output folder."""
    path = Path(out_dir)
    path.mkdir(parents=True, exist_ok=True)
    return path


def versions() -> dict:
    """Installed versions of the packages a result depends on."""
    found = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found


def _plain(value):
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_metrics(out_dir, study: str, metrics: dict, parameters: dict, seed: int, quick: bool):
    """Write ``metrics.json`` with the seed, parameters and package versions; return it."""
    record = {
        "study": study,
        "quick": quick,
        "seed": seed,
        "parameters": parameters,
        "versions": versions(),
        **metrics,
    }
    record = _plain(record)
    path = output_dir(out_dir) / "metrics.json"
    path.write_text(json.dumps(record, indent=2) + "\n")
    return record


def pyplot():
    """matplotlib's pyplot on the non-interactive Agg backend (clear error if missing)."""
    try:
        import matplotlib
    except ImportError as error:
        from dmpopt.exceptions import MissingDependency

        raise MissingDependency(
            "the studies draw figures with matplotlib: pip install 'dmpopt[plot]'"
        ) from error
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def median_time(function, repeats: int = 20) -> float:
    """Median wall time of ``function()`` over ``repeats`` calls [s]."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return float(np.median(times))
