"""Bad inputs at every public DMP entry point: a named error, never a silently wrong result."""

from decimal import Decimal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from problems import minimum_jerk_demo, periodic_demo, random_discrete, random_rhythmic

from dmpopt import (
    InvalidInputError,
    ResourceLimitError,
    ShapeError,
    Trajectory,
    fit_discrete,
    fit_rhythmic,
    fit_to_accuracy,
    load,
    reproduction_error,
    save,
    validation,
)
from dmpopt.basis import discrete_basis
from dmpopt.fitting.imitation import estimate_period, periodicity_mismatch

DISCRETE = random_discrete()
RHYTHMIC = random_rhythmic()
DEMO = minimum_jerk_demo(n_dofs=2, n_steps=201)
PERIODIC = periodic_demo(n_steps=801)
TIMES = np.linspace(0.0, 1.0, 50)
RK4_REAL_LIMIT = 2.785293563405282  # |R(-h)| = 1 at h = 2.7853: RK4 on the negative real axis


def _trajectory_0dof():
    return Trajectory.from_positions(TIMES, np.zeros((50, 0)))


BAD_INPUTS = [
    # complex values lose their imaginary part if converted silently
    (lambda: Trajectory.from_positions(TIMES, np.sin(TIMES) + 1j), "positions is complex"),
    (lambda: Trajectory.from_positions(TIMES + 0j, TIMES), "times is complex"),
    (lambda: DISCRETE.with_goal(DISCRETE.goal + 1j), "goal is complex"),
    (lambda: DISCRETE.with_start([1j, 0.0]), "start is complex"),
    (lambda: DISCRETE.replace(weights=DISCRETE.weights + 1j), "weights is complex"),
    (lambda: RHYTHMIC.with_setpoint([1j, 0.0]), "setpoint is complex"),
    (lambda: RHYTHMIC.replace(weights=RHYTHMIC.weights + 0j), "weights is complex"),
    (lambda: DISCRETE.rollout(0.2, start_velocity=[1j, 0]), "start_velocity is complex"),
    (lambda: DISCRETE.stepper().set_goal([1j, 0.0]), "goal is complex"),
    (lambda: DISCRETE.stepper().step(coupling=[1j, 0.0]), "coupling is complex"),
    (lambda: RHYTHMIC.stepper(start=[0.0, 1j]), "start is complex"),
    (lambda: DISCRETE.with_tau(1 + 1j), "tau must be a real number"),
    # no DOF, no basis function
    (_trajectory_0dof, r"positions has shape \(50, 0\), expected \(50, n_dofs\) with n_dofs >= 1"),
    (
        lambda: DISCRETE.replace(
            weights=np.zeros((0, 20)), start=[], goal=[], reference_displacement=[]
        ),
        r"weights has shape \(0, 20\)",
    ),
    (lambda: DISCRETE.replace(weights=np.zeros((2, 0))), r"weights has shape \(2, 0\)"),
    # wrong types
    (lambda: DISCRETE.with_tau("1"), "tau must be a real number"),
    (lambda: DISCRETE.with_tau(None), "tau must be a real number"),
    (lambda: DISCRETE.with_tau(True), "tau must be a real number"),
    (lambda: DISCRETE.replace(alpha_z="25"), "alpha_z must be a real number"),
    (lambda: DISCRETE.rollout("1", 0.001), "duration must be a real number"),
    (lambda: DISCRETE.rollout(0.5, None), "dt must be a real number"),
    (lambda: DISCRETE.affine_plan(0.5, True), "dt must be a real number"),
    (lambda: DISCRETE.phase_features(10.5, 0.001), "n_steps must be an integer >= 1, got 10.5"),
    (lambda: DISCRETE.phase_features(10, 1.0), "dt = 1 s is beyond the stability limit"),
    (lambda: DISCRETE.stepper("0.001"), "dt must be a real number"),
    (lambda: DISCRETE.stepper(0.001, compile="no"), "compile must be True or False"),
    (lambda: DISCRETE.stepper().set_tau(None), "tau must be a real number"),
    (lambda: DISCRETE.stepper().step(canonical_coupling=None), "canonical_coupling must be"),
    (
        lambda: DISCRETE.stepper().step(coupling="ab"),
        "coupling must be an array of real numbers, got 'ab'",
    ),
    (lambda: DISCRETE.stepper().step(coupling=[np.nan, 0.0]), "coupling contains 1 NaN"),
    (lambda: RHYTHMIC.stepper().reset_phase(np.nan), "phase must be a finite number, got"),
    (lambda: RHYTHMIC.stepper().reset_phase(None), "phase must be a real number"),
    (lambda: RHYTHMIC.stepper().set_amplitude("2"), "amplitude must be a real number"),
    (lambda: RHYTHMIC.rollout(0.5, phase=np.inf), "phase must be a finite number, got"),
    (lambda: RHYTHMIC.with_amplitude(None), "amplitude must be a real number"),
    (
        lambda: Trajectory.from_positions(TIMES, TIMES > 0.5),
        "positions must be an array of real numbers, got booleans",
    ),
    (
        lambda: Trajectory.from_positions(None, None),
        "times must be an array of real numbers, got None",
    ),
    (lambda: Trajectory.from_positions(TIMES, TIMES, smoothing_window=7.5), "smoothing_window"),
    (lambda: DEMO.resampled("100"), "n_steps must be"),
    # fits
    (
        lambda: fit_discrete(DEMO, 10, regularization=-1e-3),
        "regularization must be a finite number >= 0, got -",
    ),
    (
        lambda: fit_discrete(DEMO, 10, regularization=np.nan),
        "regularization must be a finite number >= 0, got nan",
    ),
    (lambda: fit_discrete(DEMO, 10, regularization="1e-9"), "regularization must be a real"),
    (
        lambda: fit_rhythmic(PERIODIC, 8, regularization=-1.0),
        "regularization must be a finite number >= 0, got -",
    ),
    (lambda: fit_discrete(DEMO, 300), "n_basis = 300 gives 300 weights per DOF but demo has"),
    (lambda: fit_rhythmic(PERIODIC, 401), "n_basis = 401 gives 802 weights per DOF"),
    (lambda: fit_rhythmic(PERIODIC, 8, period="0.8"), "period must be a real number"),
    (lambda: fit_rhythmic(PERIODIC, 8, amplitude=None), "amplitude must be a real number"),
    (
        lambda: fit_rhythmic(PERIODIC, 8, warm_up_periods=-1),
        "warm_up_periods must be an integer >= 0, got -1",
    ),
    (lambda: fit_rhythmic(PERIODIC, 8, warm_up_periods=np.nan), "warm_up_periods must be"),
    (lambda: fit_to_accuracy(DEMO, "0.1"), "tolerance must be a real number"),
    (lambda: fit_to_accuracy(DEMO, np.inf), "tolerance must be a finite number > 0, got inf"),
    (lambda: fit_to_accuracy(DEMO, 0.1, candidates=()), "candidates is empty"),
    (lambda: fit_to_accuracy(DEMO, 0.1, candidates="ab"), "candidates must be a sequence"),
    (lambda: fit_to_accuracy(DEMO, 0.1, rhythmic="yes"), "rhythmic must be True or False"),
    (lambda: reproduction_error(None, DEMO), "dmp must be a DiscreteDMP or RhythmicDMP"),
    (lambda: reproduction_error(random_discrete(n_dofs=1), DEMO), "demo has 2 DOFs but dmp has 1"),
    (lambda: estimate_period(PERIODIC.positions), "demo must be a Trajectory"),
    # files
    (lambda: save(DISCRETE, None), "path must be a str or os.PathLike"),
    (lambda: load(None), "path must be a str or os.PathLike"),
    (lambda: save(DISCRETE, "/nonexistent-folder/x"), "folder /nonexistent-folder does not"),
]


