"""The ``dmpopt`` command, staged study output, and where caches go (never into the package)."""

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from dmpopt_studies.common import write_text_atomic
from dmpopt_studies.report import write_report
from hypothesis import given, settings
from hypothesis import strategies as st

import dmpopt
from dmpopt import Trajectory, cli, fit_discrete, symbolic
from dmpopt.exceptions import FittingFailed
from dmpopt.folders import staged_output

REPO = Path(__file__).resolve().parents[2]


def run_cli(capsys, *argv):
    """Exit code, stdout and stderr of ``dmpopt argv``."""
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def fake_run(seed_box, fail_with=None):
    """A study run that writes a figure and metrics; raises ``fail_with`` between the two."""

    def run(out_dir, quick=False, seed=0):
        (Path(out_dir) / "figure.png").write_text(f"figure of seed {seed}")
        seed_box.append(seed)
        if fail_with is not None:
            raise fail_with
        (Path(out_dir) / "metrics.json").write_text(json.dumps({"seed": seed}))
        return {"seed": seed}

    return run


def contents(folder: Path) -> dict:
    return {p.name: p.read_text() for p in sorted(folder.iterdir())}


# ------------------------------------------------------------------ one-line errors


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["study", "run", "nonsense"],
            r"unknown study 'nonsense'; choose from imitation, .* 'all'",
        ),
        (["study", "run", "rl", "--seed", "-1"], r"--seed: expected an integer >= 0, got '-1'"),
        (["study", "run", "rl", "--seed", "abc"], r"--seed: expected an integer >= 0, got 'abc'"),
        (["study", "run", "rl", "--seed", "1.5"], r"--seed: expected an integer >= 0, got '1.5'"),
        (["study", "run", "rl", "--out", ""], r"--out is empty; give the folder"),
        (["study", "run", "rl", "--bogus"], r"unrecognized arguments: --bogus"),
        (["study", "run", "rl", "--workers", "0"], r"--workers: expected an integer >= 1"),
        (["study", "run", "rl", "--workers", "two"], r"--workers: expected an integer >= 1"),
        (["study", "run", "rl", "--ray", "nohost"], r"--ray: .*'HOST:PORT', got 'nohost'"),
        (["study"], r"required: action .*'dmpopt study --help'"),
        ([], r"required: command"),
    ],
)
def test_bad_arguments_give_one_line_and_exit_code_2(capsys, argv, message):
    """Each bad value: one line on stderr naming the argument, exit code 2, nothing run."""
    code, out, err = run_cli(capsys, *argv)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("dmpopt: error: ")
    assert re.search(message, err)


