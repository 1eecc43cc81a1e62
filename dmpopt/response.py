r"""The response matrices of a rollout of one DOF, in one compiled pass (numba).

A rollout's positions, velocities and accelerations are linear in the initial transformation
states, the goal and the forcing weights (:mod:`dmpopt.dmp`). Their coefficients, the
response matrices, follow from the RK4 step of the transformation system as matrices
(:func:`symbolic.transformation_matrices`) driven at each of the step's four stages by the
features there. :func:`response_matrices` runs that recurrence, the canonical system's step
and the features in one loop over the steps, compiled by numba, without arrays of features.

Where the numbers come from. Every form- and kernel-specific expression is CasADi's: the
canonical step (:func:`symbolic.canonical_step_function`), the basis phase, carrier, their
rates and what the kernel needs of the phase, its terms
(:func:`symbolic.phase_point_function`: a von Mises basis needs the phase's unit vector,
taken once per point for every basis), one basis's terms
(:func:`symbolic.basis_terms_function`, once per basis) and its log-activation and slope
from both (:func:`symbolic.log_activation_function`) are translated instruction by
instruction into Python for numba (:func:`symbolic.numba_source`), so they are computed by
the same operations in the same order as CasADi's virtual machine. What the loop adds is the
same for every form and kernel: the normalisation of :func:`forms.normalised_activations`
(:math:`a_j = e^{l_j - M} / \sum_i e^{l_i - M}`, :math:`M = \max_i l_i`), the layout of
:meth:`forms.Form.features` (:math:`\phi_{j,e} = a_j C_e` with the carrier :math:`C`) and
the rate of that product along the canonical flow, :math:`\dot\phi_{j,e} = a_j (l_j' -
\sum_i a_i l_i') \dot p\, C_e + a_j \dot C_e` (:math:`l' = \partial l / \partial p`,
:math:`p` the basis phase). tests/core/test_response.py checks the result against CasADi's
own :func:`symbolic.feature_rate_function` for every form and kernel, and the rollout
against the step-by-step integration. So a form or kernel added to :mod:`dmpopt.forms`
reaches this pass with no code here, if its log-activations have the two properties the
truncation uses (below); a numba copy of each form's equations was not written, as it would
be a second definition to keep equal to CasADi's. (Evaluating CasADi's instruction list on
arrays instead, as :class:`symbolic.ArrayFunction` does, took 45-55 ms of the 60-170 ms that
the LASA demo's plan of 10676 steps cost: every basis at all 4 x 10676 stage points, each
through numpy temporaries.)

The normalisation's exp (``table_exp``) is computed in the loop rather than called from the C
library, so that a loop of them runs without calls (the call, its wrapper and errno check
cost more than the exp): glibc's algorithm (since 2.28, from Arm's optimized-routines),
:math:`x = k \ln 2 / 128 + r` with :math:`|r| \le \ln 2 / 256`, :math:`e^x = 2^{k/128} (1
+ t_i + r + c_2 r^2 + c_3 r^3 + c_4 r^4 + c_5 r^5)` with :math:`i = k \bmod 128`, a table of
the 128 powers :math:`2^{i/128}` and their rounding errors :math:`t_i` (computed to 60
digits, :func:`exp_constants`) and the fused multiply-adds of glibc's build for processors
with FMA, in its order. Its error is at most 0.511 ulp (tests/core/test_response.py checks
it against the decimal module's exp); with a glibc that selects that build (this machine:
2.36, AMD EPYC) it gives math.exp's bits (8 million arguments compared, and the response
matrices of 34 plans of every form), so the features are those of before; with another C
library they differ within rounding. It holds for :math:`|x| < 512`; the arguments are
within :math:`[-3 L_0, 0]` (:math:`L_0 \approx 41` for 50 bases) except where nothing is
left out, and there math.exp is called.

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

Segments (:class:`ResponseMatrices`). A step forces only the columns of the bases kept at
its points; every other column moves under the unforced step, which is affine in the state
with constant matrices (:func:`symbolic.transformation_matrices`): its response from step
:math:`K` on, until it is forced again, is that of the unit states and the goal, times its
state at :math:`K`. A first pass (``candidates``, below) bounds the bases each step may
force, and the steps are split into segments whose steps force a window of a few bases
(``segment_bounds``: at most ``SLACK`` more than the narrowest step's, at least
``SHORTEST`` steps): a segment holds the responses of the unit states, the goal and its
window's columns, and the states of every column at its start as a factor. The response
pass tracks the states of every column up to the last segment's start (they are the
factors), then those of the last segment's window only. The forcing does not vanish once a
discrete plan settles (the normalisation keeps the largest basis and the carrier, the phase
velocity :math:`v`, only decays: 2.8e-7 at the end of the LASA demo's default plan), so the
last segment, the settling tail, has a window too; it starts where a dense head and the
tail would hold the fewest numbers (:func:`tail_start`). For the LASA demo's default plan:
21 segments of 3 + 11 to 14 columns, the tail 8439 of the 10676 steps, 3.9 MB against 13.6
MB dense (5.9 MB with a dense head and a factored tail, before); a phase form's three
periods of 50 von Mises bases (9426 steps): 58 segments, 8.4 against 23.3 MB. The window columns are
the dense pass's to the bit; the other columns round differently, by at most :math:`(n + 1)
\epsilon ||\tilde O||_\infty P (2 i P ||\tilde S||_\infty + 3) ||c_j||_1` at step
:math:`i` of their segment (:math:`\tilde S`, :math:`\tilde O` the step and output with the
goal as a constant state, :math:`P` the largest :math:`||\tilde S^i||_\infty`, :math:`c_j`
the column's state and goal factor; derived and checked in tests/core/test_response.py),
and the plan's product (``product``: the factor times the inputs, then one matrix-vector
product per segment and DOF) sums in another order than a dense product, within
:math:`\gamma_k` of each sum's absolute terms (Higham, Accuracy and Stability of Numerical
Algorithms, 2nd ed., eq. (3.5)). A rhythmic form's plan is split likewise (its phase cycles:
the kept bases of a step wrap past the last basis to the first where the phase passes
between them, and a segment of such steps takes every column); with the printed periodic
kernel, which jumps where the phase wraps, it is one segment of every column, as is a dense response
(``factored=False``).

Which bases are kept is found without evaluating every basis at every point. It rests on
:math:`l'^2 \le 4 h |l|`: :math:`\sqrt{-l_j}` changes by at most :math:`\sqrt{h_j}` per unit
of phase, for kernels continuous in the phase.

- ``candidates``: consecutive steps are grouped into blocks whose points (samples and
  stages) lie within :math:`r =` ``BLOCK_REACH`` :math:`/ \sqrt{h_\max}` of the block's
  middle phase :math:`m`. With :math:`s_j = \sqrt{-l_j(m)}`, every point of the block has
  :math:`-(s_j + \sqrt{h_j} r)^2 \le l_j \le -\max(s_j - \sqrt{h_j} r, 0)^2`, so its largest
  log-activation :math:`M` is at least :math:`T = \max_j -(s_j + \sqrt{h_j} r)^2` and its
  level (the samples', the lowest; the level :math:`M - L(M)` falls as :math:`M` does) at
  least that of :math:`T`. A basis whose upper bound is more than ``SKIP_MARGIN`` (which
  covers the rounding of these few operations) below it is below the level at every point of
  the block; the others, from the first to the last, are the step's candidates, 50
  log-activations per block instead of per point. At each point the response pass evaluates
  the candidates only: the largest log-activation and the kept bases are those of every
  basis (tests/core/test_response.py compares them at every point), so the features, and the
  response, are the same to the bit. (The Gaussian is continuous in the phase, and a
  discrete phase stays far from :math:`2\pi`, where the printed periodic kernel jumps.)
  The same holds for a rhythmic form's von Mises bases (:data:`forms.TRACKED_KERNELS`),
  continuous in the phase as it wraps, on a circle (``PERIODIC``): the candidates are the
  complement of the longest circular run of bases proved below the level, a range that may
  wrap past the last basis (``basis_at``, ``window_size``), as may the kept window; a block
  whose phases straddle the energy form's jump of :math:`\mathrm{atan2}` at :math:`\pi` has
  a wide interval and keeps every basis. The
  printed periodic kernel jumps where the phase wraps, so its pass evaluates every basis
  at every point (``window``).

Each log-activation is evaluated once per point, and only what the point needs: at the
stages, the log-activation alone (``log_value``: CasADi's function of the log-activation
without its slope, the same instructions less those of the slope); at the sample, each
candidate's log-activation and slope from one evaluation. Where a stage's phase terms equal
the last stage's (the phase form's phase advances at a constant rate: its RK4 stages 2 and 3
have the same phase), it takes that stage's normalised activations, which depend on the
terms only, and multiplies them by its own carrier. A von Mises log-activation is
:math:`-\frac{h}{2} |u(\phi) - u(c)|^2` with the unit vectors :math:`u` of the phase and the
centre (:func:`forms.basis_log_activations`): the phase's cosine and sine once per point,
none per basis (the energy form gives :math:`u(\phi)` as its normalised state, no trig at
all: :meth:`forms.EnergyForm.basis_direction`). A first rollout of 50 von Mises bases over
three periods (9426 steps, benchmarks/bench_core.py, medians of 15 at load 0.6): phase form
15.1 ms with a cosine per basis and point and contiguous windows (every basis kept at the
16 % of steps whose window wrapped), 10.3 with the unit vectors, 8.7 with circular windows,
8.0 with the terms from phase_point; energy form 18.1, 12.6, 10.5, 9.1 (its pass 7.6 ms,
the candidates 0.9, the product 1.0). The unit vectors and circular windows change von
Mises plans in the last bits (within 2e-14 relative of the cosine form's); discrete and
printed-kernel plans are bitwise those of before.

Where the LASA demo's first rollout goes (2 DOFs, 50 Gaussian bases, 10676 steps; thread
CPU at load 1.9-2.1, a pass's least of 200 runs timed alone): the head pass (2237 steps, every
column tracked) 1.45 ms and the settling tail's pass (8439 steps, 15 columns) 3.9 ms, against
1.8-2.0 and 5.1-5.7 ms before the exp was inlined (``table_exp``: the tail spent 0.6 ms in it
after, as timed with a cheap stand-in), the rows written by index and the samples' level
bracketed (the exact level, a sqrt and a log1p per sample, had cost 0.65 ms of the tail; the
bracket leaves the log1p to 11 % of the samples). In the tail's 0.46 us per step, about 10
bases are kept at each of 4 points, the rows (3 outputs and 2 states of 15 columns, and the
forcing of the 4 points) take 1.1 ms. The candidates take 0.45 ms, the product 0.6-0.85, the
Python around them about 0.8 (the step matrices, a CasADi call, are kept per form, step and
gains: :func:`step_matrices`). New memory: the 3.9 MB of segments took 2.1-2.2 ms of thread
time where malloc gave fresh pages (a fault per 4 KiB page), 1.7 ms mapped populated
(:func:`fresh_array`), none where a released response's memory is taken again
(:func:`block_memory`). The whole first rollout in benchmarks/bench_core.py (its median of
15): 8.9-15.9 ms, median 11.5, against 11.6-20.5, median 17.4, before, in 10 alternating
runs at load 1.8-2.2 (the thread time on this 2-core machine depends on what shares its
core; the code before measured 11.4 ms quiet). Before the candidates (one pass evaluating
all 50 bases at all 4 points of each step) the first rollout cost 1.1-1.4 times as much
again (benchmarks/bench_core.py at load 8-9).
"""