@pytest.mark.parametrize("call, message", BAD_INPUTS)
def test_bad_input_is_a_named_error(call, message):
    """Every bad value raises the library's error (also a ValueError) naming the argument."""
    with pytest.raises((InvalidInputError, ShapeError), match=message):
        call()


# -- stability of the integration --------------------------------------------------------


def _plain_rk4_growth(alpha_z, beta_z, tau, dt, n_steps=2000):
    """|state| after n_steps RK4 steps of tau (y, z)' = (z, a (b (0 - y) - z)) from (1, 0)."""
    matrix = np.array([[0.0, 1.0], [-alpha_z * beta_z, -alpha_z]]) / tau
    state = np.array([1.0, 0.0])
    for _ in range(n_steps):
        k1 = matrix @ state
        k2 = matrix @ (state + dt / 2 * k1)
        k3 = matrix @ (state + dt / 2 * k2)
        k4 = matrix @ (state + dt * k3)
        state = state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return np.linalg.norm(state)


@pytest.mark.parametrize("alpha_z, alpha_v", [(25.0, 25.0), (100.0, 25.0), (10.0, 60.0)])
def test_max_step_is_the_rk4_limit_of_the_fastest_mode(alpha_z, alpha_v):
    """Critically damped modes sit at -alpha / (2 tau): the limit is 2.7853 tau / (alpha / 2)."""
    dmp = random_discrete(alpha_z=alpha_z, alpha_v=alpha_v)
    fastest = max(alpha_z, alpha_v) / 2
    assert dmp.max_step == pytest.approx(RK4_REAL_LIMIT * dmp.tau / fastest, rel=1e-9)
    if alpha_z >= alpha_v:  # answer key: a plain RK4 of the transformation system
        assert _plain_rk4_growth(alpha_z, alpha_z / 4, 0.4, 0.98 * dmp.max_step) < 1.0
        assert _plain_rk4_growth(alpha_z, alpha_z / 4, 0.4, 1.02 * dmp.max_step) > 1e3