def test_unwritable_out_is_one_line(capsys, tmp_path):
    """--out under a file, or naming a file, is refused before any study runs."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    for out, message in [
        (blocker / "results", r"--out .*/file/results: cannot write there \(Not a directory\)"),
        (blocker, r"--out .*/file is a file, not a folder"),
    ]:
        code, stdout, err = run_cli(capsys, "study", "run", "imitation", "--out", str(out))
        assert (code, stdout, err.count("\n")) == (2, "", 1)
        assert re.search(message, err)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes everywhere")
def test_read_only_out_is_one_line(capsys, tmp_path):
    tmp_path.chmod(0o500)
    try:
        code, _, err = run_cli(capsys, "study", "run", "imitation", "--out", str(tmp_path))
    finally:
        tmp_path.chmod(0o700)
    assert code == 2 and "cannot write there (Permission denied)" in err


@settings(max_examples=40, deadline=None)
@given(st.one_of(st.integers(-(10**30), 10**30).map(str), st.text(max_size=8)))
def test_seed_accepts_exactly_the_non_negative_integers(text):
    try:
        expected = int(text)
    except ValueError:
        expected = -1
    if expected >= 0:
        assert cli._seed(text) == expected
    else:
        with pytest.raises(Exception, match="expected an integer >= 0"):
            cli._seed(text)


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out == f"dmpopt {dmpopt.__version__}\n"


def test_the_library_never_imports_the_studies():
    """Importing every dmpopt module (the command's too) loads no ``studies`` module, and no
    dmpopt file names the package in an import: the command finds the studies through the
    entry points of pyproject.toml. A one-line bug it catches: ``from dmpopt_studies.common import
    staged_output`` back in dmpopt/cli.py."""
    script = (
        "import pkgutil, importlib, sys, dmpopt\n"
        "for module in pkgutil.walk_packages(dmpopt.__path__, 'dmpopt.'):\n"
        "    importlib.import_module(module.name)\n"
        "top = {n.split('.')[0] for n in sys.modules}\n"
        "print(sorted(top & {'dmpopt_studies', 'dmpopt_robots'}))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, cwd=REPO, check=True
    )
    assert done.stdout.strip() == "[]"
    named = re.compile(r"^\s*(from|import)\s+studies\b", re.MULTILINE)
    offenders = [
        p.name for p in Path(dmpopt.__file__).parent.rglob("*.py") if named.search(p.read_text())
    ]
    assert offenders == []


def test_pyproject_declares_the_studies_and_the_report():
    """The entry points that the command loads name the registry's studies and the report."""
    tomllib = pytest.importorskip("tomllib")
    import importlib

    import dmpopt_studies.registry
    import dmpopt_studies.report

    declared = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["entry-points"]
    points = declared[cli.ENTRY_POINTS]
    loaded = {}
    for name, target in points.items():
        module, attribute = target.split(":")
        loaded[name] = getattr(importlib.import_module(module), attribute)
    assert loaded == {
        "available": dmpopt_studies.registry.available,
        "write_report": dmpopt_studies.report.write_report,
    }
    assert list(loaded["available"]()) == list(dmpopt_studies.registry.STUDIES)


def test_without_the_entry_points_the_command_says_how_to_install(capsys, monkeypatch):
    monkeypatch.setattr(cli.metadata, "entry_points", lambda group: [])
    code, out, err = run_cli(capsys, "study", "list")
    assert code == 2 and out == ""
    assert err == (
        "dmpopt: error: no studies are installed: the entry point 'available' of the group "
        "'dmpopt.studies' is missing; install dmpopt from its repository (pip install -e . or "
        "pip install .)\n"
    )


def test_list_shows_quick_and_full_times(capsys):
    """One row per study with the times the study module declares."""
    code, out, _ = run_cli(capsys, "study", "list")
    rows = out.splitlines()
    assert code == 0 and rows[0].split()[:3] == ["study", "--quick", "full"]
    studies = cli.available_studies()
    assert [row.split()[0] for row in rows[1:]] == list(studies)
    for row, module in zip(rows[1:], studies.values()):
        shown = [
            [f"~{round(seconds / 60)}", "min"] if seconds >= 90 else [f"~{seconds}", "s"]
            for seconds in (module.EXPECTED_SECONDS["quick"], module.EXPECTED_SECONDS["full"])
        ]
        assert row.split()[1:5] == shown[0] + shown[1]


# ------------------------------------------------------------------ nothing lost


def test_workers_reach_the_studies_that_take_a_runner(capsys, monkeypatch, tmp_path):
    """--workers N: a study taking ``runner`` gets Runner(workers=N); others run as before.
    (The machine's cores are set to 4 here: more workers than cores are cut to them.)"""
    from dmpopt_studies import constrained, imitation

    from dmpopt import parallel

    monkeypatch.setattr(parallel, "available_cores", lambda: 4)

    received = []

    def run_with_runner(out_dir, quick=False, seed=0, runner=None):
        received.append(runner)
        (Path(out_dir) / "metrics.json").write_text("{}")

    monkeypatch.setattr(imitation, "run", run_with_runner)
    monkeypatch.setattr(constrained, "run", fake_run([]))
    for name in ("imitation", "constrained"):
        argv = ("study", "run", name, "--out", str(tmp_path), "--workers", "3")
        assert run_cli(capsys, *argv)[0] == 0
    assert len(received) == 1
    assert (received[0].workers, received[0].ray, received[0].backend) == (3, None, "processes")


def test_workers_default_to_the_cores_and_are_cut_to_them_with_one_line(
    capsys, monkeypatch, tmp_path
):
    """No --workers: one process per core; --workers 100000 (once one process per queued
    run): the cores, with a one-line warning."""
    from dmpopt_studies import imitation

    from dmpopt import parallel

    received = []

    def run_with_runner(out_dir, quick=False, seed=0, runner=None):
        received.append(runner.workers)

    monkeypatch.setattr(parallel, "available_cores", lambda: 4)
    monkeypatch.setattr(imitation, "run", run_with_runner)
    argv = ("study", "run", "imitation", "--out", str(tmp_path))
    assert run_cli(capsys, *argv)[0] == 0
    code, _, err = run_cli(capsys, *argv, "--workers", "100000")
    assert (code, received) == (0, [4, 4])
    assert err == (
        "warning: workers=100000 is more than this machine's 4 cores; using 4 (more processes "
        "than cores only share them)\n"
    )


def test_interrupted_study_leaves_previous_output(capsys, monkeypatch, tmp_path):
    """Ctrl-C midway: one line, exit 130, the previous complete output intact, no leftovers."""
    from dmpopt_studies import imitation

    seeds = []
    monkeypatch.setattr(imitation, "run", fake_run(seeds))
    assert (
        run_cli(capsys, "study", "run", "imitation", "--out", str(tmp_path), "--seed", "1")[0] == 0
    )
    before = contents(tmp_path / "imitation")
    assert before == {"figure.png": "figure of seed 1", "metrics.json": '{"seed": 1}'}

    monkeypatch.setattr(imitation, "run", fake_run(seeds, KeyboardInterrupt()))
    code, _, err = run_cli(
        capsys, "study", "run", "imitation", "--out", str(tmp_path), "--seed", "2"
    )
    assert seeds == [1, 2]  # the second run did start writing
    assert (code, err) == (130, f"interrupted: {tmp_path / 'imitation'} left unchanged\n")
    assert contents(tmp_path / "imitation") == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imitation"]


def test_a_second_run_into_the_same_out_is_refused_before_writing(capsys, monkeypatch, tmp_path):
    """Another process holds --out (flock on the folder, taken here by a plain script): the
    run is refused with one line and exit 2, writes nothing and starts no study (once two
    runs at once mixed one seed's metrics with the other's figures). Once it is gone, the
    run goes ahead."""
    from dmpopt_studies import imitation

    seeds = []
    monkeypatch.setattr(imitation, "run", fake_run(seeds))
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import fcntl, os, sys, time\n"
            f"fd = os.open({str(tmp_path)!r}, os.O_RDONLY)\n"
            "fcntl.flock(fd, fcntl.LOCK_EX)\nprint('held', flush=True)\ntime.sleep(60)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline() == "held\n"
        code, _, err = run_cli(capsys, "study", "run", "imitation", "--out", str(tmp_path))
    finally:
        holder.kill()
        holder.wait()
    assert (code, seeds, list(tmp_path.iterdir())) == (2, [], [])
    assert err == (
        f"dmpopt: error: --out {tmp_path} is being written by another dmpopt run (one run at "
        "a time per output folder); wait for it to end or choose another --out\n"
    )
    assert run_cli(capsys, "study", "run", "imitation", "--out", str(tmp_path))[0] == 0
    assert seeds == [0]


def test_two_runs_at_once_publish_one_complete_run(tmp_path):
    """Two processes into one folder: while the first is inside staged_output (it waits for
    a line on stdin there), the second is refused before writing; the folder then holds the
    first run's files only."""
    script = (
        "import sys\n"
        "from pathlib import Path\n"
        "from dmpopt.folders import FolderInUse, staged_output\n"
        "seed = sys.argv[1]\n"
        "try:\n"
        f"    with staged_output(Path({str(tmp_path)!r}) / 'study') as folder:\n"
        "        (folder / 'figure.png').write_text(seed)\n"
        "        print('inside', flush=True)\n"
        "        sys.stdin.readline()\n"
        "        (folder / 'metrics.json').write_text(seed)\n"
        "except FolderInUse:\n"
        "    sys.exit(3)\n"
    )
    environment = {**os.environ, "PYTHONPATH": str(REPO)}
    pipes = {"stdin": subprocess.PIPE, "stdout": subprocess.PIPE, "text": True}
    first = subprocess.Popen([sys.executable, "-c", script, "1"], env=environment, **pipes)
    try:
        assert first.stdout.readline() == "inside\n"
        second = subprocess.run([sys.executable, "-c", script, "2"], env=environment, **pipes)
        first.stdin.write("go\n")
        first.stdin.close()
        assert (first.wait(timeout=60), second.returncode, second.stdout) == (0, 3, "")
    finally:
        first.kill()
    assert contents(tmp_path / "study") == {"figure.png": "1", "metrics.json": "1"}


@pytest.mark.parametrize(
    "error", [FittingFailed("no fit for demo 3"), OSError(28, "No space left on device")]
)
def test_failed_study_leaves_nothing(capsys, monkeypatch, tmp_path, error):
    """A study that fails on its first run: one line, exit 1, no folder at all."""
    from dmpopt_studies import imitation

    monkeypatch.setattr(imitation, "run", fake_run([], error))
    code, _, err = run_cli(capsys, "study", "run", "imitation", "--out", str(tmp_path))
    assert code == 1 and err.count("\n") == 1
    assert err.startswith(f"dmpopt: imitation failed: {error}")
    assert err.endswith(f"{tmp_path / 'imitation'} not written\n")
    assert list(tmp_path.iterdir()) == []


def test_interrupted_all_keeps_report_consistent(capsys, monkeypatch, tmp_path):
    """Interrupted at the second study of 'all': the first is replaced, the others kept, and
    report.html shows exactly the metrics now in the folders."""
    studies = cli.available_studies()
    for module in studies.values():
        monkeypatch.setattr(module, "run", fake_run([]))
    serial = ("study", "run", "all", "--out", str(tmp_path), "--workers", "1")  # patched here
    assert run_cli(capsys, *serial, "--seed", "1")[0] == 0
    names = list(studies)
    monkeypatch.setattr(studies[names[1]], "run", fake_run([], KeyboardInterrupt()))
    code, _, err = run_cli(capsys, *serial, "--seed", "7")
    assert code == 130 and err == f"interrupted: {tmp_path / names[1]} left unchanged\n"
    seeds = {n: json.loads((tmp_path / n / "metrics.json").read_text())["seed"] for n in names}
    assert seeds == {n: 7 if n == names[0] else 1 for n in names}
    page = (tmp_path / "report.html").read_text()
    seed = "<tr><td>seed</td><td>{}</td></tr>"
    assert page.count(seed.format(7)) == 1 and page.count(seed.format(1)) == len(names) - 1
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*names, "report.html"])


