"""The ``dmpopt`` command: list and run the studies that reproduce the paper.

Each study writes into a temporary folder that replaces ``OUT/<study>`` only when the study
is done, so an interrupted or failed run leaves the previous output as it was. Bad arguments,
failures and Ctrl-C end with one line on stderr and a non-zero exit code (2: bad arguments,
1: a study failed, 130: interrupted).

``run all`` on several local workers (the default on a machine with several cores) runs the
studies side by side, one process per core, each study in series inside its process, the
longest first (by ``EXPECTED_SECONDS``): the cores stay busy through every study's serial
stretches, and no study pays for worker processes of its own (each would import the
libraries and rebuild its caches: a third more CPU time for the quick runs). Studies run one
after the other, each on all the workers, when one of them alone would outlast the others
together (``run rl feasible``). Each study's output goes to ``OUT/logs/<study>.log``. Every
study gives the same results in its own process as in a serial run (``--workers 1``): its
runs depend on their inputs and seeds only.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import os
import sys
import tempfile
import time
import warnings
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

from .folders import FolderInUse, held_by_parent, locked_folder, staged_output

ENTRY_POINTS = "dmpopt.studies"
# A study module's ``EXPECTED_SECONDS = {"quick": ..., "full": ...}``: the CPU seconds of a run
# (the study's process and its workers together) on this project's 2-core machine, quiet. A
# run on N cores takes about 1/N of that when its runs keep them busy.
"""The entry-point group that declares the studies (``available``: name -> module) and the
results page (``write_report``); the repository's ``pyproject.toml`` fills it, so dmpopt never
imports a studies package by name."""


class UsageError(Exception):
    """A command-line value that cannot be used."""


class _Parser(argparse.ArgumentParser):
    """Reports argument errors as a UsageError (one line), not a usage block."""

    def error(self, message):
        raise UsageError(f"{message} (see '{self.prog} --help')")


def entry_point(name: str):
    """The object declared as ``name`` in the :data:`ENTRY_POINTS` group, loaded."""
    found = [point for point in metadata.entry_points(group=ENTRY_POINTS) if point.name == name]
    if not found:
        raise UsageError(
            f"no studies are installed: the entry point {name!r} of the group {ENTRY_POINTS!r} "
            "is missing; install dmpopt from its repository (pip install -e . or pip install .)"
        )
    return found[0].load()


def available_studies() -> dict:
    """Study name -> module, for the studies installed with this version."""
    return entry_point("available")()


def _summary(module) -> str:
    return (module.__doc__ or "").strip().splitlines()[0]


def _seconds(module, quick: bool) -> float:
    return getattr(module, "EXPECTED_SECONDS", {}).get("quick" if quick else "full", 0)


def _expected(module, quick: bool) -> str:
    seconds = _seconds(module, quick)
    if not seconds:
        return "?"
    return f"~{seconds / 60:.0f} min" if seconds >= 90 else f"~{seconds:.0f} s"


def _list(studies: dict) -> int:
    times = "(times: CPU of all its processes)"
    print(f"{'study':12s} {'--quick':>8s} {'full':>8s}  what it reproduces {times}")
    for name, module in studies.items():
        quick, full = _expected(module, True), _expected(module, False)
        print(f"{name:12s} {quick:>8s} {full:>8s}  {_summary(module)}")
    return 0


def _integer_at_least(minimum: int):
    """An argparse type: the integers >= ``minimum``, anything else refused in one line."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {text!r}")
        return value

    return parse


_seed = _integer_at_least(0)
_workers = _integer_at_least(1)


def _writable_folder(text: str) -> Path:
    """The folder ``text``, created if needed, after checking that files can be written in it."""
    if not text.strip():
        raise UsageError("--out is empty; give the folder for the results, e.g. --out results")
    out = Path(text)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file, not a folder; choose a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except (OSError, ValueError) as error:
        reason = getattr(error, "strerror", None) or str(error)
        raise UsageError(
            f"--out {out}: cannot write there ({reason}); choose a writable folder"
        ) from None
    return out


def _check_targets(out: Path, names: list[str]) -> None:
    for name in names:
        if (out / name).exists() and not (out / name).is_dir():
            raise UsageError(
                f"--out {out}: {out / name} is a file, not a study folder; "
                "move it away or choose another --out"
            )


@contextmanager
def _locked(out: Path):
    """Hold ``--out`` for this run (:func:`dmpopt.folders.locked_folder`); a second run is
    refused."""
    try:
        with locked_folder(out):
            yield
    except FolderInUse as error:
        raise UsageError(f"--out {error}") from None


def _left(target: Path, existed: bool) -> str:
    return f"{target} left unchanged" if existed else f"{target} not written"