@pytest.mark.parametrize("dmp", [random_discrete(), random_discrete(form="acceleration"), RHYTHMIC])
def test_steps_beyond_the_stability_limit_are_refused(dmp):
    limit = dmp.max_step
    for make in (dmp.stepper, lambda dt: dmp.rollout(20 * limit, dt)):
        with pytest.raises(
            InvalidInputError, match=f"dt = .* beyond the stability limit {limit:.4g}"
        ):
            make(1.01 * limit)
        make(0.99 * limit)


def test_phase_oscillator_limit_comes_from_the_transformation_system():
    """Eigenvalues -12.5 / tau (double, eq. (5)), -10 / tau (amplitude, eq. (11)) and 0."""
    assert RHYTHMIC.max_step == pytest.approx(RK4_REAL_LIMIT * RHYTHMIC.tau / 12.5)


def test_tau_change_that_makes_the_step_unstable_is_refused():
    """Stable is not accurate: just inside the limit the plan still converges to the goal."""
    stepper = DISCRETE.stepper(0.01)  # limit 0.4 * 2.785 / 12.5 = 0.089 s
    shortest = 0.01 * 12.5 / RK4_REAL_LIMIT  # the tau at which 0.01 s is the limit
    with pytest.raises(InvalidInputError, match="tau = 0.04 s puts the step dt = 0.01"):
        stepper.set_tau(0.04)
    stepper.set_tau(1.01 * shortest)
    for _ in range(20000):
        position, _, _ = stepper.step()
    np.testing.assert_allclose(position, DISCRETE.goal, atol=1e-6)