FAKE_STUDY = """\"\"\"Fake study.\"\"\"
import json, os
from pathlib import Path

EXPECTED_SECONDS = {{"quick": {seconds}, "full": {seconds}}}


def run(out_dir, quick=False, seed=0, runner=None):
    print("{name} runs", flush=True)
    if {fails}:
        raise ValueError("{name} breaks")
    if {crashes}:
        os._exit(7)  # dies without a word, as a segfault would
    record = {{"seed": seed, "pid": os.getpid(), "workers": runner.workers}}
    (Path(out_dir) / "metrics.json").write_text(json.dumps(record))
"""


def fake_studies(monkeypatch, folder, seconds, failing=(), crashing=()):
    """Importable study modules ``fake_<i>`` (so that other processes find them), as the
    installed studies; ``seconds``: their EXPECTED_SECONDS."""
    import importlib

    folder.mkdir()
    for i, value in enumerate(seconds):
        name = f"fake_{i}"
        text = FAKE_STUDY.format(
            name=name, seconds=value, fails=name in failing, crashes=name in crashing
        )
        (folder / f"{name}.py").write_text(text)
    monkeypatch.syspath_prepend(str(folder))
    for i in range(len(seconds)):  # another test's fake_<i> may be imported
        monkeypatch.delitem(sys.modules, f"fake_{i}", raising=False)
    importlib.invalidate_caches()
    studies = {f"fake_{i}": importlib.import_module(f"fake_{i}") for i in range(len(seconds))}
    monkeypatch.setattr(cli, "available_studies", lambda: studies)
    return studies


