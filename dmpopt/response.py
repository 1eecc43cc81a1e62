r"""The response matrices of a rollout of one DOF, in one compiled pass (numba).

A rollout's positions, velocities and accelerations are linear in the initial transformation
states, the goal and the forcing weights (:mod:`dmpopt.dmp`). Their coefficients, the
response matrices, follow from the RK4 step of the transformation system as matrices
(:func:`symbolic.transformation_matrices`) driven at each of the step's four stages by the
features there. :func:`response_matrices` runs that recurrence, the canonical system's step
and the features in one loop over the steps, compiled by numba, without arrays of features.

Where the numbers come from. Every form- and kernel-specific expression is CasADi's: the
canonical step (:func:`symbolic.canonical_step_function`), the basis phase, carrier and their
rates (:func:`symbolic.phase_point_function`) and one basis function's log-activation and its
slope (:func:`symbolic.log_activation_function`) are translated instruction by instruction
into Python for numba (:func:`symbolic.numba_source`), so they are computed by the same
operations in the same order as CasADi's virtual machine. What the loop adds is the same for
every form and kernel: the normalisation of :func:`forms.normalised_activations`
(:math:`a_j = e^{l_j - M} / \sum_i e^{l_i - M}`, :math:`M = \max_i l_i`), the layout of
:meth:`forms.Form.features` (:math:`\phi_{j,e} = a_j C_e` with the carrier :math:`C`) and the
rate of that product along the canonical flow, :math:`\dot\phi_{j,e} = a_j (l_j' - \sum_i a_i
l_i') \dot p\, C_e + a_j \dot C_e` (:math:`l' = \partial l / \partial p`, :math:`p` the basis
phase). tests/core/test_response.py checks the result against CasADi's own
:func:`symbolic.feature_rate_function` for every form and kernel, and the rollout against the
step-by-step integration. So a form or kernel added to :mod:`dmpopt.forms` reaches this pass
with no code here, if its log-activations have the two properties the truncation uses
(below); a numba copy of each form's equations was not written, as it would be a second
definition to keep equal to CasADi's. (Evaluating CasADi's instruction list on arrays instead, as
:class:`symbolic.ArrayFunction` does, took 45-55 ms of the 60-170 ms that the LASA demo's
plan of 10676 steps cost: every basis at all 4 x 10676 stage points, each through numpy
temporaries.)

Truncation. Bases whose log-activation is more than :math:`L` below the largest,
:math:`l_j < M - L`, before the first or after the last basis at or above :math:`M - L`, are
left out of the normalisation (their features are 0), so only the exp of the few bases near
the phase is taken. For the kernels' log-activations (all :math:`l \le 0`, and :math:`l'^2 \le
4 h |l|` with the width :math:`h`: equality for the Gaussian and the printed periodic kernel,
:math:`h^2 \sin^2\theta \le 2 h^2 (1 - \cos\theta)` for von Mises) this changes, with
:math:`n` bases and :math:`n e^{-L} \le 1/8`:

- each normalised activation by at most :math:`n e^{-L}`: the kept ones by the relative
  change :math:`(S - \tilde S) / \tilde S \le n e^{-L}` of the sum (:math:`\tilde S \ge 1`
  holds the largest, :math:`e^0`), the dropped ones are below :math:`e^{-L}`;
- each normalised activation's rate by at most :math:`5 n e^{-L} G |\dot p|` with
  :math:`G = 2\sqrt{h_\max (|M| + L)}`: :math:`G` bounds :math:`|l_j'|` of every basis with
  :math:`l_j \ge M - L`, and :math:`a_j |l_j'| \le 2 e^{-u} \sqrt{h_\max (|M| + u)} \le e^{-L}
  G` of every other (:math:`u = M - l_j > L`, :math:`a_j \le e^{-u}`, and :math:`e^{-u}
  \sqrt{|M| + u}` decreases for :math:`u \ge 1/2`), so
  the weighted slope :math:`T = \sum_i a_i l_i'` changes by at most :math:`2 n e^{-L} G (1 +
  n e^{-L})` and :math:`a_j' = a_j (l_j' - T) \dot p` by at most :math:`4 n e^{-L} G (1 + 2 n
  e^{-L}) |\dot p|`.

At the stage points :math:`L = L_0 = \ln(2 n / \epsilon)` (:func:`first_level`) makes the first
bound :math:`\epsilon / 2`; at the samples, where the rates are needed,
:math:`L = L_0 + \ln(1 + 5 G)` (:math:`G` taken at :math:`L = 3 L_0`, valid while :math:`L
\le 3 L_0`, else nothing is left out) makes the features' rates :math:`\dot\phi = \dot a C + a
\dot C` change by at most :math:`\frac{\epsilon}{2} (|\dot p| |C| + |\dot C|)`. The features
are then those of all the bases to rounding, and the rollout equals the stepper's integration
as before (tests/core/test_response.py checks both bounds at levels far below these, where
the truncation shows).

The settling tail (:class:`ResponseMatrices`). The forcing term does not vanish once a
discrete plan settles: the normalisation always keeps the largest basis and the carrier, the
phase velocity :math:`v`, only decays (2.8e-7 at the end of the LASA demo's default plan,
whose last 77 % of steps follow its convergence time); the bases near the phase's end (10 of
50 there) are forced to the last step. Every other column is forced only over a stretch of
steps, then moves under the unforced step, which is affine in the state with constant
matrices (:func:`symbolic.transformation_matrices`): its response from step :math:`K` on is
that of the unit states and the goal, times its state at :math:`K`. A first pass
(``candidates``, below) bounds the bases each step may force; :func:`tail_start` puts
:math:`K` where the dense head and the tail (the unit responses and the columns still forced
after :math:`K`) hold the fewest numbers: for the LASA demo 2237 of 10676 steps dense, 5.9
instead of 13.6 MB. The head and
the forced columns are the dense pass's to the bit; the other columns round differently, by
at most :math:`(n + 1) \epsilon ||\tilde O||_\infty P (2 i P ||\tilde S||_\infty + 3)
||c_j||_1` at tail step :math:`i` (:math:`\tilde S`, :math:`\tilde O` the step and output
with the goal as a constant state, :math:`P` the largest :math:`||\tilde S^i||_\infty`,
:math:`c_j` the column's state and goal factor; derived and checked in
tests/core/test_response.py). Rhythmic forms keep no tail: their phase cycles, so every
basis is forced once a period; their pass (and that of a dense response) finds the kept
bases itself.

Which bases are kept is found without evaluating every basis at every point. Both ways
rest on :math:`l'^2 \le 4 h |l|`: :math:`\sqrt{-l_j}` changes by at most :math:`\sqrt{h_j}`
per unit of phase, for kernels continuous in the phase.

- Discrete forms (``candidates``): their phase runs once from 0 towards 1, so consecutive
  steps are grouped into blocks whose points (samples and stages) lie within :math:`r =`
  ``BLOCK_REACH`` :math:`/ \sqrt{h_\max}` of the block's middle phase :math:`m`. With
  :math:`s_j = \sqrt{-l_j(m)}`, every point of the block has :math:`-(s_j + \sqrt{h_j} r)^2
  \le l_j \le -\max(s_j - \sqrt{h_j} r, 0)^2`, so its largest log-activation :math:`M` is at
  least :math:`T = \max_j -(s_j + \sqrt{h_j} r)^2` and its level (the samples', the lowest;
  the level :math:`M - L(M)` falls as :math:`M` does) at least that of :math:`T`. A basis
  whose upper bound is more than ``SKIP_MARGIN`` (which covers the rounding of these few
  operations) below it is below the level at every point of the block; the others, from
  the first to the last, are the step's candidates, 50 log-activations per block instead
  of per point. At each point the response pass evaluates the candidates only: the largest
  log-activation and the kept bases are those of every basis (tests/core/test_response.py
  compares them at every point), so the features, and the response, are the same to the
  bit. (The Gaussian is continuous in the phase, and a discrete phase stays far from
  :math:`2\pi`, where the printed periodic kernel jumps.)
- Rhythmic forms (``tracked_window``, :data:`forms.TRACKED_KERNELS`): their phase cycles, so
  the pass tracks the bases itself: a basis evaluated at phase :math:`p_j` is still more
  than a margin below the level at phase :math:`p` if :math:`(\sqrt{-l_j(p_j)} - \sqrt{h_j}
  |p - p_j|)^2` says so, and is then left out. Not for the printed periodic kernel, which
  jumps where the phase wraps. (The phase form's first rollout of 50 von Mises bases, 9426
  steps, fell from 75 to 50 ms of thread CPU at load 8 with it.)

Where the LASA demo's first rollout goes (2 DOFs, 50 Gaussian bases, 10676 steps;
benchmarks/bench_core.py; thread CPU at load 9, medians of 40 new DMPs, 18.9 ms in all):
the candidates pass 2 %, the head pass (2237 steps, 53 columns) 25 %, the tail pass (8439
steps, 15 columns: about 10 bases kept at each of 4 points per step, an exp each) 54 %, the
product 9 %. A third of it (6.4 ms) was the system's: the passes' first writes to the 5.9
MB of new response fault it in page by page (1440 pages of 4 KiB; each new DMP keeps its
last plan, so the memory is new). Before the candidates (one pass evaluating all 50 bases
at all 4 points of each step, 28 % of the first rollout, and the head and tail passes each
kept basis again) the first rollout cost 1.1-1.4 times as much in side-by-side runs of
benchmarks/bench_core.py at load 8-9, and the response passes alone 1.3 times (medians of
40, interleaved).
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
import mmap
import os
import sys
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from . import forms, symbolic

EPS = float(np.finfo(float).eps)


def first_level(n_basis: int) -> float:
    r"""The truncation level at the stage points, :math:`L_0 = \ln(2 n / \epsilon)`
    (module docstring): the normalised activations change by at most :math:`n e^{-L_0} =
    \epsilon / 2`. The level at the samples follows from it in the compiled loop."""
    return math.log(2.0 * n_basis / EPS)


_KERNELS = '''
_compile = numba.njit(cache=True, nogil=True, error_model="numpy")
_inline = numba.njit(nogil=True, error_model="numpy", inline="always")  # per point: no call
canonical_step = _compile(canonical_step)
phase_point = _compile(phase_point)
log_activation = _compile(log_activation)
N_CARRIER = {n_carrier}
N_STATES = {n_states}
TRACKED = {tracked}
SKIP_MARGIN = 1.0  # a basis is left unevaluated only if proved this far below the level
BLOCK_REACH = 0.25  # sqrt(max h) times the half-width of a block of candidates (phase)


@_compile
def window(canonical, target, gains, centres, widths, max_width, first, with_rate, logs):
    """The point's phase values and the bases kept at one canonical state (those from the
    first to the last at or above the truncation level): (point, lo, hi, top), logs[j] the
    log-activation of basis j."""
    point = phase_point(canonical, target, gains)
    n_basis = centres.size
    for j in range(n_basis):
        logs[j] = log_activation(point[0], centres[j], widths[j])[0]
    top = logs[0]
    for j in range(1, n_basis):
        top = max(top, logs[j])
    bound = first
    if with_rate:  # the level at the samples (module docstring)
        slope = 2.0 * math.sqrt(max_width * (abs(top) + 3.0 * first))
        extra = math.log1p(5.0 * slope)
        bound = first + extra if extra <= 2.0 * first else math.inf
    level = top - bound
    lo, hi = 0, n_basis - 1
    while logs[lo] < level:
        lo += 1
    while logs[hi] < level:
        hi -= 1
    return point, lo, hi, top


@_inline
def kept_features(point, lo, hi, top, centres, widths, with_rate, logs, seen, mark, slopes,
                  values, rates):
    """Features (with_rate: and their rates) of the bases lo .. hi at the point ``point`` of
    phase_point, ``top`` the largest log-activation there: values[i, e] = a_(lo+i) C_e,
    rates[i, e] its rate. logs[j] is taken as basis j's log-activation where seen[j] ==
    mark (evaluated there by tracked_window or candidate_window), else evaluated."""
    phase, phase_rate = point[0], point[1]
    total = 0.0
    for j in range(lo, hi + 1):
        if with_rate:  # the log-activation and its slope from one evaluation
            value, slopes[j - lo] = log_activation(phase, centres[j], widths[j])
            if seen[j] != mark:
                logs[j] = value
        elif seen[j] != mark:
            logs[j] = log_activation(phase, centres[j], widths[j])[0]
        weight = math.exp(logs[j] - top)
        logs[j] = weight
        total += weight
    inverse = 1.0 / total
    count = hi + 1 - lo
    slope_sum = 0.0
    for i in range(count):
        activation = logs[lo + i] * inverse
        logs[lo + i] = activation
        for e in range(N_CARRIER):
            values[i, e] = activation * point[2 + e]
        if with_rate:
            slope_sum += activation * slopes[i]
    if with_rate:
        for i in range(count):
            activation = logs[lo + i]
            rate = activation * (slopes[i] - slope_sum) * phase_rate
            for e in range(N_CARRIER):
                rates[i, e] = rate * point[2 + e] + activation * point[4 + e]


@_compile
def features(canonical, target, gains, centres, widths, max_width, first, with_rate, logs,
             slopes, values, rates):
    """Features (with_rate: and their rates) at one canonical state, of the bases lo .. lo +
    count - 1 (those left out are below the truncation level): values[i, e] = a_(lo+i) C_e,
    rates[i, e] its rate. Returns (lo, count)."""
    point, lo, hi, top = window(canonical, target, gains, centres, widths, max_width, first,
                                with_rate, logs)
    seen = np.zeros(centres.size, dtype=np.int64)  # every log-activation is known
    kept_features(point, lo, hi, top, centres, widths, with_rate, logs, seen, 0, slopes, values,
                  rates)
    return lo, hi + 1 - lo


@_compile
def level_of(top, max_width, first, with_rate):
    """The truncation level below the largest log-activation ``top`` (module docstring): at
    the samples (with_rate) L0 + ln(1 + 5 G), else L0 = first."""
    bound = first
    if with_rate:
        slope = 2.0 * math.sqrt(max_width * (abs(top) + 3.0 * first))
        extra = math.log1p(5.0 * slope)
        bound = first + extra if extra <= 2.0 * first else math.inf
    return top - bound


@_compile
def tracked_window(canonical, target, gains, centres, widths, root_widths, max_width, first,
                   with_rate, logs, lasts, phases, seen, mark, previous):
    """:func:`window` of a point that evaluates only the bases it cannot rule out: the
    window of the previous point first, then each other basis j unless its log-activation
    at its last evaluation (lasts[j], at phase phases[j]) proves it more than SKIP_MARGIN
    below the level here: sqrt(-l_j) changes by at most sqrt(h_j) (root_widths[j]) per unit
    of phase, so -l_j > (sqrt(h_j) |p - p_j| + sqrt(SKIP_MARGIN - level))^2 there suffices
    (TRACKED kernels only, else every basis is evaluated, by window(); the level only rises
    as more bases are evaluated). seen[j] == mark: evaluated here (logs[j]). Returns
    (point, lo, hi, top), as window(): the others are below the level."""
    if not TRACKED:
        return window(canonical, target, gains, centres, widths, max_width, first, with_rate,
                      logs)
    point = phase_point(canonical, target, gains)
    phase = point[0]
    n_basis = centres.size
    top = -math.inf
    for j in range(previous[0], previous[1] + 1):
        logs[j] = log_activation(phase, centres[j], widths[j])[0]
        lasts[j], phases[j], seen[j] = logs[j], phase, mark
        top = max(top, logs[j])
    level = level_of(top, max_width, first, with_rate)
    reach = math.sqrt(SKIP_MARGIN - level)
    for j in range(n_basis):
        if seen[j] == mark:
            continue
        if TRACKED:
            distance = root_widths[j] * abs(phase - phases[j]) + reach
            if -lasts[j] > distance * distance:
                continue
        logs[j] = log_activation(phase, centres[j], widths[j])[0]
        lasts[j], phases[j], seen[j] = logs[j], phase, mark
        if logs[j] > top:
            top = logs[j]
            level = level_of(top, max_width, first, with_rate)
            reach = math.sqrt(SKIP_MARGIN - level)
    lo, hi = 0, n_basis - 1
    while seen[lo] != mark or logs[lo] < level:
        lo += 1
    while seen[hi] != mark or logs[hi] < level:
        hi -= 1
    previous[0], previous[1] = lo, hi
    return point, lo, hi, top


@_compile
def candidates(canonical0, dt, target, gains, centres, widths, first, lowest, highest):
    """The bases step k may keep at its sample or stages, lowest[k] .. highest[k]: every
    other basis is proved more than SKIP_MARGIN below the truncation level at all four
    points, by blocks of steps whose points' phases lie within BLOCK_REACH / sqrt(max h) of
    the block's middle m (module docstring, discrete forms): sqrt(-l_j) moves by at most
    sqrt(h_j) r from its value at m over a block of half-width r."""
    n_steps = lowest.size
    root_widths = np.sqrt(widths)
    max_width = widths.max()
    reach = BLOCK_REACH / math.sqrt(max_width)
    canonical = canonical0.copy()
    stage = np.empty(2)
    begin = 0
    low = high = phase_point(canonical, target, gains)[0]
    for k in range(n_steps):
        step_low = step_high = phase_point(canonical, target, gains)[0]
        if k < n_steps - 1:
            result = canonical_step(canonical, dt, target, gains)
            for s in range(1, 4):
                stage[0] = result[2 + 2 * s]
                stage[1] = result[3 + 2 * s]
                phase = phase_point(stage, target, gains)[0]
                step_low, step_high = min(step_low, phase), max(step_high, phase)
            canonical[0] = result[0]
            canonical[1] = result[1]
        if k > begin and max(high, step_high) - min(low, step_low) > 2.0 * reach:
            block_candidates(low, high, begin, k, centres, widths, root_widths, max_width,
                             first, lowest, highest)
            begin, low, high = k, step_low, step_high
        else:
            low, high = min(low, step_low), max(high, step_high)
    block_candidates(low, high, begin, n_steps, centres, widths, root_widths, max_width, first,
                     lowest, highest)


@_compile
def block_candidates(low, high, begin, end, centres, widths, root_widths, max_width, first,
                     lowest, highest):
    """lowest[begin:end], highest[begin:end]: the first and last basis not proved below the
    level anywhere on the phases low .. high (:func:`candidates`)."""
    n_basis = centres.size
    middle, radius = 0.5 * (low + high), 0.5 * (high - low)
    roots = np.empty(n_basis)
    top = -math.inf  # a lower bound of the largest log-activation on the block
    for j in range(n_basis):
        roots[j] = math.sqrt(-log_activation(middle, centres[j], widths[j])[0])
        spread = roots[j] + root_widths[j] * radius
        top = max(top, -spread * spread)
    level = level_of(top, max_width, first, True) - SKIP_MARGIN  # the sample's, the lowest
    lo, hi = 0, n_basis - 1
    while lo < hi and -max(roots[lo] - root_widths[lo] * radius, 0.0) ** 2 < level:
        lo += 1
    while hi > lo and -max(roots[hi] - root_widths[hi] * radius, 0.0) ** 2 < level:
        hi -= 1
    for k in range(begin, end):
        lowest[k], highest[k] = lo, hi


@_inline
def candidate_window(point, low, high, centres, widths, max_width, first, with_rate, logs,
                     seen, mark):
    """:func:`window` of a point from the bases low .. high only (:func:`candidates`: the
    others are below the level there): (lo, hi, top), logs[j] the log-activation of basis j
    for low <= j <= high, marked seen[j] = mark."""
    top = -math.inf
    for j in range(low, high + 1):
        logs[j] = log_activation(point[0], centres[j], widths[j])[0]
        seen[j] = mark
        top = max(top, logs[j])
    level = level_of(top, max_width, first, with_rate)
    lo, hi = low, high
    while logs[lo] < level:
        lo += 1
    while logs[hi] < level:
        hi -= 1
    return lo, hi, top


@_compile
def affine_row(row, coefficients, goal, states):
    """row[:m] = coefficients @ states (m columns of the states' response), then goal added
    to the goal's column N_STATES."""
    for column in range(states.shape[1]):
        total = 0.0
        for a in range(N_STATES):
            total += coefficients[a] * states[a, column]
        row[column] = total
    row[N_STATES] += goal


@_compile
def response(canonical, dt, target, gains, centres, widths, first, lowest, highest, inline,
             first_step, first_basis, advance, step, step_goal, step_forcing, output,
             output_goal, output_forcing, states, out):
    """Fill out (3, n_steps, m): responses of position, velocity and acceleration of the m
    columns whose transformation states are ``states`` (n, m) at the canonical state
    ``canonical``, the steps from first_step on; the bases kept at them are found among step
    k's candidates lowest[k] .. highest[k] (:func:`candidates`) or, ``inline``, among all
    (tracked_window). Column N_STATES takes
    the goal, column N_STATES + 1 + N_CARRIER i + e the feature e of basis first_basis + i (a
    basis outside them must not be forced). ``advance``: step past the last sample too.
    ``canonical`` and ``states`` are left at the state after the last step."""
    n, n_steps, m = N_STATES, out.shape[1], out.shape[2]
    n_basis = centres.size
    current, following = states.copy(), np.empty((n, m))
    stage = np.empty(2)
    logs, slopes = np.empty(n_basis), np.empty(n_basis)
    values, rates = np.empty((n_basis, N_CARRIER)), np.empty((n_basis, N_CARRIER))
    lasts, phases = np.zeros(n_basis), np.zeros(n_basis)
    seen, previous = np.full(n_basis, -1), np.array([0, n_basis - 1])
    root_widths, max_width = np.sqrt(widths), widths.max()
    for k in range(n_steps):
        at, mark = first_step + k, 4 * k
        if inline:
            point, lo, hi, top = tracked_window(canonical, target, gains, centres, widths,
                                                root_widths, max_width, first, True, logs, lasts,
                                                phases, seen, mark, previous)
        else:
            point = phase_point(canonical, target, gains)
            lo, hi, top = candidate_window(point, lowest[at], highest[at], centres, widths,
                                           max_width, first, True, logs, seen, mark)
        kept_features(point, lo, hi, top, centres, widths, True, logs, seen, mark, slopes,
                      values, rates)
        count = hi + 1 - lo
        start = n + 1 + N_CARRIER * (lo - first_basis)  # the first kept basis's first column
        if start < n + 1 or start + N_CARRIER * count > m:
            raise ValueError("a basis outside the response's columns is forced")
        for j in range(3):  # O x + O_g g + O_f (f, fdot)
            row = out[j, k]
            affine_row(row, output[j], output_goal[j], current)
            for i in range(count):
                for e in range(N_CARRIER):
                    row[start + N_CARRIER * i + e] += (
                        output_forcing[j, 0] * values[i, e] + output_forcing[j, 1] * rates[i, e]
                    )
        if k == n_steps - 1 and not advance:
            break
        for i in range(n):  # S x + S_g g + S_f (f_1, .., f_4), stage 1 at the sample
            row = following[i]
            affine_row(row, step[i], step_goal[i], current)
            for a in range(count):
                for e in range(N_CARRIER):
                    row[start + N_CARRIER * a + e] += step_forcing[i, 0] * values[a, e]
        result = canonical_step(canonical, dt, target, gains)
        for s in range(1, 4):
            stage[0] = result[2 + 2 * s]
            stage[1] = result[3 + 2 * s]
            mark = 4 * k + s
            if inline:
                point, lo, hi, top = tracked_window(stage, target, gains, centres, widths,
                                                    root_widths, max_width, first, False, logs,
                                                    lasts, phases, seen, mark, previous)
            else:
                point = phase_point(stage, target, gains)
                lo, hi, top = candidate_window(point, lowest[at], highest[at], centres, widths,
                                               max_width, first, False, logs, seen, mark)
            kept_features(point, lo, hi, top, centres, widths, False, logs, seen, mark, slopes,
                          values, rates)
            count = hi + 1 - lo
            start = n + 1 + N_CARRIER * (lo - first_basis)
            if start < n + 1 or start + N_CARRIER * count > m:
                raise ValueError("a basis outside the response's columns is forced")
            for i in range(n):
                for a in range(count):
                    for e in range(N_CARRIER):
                        following[i, start + N_CARRIER * a + e] += step_forcing[i, s] * values[a, e]
        canonical[0] = result[0]
        canonical[1] = result[1]
        current, following = following, current
    states[:, :] = current
'''


def kernel_source(form: str, kernel: str) -> str:
    """Source of the compiled response of ``form`` with ``kernel``: CasADi's expressions as
    Python (:func:`symbolic.numba_source`) and the loop (module docstring)."""
    signature = symbolic.Signature(form, 1, 1, kernel)
    generated = [
        symbolic.numba_source(symbolic.canonical_step_function(signature), "canonical_step"),
        symbolic.numba_source(symbolic.phase_point_function(form), "phase_point"),
        symbolic.numba_source(symbolic.log_activation_function(kernel), "log_activation"),
    ]
    equations = symbolic.FORMS[form]
    loop = _KERNELS.replace("{n_carrier}", str(equations.vectors_per_basis))
    loop = loop.replace("{n_states}", str(equations.n_transformation))
    loop = loop.replace("{tracked}", str(kernel in forms.TRACKED_KERNELS))
    header = (
        f'"""Generated by dmpopt.response for the {form} form with the {kernel} kernel."""\n\n'
        "import math\n\nimport numba\nimport numpy as np\n\n\n"
    )
    return header + "\n\n".join(generated) + loop


@lru_cache(maxsize=None)
def kernels(form: str, kernel: str):
    """The compiled module of :func:`kernel_source`.

    Its source is written once per machine to ``generated`` in :func:`symbolic.cache_dir`,
    under a hash of the source, so that numba caches the compiled code with it: 1-3 s the
    first time for each form and kernel, then a load. If that folder cannot be written, to a
    temporary folder of the process (compiled again in each process)."""
    source = kernel_source(form, kernel)
    name = f"response_{form}_{kernel}_{hashlib.sha1(source.encode()).hexdigest()[:16]}"
    try:
        path = _write(symbolic.cache_dir() / "generated", name, source)
    except OSError:
        path = _write(Path(tempfile.mkdtemp(prefix="dmpopt-generated-")), name, source)
    spec = importlib.util.spec_from_file_location(f"dmpopt_generated.{name}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # numba's cache imports the module by this name
    spec.loader.exec_module(module)
    return module


def _write(folder: Path, name: str, source: str) -> Path:
    """``folder/name.py`` holding ``source``, written whole or not at all (other processes may
    read it)."""
    path = folder / f"{name}.py"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.tmp")
        partial.write_text(source)
        partial.replace(path)
    return path


@dataclass(frozen=True, eq=False)
class ResponseMatrices:
    r"""The response matrices of one DOF (:func:`response_matrices`): the first ``n_head``
    steps dense, the rest (the settling tail of a discrete form) as a factor.

    In the tail no column but the ``alive`` ones is forced, so each other column's response
    there is that of its transformation state at the tail's first step under the unforced,
    affine step: with :math:`U_i` the responses (3 rows) of the :math:`n` unit states and of
    the goal from rest :math:`i` steps into the tail, column :math:`j` at tail step
    :math:`i` is :math:`U_i c_j`, :math:`c_j` its state at the tail's start (and a 1 for
    the goal's column). Then :math:`R w = (U_i C w)` on them, with ``coefficients``
    :math:`C`, plus the alive columns' own rows.

    Attributes
    ----------
    head : ndarray, shape (3, n_head, n_inputs)
        Positions, velocities and accelerations of the first ``n_head`` steps against every
        input.
    tail : ndarray, shape (3, n_tail, n + 1 + n_alive)
        The rest: the unit states' and the goal's responses :math:`U`, then those of the
        alive inputs.
    coefficients : ndarray, shape (n + 1, n_inputs)
        :math:`C`: each input's transformation state at the tail's start and its goal
        factor; zero for the alive inputs.
    alive : slice
        The inputs whose tail is in ``tail[:, :, n + 1:]``.
    """

    head: np.ndarray
    tail: np.ndarray
    coefficients: np.ndarray
    alive: slice

    @property
    def n_steps(self) -> int:
        """Samples of the plan."""
        return self.head.shape[1] + self.tail.shape[1]

    @property
    def n_inputs(self) -> int:
        """Inputs per DOF: the initial transformation states, the goal and the weights."""
        return self.head.shape[2]

    @property
    def nbytes(self) -> int:
        """Bytes held."""
        return self.head.nbytes + self.tail.nbytes + self.coefficients.nbytes

    def product(self, inputs: np.ndarray) -> np.ndarray:
        """The plans of the DOFs whose inputs are the columns of ``inputs`` (n_inputs,
        n_dofs): positions, velocities and accelerations, shape (3, n_steps, n_dofs)."""
        n_head, n_dofs = self.head.shape[1], inputs.shape[1]
        plan = np.empty((3, self.n_steps, n_dofs))
        if n_head:
            _product(self.head, inputs, plan[:, :n_head])
        if self.tail.shape[1]:
            tail_inputs = np.concatenate([self.coefficients @ inputs, inputs[self.alive]])
            _product(self.tail, tail_inputs, plan[:, n_head:])
        return plan

    def dense(self) -> np.ndarray:
        """The whole response, shape (3, n_steps, n_inputs)."""
        if self.tail.shape[1] == 0:
            return self.head
        n = self.coefficients.shape[0]
        tail = self.tail[:, :, :n] @ self.coefficients
        tail[:, :, self.alive] = self.tail[:, :, n:]
        return np.concatenate([self.head, tail], axis=1)

    def freeze(self) -> None:
        """Make the arrays read-only (the cached response is shared)."""
        for array in (self.head, self.tail, self.coefficients):
            array.setflags(write=False)


def _product(response: np.ndarray, inputs: np.ndarray, out: np.ndarray) -> None:
    """``out[...] = response @ inputs`` (``response`` (3, n, m), ``out`` (3, n, n_dofs)): for a
    few DOFs one matrix-vector product per DOF, each written to its place in ``out``, which
    reads ``response`` faster than OpenBLAS's matrix product (LASA, 2 DOFs, 1000 steps: 83
    against 136 us; benchmarks/bench_core.py) and copies once."""
    flat = response.reshape(-1, response.shape[2])
    if inputs.shape[1] > 4:
        out[...] = (flat @ inputs).reshape(out.shape)
        return
    for dof in range(inputs.shape[1]):
        out[:, :, dof] = (flat @ inputs[:, dof]).reshape(out.shape[:2])


def tail_start(
    lows: np.ndarray, highs: np.ndarray, n_inputs: int, n_other: int, n_carrier: int
) -> int:
    """The step from which the response is kept as a factor (:class:`ResponseMatrices`), the
    one that holds the fewest numbers, from the first and last basis each step forces
    (``lows``, ``highs``); ``len(lows)`` for none. ``n_other``: the inputs that are not
    weights (the tail keeps as many unit responses), ``n_carrier`` weights per basis."""
    n_steps = lows.size
    first = np.minimum.accumulate(lows[::-1])[::-1]  # the bases forced from step k on
    last = np.maximum.accumulate(highs[::-1])[::-1]
    steps = np.arange(n_steps)
    alive = n_carrier * (last - first + 1)
    held = steps * n_inputs + (n_steps - steps) * (n_other + alive)
    best = int(np.argmin(held))
    return best if held[best] < n_steps * n_inputs else n_steps


def response_matrices(key: tuple, factored: bool = True) -> ResponseMatrices:
    """Response matrices of one DOF for the cache key of :func:`dmpopt.dmp._response`, in time
    normalised by ``tau``: positions, velocities and accelerations against the initial
    transformation states, the goal and the weights (:class:`ResponseMatrices`).

    Discrete forms: a first pass finds each step's candidate bases (:func:`candidates`),
    from which the response pass finds the kept ones at each point; ``factored``: in the
    settling tail only the bases near the phase's end are forced, so the other columns are
    kept as a factor there (:func:`tail_start`). Rhythmic forms: no tail (their phase
    cycles, each basis is forced once a period), and the response pass finds the kept bases
    itself (tracked_window), as their phase wraps."""
    (form, kernel, n_basis, n_steps, dt, target, canonical0, centres, widths, gains) = key
    gains = np.array(gains, dtype=float)
    centres, widths = np.array(centres, dtype=float), np.array(widths, dtype=float)
    matrices = symbolic.transformation_matrices(form)(dt=dt, gains=gains)
    matrices = {name: value.full() for name, value in matrices.items()}
    n = symbolic.n_transformation_states(form)
    n_inputs = n + 1 + symbolic.n_features(form, n_basis)
    n_carrier = symbolic.FORMS[form].vectors_per_basis
    module = kernels(form, kernel)
    first, canonical = first_level(n_basis), np.array(canonical0, dtype=float)
    n_head, inline = n_steps, not symbolic.FORMS[form].discrete
    held = 1 if inline else n_steps
    lowest, highest = np.empty(held, dtype=np.int64), np.empty(held, dtype=np.int64)
    if not inline:
        module.candidates(canonical, float(dt), float(target), gains, centres, widths, first,
                          lowest, highest)  # fmt: skip
        if factored:
            n_head = tail_start(lowest, highest, n_inputs, n + 1, n_carrier)
    constants = (
        matrices["step"], matrices["step_goal"][:, 0], matrices["step_forcing"],
        matrices["output"], matrices["output_goal"][:, 0], matrices["output_forcing"],
    )  # fmt: skip
    windows = (first, lowest, highest, inline)
    states = np.zeros((n, n_inputs))
    states[:, :n] = np.eye(n)
    head = fresh_array((3, n_head, n_inputs))
    module.response(canonical, float(dt), float(target), gains, centres, widths, *windows, 0, 0,
                    n_head < n_steps, *constants, states, head)  # fmt: skip
    if n_head == n_steps:
        return ResponseMatrices(head, np.empty((3, 0, n + 1)), np.zeros((n + 1, n_inputs)),
                                slice(n_inputs, n_inputs))  # fmt: skip
    low, high = int(lowest[n_head:].min()), int(highest[n_head:].max())
    alive = slice(n + 1 + n_carrier * low, n + 1 + n_carrier * (high + 1))
    coefficients = np.zeros((n + 1, n_inputs))
    coefficients[:n], coefficients[n, n] = states, 1.0
    coefficients[:, alive] = 0.0
    tail_states = np.zeros((n, n + 1 + alive.stop - alive.start))
    tail_states[:, :n], tail_states[:, n + 1 :] = np.eye(n), states[:, alive]
    tail = fresh_array((3, n_steps - n_head, tail_states.shape[1]))
    module.response(canonical, float(dt), float(target), gains, centres, widths, *windows,
                    n_head, low, False, *constants, tail_states, tail)  # fmt: skip
    return ResponseMatrices(head, tail, coefficients, alive)


HUGE_PAGE_ADVICE = 4 * 1024**2
"""Bytes from which numpy asks Linux for transparent huge pages for an array (numpy 1.22+)."""


def fresh_array(shape: tuple) -> np.ndarray:
    """A new float array of ``shape``: from :data:`HUGE_PAGE_ADVICE` bytes on, memory that the
    system maps and zeroes in one call where it can (Linux: ``MAP_POPULATE``), else
    ``np.empty``.

    numpy asks Linux for transparent huge pages for large arrays; where memory is
    fragmented, the first write to such an array waits for the system to compact memory.
    The 13.6 MB response of the LASA demo's plan took 35-45 ms of thread time to allocate
    and fill so on this machine (loaded, 2-4 ms where huge pages were at hand), 6-8 ms mapped
    and populated in one call, 9-11 ms by one page fault per 4 KiB page.
    """
    if 8 * math.prod(shape) < HUGE_PAGE_ADVICE or not hasattr(mmap, "MAP_POPULATE"):
        return np.empty(shape)
    flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | mmap.MAP_POPULATE
    memory = mmap.mmap(-1, 8 * math.prod(shape), flags=flags)
    return np.frombuffer(memory, dtype=float, count=math.prod(shape)).reshape(shape)
