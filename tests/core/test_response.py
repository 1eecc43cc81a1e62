"""The compiled pass of a rollout's response matrices (dmpopt.response): CasADi's expressions
translated for numba, the truncated features against CasADi's features of all the bases and
against the truncation bounds derived in dmpopt/response.py, and the rollout against the
step-by-step integration."""

import decimal
import math
import mmap
import sys

import numpy as np
import problems
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from problems import random_discrete, random_rhythmic

from dmpopt import response, symbolic
from dmpopt.basis import discrete_basis, rhythmic_basis

EPS = np.finfo(float).eps
DISCRETE_GAINS = list(problems.DISCRETE_GAINS)
CASES = problems.FORMS_AND_KERNELS
DISCRETE = ("velocity", "acceleration")


def _problem(form, kernel, n_basis=30, n_points=200, seed=0):
    """Centres, widths, target, gains and random canonical states (as in test_symbolic)."""
    rng = np.random.default_rng(seed)
    if form in ("velocity", "acceleration"):
        centres, widths = discrete_basis(n_basis, tuple(DISCRETE_GAINS))
        gains = np.array(DISCRETE_GAINS + [12.5] * (form == "acceleration"))
        points = np.vstack([rng.uniform(-0.1, 1.1, n_points), rng.uniform(-1.0, 3.0, n_points)])
    else:
        centres, widths = rhythmic_basis(n_basis, kernel)
        gains = np.array([25.0, 6.25, 10.0] + [2.0] * (form == "energy"))
        points = np.vstack([rng.uniform(-10, 10, n_points), rng.uniform(-2.0, 2.0, n_points)])
    return centres, widths, 1.3, gains, points


def _features(module, canonical, target, gains, centres, widths, first, with_rate=True):
    """The compiled features (and rates) at one canonical state, spread over all bases."""
    n_basis, n_carrier = centres.size, module.N_CARRIER
    logs, slopes = np.empty(n_basis), np.empty(n_basis)
    values, rates = np.empty((n_basis, n_carrier)), np.empty((n_basis, n_carrier))
    lo, count = module.features(
        np.asarray(canonical, dtype=float), target, gains, centres, widths, widths.max(),
        first, with_rate, logs, slopes, values, rates,
    )  # fmt: skip
    dense = np.zeros((2, n_basis, n_carrier))
    dense[0, lo : lo + count], dense[1, lo : lo + count] = values[:count], rates[:count]
    return dense.reshape(2, -1), count


@pytest.mark.parametrize("form, kernel", CASES)
def test_the_translated_expressions_compute_what_casadi_computes(form, kernel):
    """The canonical step (only +, -, * and / in every form) is CasADi's to the bit: the same
    operations in the same order; the phase, carrier and log-activation (with cos, sin,
    atan2, fmod from the C library on both sides) agree within 100 eps of their size."""
    centres, widths, target, gains, points = _problem(form, kernel, n_points=50)
    module = response.kernels(form, kernel)
    step = symbolic.canonical_step_function(symbolic.Signature(form, 1, 1, kernel))
    point = symbolic.phase_point_function(form, kernel)
    phase_terms = symbolic.phase_terms_function(kernel)
    basis_terms = symbolic.basis_terms_function(kernel)
    log_activation = symbolic.log_activation_function(kernel)
    for state in points.T:
        expected = step(canonical=state, dt=0.01, canonical_target=target, gains=gains)
        expected = np.concatenate([expected["next_canonical"].full().ravel(),
                                   expected["stages"].full().ravel(order="F")])  # fmt: skip
        np.testing.assert_array_equal(module.canonical_step(state, 0.01, target, gains), expected)
        expected = np.concatenate([v.full().ravel() for v in point(state, target, gains)])
        got = np.array(module.phase_point(state, target, gains))
        np.testing.assert_allclose(got, expected, rtol=0, atol=100 * EPS * np.abs(expected).max())
        terms = phase_terms(state[0]).full().ravel()
        np.testing.assert_allclose(module.phase_terms(state[0]), terms, rtol=0, atol=100 * EPS)
        n_terms = terms.size  # the point's terms and slopes follow its phase, rates and carrier
        terms, terms_slope = got[6 : 6 + n_terms], got[6 + n_terms :]
        for centre, width in zip(centres[::7], widths[::7]):
            basis = basis_terms(centre, width).full().ravel()
            got = np.array(module.basis_terms(centre, width))
            np.testing.assert_allclose(got, basis, rtol=0, atol=100 * EPS * abs(basis).max())
            arguments = [t if t.size > 1 else float(t[0]) for t in (terms, terms_slope, got)]
            expected = np.array([float(v) for v in log_activation(*arguments)])
            got = np.array(module.log_activation(*arguments))
            np.testing.assert_allclose(got, expected, rtol=0, atol=100 * EPS * abs(expected).max())
            # the value alone (stage points) by the same instructions less the slope's
            assert module.log_value(arguments[0], arguments[2]) == (got[0],)


