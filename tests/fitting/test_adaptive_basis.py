"""Automatic choice of the number and widths of the basis functions (fit_adaptive)."""

import numpy as np
import pytest
from problems import minimum_jerk_demo

from dmpopt import InvalidInputError, Trajectory, fit_discrete, reproduction_error
from dmpopt.basis import discrete_basis
from dmpopt.fitting import adaptive_basis
from dmpopt.fitting.adaptive_basis import _numbers, fit_adaptive

DEMO = minimum_jerk_demo(n_dofs=2, n_steps=401)


def _curve(n_steps=401, noise=0.0, seed=0):
    """A planar stroke with a bend (a minimum-jerk base plus a bump), optional noise."""
    times = np.linspace(0.0, 1.0, n_steps)
    s = 10 * times**3 - 15 * times**4 + 6 * times**5
    positions = np.c_[s, 0.5 * s + 0.4 * np.sin(np.pi * s) ** 2]
    rng = np.random.default_rng(seed)
    positions = positions + noise * rng.normal(size=positions.shape)
    positions[[0, -1]] = [[0.0, 0.0], [1.0, 0.5]]
    return Trajectory.from_positions(times, positions)


@pytest.mark.parametrize("method", ["position", "least_squares", "lwr"])
def test_one_layout_gives_fit_discrete(method):
    """Answer key: fit_discrete's own regression. With one candidate number and the width
    factor 1, the chosen DMP is fit_discrete's, weights and all."""
    choice = fit_adaptive(
        DEMO, 1e-30, method=method, width_scales=(1.0,), min_basis=12, max_basis=12
    )
    expected = fit_discrete(DEMO, 12, method=method)
    assert choice.n_basis == 12 and choice.stopped == "max_basis"
    np.testing.assert_allclose(
        choice.dmp.weights, expected.weights, rtol=1e-9, atol=1e-9 * np.abs(expected.weights).max()
    )
    np.testing.assert_allclose(choice.dmp.widths, expected.widths)


def test_width_factor_scales_the_default_widths():
    choice = fit_adaptive(DEMO, 1e-30, width_scales=(3.0,), min_basis=9, max_basis=9)
    centres, widths = discrete_basis(9, (25.0, 6.25, 25.0, 6.25))
    np.testing.assert_allclose(choice.dmp.centres, centres)
    np.testing.assert_allclose(choice.dmp.widths, 3.0 * widths)


def test_stops_at_the_first_number_that_meets_the_tolerance():
    """The choice is the first number in the growth sequence whose best validation error is
    within the tolerance; every number before it was above."""
    demo = _curve()
    choice = fit_adaptive(demo, 1e-3, growth=1.5)
    assert choice.stopped == "tolerance" and choice.validation_error <= 1e-3
    tried = sorted({n for n, _, _ in choice.history})
    assert tried == _numbers(5, 200, 1.5)[: len(tried)] and tried[-1] == choice.n_basis
    for n in tried[:-1]:
        assert min(e for m, _, e in choice.history if m == n) > 1e-3
    best = min((e, s) for m, s, e in choice.history if m == choice.n_basis)
    assert (choice.validation_error, choice.width_scale) == best
    # the fit to all samples is at least as close to the demo as the held-out score says
    assert reproduction_error(choice.dmp, demo) <= 1.5 * choice.validation_error


def test_widths_found_by_descent_are_a_local_minimum():
    choice = fit_adaptive(_curve(), 1e-4, method="lwr", max_basis=60)
    errors = {s: e for n, s, e in choice.history if n == choice.n_basis}
    chosen = errors[choice.width_scale]
    assert all(chosen <= e for e in errors.values())
    assert len(errors) >= 2  # a neighbour was tried


def test_noise_floor_stops_growth():
    """Answer key: white noise of standard deviation sigma per axis on held-out samples
    cannot be predicted, so the validation error cannot fall below about sigma * sqrt(2);
    growth stops for lack of improvement, well before max_basis."""
    sigma = 0.01
    choice = fit_adaptive(_curve(noise=sigma, seed=1), 1e-6)
    assert choice.stopped == "no improvement"
    assert choice.n_basis < 100
    tried = sorted({n for n, _, _ in choice.history})
    assert tried[-3] == choice.n_basis  # two more numbers tried without enough improvement
    assert 0.8 * sigma * np.sqrt(2) <= choice.validation_error <= 1.3 * sigma * np.sqrt(2)


