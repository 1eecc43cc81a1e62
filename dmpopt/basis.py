r"""Placement of the basis functions and the convergence time that sets ``tau``.

The activations themselves are defined once, symbolically, in :mod:`dmpopt.symbolic`;
this module only chooses centres ``c_i`` and widths ``h_i``.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from . import symbolic
from .exceptions import InvalidInputError

CONVERGENCE_FRACTION = 0.95
"""Imitation picks ``tau`` so that the system with ``f = 0`` is this close to its goal at the
end of the demonstration (Section 3.4)."""


def check_n_basis(n_basis) -> int:
    """Validate a number of basis functions."""
    if isinstance(n_basis, bool) or not isinstance(n_basis, (int, np.integer)) or n_basis < 1:
        raise InvalidInputError(f"n_basis must be a positive integer, got {n_basis!r}")
    return int(n_basis)


@lru_cache(maxsize=16)
def convergence_time(form: str, gains: tuple, fraction: float = CONVERGENCE_FRACTION) -> float:
    """Time, for ``tau = 1``, after which the unforced system stays ``fraction`` of the way to
    its goal (95 % by default).

    Computed from the symbolic definition (a 1-DOF rollout from 0 to 1 with zero weights),
    so it holds for any gains. Rollouts scale in time with ``tau``, so the convergence
    time of a system with time constant ``tau`` is ``tau`` times this value.
    """
    dt, n_steps = 1e-4, 20001
    signature = symbolic.Signature(form, 1, 1, "gaussian")
    n_transformation = symbolic.n_transformation_states(form)
    initial = np.zeros(2 + n_transformation)
    parameters = [1.0, 1.0, 1.0, np.zeros((1, 1)), 0.0, 1.0, np.array(gains), 0.0, 0.0]
    positions = symbolic.simulate(signature, n_steps, initial, dt, parameters)[1][:, 0]
    error = np.abs(1.0 - positions)
    outside = np.nonzero(error > 1.0 - fraction)[0]
    if outside.size == 0 or outside[-1] == n_steps - 1:
        raise InvalidInputError(f"the unforced {form} system with gains {gains} does not converge")
    k = outside[-1]  # interpolate the crossing between samples k and k + 1
    part = (error[k] - (1.0 - fraction)) / (error[k] - error[k + 1])
    return float((k + part) * dt)


@lru_cache(maxsize=16)
def discrete_phase(gains: tuple, times: tuple) -> np.ndarray:
    """Normalised phase of the canonical system (6) at ``times`` (for ``tau = 1``)."""
    dt = 1e-4
    n_steps = int(np.ceil(max(times) / dt)) + 2
    signature = symbolic.Signature("velocity", 1, 1, "gaussian")
    parameters = [1.0, 0.0, 1.0, np.zeros((1, 1)), 0.0, 1.0, np.array(gains), 0.0, 0.0]
    states = symbolic.simulate(signature, n_steps, np.zeros(4), dt, parameters)[0]
    return np.interp(times, np.arange(n_steps) * dt, states[:, 0])


def discrete_basis(n_basis: int, gains: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Centres and widths of ``n_basis`` Gaussians on the discrete phase, eq. (7).

    Centres sit at the phase reached at equally spaced times over the convergence time,
    so that each basis covers an equal share of the movement's duration; neighbouring
    Gaussians cross at :math:`1/\\sqrt{2}` of their height (wide enough for smooth fits:
    measured on LASA, it lowers the reproduction error by a quarter against half height).
    """
    n_basis = check_n_basis(n_basis)
    end = convergence_time("velocity", gains[:4])
    times = tuple(np.linspace(0.0, end, n_basis)) if n_basis > 1 else (0.5 * end,)
    centres = discrete_phase(tuple(gains[:4]), times)
    spacing = np.diff(centres) if n_basis > 1 else np.array([1.0])
    spacing = np.append(spacing, spacing[-1])
    widths = 2.0 * np.log(2.0) / spacing**2
    return centres, widths


def rhythmic_basis(n_basis: int, kernel: str) -> tuple[np.ndarray, np.ndarray]:
    """Centres equally spaced on ``[0, 2 pi)`` and widths crossing at half height."""
    n_basis = check_n_basis(n_basis)
    centres = 2 * np.pi * np.arange(n_basis) / n_basis
    half_spacing = np.pi / n_basis
    if kernel == "von_mises":
        width = np.log(2.0) / (1.0 - np.cos(half_spacing))
    elif kernel == "paper":
        width = np.log(2.0) / half_spacing**2
    else:
        raise InvalidInputError(f"kernel must be 'von_mises' or 'paper', got {kernel!r}")
    return centres, np.full(n_basis, width)
