r"""Placement of the basis functions and the convergence time that sets ``tau``.

The activations themselves are defined once, symbolically, in :mod:`dmpopt.symbolic`;
this module only chooses centres ``c_i`` and widths ``h_i``.
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca
import numpy as np

from . import forms, symbolic
from .exceptions import InvalidInputError
from .validation import integer

CONVERGENCE_FRACTION = 0.95
"""Imitation picks ``tau`` so that the system with ``f = 0`` is this close to its goal at the
end of the demonstration (Section 3.4)."""


def check_n_basis(n_basis) -> int:
    """Validate a number of basis functions (one or more)."""
    return integer("n_basis", n_basis, minimum=1)


RK4_STABILITY_RADII = np.linspace(0.0, 3.0, 3001)[1:]
"""Values of ``|h lambda|`` scanned for the edge of the RK4 stability region (which lies
below 2.9 in every direction of the left half-plane); the crossing is then bisected."""


def _rk4_growth(z):
    """``|R(z)|`` with ``R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24``, RK4's amplification."""
    return np.abs(1 + z * (1 + z / 2 * (1 + z / 3 * (1 + z / 4))))


def _rk4_limit(eigenvalue: complex) -> float:
    """Largest ``h`` with ``|R(h lambda)| <= 1`` on all of ``(0, h]``."""
    if eigenvalue == 0:
        return np.inf
    direction = eigenvalue / abs(eigenvalue)
    outside = np.nonzero(_rk4_growth(RK4_STABILITY_RADII * direction) > 1.0 + 1e-12)[0]
    if outside.size == 0:
        return np.inf
    k = outside[0]
    low, high = (RK4_STABILITY_RADII[k - 1] if k > 0 else 0.0), RK4_STABILITY_RADII[k]
    for _ in range(40):
        middle = 0.5 * (low + high)
        if _rk4_growth(middle * direction) > 1.0 + 1e-12:
            high = middle
        else:
            low = middle
    return low / abs(eigenvalue)


@lru_cache(maxsize=64)
def stable_step(form: str, gains: tuple, canonical_target: float, canonical_states: tuple) -> float:
    r"""Largest integration step, for ``tau = 1``, at which the RK4 discretisation is stable.

    An RK4 step :math:`h` multiplies each mode of a linear system by :math:`R(h\lambda) = 1 +
    h\lambda + \dots + (h\lambda)^4/24`, so it is stable while :math:`|R(h\lambda)| \le 1` for
    every eigenvalue :math:`\lambda` of its Jacobian (e.g. :math:`h \le 2.785 / (\alpha_z / 2)`
    for a critically damped system). The Jacobian :math:`J` of eqs. (5)-(14) (the forcing
    term is an input that does not feed back) is taken at ``canonical_states``: one state for
    the linear discrete and phase forms, points along the limit cycle for the energy form.
    There :math:`J` rotates with the oscillation, so the limit uses the eigenvalues of its
    mean over the cycle (the oscillation) and the decaying eigenvalues at each point (the
    stiff pull back onto the cycle). Time scales with ``tau``: the limit for time constant
    ``tau`` is ``tau`` times this value. Accurate plans need steps well below the limit.
    """
    signature = symbolic.Signature(form, 1, 1, "gaussian")
    s = symbolic.make_symbols(signature)
    rate = symbolic.system_rhs(signature, s, s.state)
    jacobian = symbolic.function(
        "jacobian", {"state": s.state, **s.parameters()}, {"jacobian": ca.jacobian(rate, s.state)}
    )
    parameters = symbolic.parameters(canonical_target=canonical_target, gains=np.array(gains))
    padding = np.zeros(signature.n_states - 2)
    matrices = [
        jacobian(state=np.concatenate([canonical, padding]), **parameters)["jacobian"].full()
        for canonical in canonical_states
    ]
    frozen = [value for m in matrices for value in np.linalg.eigvals(m) if value.real < 0.0]
    eigenvalues = [*np.linalg.eigvals(np.mean(matrices, axis=0)), *frozen]
    return float(min(_rk4_limit(value) for value in eigenvalues))