@pytest.mark.parametrize("goal_scaling", ["auto", "paper"])
def test_chosen_dmp_generalises_like_the_scaling_promises(goal_scaling):
    """Weights stored per unit of the goal map: a new goal maps the plan by rotation and
    uniform scaling (auto: rotation here) or per axis (paper), as written out here."""
    demo = _curve()
    choice = fit_adaptive(demo, 1e-3, goal_scaling=goal_scaling)
    start, goal = demo.positions[0], demo.positions[-1]
    new_goal = np.array([1.3, 0.6])
    plan = choice.dmp.rollout(1.0, 0.0025).positions
    moved = choice.dmp.with_goal(new_goal).rollout(1.0, 0.0025).positions
    if goal_scaling == "paper":
        expected = start + (plan - start) * (new_goal - start) / (goal - start)
    else:
        d, e = complex(*(goal - start)), complex(*(new_goal - start))
        z = complex(1, 0) * (plan[:, 0] - start[0]) + 1j * (plan[:, 1] - start[1])
        z = z * e / d
        expected = start + np.c_[z.real, z.imag]
    np.testing.assert_allclose(moved, expected, atol=1e-9)
    assert reproduction_error(choice.dmp, demo) <= 2e-3  # the stored weights reproduce it


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: fit_adaptive(DEMO, 0.0), "tolerance must be a finite number > 0"),
        (lambda: fit_adaptive(DEMO, "0.1"), "tolerance must be a real number"),
        (lambda: fit_adaptive(DEMO, 0.1, width_scales=()), "width_scales is empty"),
        (lambda: fit_adaptive(DEMO, 0.1, width_scales="ab"), "width_scales must be a sequence"),
        (lambda: fit_adaptive(DEMO, 0.1, width_scales=(2.0, 1.0)), "width_scales must be sorted"),
        (lambda: fit_adaptive(DEMO, 0.1, width_scales=(-1.0,)), "width_scales must be"),
        (lambda: fit_adaptive(DEMO, 0.1, min_basis=0), "n_basis must be"),
        (lambda: fit_adaptive(DEMO, 0.1, min_basis=20, max_basis=10), "max_basis must be"),
        (lambda: fit_adaptive(DEMO, 0.1, max_basis=300), "max_basis = 300 exceeds the 201"),
        (lambda: fit_adaptive(DEMO, 0.1, growth=1.0), "growth must be a finite number > 1"),
        (lambda: fit_adaptive(DEMO, 0.1, min_improvement=1.0), "min_improvement must be below"),
        (lambda: fit_adaptive(DEMO, 0.1, min_improvement=-0.1), "min_improvement must be"),
        (lambda: fit_adaptive(DEMO, 0.1, method="lwpr"), "method must be one of"),
        (lambda: fit_adaptive(DEMO.positions, 0.1), "demo must be a Trajectory"),
        (
            lambda: fit_adaptive(Trajectory.from_positions(np.arange(5.0), np.arange(5.0)), 1.0),
            "demo has 5 samples",
        ),
    ],
)
def test_bad_input_is_refused_with_the_argument_named(call, match):
    with pytest.raises(InvalidInputError, match=match):
        call()


# ---------------------------------------------------------------- the search, on a known landscape
SCALES = tuple(2.0**k for k in range(-3, 4))  # 1/8 ... 8, the factor 1 at index 3


def _scripted(monkeypatch, landscape):
    """Replace the held-out score by ``landscape(n_basis, width_scale)`` and record the
    calls: the growth and width logic then runs on errors known in advance."""
    calls = []

    def score(self, n_basis, scale, train):
        calls.append((n_basis, scale))
        return landscape(n_basis, scale)

    monkeypatch.setattr(adaptive_basis._Demo, "validation_error", score)
    return calls


@pytest.mark.parametrize("best", [0, 1, 2, 3, 4, 5, 6])
def test_width_descent_from_the_factor_one_reaches_the_minimum(monkeypatch, best):
    """A unimodal landscape over the factors, lowest at index ``best``: the descent starts at
    the factor 1, tries both of its neighbours, walks one factor at a time towards the
    minimum (each step to the better neighbour) and stops there, having tried exactly the
    factors from the start to one past the minimum."""
    calls = _scripted(monkeypatch, lambda n, s: 1.0 + (np.log2(s) + 3 - best) ** 2)
    choice = fit_adaptive(DEMO, 1e-9, width_scales=SCALES, min_basis=8, max_basis=8)
    assert choice.width_scale == SCALES[best] and choice.validation_error == 1.0
    low, high = min(best, 3), max(best, 3)
    tried = set(range(max(low - 1, 0), min(high + 1, 6) + 1))
    assert {SCALES.index(s) for _, s in calls} == tried


def test_width_descent_takes_the_better_of_two_falling_neighbours(monkeypatch):
    """Both neighbours of the factor 1 are lower; the lower one (above) wins."""
    errors = {0.125: 9.0, 0.25: 8.0, 0.5: 1.5, 1.0: 2.0, 2.0: 1.2, 4.0: 1.4, 8.0: 9.0}
    _scripted(monkeypatch, lambda n, s: errors[s])
    choice = fit_adaptive(DEMO, 1e-9, width_scales=SCALES, min_basis=8, max_basis=8)
    assert choice.width_scale == 2.0


def test_growth_follows_the_documented_defaults(monkeypatch):
    """Defaults: 5 basis functions first, 1.5 times more each step (rounded up), up to 200;
    an error that falls by 10 % per step never stalls, so every number is tried."""
    calls = _scripted(monkeypatch, lambda n, s: 0.9**n * (1.0 + abs(np.log2(s))))
    choice = fit_adaptive(_curve(n_steps=399), 1e-30)  # 200 training rows
    numbers = [5, 8, 12, 18, 27, 41, 62, 93, 140, 200]
    assert sorted({n for n, _ in calls}) == numbers
    assert (choice.n_basis, choice.width_scale, choice.stopped) == (200, 1.0, "max_basis")