@settings(max_examples=300, deadline=None)
@given(st.floats(-20.0, 20.0), st.floats(0.0, 2 * np.pi), st.floats(0.1, 200.0))
def test_von_mises_log_activation_is_the_cosine_written_out(phase, centre, width):
    """The compiled von Mises log-activation from its terms (-h/2 |u(phi) - u(c)|^2, u(a) =
    (cos a, sin a)) is h (cos(phi - c) - 1) = -2 h sin^2(theta / 2), theta = phi - c, and its
    slope -h sin(theta). Bounds: with cos and sin within 1 ulp (<= eps for values <= 1), each
    of d = u(phi) - u(c)'s entries is off by at most eps plus its rounding, so |d|^2 (|d| <= 2)
    by at most 4 sqrt(2) |d| eps + 3 eps |d|^2 <= 24 eps and the log-activation by 12 h eps; the
    key, theta rounded once and sin within 1 ulp, by 4 eps |l| <= 8 h eps; the slope likewise
    within 16 h eps, and the key's sin(theta) by eps (1 + |theta|)."""
    module = response.kernels("phase", "von_mises")
    terms = module.phase_terms(phase)
    terms_slope = (-terms[1], terms[0])  # d/dphi (cos, sin)
    basis = module.basis_terms(centre, width)
    log, slope = module.log_activation(terms, terms_slope, basis)
    theta = phase - centre
    assert log <= 0.0
    assert abs(log - (-2.0 * width * math.sin(theta / 2) ** 2)) <= 20 * width * EPS
    assert abs(slope - (-width * math.sin(theta))) <= width * EPS * (17 + abs(theta))


@pytest.mark.parametrize("form, kernel", CASES)
def test_truncated_features_equal_casadis_features_of_all_bases(form, kernel):
    """At the levels of a rollout (dmpopt/response.py) the left-out bases change the features
    by at most eps/2 |C| and their rates by eps/2 (|p'| |C| + |C'|): the features and rates
    equal CasADi's own of all 30 bases (feature_rate_function) to rounding: within 100 eps of
    their size as for symbolic.ArrayFunction (tests/core/test_symbolic.py), the rates of the
    size of their largest term (_rate_terms); fewer bases than all are evaluated at some
    points."""
    centres, widths, target, gains, points = _problem(form, kernel)
    module = response.kernels(form, kernel)
    casadi = symbolic.feature_rate_function(symbolic.Signature(form, 1, centres.size, kernel))
    first = response.first_level(centres.size)
    counts = []
    for state in points.T:
        expected = [v.full().ravel() for v in casadi(state, centres, widths, target, gains)]
        for with_rate in (True, False):
            got, count = _features(module, state, target, gains, centres, widths, first, with_rate)
            counts.append(count)
            scale = np.abs(expected[0]).max()
            np.testing.assert_allclose(got[0], expected[0], rtol=0, atol=100 * EPS * scale)
            if with_rate:
                scale = _rate_terms(kernel, state, centres, widths, target, gains, form)
                np.testing.assert_allclose(got[1], expected[1], rtol=0, atol=100 * EPS * scale)
    assert min(counts) < centres.size


def _log_activations(kernel, phase, centres, widths):
    """l_j and dl_j/dp of eq. (7) (Gaussian), the von Mises kernel and eq. (12) as printed."""
    if kernel == "von_mises":
        return widths * (np.cos(phase - centres) - 1.0), -widths * np.sin(phase - centres)
    if kernel == "paper":
        phase = np.fmod(np.fmod(phase, 2 * np.pi) + 2 * np.pi, 2 * np.pi)
    return -widths * (phase - centres) ** 2, -2 * widths * (phase - centres)


def _rate_terms(kernel, state, centres, widths, target, gains, form):
    """The size of the largest term of a feature's rate, a_j (|l_j'| + sum_i a_i |l_i'|) |p'|
    |C| + a_j |C'|: the rate is their sum, so it rounds within a few eps of it."""
    phase, phase_rate, carrier, carrier_rate, _, _ = (
        v.full().ravel() for v in symbolic.phase_point_function(form, kernel)(state, target, gains)
    )
    logs, slopes = _log_activations(kernel, phase[0], centres, widths)
    activations = np.exp(logs - logs.max())
    activations /= activations.sum()
    weighted = activations @ np.abs(slopes)
    terms = activations * (np.abs(slopes) + weighted) * abs(phase_rate[0])
    return (terms * np.abs(carrier).max() + activations * np.abs(carrier_rate).max()).max()


def _bounds(kernel, phase, centres, widths, first, phase_rate, carrier, carrier_rate):
    """The truncation bounds of dmpopt/response.py, written out: the features change by at most
    n e^-L0 |C|, the rates by 5 n e^-L G |p'| |C| + n e^-L |C'| at the samples' level L = L0 +
    ln(1 + 5 G), G = 2 sqrt(h_max (|M| + 3 L0)) (no truncation if ln(1 + 5 G) > 2 L0)."""
    n = centres.size
    top = _log_activations(kernel, phase, centres, widths)[0].max()
    slope = 2 * math.sqrt(widths.max() * (abs(top) + 3 * first))
    extra = math.log1p(5 * slope)
    level = first + extra if extra <= 2 * first else math.inf
    carrier_size, rate_size = np.abs(carrier).max(), np.abs(carrier_rate).max()
    feature_bound = n * math.exp(-first) * carrier_size
    rate_bound = n * math.exp(-level) * (5 * slope * abs(phase_rate) * carrier_size + rate_size)
    return feature_bound, rate_bound