def test_stable_energy_oscillator_stays_on_its_cycle():
    """At peak speed v = k A (x = 0) eq. (13) linearises to [[0, 1], [-k^2, -alpha_E v^2]]:
    its fast eigenvalue, the pull back onto the cycle, sets the limit."""
    dmp = random_rhythmic(form="energy", amplitude=3.0, k=2.0)
    fast = (10.0 * 36.0 + np.sqrt((10.0 * 36.0) ** 2 - 4 * 4.0)) / 2
    assert dmp.max_step == pytest.approx(RK4_REAL_LIMIT * dmp.tau / fast, rel=1e-9)
    stepper = dmp.stepper(0.99 * dmp.max_step)
    for _ in range(5000):
        stepper.step()
    energy = 0.5 * (stepper.state[1] ** 2 + 4.0 * stepper.state[0] ** 2)
    assert energy == pytest.approx(0.5 * (2.0 * 3.0) ** 2, rel=1e-3)


# -- resource bounds ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "call",
    [
        lambda: DISCRETE.rollout(1.0, 1e-7),
        lambda: DISCRETE.rollout(1e4, 0.001),
        lambda: DISCRETE.with_tau(1e9).rollout(),
        lambda: RHYTHMIC.with_tau(1e9).affine_plan(),
        lambda: DEMO.resampled(10**9),
    ],
)
def test_requests_beyond_the_sample_bound_are_refused_up_front(call):
    with pytest.raises(ResourceLimitError, match="dmpopt.validation.MAX_SAMPLES"):
        call()


def test_memory_budget_is_checked_before_allocating(monkeypatch):
    """A 1001-sample plan of 23 inputs needs > 1 MB: refused under a 1 MB budget."""
    monkeypatch.setattr(validation, "MEMORY_BUDGET", 1e6)
    with pytest.raises(ResourceLimitError, match=r"a plan of 1 s at dt = 0.001 s needs 1e\+03"):
        DISCRETE.rollout(1.0, 0.001)


# -- one basis function, periodicity ------------------------------------------------------


def test_one_basis_function_is_the_phase_velocity():
    """One basis: its normalised activation is 1, so its feature is v of eq. (6), which from
    rest is v(s) = (alpha_v / 2)^2 s exp(-alpha_v s / 2) at s = t / tau (beta_v = alpha_v / 4).
    """
    centres, widths = discrete_basis(1, (25.0, 6.25, 25.0, 6.25))
    assert centres.shape == widths.shape == (1,)
    dmp = random_discrete(n_basis=1, centres=centres, widths=widths, weights=[[40.0], [-25.0]])
    s = np.arange(1000) * 0.001 / dmp.tau
    v = 12.5**2 * s * np.exp(-12.5 * s)
    np.testing.assert_allclose(dmp.phase_features(1000, 0.001)[:, 0], v, atol=1e-7)
    fitted = fit_discrete(DEMO, 1)
    assert fitted.weights.shape == (2, 1) and np.all(np.isfinite(fitted.rollout().positions))


def _drifting_sine(drift, period=0.8, duration=2.0, n_steps=801):
    times = np.linspace(0.0, duration, n_steps)
    return Trajectory.from_positions(times, np.sin(2 * np.pi * times / period) + drift * times)


def test_periodicity_mismatch_of_a_drifting_sine():
    """y = sin(2 pi t / P) + c t repeats after P up to c P everywhere: RMS c P / ptp(y)."""
    demo = _drifting_sine(0.3)
    position, velocity = periodicity_mismatch(demo, 0.8)
    assert position == pytest.approx(0.3 * 0.8 / np.ptp(demo.positions), rel=1e-6)
    assert velocity < 1e-3  # the velocity 2 pi / P cos(.) + c does repeat
    assert max(periodicity_mismatch(PERIODIC, 0.8)) < 1e-3


def test_non_periodic_demo_is_refused_with_the_numbers():
    drifting = _drifting_sine(0.3)
    expected = f"{0.3 * 0.8 / np.ptp(drifting.positions):.2%}"
    with pytest.raises(InvalidInputError, match=f"positions differ by {expected} .* above"):
        fit_rhythmic(drifting, 15, period=0.8)
    one_cycle_and_a_jump = _drifting_sine(0.0, duration=0.8, n_steps=401)
    positions = one_cycle_and_a_jump.positions + (one_cycle_and_a_jump.times > 0.7)[:, None]
    jumping = Trajectory.from_positions(one_cycle_and_a_jump.times, positions)
    with pytest.raises(InvalidInputError, match="is not periodic with period 0.8"):
        fit_rhythmic(jumping, 15, period=0.8)
    fit_rhythmic(_drifting_sine(0.3), 15, period=0.8, periodicity_tolerance=np.inf)
    fit_rhythmic(_drifting_sine(0.0), 15, period=0.8)


