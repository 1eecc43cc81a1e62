r"""Walking plans: footsteps, a linear-inverted-pendulum CoM plan through the DCM, and swing-foot
references from discrete DMPs.

Centre of mass. The linear inverted pendulum (LIPM) keeps the CoM at a constant height
:math:`z_c`; its horizontal position :math:`x` obeys

.. math:: \ddot x = \omega^2 (x - p), \qquad \omega = 1 / T_c = \sqrt{g / z_c},

with :math:`p` the zero-moment point (ZMP). For a constant ZMP the solution is
:math:`x(t) = p + (x_0 - p)\cosh(t/T_c) + T_c \dot x_0 \sinh(t/T_c)` (:func:`lipm_state`).
The divergent component of motion (DCM, capture point) :math:`\xi = x + \dot x / \omega`
splits it into :math:`\dot \xi = \omega (\xi - p)` (unstable) and
:math:`\dot x = \omega (\xi - x)` (stable).

The ZMP plan is piecewise linear in time: at the centre between the feet while standing, on
the stance foot in single support, moving linearly from one foot to the other in double
support. On a segment :math:`[t_a, t_b]` with ZMP slope :math:`m` the DCM that ends at
:math:`\xi_b` is

.. math:: \xi(t) = p(t) + m/\omega + (\xi_b - p_b - m/\omega)\, e^{\omega (t - t_b)},

so the DCM is computed backwards from the last segment, where it rests on the final ZMP
(the end-of-step recursion of Englsberger et al. 2015, with a linear ZMP in double
support). Without double support and for a steady walk of step length :math:`L` and
single-support time :math:`T` the end-of-step DCM lies :math:`L / (e^{\omega T} - 1)`
ahead of the next footstep (:func:`steady_dcm_offset`). The CoM follows
:math:`\dot x = \omega (\xi - x)` from its start, in closed form per segment.

Swing foot. A demonstrated foot lift (up, over and down: the foot is above its foothold
while still half its lift high, so that ground up to that much higher than planned is met
with the foot in place) is learnt once as two discrete DMPs: the horizontal motion (goal scaling
``"rotation"``: the demonstrated path is rotated and scaled onto each step) and the height
(``"translation"``: the lift profile is kept). Each step re-targets them to its start and
goal foothold, the DMP's goal-change property (Section 3.2).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

from .dmp import DiscreteDMP
from .exceptions import InvalidInputError, ShapeError
from .fitting import fit_discrete
from .trajectory import Trajectory
from .validation import integer, real, real_array

__all__ = [
    "GRAVITY",
    "Footstep",
    "SwingDMPs",
    "WalkPlan",
    "fit_swing_dmps",
    "footstep_plan",
    "lipm_state",
    "lipm_time_constant",
    "plan_walk",
    "quintic",
    "steady_dcm_offset",
    "swing_reference",
]

GRAVITY = 9.81  # [m/s^2]
SIDES = ("left", "right")


def lipm_time_constant(com_height: float, gravity: float = GRAVITY) -> float:
    r""":math:`T_c = \sqrt{z_c / g}` [s] of the linear inverted pendulum."""
    com_height = real("com_height", com_height, minimum=0.0, open_minimum=True)
    gravity = real("gravity", gravity, minimum=0.0, open_minimum=True)
    return float(np.sqrt(com_height / gravity))


def lipm_state(position, velocity, zmp, t, time_constant: float) -> tuple[np.ndarray, np.ndarray]:
    r"""Closed-form LIPM state after ``t`` seconds about a constant ZMP.

    .. math::
        x(t) = p + (x_0 - p)\cosh(t/T_c) + T_c \dot x_0 \sinh(t/T_c), \qquad
        \dot x(t) = \frac{x_0 - p}{T_c}\sinh(t/T_c) + \dot x_0 \cosh(t/T_c)

    Parameters
    ----------
    position, velocity, zmp : array_like, shape (n,)
        :math:`x_0` [m], :math:`\dot x_0` [m/s] and :math:`p` [m] (horizontal components).
    t : float
        Elapsed time [s], >= 0.
    time_constant : float
        :math:`T_c` [s] (:func:`lipm_time_constant`).

    Returns
    -------
    position, velocity : ndarray, shape (n,)
    """
    x0 = real_array("position", position, ndim=1)
    v0 = real_array("velocity", velocity, shape=x0.shape)
    p = real_array("zmp", zmp, shape=x0.shape)
    t = real("t", t, minimum=0.0)
    tc = real("time_constant", time_constant, minimum=0.0, open_minimum=True)
    c, s = np.cosh(t / tc), np.sinh(t / tc)
    return p + (x0 - p) * c + tc * v0 * s, (x0 - p) / tc * s + v0 * c


def steady_dcm_offset(step_length: float, single_support: float, time_constant: float) -> float:
    r"""Distance [m] of the end-of-step DCM ahead of the next footstep in a steady walk
    without double support: :math:`b = L / (e^{T/T_c} - 1)`, the fixed point of
    :math:`b = e^{-T/T_c}(b + L)`."""
    step_length = real("step_length", step_length)
    single_support = real("single_support", single_support, minimum=0.0, open_minimum=True)
    tc = real("time_constant", time_constant, minimum=0.0, open_minimum=True)
    return step_length / np.expm1(single_support / tc)


@dataclass(frozen=True, eq=False)
class Footstep:
    """One step: the ``side`` foot moves from ``start`` to ``goal`` (world positions of its sole
    frame [m], shape (3,)) while the other foot stands at ``stance``."""

    side: str
    start: np.ndarray
    goal: np.ndarray
    stance: np.ndarray

    def __post_init__(self):
        if self.side not in SIDES:
            raise InvalidInputError(f"side must be 'left' or 'right', got {self.side!r}")
        for name in ("start", "goal", "stance"):
            point = _point(name, getattr(self, name))
            point.setflags(write=False)
            object.__setattr__(self, name, point)

    @property
    def length(self) -> float:
        """Forward (x) displacement of the moving foot [m]."""
        return float(self.goal[0] - self.start[0])


def _point(name: str, value) -> np.ndarray:
    point = real_array(name, value)
    if point.shape != (3,):
        raise ShapeError(f"{name} has shape {point.shape}, expected (3,): a world position [m]")
    return point


def footstep_plan(
    left,
    right,
    n_in_place: int,
    n_forward: int,
    step_length: float,
    first_side: str = "right",
) -> list[Footstep]:
    """Footsteps on flat ground: ``n_in_place`` steps in place, then ``n_forward`` steps forward
    along x, then one step that brings the feet side by side.

    Sides alternate from ``first_side``. A forward step places the moving foot
    ``step_length`` ahead of the standing foot (so the first moves ``step_length``, the others
    ``2 step_length``); the closing step places it level with the standing foot. Each foot
    keeps its lateral position.

    Parameters
    ----------
    left, right : array_like, shape (3,)
        Initial positions of the left and right sole frames [m].
    n_in_place, n_forward : int
        Numbers of steps (>= 0).
    step_length : float
        [m], in [0, 0.4].
    first_side : {"left", "right"}
        The foot that moves first.

    Returns
    -------
    list of Footstep
        ``n_in_place + n_forward + 1`` steps if ``n_forward`` > 0, else ``n_in_place``.
    """
    feet = {"left": _point("left", left), "right": _point("right", right)}
    n_in_place = integer("n_in_place", n_in_place, minimum=0)
    n_forward = integer("n_forward", n_forward, minimum=0)
    step_length = real("step_length", step_length, minimum=0.0, maximum=0.4)
    if first_side not in SIDES:
        raise InvalidInputError(f"first_side must be 'left' or 'right', got {first_side!r}")
    advances = [0.0] * n_in_place + [step_length] * n_forward + ([0.0] if n_forward else [])
    steps, side = [], first_side
    for advance in advances:
        other = SIDES[1 - SIDES.index(side)]
        goal = feet[side].copy()
        goal[0] = feet[other][0] + advance
        steps.append(Footstep(side, feet[side], goal, feet[other]))
        feet[side] = goal
        side = other
    return steps


@dataclass(frozen=True, eq=False)
class WalkPlan:
    r"""A piecewise-linear ZMP plan with its DCM and LIPM CoM (module docstring).

    Attributes
    ----------
    footsteps : tuple of Footstep
    knot_times : ndarray, shape (n_knots,)
        Times [s] at which the ZMP plan changes slope, non-decreasing from 0 (two equal
        times: the ZMP jumps there, no double support).
    zmp_knots, dcm_knots, com_knots : ndarray, shape (n_knots, 2)
        ZMP, DCM and CoM at the knots [m] (the ZMP and the DCM of the segment that starts
        there, the CoM at rest at the first).
    com_height : float
        :math:`z_c` [m].
    time_constant : float
        :math:`T_c` [s].
    lift_off, touchdown : ndarray, shape (n_steps,)
        When each step's foot leaves and reaches the ground [s] (start and end of its single
        support).
    """

    footsteps: tuple
    knot_times: np.ndarray
    zmp_knots: np.ndarray
    dcm_knots: np.ndarray
    com_knots: np.ndarray
    com_height: float
    time_constant: float
    lift_off: np.ndarray
    touchdown: np.ndarray
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def duration(self) -> float:
        """End of the plan [s]."""
        return float(self.knot_times[-1])

    def _segment(self, t):
        """Times clipped to the plan, and the index of the segment each lies on (never a
        zero-length one: at a ZMP jump, the segment after it)."""
        t = real_array("t", t)
        t = np.clip(t, 0.0, self.duration)
        last = len(self.knot_times) - 2
        k = np.clip(np.searchsorted(self.knot_times, t, side="right") - 1, 0, last)
        return t, k

    def _evaluate(self, t):
        if isinstance(t, float) and math.isfinite(t):  # one time, as a walk's tick asks
            return self._evaluate_at(t)
        t, k = self._segment(t)
        return _lipm_segment(
            1.0 / self.time_constant,
            self.knot_times[k], self.knot_times[k + 1], self.zmp_knots[k], self.zmp_knots[k + 1],
            self.dcm_knots[k + 1], self.com_knots[k], t,
        )  # fmt: skip

    def _evaluate_at(self, t: float):
        """:meth:`_evaluate` at one time ``t`` [s] (a float), from :meth:`values_at`, the
        last time's answer kept (a tick asks for the CoM and then the ZMP and DCM at the same
        time). The arrays returned are read-only."""
        cache = self._cache
        if cache.get("t") == t:
            return cache["answer"]
        values = self.values_at(t)
        answer = tuple(np.array(values[a : a + 2]) for a in range(0, 10, 2))
        for array in answer:
            array.setflags(write=False)
        cache["t"], cache["answer"] = t, answer
        return answer

    def values_at(self, t: float) -> tuple:
        """ZMP, DCM, CoM position, velocity and acceleration (x then y of each: ten Python
        floats [m, m/s, m/s^2]) at one time ``t`` [s], a finite float: the numbers of
        :meth:`zmp`, :meth:`dcm` and :meth:`com`, each bit, computed on floats from the
        segment's coefficients (kept per segment) for a walk's tick."""
        cache = self._cache
        times = cache.get("times")
        if times is None:
            times = cache["times"] = self.knot_times.tolist()
        t = min(max(t, 0.0), times[-1])
        k = min(max(bisect.bisect_right(times, t) - 1, 0), len(times) - 2)
        w = 1.0 / self.time_constant
        segment = cache.get(k)
        if segment is None:
            ta, tb, pa, slope, c, e = _segment_coefficients(
                w, self.knot_times[k], self.knot_times[k + 1], self.zmp_knots[k],
                self.zmp_knots[k + 1], self.dcm_knots[k + 1], self.com_knots[k],
            )  # fmt: skip
            rows = tuple(zip(*(a.tolist() for a in (pa, slope, c, e))))
            segment = cache[k] = (float(ta), float(tb), rows)
        ta, tb, rows = segment
        # _segment_at on floats: the exponentials are the same for both axes
        grow, decay = float(np.exp(w * (t - tb))), float(np.exp(-w * (t - ta)))
        (px, dx, x, vx, ax), (py, dy, y, vy, ay) = (
            _segment_values(w, ta, *row, t, grow, decay) for row in rows
        )
        return px, py, dx, dy, x, y, vx, vy, ax, ay

    def zmp(self, t) -> np.ndarray:
        """ZMP [m] at time(s) ``t``, shape (..., 2)."""
        return self._evaluate(t)[0]

    def dcm(self, t) -> np.ndarray:
        r"""DCM :math:`\xi` [m] at time(s) ``t``, shape (..., 2)."""
        return self._evaluate(t)[1]

    def zmp_and_dcm(self, t) -> tuple[np.ndarray, np.ndarray]:
        """ZMP and DCM [m] at time(s) ``t`` (one evaluation), each of shape (..., 2)."""
        zmp, dcm = self._evaluate(t)[:2]
        return zmp, dcm

    def com(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CoM position [m], velocity [m/s] and acceleration [m/s^2] at time(s) ``t``, each of
        shape (..., 3) (the height is constant)."""
        _, _, position, velocity, acceleration = self._evaluate(t)
        if position.ndim == 1:  # one time
            return (
                np.array([position[0], position[1], self.com_height]),
                np.array([velocity[0], velocity[1], 0.0]),
                np.array([acceleration[0], acceleration[1], 0.0]),
            )
        height = np.full(position.shape[:-1] + (1,), self.com_height)
        zero = np.zeros_like(height)
        return (
            np.concatenate([position, height], axis=-1),
            np.concatenate([velocity, zero], axis=-1),
            np.concatenate([acceleration, zero], axis=-1),
        )

    def _check_step(self, step) -> int:
        i, n = integer("step", step, minimum=0), len(self.footsteps)
        if i >= n:
            raise InvalidInputError(f"step must be < {n}, the plan's number of steps, got {i}")
        return i

    def _start_com(self) -> np.ndarray:
        return np.append(self.com_knots[0], self.com_height)

    def with_touchdown(self, step: int, time: float, shift_later: bool = True) -> WalkPlan:
        """The plan with step ``step``'s touchdown at ``time`` [s]: its single support ends then.

        ``shift_later`` True: everything after shifts by the same amount (a late foot, or a
        step made quicker on purpose). False: the next lift-off (after the last step, the end
        of the closing double support) stays where it was and the double support absorbs the
        difference (a foot that met higher ground than planned, early: the walk keeps its
        rhythm and the weight moves over more slowly; shifted, the DCM plan would jump ahead
        of the robot). The DCM and CoM are solved again.
        """
        i = self._check_step(step)
        lift_off = float(self.lift_off[i])
        time = real("time", time, minimum=lift_off, open_minimum=True,
                    fix=f"after step {i}'s lift-off at {lift_off:.4g} s")  # fmt: skip
        times = self.knot_times.copy()
        if shift_later:
            times[3 + 2 * i :] += time - self.touchdown[i]
        else:
            end = times[4 + 2 * i]
            if time > end:
                raise InvalidInputError(
                    f"time must be <= {end:.4g} s (the end of step {i}'s double support) with "
                    f"shift_later=False, got {time:.4g}; use shift_later=True for a later "
                    "touchdown"
                )
            times[3 + 2 * i] = time
        return _solve(self.footsteps, times, self._start_com(), self.com_height,
                      self.time_constant)  # fmt: skip

    def with_lift_off(self, step: int, time: float) -> WalkPlan:
        """The plan with step ``step``'s lift-off at ``time`` [s] (the double support before
        it shortened or lengthened) and everything after it shifted by the same amount. The
        DCM and CoM are solved again."""
        i = self._check_step(step)
        start = float(self.knot_times[1 + 2 * i])
        fix = f"at or after the start of step {i}'s double support, {start:.4g} s"
        time = real("time", time, minimum=start, fix=fix)
        times = self.knot_times.copy()
        times[2 + 2 * i :] += time - self.lift_off[i]
        return _solve(self.footsteps, times, self._start_com(), self.com_height,
                      self.time_constant)  # fmt: skip

    def with_goal(self, step: int, goal) -> WalkPlan:
        """The plan with step ``step``'s foothold at ``goal`` (shape (3,), [m]) and every
        later foothold moved by the same displacement (the rest of the walk translated, as
        after a foot placed to recover balance). The DCM and CoM are solved again."""
        i = self._check_step(step)
        shift = _point("goal", goal) - self.footsteps[i].goal
        first = self.footsteps[0]
        feet = {first.side: first.start, SIDES[1 - SIDES.index(first.side)]: first.stance}
        steps = []
        for j, step_j in enumerate(self.footsteps):
            other = SIDES[1 - SIDES.index(step_j.side)]
            target = step_j.goal + shift if j >= i else step_j.goal
            steps.append(Footstep(step_j.side, feet[step_j.side], target, feet[other]))
            feet[step_j.side] = target
        return _solve(steps, self.knot_times.copy(), self._start_com(), self.com_height,
                      self.time_constant)  # fmt: skip

    def phase(self, t: float) -> tuple[str, int]:
        """``("double", i)`` before the lift-off of step ``i`` (``i = n_steps`` after the last
        touchdown) or ``("single", i)`` during step ``i``'s swing."""
        t = real("t", t)
        i = int(np.searchsorted(self.touchdown, t, side="right"))
        if i < len(self.footsteps) and t >= self.lift_off[i]:
            return "single", i
        return "double", i