@settings(max_examples=60, deadline=None)
@given(
    form=st.sampled_from(["velocity", "phase"]),
    phase=st.floats(-0.2, 1.2),
    width_scale=st.floats(0.02, 3.0),
    first=st.floats(1.0, 12.0),
)
def test_the_truncation_bounds_hold_where_the_truncation_shows(form, phase, width_scale, first):
    """At levels L0 of 1 to 12 (a rollout uses ln(2 n / eps) = 39.3 for 30 bases) the
    truncated features differ from CasADi's of all bases by up to ~1e-1, always within the
    bounds derived in dmpopt/response.py (written out in _bounds) plus 100 eps of rounding;
    drawn: the phase (times 2 pi for the periodic kernel), the widths' scale and the level."""
    kernel = "gaussian" if form == "velocity" else "von_mises"
    centres, widths, target, gains, _ = _problem(form, kernel)
    widths = widths * width_scale
    if form == "velocity":
        state = np.array([phase, 1.0 + phase])
    else:
        state = np.array([2 * np.pi * phase, 1.0 + phase])
    module = response.kernels(form, kernel)
    casadi = symbolic.feature_rate_function(symbolic.Signature(form, 1, centres.size, kernel))
    expected = [v.full().ravel() for v in casadi(state, centres, widths, target, gains)]
    point_function = symbolic.phase_point_function(form, kernel)
    point = [v.full().ravel() for v in point_function(state, target, gains)]
    feature_bound, rate_bound = _bounds(kernel, point[0][0], centres, widths, first,
                                        point[1][0], point[2], point[3])  # fmt: skip
    got, _ = _features(module, state, target, gains, centres, widths, first, with_rate=False)
    rounding = 100 * EPS * np.abs(expected[0]).max()
    assert np.abs(got[0] - expected[0]).max() <= feature_bound + rounding
    got, _ = _features(module, state, target, gains, centres, widths, first, with_rate=True)
    rounding = 100 * EPS * _rate_terms(kernel, state, centres, widths, target, gains, form)
    assert np.abs(got[1] - expected[1]).max() <= rate_bound + rounding


def test_the_truncation_shows_at_a_low_level_and_stays_within_its_bound():
    """The bound is not idle: at L0 = 3 between two Gaussian centres the features of the
    velocity form differ from all bases' by more than 1e-4, and by less than n e^-3 |C|."""
    centres, widths, target, gains, _ = _problem("velocity", "gaussian")
    state = np.array([0.5 * (centres[10] + centres[11]), 1.0])
    module = response.kernels("velocity", "gaussian")
    casadi = symbolic.feature_function(symbolic.Signature("velocity", 1, centres.size, "gaussian"))
    expected = casadi(state, centres, widths).full().ravel()
    got, count = _features(module, state, target, gains, centres, widths, 3.0, False)
    error = np.abs(got[0] - expected).max()
    assert count < centres.size and 1e-4 < error <= centres.size * math.exp(-3.0)


@pytest.mark.parametrize("form", ["velocity", "acceleration", "phase", "energy"])
def test_rollout_equals_the_stepwise_integration(form):
    """The response pass and the integration step by step (symbolic.simulate: CasADi's RK4
    step of the whole system, the stepper's arithmetic) agree over 800 steps within 4
    n_steps eps of each output's largest value: both round each step's sums differently."""
    if form in ("velocity", "acceleration"):
        dmp = random_discrete(seed=4, n_basis=12, form=form)
        canonical, rows = (0.0, 0.0), [dmp.start, np.zeros(2)]
        rows += [dmp.start] if form == "acceleration" else []
        plan = dmp.rollout(0.8, 0.001, start_velocity=np.zeros(2))
        forcing = dmp.forcing_weights() @ dmp._features(canonical)
        rows[1] = rows[1] - forcing if form == "velocity" else rows[1]
    else:
        dmp = random_rhythmic(seed=4, n_basis=12, form=form)
        canonical, rows = dmp.canonical_state(0.0), [dmp.setpoint, np.zeros(2)]
        plan = dmp.rollout(0.8, 0.001)
        rows[1] = rows[1] - dmp.forcing_weights() @ dmp._features(canonical)
    initial = np.concatenate([canonical, *rows])
    stepped = symbolic.simulate(dmp.signature, plan.n_steps, initial, 0.001, dmp.parameters())
    for got, expected in zip((plan.positions, plan.velocities, plan.accelerations), stepped[1:]):
        bound = 4 * plan.n_steps * EPS * np.abs(expected).max()
        np.testing.assert_allclose(got, expected, rtol=0, atol=bound)


def test_a_first_stage_at_phase_zero_takes_its_own_activations():
    """The pass reuses a stage's activations only for the next stage of the same phase (the
    phase form's stages 2 and 3), never the sample's: started at the phase whose first
    stage lands on exactly 0.0, the plan still agrees with the integration step by step
    within 4 n_steps eps (taking the sample's activations there errs by O(dt))."""
    dmp = random_rhythmic(seed=4, n_basis=12, form="phase")
    module = response.kernels("phase", "von_mises")
    amplitude = dmp.canonical_state(0.0)[1]
    gains = np.array(dmp.gains, dtype=float)
    dt = 0.001 / dmp.tau
    half_step = module.canonical_step(np.array([0.0, amplitude]), dt, amplitude, gains)[4]
    canonical = dmp.canonical_state(-half_step)
    first_stage = module.canonical_step(np.array(canonical), dt, amplitude, gains)[4]
    assert half_step > 0 and first_stage == 0.0
    plan = dmp.rollout(0.3, 0.001, phase=-half_step)
    velocity = -dmp.forcing_weights() @ dmp._features(canonical)
    initial = np.concatenate([canonical, dmp.setpoint, velocity])
    stepped = symbolic.simulate(dmp.signature, plan.n_steps, initial, 0.001, dmp.parameters())
    for got, expected in zip((plan.positions, plan.velocities, plan.accelerations), stepped[1:]):
        bound = 4 * plan.n_steps * EPS * np.abs(expected).max()
        np.testing.assert_allclose(got, expected, rtol=0, atol=bound)


