"""Checks of user arguments shared by the fitting, retiming, learning and recognition modules.

Each check names the argument, says what was expected, what arrived and, when given, the fix.
Strings, booleans, ``None`` and complex numbers are refused where a real number is expected
(``float("1.5")`` or ``float(True)`` would silently accept them).
"""

from __future__ import annotations

import numbers

import numpy as np

from .exceptions import InvalidInputError, ResourceLimitError, ShapeError

MAX_ELEMENTS = 20_000_000
"""Largest array (in float64 entries, 160 MB) that a user number may make dmpopt allocate."""


def _suffix(fix: str) -> str:
    return f"; {fix}" if fix else ""


def _is_real_scalar(value) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, np.ndarray):
        return value.ndim == 0 and value.dtype.kind in "iuf"
    return isinstance(value, numbers.Real)


def real(
    name: str,
    value,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    open_minimum: bool = False,
    fix: str = "",
) -> float:
    """``value`` as a finite float in ``[minimum, maximum]`` (``(minimum, ...`` if open)."""
    low = "" if minimum is None else f"{'>' if open_minimum else '>='} {minimum:g}"
    high = "" if maximum is None else f"<= {maximum:g}"
    expected = (
        "a finite number"
        + (f" {low}" if low else "")
        + (f"{' and' if low else ''} {high}" if high else "")
    )
    if not _is_real_scalar(value):
        raise InvalidInputError(
            f"{name} must be {expected}, got {value!r} ({type(value).__name__}){_suffix(fix)}"
        )
    number = float(value)
    too_low = minimum is not None and (number <= minimum if open_minimum else number < minimum)
    too_high = maximum is not None and number > maximum
    if not np.isfinite(number) or too_low or too_high:
        raise InvalidInputError(f"{name} must be {expected}, got {number!r}{_suffix(fix)}")
    return number


def integer(name: str, value, *, minimum: int, maximum: int | None = None, fix: str = "") -> int:
    """``value`` as an int in ``[minimum, maximum]``; integral floats (``5.0``) are accepted.

    Above ``maximum`` the error is a :class:`ResourceLimitError` (the bound is a resource one)
    whose message ends with ``fix``.
    """
    is_int = isinstance(value, (numbers.Integral, np.integer)) and not isinstance(
        value, (bool, np.bool_)
    )
    is_integral_float = (
        _is_real_scalar(value) and np.isfinite(float(value)) and float(value).is_integer()
    )
    if not (is_int or is_integral_float) or int(value) < minimum:
        raise InvalidInputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    number = int(value)
    if maximum is not None and number > maximum:
        raise ResourceLimitError(
            f"{name} = {number} exceeds the bound {maximum} of this function{_suffix(fix)}"
        )
    return number


def real_array(name: str, value, *, ndim: int | None = None, fix: str = "") -> np.ndarray:
    """``value`` as a non-empty float64 array of finite real numbers (a copy)."""
    if value is None or isinstance(value, (str, bytes)):
        raise InvalidInputError(
            f"{name} must be an array of real numbers, got {value!r}{_suffix(fix)}"
        )
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as error:  # ragged nested sequences
        raise ShapeError(f"{name} must be a regular array of real numbers{_suffix(fix)}") from error
    if raw.dtype.kind not in "iuf":
        kind = {"b": "booleans", "c": "complex numbers", "U": "strings", "S": "bytes"}
        raise InvalidInputError(
            f"{name} must be an array of real numbers, got "
            f"{kind.get(raw.dtype.kind, raw.dtype.name)}{_suffix(fix)}"
        )
    array = np.array(raw, dtype=float)
    if ndim is not None and array.ndim != ndim:
        raise ShapeError(
            f"{name} has shape {array.shape}, expected {ndim} dimension(s){_suffix(fix)}"
        )
    if array.size == 0:
        raise ShapeError(f"{name} is empty (shape {array.shape}){_suffix(fix)}")
    if not np.all(np.isfinite(array)):
        bad = int(array.size - np.count_nonzero(np.isfinite(array)))
        raise InvalidInputError(
            f"{name} contains {bad} NaN or infinite value(s); "
            f"{fix or 'clean or interpolate them first'}"
        )
    return array


def budget(what: str, n_elements: float, fix: str, limit: float = MAX_ELEMENTS) -> None:
    """Refuse a request whose largest array would hold more than ``limit`` float64 entries."""
    if not n_elements <= limit:
        raise ResourceLimitError(
            f"{what} would need about {n_elements:.3g} float64 values "
            f"({8 * n_elements / 2**30:.3g} GiB), above the bound of {limit:.3g} "
            f"({8 * limit / 2**20:.0f} MiB); {fix}"
        )


def sequence_of(name: str, value, kind: type, fix: str = "") -> tuple:
    """``value`` as a tuple of ``kind`` instances (a list, tuple or other iterable)."""
    if isinstance(value, kind):
        raise InvalidInputError(
            f"{name} must be a sequence of {kind.__name__}, got a single {kind.__name__}; "
            f"wrap it in a list: [{kind.__name__}(...)]"
        )
    if value is None or isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise InvalidInputError(
            f"{name} must be a sequence of {kind.__name__}, got {type(value).__name__}"
            f"{_suffix(fix or 'pass () for none')}"
        )
    items = tuple(value)
    for i, item in enumerate(items):
        if not isinstance(item, kind):
            raise InvalidInputError(
                f"{name}[{i}] must be a {kind.__name__}, got {type(item).__name__}{_suffix(fix)}"
            )
    return items
