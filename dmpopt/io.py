"""Saving and loading DMPs: a versioned ``.npz`` file with an exact round trip.

The file holds one JSON header (format name, version, class, scalar fields) and the arrays
in binary float64, so that ``load(save(dmp))`` reproduces every parameter bit for bit.
"""

from __future__ import annotations

import dataclasses
import json
import zipfile
from pathlib import Path

import numpy as np

from .dmp import DiscreteDMP, RhythmicDMP
from .exceptions import FileFormatError, InvalidInputError

FORMAT = "dmpopt-dmp"
VERSION = 1
CLASSES = {"DiscreteDMP": DiscreteDMP, "RhythmicDMP": RhythmicDMP}


def save(dmp, path) -> Path:
    """Write ``dmp`` to ``path`` (``.npz`` is appended if missing); return the path."""
    if type(dmp).__name__ not in CLASSES:
        raise InvalidInputError(
            f"dmp must be a DiscreteDMP or RhythmicDMP, got {type(dmp).__name__}"
        )
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_name(path.name + ".npz")
    arrays, scalars = {}, {}
    for field in dataclasses.fields(dmp):
        value = getattr(dmp, field.name)
        if isinstance(value, np.ndarray):
            arrays[field.name] = value
        elif field.init:
            scalars[field.name] = value
    header = {
        "format": FORMAT,
        "version": VERSION,
        "class": type(dmp).__name__,
        "scalars": scalars,
    }
    with open(path, "wb") as stream:
        np.savez(stream, header=np.array(json.dumps(header)), **arrays)
    return path


def load(path):
    """Read a DMP written by :func:`save`.

    Raises
    ------
    FileFormatError
        If the file is missing, corrupt, not written by dmpopt, or of a newer version.
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"no DMP file at {path}")
    try:
        with np.load(path, allow_pickle=False) as archive:
            if "header" not in archive.files:
                raise FileFormatError(f"{path} is not a dmpopt DMP file (no header)")
            header = json.loads(str(archive["header"]))
            arrays = {name: archive[name] for name in archive.files if name != "header"}
    except FileFormatError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, json.JSONDecodeError, EOFError) as error:
        raise FileFormatError(f"{path} is corrupt or not a dmpopt DMP file: {error}") from error
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise FileFormatError(f"{path} is not a dmpopt DMP file (format {header!r})")
    if header.get("version") != VERSION:
        raise FileFormatError(
            f"{path} has format version {header.get('version')!r}; this dmpopt reads "
            f"version {VERSION}: upgrade dmpopt"
        )
    cls = CLASSES.get(header.get("class"))
    if cls is None:
        raise FileFormatError(f"{path} holds an unknown class {header.get('class')!r}")
    try:
        return cls(**header["scalars"], **arrays)
    except (TypeError, ValueError, KeyError) as error:
        raise FileFormatError(f"{path} has inconsistent contents: {error}") from error