def test_the_generated_source_goes_to_a_temporary_folder_if_the_cache_cannot_be_written(
    monkeypatch,
):
    """A cache folder that cannot be created (under a file) sends the generated module to a
    temporary folder of the process instead of failing the rollout."""
    cached = response.kernels("velocity", "gaussian")
    monkeypatch.setitem(sys.modules, cached.__name__, cached)  # put back after the test
    monkeypatch.setattr(symbolic, "cache_dir", lambda: symbolic.Path("/dev/null/dmpopt"))
    module = response.kernels.__wrapped__("velocity", "gaussian")
    assert "dmpopt-generated-" in module.__file__
    assert module.N_CARRIER == 1 and module.N_STATES == 2


@pytest.mark.parametrize("shape", [(3, 5, 4), (3, 4000, 53)])
def test_a_fresh_array_is_a_writable_float_array_of_its_shape(shape):
    """Small arrays come from numpy, those of 1 MiB and more (5 MB here) from a populated
    mapping where the system has one: either way a writable float array that keeps what is
    written to it."""
    array = response.fresh_array(shape)
    assert array.shape == shape and array.dtype == np.float64 and array.flags.writeable
    array[...] = np.arange(array.size).reshape(shape)
    assert array[-1, -1, -1] == array.size - 1 and array.sum() == array.size * (array.size - 1) / 2


def _key(dmp, duration, dt=0.001):
    """The cache key of dmpopt.dmp._response for a default-start plan of ``dmp`` (a rhythmic
    one at phase 0)."""
    n_steps = int(round(duration / dt)) + 1
    gains = tuple(dmp.gains)
    canonical = (0.0, 0.0) if dmp.form in DISCRETE else tuple(dmp.canonical_state(0.0))
    return (dmp.form, dmp.kernel, dmp.n_basis, n_steps, dt / dmp.tau,
            float(dmp._canonical_target()), canonical, tuple(dmp.centres), tuple(dmp.widths),
            gains)  # fmt: skip


def _default_plan_key(form: str) -> tuple:
    """The cache key of a random DMP's plan of 20 bases at its default duration: the settling
    time (discrete) or three periods (rhythmic)."""
    if form in DISCRETE:
        dmp = random_discrete(seed=3, n_basis=20, form=form)
        return _key(dmp, dmp.settling_time)
    dmp = random_rhythmic(seed=3, n_basis=20, form=form)
    return _key(dmp, 3 * dmp.period)


def _power_bound(step, step_goal, n_steps):
    """P = max_i ||S~^i||_inf over i < n_steps of the augmented step S~ = [[S, S_g], [0, 1]]
    (the goal as a constant state) and ||S~||_inf."""
    n = step.shape[0]
    augmented = np.eye(n + 1)
    augmented[:n, :n], augmented[:n, n] = step, step_goal
    power, largest = np.eye(n + 1), 1.0
    for _ in range(n_steps):
        power = augmented @ power
        largest = max(largest, np.abs(power).sum(axis=1).max())
    return largest, np.abs(augmented).sum(axis=1).max()


@pytest.mark.parametrize("form", ["velocity", "acceleration", "phase", "energy"])
def test_the_segments_equal_the_dense_pass_within_their_rounding_bound(form):
    r"""A discrete form's default plan is kept segment by segment (dmpopt/response.py): each
    segment's window columns are the dense pass's to the bit (the same operations), and
    every other column i steps into its segment differs from it by at most

    .. math:: \gamma ||\tilde O||_\infty P (2 i P ||\tilde S||_\infty + 3) ||c_j||_1,
              \quad \gamma = (n + 1)\,\epsilon

    (the goal as a constant state: :math:`\tilde S = [[S, S_g], [0, 1]]`, :math:`\tilde O =
    [O, O_g]`, :math:`P = \max_i ||\tilde S^i||_\infty`, :math:`c_j` the column's
    factor). Both compute :math:`\tilde O \tilde S^i c_j`: each of the i steps of either
    rounds each entry by at most :math:`\gamma/2 |\tilde S| |s|` (a sum of n + 1 terms),
    which the later steps carry by at most P; the outputs and the factor's combination round
    once more each. The forcing is not zero in the settling tail (the carrier v > 0 and the
    normalisation keeps the largest basis), so the last segment has a window too. A rhythmic
    plan (three periods of von Mises bases) is split likewise but where the phase wraps."""
    key = _default_plan_key(form)
    factored = response.response_matrices(key)
    dense = response.response_matrices(key, False).dense()
    n = symbolic.n_transformation_states(form)
    segments = factored.segments
    assert len(segments) > 2 and np.any(segments[:, 4] < dense.shape[2] - n - 1)
    matrices = symbolic.transformation_matrices(form)(dt=key[4], gains=np.array(key[-1]))
    matrices = {name: value.full() for name, value in matrices.items()}
    longest = int(segments[:, 1].max())
    power, step_norm = _power_bound(matrices["step"], matrices["step_goal"][:, 0], longest)
    output = np.hstack([matrices["output"], matrices["output_goal"]])
    output_norm = np.abs(output).sum(axis=1)[:, None, None]  # per output row
    whole = factored.dense()
    largest = 0.0
    for t, (begin, length, _, _, _) in enumerate(segments):
        steps = slice(begin, begin + length)
        window = factored.window(t)
        np.testing.assert_array_equal(factored.block(t)[:, :, n + 1 :], dense[:, steps, window])
        np.testing.assert_array_equal(whole[:, steps, window], dense[:, steps, window])
        inside = np.arange(length)[None, :, None]
        size = np.abs(factored.factors[t]).sum(axis=0)[None, None, :]
        bound = (n + 1) * EPS * output_norm * power * (2 * inside * power * step_norm + 3) * size
        error = np.abs(whole[:, steps] - dense[:, steps])
        assert np.all(error <= bound)
        largest = max(largest, error.max())
    assert largest > 0  # the bound is not idle: the factors round otherwise


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_a_default_rollout_by_segments_equals_the_stepwise_integration(form):
    """The whole default plan (kept by segments) agrees with the integration step by step
    (symbolic.simulate) within 4 n_steps eps of each output's largest value, as in
    test_rollout_equals_the_stepwise_integration."""
    dmp = random_discrete(seed=5, n_basis=20, form=form)
    plan = dmp.rollout(start_velocity=np.zeros(2))
    assert len(response.response_matrices(_key(dmp, dmp.settling_time)).segments) > 2
    rows = [dmp.start, np.zeros(2)] + [dmp.start] * (form == "acceleration")
    if form == "velocity":
        rows[1] = rows[1] - dmp.forcing_weights() @ dmp._features((0.0, 0.0))
    initial = np.concatenate([(0.0, 0.0), *rows])
    stepped = symbolic.simulate(dmp.signature, plan.n_steps, initial, 0.001, dmp.parameters())
    for got, expected in zip((plan.positions, plan.velocities, plan.accelerations), stepped[1:]):
        bound = 4 * plan.n_steps * EPS * np.abs(expected).max()
        np.testing.assert_allclose(got, expected, rtol=0, atol=bound)


