"""Argument checks shared by the simulation modules: errors name the argument and the fix."""

from __future__ import annotations

import numpy as np

from dmpopt.exceptions import InvalidInputError, ShapeError


def real(name: str, value, expected: str, positive: bool = False, finite: bool = True) -> float:
    """``value`` as a float; InvalidInputError unless it is a real number as required.

    Parameters
    ----------
    name : str
        Argument name for the message.
    expected : str
        What was expected, for the message, e.g. ``"a positive time step [s] such as 1e-3"``.
    positive : bool
        Refuse values <= 0.
    finite : bool
        Refuse +-inf (NaN is always refused).
    """
    number = None
    if not isinstance(value, (bool, np.bool_, str, bytes)) and np.ndim(value) == 0:
        try:
            number = float(value)
        except (TypeError, ValueError):
            pass
    if (
        number is None
        or np.isnan(number)
        or (finite and np.isinf(number))
        or (positive and number <= 0)
    ):
        raise InvalidInputError(f"{name} must be {expected}, got {value!r}")
    return number


def vector(name: str, value, size: int, expected: str, labels=None) -> np.ndarray:
    """``value`` as a finite float array of shape ``(size,)`` (a new array).

    Raises ShapeError for a wrong shape and InvalidInputError for non-numbers or non-finite
    entries; ``expected`` describes the entries, e.g. ``"torques [N m] of the actuated joints"``,
    and ``labels`` (one per entry, optional) names the culprit entry.
    """
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(
            f"{name} must be an array of {size} numbers ({expected}), got {value!r}"
        ) from None
    if array.shape != (size,):
        raise ShapeError(f"{name} has shape {array.shape}, expected ({size},): {expected}")
    if not np.isfinite(array).all():
        first = np.flatnonzero(~np.isfinite(array))[0]
        label = "" if labels is None else f" ({labels[first]})"
        raise InvalidInputError(
            f"{name}[{first}]{label} is {array[first]}: {name} must be finite ({expected})"
        )
    return array