def _study_options(module, runner) -> dict:
    """``runner=`` for the studies whose independent runs can go elsewhere."""
    accepts = "runner" in inspect.signature(module.run).parameters
    return {"runner": runner} if accepts else {}


def _cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and of its ended, waited-for children."""
    import resource

    return sum(
        usage.ru_utime + usage.ru_stime
        for usage in map(resource.getrusage, (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    )


def _run_one(name: str, module, target: Path, quick: bool, seed: int, runner=None) -> int:
    """Run one study into a staged folder that replaces ``target``; return the exit code.

    The closing line gives the wall time and the CPU time of this process and its local
    workers (their pool is closed first so that their time is counted)."""
    from threadpoolctl import threadpool_limits

    from .exceptions import DmpoptError

    start, existed, cpu = time.perf_counter(), target.exists(), _cpu_seconds()
    print(f"== {name}: {_summary(module)}")
    try:
        # the studies multiply small matrices: one BLAS thread is faster, and on a loaded
        # machine several threads per product cost milliseconds each
        with staged_output(target) as folder, threadpool_limits(limits=1, user_api="blas"):
            module.run(folder, quick=quick, seed=seed, **_study_options(module, runner))
    except KeyboardInterrupt:
        print(f"interrupted: {_left(target, existed)}", file=sys.stderr)
        return 130
    except (DmpoptError, OSError) as error:
        print(f"dmpopt: {name} failed: {error}; {_left(target, existed)}", file=sys.stderr)
        return 1
    finally:
        if runner is not None and runner.ray is None:
            runner.close()
    wall, cpu = time.perf_counter() - start, _cpu_seconds() - cpu
    print(f"== {name} done in {wall:.1f} s (CPU {cpu:.1f} s) -> {target}")
    return 0


def _run(studies: dict, names: list[str], out: Path, quick: bool, seed: int, runner=None) -> int:
    write_report = entry_point("write_report")
    total = sum(_seconds(studies[n], quick) for n in names)
    cores = 1 if runner is None else runner.workers
    wall = "" if runner is not None and runner.ray else f", {total / 60 / cores:.1f} min here"
    print(
        f"running {', '.join(names)} ({'quick' if quick else 'full'}): about "
        f"{total / 60:.1f} CPU-minutes{wall}; results in {out}"
    )
    refresh_report = len(names) > 1 or (out / "report.html").exists()
    code, done = 0, 0
    longest = max(_seconds(studies[n], quick) for n in names)
    if (
        runner is not None
        and runner.backend == "processes"
        and _side_by_side(len(names), longest, total, runner.workers)
    ):
        code, done = _run_side_by_side(studies, names, out, quick, seed, runner.workers)
    else:
        for name in names:
            code = _run_one(name, studies[name], out / name, quick, seed, runner)
            if code:
                break
            done += 1
    if done and refresh_report:
        try:
            path = write_report(out)  # from the folders on disk, so it matches them
        except (OSError, ValueError) as error:
            print(f"dmpopt: {out / 'report.html'} not written: {error}", file=sys.stderr)
            return code or 1
        if not code:
            print(f"report: {path}")
    return code


def _side_by_side(n_studies: int, longest: float, total: float, cores: int) -> bool:
    """Whether studies expected to take ``total`` CPU seconds, the longest ``longest``, fill
    ``cores`` better side by side (each in series) than one after the other (each on all
    the cores): when the longest fits in one core's share."""
    return n_studies > 1 and cores > 1 and longest * cores <= total


def _study_process(name, module_name, out, quick, seed, log, report) -> None:
    """One study of :func:`_run_side_by_side`, in a process of its own and in series inside
    it: its output into ``log``; sends ``(exit code, CPU seconds)`` through ``report``."""
    from .parallel import Runner

    with open(log, "w") as file:
        os.dup2(file.fileno(), 1)  # the study's prints and its libraries' output alike
        os.dup2(file.fileno(), 2)
    code = 1
    try:
        module = importlib.import_module(module_name)
        with held_by_parent(out), Runner(workers=1, progress=False) as runner:
            code = _run_one(name, module, out / name, quick, seed, runner)
    finally:
        sys.stdout.flush()
        report.send((code, _cpu_seconds()))


def _tail(log: Path, lines: int = 5) -> str:
    try:
        return "".join(log.read_text(errors="replace").splitlines(True)[-lines:])
    except OSError:
        return ""