@pytest.mark.parametrize("n_dofs", [1, 3, 7])
def test_the_product_of_the_segments_is_the_dense_product(n_dofs):
    r"""The plan of random inputs from the segments (a factor product and a matrix-vector
    product per segment) equals the dense response times the inputs written with numpy
    within the rounding of the two ways: each is within :math:`\gamma_k \sum_c |R_c| |w_c|`
    of the exact sum of k <= n_inputs + n + 1 products (Higham, Accuracy and Stability of
    Numerical Algorithms, 2nd ed., eq. (3.5)), and the factored columns' combination
    :math:`U (C w)` instead of :math:`(U C) w` moves them by another :math:`\gamma_{n + 1}`
    of the size :math:`|U| |C| |w|` (the dense response here is the segments' own, so the
    factors' rounding against the dense pass is not in it)."""
    dmp = random_discrete(seed=7, n_basis=20, form="acceleration")
    factored = response.response_matrices(_key(dmp, dmp.settling_time))
    inputs = np.random.default_rng(n_dofs).normal(size=(factored.n_inputs, n_dofs))
    whole = factored.dense()
    expected = np.einsum("rkc,cd->rkd", whole, inputs)
    n1 = factored.factors.shape[1]
    size = np.einsum("rkc,cd->rkd", np.abs(whole), np.abs(inputs))
    for t, (begin, length, _, _, _) in enumerate(factored.segments):
        unit = np.abs(factored.block(t)[:, :, :n1])
        size[:, begin : begin + length] += np.einsum(
            "rkc,ci,id->rkd", unit, np.abs(factored.factors[t]), np.abs(inputs)
        )
    gamma = lambda k: k * EPS / (1 - k * EPS)  # noqa: E731
    bound = 2 * gamma(factored.n_inputs + n1) * size
    got = factored.product(inputs)
    assert got.shape == (3, factored.n_steps, n_dofs)
    assert np.all(np.abs(got - expected) <= bound)


def test_segments_grow_while_their_bases_span_at_most_the_slack_more():
    """Written out: steps forcing bases (lows, highs) with slack 1 and at least 2 steps a
    segment: [0, 3) spans bases 0-2 (its narrowest step 0-1, one more), [3, 6) 2-4 (2-3, one
    more; step 6's 4-5 would make 2-5), [6, 10) 4-5 (to the end); with slack 0 and at least
    one step, a segment ends where its bases span more than its narrowest step's: [0, 1),
    [1, 2), ..., [5, 6), then [6, 10). A wide step (where a rhythmic phase wraps) is a
    segment of its own: the narrow steps after it would span its bases."""
    lows = np.array([0, 0, 1, 2, 2, 3, 4, 4, 4, 4])
    highs = np.array([1, 2, 2, 3, 4, 4, 5, 5, 5, 5])
    bounds = np.empty((10, 4), dtype=np.int64)
    module = response.kernels("velocity", "gaussian")
    count = module.segment_bounds(lows, highs, 1, 2, bounds)
    assert bounds[:count].tolist() == [[0, 3, 0, 2], [3, 6, 2, 4], [6, 10, 4, 5]]
    count = module.segment_bounds(lows, highs, 0, 1, bounds)
    expected = [[0, 1, 0, 1], [1, 2, 0, 2], [2, 3, 1, 2], [3, 4, 2, 3], [4, 5, 2, 4],
                [5, 6, 3, 4], [6, 10, 4, 5]]  # fmt: skip
    assert bounds[:count].tolist() == expected
    count = module.segment_bounds(np.array([0, 3, 3, 3]), np.array([9, 4, 4, 4]), 1, 1, bounds)
    assert bounds[:count].tolist() == [[0, 1, 0, 9], [1, 4, 3, 4]]


