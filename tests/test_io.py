"""Saving and loading DMPs: exact round trip, clear errors."""

import dataclasses
import json

import numpy as np
import pytest
from problems import random_discrete, random_rhythmic

from dmpopt import FileFormatError, load, save


@pytest.mark.parametrize(
    "dmp",
    [
        random_discrete(seed=1, form="acceleration"),
        random_rhythmic(seed=2, form="energy"),
        random_discrete(seed=3, goal_scaling="translation", reference_displacement=None),
    ],
)
def test_round_trip_is_exact(tmp_path, dmp):
    loaded = load(save(dmp, tmp_path / "movement"))
    assert type(loaded) is type(dmp)
    for field in dataclasses.fields(dmp):
        a, b = getattr(dmp, field.name), getattr(loaded, field.name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and np.array_equal(a, b)
        else:
            assert a == b
    assert np.array_equal(dmp.rollout(0.3).positions, loaded.rollout(0.3).positions)


def test_corrupt_and_foreign_files(tmp_path):
    broken = tmp_path / "broken.npz"
    broken.write_bytes(b"not a zip file")
    with pytest.raises(FileFormatError, match="corrupt or not a dmpopt DMP file"):
        load(broken)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.zeros(3))
    with pytest.raises(FileFormatError, match="not a dmpopt DMP file"):
        load(foreign)
    with pytest.raises(FileFormatError, match="no DMP file at"):
        load(tmp_path / "missing.npz")


def test_newer_version_is_refused(tmp_path):
    path = save(random_discrete(), tmp_path / "dmp")
    with np.load(path) as archive:
        contents = dict(archive)
    header = json.loads(str(contents["header"]))
    header["version"] = 99
    contents["header"] = np.array(json.dumps(header))
    np.savez(path, **contents)
    with pytest.raises(FileFormatError, match="format version 99; this dmpopt reads version 1"):
        load(path)