def test_all_on_several_workers_runs_studies_side_by_side(capsys, monkeypatch, tmp_path):
    """Two cores and 'all': each study in a process of its own (not this one), in series
    inside it, the longest expected first, its output in OUT/logs; a failing study (the last
    to start) is named with its log's end, exit code 1, and the others are complete."""
    from dmpopt import parallel

    monkeypatch.setattr(parallel, "available_cores", lambda: 2)
    fake_studies(monkeypatch, tmp_path / "modules", [10, 12, 11], failing=("fake_0",))
    out = tmp_path / "out"
    code, stdout, err = run_cli(capsys, "study", "run", "all", "--out", str(out), "--seed", "3")
    lines = stdout.splitlines()
    started = [line.split()[1].rstrip(":") for line in lines if line.endswith("Fake study.")]
    assert started == ["fake_1", "fake_2", "fake_0"]
    assert code == 1 and err.startswith("dmpopt: fake_0 failed (log: ")
    assert "ValueError: fake_0 breaks" in err
    for name in ("fake_1", "fake_2"):
        record = json.loads((out / name / "metrics.json").read_text())
        assert (record["seed"], record["workers"]) == (3, 1) and record["pid"] != os.getpid()
        assert f"{name} runs" in (out / "logs" / f"{name}.log").read_text()
    assert not (out / "fake_0").exists()


