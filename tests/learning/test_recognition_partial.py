"""Tests of dmpopt.recognition.partial: partial observations and first_part."""

import numpy as np
import pytest
from recognition_shapes import N_BASIS, _moved, _raises, _shape, _synthetic_set

from dmpopt import Trajectory, fit_discrete
from dmpopt.exceptions import InvalidInputError
from dmpopt.recognition import (
    PartialObservationClassifier,
    first_part,
)


def test_partial_observation_recognised():
    """The first half of a transformed stroke is matched to the right kind."""
    demos, labels = _synthetic_set(n_per_class=2)
    classifier = PartialObservationClassifier().fit(
        [fit_discrete(d, N_BASIS) for d in demos], labels
    )
    for kind in range(3):
        observation = first_part(_moved(_shape(kind), angle=0.0), 0.5)
        assert classifier.predict([observation])[0] == f"kind{kind}"
    residuals, fractions = classifier.match(first_part(_shape(1), 0.5))
    assert residuals.shape == fractions.shape == (6,)
    assert np.all(residuals >= -1e-12) and np.all(residuals <= 1 + 1e-12)


def test_partial_observation_rotation_option():
    """With rotation=True a rotated observation fits its plan as well as the original."""
    dmp = fit_discrete(_shape(2), N_BASIS)
    classifier = PartialObservationClassifier(rotation=True).fit([dmp], ["kind2"])
    plain = classifier.match(first_part(_shape(2), 0.5))[0]
    rotated = classifier.match(first_part(_moved(_shape(2), angle=2.0), 0.5))[0]
    assert np.allclose(rotated, plain, atol=1e-9)


def test_first_part_keeps_the_beginning(demo):
    """first_part keeps the samples of the first fraction of the duration."""
    half = first_part(demo, 0.5)
    assert half.times[-1] <= demo.times[0] + 0.5 * demo.duration + 1e-12
    assert half.n_steps == np.count_nonzero(demo.times <= 0.5 + 1e-12)


def test_error_partial_inputs(dmp, demo):
    """The partial classifier checks fractions and observations."""
    with _raises(
        InvalidInputError, "fractions must be a non-empty list of numbers in (0, 1], got (0.5, 1.5)"
    ):
        PartialObservationClassifier(fractions=(0.5, 1.5)).fit([dmp], ["a"])
    classifier = PartialObservationClassifier().fit([dmp], ["a"])
    with _raises(
        InvalidInputError,
        "observation must be a Trajectory, got ndarray; build one "
        "with Trajectory.from_positions(times, positions)",
    ):
        classifier.match(np.zeros((10, 2)))
    still = Trajectory.from_positions(np.arange(5.0), np.ones((5, 2)))
    with _raises(InvalidInputError, "observation does not move, so it matches every shape"):
        classifier.match(still)
    with _raises(InvalidInputError, "fraction must be a finite number > 0 and <= 1, got 0.0"):
        first_part(demo, 0.0)


def _best_similarity_fit(template, observed, rotation):
    """min over s >= 0 (and a rotation angle) of |O - s T R|^2 / |O|^2, by scipy."""
    from scipy.optimize import minimize

    def cost(x):
        angle = x[1] if rotation else 0.0
        r = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        return np.sum((observed - max(x[0], 0.0) * template @ r) ** 2)

    starts = [[1.0, a] for a in np.linspace(-np.pi, np.pi, 13)] if rotation else [[1.0, 0.0]]
    best = min(
        minimize(cost, s, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-14}).fun
        for s in starts
    )
    return min(best, cost([0.0, 0.0])) / np.sum(observed**2)


@pytest.mark.parametrize("rotation", [False, True])
def test_match_residuals_are_the_best_similarity_fits(rotation):
    """Residuals of random, mirrored, opposite and zero templates against a second solver."""
    from dmpopt.recognition.partial import _match_residuals

    rng = np.random.default_rng(5)
    observed = rng.standard_normal((15, 2))
    templates = np.stack(
        [
            rng.standard_normal((15, 2)),
            observed + 0.3 * rng.standard_normal((15, 2)),
            -observed,  # rotation by pi fits it exactly; a scale >= 0 alone cannot
            observed * [1.0, -1.0],  # a reflection: no proper rotation fits it
            np.zeros((15, 2)),
            0.01 * observed,  # a small copy: fitted exactly by the scale 100
        ]
    )
    expected = [_best_similarity_fit(t, observed, rotation) for t in templates]
    actual = _match_residuals(templates, observed, rotation)
    np.testing.assert_allclose(actual, expected, rtol=1e-6, atol=1e-9)
    assert actual[2] == pytest.approx(0.0 if rotation else 1.0, abs=1e-12)
    assert actual[4] == 1.0 and actual[5] == pytest.approx(0.0, abs=1e-12)