def plan_walk(
    footsteps,
    com,
    com_height: float,
    single_support: float,
    double_support: float,
    initial_hold: float = 1.0,
    final_hold: float = 1.0,
    gravity: float = GRAVITY,
) -> WalkPlan:
    """ZMP, DCM and CoM plan for a footstep sequence (module docstring).

    The ZMP starts at ``com`` (its horizontal part) for ``initial_hold`` seconds; each step
    has a double support of ``double_support`` seconds (the ZMP moves onto the standing foot)
    then a single support of ``single_support`` seconds (the ZMP on the standing foot, the
    other foot swings); after the last step the ZMP moves in ``double_support`` seconds to the
    middle of the feet and stays there ``final_hold`` seconds.

    Parameters
    ----------
    footsteps : sequence of Footstep
        From :func:`footstep_plan`.
    com : array_like, shape (3,)
        Initial CoM [m] (at rest).
    com_height : float
        :math:`z_c` [m] of the plan (the CoM height kept throughout).
    single_support, double_support : float
        Durations [s]; ``single_support`` > 0, ``double_support`` >= 0.
    initial_hold, final_hold : float
        [s], > 0. A longer ``initial_hold`` lets the planned CoM start closer to rest
        (its start velocity is :math:`\\omega` times the DCM's distance from the CoM, which
        decays as :math:`e^{-\\omega\\, t_{\\text{hold}}}`).
    """
    footsteps = tuple(footsteps)
    for i, step in enumerate(footsteps):
        if not isinstance(step, Footstep):
            raise InvalidInputError(
                f"footsteps[{i}] is a {type(step).__name__}, expected a Footstep from footstep_plan"
            )
    com = _point("com", com)
    tc = lipm_time_constant(com_height, gravity)
    single_support = real("single_support", single_support, minimum=0.0, open_minimum=True)
    double_support = real("double_support", double_support, minimum=0.0)
    initial_hold = real("initial_hold", initial_hold, minimum=0.0, open_minimum=True)
    final_hold = real("final_hold", final_hold, minimum=0.0, open_minimum=True)

    times = [0.0, initial_hold]
    for _ in footsteps:  # double support (the ZMP moves onto the stance foot), then single
        times += [times[-1] + double_support, times[-1] + double_support + single_support]
    if footsteps:
        times.append(times[-1] + double_support)
    times.append(times[-1] + final_hold)
    return _solve(footsteps, np.array(times), com, float(com_height), tc)