def _time_step(form: str, gains: tuple) -> float:
    """Step (``tau = 1``) of the reference integrations: 1e-4, or less for fast gains so that
    the fastest eigenvalue times the step stays below 0.0025 (as with the default gains)."""
    fastest = np.max(np.abs(np.concatenate(discrete_eigenvalues(form, gains))))
    return min(1e-4, 0.0025 / fastest)


@lru_cache(maxsize=16)
def convergence_time(form: str, gains: tuple, fraction: float = CONVERGENCE_FRACTION) -> float:
    """Time, for ``tau = 1``, after which the unforced system stays ``fraction`` of the way to
    its goal (95 % by default).

    Computed from the symbolic definition (a 1-DOF rollout from 0 to 1 with zero weights),
    so it holds for any gains. Rollouts scale in time with ``tau``, so the convergence
    time of a system with time constant ``tau`` is ``tau`` times this value.
    """
    dt, n_steps = _time_step(form, gains), 20001
    # without forcing term the transformation system steps alone: s' = S s + S_g g
    matrices = symbolic.transformation_matrices(form)(dt=dt, gains=np.array(gains))
    step, goal = matrices["step"].full(), matrices["step_goal"].full()
    length, padded = symbolic.linear_blocks(n_steps)
    states = np.zeros((step.shape[0], padded, 1))
    states[:, : n_steps - 1, 0] = goal
    positions = symbolic.linear_states(step, np.zeros((step.shape[0], 1)), states, length)
    positions = positions[0, :n_steps, 0]
    error = np.abs(1.0 - positions)
    outside = np.nonzero(error > 1.0 - fraction)[0]
    if outside.size == 0 or outside[-1] == n_steps - 1:
        rates = np.abs(np.concatenate(discrete_eigenvalues(form, gains)).real)
        raise InvalidInputError(
            f"the unforced {form} system with gains {gains} does not come {fraction:g} of the "
            f"way to its goal within {(n_steps - 1) * dt:.3g} tau (its modes decay at rates "
            f"{rates.min():.4g} to {rates.max():.4g} per tau): use gains of one scale, e.g. "
            "beta_z = alpha_z / 4 (critical damping, the default)"
        )
    k = outside[-1]  # interpolate the crossing between samples k and k + 1
    part = (error[k] - (1.0 - fraction)) / (error[k] - error[k + 1])
    return float((k + part) * dt)


@lru_cache(maxsize=16)
def _jacobians(form: str) -> ca.Function:
    """``gains -> (canonical, transformation)``: Jacobians of the form's canonical and
    transformation systems (one DOF, unforced) with respect to their states, from its
    equations (:mod:`dmpopt.forms`); constant for the linear discrete systems."""
    equations = forms.FORMS[form]
    gains = ca.SX.sym("gains", len(equations.gain_names))
    canonical = ca.SX.sym("canonical", 2)
    transformation = ca.SX.sym("transformation", equations.n_transformation)
    zero = ca.SX.zeros(1)
    canonical_rate = equations.canonical_rhs(canonical, 1.0, gains, 0.0)
    rate = equations.transformation_rhs(transformation, zero, zero, gains, 0.0)
    return ca.Function(
        "dmp_jacobians",
        [gains, canonical],
        [ca.jacobian(canonical_rate, canonical), ca.jacobian(rate, transformation)],
    )


@lru_cache(maxsize=64)  # every DiscreteDMP asks at construction (its phase-rate check)
def discrete_eigenvalues(form: str, gains: tuple) -> tuple[np.ndarray, np.ndarray]:
    r"""Eigenvalues, for ``tau = 1``, of the canonical system (6) and of the linear part of the
    transformation system (5) or (10), as ``(canonical, transformation)``.

    Both are linear, so these are the eigenvalues of their Jacobians (taken from the form's
    equations): for eq. (6) the roots of :math:`s^2 + \alpha_v s + \alpha_v \beta_v`, for
    eq. (5) those of :math:`s^2 + \alpha_z s + \alpha_z \beta_z`, and eq. (10) adds
    :math:`-\alpha_g` (the goal filter). The forcing term is an input that does not feed back.
    """
    canonical, transformation = _jacobians(form)(np.asarray(gains, dtype=float), np.zeros(2))
    eigenvalues = np.linalg.eigvals(canonical.full()), np.linalg.eigvals(transformation.full())
    for values in eigenvalues:
        values.setflags(write=False)  # shared by the cache
    return eigenvalues