def test_the_tail_starts_where_the_fewest_numbers_are_held():
    """Written out: with 3 inputs besides 6 bases (9 in all), 10 steps whose last 6 force only
    bases 4-5, holding head k x 9 + tail (10 - k) x (3 + alive) is least at k = 4: 4 x 9 + 6 x
    5 = 66 numbers, against 90 dense; plans that force every basis to the end keep no tail."""
    lows = np.array([0, 0, 1, 2, 4, 4, 4, 5, 4, 4])
    highs = np.array([1, 2, 3, 4, 5, 5, 5, 5, 5, 5])
    held = [k * 9 + (10 - k) * (3 + highs[k:].max() - lows[k:].min() + 1) for k in range(10)]
    assert int(np.argmin(held)) == 4 and min(held) == 66
    assert response.tail_start(lows, highs, 9, 3, 1) == 4
    assert response.tail_start(np.zeros(10, int), np.full(10, 5), 9, 3, 1) == 10


def _points(module, canonical, target, gains, n_steps, dt):
    """Each step's sample and stages (canonical states) along n_steps steps."""
    for _ in range(n_steps - 1):
        result = module.canonical_step(canonical, dt, target, gains)
        yield [canonical] + [np.array(result[2 + 2 * s : 4 + 2 * s]) for s in (1, 2, 3)]
        canonical = np.array(result[:2])


CANDIDATES = [case for case in CASES if case[0] in DISCRETE or case[1] == "von_mises"]


def _kept_window(logs, level, periodic):
    """The kept bases written out: those at or above ``level``, from the first to the last
    (lo, hi); on a circle (the rhythmic forms) the window may wrap past the last basis (hi <
    lo): it runs from the basis after those below the level to the one before them. Von
    Mises log-activations rise and fall once around the circle, so those below form one run
    (checked)."""
    above = logs >= level
    if periodic:
        assert np.count_nonzero(above != np.roll(above, 1)) <= 2  # one run of each
    if periodic and above[0] and above[-1] and not above.all():
        below = np.flatnonzero(~above)
        return int(below[-1] + 1), int(below[0] - 1)
    kept = np.flatnonzero(above)
    return int(kept[0]), int(kept[-1])


@pytest.mark.parametrize(
    "below, expected",
    [
        ("-TT-TTT-", (7, 3)),  # the longest run of bases below (4 .. 6) is left out: wraps
        ("TT---TTT", (2, 4)),  # the longest run crosses the last basis (5 .. 1)
        ("T-------", (1, 7)),
        ("--------", (0, 7)),  # none below: every basis
        ("TTTTTTTT", (0, 7)),  # all below (only by rounding): every basis
    ],
)
def test_circular_candidates_leave_out_the_longest_run_below_the_level(below, expected):
    """On a circle of 8 bases, the candidates are the shortest range holding every basis not
    proved below the level: all but the longest circular run of those below, written out
    (zero reach: basis j is below where -roots[j]^2 < level)."""
    module = response.kernels("phase", "von_mises")
    roots = np.array([2.0 if mark == "T" else 0.0 for mark in below])  # -4 or 0
    found = module.circular_candidates(roots, np.zeros(8), 0.0, -1.0)
    assert found == expected


@pytest.mark.parametrize("form, kernel", CANDIDATES)
@pytest.mark.parametrize("n_steps, dt", [(1500, 0.002), (60, 0.05)])
def test_the_candidate_bases_hold_every_kept_basis(form, kernel, n_steps, dt):
    """A discrete form's bases, and a rhythmic form's von Mises bases (continuous in the
    phase, as it wraps), are evaluated only among each step's candidates (proved by
    blocks: sqrt(-l) moves by at most sqrt(h) per unit of phase, as l'^2 <= 4 h |l|): at
    every sample and stage of the steps (small ones, and steps that each cross several
    bases, a block of one step each) the kept bases and the largest log-activation found
    among them equal those from every basis's log-activation (window's, with the level of
    level_of), checked at each point in turn; the candidates leave out some basis (the proof
    is not idle), and on the circle some candidate ranges and kept windows wrap past the last
    basis (the rhythmic windows are circular)."""
    centres, widths, target, gains, _ = _problem(form, kernel, n_basis=30)
    n_basis, periodic = centres.size, form not in DISCRETE
    # rhythmic: the energy form's phase atan2(v, x) wraps at pi within the 3 time units
    start = np.zeros(2) if form in DISCRETE else np.array([0.3, 1.2])
    module = response.kernels(form, kernel)
    first = response.first_level(n_basis)
    lowest, highest = np.empty(n_steps, dtype=np.int64), np.empty(n_steps, dtype=np.int64)
    module.candidates(start, dt, target, gains, centres, widths, first, lowest, highest)
    sizes = (highest - lowest) % n_basis + 1  # a range wraps where highest < lowest
    narrower = sizes < n_basis  # all but where the energy form's phase jumps
    assert np.all(narrower) if form in DISCRETE else np.any(narrower)
    assert np.any(highest < lowest) == periodic
    logs, slopes, seen = np.empty(n_basis), np.empty(n_basis), np.full(n_basis, -1)
    basis = module.basis_table(centres, widths)
    wrapped = 0
    for k, points in enumerate(_points(module, start, target, gains, n_steps, dt)):
        for s, point in enumerate(points):
            _, terms, terms_slope, _, _, top = module.window(
                point, target, gains, basis, widths, widths.max(), first, s == 0, logs
            )
            level = module.level_of(top, widths.max(), first, s == 0)
            expected = (*_kept_window(logs.copy(), level, periodic), top)
            found = module.candidate_window(terms, terms_slope, lowest[k], highest[k], basis,
                                            widths.max(), first, s == 0, logs, slopes, seen,
                                            0)  # fmt: skip
            assert found == expected
            wrapped += found[1] < found[0]
            if s == 0:  # the sample's slopes, from the evaluation that gave the logs
                for i in range(sizes[k]):
                    j = (lowest[k] + i) % n_basis
                    expected = module.log_activation_at(terms, terms_slope, basis, j)
                    assert (logs[j], slopes[j]) == expected
    assert (wrapped > 0) == periodic