def _zmp_knots(footsteps, n_knots: int) -> np.ndarray:
    """ZMP knots of a plan with knot times as built by :func:`plan_walk`: the start CoM is
    filled in by the caller (rows 0 and 1), each step adds its stance foot twice, then the
    middle of the last two feet."""
    points = np.empty((n_knots, 2))
    for i, step in enumerate(footsteps):
        points[2 + 2 * i] = points[3 + 2 * i] = step.stance[:2]
    if footsteps:
        last = footsteps[-1]
        points[-2] = points[-1] = 0.5 * (last.goal[:2] + last.stance[:2])
    return points


def _solve(footsteps, times, com, com_height, tc) -> WalkPlan:
    """The DCM backwards and the CoM forwards through the ZMP knots at ``times``."""
    n = len(times)
    points = _zmp_knots(footsteps, n)
    points[:2] = com[:2]
    if not footsteps:
        points[-1] = com[:2]
    w = 1.0 / tc
    dcm = np.empty((n, 2))
    dcm[-1] = points[-1]
    for k in range(n - 2, -1, -1):  # backwards: the DCM at the start of each segment
        if times[k + 1] == times[k]:  # a ZMP jump: the DCM is continuous
            dcm[k] = dcm[k + 1]
            continue
        dcm[k] = _lipm_segment(
            w, times[k], times[k + 1], points[k], points[k + 1], dcm[k + 1], com[:2], times[k]
        )[1]
    positions = np.empty((n, 2))
    positions[0] = com[:2]
    for k in range(n - 1):  # forwards: the CoM at the end of each segment
        positions[k + 1] = positions[k]
        if times[k + 1] > times[k]:
            positions[k + 1] = _lipm_segment(
                w, times[k], times[k + 1], points[k], points[k + 1], dcm[k + 1], positions[k],
                times[k + 1],
            )[2]  # fmt: skip
    steps = np.arange(len(footsteps))
    return WalkPlan(
        footsteps=tuple(footsteps),
        knot_times=times,
        zmp_knots=points,
        dcm_knots=dcm,
        com_knots=positions,
        com_height=com_height,
        time_constant=tc,
        lift_off=times[2 + 2 * steps],
        touchdown=times[3 + 2 * steps],
    )