def test_growth_by_a_factor_near_one_adds_one_basis_function(monkeypatch):
    calls = _scripted(monkeypatch, lambda n, s: 1.0 / n)
    fit_adaptive(DEMO, 1e-30, width_scales=(1.0,), min_basis=5, max_basis=9, growth=1.01)
    assert [n for n, _ in calls] == [5, 6, 7, 8, 9]


@pytest.mark.parametrize(
    "errors, min_improvement, stopped, chosen",
    [
        # each step lowers the best by 1 % < 2 %: two stale steps end growth at the first
        ({5: 1.0, 8: 0.99, 12: 0.985, 18: 0.1}, 0.02, "no improvement", 5),
        # one stale step, then a real improvement: growth goes on
        ({5: 1.0, 8: 0.99, 12: 0.5, 18: 0.495, 27: 0.494}, 0.02, "no improvement", 12),
        # an equal error lowers the best by 0 %, enough for min_improvement = 0
        ({5: 1.0, 8: 1.0, 12: 1.0, 18: 0.2}, 0.0, "tolerance", 18),
        # exactly at the tolerance (0.2) stops growth
        ({5: 1.0, 8: 0.5, 12: 0.2, 18: 0.01}, 0.02, "tolerance", 12),
    ],
)
def test_growth_stops_as_documented(monkeypatch, errors, min_improvement, stopped, chosen):
    _scripted(monkeypatch, lambda n, s: errors[n])
    choice = fit_adaptive(
        DEMO, 0.2, width_scales=(1.0,), max_basis=27, min_improvement=min_improvement
    )
    assert (choice.stopped, choice.n_basis, choice.validation_error) == (
        stopped,
        chosen,
        errors[chosen],
    )


# ---------------------------------------------------------------- what the fits are trained on
def test_held_out_samples_are_the_odd_ones():
    """An outlier of 1 at odd sample 201 of a demo the layout fits closely: held out, it is
    the validation error alone, 1 / sqrt(200) (200 held-out samples), and it leaves the
    fit untouched."""
    demo = minimum_jerk_demo(n_dofs=1, n_steps=401)
    positions = demo.positions.copy()
    positions[201] += 1.0
    spiked = Trajectory(demo.times, positions, demo.velocities, demo.accelerations)
    choice = fit_adaptive(spiked, 1e-9, width_scales=(1.0,), min_basis=15, max_basis=15)
    assert choice.validation_error == pytest.approx(1.0 / np.sqrt(200), rel=1e-3)


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
@pytest.mark.parametrize("method", ["position", "least_squares", "lwr"])
def test_one_layout_gives_fit_discrete_for_every_option(form, method):
    """As test_one_layout_gives_fit_discrete, for a demo that starts moving, both forms and
    gains other than the defaults."""
    demo = _curve()
    moving = Trajectory.from_positions(demo.times[50:] - demo.times[50], demo.positions[50:])
    options = dict(method=method, form=form, alpha_z=16.0, alpha_v=12.0, regularization=1e-6)
    choice = fit_adaptive(moving, 1e-30, width_scales=(1.0,), min_basis=9, max_basis=9, **options)
    expected = fit_discrete(moving, 9, **options)
    assert (choice.dmp.form, choice.dmp.alpha_z, choice.dmp.alpha_v) == (form, 16.0, 12.0)
    scale = np.abs(expected.weights).max()
    np.testing.assert_allclose(choice.dmp.weights, expected.weights, rtol=1e-9, atol=1e-9 * scale)
    np.testing.assert_allclose(choice.dmp.start_velocity, moving.velocities[0], rtol=1e-12)


def test_short_demos_down_to_six_samples():
    """Six samples: four train (0, 2, 4 and the last), two are held out; max_basis may equal
    the training rows. A 20-sample demo fits from 5 basis functions (fewer than the 30 of
    fit_discrete's default)."""
    six = minimum_jerk_demo(n_dofs=1, n_steps=6)
    choice = fit_adaptive(six, 1e-30, width_scales=(1.0,), min_basis=4, max_basis=4)
    assert choice.n_basis == 4
    twenty = minimum_jerk_demo(n_dofs=1, n_steps=20)
    assert fit_adaptive(twenty, 1e-30, width_scales=(1.0,), max_basis=8).n_basis <= 8


@pytest.mark.parametrize(
    "scales, match",
    [
        ((0.0, 1.0), "width_scales must be a finite number > 0, got 0.0"),
        ((1.0, 1.0), r"width_scales must be sorted ascending without repeats, got \(1.0, 1.0\)"),
    ],
)
def test_width_scales_are_positive_and_distinct(scales, match):
    with pytest.raises(InvalidInputError, match=match):
        fit_adaptive(DEMO, 0.1, width_scales=scales)