from __future__ import annotations

import decimal
import hashlib
import importlib.util
import math
import mmap
import os
import struct
import sys
import tempfile
import threading
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
log_value = _compile(log_value)  # the log-activation alone: where no slope is needed
phase_terms = _compile(phase_terms)
basis_terms = _compile(basis_terms)
NO_TERMS = {no_terms}  # equal to no phase terms (NaN)
N_BASIS_TERMS = {n_basis_terms}


@_inline
def terms_at(phase):
    """The phase terms at ``phase`` (symbolic.phase_terms_function), as a tuple."""
    result = phase_terms(phase)
    return {terms}


@_inline
def point_terms(point):
    """The phase terms and their slopes of a point of phase_point (which gives them from the
    canonical state, as the form has them: Form.phase_terms), as two tuples."""
    return {point_terms}, {point_terms_slope}


@_inline
def log_value_at(terms, basis, j):
    """Basis j's log-activation at the point whose phase terms are ``terms``, ``basis`` the
    table of :func:`basis_table`."""
    return log_value({terms_argument}, {basis_argument})[0]


@_inline
def log_activation_at(terms, terms_slope, basis, j):
    """Basis j's log-activation and its slope at the point whose phase terms are ``terms``
    and their slopes ``terms_slope``."""
    return log_activation({terms_argument}, {slope_argument}, {basis_argument})


@_compile
def basis_table(centres, widths):
    """basis[j]: basis j's terms (symbolic.basis_terms_function), taken once per basis."""
    table = np.empty((centres.size, N_BASIS_TERMS))
    for j in range(centres.size):
        terms = basis_terms(centres[j], widths[j])
        for i in range(N_BASIS_TERMS):
            table[j, i] = terms[i]
    return table