def test_fit_beyond_the_memory_budget_is_refused_before_any_work(monkeypatch):
    """The regressors alone take 201 x 30 x 8 bytes = 48 kB: refused under a 40 kB budget."""
    monkeypatch.setattr(validation, "MEMORY_BUDGET", 4e4)
    with pytest.raises(ResourceLimitError, match="a fit of 30 basis functions to 201 samples"):
        fit_discrete(DEMO, 30)


def test_reproduction_error_of_a_non_uniform_demo_compares_equal_times():
    """A DMP's own plan sampled on a non-uniform grid reproduces itself to interpolation error."""
    dmp = random_discrete(seed=2)
    plan = dmp.rollout(1.0, 0.001)
    keep = np.r_[0:500:5, 500:1001]  # coarse then fine
    demo = Trajectory(
        plan.times[keep], *(a[keep] for a in (plan.positions, plan.velocities, plan.accelerations))
    )
    assert reproduction_error(dmp, demo) < 1e-3 * np.ptp(plan.positions)


def test_a_dof_at_rest_beside_a_periodic_one_is_periodic():
    """Mismatch is relative to the largest extent: rounding on a constant DOF does not count."""
    demo = _drifting_sine(0.0)
    beside = Trajectory.from_positions(demo.times, np.c_[demo.positions, np.full(801, 0.3)])
    assert max(periodicity_mismatch(beside, 0.8)) < 1e-3
    fit_rhythmic(beside, 15, period=0.8)


# The checks themselves: each answer key is the rule written plainly.

NOT_REAL = [True, np.bool_(False), "1.5", b"1", None, 1 + 0j, [1.0], np.array([1.0])]


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(allow_nan=True, allow_infinity=True),
    low=st.floats(-10, 10),
    width=st.floats(0, 10),
    open_minimum=st.booleans(),
)
def test_real_accepts_exactly_the_finite_numbers_within_the_bounds(x, low, width, open_minimum):
    high = low + width
    inside = np.isfinite(x) and (x > low if open_minimum else x >= low) and x <= high
    if inside:
        assert validation.real("gain", x, minimum=low, maximum=high, open_minimum=open_minimum) == x
    else:
        with pytest.raises(
            InvalidInputError,
            match=f"^gain must be a finite number {'>' if open_minimum else '>='} ",
        ):
            validation.real("gain", x, minimum=low, maximum=high, open_minimum=open_minimum)


@pytest.mark.parametrize("value", NOT_REAL, ids=repr)
def test_real_refuses_what_float_would_silently_convert(value):
    with pytest.raises(
        InvalidInputError, match=r"^gain must be a real number \(a finite number >= 0\), got "
    ):
        validation.real("gain", value, minimum=0.0, fix="e.g. 0.5")


def test_real_states_the_expected_value_infinity_and_the_fix():
    assert validation.real("bound", np.inf, finite=False) == np.inf
    assert validation.real("bound", np.array(2)) == 2.0
    assert validation.real("bound", Decimal("0.5")) == 0.5
    with pytest.raises(
        InvalidInputError, match=r"^bound must be a height \[m\], got nan; raise it$"
    ):
        validation.real("bound", np.nan, finite=False, expected="a height [m]", fix="raise it")


@pytest.mark.parametrize("value, result", [(3, 3), (np.int64(4), 4), (5.0, 5), (np.float32(6), 6)])
def test_integer_accepts_integral_values(value, result):
    number = validation.integer("n_basis", value, minimum=1)
    assert number == result and type(number) is int