def _lipm_segment(w, ta, tb, pa, pb, xi_b, x_a, t):
    r"""ZMP, DCM, CoM position, velocity and acceleration at ``t`` on the segment
    :math:`[t_a, t_b]` whose ZMP goes linearly from ``pa`` to ``pb``, whose DCM ends at
    ``xi_b`` and whose CoM starts at ``x_a``.

    With slope :math:`m` and :math:`c = \xi_b - p_b - m/\omega`:
    :math:`\xi = p + m/\omega + c\,e^{\omega(t - t_b)}` and
    :math:`x = p + \tfrac{c}{2} e^{\omega(t - t_b)} + e\,e^{-\omega(t - t_a)}`, with
    :math:`e` from :math:`x(t_a) = x_a`; both solve :math:`\dot\xi = \omega(\xi - p)`,
    :math:`\dot x = \omega(\xi - x)`.
    """
    column = np.ndim(t) > 0
    ta, tb, t = (np.asarray(a, dtype=float)[..., None] if column else a for a in (ta, tb, t))
    return _segment_at(w, ta, tb, pa, *_segment_coefficients(w, ta, tb, pa, pb, xi_b, x_a)[3:], t)


def _segment_coefficients(w, ta, tb, pa, pb, xi_b, x_a):
    """``(ta, tb, pa, slope, c, e)`` of :func:`_lipm_segment`: what does not depend on ``t``."""
    slope = (pb - pa) / (tb - ta)
    c = xi_b - pb - slope / w
    e = x_a - pa - 0.5 * c * np.exp(w * (ta - tb))
    return ta, tb, pa, slope, c, e