def _run_side_by_side(studies, names, out, quick, seed, workers) -> tuple[int, int]:
    """Run ``names`` at most ``workers`` at a time, each in a process of its own (in series
    inside it), the longest (by its ``EXPECTED_SECONDS``) first. The processes start from
    one that imported the study modules once (:func:`~dmpopt.parallel.process_context`).

    After a failure or Ctrl-C no new study starts; those running end as they would alone
    (their own Ctrl-C handling, or to completion). Returns (exit code, studies done)."""
    from multiprocessing.connection import wait

    from .parallel import process_context

    context = process_context([studies[name].__name__ for name in names])
    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    waiting = sorted(names, key=lambda name: -_seconds(studies[name], quick))
    running, code, done, start = {}, 0, 0, time.perf_counter()
    print(f"{len(names)} studies side by side, {workers} at a time; logs in {logs}")
    try:
        while waiting or running:
            while waiting and len(running) < workers and not code:
                name = waiting.pop(0)
                receive, send = context.Pipe(duplex=False)
                log = logs / f"{name}.log"
                process = context.Process(
                    target=_study_process,
                    args=(name, studies[name].__name__, out, quick, seed, log, send),
                    name=f"dmpopt study {name}",
                )
                process.start()
                send.close()
                running[process.sentinel] = (name, process, receive, log)
                print(f"== {name}: {_summary(studies[name])}", flush=True)
            if not running:
                break
            for sentinel in wait(list(running)):
                name, process, receive, log = running.pop(sentinel)
                process.join()
                try:
                    study_code, cpu = receive.recv()
                except EOFError:  # it died before reporting (killed, or a crash)
                    study_code, cpu = 1, float("nan")
                if study_code == 0 and process.exitcode == 0:
                    done += 1
                    elapsed = time.perf_counter() - start
                    print(f"== {name} done, CPU {cpu:.1f} s, at {elapsed:.1f} s -> {out / name}")
                else:
                    code = code or study_code or 1
                    print(f"dmpopt: {name} failed (log: {log}):\n{_tail(log)}", file=sys.stderr)
    except KeyboardInterrupt:
        for name, process, _, _ in running.values():
            process.join()  # Ctrl-C reached it too: it leaves its folder as it was
        print("interrupted", file=sys.stderr)
        return 130, done
    return code, done


def _runner(workers: int | None, ray: str | None):
    from .exceptions import DmpoptError
    from .parallel import Runner, available_cores

    if workers is None:
        workers = 1 if ray is not None else available_cores()
    try:
        with warnings.catch_warnings(record=True) as caught:  # shown whatever the filters
            warnings.simplefilter("always")
            runner = Runner(workers=workers, ray=ray)
        for warning in caught:
            print(f"warning: {warning.message}", file=sys.stderr)
        if ray is not None:
            runner.connect()  # a wrong address or a missing ray fails now, not mid-study
    except DmpoptError as error:
        raise UsageError(f"--ray: {error}") from None
    return runner


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    print(f"warning: {message}", file=sys.stderr if file is None else file)


def main(argv=None) -> int:
    """Entry point of the ``dmpopt`` command; returns the exit code."""
    from . import __version__

    parser = _Parser(prog="dmpopt", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"dmpopt {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)
    study = commands.add_parser("study", help="list or run the studies")
    actions = study.add_subparsers(dest="action", required=True)
    actions.add_parser("list", help="each study, how long it takes, what it reproduces")
    run = actions.add_parser("run", help="run studies, or all")
    run.add_argument(
        "name", nargs="+", help="study names from 'dmpopt study list', or 'all' for every one"
    )
    run.add_argument("--out", default="results", help="output folder (default: results)")
    run.add_argument("--quick", action="store_true", help="a reduced run (about a minute each)")
    run.add_argument("--seed", default=0, type=_seed, help="random seed, >= 0 (default: 0)")
    run.add_argument(
        "--workers",
        default=None,
        type=_workers,
        help="N local processes (default: this machine's cores; at most those; 1: in series, "
        "the same results): several studies side by side, N at a time, or one study's "
        "independent runs (seeds, trials, folds); with --ray, the CPUs a local Ray may use",
    )
    run.add_argument(
        "--ray",
        nargs="?",
        const="local",
        metavar="ADDRESS",
        help="independent runs on Ray: a local Ray without ADDRESS, 'auto' for the cluster "
        "of 'ray start', or HOST:PORT of a head (needs pip install 'dmpopt[ray]')",
    )
    try:
        args = parser.parse_args(argv)
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            studies = available_studies()
            if args.action == "list":
                return _list(studies)
            for name in args.name:
                if name not in studies and name != "all":
                    run.error(f"unknown study {name!r}; choose from {', '.join(studies)} or 'all'")
            names = list(studies) if "all" in args.name else list(dict.fromkeys(args.name))
            out = _writable_folder(args.out)
            _check_targets(out, names)
            with _locked(out), _runner(args.workers, args.ray) as runner:
                return _run(studies, names, out, args.quick, args.seed, runner)
    except UsageError as error:
        print(f"dmpopt: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