def test_a_study_process_that_dies_is_a_failure(capsys, monkeypatch, tmp_path):
    """A study process that ends without reporting (killed, crashed): exit code 1, its log
    named; the other study is complete."""
    from dmpopt import parallel

    monkeypatch.setattr(parallel, "available_cores", lambda: 2)
    fake_studies(monkeypatch, tmp_path / "modules", [2, 2], crashing=("fake_1",))
    code, _, err = run_cli(capsys, "study", "run", "all", "--out", str(tmp_path / "out"))
    assert code == 1 and err.startswith("dmpopt: fake_1 failed (log: ")
    assert (tmp_path / "out" / "fake_0" / "metrics.json").is_file()


def test_side_by_side_only_when_the_longest_study_fits_one_cores_share():
    """Side by side (each study in series) when the longest expected study takes at most
    the total / cores; else one after the other on all the cores (a dominant study would
    otherwise hold one core while the other idles)."""
    assert cli._side_by_side(9, longest=900, total=2600, cores=2)
    assert not cli._side_by_side(2, longest=500, total=530, cores=2)  # rl and feasible
    assert not cli._side_by_side(9, longest=900, total=2600, cores=1)
    assert not cli._side_by_side(1, longest=10, total=10, cores=2)


def test_several_names_run_those_studies(capsys, monkeypatch, tmp_path):
    """'run NAME NAME': those studies (each once), none of the others."""
    fake_studies(monkeypatch, tmp_path / "modules", [1, 2, 3])
    argv = ("study", "run", "fake_2", "fake_0", "fake_2", "--out", str(tmp_path / "out"))
    assert run_cli(capsys, *argv, "--workers", "1")[0] == 0
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert written == ["fake_0", "fake_2", "report.html"]


