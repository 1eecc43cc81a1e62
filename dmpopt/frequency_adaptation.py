r"""Phase resetting and frequency adaptation of a rhythmic DMP at heel strike, eq. (21).

At heel strike ``n`` of a walker driven by rhythmic DMPs on one shared oscillator
([dmpopt-paper] eq. (21), Section 4.3):

.. math::

    \phi \leftarrow \phi_{\mathrm{robot}}^{\mathrm{heelstrike}}, \qquad
    \omega_{n+1} = \omega_n + K\,(\omega_n^{\mathrm{measured}} - \omega_n), \qquad
    \omega_n^{\mathrm{measured}} = \pi / T_n,

where :math:`\phi_{\mathrm{robot}}^{\mathrm{heelstrike}}` is 0 at the heel strike of the leg the
oscillator is defined on and :math:`\pi` at the heel strike of the other leg, and :math:`T_n`
is the duration of step ``n`` (half a period), the time between two successive heel strikes.

Symbols: :math:`\phi` phase (``phase``), :math:`\omega` oscillator frequency [rad/s]
(``frequency``; the DMP time constant is :math:`1/\omega`), :math:`K` (``gain``),
:math:`T_n` (``step_duration``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.validation import real, real_array

__all__ = [
    "FrequencyAdaptation",
    "HeelStrike",
    "HeelStrikeDetector",
    "adapt_frequency",
    "closed_loop_frequencies",
    "heel_strike_phase",
    "measured_frequency",
]


def measured_frequency(step_duration: float) -> float:
    r"""Frequency of locomotion measured over one step, :math:`\pi / T_n` of eq. (21) [rad/s].

    Parameters
    ----------
    step_duration : float
        :math:`T_n`, time between two successive heel strikes [s] (half a gait period).
    """
    step_duration = real("step_duration", step_duration, minimum=0.0, open_minimum=True)
    return float(np.pi / step_duration)


def _check_gain(gain) -> float:
    return real("gain", gain, minimum=0.0, maximum=2.0, fix="[0, 1] converges without overshoot")


def _check_leg(name: str, leg) -> int:
    if (
        isinstance(leg, (bool, np.bool_))
        or not isinstance(leg, (int, np.integer))
        or leg not in (0, 1)
    ):
        raise InvalidInputError(f"{name} must be 0 or 1, got {leg!r}")
    return int(leg)


def adapt_frequency(frequency: float, step_duration: float, gain: float) -> float:
    r"""One step of the frequency adaptation law, eq. (21).

    .. math:: \omega_{n+1} = \omega_n + K (\pi / T_n - \omega_n)

    Parameters
    ----------
    frequency : float
        :math:`\omega_n` [rad/s].
    step_duration : float
        :math:`T_n` [s].
    gain : float
        :math:`K`, in [0, 1] for a convergent (non-overshooting) update.

    Returns
    -------
    float
        :math:`\omega_{n+1}` [rad/s].
    """
    frequency = real("frequency", frequency, minimum=0.0, open_minimum=True)
    gain = _check_gain(gain)
    return float(frequency + gain * (measured_frequency(step_duration) - frequency))


def heel_strike_phase(leg: int, oscillator_leg: int = 0) -> float:
    r"""Oscillator phase at a heel strike, :math:`\phi_{\mathrm{robot}}^{\mathrm{heelstrike}}`
    of eq. (21): 0 for the oscillator's own leg, :math:`\pi` for the other leg [rad]."""
    leg = _check_leg("leg", leg)
    oscillator_leg = _check_leg("oscillator_leg", oscillator_leg)
    return 0.0 if leg == oscillator_leg else float(np.pi)


@dataclass(frozen=True)
class HeelStrike:
    """A foot landed: ``time`` [s], ``leg`` index and world ``position`` [m]."""

    time: float
    leg: int
    position: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "time", real("time", self.time))
        object.__setattr__(self, "leg", _check_leg("leg", self.leg))
        position = real_array("position", self.position)
        if position.shape != (3,):
            raise ShapeError(f"position has shape {position.shape}, expected (3,)")
        object.__setattr__(self, "position", position)


