"""Output folders written by one process at a time, and replaced whole.

:func:`locked_folder` holds a folder for one process (``flock``); :func:`staged_output` gives a
fresh folder that replaces its target only when the block ends without an error, so a
target always holds one complete run. The ``dmpopt`` command writes each study through them.
"""

from __future__ import annotations

import os
import shutil
from contextlib import contextmanager
from pathlib import Path

from .exceptions import DmpoptError


class FolderInUse(DmpoptError):
    """Another process writes into the output folder."""


_HELD: dict = {}
"""Output folders this process has locked (resolved path -> open descriptor, depth)."""


@contextmanager
def locked_folder(folder):
    """Hold ``folder`` for this process's writes; refuse if another process holds it.

    The lock is ``flock`` on the folder itself (no lock file: the folder's contents stay the
    results), released when the block ends or the process dies, so a killed run never leaves
    a stale lock. Re-entrant within one process (the command locks ``--out``, each study's
    :func:`staged_output` locks it again). Where ``fcntl`` is missing (Windows) there is no
    lock, and one output folder must take one run at a time by hand.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not on POSIX
        yield Path(folder)
        return
    path = Path(folder).resolve()
    if path in _HELD:
        descriptor, depth = _HELD[path]
        _HELD[path] = (descriptor, depth + 1)
    else:
        descriptor = os.open(path, os.O_RDONLY)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(descriptor)
            raise FolderInUse(
                f"{folder} is being written by another dmpopt run (one run at a time per "
                "output folder); wait for it to end or choose another --out"
            ) from None
        _HELD[path] = (descriptor, 1)
    try:
        yield Path(folder)
    finally:
        descriptor, depth = _HELD[path]
        if depth > 1:
            _HELD[path] = (descriptor, depth - 1)
        else:
            del _HELD[path]
            os.close(descriptor)  # releases the lock


@contextmanager
def held_by_parent(folder):
    """In a process started by the one that holds ``folder`` (the ``dmpopt`` command running
    studies in processes of their own): count ``folder`` as held here, so that
    :func:`staged_output` inside does not try to lock it again. The parent's lock covers the
    child: the parent waits for it before releasing."""
    path = Path(folder).resolve()
    if path in _HELD:
        raise RuntimeError(f"{folder} is already held by this process")
    _HELD[path] = (None, 1)
    try:
        yield Path(folder)
    finally:
        del _HELD[path]


def _partial(target: Path) -> Path:
    return target.with_name(f".{target.name}.partial")


def _previous(target: Path) -> Path:
    return target.with_name(f".{target.name}.previous")


def _remove(path: Path) -> None:
    if path.is_symlink() or path.is_file():
        path.unlink()
    else:
        shutil.rmtree(path, ignore_errors=True)


def _recover(target: Path) -> None:
    """Undo what a run killed outright (no Python cleanup) left next to ``target``."""
    previous = _previous(target)
    if previous.exists() and not target.exists():
        previous.rename(target)  # killed between the two renames of _swap
    for leftover in (_partial(target), previous):
        _remove(leftover)


def _swap(staged: Path, target: Path) -> None:
    """Put ``staged`` in place of ``target`` (two renames, then the old one is deleted)."""
    previous = _previous(target)
    if target.exists() or target.is_symlink():
        target.rename(previous)
    staged.rename(target)
    _remove(previous)


@contextmanager
def staged_output(target):
    """A fresh folder to write a study's output into; it replaces ``target`` on success.

    The folder is ``.<name>.partial`` next to ``target``. If the block raises (an error or
    Ctrl-C), it is deleted and ``target`` is left as it was, so ``target`` always holds one
    complete run. Leftovers of a run that was killed outright are cleaned on the next run.
    The folder holding ``target`` is locked (:func:`locked_folder`): a second process writing
    there at the same time gets :class:`FolderInUse` before it writes anything.

    >>> with staged_output("results/rl") as folder:     # doctest: +SKIP
    ...     metrics = rl.run(folder)
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    with locked_folder(target.parent):
        _recover(target)
        staged = _partial(target)
        staged.mkdir(parents=True)
        try:
            yield staged
            _swap(staged, target)
        finally:
            shutil.rmtree(staged, ignore_errors=True)