def test_killed_run_leftovers_are_cleaned(tmp_path):
    """A run killed outright (no cleanup) leaves .<name>.partial; the next run removes it,
    and restores the previous output if the kill fell between the two renames."""
    target = tmp_path / "rl"
    (tmp_path / ".rl.partial").mkdir()
    (tmp_path / ".rl.partial" / "half.png").write_text("half")
    (tmp_path / ".rl.previous").mkdir()
    (tmp_path / ".rl.previous" / "metrics.json").write_text("old")
    with pytest.raises(KeyboardInterrupt), staged_output(target) as folder:
        assert list(folder.iterdir()) == []
        raise KeyboardInterrupt
    assert contents(target) == {"metrics.json": "old"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rl"]


def test_symlinked_target_is_replaced_and_its_folder_kept(tmp_path):
    """A target that links to a folder elsewhere becomes the new output; the linked folder
    is not touched and no link is left beside the target."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "metrics.json").write_text("old")
    out = tmp_path / "out"
    out.mkdir()
    (out / "rl").symlink_to(elsewhere)
    with staged_output(out / "rl") as folder:
        (folder / "metrics.json").write_text("new")
    assert not (out / "rl").is_symlink() and contents(out / "rl") == {"metrics.json": "new"}
    assert contents(elsewhere) == {"metrics.json": "old"}
    assert [p.name for p in out.iterdir()] == ["rl"]


def test_unwritable_report_is_one_line(capsys, monkeypatch, tmp_path):
    """report.html that cannot be replaced (here a folder): one line, exit code 1; the
    study's own folder is complete."""
    studies = cli.available_studies()
    for module in studies.values():
        monkeypatch.setattr(module, "run", fake_run([]))
    (tmp_path / "report.html").mkdir()
    code, _, err = run_cli(capsys, "study", "run", "imitation", "--out", str(tmp_path))
    assert code == 1 and err.count("\n") == 1
    assert err.startswith(f"dmpopt: {tmp_path / 'report.html'} not written: ")
    assert contents(tmp_path / "imitation") == {
        "figure.png": "figure of seed 0",
        "metrics.json": '{"seed": 0}',
    }


@settings(max_examples=15, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=6))
def test_target_always_holds_the_last_complete_run(outcomes):
    """Whatever the sequence of completed (True) and interrupted runs, the target holds the
    files of the last completed run only, and nothing else is left beside it."""
    with tempfile.TemporaryDirectory() as scratch:
        target = Path(scratch) / "study"
        last = None
        for run, completes in enumerate(outcomes):
            try:
                with staged_output(target) as folder:
                    (folder / f"figure_{run}.png").write_text(str(run))
                    if not completes:
                        raise KeyboardInterrupt
                    (folder / "metrics.json").write_text(str(run))
                last = run
            except KeyboardInterrupt:
                pass
            if last is None:
                assert not target.exists()
            else:
                expected = {f"figure_{last}.png": str(last), "metrics.json": str(last)}
                assert contents(target) == expected
            assert [p.name for p in Path(scratch).iterdir()] == ([] if last is None else ["study"])


def test_report_written_whole_or_not(monkeypatch, tmp_path):
    """An interrupt while report.html is replaced leaves the old page and no partial file."""
    page = tmp_path / "report.html"
    page.write_text("old page")

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_text_atomic(page, "new page")
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]
    assert page.read_text() == "old page"
    monkeypatch.undo()
    assert write_text_atomic(page, "new page").read_text() == "new page"


def test_report_reads_the_folders(tmp_path):
    """The page shows the metrics.json on disk, for the study folders that hold one."""
    (tmp_path / "rl").mkdir()
    (tmp_path / "rl" / "metrics.json").write_text(json.dumps({"trials_to_95": {"enac": 140}}))
    (tmp_path / "biped").mkdir()  # no metrics.json: not a complete study folder
    page = write_report(tmp_path).read_text()
    assert '<section id="rl">' in page and "<td>trials_to_95.enac</td><td>140</td>" in page
    assert 'id="biped"' not in page


