"""Saving and loading DMPs: exact round trip, clear errors."""

import dataclasses
import errno
import io as io_module
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from problems import random_discrete, random_rhythmic

from dmpopt import DiscreteDMP, FileFormatError, ResourceLimitError, io, load, save, validation

DISCRETE = random_discrete(seed=5)


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
    with pytest.raises(FileFormatError, match="format version 99; this dmpopt reads version 2"):
        load(path)


def _every_field_non_default():
    """A DMP whose every constructor field differs from its default."""
    dmp = random_discrete(
        seed=4,
        form="acceleration",
        goal_scaling="paper",
        reference_displacement=np.array([0.25, -1.5]),
        alpha_z=30.0,
        beta_z=7.0,
        alpha_v=20.0,
        beta_v=4.0,
        alpha_g=11.0,
    )
    for field in dataclasses.fields(dmp):
        if field.init and field.default is not dataclasses.MISSING:
            assert getattr(dmp, field.name) is not field.default, field.name
            assert not np.array_equal(getattr(dmp, field.name), field.default), field.name
    return dmp


def _assert_same_fields(a, b):
    assert type(a) is type(b)
    for field in dataclasses.fields(a):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), field.name
        else:
            assert type(x) is type(y) and x == y, field.name


def test_every_field_set_to_a_non_default_value_round_trips_exactly(tmp_path):
    dmp = _every_field_non_default()
    _assert_same_fields(dmp, load(save(dmp, tmp_path / "all_fields")))


def test_a_field_added_later_is_saved_without_changing_io(tmp_path, monkeypatch):
    """io iterates the dataclass fields: a new array or scalar field is carried as it is."""

    @dataclasses.dataclass(frozen=True, eq=False)
    class ExtendedDMP(DiscreteDMP):
        demonstrated_velocity: np.ndarray | None = None
        label: str = "none"

    monkeypatch.setitem(io.CLASSES, "ExtendedDMP", ExtendedDMP)
    fields = {f.name: getattr(DISCRETE, f.name) for f in dataclasses.fields(DISCRETE) if f.init}
    dmp = ExtendedDMP(**fields, demonstrated_velocity=np.array([0.5, -0.25]), label="reach")
    _assert_same_fields(dmp, load(save(dmp, tmp_path / "extended")))


def test_an_older_file_without_a_later_field_loads_with_its_default(tmp_path):
    path = save(DISCRETE, tmp_path / "old")
    with np.load(path) as archive:
        contents = dict(archive)
    header = json.loads(str(contents["header"]))
    del header["scalars"]["alpha_g"]  # as written before alpha_g existed
    contents["header"] = np.array(json.dumps(header))
    np.savez(path, **contents)
    assert load(path).alpha_g == DISCRETE.alpha_z / 2


def test_a_file_with_unknown_fields_asks_for_an_upgrade(tmp_path):
    path = save(DISCRETE, tmp_path / "new")
    with np.load(path) as archive:
        contents = dict(archive)
    np.savez(path, **contents, start_acceleration=np.zeros(2))
    with pytest.raises(FileFormatError, match=r"fields \['start_acceleration'\] .* upgrade"):
        load(path)


def test_save_and_load_apply_the_same_suffix_rule(tmp_path):
    written = save(DISCRETE, tmp_path / "reach")
    assert written == tmp_path / "reach.npz"
    _assert_same_fields(load(tmp_path / "reach"), load(str(written)))