N_CARRIER = {n_carrier}
N_STATES = {n_states}
PERIODIC = {periodic}  # the bases lie on a circle: a kept window may wrap past the last basis
SKIP_MARGIN = 1.0  # a basis is left unevaluated only if proved this far below the level
BLOCK_REACH = 0.25  # sqrt(max h) times the half-width of a block of candidates (phase)



@intrinsic
def fma(typingctx, a, b, c):
    """a * b + c rounded once (LLVM's fma: one instruction where the processor has one)."""

    def codegen(context, builder, signature, args):
        double = ir.DoubleType()
        kind = ir.FunctionType(double, [double, double, double])
        return builder.call(builder.module.declare_intrinsic("llvm.fma", [double], kind), args)

    return types.float64(types.float64, types.float64, types.float64), codegen


@intrinsic
def bits_of(typingctx, x):
    """The bits of the float x, as an unsigned integer."""

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.uint64(types.float64), codegen


@intrinsic
def float_of(typingctx, bits):
    """The float whose bits are the unsigned integer ``bits``."""

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.uint64), codegen


EXP_TAILS = np.array({exp_tails})
EXP_SCALES = np.array({exp_scales}, dtype=np.uint64)
EXP_SHIFT = 6755399441055744.0  # 1.5 * 2**52: adding it rounds to an integer
EXP_INVERSE = {exp_inverse}  # 128 / ln 2
EXP_LN2_HIGH = {exp_ln2_high}  # -ln 2 / 128 in two parts
EXP_LN2_LOW = {exp_ln2_low}
EXP_POLYNOMIAL = {exp_polynomial}
LN2 = math.log(2.0)


@_inline
def table_exp(x):
    """exp(x) for -512 < x < 512 (module docstring): glibc's table algorithm, inlined."""
    shifted = fma(x, EXP_INVERSE, EXP_SHIFT)  # k = round(128 x / ln 2) in its low bits
    k = bits_of(shifted)
    kd = shifted - EXP_SHIFT
    r = fma(kd, EXP_LN2_LOW, fma(kd, EXP_LN2_HIGH, x))  # x - k ln 2 / 128
    i = k & np.uint64(127)
    r2 = r * r
    c2, c3, c4, c5 = EXP_POLYNOMIAL
    tail = fma(fma(r, c3, c2), r2, EXP_TAILS[i] + r)
    tail = fma(r2 * r2, fma(r, c5, c4), tail)
    scale = float_of(EXP_SCALES[i] + (k << np.uint64(45)))  # 2 ** (k / 128)
    return fma(scale, tail, scale)


@_compile
def window(canonical, target, gains, basis, widths, max_width, first, with_rate, logs):
    """The point's phase values and phase terms, and the bases kept at one canonical state
    (those from the first to the last at or above the truncation level): (point, terms,
    terms_slope, lo, hi, top), logs[j] the log-activation of basis j."""
    point = phase_point(canonical, target, gains)
    terms, terms_slope = point_terms(point)
    n_basis = basis.shape[0]
    for j in range(n_basis):
        logs[j] = log_value_at(terms, basis, j)
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
    return point, terms, terms_slope, lo, hi, top


@_inline
def basis_at(lo, i, n_basis):
    """The i-th basis of a window starting at basis lo (past the last basis: from the first,
    on a circle; PERIODIC is a constant of the compiled code)."""
    j = lo + i
    if PERIODIC and j >= n_basis:
        return j - n_basis
    return j


@_inline
def window_size(lo, hi, n_basis):
    """The bases in the window lo .. hi, which wraps past the last basis where hi < lo."""
    if PERIODIC and hi < lo:
        return hi + 1 - lo + n_basis
    return hi + 1 - lo


@_inline
def kept_features(point, terms, terms_slope, lo, hi, top, basis, with_rate, logs, seen, mark,
                  slopes, values, rates):
    """Features (with_rate: and their rates) of the bases lo .. hi (wrapping past the last
    basis where hi < lo) at the point ``point`` of phase_point, whose phase terms are
    ``terms`` (and their slopes ``terms_slope``), ``top`` the largest log-activation there:
    values[i, e] = a_j C_e of the window's i-th basis j (basis_at), rates[i, e] its rate.
    logs[j] (with_rate: and slopes[j]) is taken as basis j's log-activation (and slope) where
    seen[j] == mark (evaluated there by candidate_window), else evaluated."""
    phase_rate = point[1]
    n_basis = basis.shape[0]
    count = window_size(lo, hi, n_basis)
    least = top
    for i in range(count):
        j = basis_at(lo, i, n_basis)
        if seen[j] != mark:
            if with_rate:  # the log-activation and its slope from one evaluation
                logs[j], slopes[j] = log_activation_at(terms, terms_slope, basis, j)
            else:
                logs[j] = log_value_at(terms, basis, j)
        least = min(least, logs[j])
    if least - top > -512.0:  # within table_exp's range (false for NaN)
        for i in range(count):
            j = basis_at(lo, i, n_basis)
            logs[j] = table_exp(logs[j] - top)
    else:
        for i in range(count):
            j = basis_at(lo, i, n_basis)
            logs[j] = math.exp(logs[j] - top)
    total = 0.0
    for i in range(count):
        total += logs[basis_at(lo, i, n_basis)]
    inverse = 1.0 / total
    slope_sum = 0.0
    for i in range(count):
        j = basis_at(lo, i, n_basis)
        activation = logs[j] * inverse
        logs[j] = activation
        for e in range(N_CARRIER):
            values[i, e] = activation * point[2 + e]
        if with_rate:
            slope_sum += activation * slopes[j]
    if with_rate:
        for i in range(count):
            j = basis_at(lo, i, n_basis)
            activation = logs[j]
            rate = activation * (slopes[j] - slope_sum) * phase_rate
            for e in range(N_CARRIER):
                rates[i, e] = rate * point[2 + e] + activation * point[4 + e]


@_compile
def features(canonical, target, gains, centres, widths, max_width, first, with_rate, logs,
             slopes, values, rates):
    """Features (with_rate: and their rates) at one canonical state, of the bases lo .. lo +
    count - 1 (those left out are below the truncation level): values[i, e] = a_(lo+i) C_e,
    rates[i, e] its rate. Returns (lo, count)."""
    basis = basis_table(centres, widths)
    point, terms, terms_slope, lo, hi, top = window(canonical, target, gains, basis, widths,
                                                    max_width, first, with_rate, logs)
    # window knows every log-activation, not their slopes: with_rate evaluates both again
    seen = np.full(centres.size, -1 if with_rate else 0, dtype=np.int64)
    kept_features(point, terms, terms_slope, lo, hi, top, basis, with_rate, logs, seen, 0,
                  slopes, values, rates)
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
def candidates(canonical0, dt, target, gains, centres, widths, first, lowest, highest):
    """The bases step k may keep at its sample or stages, lowest[k] .. highest[k]: every
    other basis is proved more than SKIP_MARGIN below the truncation level at all four
    points, by blocks of steps whose points' phases lie within BLOCK_REACH / sqrt(max h) of
    the block's middle m (module docstring, discrete forms): sqrt(-l_j) moves by at most
    sqrt(h_j) r from its value at m over a block of half-width r."""
    n_steps = lowest.size
    basis = basis_table(centres, widths)
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
            block_candidates(low, high, begin, k, basis, root_widths, max_width, first,
                             lowest, highest)
            begin, low, high = k, step_low, step_high
        else:
            low, high = min(low, step_low), max(high, step_high)
    block_candidates(low, high, begin, n_steps, basis, root_widths, max_width, first, lowest,
                     highest)


