"""Checks at the boundary of the library: argument types, values and resource bounds.

Every public entry point converts its arguments with these helpers, so a bad value gets
one error that names the argument, what was expected, what arrived and what to do. Work
whose size follows from the arguments (a rollout's samples, a fit's matrices) is estimated
with :func:`check_resources` before anything is allocated.
"""

from __future__ import annotations

import numbers

import numpy as np

from .exceptions import InvalidInputError, ResourceLimitError, ShapeError

MAX_SAMPLES = 2_000_000
"""Most samples one rollout, plan or fit may integrate (about a minute of work; 2000 s at
``dt = 1 ms``)."""

MEMORY_BUDGET = 2 * 1024**3
"""Most memory [bytes] one rollout, plan or fit may allocate for its arrays."""


def as_finite_array(name: str, value, ndim: int | None = None) -> np.ndarray:
    """Return ``value`` as a float64 array; refuse non-numbers, booleans, complex, NaN, inf.

    Parameters
    ----------
    name : str
        Argument name used in the error message.
    value : array_like
        The value to check.
    ndim : int, optional
        Required number of dimensions.
    """
    try:
        raw = np.asarray(value)
    except ValueError as error:  # ragged nested sequences
        raise InvalidInputError(f"{name} must be a numeric array, got {error}") from error
    if raw.dtype.kind == "c":
        raise InvalidInputError(
            f"{name} is complex; dmpopt works on real numbers: pass the real part "
            "(np.real) if the imaginary part is meant to be dropped"
        )
    if raw.dtype.kind not in "iuf":
        raise InvalidInputError(
            f"{name} must be numeric, got {type(value).__name__} of dtype {raw.dtype}"
        )
    array = np.array(raw, dtype=float)
    if ndim is not None and array.ndim != ndim:
        raise ShapeError(f"{name} has {array.ndim} dimensions {array.shape}, expected {ndim}")
    if not np.all(np.isfinite(array)):
        bad = int(np.size(array) - np.count_nonzero(np.isfinite(array)))
        raise InvalidInputError(
            f"{name} contains {bad} NaN or infinite value(s); clean or interpolate them first"
        )
    return array


def real_number(name: str, value) -> float:
    """A finite real number (int or float, not bool, str, None or complex)."""
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value.item()
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InvalidInputError(f"{name} must be a real number, got {value!r}")
    value = float(value)
    if not np.isfinite(value):
        raise InvalidInputError(f"{name} must be finite, got {value!r}")
    return value


def positive_number(name: str, value) -> float:
    """A finite real number above zero."""
    value = real_number(name, value)
    if value <= 0.0:
        raise InvalidInputError(f"{name} must be a positive finite number, got {value!r}")
    return value


def non_negative_number(name: str, value) -> float:
    """A finite real number, zero or above."""
    value = real_number(name, value)
    if value < 0.0:
        raise InvalidInputError(f"{name} must be zero or positive, got {value!r}")
    return value


def integer(name: str, value, minimum: int) -> int:
    """An integer (not bool) of at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        expected = {0: "a non-negative integer", 1: "a positive integer"}.get(
            minimum, f"an integer of at least {minimum}"
        )
        raise InvalidInputError(f"{name} must be {expected}, got {value!r}")
    return int(value)


def flag(name: str, value) -> bool:
    """A bool (``True`` or ``False``, not a truthy string)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidInputError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_resources(what: str, n_samples: int, n_bytes: float, remedy: str) -> None:
    """Refuse work beyond :data:`MAX_SAMPLES` samples or :data:`MEMORY_BUDGET` bytes.

    Parameters
    ----------
    what : str
        The request, as the user wrote it (e.g. ``"rollout(duration=10, dt=1e-07)"``).
    n_samples : int
        Samples to integrate.
    n_bytes : float
        Estimated memory of the arrays to allocate.
    remedy : str
        What to change to stay within the bounds.
    """
    if n_samples > MAX_SAMPLES or n_bytes > MEMORY_BUDGET:
        raise ResourceLimitError(
            f"{what} needs {n_samples:.3g} samples and about {n_bytes / 1024**3:.3g} GiB; "
            f"the bounds are {MAX_SAMPLES:.3g} samples (dmpopt.validation.MAX_SAMPLES) and "
            f"{MEMORY_BUDGET / 1024**3:.3g} GiB (dmpopt.validation.MEMORY_BUDGET): {remedy}"
        )