def test_failed_overwrite_keeps_the_previous_file(tmp_path, monkeypatch):
    """The writer dies midway: the old file is intact and no partial file is left behind."""
    path = save(DISCRETE, tmp_path / "dmp")

    def dying_writer(stream, **arrays):
        stream.write(b"PK\x03\x04 half a zip")
        raise OSError("disk full")

    monkeypatch.setattr(io.np, "savez", dying_writer)
    with pytest.raises(OSError, match="disk full"):
        save(random_discrete(seed=9), path)
    monkeypatch.undo()
    _assert_same_fields(DISCRETE, load(path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dmp.npz"]


def test_file_size_limit_during_overwrite_keeps_the_previous_file(tmp_path):
    """Reproduces issue 13: an overwrite beyond RLIMIT_FSIZE used to destroy the old file."""
    path = save(DISCRETE, tmp_path / "dmp")
    script = (
        "import resource, signal, sys\n"
        "sys.path.insert(0, sys.argv[2])\n"
        "from problems import random_discrete\n"
        "from dmpopt import save\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (2000, 2000))\n"
        "try:\n"
        "    save(random_discrete(n_basis=400), sys.argv[1])\n"
        "except OSError as error:\n"
        "    print(error.errno)\n"
    )
    tests = str(Path(__file__).parents[1])
    result = subprocess.run(
        [sys.executable, "-c", script, str(path), tests], capture_output=True, text=True
    )
    assert result.stdout.strip() == str(errno.EFBIG), result.stderr
    _assert_same_fields(DISCRETE, load(path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dmp.npz"]


def _write_version_1(path, cls, scalars, arrays):
    """A file as dmpopt wrote it before version 2, with the former field names."""
    header = {"format": "dmpopt-dmp", "version": 1, "class": cls, "scalars": scalars}
    np.savez(path, header=np.array(json.dumps(header)), **arrays)
    return path


def test_a_version_1_discrete_file_loads_under_the_new_names(tmp_path):
    arrays = {
        "weights": np.array([[1.0, -2.0, 3.0]]),
        "start": np.array([0.5]),
        "goal": np.array([1.5]),
        "centres": np.array([0.1, 0.5, 0.9]),
        "widths": np.array([10.0, 20.0, 30.0]),
        "scaled_start_velocity": np.array([0.25]),
    }
    scalars = {
        "time_constant": 0.7,
        "form": "acceleration",
        "goal_scaling": "translation",
        "reference_displacement": None,
        "stiffness": 30.0,
        "damping": 7.0,
        "phase_stiffness": 20.0,
        "phase_damping": 4.0,
        "goal_rate": 11.0,
    }
    dmp = load(_write_version_1(tmp_path / "v1.npz", "DiscreteDMP", scalars, arrays))
    expected = {"tau": 0.7, "alpha_z": 30.0, "beta_z": 7.0, "alpha_v": 20.0, "beta_v": 4.0}
    assert {name: getattr(dmp, name) for name in expected} == expected
    assert dmp.alpha_g == 11.0 and dmp.form == "acceleration"
    np.testing.assert_array_equal(dmp.weights, arrays["weights"])


@pytest.mark.parametrize("form, rate", [("phase", "alpha_r"), ("energy", "alpha_E")])
def test_a_version_1_rhythmic_file_maps_amplitude_rate_by_form(tmp_path, form, rate):
    """amplitude_rate was alpha_r of eq. (11) or alpha_E of eq. (13); frequency was k."""
    arrays = {
        "weights": np.ones((1, 2, 2)),
        "setpoint": np.array([0.0]),
        "centres": np.array([0.0, np.pi]),
        "widths": np.array([2.0, 2.0]),
    }
    scalars = {"time_constant": 0.3, "form": form, "amplitude_rate": 7.5, "frequency": 2.0}
    dmp = load(_write_version_1(tmp_path / "v1.npz", "RhythmicDMP", scalars, arrays))
    assert getattr(dmp, rate) == 7.5 and dmp.k == 2.0 and dmp.tau == 0.3
    other = "alpha_E" if rate == "alpha_r" else "alpha_r"
    assert getattr(dmp, other) == 10.0  # the default: the file did not set it


def test_a_version_2_file_with_a_former_name_is_refused(tmp_path):
    path = save(DISCRETE, tmp_path / "v2")
    with np.load(path) as archive:
        contents = dict(archive)
    header = json.loads(str(contents["header"]))
    header["scalars"]["stiffness"] = header["scalars"].pop("alpha_z")
    contents["header"] = np.array(json.dumps(header))
    np.savez(path, **contents)
    with pytest.raises(FileFormatError, match=r"\['stiffness'\]"):
        load(path)


def test_a_version_1_file_with_a_field_under_both_names_is_refused(tmp_path):
    """time_constant (version 1) and tau (version 2) both present: one used to win silently."""
    arrays = {"weights": np.ones((1, 2)), "start": [0.0], "goal": [1.0]}
    arrays |= {"centres": np.array([0.2, 0.8]), "widths": np.array([5.0, 5.0])}
    scalars = {"time_constant": 0.7, "tau": 0.9, "goal_scaling": "translation"}
    path = _write_version_1(tmp_path / "v1.npz", "DiscreteDMP", scalars, arrays)
    with pytest.raises(FileFormatError) as error:
        load(path)
    assert str(error.value) == (
        f"{path} is a version 1 file holding both 'tau' and 'time_constant', two names of the "
        "field 'tau'; keep one (version 1 wrote the former names only)"
    )


def _zip_of(path, members: dict, compression=zipfile.ZIP_DEFLATED):
    """A zip of raw .npy bytes by name (np.savez's layout) written by hand."""
    with zipfile.ZipFile(path, "w", compression) as archive:
        for name, data in members.items():
            archive.writestr(f"{name}.npy", data)
    return path


def _npy(array) -> bytes:
    stream = io_module.BytesIO()
    np.lib.format.write_array(stream, np.asarray(array))
    return stream.getvalue()


def test_a_file_inflating_beyond_the_memory_budget_is_refused_before_inflating(
    tmp_path, monkeypatch
):
    """The budget lowered to 1 MiB and a 4 MiB array of zeros, deflated to a few kB: the zip
    header's size (written by zipfile, the answer key) is refused before any array is read
    (once, a 10 MB file that inflated to 4.8 GB ran a minute into a MemoryError)."""
    monkeypatch.setattr(validation, "MEMORY_BUDGET", 2**20)
    header = json.dumps({"format": "dmpopt-dmp", "version": 2, "class": "DiscreteDMP"})
    members = {"header": _npy(np.array(header)), "weights": _npy(np.zeros(2**19))}
    path = _zip_of(tmp_path / "bomb.npz", members)
    with zipfile.ZipFile(path) as archive:
        inflated = sum(member.file_size for member in archive.infolist())
    assert path.stat().st_size < 20_000 and inflated > 2**22
    reads = []
    monkeypatch.setattr(np.lib.format, "read_array", lambda *a, **k: reads.append(a))
    with pytest.raises(ResourceLimitError) as error:
        load(path)
    assert reads == []
    assert str(error.value) == (
        f"load({str(path)!r}) of 2 arrays needs about {inflated / 1024**3:.3g} GiB; dmpopt "
        "allows at most 0.000977 GiB (dmpopt.validation.MEMORY_BUDGET): this is not a DMP file "
        "dmpopt wrote; check where it came from"
    )


def test_an_array_header_claiming_more_than_its_entry_holds_is_refused(tmp_path):
    """A .npy header announcing 10^11 floats in an entry of a few bytes: corrupt, refused
    before numpy allocates the 800 GB it announces."""
    stream = io_module.BytesIO()
    npy_header = {"descr": "<f8", "fortran_order": False, "shape": (10**11,)}
    np.lib.format.write_array_header_1_0(stream, npy_header)
    stream.write(bytes(80))
    header = json.dumps({"format": "dmpopt-dmp", "version": 2, "class": "DiscreteDMP"})
    path = _zip_of(
        tmp_path / "liar.npz", {"header": _npy(np.array(header)), "w": stream.getvalue()}
    )
    with pytest.raises(FileFormatError) as error:
        load(path)
    assert str(error.value) == (
        f"{path} is corrupt: w.npy claims an array of (100000000000,) float64 (800000000000 "
        f"bytes) in {len(stream.getvalue())} bytes"
    )