@_compile
def block_candidates(low, high, begin, end, basis, root_widths, max_width, first, lowest,
                     highest):
    """lowest[begin:end], highest[begin:end]: the first and last basis not proved below the
    level anywhere on the phases low .. high (:func:`candidates`)."""
    n_basis = basis.shape[0]
    middle, radius = 0.5 * (low + high), 0.5 * (high - low)
    terms = terms_at(middle)
    roots = np.empty(n_basis)
    top = -math.inf  # a lower bound of the largest log-activation on the block
    for j in range(n_basis):
        roots[j] = math.sqrt(-log_value_at(terms, basis, j))
        spread = roots[j] + root_widths[j] * radius
        top = max(top, -spread * spread)
    level = level_of(top, max_width, first, True) - SKIP_MARGIN  # the sample's, the lowest
    if PERIODIC:
        lo, hi = circular_candidates(roots, root_widths, radius, level)
    else:
        lo, hi = 0, n_basis - 1
        while lo < hi and -max(roots[lo] - root_widths[lo] * radius, 0.0) ** 2 < level:
            lo += 1
        while hi > lo and -max(roots[hi] - root_widths[hi] * radius, 0.0) ** 2 < level:
            hi -= 1
    for k in range(begin, end):
        lowest[k], highest[k] = lo, hi


@_compile
def circular_candidates(roots, root_widths, radius, level):
    """Bases on a circle: the shortest range lo .. hi (wrapping past the last basis where hi <
    lo) holding every basis not proved below ``level`` (:func:`block_candidates`), the
    complement of the longest circular run of bases that are; all of them if none is."""
    n_basis = roots.size
    below = np.empty(n_basis, dtype=np.bool_)
    for j in range(n_basis):
        below[j] = -max(roots[j] - root_widths[j] * radius, 0.0) ** 2 < level
    if not below.any() or below.all():  # none below (or, by rounding, all): every basis
        return 0, n_basis - 1
    start = 0
    while below[start]:  # a basis above, so that no run of those below is cut at it
        start += 1
    best, best_end, run = 0, 0, 0
    for i in range(1, n_basis + 1):
        j = basis_at(start, i, n_basis)
        run = run + 1 if below[j] else 0
        if run > best:
            best, best_end = run, j
    if best == 0:
        return 0, n_basis - 1
    lo = basis_at(best_end, 1, n_basis)
    hi = basis_at(best_end, n_basis - best, n_basis)
    return lo, hi


@_inline
def candidate_window(terms, terms_slope, low, high, basis, max_width, first, with_rate, logs,
                     slopes, seen, mark):
    """:func:`window` of a point, whose phase terms are ``terms`` (and their slopes
    ``terms_slope``), from the bases low .. high only (:func:`candidates`: the others are below
    the level there; the range wraps past the last basis where high < low): (lo, hi, top),
    logs[j] the log-activation of each basis j of the range (with_rate: slopes[j] its slope,
    from the same evaluation), marked seen[j] = mark."""
    top = -math.inf
    n_basis = basis.shape[0]
    for i in range(window_size(low, high, n_basis)):
        j = basis_at(low, i, n_basis)
        if with_rate:
            logs[j], slopes[j] = log_activation_at(terms, terms_slope, basis, j)
        else:
            logs[j] = log_value_at(terms, basis, j)
        seen[j] = mark
        top = max(top, logs[j])
    if with_rate:  # first without log1p: bracket the level, compute it where the scans differ
        size = 5.0 * 2.0 * math.sqrt(max_width * (abs(top) + 3.0 * first))  # level_of's
        if 1.0 <= size < math.inf:
            power = float(int(bits_of(size) >> np.uint64(52)) - 1023)  # 2 ** power <= size
            least = power * LN2 - 1e-9  # <= ln(size) <= log1p(size) (and its rounding)
            most = (power + 1.0) * LN2 + 1.0 / size + 1e-9  # >= ln(size) + 1 / size
            if most <= 2.0 * first:  # level_of's bound is finite
                lo, hi = window_of(logs, low, high, top - (first + least))
                if (lo, hi) == window_of(logs, low, high, top - (first + most)):
                    return lo, hi, top
    lo, hi = window_of(logs, low, high, level_of(top, max_width, first, with_rate))
    return lo, hi, top


@_inline
def window_of(logs, low, high, level):
    """The first and last of the bases low .. high (wrapping past the last basis where high <
    low) whose logs[j] is at least ``level`` (one of them is)."""
    lo, hi, last = low, high, logs.size - 1
    while logs[lo] < level:
        lo = lo + 1 if lo < last else 0
    while logs[hi] < level:
        hi = hi - 1 if hi > 0 else last
    return lo, hi


@_inline
def row_product(coefficients, i, states, first, count, out, row, offset):
    """out[row, offset + c] = coefficients[i] @ states[:, first + c] for c < count, summed in
    the order of the states (indices, not row views: a view per row and step would count
    references)."""
    for c in range(count):
        total = 0.0
        for a in range(N_STATES):
            total += coefficients[i, a] * states[a, first + c]
        out[row, offset + c] = total


@_compile
def segment_bounds(lowest, highest, slack, shortest, bounds):
    """Split the steps into segments (:class:`ResponseMatrices`): a segment grows while the
    bases its steps may force (lowest[k] .. highest[k], :func:`candidates`) span at most
    ``slack`` more than those of its narrowest step, and to at least ``shortest`` steps.
    bounds[t] = (first step, end, first basis, last basis); returns the count."""
    n_steps = lowest.size
    count = begin = 0
    while begin < n_steps:
        lo, hi = lowest[begin], highest[begin]
        narrowest = hi - lo
        end = begin + 1
        while end < n_steps and (
            end - begin < shortest
            or max(hi, highest[end]) - min(lo, lowest[end])
            <= min(narrowest, highest[end] - lowest[end]) + slack
        ):
            lo, hi = min(lo, lowest[end]), max(hi, highest[end])
            narrowest = min(narrowest, highest[end] - lowest[end])
            end += 1
        bounds[count, 0], bounds[count, 1], bounds[count, 2], bounds[count, 3] = begin, end, lo, hi
        count += 1
        begin = end
    return count


