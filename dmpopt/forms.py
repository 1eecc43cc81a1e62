r"""The forms of a DMP: each one object holding its equations, state layout and constants.

A form is what ``form=`` names (``"velocity"``, ``"acceleration"``, ``"phase"``,
``"energy"``). Its object writes the form's equations once, symbolically (CasADi), and says
how its state is laid out; :mod:`dmpopt.symbolic` builds every compiled function from them
and the DMP classes read the rest (which constants, which start state, what period) from the
object, so adding a form is one class here and its tests.

The state of a system with ``D`` DOFs is the canonical state (two numbers shared by all DOFs,
Section 3.6) followed by the transformation states, ``D`` numbers each:

================  ==========================  ===================================
form              canonical state             transformation state
================  ==========================  ===================================
``velocity``      phase ``x``, ``v`` (eq. 6)  ``y``, ``z``                (eq. 5)
``acceleration``  phase ``x``, ``v`` (eq. 6)  ``y``, ``z``, goal filter ``r`` (eq. 10)
``phase``         ``phi``, amplitude ``r``    ``y``, ``z``     (eqs. 5, 11)
``energy``        ``x``, ``v``     (eq. 13)   ``y``, ``z``     (eqs. 5, 13)
================  ==========================  ===================================

Right-hand sides are time derivatives times ``tau``: time enters only as ``t / tau``.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from .exceptions import InvalidInputError

KERNELS = ("gaussian", "von_mises", "paper")
TRACKED_KERNELS = ("von_mises",)
r"""Rhythmic kernels whose plans :mod:`dmpopt.response` keeps in segments, evaluating each
step's candidate bases only (as for the Gaussian bases of the discrete forms): their
log-activation is continuous in the phase as it wraps (``paper`` jumps where the phase wraps
at :math:`2\pi`, so its plan is one segment with every basis evaluated at every point)."""


def normalised_activations(log_psi):
    """Normalise log-activations ``log psi_i`` to ``psi_i / sum_j psi_j`` without underflow."""
    shifted = log_psi - ca.mmax(log_psi)
    psi = ca.exp(shifted)
    return psi / ca.sum1(psi)


def kernel_phase_terms(kernel: str, phase, direction=None) -> list:
    r"""What a kernel's log-activations need of the phase (:func:`basis_log_activations`),
    computed once per phase for every basis: ``von_mises``: the unit vector :math:`(\cos\phi,
    \sin\phi)` (``direction``, where the form gives it without trig functions:
    :meth:`Form.basis_direction`); ``gaussian``: the phase; ``paper``: the phase wrapped to
    :math:`[0, 2\pi)`."""
    if kernel == "gaussian":
        return [phase]
    if kernel == "von_mises":
        return list(direction) if direction is not None else [ca.cos(phase), ca.sin(phase)]
    if kernel == "paper":
        return [ca.fmod(ca.fmod(phase, 2 * np.pi) + 2 * np.pi, 2 * np.pi)]
    raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")


def kernel_phase_terms_slope(kernel: str, terms) -> list:
    r"""The derivative of :func:`kernel_phase_terms` in the phase, from the terms:
    ``von_mises``: the unit vector turned by a right angle, :math:`(-\sin\phi, \cos\phi)`;
    the others 1 (the wrapped phase moves with the phase)."""
    if kernel == "von_mises":
        return [-terms[1], terms[0]]
    if kernel in ("gaussian", "paper"):
        return [1.0]
    raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")


def kernel_basis_terms(kernel: str, centres, widths) -> list:
    r"""What a kernel's log-activations need of each basis (:func:`basis_log_activations`),
    computed once per basis: ``von_mises``: the centre's unit vector and the width; the others
    the centre and the width."""
    if kernel == "von_mises":
        return [ca.cos(centres), ca.sin(centres), widths]
    if kernel in ("gaussian", "paper"):
        return [centres, widths]
    raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")


def kernel_log_activations(kernel: str, phase_terms, basis_terms):
    r"""The log-activations of :func:`basis_log_activations` from the phase's and the bases'
    terms (:func:`kernel_phase_terms`, :func:`kernel_basis_terms`)."""
    if kernel == "von_mises":
        cos_phase, sin_phase = phase_terms
        cos_centres, sin_centres, widths = basis_terms
        return -0.5 * widths * ((cos_phase - cos_centres) ** 2 + (sin_phase - sin_centres) ** 2)
    if kernel in ("gaussian", "paper"):
        (phase,), (centres, widths) = phase_terms, basis_terms
        return -widths * (phase - centres) ** 2
    raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")


def basis_log_activations(kernel: str, phase, centres, widths):
    r"""Logarithm of the basis activations ``psi_i`` at ``phase``.

    ``gaussian``: :math:`-h_i (x - c_i)^2`, eq. (7) on the discrete phase.
    ``von_mises``: :math:`h_i (\cos(\phi - c_i) - 1)`, periodic, smooth at :math:`2\pi`,
    computed as :math:`-\frac{h_i}{2} |u(\phi) - u(c_i)|^2` with the unit vector :math:`u(a) =
    (\cos a, \sin a)` (:math:`|u - v|^2 = 2 - 2 u \cdot v`): the same number, at most 0 exactly
    and accurate near the centre, and the trig functions of the phase are taken once for every
    basis, not once per basis (the rhythmic rollouts' cost, :mod:`dmpopt.response`).
    ``paper``: :math:`-h_i (\mathrm{mod}(\phi, 2\pi) - c_i)^2`, eqs. (12) and (14) as printed.
    """
    return kernel_log_activations(
        kernel, kernel_phase_terms(kernel, phase), kernel_basis_terms(kernel, centres, widths)
    )


class Form:
    """A DMP form: the transformation system of eq. (5) with the canonical system of the
    subclass. Subclasses set the class attributes and override what differs."""

    name: str
    discrete: bool
    gain_names: tuple[str, ...]
    """Its constants, named after the paper's symbols (docs/glossary.md), in the order of the
    ``gains`` input of the compiled functions (and of a DMP's ``gains``)."""
    transformation_states: tuple[str, ...] = ("y", "z")
    """Transformation states per DOF, in the order of the state vector."""
    vectors_per_basis: int = 1
    """Features per basis function: 1 (discrete) or a 2-vector (rhythmic)."""
    forcing_on_velocity: bool = True
    r"""Where :math:`f` enters: :math:`\tau\dot y = z + f` (eq. (5)) or :math:`\tau\dot z`."""

    def __repr__(self) -> str:
        return f"<DMP form {self.name!r}>"

    @property
    def n_transformation(self) -> int:
        """Transformation states per DOF."""
        return len(self.transformation_states)

    def n_features(self, n_basis: int) -> int:
        """Weights per DOF."""
        return self.vectors_per_basis * n_basis

    # -- equations (symbolic) ---------------------------------------------------------------
    def canonical_rhs(self, canonical, target, gains, coupling):
        """Time derivative, times ``tau``, of the canonical state."""
        raise NotImplementedError

    def basis_phase(self, canonical):
        """The argument of the basis functions: the canonical state's first entry."""
        return canonical[0]

    def carrier(self, canonical):
        """What the normalised activations multiply (a row per vector entry)."""
        return canonical[1]

    def basis_direction(self, canonical):
        r"""The unit vector :math:`(\cos\phi, \sin\phi)` of the basis phase where the form
        has it without trig functions, else None (:func:`kernel_phase_terms`)."""
        return None

    def phase_terms(self, kernel: str, canonical) -> list:
        """What the kernel's log-activations need of the canonical state
        (:func:`kernel_phase_terms`)."""
        return kernel_phase_terms(
            kernel, self.basis_phase(canonical), self.basis_direction(canonical)
        )

    def log_activations(self, kernel: str, canonical, centres, widths):
        """The bases' log-activations at a canonical state (:func:`basis_log_activations`, the
        phase's terms from :meth:`phase_terms`)."""
        basis_terms = kernel_basis_terms(kernel, centres, widths)
        return kernel_log_activations(kernel, self.phase_terms(kernel, canonical), basis_terms)

    def features(self, kernel: str, canonical, centres, widths):
        r"""The vector that the weights multiply to give the forcing term:
        :math:`\psi_i \tilde v / \sum_j \psi_j` with :meth:`carrier` :math:`\tilde v`, laid
        out ``[psi_1 v1, psi_1 v2, psi_2 v1, ...]``."""
        log_psi = self.log_activations(kernel, canonical, centres, widths)
        psi = normalised_activations(log_psi)
        return ca.vec(self.carrier(canonical) @ psi.T)

    def transformation_rhs(self, transformation, goal, forcing, gains, coupling):
        r"""Eq. (5): :math:`\tau\dot z = \alpha_z(\beta_z(g - y) - z) + C`,
        :math:`\tau \dot y = z + f`, for all DOFs (``goal``: the setpoint of a rhythmic form)."""
        n = goal.shape[0]
        alpha_z, beta_z = gains[0], gains[1]
        y, z = transformation[:n], transformation[n : 2 * n]
        return ca.vertcat(z + forcing, alpha_z * (beta_z * (goal - y) - z) + coupling)

    # -- state layout (numeric) -------------------------------------------------------------
    def phase_of(self, canonical) -> float:
        """The normalised phase (discrete) or the oscillator's angle [rad] (rhythmic) at a
        numeric canonical state."""
        return float(canonical[0])

    def initial_transformation(self, start, scaled_velocity, forcing) -> list:
        r"""Transformation states, one array of ``D`` per entry of
        :attr:`transformation_states`, at position ``start`` with :math:`\tau\dot y` =
        ``scaled_velocity`` and forcing term ``forcing``: ``z = tau yd - f`` (eq. (5))."""
        return [start, scaled_velocity - forcing]


class _Discrete(Form):
    discrete = True
    gain_names = ("alpha_z", "beta_z", "alpha_v", "beta_v")

    def canonical_rhs(self, canonical, target, gains, coupling):
        r"""Eq. (6) normalised: :math:`\tau \dot v = \alpha_v(\beta_v (1 - x) - v) + C`,
        :math:`\tau \dot x = v`."""
        first, second = canonical[0], canonical[1]
        alpha_v, beta_v = gains[2], gains[3]
        return ca.vertcat(second, alpha_v * (beta_v * (1 - first) - second) + coupling)


class VelocityForm(_Discrete):
    """Eqs. (5)-(7): the forcing term drives the velocity."""

    name = "velocity"


class AccelerationForm(_Discrete):
    """Eq. (10): the forcing term drives the acceleration; the goal is filtered (``r``), so
    accelerations are continuous from rest (for inverse-dynamics control)."""

    name = "acceleration"
    gain_names = _Discrete.gain_names + ("alpha_g",)
    transformation_states = ("y", "z", "r")
    forcing_on_velocity = False

    def transformation_rhs(self, transformation, goal, forcing, gains, coupling):
        r"""Eq. (10): :math:`\tau\dot z = \alpha_z(\beta_z(r - y) - z) + f + C`,
        :math:`\tau\dot y = z`, :math:`\tau \dot r = \alpha_g (g - r)`."""
        n = goal.shape[0]
        alpha_z, beta_z, alpha_g = gains[0], gains[1], gains[4]
        y, z, r = transformation[:n], transformation[n : 2 * n], transformation[2 * n :]
        return ca.vertcat(
            z,
            alpha_z * (beta_z * (r - y) - z) + forcing + coupling,
            alpha_g * (goal - r),
        )

    def initial_transformation(self, start, scaled_velocity, forcing) -> list:
        """``z = tau yd`` (eq. (10)) and the goal filter at the start, ``r = start``."""
        return [start, scaled_velocity, start]


class _Rhythmic(Form):
    discrete = False
    vectors_per_basis = 2
    turn_direction = 1.0
    """Sign of d(angle)/d(t / tau) on the limit cycle."""

    def canonical_target(self, amplitude: float, gains) -> float:
        """The ``canonical_target`` input for an oscillation of ``amplitude``."""
        raise NotImplementedError

    def canonical_state(self, angle: float, amplitude: float, gains) -> tuple[float, float]:
        """The oscillator's state on its limit cycle at ``angle`` [rad]."""
        raise NotImplementedError

    def amplitude_of(self, canonical, gains) -> float:
        """The amplitude of the oscillation at a numeric canonical state."""
        raise NotImplementedError

    def period(self, gains) -> float:
        """Period of the oscillator for ``tau = 1``."""
        return 2 * math.pi


class PhaseForm(_Rhythmic):
    """Eqs. (11)-(12): a phase oscillator with an amplitude that converges to ``A``."""

    name = "phase"
    gain_names = ("alpha_z", "beta_z", "alpha_r")

    def canonical_rhs(self, canonical, target, gains, coupling):
        r"""Eq. (11): :math:`\tau\dot\phi = 1 + C`, :math:`\tau \dot r = \alpha_r (A - r)`,
        ``target`` = A."""
        alpha_r = gains[2]
        return ca.vertcat(1 + coupling, alpha_r * (target - canonical[1]))

    def carrier(self, canonical):
        r""":math:`\tilde v = [r\cos\phi, r\sin\phi]`, eq. (12)."""
        first, second = canonical[0], canonical[1]
        return ca.vertcat(second * ca.cos(first), second * ca.sin(first))

    def canonical_target(self, amplitude, gains):
        return amplitude

    def canonical_state(self, angle, amplitude, gains):
        return (angle, amplitude)

    def amplitude_of(self, canonical, gains):
        return float(canonical[1])


class EnergyForm(_Rhythmic):
    """Eqs. (13)-(14): a limit cycle of the energy :math:`E = (v^2 + k^2 x^2) / 2`."""

    name = "energy"
    gain_names = ("alpha_z", "beta_z", "alpha_E", "k")
    turn_direction = -1.0  # x = A cos, v = A k sin turns clockwise in (x, v)

    def canonical_rhs(self, canonical, target, gains, coupling):
        r"""Eq. (13): :math:`\tau \dot x = v`, :math:`\tau \dot v = -\alpha_E (E - E_0) v -
        k^2 x + C`, ``target`` = :math:`E_0`."""
        first, second = canonical[0], canonical[1]
        alpha_e, k = gains[2], gains[3]
        energy = 0.5 * (second**2 + k**2 * first**2)
        return ca.vertcat(second, -alpha_e * (energy - target) * second - k**2 * first + coupling)

    def basis_phase(self, canonical):
        r""":math:`\theta = \mathrm{atan2}(v, x)`, eq. (14)."""
        return ca.atan2(canonical[1], canonical[0])

    def basis_direction(self, canonical):
        r""":math:`(\cos\theta, \sin\theta) = (x, v) / \sqrt{x^2 + v^2}`: the phase's unit
        vector without the trig functions of :math:`\mathrm{atan2}` (the rhythmic rollouts'
        cost, :mod:`dmpopt.response`)."""
        radius = ca.sqrt(canonical[0] ** 2 + canonical[1] ** 2)
        return [canonical[0] / radius, canonical[1] / radius]

    def carrier(self, canonical):
        r""":math:`\tilde v = [x, v]`, eq. (14)."""
        return ca.vertcat(canonical[0], canonical[1])

    def canonical_target(self, amplitude, gains):
        """:math:`E_0 = (k A)^2 / 2`."""
        return 0.5 * (gains[3] * amplitude) ** 2

    def canonical_state(self, angle, amplitude, gains):
        # x = A cos(theta), v = A k sin(theta) gives atan2(v, x) = theta for k = 1
        k = gains[3]
        return (amplitude * float(np.cos(angle)), amplitude * k * float(np.sin(angle)))

    def phase_of(self, canonical) -> float:
        return float(np.arctan2(canonical[1], canonical[0]))

    def amplitude_of(self, canonical, gains):
        return float(np.hypot(canonical[0], canonical[1] / gains[3]))

    def period(self, gains) -> float:
        return 2 * math.pi / gains[3]


FORMS = {
    form.name: form for form in (VelocityForm(), AccelerationForm(), PhaseForm(), EnergyForm())
}
"""Every form by name: a new form is one class above and one entry here."""


def get(name: str, kind: str = "") -> Form:
    """The form called ``name``; ``kind`` ``"discrete"`` or ``"rhythmic"`` restricts it."""
    names = tuple(
        key for key, form in FORMS.items() if not kind or form.discrete == (kind == "discrete")
    )
    if not isinstance(name, str) or name not in names:
        raise InvalidInputError(f"form must be one of {names}, got {name!r}")
    return FORMS[name]