# ------------------------------------------------------------------ caches and compilers


def test_cache_dir_follows_the_platform(monkeypatch, tmp_path):
    monkeypatch.delenv("DMPOPT_CACHE", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(sys, "platform", "linux")
    assert symbolic.cache_dir() == tmp_path / "xdg" / "dmpopt"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/ignored")
    assert symbolic.cache_dir() == tmp_path / ".cache" / "dmpopt"
    monkeypatch.setattr(sys, "platform", "darwin")
    assert symbolic.cache_dir() == tmp_path / "Library" / "Caches" / "dmpopt"
    monkeypatch.setattr(sys, "platform", "win32")
    monkeypatch.setenv("LOCALAPPDATA", str(tmp_path / "local"))
    assert symbolic.cache_dir() == tmp_path / "local" / "dmpopt"
    monkeypatch.setenv("DMPOPT_CACHE", str(tmp_path / "mine"))
    assert symbolic.cache_dir() == tmp_path / "mine"


NUMBA_PROBE = """
import importlib
{first}
import numba.core.config as config
from numba.core.registry import CPUDispatcher
for name in {modules}:
    module = importlib.import_module(name)
    kernels = [k for k in vars(module).values() if isinstance(k, CPUDispatcher)]
    print(name, len(kernels), *(kernel._cache._cache_path for kernel in kernels))
print(config.CACHE_DIR)
"""

NUMBA_MODULES = [
    "dmpopt.learning.rewards",
    "dmpopt.learning.policy_search",
    "dmpopt.control.kernels",
    "dmpopt.sim.kernels",
    "dmpopt.sim.kernels_mujoco",
]
"""Every module of dmpopt with numba kernels of its own; the rollout kernels of
``dmpopt.response`` are generated into the cache folder itself."""


@pytest.mark.parametrize("numba_first", [False, True])
def test_numba_cache_is_outside_the_package(tmp_path, numba_first):
    """In a fresh interpreter (numba imported before dmpopt or not), every numba kernel of
    dmpopt caches in $XDG_CACHE_HOME/dmpopt/numba, outside the installed package (the
    learning kernels first, as ``dmpopt study run rl`` imports them, without the controller)."""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "DMPOPT_CACHE")}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    first = "import numba" if numba_first else ""
    code = NUMBA_PROBE.format(first=first, modules=NUMBA_MODULES)
    lines = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, check=True
    ).stdout.splitlines()
    assert lines[-1] == str(tmp_path / "dmpopt" / "numba")
    assert [line.split()[0] for line in lines[:-1]] == NUMBA_MODULES
    for line in lines[:-1]:
        _, count, *paths = line.split()
        assert int(count) > 0 and len(paths) == int(count)
        for path in map(Path, paths):
            assert path.is_relative_to(tmp_path / "dmpopt" / "numba")
            assert not path.is_relative_to(Path(dmpopt.__file__).parent)


def test_user_numba_cache_dir_is_kept(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "own")}
    code = "import dmpopt.control, numba.core.config as c; print(c.CACHE_DIR)"
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == str(tmp_path / "own")


@pytest.fixture(scope="module")
def small_dmp():
    times = np.linspace(0.0, 1.0, 200)
    demo = Trajectory.from_positions(times, np.c_[np.sin(np.pi * times), times**2])
    return fit_discrete(demo, n_basis=8)


def steps(dmp, compile_):
    stepper = dmp.stepper(dt=0.002, compile=compile_)
    stepper.step()
    stepper.set_goal([1.5, -0.5])
    return np.array([np.concatenate(stepper.step()) for _ in range(300)])