def _exact_exp(x: float) -> "decimal.Decimal":
    """exp(x) to 50 digits (the decimal module's own algorithm)."""
    with decimal.localcontext() as context:
        context.prec = 50
        return decimal.Decimal(x).exp()


def _ulps(value: float, exact) -> float:
    """|value - exact| in units of the last place of ``value``."""
    return float(abs(decimal.Decimal(value) - exact) / decimal.Decimal(math.ulp(value)))


@settings(max_examples=300, deadline=None)
@given(st.floats(-511.0, 511.0))
def test_the_inlined_exp_is_within_its_error_bound(x):
    """The compiled table_exp (the normalisation's exp, the table algorithm of glibc 2.28+
    and Arm's optimized-routines) is within their stated 0.511 ulp of exp(x) (module
    docstring) on its range |x| < 512."""
    module = response.kernels("velocity", "gaussian")
    assert _ulps(module.table_exp(x), _exact_exp(x)) <= 0.511


def test_the_inlined_exp_table_holds_the_nearest_powers_of_two():
    """Entry i of the table: the bits of the float nearest 2**(i / 128), less i << 45, and its
    relative error, against 2**(i / 128) as exp(i ln 2 / 128) to 50 digits (another
    algorithm than the table's repeated products); exp(0) is 1 exactly."""
    module = response.kernels("velocity", "gaussian")
    with decimal.localcontext() as context:
        context.prec = 50
        for i in range(128):
            power = (decimal.Decimal(i) * decimal.Decimal(2).ln() / 128).exp()
            nearest = float(power)
            bits = int(np.float64(nearest).view(np.uint64)) - (i << 45)
            assert int(module.EXP_SCALES[i]) == bits
            assert module.EXP_TAILS[i] == float(
                (power - decimal.Decimal(nearest)) / decimal.Decimal(nearest)
            )
    assert module.table_exp(0.0) == 1.0 and module.table_exp(-0.0) == 1.0


