"""Saving and loading DMPs: a versioned ``.npz`` file with an exact round trip.

The file holds one JSON header (format name, version, class, scalar fields) and the arrays
in binary float64, so that ``load(save(dmp))`` reproduces every parameter bit for bit. The
fields are those of the DMP's dataclass, whatever they are, so a new field needs no change
here. Both functions append ``.npz`` to a path without it; saving writes a temporary file
beside the target and renames it, so a failed save never destroys an earlier file.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import secrets
import zipfile
from pathlib import Path

import numpy as np
from numpy.lib import format as npy

from .cartesian import CartesianDMP
from .dmp import RENAMED, DiscreteDMP, RhythmicDMP
from .exceptions import FileFormatError, InvalidInputError, ResourceLimitError
from .promp import ProMP
from .validation import check_resources

FORMAT = "dmpopt-dmp"
VERSION = 2
"""Written by :func:`save`; :func:`load` reads this version and every older one. A file
lacking a field (written before the field existed) gets the field's default. Version 2
named the fields after the paper's symbols (``tau``, ``alpha_z``, ...); a version 1 file's
fields are renamed on loading (:func:`_renamed`)."""
CLASSES = {
    "DiscreteDMP": DiscreteDMP,
    "RhythmicDMP": RhythmicDMP,
    "CartesianDMP": CartesianDMP,
    "ProMP": ProMP,
}
"""The classes a file may hold (``CartesianDMP`` and ``ProMP`` since the version 2 format,
which they share: their files do not change how older files read)."""
SCALAR_TYPES = (type(None), bool, int, float, str)


def _file_path(path) -> Path:
    """``path`` with ``.npz`` appended if missing: the same rule for save and load."""
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidInputError(f"path must be a str or os.PathLike, got {type(path).__name__}")
    path = Path(path)
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")


def _split_fields(dmp) -> tuple[dict, dict]:
    """Every constructor field of ``dmp``: arrays (binary) and scalars (JSON)."""
    arrays, scalars = {}, {}
    for field in dataclasses.fields(dmp):
        if not field.init:
            continue
        value = getattr(dmp, field.name)
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, np.ndarray):
            arrays[field.name] = value
        elif isinstance(value, SCALAR_TYPES):
            scalars[field.name] = value
        else:
            raise InvalidInputError(
                f"field {field.name} of {type(dmp).__name__} holds a {type(value).__name__}, "
                "which a DMP file cannot store (arrays, numbers, strings, None)"
            )
    return arrays, scalars


def save(dmp, path) -> Path:
    """Write every field of ``dmp`` to ``path`` (``.npz`` appended if missing); return the path.

    The file is written beside the target and then renamed over it, so an interrupted or
    failed save leaves any previous file at ``path`` intact.
    """
    if type(dmp).__name__ not in CLASSES:
        raise InvalidInputError(f"dmp must be one of {sorted(CLASSES)}, got {type(dmp).__name__}")
    path = _file_path(path)
    if not path.parent.is_dir():
        raise InvalidInputError(f"path {path}: folder {path.parent} does not exist; create it")
    arrays, scalars = _split_fields(dmp)
    header = {
        "format": FORMAT,
        "version": VERSION,
        "class": type(dmp).__name__,
        "scalars": scalars,
    }
    partial = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    try:  # 0o666 and the umask: the permissions of a plain new file
        with os.fdopen(os.open(partial, flags, 0o666), "wb") as stream:
            np.savez(stream, header=np.array(json.dumps(header)), **arrays)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(partial, path)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    return path


def load(path):
    """Read a DMP written by :func:`save` (``.npz`` appended to ``path`` if missing).

    Raises
    ------
    FileFormatError
        If the file is missing, corrupt, not written by dmpopt, or of a newer version.
    ResourceLimitError
        If its arrays would need more than :data:`dmpopt.validation.MEMORY_BUDGET` (from the
        file's headers, before anything is inflated).
    """
    path = _file_path(path)
    if not path.is_file():
        raise FileFormatError(f"no DMP file at {path}")
    try:
        _check_sizes(path)
        with np.load(path, allow_pickle=False) as archive:
            if "header" not in archive.files:
                raise FileFormatError(f"{path} is not a dmpopt DMP file (no header)")
            header = json.loads(str(archive["header"]))
            arrays = {name: archive[name] for name in archive.files if name != "header"}
    except (FileFormatError, ResourceLimitError):
        raise
    except (OSError, ValueError, zipfile.BadZipFile, json.JSONDecodeError, EOFError) as error:
        raise FileFormatError(f"{path} is corrupt or not a dmpopt DMP file: {error}") from error
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise FileFormatError(f"{path} is not a dmpopt DMP file (format {header!r})")
    version = header.get("version")
    if not isinstance(version, int) or not 1 <= version <= VERSION:
        raise FileFormatError(
            f"{path} has format version {version!r}; this dmpopt reads version {VERSION} "
            "and older: upgrade dmpopt"
        )
    cls = CLASSES.get(header.get("class"))
    if cls is None:
        raise FileFormatError(f"{path} holds an unknown class {header.get('class')!r}")
    values = {**header.get("scalars", {}), **arrays}
    if version < 2:
        values = _renamed(values, path)
    known = {field.name for field in dataclasses.fields(cls) if field.init}
    unknown = sorted(set(values) - known)
    if unknown:
        raise FileFormatError(
            f"{path} has fields {unknown} that this dmpopt's {cls.__name__} lacks: upgrade dmpopt"
        )
    try:
        return cls(**values)
    except (TypeError, ValueError, KeyError) as error:
        raise FileFormatError(f"{path} has inconsistent contents: {error}") from error


def _check_sizes(path: Path) -> None:
    """Refuse, before inflating anything, a file whose arrays would need more than
    :data:`dmpopt.validation.MEMORY_BUDGET`: the sizes come from the zip's headers and from
    each array's ``.npy`` header (shape and type), which must fit in its zip entry (a 10 MB
    file that inflated to 4.8 GB ran a minute into a MemoryError)."""
    readers = {(1, 0): npy.read_array_header_1_0, (2, 0): npy.read_array_header_2_0}
    with zipfile.ZipFile(path) as archive:
        members = archive.infolist()
        check_resources(
            f"load({str(path)!r}) of {len(members)} arrays",
            sum(member.file_size for member in members),
            "this is not a DMP file dmpopt wrote; check where it came from",
        )
        for member in members:
            with archive.open(member) as stream:
                version = npy.read_magic(stream)
                if version not in readers:
                    raise FileFormatError(f"{path}: {member.filename} is in .npy {version}")
                shape, _, dtype = readers[version](stream)
                n_bytes = math.prod(shape) * dtype.itemsize
                if n_bytes > member.file_size:
                    raise FileFormatError(
                        f"{path} is corrupt: {member.filename} claims an array of {shape} "
                        f"{dtype} ({n_bytes} bytes) in {member.file_size} bytes"
                    )


def _renamed(values: dict, path: Path) -> dict:
    """Fields of a version 1 file under their version 2 names (:data:`dmpopt.dmp.RENAMED`);
    a file holding a field under both names is refused (one would silently win)."""
    renamed, sources = {}, {}
    for name, value in values.items():
        new = RENAMED.get(name, name)
        if name == "amplitude_rate" and values.get("form") == "energy":
            new = "alpha_E"
        if new in sources:
            first, second = sorted((sources[new], name))
            raise FileFormatError(
                f"{path} is a version 1 file holding both {first!r} and {second!r}, two names "
                f"of the field {new!r}; keep one (version 1 wrote the former names only)"
            )
        renamed[new], sources[new] = value, name
    return renamed