def test_compiled_step_is_cached_by_content(monkeypatch, tmp_path, small_dmp):
    """Generated C compiles into the dmpopt cache folder, once: a second stepper reuses it."""
    monkeypatch.setenv("DMPOPT_CACHE", str(tmp_path))
    monkeypatch.delenv("CC", raising=False)
    if symbolic.c_compiler() is None:
        pytest.skip("no C compiler on this machine")
    first = steps(small_dmp, True)
    libraries = list(tmp_path.iterdir())
    assert len(libraries) == 1 and libraries[0].suffix == ".so"
    mtime = libraries[0].stat().st_mtime_ns
    np.testing.assert_array_equal(steps(small_dmp, True), first)
    assert list(tmp_path.iterdir()) == libraries and libraries[0].stat().st_mtime_ns == mtime
    # within a process the library found is kept per function, compiler and cache folder
    step = symbolic.step_function(small_dmp.signature)
    assert symbolic.compiled(step) is symbolic.compiled(step)
    monkeypatch.setenv("DMPOPT_CACHE", str(tmp_path / "other"))
    elsewhere = symbolic.compiled(step)
    assert len(list((tmp_path / "other").glob("*.so"))) == 1  # built there too
    np.testing.assert_array_equal(steps(small_dmp, True), first)
    assert symbolic.compiled(step) is elsewhere


@pytest.fixture(scope="module")
def compiled_steps(tmp_path_factory, small_dmp):
    """Steps of the small DMP through C compiled with the system compiler."""
    with pytest.MonkeyPatch.context() as patch:
        patch.delenv("CC", raising=False)
        patch.setenv("DMPOPT_CACHE", str(tmp_path_factory.mktemp("reference")))
        if symbolic.c_compiler() is None:
            pytest.skip("no C compiler on this machine to compare with")
        return steps(small_dmp, True)


@pytest.mark.parametrize(
    ("cc", "cache", "message"),
    [
        ("/nonexistent/cc", "cache", r"\$CC='/nonexistent/cc' was not found"),
        ("false", "cache", r"false could not build it in .*: exit status 1"),
        (None, "file/cache", r"could not build it in .*file/cache: Not a directory"),
    ],
)
def test_without_a_compiler_the_vm_gives_identical_steps(
    monkeypatch, tmp_path, small_dmp, compiled_steps, cc, cache, message
):
    """No compiler, a failing one, or an unusable cache folder: one warning, then the CasADi
    VM steps exactly as the compiled C."""
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("DMPOPT_CACHE", str(tmp_path / cache))
    monkeypatch.delenv("CC", raising=False)
    if cc is not None:
        monkeypatch.setenv("CC", cc)
    with pytest.warns(RuntimeWarning, match=message + r".*runs on the CasADi VM") as caught:
        fallback = steps(small_dmp, True)
    assert len(caught) == 1
    np.testing.assert_array_equal(fallback, compiled_steps)
    leftovers = list((tmp_path / cache).glob("*")) if (tmp_path / cache).is_dir() else []
    assert leftovers == []


def test_without_a_compiler_on_the_path_the_warning_says_so(monkeypatch, tmp_path, small_dmp):
    """No $CC and no cc or gcc on PATH: the VM fallback's warning names that and the fix."""
    monkeypatch.setenv("DMPOPT_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))  # an empty folder: no compiler on it
    with pytest.warns(RuntimeWarning, match=r"no cc or gcc on PATH \(install gcc, or set CC "
                      r"to a C compiler\)"):  # fmt: skip
        assert small_dmp.stepper(1e-3, compile=True).compiled is False


def test_stepper_says_whether_its_step_is_compiled(monkeypatch, tmp_path, small_dmp):
    """``Stepper.compiled``: False on the VM fallback (what the studies report), True with C."""
    monkeypatch.setenv("DMPOPT_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", "/nonexistent/cc")
    with pytest.warns(RuntimeWarning, match="runs on the CasADi VM"):
        assert small_dmp.stepper(1e-3, compile=True).compiled is False
    assert small_dmp.stepper(1e-3).compiled is False
    monkeypatch.delenv("CC")
    if symbolic.c_compiler() is None:
        pytest.skip("no C compiler on this machine")
    assert small_dmp.stepper(1e-3, compile=True).compiled is True