def test_block_memory_is_reused_only_once_nothing_references_it():
    """A response's block memory is taken again once no array refers to it (a view of a view
    holds it too), never while one does; arrays of REUSED_BYTES and more are not kept."""
    first = response.block_memory(1000)
    first[:] = 1.0
    view = first.reshape(10, 100)[3:]
    del first
    held = response.block_memory(1000)
    assert not np.shares_memory(held, view)
    del view
    again = response.block_memory(900)
    assert again.shape == (900,) and again.flags.writeable
    assert any(np.shares_memory(again, owner) for owner in response._REUSED)
    assert not np.shares_memory(again, held)
    large = response.block_memory(response.REUSED_BYTES // 8)
    assert not any(np.shares_memory(large, owner) for owner in response._REUSED)


# answer keys (mutation run): each test below names the bound, size or rule it writes out


def test_the_first_level_leaves_at_most_half_an_epsilon_per_basis():
    """L_0 = ln(2 n / eps) (module docstring): n e^{-L_0} = eps / 2, to the rounding of log and
    exp (a few eps of L_0 ~ 40, so a relative 1e-13 here)."""
    for n_basis in (1, 30, 500):
        assert n_basis * math.exp(-response.first_level(n_basis)) == pytest.approx(
            EPS / 2, rel=1e-13, abs=0
        )


def test_the_generated_source_is_written_whole_into_a_new_nested_folder(tmp_path):
    """A cache folder whose parents do not exist yet is created with them; the file holds the
    source and no partial file is left."""
    folder = tmp_path / "a" / "b" / "generated"
    path = response._write(folder, "module", "x = 1\n")
    assert path == folder / "module.py" and path.read_text() == "x = 1\n"
    assert [p.name for p in folder.iterdir()] == ["module.py"]


@pytest.fixture
def no_idle_blocks(monkeypatch):
    """block_memory with an empty list of idle arrays (other tests leave theirs in it)."""
    monkeypatch.setattr(response, "_REUSED", [])


def test_block_memory_takes_an_idle_array_of_one_to_two_times_the_size(no_idle_blocks):
    """Written out: an idle array of 1000 numbers serves a request of 1000 (the same size) and
    of 500 (twice the size), not one of 499 (more than twice: a new array) nor one of 1001
    (too small)."""
    first = response.block_memory(1000)
    address = first.ctypes.data
    del first
    again = response.block_memory(1000)
    assert again.ctypes.data == address and again.shape == (1000,)
    del again
    half = response.block_memory(500)
    assert half.ctypes.data == address and half.shape == (500,)
    del half
    smaller = response.block_memory(499)
    assert smaller.ctypes.data != address
    del smaller
    larger = response.block_memory(1001)
    assert larger.ctypes.data != address


def test_block_memory_keeps_arrays_below_reused_bytes_only(no_idle_blocks):
    """An array of REUSED_BYTES less 8 is kept for reuse, one of REUSED_BYTES is not."""
    kept = response.block_memory(response.REUSED_BYTES // 8 - 1)
    assert len(response._REUSED) == 1 and np.shares_memory(kept, response._REUSED[0])
    response.block_memory(response.REUSED_BYTES // 8)
    assert len(response._REUSED) == 1


def _resident_pages(array) -> list:
    """Whether each page of a mapped array's memory is in RAM (Linux mincore(2))."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    page = mmap.PAGESIZE
    pages = -(-array.nbytes // page)
    vector = (ctypes.c_ubyte * pages)()
    status = libc.mincore(ctypes.c_void_p(array.ctypes.data), ctypes.c_size_t(pages * page), vector)
    assert status == 0, ctypes.get_errno()
    return [bool(v & 1) for v in vector]


@pytest.mark.skipif(not hasattr(mmap, "MAP_POPULATE"), reason="no populated mappings here")
def test_a_fresh_array_from_populated_bytes_on_is_mapped_in_ram_before_any_write():
    """Below POPULATED_BYTES an array is numpy's own; from it, a mapping of exactly its bytes
    whose every page is in RAM before anything is written (MAP_POPULATE; an anonymous
    mapping without it gets its pages at the first write to each)."""
    small = response.fresh_array((response.POPULATED_BYTES // 8 - 1,))
    assert small.flags.owndata
    for shape in [(response.POPULATED_BYTES // 8,), (3, 4000, 53)]:
        array = response.fresh_array(shape)
        assert not array.flags.owndata and array.shape == shape
        owner = array
        while isinstance(owner, np.ndarray):
            owner = owner.base
        assert memoryview(owner).nbytes == array.nbytes
        assert all(_resident_pages(array))
        assert not array.any()


def test_the_tail_start_is_the_least_held_split_of_random_plans():
    """Against the numbers held written out for every split k (head k x n_inputs, tail
    (n_steps - k) x (n_other + n_carrier x (bases it forces))), on random windows: the first
    least split, or n_steps where none holds fewer than the dense n_steps x n_inputs."""
    rng = np.random.default_rng(11)
    for _ in range(200):
        n_steps, n_basis = int(rng.integers(1, 12)), int(rng.integers(1, 8))
        n_other, n_carrier = int(rng.integers(1, 4)), int(rng.integers(1, 3))
        n_inputs = n_other + n_carrier * n_basis
        lows = rng.integers(0, n_basis, n_steps)
        highs = np.minimum(lows + rng.integers(0, 3, n_steps), n_basis - 1)
        held = [
            k * n_inputs
            + (n_steps - k) * (n_other + n_carrier * (max(highs[k:]) - min(lows[k:]) + 1))
            for k in range(n_steps)
        ]
        best = held.index(min(held))
        expected = best if held[best] < n_steps * n_inputs else n_steps
        assert response.tail_start(lows, highs, n_inputs, n_other, n_carrier) == expected


@pytest.mark.parametrize("form", ["velocity", "phase"])
def test_the_blocks_hold_the_segments_responses_and_nothing_else(form):
    """blocks holds 3 x steps x (n + 1 + window inputs) numbers per segment, back to back."""
    key = _default_plan_key(form)
    matrices = response.response_matrices(key)
    n1 = symbolic.n_transformation_states(form) + 1
    sizes = [3 * length * (n1 + width) for _, length, _, _, width in matrices.segments]
    assert len(sizes) > 2 and matrices.blocks.size == sum(sizes)
    assert matrices.segments[:, 2].tolist() == [sum(sizes[:t]) for t in range(len(sizes))]


def test_a_short_plan_of_one_segment_with_a_window_equals_the_stepwise_integration():
    """A plan too short to force every basis is one segment that keeps its window's columns
    and the others as a factor; its dense response times the inputs is the integration step
    by step (symbolic.simulate) within 4 n_steps eps, as in
    test_rollout_equals_the_stepwise_integration."""
    dmp = random_discrete(seed=5, n_basis=20, form="velocity")
    _, matrices, inputs = dmp._response_and_inputs(0.05, 0.001, None, np.zeros(2), (0.0, 0.0), True)
    assert len(matrices.segments) == 1 and matrices.segments[0, 4] < matrices.n_inputs - 3
    plan = np.einsum("rkc,cd->rkd", matrices.dense(), inputs)
    plan[1] /= dmp.tau
    plan[2] /= dmp.tau**2
    velocity = -dmp.forcing_weights() @ dmp._features((0.0, 0.0))
    initial = np.concatenate([(0.0, 0.0), dmp.start, velocity])
    stepped = symbolic.simulate(dmp.signature, plan.shape[1], initial, 0.001, dmp.parameters())
    for got, expected in zip(plan, stepped[1:]):
        bound = 4 * plan.shape[1] * EPS * np.abs(expected).max()
        np.testing.assert_allclose(got, expected, rtol=0, atol=bound)


def test_frozen_response_matrices_are_read_only():
    """freeze (the cached response is shared) makes blocks, segments and factors read-only."""
    dmp = random_discrete(seed=3, n_basis=10)
    matrices = response.response_matrices(_key(dmp, 0.2))
    matrices.freeze()
    for array in (matrices.blocks, matrices.segments, matrices.factors):
        assert not array.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            array.flat[0] = 0
