r"""Automatic choice of the number and widths of the basis functions (Section 3.4).

The paper fits the forcing term with LWPR, which adds receptive fields where the data need
them and adapts their widths, so that the number :math:`N` and the widths :math:`h_i` of
eq. (7) need not be chosen by hand. :func:`fit_adaptive` does the same job by validation:
every other sample of the demonstration is held out, the DMP is fitted to the rest, and its
plan is scored on the held-out samples. The number of basis functions grows geometrically;
at each number the widths are scaled by each of a few factors and the best is kept. Growth
stops at the first number whose validation error meets the tolerance, or when growing no
longer lowers the validation error (noisy demonstrations: the error floors at the noise).
The chosen layout is then fitted to all samples.

Unlike LWPR, the centres keep the library's layout (equal shares of the movement's
duration, :func:`dmpopt.basis.discrete_basis`) and one width factor applies to every basis
function.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .. import basis
from ..dmp import DiscreteDMP
from ..exceptions import InvalidInputError
from ..validation import integer, real
from .imitation import (
    _check_demo,
    _local_regression,
    _ridge,
    fit_discrete,
    forcing_targets,
    unforced_states,
)

STOP_REASONS = ("tolerance", "no improvement", "max_basis")
PATIENCE = 2
"""Growth steps in a row without enough improvement after which growth stops (one step can
fail where the width search is caught in a poor local minimum)."""
WIDTH_SCALES = tuple(2.0**k for k in range(-3, 7))
"""Default factors on the widths, 1/8 to 64: on LASA the position-space fit prefers wider
basis functions than the default layout, LWR much narrower ones."""


@dataclass(frozen=True, eq=False)
class BasisChoice:
    """What :func:`fit_adaptive` chose, and why.

    Attributes
    ----------
    dmp : DiscreteDMP
        The DMP fitted to all samples with the chosen basis.
    n_basis : int
        Chosen number of basis functions per DOF.
    width_scale : float
        Chosen factor on the widths :math:`h_i` of the default layout (> 1: narrower).
    validation_error : float
        RMS Euclidean position error [demo units] of the plan at the held-out samples, for
        the chosen layout fitted to the other samples.
    stopped : {"tolerance", "no improvement", "max_basis"}
        Why growth stopped: the tolerance was met, :data:`PATIENCE` growth steps in a row
        lowered the validation error by less than ``min_improvement``, or ``max_basis``
        was reached.
    history : tuple of (int, float, float)
        ``(n_basis, width_scale, validation_error)`` of every layout tried, in order.
    """

    dmp: DiscreteDMP
    n_basis: int
    width_scale: float
    validation_error: float
    stopped: str
    history: tuple


def fit_adaptive(
    demo,
    tolerance: float,
    *,
    method: str = "position",
    form: str = "velocity",
    goal_scaling: str = "auto",
    width_scales=WIDTH_SCALES,
    min_basis: int = 5,
    max_basis: int = 200,
    growth: float = 1.5,
    min_improvement: float = 0.02,
    regularization: float = 1e-9,
    alpha_z: float = 25.0,
    alpha_v: float = 25.0,
) -> BasisChoice:
    """Fit a discrete DMP, choosing the number and widths of its basis functions.

    See the module docstring for the procedure.

    Parameters
    ----------
    demo : Trajectory
        Point-to-point demonstration (at least 6 samples).
    tolerance : float
        Validation RMS position error [demo units] that is good enough.
    method, form, goal_scaling, regularization, alpha_z, alpha_v
        As in :func:`dmpopt.fitting.fit_discrete`.
    width_scales : sequence of float
        Factors on the widths :math:`h_i` of eq. (7) (1: neighbours cross at
        :math:`1/\\sqrt{2}` of their height; > 1: narrower), sorted. At each number of basis
        functions the search starts at the previous number's choice (first: the factor
        nearest 1) and steps to a neighbouring factor while that lowers the validation error.
    min_basis, max_basis : int
        First and largest number of basis functions tried.
    growth : float
        Factor (> 1) between successive numbers of basis functions (rounded up, at least +1).
    min_improvement : float
        Growth stops when :data:`PATIENCE` steps in a row each fail to lower the best
        validation error by this fraction (in [0, 1)); the best layout found is kept.

    Returns
    -------
    BasisChoice
    """
    demo = _check_demo(demo)
    tolerance = real("tolerance", tolerance, minimum=0.0, open_minimum=True)
    scales = _width_scales(width_scales)
    min_basis = basis.check_n_basis(min_basis)
    max_basis = integer("max_basis", max_basis, minimum=min_basis)
    growth = real("growth", growth, minimum=1.0, open_minimum=True)
    min_improvement = real("min_improvement", min_improvement, minimum=0.0)
    if min_improvement >= 1.0:
        raise InvalidInputError(
            f"min_improvement must be below 1 (a fraction of the error), got {min_improvement}"
        )
    train = _training_rows(demo, max_basis)
    first = fit_discrete(
        demo,
        min_basis,
        method=method,
        form=form,
        goal_scaling=goal_scaling,
        regularization=regularization,
        alpha_z=alpha_z,
        alpha_v=alpha_v,
    )
    data = _Demo(demo, first, method, regularization)
    history, best, stale, stopped = [], None, 0, "max_basis"
    k = int(np.argmin(np.abs(np.log(scales))))
    for n_basis in _numbers(min_basis, max_basis, growth):
        k, errors = _width_search(data, n_basis, scales, k, train)
        history += [(n_basis, scales[i], errors[i]) for i in sorted(errors)]
        if best is not None and errors[k] > (1.0 - min_improvement) * best[2]:
            stale += 1
            if stale == PATIENCE:
                stopped = "no improvement"
                break
            continue
        best, stale = (n_basis, scales[k], errors[k]), 0
        if errors[k] <= tolerance:
            stopped = "tolerance"
            break
    n_basis, scale, error = best
    dmp = data.fit(n_basis, scale, np.ones(demo.n_steps, dtype=bool))[0]
    return BasisChoice(dmp, n_basis, scale, error, stopped, tuple(history))


def _width_search(data, n_basis: int, scales: tuple, k: int, train) -> tuple[int, dict]:
    """Descend from ``scales[k]`` to neighbouring factors while the validation error falls.

    Returns the index reached and the errors computed, by index.
    """
    errors = {}

    def error(i: int) -> float:
        if i not in errors:
            errors[i] = data.validation_error(n_basis, scales[i], train)
        return errors[i]

    while True:
        neighbours = [i for i in (k - 1, k + 1) if 0 <= i < len(scales)]
        step = min(neighbours, key=error, default=k)
        if error(step) >= error(k):
            return k, errors
        k = step


def _width_scales(value) -> tuple:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise InvalidInputError(
            f"width_scales must be a sequence of positive numbers, got {value!r}"
        )
    scales = tuple(real("width_scales", scale, minimum=0.0, open_minimum=True) for scale in value)
    if not scales:
        raise InvalidInputError("width_scales is empty; give at least one factor, e.g. (1.0,)")
    if any(b <= a for a, b in zip(scales, scales[1:])):
        raise InvalidInputError(
            f"width_scales must be sorted ascending without repeats, got {scales}"
        )
    return scales


def _training_rows(demo, max_basis: int) -> np.ndarray:
    """Even samples and the last one; the odd ones (but the last) are held out."""
    rows = np.arange(demo.n_steps) % 2 == 0
    rows[-1] = True
    if demo.n_steps < 6:
        raise InvalidInputError(
            f"demo has {demo.n_steps} samples; fit_adaptive holds every other sample out "
            "for validation and needs at least 6: resample it (demo.resampled(n_steps))"
        )
    if max_basis > rows.sum():
        raise InvalidInputError(
            f"max_basis = {max_basis} exceeds the {rows.sum()} samples the fits are trained on "
            "(every other sample of the demo is held out for validation); lower max_basis or "
            "resample the demonstration to more samples"
        )
    return rows


def _numbers(first: int, last: int, growth: float) -> list:
    """``first, ceil(first * growth), ...`` up to ``last``; each is at least one more, as
    ``n * growth`` rounds above ``n`` for any float ``growth > 1``."""
    numbers = [first]
    while numbers[-1] < last:
        numbers.append(min(last, int(np.ceil(numbers[-1] * growth))))
    return numbers


@lru_cache(maxsize=96)  # an entry holds n_steps x n_basis floats
def _position_response(form, n_steps, step, centres, widths, gains) -> np.ndarray:
    """Position response of one DOF to each forcing weight, shape (n_steps, n_basis).

    Independent of start, goal and (for a fixed ``step = dt / tau``) of ``tau``: cached here
    for the many layouts :func:`fit_adaptive` tries on demonstrations sampled alike.
    """
    n_basis = len(centres)
    probe = DiscreteDMP(
        weights=np.zeros((1, n_basis)),
        start=[0.0],
        goal=[0.0],
        tau=1.0,
        centres=centres,
        widths=widths,
        form=form,
        goal_scaling="translation",
        **dict(zip(("alpha_z", "beta_z", "alpha_v", "beta_v", "alpha_g"), gains)),
    )
    return probe.affine_plan((n_steps - 1) * step, step).weight_response[0]


class _Demo:
    """One demonstration and what every layout shares: the plan with zero weights and, for
    the regressions of the forcing term, the canonical states and forcing targets."""

    def __init__(self, demo, fitted: DiscreteDMP, method: str, regularization: float):
        self.demo, self.method, self.regularization = demo, method, regularization
        self.zero = fitted.replace(weights=np.zeros_like(fitted.weights))
        self.dt = demo.duration / (demo.n_steps - 1)
        # the fitted DMP keeps the demo's start velocity: its plans start with it
        self.free = self.zero.affine_plan(demo.duration, self.dt).free[0]
        if method != "position":
            self.states = unforced_states(self.zero, demo)
            self.targets = forcing_targets(self.zero, demo, self.states)

    def fit(self, n_basis: int, scale: float, rows):
        """The DMP with ``n_basis`` functions, widths scaled by ``scale``, fitted to the
        samples ``rows``, and its plan's positions at every sample (:meth:`_fitted`); the
        forcing weights are stored per unit of the goal map at the demo's start and goal, as
        :func:`dmpopt.fitting.fit_discrete` stores them."""
        centres, widths, forcing, positions = self._fitted(n_basis, scale, rows)
        weights = np.linalg.solve(self.zero.goal_map(), forcing)
        return self._unit(centres, widths).replace(weights=weights), positions

    def _unit(self, centres: np.ndarray, widths: np.ndarray) -> DiscreteDMP:
        """The demo's DMP with these basis functions and zero weights."""
        weights = np.zeros((self.demo.n_dofs, centres.size))
        return self.zero.replace(weights=weights, centres=centres, widths=widths)

    def _fitted(self, n_basis: int, scale: float, rows):
        """The centres and widths of ``n_basis`` functions with widths scaled by ``scale``,
        the forcing weights fitted to the samples ``rows`` and the plan's positions at every
        sample.

        The regressions are those of :func:`dmpopt.fitting.fit_discrete` (same centres, same
        ``tau``). The validation needs only the positions: no DMP of the fitted weights is
        built, and the position fit none at all (each costs about as much as its solve).
        """
        demo, zero = self.demo, self.zero
        centres, widths = basis.discrete_basis(n_basis, zero.gains)
        widths = scale * widths
        # dt / tau rounded: demos of equal sample counts share it up to rounding errors
        step = float(f"{self.dt / zero.tau:.12g}")
        key = (zero.form, demo.n_steps, step, tuple(centres), tuple(widths))
        response = _position_response(*key, zero.gains)
        if self.method == "position":
            last = (response[-1], demo.positions[-1] - self.free[-1])
            residual = (demo.positions - self.free)[rows]
            forcing = _ridge(response[rows], residual, self.regularization, last).T
        elif self.method == "least_squares":
            regressors = self._unit(centres, widths).phase_features(demo.n_steps, self.dt)
            forcing = _ridge(regressors[rows], self.targets[rows], self.regularization).T
        else:
            unit = self._unit(centres, widths)
            forcing = _local_regression(unit, self.states[rows, :2], self.targets[rows])
        return centres, widths, forcing, self.free + response @ forcing.T

    def validation_error(self, n_basis: int, scale: float, train) -> float:
        """RMS position error at the held-out samples of the layout fitted to ``train``."""
        positions = self._fitted(n_basis, scale, train)[3]
        held_out = ~train
        distance = np.linalg.norm(positions[held_out] - self.demo.positions[held_out], axis=1)
        return float(np.sqrt(np.mean(distance**2)))