def _segment_at(w, ta, tb, pa, slope, c, e, t):
    """:func:`_lipm_segment` at ``t`` from its coefficients (:func:`_segment_coefficients`)."""
    grow, decay = np.exp(w * (t - tb)), np.exp(-w * (t - ta))
    return _segment_values(w, ta, pa, slope, c, e, t, grow, decay)


def _segment_values(w, ta, pa, slope, c, e, t, grow, decay):
    """ZMP, DCM, CoM position, velocity and acceleration of :func:`_segment_at`, given its
    exponentials ``grow`` :math:`= e^{w (t - t_b)}` and ``decay`` :math:`= e^{-w (t - t_a)}`
    (arrays or floats alike)."""
    p = pa + slope * (t - ta)
    position = p + 0.5 * c * grow + e * decay
    velocity = slope + 0.5 * w * c * grow - w * e * decay
    return p, p + slope / w + c * grow, position, velocity, w**2 * (position - p)


@dataclass(frozen=True, eq=False)
class SwingDMPs:
    """The demonstrated foot lift as two discrete DMPs (module docstring).

    Attributes
    ----------
    horizontal : DiscreteDMP
        x and y of the sole frame, goal scaling ``"rotation"``.
    vertical : DiscreteDMP
        z of the sole frame, goal scaling ``"translation"``.
    duration : float
        Length of the demonstration and of each swing [s].
    """

    horizontal: DiscreteDMP
    vertical: DiscreteDMP
    duration: float