@_inline
def kept_columns(lo, hi, n_basis, first_basis, left, width, columns):
    """columns[i]: the first state column of the window's i-th basis (basis_at) when the
    segment's window inputs start at basis first_basis; returns the window's bases. Raises
    where one lies outside the segment's columns left .. left + width - 1."""
    count = window_size(lo, hi, n_basis)
    for i in range(count):
        columns[i] = N_STATES + 1 + N_CARRIER * (basis_at(lo, i, n_basis) - first_basis)
        if columns[i] < left or columns[i] + N_CARRIER > left + width:
            raise ValueError("a basis outside the segment's columns is forced")
    return count


@_compile
def response(canonical, dt, target, gains, centres, widths, first, lowest, highest, inline,
             first_step, first_basis, advance, step, step_goal, step_forcing, output,
             output_goal, output_forcing, states, segments, out, starts):
    """Responses of position, velocity and acceleration, segment by segment, of the m columns
    whose transformation states are ``states`` (n, m) at the canonical state ``canonical``,
    the steps from first_step on; the bases kept at them are found among step k's
    candidates lowest[k] .. highest[k] (:func:`candidates`) or, ``inline``, among all
    (:func:`window`). Column N_STATES takes the goal, column N_STATES + 1 + N_CARRIER i + e
    the feature e of basis first_basis + i.

    Segment t (segments[t] = first step, steps, offset in ``out``, left, width; steps
    counted from first_step) fills out[offset:].reshape(3, steps, N_STATES + 1 + width):
    first the responses of the n unit states and of the goal from rest at its first step,
    then those of its window, the columns left .. left + width - 1 (a basis outside them
    must not be forced there); starts[t, :n] takes the states at its first step. ``advance``: step
    past the last sample too. ``canonical`` and ``states`` are left at the state after the
    last step."""
    n, m = N_STATES, states.shape[1]
    n_steps = segments[-1, 0] + segments[-1, 1]
    n_basis = centres.size
    basis = basis_table(centres, widths)
    current, following = states.copy(), np.empty((n, m))
    unit, unit_following = np.zeros((n, n + 1)), np.empty((n, n + 1))
    stage = np.empty(2)
    logs, slopes = np.empty(n_basis), np.empty(n_basis)
    values, rates = np.empty((n_basis, N_CARRIER)), np.empty((n_basis, N_CARRIER))
    seen, max_width = np.full(n_basis, -1), widths.max()
    columns = np.empty(n_basis, dtype=np.int64)  # the state column of each kept basis's first
    segment, begin, length, left, width = -1, 0, 0, 0, 0
    block = np.empty((0, n + 1))
    for k in range(n_steps):
        if segment + 1 < segments.shape[0] and k == segments[segment + 1, 0]:
            segment += 1
            begin, length, offset = segments[segment, 0], segments[segment, 1], segments[segment, 2]
            left, width = segments[segment, 3], segments[segment, 4]
            size = 3 * length * (n + 1 + width)
            block = out[offset : offset + size].reshape((3 * length, n + 1 + width))
            starts[segment, :n, :] = current
            unit[:, :] = 0.0
            for i in range(n):
                unit[i, i] = 1.0
        at, mark = first_step + k, 4 * k
        if inline:
            point, terms, terms_slope, lo, hi, top = window(canonical, target, gains, basis,
                                                            widths, max_width, first, True, logs)
        else:
            point = phase_point(canonical, target, gains)
            terms, terms_slope = point_terms(point)
            lo, hi, top = candidate_window(terms, terms_slope, lowest[at], highest[at], basis,
                                           max_width, first, True, logs, slopes, seen, mark)
        kept_features(point, terms, terms_slope, lo, hi, top, basis, True, logs, seen, mark,
                      slopes, values, rates)
        count = kept_columns(lo, hi, n_basis, first_basis, left, width, columns)
        for j in range(3):  # O x + O_g g + O_f (f, fdot)
            row = j * length + k - begin
            row_product(output, j, unit, 0, n + 1, block, row, 0)
            block[row, n] += output_goal[j]
            row_product(output, j, current, left, width, block, row, n + 1)
            for i in range(count):
                column = n + 1 + columns[i] - left  # its column in the block
                for e in range(N_CARRIER):
                    block[row, column + e] += (
                        output_forcing[j, 0] * values[i, e] + output_forcing[j, 1] * rates[i, e]
                    )
        if k == n_steps - 1 and not advance:
            break
        for i in range(n):  # S x + S_g g + S_f (f_1, .., f_4), stage 1 at the sample
            row_product(step, i, unit, 0, n + 1, unit_following, i, 0)
            unit_following[i, n] += step_goal[i]
            row_product(step, i, current, 0, m, following, i, 0)
            following[i, n] += step_goal[i]
            for a in range(count):
                for e in range(N_CARRIER):
                    following[i, columns[a] + e] += step_forcing[i, 0] * values[a, e]
        result = canonical_step(canonical, dt, target, gains)
        last = NO_TERMS  # the last stage's phase terms
        for s in range(1, 4):
            stage[0] = result[2 + 2 * s]
            stage[1] = result[3 + 2 * s]
            mark = 4 * k + s
            point = phase_point(stage, target, gains)
            terms, terms_slope = point_terms(point)
            if terms == last:  # the last stage's activations (phase form: stages 2 and 3)
                for i in range(count):
                    for e in range(N_CARRIER):
                        values[i, e] = logs[basis_at(lo, i, n_basis)] * point[2 + e]
            else:
                if inline:
                    point, terms, terms_slope, lo, hi, top = window(
                        stage, target, gains, basis, widths, max_width, first, False, logs
                    )
                else:
                    lo, hi, top = candidate_window(terms, terms_slope, lowest[at], highest[at],
                                                   basis, max_width, first, False, logs, slopes,
                                                   seen, mark)
                kept_features(point, terms, terms_slope, lo, hi, top, basis, False, logs, seen,
                              mark, slopes, values, rates)
            last = terms
            count = kept_columns(lo, hi, n_basis, first_basis, left, width, columns)
            for i in range(n):
                for a in range(count):
                    for e in range(N_CARRIER):
                        following[i, columns[a] + e] += step_forcing[i, s] * values[a, e]
        canonical[0] = result[0]
        canonical[1] = result[1]
        current, following = following, current
        unit, unit_following = unit_following, unit
    states[:, :] = current