def erlang_time(n_poles: int, fraction: float) -> float:
    r"""The :math:`x` at which :math:`e^{-x} \sum_{j < n} x^j / j! = 1 - \mathrm{fraction}`.

    The step response of :math:`n` poles at :math:`-1` has that distance left to its goal at
    time :math:`x`, the tail of an Erlang distribution; it decreases from 1 to 0, so bisection
    finds it.
    """
    remaining = 1.0 - fraction
    low, high = 0.0, 10.0 * n_poles - math.log(remaining)
    for _ in range(100):
        x = 0.5 * (low + high)
        tail = math.exp(-x) * sum(x**j / math.factorial(j) for j in range(n_poles))
        low, high = (x, high) if tail > remaining else (low, x)
    return 0.5 * (low + high)


@lru_cache(maxsize=16)
def settling_time(form: str, gains: tuple, fraction: float) -> float:
    r"""Time, for ``tau = 1``, in which the canonical and transformation systems of a discrete
    DMP together come ``fraction`` of the way to rest, each of their :math:`n` modes counted
    as slow as the slowest, :math:`\lambda = \min |\mathrm{Re}\, s|`
    (:func:`discrete_eigenvalues`): :math:`x / \lambda` with :math:`x` the Erlang tail's
    crossing (:func:`erlang_time`). The forcing term is gated by the canonical velocity, so
    the plan cannot rest before the canonical system does: a slow phase (small
    :math:`\alpha_v`) lengthens the plan.
    """
    eigenvalues = np.concatenate(discrete_eigenvalues(form, gains))
    rate = float(np.min(-eigenvalues.real))
    return erlang_time(eigenvalues.size, fraction) / rate


@lru_cache(maxsize=16)
def discrete_phase(gains: tuple, times: tuple) -> np.ndarray:
    """Normalised phase of the canonical system (6) at ``times`` (for ``tau = 1``)."""
    dt = _time_step("velocity", gains)
    n_steps = int(np.ceil(max(times) / dt)) + 2
    signature = symbolic.Signature("velocity", 1, 1, "gaussian")
    gains = np.array(gains)
    rest = (0.0, 0.0)
    states = symbolic.canonical_trajectory(signature, n_steps, dt, rest, 1.0, gains, False)[0]
    return np.interp(times, np.arange(n_steps) * dt, states[0])


def discrete_basis(n_basis: int, gains: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Centres and widths of ``n_basis`` Gaussians on the discrete phase, eq. (7).

    Centres sit at the phase reached at equally spaced times over the convergence time,
    so that each basis covers an equal share of the movement's duration; neighbouring
    Gaussians cross at :math:`1/\\sqrt{2}` of their height (wide enough for smooth fits:
    measured on LASA, it lowers the reproduction error by a quarter against half height).
    One basis function is allowed: its normalised activation is 1 whatever its width, so
    the forcing term is :math:`w v` (its width is set as if the spacing were the whole phase).
    ``gains`` are a DMP's :attr:`~dmpopt.dmp.DiscreteDMP.gains`; the first four are read.
    """
    n_basis = check_n_basis(n_basis)
    end = convergence_time("velocity", gains[:4])
    times = tuple(np.linspace(0.0, end, n_basis)) if n_basis > 1 else (0.5 * end,)
    centres = discrete_phase(tuple(gains[:4]), times)
    if n_basis == 1:  # its normalised activation is 1 whatever the width: span the phase
        return centres, np.full(1, 2.0 * np.log(2.0))
    spacing = np.diff(centres)
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