def fit_swing_dmps(
    duration: float,
    step_length: float = 0.2,
    height: float = 0.05,
    descent: float = 0.4,
    dt: float = 0.01,
) -> SwingDMPs:
    r"""Fit the swing-foot DMPs to a demonstrated foot lift: up, over and down.

    With :math:`s = t / T`, :math:`d` = ``descent`` and the minimum-jerk profile
    :math:`m(u) = 10 u^3 - 15 u^4 + 6 u^5` (0 at :math:`u \le 0`, 1 at :math:`u \ge 1`), the
    demonstration moves forward by :math:`L\, m(s / (1 - d/2))` and lifts the foot by
    :math:`h\, m(s / d)` while :math:`s \le 1/2`, then by :math:`h\, m((1 - s) / d)`: it rises
    over the first :math:`d` of the swing, stays at :math:`h` and comes down over the last
    :math:`d`, and it is above its foothold (forward motion over) at :math:`s = 1 - d/2`,
    still :math:`h / 2` high. A foot that meets ground up to :math:`h / 2` higher than
    planned thus lands on its foothold, not short of it on an edge. Both start and end at rest
    with zero acceleration.

    Parameters
    ----------
    duration : float
        :math:`T` [s], the swing (single-support) time.
    step_length, height : float
        :math:`L` and :math:`h` [m] of the demonstration (> 0).
    descent : float
        :math:`d`, the fraction of the swing spent rising and the one spent coming down, in
        (0, 0.5].
    dt : float
        Sample period of the demonstration [s].
    """
    duration = real("duration", duration, minimum=0.0, open_minimum=True)
    step_length = real("step_length", step_length, minimum=0.0, open_minimum=True)
    height = real("height", height, minimum=0.0, open_minimum=True)
    descent = real("descent", descent, minimum=0.0, maximum=0.5, open_minimum=True)
    dt = real("dt", dt, minimum=0.0, maximum=duration / 20, open_minimum=True)
    times = np.linspace(0.0, duration, int(round(duration / dt)) + 1)
    s = times / duration
    forward = step_length * _minimum_jerk(s / (1.0 - descent / 2))
    lift = height * _minimum_jerk(np.minimum(s, 1.0 - s) / descent)
    horizontal = Trajectory.from_positions(times, np.column_stack([forward, 0.0 * s]))
    vertical = Trajectory.from_positions(times, lift[:, None])
    return SwingDMPs(
        horizontal=fit_discrete(horizontal, 20, goal_scaling="rotation"),
        vertical=fit_discrete(vertical, 20, goal_scaling="translation"),
        duration=duration,
    )