@_compile
def product(out, segments, starts, inputs, plan):
    """plan (3, n_steps, n_dofs): the responses of :func:`response` (its ``out``,
    ``segments`` and ``starts``, the latter with the goal's row and zero window columns)
    times the inputs of each DOF (m, n_dofs): segment t's first N_STATES + 1 columns take
    starts[t] @ inputs, its window columns their inputs. One matrix-vector product per DOF,
    which reads the responses faster than a matrix product for a few DOFs (module
    docstring; ResponseMatrices.product takes many DOFs through numpy)."""
    n1, n_dofs = N_STATES + 1, inputs.shape[1]
    for t in range(segments.shape[0]):
        begin, length, offset = segments[t, 0], segments[t, 1], segments[t, 2]
        window, width = segments[t, 3], segments[t, 4]
        block = out[offset : offset + 3 * length * (n1 + width)].reshape((3 * length, n1 + width))
        factors = np.empty((n1 + width, n_dofs))
        factors[:n1] = starts[t] @ inputs
        factors[n1:] = inputs[window : window + width]
        vector = np.empty(n1 + width)
        for d in range(n_dofs):
            vector[:] = factors[:, d]
            values = block @ vector
            for r in range(3):
                plan[r, begin : begin + length, d] = values[r * length : (r + 1) * length]
