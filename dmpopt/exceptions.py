"""Errors raised by dmpopt; every one derives from :class:`DmpoptError`."""


class DmpoptError(Exception):
    """Base class of every error dmpopt raises on purpose."""


class ShapeError(DmpoptError, ValueError):
    """An array argument has the wrong shape."""


class InvalidInputError(DmpoptError, ValueError):
    """An argument has a wrong value (non-finite, out of range, inconsistent)."""


class FittingFailed(DmpoptError, RuntimeError):
    """A fit could not produce weights; carries the problem for inspection."""

    def __init__(self, message: str, problem: object = None, stats: object = None):
        super().__init__(message)
        self.problem = problem
        self.stats = stats


class InfeasibleProblem(FittingFailed):
    """A constrained problem has no solution; names the constraint group that fails."""


class NoSolutionFound(DmpoptError, RuntimeError):
    """A solver (QP, retiming) failed to return a usable solution."""

    def __init__(self, message: str, stats: object = None):
        super().__init__(message)
        self.stats = stats


class FileFormatError(DmpoptError, ValueError):
    """A file is corrupt, foreign or of an unsupported version."""


class MissingDependency(DmpoptError, ImportError):
    """An optional dependency is not installed; the message names the extra to install."""


class SimulationDiverged(DmpoptError, RuntimeError):
    """A simulation blew up (non-finite or exploding state)."""


class ResourceLimitError(DmpoptError, ValueError):
    """A request would need more memory or time than a documented bound; the message states
    the estimate and what to change."""
