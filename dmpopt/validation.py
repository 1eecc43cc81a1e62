"""Checks at the boundary of the library: argument types, values and resource bounds.

Every public entry point converts its arguments with these helpers, so a bad value gets
one error that names the argument, what was expected, what arrived and what to do.
Strings, booleans, ``None`` and complex numbers are refused where a real number is expected
(``float("1.5")`` or ``float(True)`` would silently accept them). Work whose size follows
from the arguments (a rollout's samples, a fit's matrices) is estimated with
:func:`check_resources` before anything is allocated.
"""

from __future__ import annotations

import decimal
import math
import numbers

import numpy as np

from .exceptions import InvalidInputError, ResourceLimitError, ShapeError

MAX_SAMPLES = 2_000_000
"""Most samples one rollout, plan or fit may integrate (about a minute of work; 2000 s at
``dt = 1 ms``)."""

MEMORY_BUDGET = 2 * 1024**3
"""Most memory [bytes] one request (rollout, plan, fit, retiming, learner, classifier) may
allocate for its arrays."""


def _suffix(fix: str) -> str:
    return f"; {fix}" if fix else ""


def _is_real_scalar(value) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, np.ndarray):
        return value.ndim == 0 and value.dtype.kind in "iuf"
    return isinstance(value, (numbers.Real, decimal.Decimal))


def _bounds(minimum, maximum, open_minimum: bool) -> str:
    low = "" if minimum is None else f" {'>' if open_minimum else '>='} {minimum:g}"
    high = "" if maximum is None else f"{' and' if low else ''} <= {maximum:g}"
    return low + high


def real(
    name: str,
    value,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    open_minimum: bool = False,
    finite: bool = True,
    expected: str = "",
    fix: str = "",
) -> float:
    """``value`` as a float in ``[minimum, maximum]`` (``(minimum, ...`` if ``open_minimum``).

    Parameters
    ----------
    name : str
        Argument name used in the error message.
    value : object
        An int, float or Decimal (also NumPy scalars and 0-d arrays); not bool, str, None or
        complex.
    minimum, maximum : float, optional
        Bounds; ``open_minimum`` excludes ``minimum`` itself.
    finite : bool
        Refuse +-inf (NaN is always refused).
    expected : str
        What was expected, e.g. ``"a positive time step [s] such as 1e-3"``; by default
        stated from the bounds (``"a finite number > 0"``).
    fix : str
        What to do, appended to the message.
    """
    if not isinstance(value, float) and not _is_real_scalar(value):  # floats need no check
        expected = expected or _expected_real(minimum, maximum, open_minimum, finite)
        raise InvalidInputError(
            f"{name} must be a real number ({expected}), got {value!r} "
            f"({type(value).__name__}){_suffix(fix)}"
        )
    number = float(value)
    too_low = minimum is not None and (number <= minimum if open_minimum else number < minimum)
    too_high = maximum is not None and number > maximum
    if math.isnan(number) or (finite and math.isinf(number)) or too_low or too_high:
        expected = expected or _expected_real(minimum, maximum, open_minimum, finite)
        raise InvalidInputError(f"{name} must be {expected}, got {number!r}{_suffix(fix)}")
    return number


def _expected_real(minimum, maximum, open_minimum: bool, finite: bool) -> str:
    """What :func:`real` expected, stated from its bounds (built only for an error)."""
    return ("a finite number" if finite else "a number") + _bounds(minimum, maximum, open_minimum)


def integer(name: str, value, *, minimum: int, maximum: int | None = None, fix: str = "") -> int:
    """``value`` as an int in ``[minimum, maximum]``; integral floats (``5.0``) are accepted.

    Above ``maximum`` the error is a :class:`ResourceLimitError` (the bound is a resource one)
    whose message ends with ``fix``.
    """
    is_int = isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
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