'''


@lru_cache(maxsize=1)
def exp_constants() -> dict:
    """The constants of the compiled ``table_exp`` as source text (module docstring): the
    table of :math:`2^{i/128}`, i = 0 .. 127, each as the bits of its nearest float less
    ``i << 45`` (``EXP_SCALES``) and the relative error of that float (``EXP_TAILS``),
    computed to 60 digits; the reduction's constants; the polynomial's coefficients."""
    tails, scales = [], []
    with decimal.localcontext() as context:
        context.prec = 60
        step, power = decimal.Decimal(2) ** (decimal.Decimal(1) / 128), decimal.Decimal(1)
        for i in range(128):
            nearest = float(power)
            tails.append(repr(float((power - decimal.Decimal(nearest)) / decimal.Decimal(nearest))))
            scales.append(str(struct.unpack("<Q", struct.pack("<d", nearest))[0] - (i << 45)))
            power *= step
    return {
        "exp_tails": "[" + ", ".join(tails) + "]",
        "exp_scales": "[" + ", ".join(scales) + "]",
        "exp_inverse": repr(float.fromhex("0x1.71547652b82fep+7")),
        "exp_ln2_high": repr(float.fromhex("-0x1.62e42fefa0000p-8")),
        "exp_ln2_low": repr(float.fromhex("-0x1.cf79abc9e3b3ap-47")),
        "exp_polynomial": repr(tuple(float.fromhex(c) for c in EXP_POLYNOMIAL)),
    }


EXP_POLYNOMIAL = (
    "0x1.ffffffffffdbdp-2",
    "0x1.555555555543cp-3",
    "0x1.55555cf172b91p-5",
    "0x1.1111167a4d017p-7",
)
"""Coefficients of r^2 .. r^5 in table_exp's polynomial for exp(r) - 1, |r| <= ln 2 / 256."""


def kernel_source(form: str, kernel: str) -> str:
    """Source of the compiled response of ``form`` with ``kernel``: CasADi's expressions as
    Python (:func:`symbolic.numba_source`) and the loop (module docstring)."""
    signature = symbolic.Signature(form, 1, 1, kernel)
    generated = [
        symbolic.numba_source(symbolic.canonical_step_function(signature), "canonical_step"),
        symbolic.numba_source(symbolic.phase_point_function(form, kernel), "phase_point"),
        symbolic.numba_source(symbolic.log_activation_function(kernel), "log_activation"),
        symbolic.numba_source(symbolic.log_activation_function(kernel, False), "log_value"),
        symbolic.numba_source(symbolic.phase_terms_function(kernel), "phase_terms"),
        symbolic.numba_source(symbolic.basis_terms_function(kernel), "basis_terms"),
    ]
    n_terms = symbolic.phase_terms_function(kernel).nnz_out(0)
    n_basis = symbolic.basis_terms_function(kernel).nnz_out(0)

    def entries(name: str, first: int, count: int) -> str:
        """A tuple of ``name[first] .. name[first + count - 1]`` as source."""
        return "(" + "".join(f"{name}[{first + i}], " for i in range(count)) + ")"

    terms = {
        "n_basis_terms": str(n_basis),
        "terms": entries("result", 0, n_terms),
        "no_terms": "(" + "math.nan, " * n_terms + ")",
        "point_terms": entries("point", 6, n_terms),  # after phase, rate, carrier and its rate
        "point_terms_slope": entries("point", 6 + n_terms, n_terms),
        # an input of one entry is a float argument of the generated code, a longer one a tuple
        # (a basis has at least a centre and a width)
        "terms_argument": "terms[0]" if n_terms == 1 else "terms",
        "slope_argument": "terms_slope[0]" if n_terms == 1 else "terms_slope",
        "basis_argument": "(" + ", ".join(f"basis[j, {i}]" for i in range(n_basis)) + ")",
    }
    equations = symbolic.FORMS[form]
    loop = _KERNELS.replace("{n_carrier}", str(equations.vectors_per_basis))
    loop = loop.replace("{n_states}", str(equations.n_transformation))
    loop = loop.replace("{periodic}", str(not equations.discrete))
    for name, value in {**exp_constants(), **terms}.items():
        loop = loop.replace("{" + name + "}", value)
    header = (
        f'"""Generated by dmpopt.response for the {form} form with the {kernel} kernel."""\n\n'
        "import math\n\nimport numba\nimport numpy as np\nfrom llvmlite import ir\n"
        "from numba import types\nfrom numba.extending import intrinsic\n\n\n"
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


FEW_DOFS = 4
"""Up to this many DOFs the plan's product is one matrix-vector product per DOF in the
compiled loop; beyond, one matrix product per segment through numpy's BLAS (30 DOFs, 1,000
steps: 0.3 ms, where the compiled loop's matrix products took 1.4-4 ms)."""

SLACK = 2
"""Bases a segment's window may span beyond those of its first step (:func:`segments_of`)."""

SHORTEST = 32
"""Steps a segment has at least (its factor holds (n + 1) x n_inputs numbers)."""


@dataclass(frozen=True, eq=False)
class ResponseMatrices:
    r"""The response matrices of one DOF (:func:`response_matrices`), segment by segment.

    Within a segment of steps no column is forced but those of its window, so each other
    column's response there is that of its transformation state at the segment's first
    step under the unforced, affine step: with :math:`U_i` the responses (3 rows) of the
    :math:`n` unit states and of the goal from rest :math:`i` steps into the segment,
    column :math:`j` is :math:`U_i c_j` there, :math:`c_j` its state at the segment's start
    (and a 1 for the goal's column). Then :math:`R w = (U_i C w)` on them, with the
    segment's factor :math:`C`, plus the window columns' own rows.

    Attributes
    ----------
    blocks : ndarray, shape (n_numbers,)
        Segment t's responses at ``segments[t, 2]``, shape (3, segments[t, 1], n + 1 +
        segments[t, 4]): positions, velocities and accelerations against the unit states and
        the goal (:math:`U`), then against the window's inputs.
    segments : ndarray of int, shape (n_segments, 5)
        Per segment: first step, steps, offset in ``blocks``, first window input, window
        inputs.
    factors : ndarray, shape (n_segments, n + 1, n_inputs)
        :math:`C` of each segment: each input's transformation state at the segment's first
        step and its goal factor; zero for the window's inputs.
    product_kernel : callable
        The compiled ``product`` of the form's and kernel's module (:func:`kernels`).
    """

    blocks: np.ndarray
    segments: np.ndarray
    factors: np.ndarray
    product_kernel: object

    @property
    def n_steps(self) -> int:
        """Samples of the plan."""
        return int(self.segments[-1, 0] + self.segments[-1, 1])

    @property
    def n_inputs(self) -> int:
        """Inputs per DOF: the initial transformation states, the goal and the weights."""
        return self.factors.shape[2]

    @property
    def nbytes(self) -> int:
        """Bytes held."""
        return self.blocks.nbytes + self.segments.nbytes + self.factors.nbytes

    def block(self, t: int) -> np.ndarray:
        """Segment t's responses, shape (3, steps, n + 1 + window inputs)."""
        _, length, offset, _, width = (int(value) for value in self.segments[t])
        columns = self.factors.shape[1] + width
        return self.blocks[offset : offset + 3 * length * columns].reshape(3, length, columns)

    def window(self, t: int) -> slice:
        """Segment t's window inputs."""
        return slice(int(self.segments[t, 3]), int(self.segments[t, 3] + self.segments[t, 4]))

    def product(self, inputs: np.ndarray) -> np.ndarray:
        """The plans of the DOFs whose inputs are the columns of ``inputs`` (n_inputs,
        n_dofs): positions, velocities and accelerations, shape (3, n_steps, n_dofs)."""
        plan = np.empty((3, self.n_steps, inputs.shape[1]))
        if inputs.shape[1] <= FEW_DOFS:
            self.product_kernel(self.blocks, self.segments, self.factors,
                                np.ascontiguousarray(inputs), plan)  # fmt: skip
            return plan
        for t, (begin, length) in enumerate(self.segments[:, :2]):
            block = self.block(t)  # numpy multiplies a stack of matrices without BLAS: flat
            factors = np.concatenate([self.factors[t] @ inputs, inputs[self.window(t)]])
            values = block.reshape(-1, block.shape[2]) @ factors
            plan[:, begin : begin + length] = values.reshape(3, length, -1)
        return plan

    def dense(self) -> np.ndarray:
        """The whole response, shape (3, n_steps, n_inputs)."""
        n1 = self.factors.shape[1]
        if len(self.segments) == 1 and self.window(0) == slice(n1, self.n_inputs):
            return self.block(0)  # one segment of every column: the dense pass's
        parts = []
        for t in range(len(self.segments)):
            block = self.block(t)
            part = block[:, :, :n1] @ self.factors[t]
            part[:, :, self.window(t)] = block[:, :, n1:]
            parts.append(part)
        return np.concatenate(parts, axis=1)

    def freeze(self) -> None:
        """Make the arrays read-only (the cached response is shared)."""
        for array in (self.blocks, self.segments, self.factors):
            array.setflags(write=False)


def segments_of(module, lowest, highest, n_carrier, n_other, n_inputs) -> np.ndarray:
    """Segments (:class:`ResponseMatrices`) of a plan whose step k may force the
    bases lowest[k] .. highest[k]: per segment its first step, steps, 0 (the offset, set
    later), first window input and window inputs (those of the bases its steps may force;
    ``n_other`` inputs come before the weights, ``n_carrier`` weights per basis).

    The settling tail of a discrete plan is one segment (:func:`tail_start`): the response
    pass tracks only its window's states there, where before the last segment it tracks
    every column's (LASA: 1.5 times as fast as splitting the tail where its window
    narrows); the steps before it are split by ``segment_bounds``."""
    n_steps = lowest.size
    end = tail_start(lowest, highest, n_inputs, n_other, n_carrier)
    bounds = np.empty((n_steps, 4), dtype=np.int64)
    count = module.segment_bounds(lowest[:end], highest[:end], SLACK, SHORTEST, bounds)
    if end < n_steps:
        bounds[count] = end, n_steps, lowest[end:].min(), highest[end:].max()
        count += 1
    bounds = bounds[:count]
    segments = np.zeros((count, 5), dtype=np.int64)
    segments[:, 0], segments[:, 1] = bounds[:, 0], bounds[:, 1] - bounds[:, 0]
    segments[:, 3] = n_other + n_carrier * bounds[:, 2]
    segments[:, 4] = n_carrier * (bounds[:, 3] + 1 - bounds[:, 2])
    return segments


def tail_start(
    lows: np.ndarray, highs: np.ndarray, n_inputs: int, n_other: int, n_carrier: int
) -> int:
    """The first step of the settling tail, the last segment (:func:`segments_of`): the one
    where a dense head and the tail hold the fewest numbers, from the first and last basis
    each step forces (``lows``, ``highs``); ``len(lows)`` for none. ``n_other``: the inputs
    that are not weights (the tail keeps as many unit responses), ``n_carrier`` weights per
    basis."""
    n_steps = lows.size
    first = np.minimum.accumulate(lows[::-1])[::-1]  # the bases forced from step k on
    last = np.maximum.accumulate(highs[::-1])[::-1]
    steps = np.arange(n_steps)
    alive = n_carrier * (last - first + 1)
    held = steps * n_inputs + (n_steps - steps) * (n_other + alive)
    best = int(np.argmin(held))
    return best if held[best] < n_steps * n_inputs else n_steps


@lru_cache(maxsize=16)
def step_matrices(form: str, dt: float, gains: tuple) -> dict:
    """:func:`symbolic.transformation_matrices` of ``form`` at the normalised step ``dt`` with
    ``gains``, as read-only arrays: the same for every DMP of the form with these gains and
    ``dt / tau`` (a CasADi call, 0.15-0.3 ms of a first rollout)."""
    matrices = symbolic.transformation_matrices(form)(dt=dt, gains=np.array(gains, dtype=float))
    matrices = {name: value.full() for name, value in matrices.items()}
    for value in matrices.values():
        value.setflags(write=False)
    return matrices


def response_matrices(key: tuple, factored: bool = True) -> ResponseMatrices:
    """Response matrices of one DOF for the cache key of :func:`dmpopt.dmp._response`, in time
    normalised by ``tau``: positions, velocities and accelerations against the initial
    transformation states, the goal and the weights (:class:`ResponseMatrices`).

    A first pass finds each step's candidate bases (:func:`candidates`), from which the
    response pass finds the kept ones at each point; ``factored``: each segment of steps
    keeps only the columns of the bases it forces, the others as a factor
    (:func:`segments_of`), else one segment of every column. The printed periodic kernel
    (not in :data:`forms.TRACKED_KERNELS`: it jumps where the phase wraps) has no
    candidates: one segment of every column, every basis evaluated at every point."""
    (form, kernel, n_basis, n_steps, dt, target, canonical0, centres, widths, gains) = key
    gains = np.array(gains, dtype=float)
    centres, widths = np.array(centres, dtype=float), np.array(widths, dtype=float)
    matrices = step_matrices(form, dt, key[-1])
    n = symbolic.n_transformation_states(form)
    n_inputs = n + 1 + symbolic.n_features(form, n_basis)
    n_carrier = symbolic.FORMS[form].vectors_per_basis
    module = kernels(form, kernel)
    first, canonical = first_level(n_basis), np.array(canonical0, dtype=float)
    inline = not symbolic.FORMS[form].discrete and kernel not in forms.TRACKED_KERNELS
    held = 1 if inline else n_steps
    lowest, highest = np.empty(held, dtype=np.int64), np.empty(held, dtype=np.int64)
    segments = np.array([[0, n_steps, 0, n + 1, n_inputs - n - 1]], dtype=np.int64)
    if not inline:
        module.candidates(canonical, float(dt), float(target), gains, centres, widths, first,
                          lowest, highest)  # fmt: skip
        if factored:  # a window that wraps past the last basis takes every column
            wraps = highest < lowest
            segments = segments_of(module, np.where(wraps, 0, lowest),
                                   np.where(wraps, n_basis - 1, highest), n_carrier, n + 1,
                                   n_inputs)  # fmt: skip
    sizes = 3 * segments[:, 1] * (n + 1 + segments[:, 4])
    segments[1:, 2] = np.cumsum(sizes)[:-1]
    blocks = block_memory(int(sizes.sum()))
    factors = np.zeros((len(segments), n + 1, n_inputs))
    constants = (
        matrices["step"], matrices["step_goal"][:, 0], matrices["step_forcing"],
        matrices["output"], matrices["output_goal"][:, 0], matrices["output_forcing"],
    )  # fmt: skip
    windows = (first, lowest, highest, inline)
    states = np.zeros((n, n_inputs))
    states[:, :n] = np.eye(n)
    head = segments[:-1]  # every column tracked: the factors are the states at their starts
    if len(head):
        module.response(canonical, float(dt), float(target), gains, centres, widths, *windows,
                        0, 0, True, *constants, states, head, blocks, factors)  # fmt: skip
    # the last segment tracks its window's columns only (no later factor needs the others)
    factors[-1, :n] = states
    tail = segments[-1:].copy()
    begin, window, width = (int(value) for value in tail[0, [0, 3, 4]])
    tail[0, 0], tail[0, 3] = 0, n + 1
    tail_states = np.zeros((n, n + 1 + width))
    tail_states[:, :n], tail_states[:, n + 1 :] = np.eye(n), states[:, window : window + width]
    first_basis = (window - n - 1) // n_carrier
    module.response(canonical, float(dt), float(target), gains, centres, widths, *windows,
                    begin, first_basis, False, *constants, tail_states, tail, blocks,
                    np.empty((1, n + 1, tail_states.shape[1])))  # fmt: skip
    factors[:, n, n] = 1.0
    for t, (_, _, _, window, width) in enumerate(segments):
        factors[t, :, window : window + width] = 0.0
    return ResponseMatrices(blocks, segments, factors, module.product)


REUSED = 4
"""Arrays of released responses' blocks kept for new ones (:func:`block_memory`)."""

REUSED_BYTES = 16 * 1024**2
"""Bytes from which a response's blocks are not kept for reuse: idle memory stays below
``REUSED`` times this."""

_REUSED: list = []  # the arrays block_memory returned views of, newest last
_REUSED_LOCK = threading.Lock()


def block_memory(size: int) -> np.ndarray:
    """A new float array of ``size`` numbers for a response's blocks.

    The memory of an earlier one that nothing references any more (no view of it is left)
    where one holds ``size`` to twice ``size``, else :func:`fresh_array`: the first write to
    new memory costs the system a page fault per 4 KiB page, about 4 ms of the LASA demo's
    first rollout (3.9 MB) in benchmarks/bench_core.py whenever malloc returned fresh pages
    (it maps an array of that size anew after freeing the last one). Up to :data:`REUSED`
    arrays below :data:`REUSED_BYTES` are kept.
    """
    if 8 * size >= REUSED_BYTES:
        return fresh_array((size,))
    with _REUSED_LOCK:  # one thread takes an idle array
        for index in range(len(_REUSED)):
            # idle: referenced by the list and getrefcount's argument only (a view's base is
            # the array that owns the memory, so every view counts)
            if size <= _REUSED[index].size <= 2 * size and sys.getrefcount(_REUSED[index]) == 2:
                _REUSED.append(_REUSED.pop(index))
                return _REUSED[-1][:size]
        array = fresh_array((size,))
        owner = array if not isinstance(array.base, np.ndarray) else array.base
        _REUSED.append(owner)
        del _REUSED[:-REUSED]
        return owner[:size]


POPULATED_BYTES = 1024**2
"""Bytes from which :func:`fresh_array` maps memory populated in one call."""


def fresh_array(shape: tuple) -> np.ndarray:
    """A new float array of ``shape``: from :data:`POPULATED_BYTES` on, memory that the
    system maps and zeroes in one call where it can (Linux: ``MAP_POPULATE``), else
    ``np.empty``.

    numpy asks Linux for transparent huge pages for arrays of 4 MiB and more; where memory
    is fragmented, the first write to such an array waits for the system to compact memory.
    The 13.6 MB response of the LASA demo's plan took 35-45 ms of thread time to allocate
    and fill so on this machine (loaded, 2-4 ms where huge pages were at hand), 6-8 ms mapped
    and populated in one call, 9-11 ms by one page fault per 4 KiB page. Below 4 MiB too, one
    call costs less than a fault per page: 3.9 MB (the LASA demo's segments) allocated and
    filled took 1.7 ms of thread time populated, 2.1-2.2 ms from ``np.empty`` when malloc
    returned fresh pages (load 2-3).
    """
    if 8 * math.prod(shape) < POPULATED_BYTES or not hasattr(mmap, "MAP_POPULATE"):
        return np.empty(shape)
    flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | mmap.MAP_POPULATE
    memory = mmap.mmap(-1, 8 * math.prod(shape), flags=flags)
    return np.frombuffer(memory, dtype=float, count=math.prod(shape)).reshape(shape)