class HeelStrikeDetector:
    """Heel strikes from per-foot contact flags, robust to contact chatter.

    A touchdown counts as a heel strike when the foot was off the ground for at least
    ``min_swing_time`` before it and the other leg struck last (legs alternate), so bounces
    of a compliant contact and scuffs of the swing foot are not taken for steps.

    Parameters
    ----------
    min_swing_time : float
        Minimum airborne time before a touchdown counts [s].
    alternate : bool
        Require left and right strikes to alternate.
    """

    def __init__(self, min_swing_time: float = 0.1, alternate: bool = True):
        self.min_swing_time = real("min_swing_time", min_swing_time, minimum=0.0)
        if not isinstance(alternate, (bool, np.bool_)):
            raise InvalidInputError(f"alternate must be True or False, got {alternate!r}")
        self.alternate = bool(alternate)
        self.strikes: list[HeelStrike] = []
        self._lift_off = [-np.inf, -np.inf]
        self._was_in_contact = [True, True]
        self._time = -np.inf

    @property
    def last_contact(self) -> tuple[bool, bool]:
        """The contact flags of the last :meth:`update` (both True before the first): an
        update with the same flags changes nothing and finds no heel strike, so a loop may
        skip it."""
        return self._was_in_contact[0], self._was_in_contact[1]

    def update(self, time: float, in_contact, positions=None) -> HeelStrike | None:
        """Feed the contact flags of both feet at ``time``; return a new heel strike or None.

        Parameters
        ----------
        time : float
            [s]
        in_contact : sequence of bool, length 2
        positions : array_like, shape (2, 3), optional
            Foot positions, stored with the strike.
        """
        time = real("time", time)
        if time < self._time:
            raise InvalidInputError(
                f"time must not decrease between updates, got {time!r} after {self._time!r}"
            )
        self._time = time
        flags = np.asarray(in_contact)
        if flags.shape != (2,) or flags.dtype.kind not in "biu":
            raise InvalidInputError(
                f"in_contact must be two booleans (one per foot), got {in_contact!r}"
            )
        if positions is not None:
            positions = real_array("positions", positions)
            if positions.shape != (2, 3):
                raise ShapeError(f"positions has shape {positions.shape}, expected (2, 3)")
        strike = None
        for leg in (0, 1):
            touching = bool(flags[leg])
            was = self._was_in_contact[leg]
            if was and not touching:
                self._lift_off[leg] = time
            elif touching and not was:
                airborne = time - self._lift_off[leg]
                last_leg = self.strikes[-1].leg if self.strikes else None
                alternates = not self.alternate or last_leg != leg
                if airborne >= self.min_swing_time and alternates:
                    where = np.zeros(3) if positions is None else positions[leg]
                    strike = HeelStrike(time, leg, where)
                    self.strikes.append(strike)
            self._was_in_contact[leg] = touching
        return strike