def test_match_finds_the_observed_fraction(dmp):
    """The first 40 % of a DMP's own plan, moved, shrunk and slowed, matches at fraction 0.4."""
    duration = dmp.convergence_time
    plan = dmp.rollout(duration, duration / 1000)
    keep = plan.times <= 0.4 * plan.times[-1] + 1e-9
    positions = 0.1 * plan.positions[keep] + [3.0, -1.0]  # small: moves less than 1
    observation = Trajectory.from_positions(3.0 * plan.times[keep] + 1.0, positions)
    classifier = PartialObservationClassifier(
        fractions=(0.5, 0.3, 0.4), n_samples=40, plan_samples=1001
    )
    classifier.fit([dmp, dmp.replace(goal=dmp.goal + [0.0, 3.0])], ["same", "other"])
    residuals, fractions = classifier.match(observation)
    assert fractions[0] == 0.4 and residuals[0] < 1e-12 and residuals[1] > 1e-3
    assert list(classifier.fractions_) == [0.3, 0.4, 0.5]
    assert classifier.predict(observation).tolist() == ["same"]


def test_partial_classifier_defaults(dmp):
    """Nine fractions 0.3-0.7, 50 compared samples, no rotation, 400 plan samples."""
    classifier = PartialObservationClassifier()
    assert classifier.fractions == (0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7)
    assert (classifier.n_samples, classifier.rotation, classifier.plan_samples) == (50, False, 400)
    classifier.fit([dmp, dmp, dmp], ["b", "a", "b"])
    assert classifier.plans_.shape == (3, 400, 2) and np.all(classifier.plans_[:, 0] == 0.0)
    assert classifier.classes_.tolist() == ["a", "b"] and classifier.labels_.tolist() == list("bab")
    whole = PartialObservationClassifier(fractions=[1.0]).fit([dmp], ["a"])
    assert whole.fractions_.tolist() == [1.0]


def test_first_part_keeps_samples_up_to_the_end_time():
    """Samples at exactly the end time are kept (within 1e-12 of the duration)."""
    line = Trajectory.from_positions(np.arange(11.0), np.arange(11.0)[:, None])
    assert first_part(line, 0.5).times.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    assert first_part(line, 0.2).n_steps == 3  # three samples are enough
    long = Trajectory.from_positions(np.arange(11.0) * 1e5, np.arange(11.0)[:, None])
    assert first_part(long, (3e5 - 1e-7) / 1e6).times[-1] == 3e5


def test_partial_fit_names_each_bad_argument(dmp):
    """A fraction of 0, a table of fractions, fractions that are not numbers, and bad sample
    counts are refused with the argument's name."""
    message = "fractions must be a non-empty list of numbers in (0, 1], got "
    for fractions in ((0.0, 0.5), ((0.5, 1.0), (0.5, 1.0))):
        with _raises(InvalidInputError, message + repr(fractions)):
            PartialObservationClassifier(fractions=fractions).fit([dmp], ["a"])
    with pytest.raises(InvalidInputError, match="^fractions"):
        PartialObservationClassifier(fractions=("a", "b")).fit([dmp], ["a"])
    for name in ("n_samples", "plan_samples"):
        with pytest.raises(InvalidInputError, match=f"^{name}"):
            PartialObservationClassifier(**{name: 0}).fit([dmp], ["a"])


def test_partial_segments_have_n_samples_samples_of_the_whole_plan(dmp):
    """With n_samples = 7 each stored segment has 7 samples, and the whole fraction's segment
    is the plan sampled at 7 equally spaced indices of its plan_samples (0, 1/6, .. 1 of
    the last index, interpolated linearly), here at plan_samples = 61: every 10th sample."""
    classifier = PartialObservationClassifier(fractions=(1.0,), n_samples=7, plan_samples=61)
    classifier.fit([dmp], ["a"])
    (segment,) = classifier._segments
    np.testing.assert_array_equal(segment[0], classifier.plans_[0, ::10])
    plan = dmp.rollout(dmp.convergence_time, dmp.convergence_time / 60).positions
    np.testing.assert_array_equal(classifier.plans_[0], plan[:61] - plan[0])


def test_a_mirrored_3d_observation_is_matched_by_the_best_proper_rotation():
    """T = (e1, 2 e2, 3 e3), O = T with z negated: T^T O = diag(1, 4, -9). Over proper
    rotations the largest trace(R^T T^T O) is 1 + 4 + 9 - 2 x 1 = 12 (R = diag(-1, 1, -1)
    flips the smallest), so the residual is 1 - 12^2 / (|T|^2 |O|^2) = 1 - 144 / 196;
    without rotation trace(T^T O) = -4 gives the scale 0 and the residual 1. A template of
    zeros explains nothing (residual 1), without a numpy warning."""
    import warnings

    from dmpopt.recognition.partial import _match_residuals

    template = np.diag([1.0, 2.0, 3.0])
    observed = template * [1.0, 1.0, -1.0]
    templates = np.stack([template, np.zeros((3, 3))])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rotated = _match_residuals(templates, observed, True)
        fixed = _match_residuals(templates, observed, False)
    np.testing.assert_allclose(rotated, [1.0 - 144.0 / 196.0, 1.0], rtol=1e-14)
    np.testing.assert_array_equal(fixed, [1.0, 1.0])