def _minimum_jerk(u):
    """:math:`10 u^3 - 15 u^4 + 6 u^5` of ``u`` clipped to [0, 1]."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10.0 - 15.0 * u + 6.0 * u**2)


def quintic(position, velocity, acceleration, goal, duration: float, t: float):
    r"""The quintic polynomial from ``position``, ``velocity`` and ``acceleration`` at time 0 to
    ``goal`` at rest (zero velocity and acceleration) at ``duration`` [s], at time ``t``
    (held at ``goal`` after ``duration``): position, velocity and acceleration.

    With :math:`h = g - p_0`, :math:`p(t) = p_0 + v_0 t + a_0 t^2 / 2 + c_3 t^3 + c_4 t^4 +
    c_5 t^5`, :math:`c_3 = (20 h - 12 v_0 T - 3 a_0 T^2) / (2 T^3)`,
    :math:`c_4 = (-30 h + 16 v_0 T + 3 a_0 T^2) / (2 T^4)`,
    :math:`c_5 = (12 h - 6 v_0 T - a_0 T^2) / (2 T^5)`; from rest it is the minimum-jerk
    :math:`p_0 + h (10 u^3 - 15 u^4 + 6 u^5)`, :math:`u = t / T`. A step adjustment moves the
    swinging foot by it, so that the foot is over its new foothold by ``duration`` whatever
    it was doing.
    """
    p0, v0 = real_array("position", position), real_array("velocity", velocity)
    a0 = real_array("acceleration", acceleration)
    goal = real_array("goal", goal)
    duration = real("duration", duration, minimum=0.0, open_minimum=True)
    t = min(real("t", t, minimum=0.0), duration)
    h, T = goal - p0, duration
    c3 = (20 * h - 12 * v0 * T - 3 * a0 * T**2) / (2 * T**3)
    c4 = (-30 * h + 16 * v0 * T + 3 * a0 * T**2) / (2 * T**4)
    c5 = (12 * h - 6 * v0 * T - a0 * T**2) / (2 * T**5)
    return (
        p0 + v0 * t + a0 * t**2 / 2 + c3 * t**3 + c4 * t**4 + c5 * t**5,
        v0 + a0 * t + 3 * c3 * t**2 + 4 * c4 * t**3 + 5 * c5 * t**4,
        a0 + 6 * c3 * t + 12 * c4 * t**2 + 20 * c5 * t**3,
    )


def swing_reference(dmps: SwingDMPs, start, goal, dt: float = 1e-3) -> Trajectory:
    """The swing-foot reference of one step: both DMPs re-targeted to the step's ``start`` and
    ``goal`` (world positions of the sole frame [m], shape (3,)) and rolled out over the
    swing, from rest.

    Returns
    -------
    Trajectory
        Samples at ``0, dt, ..., dmps.duration``; 3 DOFs (x, y, z).
    """
    if not isinstance(dmps, SwingDMPs):
        raise InvalidInputError(
            f"dmps must be SwingDMPs from fit_swing_dmps, got {type(dmps).__name__}"
        )
    start, goal = _point("start", start), _point("goal", goal)
    parts = [
        dmp.replace(start=start[axes], goal=goal[axes]).rollout(dmps.duration, dt, 0.0)
        for dmp, axes in ((dmps.horizontal, slice(0, 2)), (dmps.vertical, slice(2, 3)))
    ]
    return Trajectory(
        parts[0].times,
        np.hstack([p.positions for p in parts]),
        np.hstack([p.velocities for p in parts]),
        np.hstack([p.accelerations for p in parts]),
    )