@dataclass
class FrequencyAdaptation:
    """Phase resetting and frequency adaptation of eq. (21), each switchable.

    Parameters
    ----------
    frequency : float
        Initial oscillator frequency :math:`\\omega_0` [rad/s].
    gain : float
        :math:`K` of eq. (21).
    reset_phase : bool
        Apply :math:`\\phi \\leftarrow \\phi_{\\mathrm{robot}}^{\\mathrm{heelstrike}}`.
    adapt : bool
        Apply the frequency update; when False the frequency stays at its initial value.
    oscillator_leg : int
        The leg whose heel strike has phase 0.

    Attributes
    ----------
    frequencies : list of float
        :math:`\\omega_n` after each heel strike (the first entry is :math:`\\omega_0`).
    step_durations : list of float
        :math:`T_n` of each completed step [s].
    """

    frequency: float
    gain: float = 0.3
    reset_phase: bool = True
    adapt: bool = True
    oscillator_leg: int = 0
    frequencies: list = field(default_factory=list)
    step_durations: list = field(default_factory=list)
    _last_strike_time: float | None = None

    def __post_init__(self):
        self.frequency = real("frequency", self.frequency, minimum=0.0, open_minimum=True)
        self.gain = _check_gain(self.gain)
        self.oscillator_leg = _check_leg("oscillator_leg", self.oscillator_leg)
        for name in ("reset_phase", "adapt"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise InvalidInputError(
                    f"{name} must be True or False, got {getattr(self, name)!r}"
                )
        self.frequencies = [self.frequency]

    def on_heel_strike(self, strike: HeelStrike) -> tuple[float | None, float]:
        """Apply eq. (21) at a heel strike.

        Returns
        -------
        phase : float or None
            The phase to reset the oscillator to, or None when resetting is off.
        frequency : float
            :math:`\\omega_{n+1}` [rad/s] (unchanged when adaptation is off or at the first
            strike, which has no step duration yet).
        """
        if not isinstance(strike, HeelStrike):
            raise InvalidInputError(f"strike must be a HeelStrike, got {type(strike).__name__}")
        if self._last_strike_time is not None:
            duration = strike.time - self._last_strike_time
            if not duration > 0:
                raise InvalidInputError(
                    f"strike.time = {strike.time!r} does not follow the previous heel strike at "
                    f"{self._last_strike_time!r}; feed strikes in time order"
                )
            self.step_durations.append(duration)
            if self.adapt:
                self.frequency = adapt_frequency(self.frequency, duration, self.gain)
            self.frequencies.append(self.frequency)
        self._last_strike_time = strike.time
        phase = heel_strike_phase(strike.leg, self.oscillator_leg) if self.reset_phase else None
        return phase, self.frequency


def closed_loop_frequencies(model, q, joints, torque_law, step: float = 1e-6) -> np.ndarray:
    r"""Natural frequencies of some joints of a robot under a feedback law, linearised.

    The other coordinates are held at ``q`` (at rest), e.g. a swing leg with its hip held
    still. With :math:`M_{jj}` the joints' block of the mass matrix, :math:`h_j(q, v)` their
    bias forces (gravity, Coriolis) and :math:`\tau(q, v)` the law's torques on them,

    .. math::

        M_{jj}\,\ddot q_j + h_j = \tau \;\Rightarrow\;
        M_{jj}\,\delta\ddot q_j + D\,\delta\dot q_j + K\,\delta q_j = 0,\quad
        K = \partial (h_j - \tau) / \partial q_j,

    :math:`K` by central differences at :math:`(q, 0)`. The undamped natural frequencies are
    :math:`\omega_i = \sqrt{\lambda_i}` with :math:`K x = \lambda M_{jj} x`; for one joint
    with stiffness :math:`k_p`, centre of mass at :math:`d` below the axis and inertia
    :math:`I` about it, :math:`\omega = \sqrt{(k_p + m g d) / I}`.

    Parameters
    ----------
    model : pinocchio.Model
    q : array_like, shape (model.nq,)
        Configuration to linearise at.
    joints : sequence of int
        Indices in the velocity vector of the joints that move.
    torque_law : callable
        ``torque_law(q, v)`` returns the generalised forces on ``joints``, shape
        ``(len(joints),)`` [N m].
    step : float
        Finite-difference step [rad].

    Returns
    -------
    ndarray
        :math:`\omega_i` [rad/s], ascending; NaN for an unstable mode (:math:`\lambda_i < 0`).
    """
    import pinocchio as pin

    if not isinstance(model, pin.Model):
        raise InvalidInputError(f"model must be a pinocchio.Model, got {type(model).__name__}")
    q = real_array("q", q, shape=(model.nq,), expected="a configuration of model")
    index = np.asarray(joints)
    if (
        index.ndim != 1
        or index.size == 0
        or index.dtype.kind not in "iu"
        or len(set(index.tolist())) != index.size
        or index.min() < 0
        or index.max() >= model.nv
    ):
        raise InvalidInputError(
            f"joints must be distinct velocity indices in [0, {model.nv}), got {joints!r}"
        )
    if not callable(torque_law):
        raise InvalidInputError(
            f"torque_law must be a callable torque_law(q, v), got {type(torque_law).__name__}"
        )
    step = real("step", step, minimum=0.0, open_minimum=True)
    data = model.createData()
    zero = np.zeros(model.nv)

    def residual(dq: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """h_j - tau at the perturbed state."""
        full_dq, v = zero.copy(), zero.copy()
        full_dq[index], v[index] = dq, dv
        moved = pin.integrate(model, q, full_dq)
        torque = real_array(
            "torque_law(q, v)",
            torque_law(moved, v),
            shape=(index.size,),
            expected="generalised forces on joints [N m]",
        )
        return pin.rnea(model, data, moved, v, zero)[index] - torque

    n = index.size
    stiffness, rest = np.empty((n, n)), np.zeros(n)
    for k, unit in enumerate(np.eye(n) * step):
        stiffness[:, k] = (residual(unit, rest) - residual(-unit, rest)) / (2 * step)
    mass = pin.crba(model, data, q)
    mass = np.triu(mass) + np.triu(mass, 1).T
    block = mass[np.ix_(index, index)]
    squares = np.linalg.eigvals(np.linalg.solve(block, stiffness)).real
    return np.sort(np.sqrt(np.where(squares >= 0, squares, np.nan)))