@pytest.mark.parametrize("value", [0, 2.5, True, "3", None, np.nan, 1j, [3]], ids=repr)
def test_integer_refuses_non_integers_and_values_below_the_minimum(value):
    with pytest.raises(InvalidInputError, match=r"^n_basis must be an integer >= 1, got "):
        validation.integer("n_basis", value, minimum=1)


def test_integer_above_its_bound_is_a_resource_error_with_the_fix():
    assert validation.integer("n", 10, minimum=1, maximum=10) == 10
    with pytest.raises(ResourceLimitError, match=r"^n = 11 exceeds the bound 10 .*; use fewer$"):
        validation.integer("n", 11, minimum=1, maximum=10, fix="use fewer")


BAD_ARRAYS = [
    # (value, keyword arguments, error, message)
    ([1.0, 2j], {}, InvalidInputError, r"^x is complex; .*\(np\.real\)"),
    ([True, False], {}, InvalidInputError, r"^x must be an array of real numbers, got booleans"),
    ("ab", {}, InvalidInputError, r"^x must be an array of real numbers, got 'ab'"),
    (None, {}, InvalidInputError, r"^x must be an array of real numbers, got None"),
    ([[1.0], [1.0, 2.0]], {}, ShapeError, r"^x must be a regular array of real numbers"),
    ([1.0, 2.0], {"ndim": 2}, ShapeError, r"^x has shape \(2,\), expected 2 dimension"),
    ([1.0, 2.0], {"shape": (3,)}, ShapeError, r"^x has shape \(2,\), expected \(3,\)"),
    ([], {}, ShapeError, r"^x is empty \(shape \(0,\)\)"),
    (
        [[0.0, 1.0], [2.0, np.inf]],
        {},
        InvalidInputError,
        r"^x\[1, 1\] is inf: x contains 1 NaN or infinite value\(s\); clean",
    ),
    (
        [0.0, np.nan, np.nan],
        {"labels": ["a", "b", "c"], "fix": "drop them"},
        InvalidInputError,
        r"^x\[1\] \(b\) is nan: x contains 2 NaN or infinite value\(s\); drop them$",
    ),
]


@pytest.mark.parametrize("value, keywords, error, message", BAD_ARRAYS)
def test_real_array_names_the_argument_and_the_fault(value, keywords, error, message):
    with pytest.raises(error, match=message):
        validation.real_array("x", value, **keywords)


def test_real_array_returns_a_new_float_array():
    source = np.arange(3)
    array = validation.real_array("x", source, shape=(3,))
    array[0] = 7.0
    assert array.dtype == float and source[0] == 0
    assert validation.real_array("x", [], empty=True).shape == (0,)
    assert validation.real_array("x", np.zeros(0), shape=(0,)).shape == (0,)


def test_sequence_of_wants_an_iterable_of_the_kind():
    assert validation.sequence_of("points", [1, 2], int) == (1, 2)
    with pytest.raises(InvalidInputError, match=r"^points must be a sequence of int, got a single"):
        validation.sequence_of("points", 1, int)
    with pytest.raises(InvalidInputError, match=r"^points must be a sequence of int, got NoneType"):
        validation.sequence_of("points", None, int)
    with pytest.raises(InvalidInputError, match=r"^points\[1\] must be a int, got str"):
        validation.sequence_of("points", [1, "2"], int)


def test_check_resources_has_one_budget_in_bytes_and_one_sample_bound():
    validation.check_resources("a request", validation.MEMORY_BUDGET, "shrink it")
    validation.check_resources("a request", 1.0, "shrink it", n_samples=validation.MAX_SAMPLES)
    for n_bytes, n_samples in [
        (validation.MEMORY_BUDGET + 1, None),
        (np.nan, None),
        (1.0, validation.MAX_SAMPLES + 1),
    ]:
        with pytest.raises(
            ResourceLimitError, match=r"^a request needs .*MEMORY_BUDGET\): shrink it$"
        ):
            validation.check_resources("a request", n_bytes, "shrink it", n_samples=n_samples)