def flag(name: str, value) -> bool:
    """A bool (``True`` or ``False``, not a truthy string)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidInputError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def real_array(
    name: str,
    value,
    *,
    ndim: int | None = None,
    shape: tuple[int, ...] | None = None,
    empty: bool = False,
    expected: str = "",
    labels=None,
    fix: str = "",
) -> np.ndarray:
    """``value`` as a new float64 array of finite real numbers.

    Parameters
    ----------
    name : str
        Argument name used in the error message.
    value : array_like
        Real numbers; booleans, strings, complex numbers and ragged nesting are refused.
    ndim : int, optional
        Required number of dimensions.
    shape : tuple of int, optional
        Required shape.
    empty : bool
        Accept an array without entries (when no ``shape`` is required).
    expected : str
        What the entries are, e.g. ``"torques [N m] of the actuated joints"``.
    labels : sequence of str, optional
        One per entry of a 1-D array, to name the culprit of a NaN.
    fix : str
        What to do, appended to the message.
    """
    described = f" ({expected})" if expected else ""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as error:  # ragged nested sequences
        raise ShapeError(
            f"{name} must be a regular array of real numbers{described}, got {error}{_suffix(fix)}"
        ) from error
    if raw.dtype.kind == "c":
        raise InvalidInputError(
            f"{name} is complex; dmpopt works on real numbers: pass the real part "
            "(np.real) if the imaginary part is meant to be dropped"
        )
    if raw.dtype.kind not in "iuf":
        kind = {"b": "booleans", "U": "strings", "S": "bytes"}.get(raw.dtype.kind)
        arrived = (
            repr(raw.item()) if raw.ndim == 0 else kind or f"{type(value).__name__} of {raw.dtype}"
        )
        raise InvalidInputError(
            f"{name} must be an array of real numbers{described}, got {arrived}{_suffix(fix)}"
        )
    array = np.array(raw, dtype=float)
    if ndim is not None and array.ndim != ndim:
        raise ShapeError(
            f"{name} has shape {array.shape}, expected {ndim} dimension(s){described}{_suffix(fix)}"
        )
    if shape is not None and array.shape != tuple(shape):
        raise ShapeError(
            f"{name} has shape {array.shape}, expected {tuple(shape)}{described}{_suffix(fix)}"
        )
    if not empty and shape is None and array.size == 0:
        raise ShapeError(f"{name} is empty (shape {array.shape}){described}{_suffix(fix)}")
    finite = np.isfinite(array)
    if not finite.all():
        index = np.unravel_index(np.flatnonzero(~finite)[0], array.shape)
        label = "" if labels is None else f" ({labels[index[0]]})"
        raise InvalidInputError(
            f"{name}[{', '.join(map(str, index))}]{label} is {array[index]}: {name} contains "
            f"{array.size - np.count_nonzero(finite)} NaN or infinite value(s){described}; "
            f"{fix or 'clean or interpolate them first'}"
        )
    return array


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


def check_resources(what: str, n_bytes: float, remedy: str, n_samples: int | None = None) -> None:
    """Refuse work beyond :data:`MEMORY_BUDGET` bytes or :data:`MAX_SAMPLES` samples.

    Parameters
    ----------
    what : str
        The request, as the user wrote it (e.g. ``"rollout(duration=10, dt=1e-07)"``).
    n_bytes : float
        Estimated memory of the arrays to allocate.
    remedy : str
        What to change to stay within the bounds.
    n_samples : int, optional
        Samples to integrate, for requests that step through time.
    """
    if not n_bytes <= MEMORY_BUDGET or (n_samples is not None and n_samples > MAX_SAMPLES):
        bounds = f"{MEMORY_BUDGET / 1024**3:.3g} GiB (dmpopt.validation.MEMORY_BUDGET)"
        needs = f"about {n_bytes / 1024**3:.3g} GiB"
        if n_samples is not None:
            bounds = f"{MAX_SAMPLES:.3g} samples (dmpopt.validation.MAX_SAMPLES) and {bounds}"
            needs = f"{n_samples:.3g} samples and {needs}"
        raise ResourceLimitError(f"{what} needs {needs}; dmpopt allows at most {bounds}: {remedy}")


def positive(name: str, value) -> float:
    """``value`` as a finite float ``> 0``."""
    return real(name, value, minimum=0.0, open_minimum=True)


def vector(name: str, value, size: int, reference: str) -> np.ndarray:
    """``value`` as a float vector of ``size`` entries (a scalar or one entry fills it);
    ``reference`` says what fixes the size, for the error message."""
    array = np.atleast_1d(real_array(name, value, empty=True))
    if array.shape == (1,) and size > 1:
        array = np.full(size, array[0])
    if array.shape != (size,):
        raise ShapeError(f"{name} has shape {array.shape}, expected ({size},) to match {reference}")
    return array


def unit_rotation_blocks(model, q: np.ndarray, tolerance: float) -> list[slice]:
    """The slices of ``q`` that hold a unit quaternion (free flyer, spherical joint; order x, y,
    z, w) or a unit complex number (planar, unbounded revolute joints), each checked: a norm
    more than ``tolerance`` from 1 raises :class:`InvalidInputError` naming the joint and the
    fix. Composite joints are left to the caller (``pinocchio.isNormalized``)."""
    blocks = []
    for joint_id in range(1, model.njoints):
        joint = model.joints[joint_id]
        if joint.nq == joint.nv or joint.shortname() == "JointModelComposite":
            continue
        size = 4 if joint.shortname() in ("JointModelFreeFlyer", "JointModelSpherical") else 2
        block = slice(joint.idx_q + joint.nq - size, joint.idx_q + joint.nq)
        norm = np.linalg.norm(q[block])
        if abs(norm - 1.0) > tolerance:
            unit = "quaternion (x, y, z, w)" if size == 4 else "complex number (cos, sin)"
            identity = "(0, 0, 0, 1)" if size == 4 else "(1, 0)"
            raise InvalidInputError(
                f"q[{block.start}:{block.stop}] of joint {model.names[joint_id]!r} has norm "
                f"{norm:.4g}, expected a unit {unit}: pass e.g. {identity} for no rotation, "
                "or pinocchio.normalize(model, q) if the orientation is right but not scaled"
            )
        blocks.append(block)
    return blocks
