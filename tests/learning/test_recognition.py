"""Tests of dmpopt.recognition: invariant features, classifiers, partial observations."""

import re
import sys

import numpy as np
import pytest

from dmpopt import Trajectory, fit_discrete
from dmpopt.exceptions import InvalidInputError, MissingDependency, ShapeError
from dmpopt.recognition import (
    NearestNeighbourClassifier,
    PartialObservationClassifier,
    ShrinkageLdaClassifier,
    arc_length_resampled,
    confusion_matrix,
    first_part,
    leave_one_out,
    movement_features,
    normalised_plan,
    normalised_weights,
    plan_metric_factor,
)

N_BASIS = 12
N_STEPS = 200


def _shape(kind: int, rng=None, duration: float = 1.0) -> Trajectory:
    """Make a 2-D point-to-point synthetic stroke of one of three kinds (optionally perturbed)."""
    s = np.linspace(0.0, 1.0, N_STEPS)
    progress = 10 * s**3 - 15 * s**4 + 6 * s**5  # minimum jerk
    start, goal = np.array([-3.0, 1.0]), np.array([2.0, 0.5])
    bumps = (np.sin(np.pi * progress), np.sin(2 * np.pi * progress), np.sin(np.pi * progress) ** 3)
    amplitudes = (1.5, 1.0, -2.0)
    amplitude = amplitudes[kind]
    if rng is not None:
        amplitude *= 1.0 + 0.05 * rng.standard_normal()
        goal = goal + 0.05 * rng.standard_normal(2)
    direction = goal - start
    normal = np.array([-direction[1], direction[0]]) / np.linalg.norm(direction)
    positions = start + progress[:, None] * direction + amplitude * bumps[kind][:, None] * normal
    return Trajectory.from_positions(duration * s, positions)


def _moved(demo: Trajectory, scale=3.7, angle=0.0, offset=(40.0, -12.0), stretch=2.5):
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    positions = scale * demo.positions @ rotation.T + np.asarray(offset)
    return Trajectory.from_positions(stretch * demo.times + 0.3, positions)


def _synthetic_set(n_per_class: int = 4, seed: int = 0):
    rng = np.random.default_rng(seed)
    demos, labels = [], []
    for kind in range(3):
        for _ in range(n_per_class):
            demos.append(_shape(kind, rng, duration=rng.uniform(0.8, 1.5)))
            labels.append(f"kind{kind}")
    return demos, np.array(labels)


@pytest.fixture(scope="module")
def demo():
    """Return a clean synthetic stroke."""
    return _shape(0)


@pytest.fixture(scope="module")
def dmp(demo):
    """Return the DMP fitted to ``demo``."""
    return fit_discrete(demo, N_BASIS)


@pytest.mark.parametrize(
    "change",
    [
        {"scale": 1.0, "stretch": 1.0},  # translation only
        {"offset": (0.0, 0.0), "stretch": 1.0},  # scaling only
        {"scale": 1.0, "offset": (0.0, 0.0)},  # time stretch only
        {},  # all three
        {"angle": 2.1},  # and a rotation
    ],
)
def test_normalised_weights_are_invariant(demo, dmp, change):
    """Translation, uniform scaling, time stretching and 2-D rotation leave them unchanged."""
    moved = fit_discrete(_moved(demo, **change), N_BASIS)
    expected = normalised_weights(dmp)
    assert np.allclose(normalised_weights(moved), expected, rtol=0, atol=1e-9 * abs(expected).max())


def test_raw_weights_are_not_invariant(demo, dmp):
    """Control: the weights themselves scale and rotate with the movement."""
    moved = fit_discrete(_moved(demo, angle=0.7), N_BASIS)
    assert not np.allclose(moved.forcing_weights(), dmp.forcing_weights(), atol=1e-3)


def _moving_start(kind: int = 1) -> Trajectory:
    """A stroke that starts at speed: ``_shape(kind)`` without its first 15 %."""
    whole = _shape(kind)
    keep = whole.times >= 0.15
    return Trajectory.from_positions(whole.times[keep], whole.positions[keep])


def test_features_invariant_except_direction_under_rotation():
    """Features ignore translation, scale and time; only the direction part sees a rotation."""
    demo = _moving_start()
    demos = [demo, _moved(demo), _moved(demo, angle=-1.2)]
    dmps = [fit_discrete(d, N_BASIS) for d in demos]
    velocities = [d.velocities[0] for d in demos]
    assert np.linalg.norm(velocities[0]) > 1.0  # the plan does not start at rest
    features = movement_features(dmps, start_velocities=velocities)
    atol = 1e-9 * abs(features).max()
    assert np.allclose(features[1], features[0], rtol=0, atol=atol)
    assert np.allclose(features[2, :-2], features[0, :-2], rtol=0, atol=atol)
    assert not np.allclose(features[2, -2:], features[0, -2:], atol=1e-3)
    plain = movement_features(dmps, start_velocities=velocities, direction_weight=0.0)
    assert np.allclose(plain[2], plain[0], rtol=0, atol=atol)
    assert features.shape == (3, 2 * (N_BASIS + 1) + 2 * 200 + 2)
    weights_only = movement_features(dmps, path_weight=0.0, n_samples=50)
    assert weights_only.shape == (3, 2 * (N_BASIS + 1) + 2)


def test_normalised_plan_is_the_plan_in_the_start_goal_frame():
    """It equals S(d -> e1) (y(t) - y0) of the DMP's own plan from its start velocity."""
    demo = _moved(_moving_start(), scale=2.0, angle=0.4)
    dmp = fit_discrete(demo, N_BASIS)
    velocity = demo.velocities[0]
    plan = normalised_plan(dmp, velocity, n_samples=101)
    duration = dmp.convergence_time
    own = dmp.rollout(duration, duration / 100, start_velocity=velocity).positions[:101]
    displacement = dmp.goal - dmp.start
    angle = np.arctan2(displacement[1], displacement[0])
    frame = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])
    expected = (own - dmp.start) @ frame.T / np.linalg.norm(displacement)
    assert plan.shape == (101, 2)
    assert np.allclose(plan, expected, rtol=0, atol=1e-9)
    assert np.allclose(plan[0], 0.0) and np.allclose(plan[-1], [1.0, 0.0], atol=1e-3)
    # the fit reproduces the demo only from the demo's start velocity, not from rest
    demo_positions = (demo.resampled(101).positions - dmp.start) @ frame.T
    demo_positions /= np.linalg.norm(displacement)
    assert np.abs(plan - demo_positions).max() < 0.002
    assert np.abs(normalised_plan(dmp, n_samples=101) - demo_positions).max() > 0.02


def test_plan_metric_with_start_velocity_measures_plan_differences():
    """Feature distances (no path, no direction) are RMS differences of the normalised plans."""
    demos = [_moving_start(1), _moving_start(0)]
    dmps = [fit_discrete(d, N_BASIS) for d in demos]
    velocities = [d.velocities[0] for d in demos]
    features = movement_features(
        dmps, start_velocities=velocities, path_weight=0.0, direction_weight=0.0, n_samples=300
    )
    plans = [normalised_plan(m, v, n_samples=300) for m, v in zip(dmps, velocities)]
    expected = np.mean(np.sum((plans[1] - plans[0]) ** 2, axis=1))
    assert expected > 1e-3
    assert np.isclose(np.sum((features[1] - features[0]) ** 2), expected, rtol=1e-9)
    assert plan_metric_factor(dmps[0], 300, start_velocity=True).shape == (N_BASIS + 1,) * 2


def test_arc_length_resampling_ignores_the_speed_profile():
    """An L-shaped path traced at any speed gives points at equal distances along it."""
    slow, fast = np.linspace(0.0, 1.0, 301) ** 3, np.linspace(0.0, 1.0, 7)[1:]
    positions = np.vstack(  # along x (length 3) slowly at first, then up y (length 1) fast
        [np.column_stack([3.0 * slow, 0.0 * slow]), np.column_stack([3.0 + 0.0 * fast, fast])]
    )
    path = arc_length_resampled(positions, 9)
    expected = [[0, 0], [0.5, 0], [1, 0], [1.5, 0], [2, 0], [2.5, 0], [3, 0], [3, 0.5], [3, 1]]
    assert np.allclose(path, expected, rtol=0, atol=1e-12)


def test_path_features_ignore_the_speed_profile():
    """The same stroke drawn with another speed profile: same path block, different plan."""
    s = np.linspace(0.0, 1.0, N_STEPS)
    original = _shape(1)
    warped_progress = np.interp(s**1.6, s, s)  # the same positions, reached later
    positions = np.stack([np.interp(warped_progress, s, p) for p in original.positions.T], 1)
    warped = Trajectory.from_positions(s, positions)
    dmps = [fit_discrete(original, N_BASIS), fit_discrete(warped, N_BASIS)]
    features = movement_features(dmps, direction_weight=0.0, n_samples=100)
    n_plan = 2 * (N_BASIS + 1)
    plan_distance = np.linalg.norm(features[1, :n_plan] - features[0, :n_plan])
    path_distance = np.linalg.norm(features[1, n_plan:] - features[0, n_plan:])
    assert plan_distance > 0.1
    assert path_distance < 0.1 * plan_distance


def test_plan_metric_measures_plan_differences(dmp):
    """|(W1 - W2) L|^2 is the mean squared difference of the plans of W1 and W2."""
    rng = np.random.default_rng(1)
    other = dmp.replace(weights=dmp.weights + rng.normal(size=dmp.weights.shape))
    factor = plan_metric_factor(dmp, n_samples=300)
    duration = dmp.convergence_time
    plans = [m.rollout(duration, duration / 299).positions for m in (dmp, other)]
    expected = np.mean(np.sum((plans[1] - plans[0]) ** 2, axis=1))
    difference = (other.forcing_weights() - dmp.forcing_weights()) @ factor
    assert np.isclose(np.sum(difference**2), expected, rtol=1e-9)


def test_nearest_neighbour_on_synthetic_set():
    """1-NN and 3-NN on normalised features recognise every synthetic stroke (leave-one-out)."""
    demos, labels = _synthetic_set()
    features = movement_features([fit_discrete(d, N_BASIS) for d in demos])
    for k in (1, 3):
        predictions = leave_one_out(NearestNeighbourClassifier(k), features, labels)
        assert np.array_equal(predictions, labels)
    moved = movement_features([fit_discrete(_moved(d), N_BASIS) for d in demos])
    predictions = leave_one_out(NearestNeighbourClassifier(), features, labels, moved)
    assert np.array_equal(predictions, labels)


def test_nearest_neighbour_basics():
    """Fit returns self, attributes end in _, and ties go to the nearest neighbour."""
    features = np.array([[0.0], [1.0], [2.1], [10.0]])
    labels = np.array(["a", "b", "c", "c"])
    classifier = NearestNeighbourClassifier(n_neighbours=3)
    assert classifier.fit(features, labels) is classifier
    assert list(classifier.classes_) == ["a", "b", "c"]
    assert list(classifier.predict([[0.2], [9.0]])) == ["a", "c"]
    distances, indices = classifier.kneighbours([[0.2]])
    assert np.allclose(distances, [[0.2, 0.8, 1.9]]) and list(indices[0]) == [0, 1, 2]


def test_shrinkage_lda_on_blobs():
    """LDA separates Gaussian classes that differ along a low-variance direction."""
    rng = np.random.default_rng(2)
    spread = np.array([5.0, 0.1, 0.1])
    means = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    features = np.vstack([m + spread * rng.standard_normal((20, 3)) for m in means])
    labels = np.repeat([0, 1, 2], 20)
    classifier = ShrinkageLdaClassifier(shrinkage=0.05).fit(features, labels)
    test = np.vstack([m + spread * rng.standard_normal((10, 3)) for m in means])
    assert np.mean(classifier.predict(test) == np.repeat([0, 1, 2], 10)) >= 0.95


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


def test_confusion_matrix_counts():
    """Rows are true classes, columns predictions."""
    matrix = confusion_matrix(["a", "a", "b", "c"], ["a", "b", "b", "a"], classes=["a", "b", "c"])
    assert matrix.tolist() == [[1, 1, 0], [0, 1, 0], [1, 0, 0]]


def test_first_part_keeps_the_beginning(demo):
    """first_part keeps the samples of the first fraction of the duration."""
    half = first_part(demo, 0.5)
    assert half.times[-1] <= demo.times[0] + 0.5 * demo.duration + 1e-12
    assert half.n_steps == np.count_nonzero(demo.times <= 0.5 + 1e-12)


# ---------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------


def _raises(error, message):
    return pytest.raises(error, match=f"^{re.escape(message)}$")


def test_error_not_a_dmp():
    """Only DiscreteDMPs have normalised weights."""
    with _raises(
        InvalidInputError,
        "dmp must be a DiscreteDMP, got ndarray; fit one with dmpopt.fit_discrete(demo, n_basis)",
    ):
        normalised_weights(np.zeros((2, 3)))


def test_error_goal_equals_start(dmp):
    """Closed movements cannot be normalised by the start-goal vector."""
    with _raises(
        InvalidInputError,
        "the DMP's goal equals its start, so its weights cannot be "
        "normalised by the start-goal vector; recognition needs point-to-point "
        "movements (for a closed movement, compare dmp.forcing_weights() divided by "
        "their norm instead)",
    ):
        normalised_weights(dmp.replace(goal_scaling="translation", goal=dmp.start))


def test_error_mismatched_dmps(dmp, demo):
    """Features are only built from DMPs with the same basis, form and gains."""
    other = fit_discrete(demo, N_BASIS + 1)
    with _raises(
        ShapeError,
        f"dmps[1] has weights of shape (2, {N_BASIS + 1}), expected "
        f"(2, {N_BASIS}) like dmps[0]; fit all movements with the same n_basis and "
        "number of DOFs",
    ):
        movement_features([dmp, other])
    accel = fit_discrete(demo, N_BASIS, form="acceleration")
    with _raises(
        InvalidInputError,
        "dmps[1] has a different form, basis or gains than dmps[0]; "
        "weights are only comparable between DMPs fitted with the same options",
    ):
        movement_features([dmp, accel])


def test_error_bad_feature_options(dmp):
    """Bad metric, weights, start velocities or empty input are refused."""
    with _raises(InvalidInputError, "metric must be one of ('plan', 'euclidean'), got 'cosine'"):
        movement_features([dmp], metric="cosine")
    with _raises(InvalidInputError, "direction_weight must be a finite number >= 0, got -1.0"):
        movement_features([dmp], direction_weight=-1)
    with _raises(InvalidInputError, "path_weight must be a finite number >= 0, got inf"):
        movement_features([dmp], path_weight=np.inf)
    with _raises(
        ShapeError,
        "start_velocities has shape (2,), expected (1, 2): one first velocity per DMP "
        "(demo.velocities[0])",
    ):
        movement_features([dmp], start_velocities=[0.0, 1.0])
    with _raises(
        ShapeError,
        "start_velocity has shape (3,), expected (2,): the DMP's first velocity, one value "
        "per DOF (fit_discrete starts from demo.velocities[0])",
    ):
        normalised_plan(dmp, [0.0, 1.0, 2.0])
    with _raises(InvalidInputError, "positions do not move, so they have no path to resample"):
        arc_length_resampled(np.ones((5, 2)), 10)
    with _raises(InvalidInputError, "n_samples must be an integer >= 3, got 2"):
        normalised_plan(dmp, n_samples=2)
    with _raises(InvalidInputError, "dmps is empty; pass at least one fitted DiscreteDMP"):
        movement_features([])


def test_error_classifier_inputs():
    """Classifiers check fitting, shapes, values and hyper-parameters."""
    features = np.zeros((4, 3))
    with _raises(
        InvalidInputError, "this NearestNeighbourClassifier is not fitted yet; call fit(...) first"
    ):
        NearestNeighbourClassifier().predict(features)
    with _raises(ShapeError, "labels has shape (3,), expected (4,): one label per sample"):
        NearestNeighbourClassifier().fit(features, [0, 1, 2])
    with _raises(InvalidInputError, "n_neighbours must be a positive integer, got 0"):
        NearestNeighbourClassifier(0).fit(features, [0, 1, 2, 3])
    with _raises(InvalidInputError, "n_neighbours = 5 exceeds the 4 training samples"):
        NearestNeighbourClassifier(5).fit(features, [0, 1, 2, 3])
    fitted = NearestNeighbourClassifier().fit(features, [0, 1, 2, 3])
    with _raises(
        ShapeError,
        "features has shape (1, 2), expected (n_samples, 3) like the "
        "features the classifier was fitted on",
    ):
        fitted.predict(np.zeros((1, 2)))
    with _raises(
        InvalidInputError,
        "features[0, 0] is nan: features contains 1 NaN or infinite value(s); "
        "clean or interpolate them first",
    ):
        fitted.predict([[np.nan, 0.0, 0.0]])
    with _raises(InvalidInputError, "shrinkage must be a finite number > 0 and <= 1, got 0.0"):
        ShrinkageLdaClassifier(0.0).fit(features, [0, 1, 2, 3])
    with _raises(ShapeError, "queries has 2 entries, expected 4: one per sample"):
        leave_one_out(NearestNeighbourClassifier(), features, [0, 1, 2, 3], np.zeros((2, 3)))


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


def test_nested_leave_one_out_table_matches_refits():
    """The study's nested LOO table: entry [i, j] is 1-NN trained without samples i and j."""
    from dmpopt_studies.recognition import _loo_distance_predictions

    rng = np.random.default_rng(3)
    features = rng.normal(size=(12, 3))
    labels = np.array(list("aabbccaabbcc"))
    table = _loo_distance_predictions(features, labels)
    assert np.array_equal(
        np.diag(table), leave_one_out(NearestNeighbourClassifier(), features, labels)
    )
    for i, j in ((0, 5), (7, 2), (11, 4)):
        keep = np.setdiff1d(np.arange(12), [i, j])
        fitted = NearestNeighbourClassifier().fit(features[keep], labels[keep])
        assert table[i, j] == fitted.predict(features[[j]])[0]


def test_scaled_copy_is_indistinguishable():
    """A smaller copy of a stroke has exactly the same features: scale cannot separate classes.

    This is why, in LASA, Multi_Models sub-patterns that are smaller copies of single shapes
    (Multi_Models_4 demos 5-7 and Trapezoid) are confused by any scale-invariant recogniser.
    """
    demo = _shape(1)
    small = _moved(demo, scale=0.45, offset=(-20.0, 3.0), stretch=1.0)
    features = movement_features([fit_discrete(demo, N_BASIS), fit_discrete(small, N_BASIS)])
    assert np.allclose(features[1], features[0], rtol=0, atol=1e-9 * abs(features).max())
    classifier = NearestNeighbourClassifier().fit(features[:1], ["big"])
    assert classifier.predict(features[1:])[0] == "big"


# ---------------------------------------------------------------------------------------
# Answer keys: the plain formulas and hand-computed cases
# ---------------------------------------------------------------------------------------


def test_normalised_weights_are_the_weights_in_the_start_goal_frame_per_unit_length(dmp):
    """w_bar = R(d -> e1) w / |d|, with R the 2-D rotation by minus the angle of d."""
    moved = dmp.replace(goal=dmp.start + np.array([3.0, 4.0]))  # |d| = 5
    rotation = np.array([[3.0, 4.0], [-4.0, 3.0]]) / 5.0  # maps (3, 4) onto (5, 0)
    expected = rotation @ moved.forcing_weights() / 5.0
    assert np.allclose(normalised_weights(moved), expected, rtol=0, atol=1e-12)


def test_euclidean_features_are_the_plain_formula(dmp):
    """metric "euclidean", no path: [vec(R [w, tau v] / |d|), lambda d / |d|] per DMP."""
    d = np.array([3.0, 4.0])
    dmps = [dmp.replace(goal=dmp.start + d), dmp.replace(goal=dmp.start - d)]
    velocities = np.array([[0.5, -1.0], [2.0, 0.25]])
    features = movement_features(
        dmps, start_velocities=velocities, metric="euclidean", direction_weight=0.7, path_weight=0
    )
    rows = []
    for sign, model, velocity in zip((1.0, -1.0), dmps, velocities):
        rotation = sign * np.array([[3.0, 4.0], [-4.0, 3.0]]) / 5.0  # maps sign * d onto e1
        block = np.column_stack([model.forcing_weights(), model.tau * velocity])
        rows.append(np.concatenate([(rotation @ block / 5.0).ravel(), 0.7 * sign * d / 5.0]))
    assert np.allclose(features, rows, rtol=0, atol=1e-12)


def test_path_block_is_the_arc_length_resampled_normalised_plan(dmp):
    """The middle block is path_weight / sqrt(n) times the resampled normalised plan."""
    velocity = np.array([[0.3, -0.2]])
    features = movement_features(
        [dmp], start_velocities=velocity, path_weight=1.5, direction_weight=0.0, n_samples=40
    )
    plan = normalised_plan(dmp, velocity[0], n_samples=40)
    path = arc_length_resampled(plan, 40)
    n_plan = 2 * (N_BASIS + 1)
    expected = 1.5 / np.sqrt(40) * path.ravel()
    assert np.allclose(features[0, n_plan:-2], expected, rtol=0, atol=1e-12)
    assert np.all(features[0, -2:] == 0.0)


def _line():
    """Five 1-D samples: a, a at 0 and 1; b, b at 3 and 3.5; c at 10."""
    return np.array([[0.0], [1.0], [3.0], [3.5], [10.0]]), np.array(list("aabbc"))


def test_nearest_neighbours_on_a_hand_computed_line():
    """Query 1.9: distances 1.9, 0.9, 1.1, 1.6, 8.1; 1-NN says a, the 3-NN vote (a, b, b) b."""
    features, labels = _line()
    assert NearestNeighbourClassifier(1).fit(features, labels).predict([[1.9]])[0] == "a"
    three = NearestNeighbourClassifier(3).fit(features, labels)
    assert three.predict([[1.9]])[0] == "b"
    distances, indices = three.kneighbours([[1.9]])
    assert np.allclose(distances, [[0.9, 1.1, 1.6]]) and indices.tolist() == [[1, 2, 3]]
    assert list(three.classes_) == ["a", "b", "c"]


def test_leave_one_out_on_a_hand_computed_line():
    """Each sample (or its query) classified by 1-NN fitted on the four others."""
    features, labels = _line()
    nearest = NearestNeighbourClassifier()
    assert leave_one_out(nearest, features, labels).tolist() == list("aabbb")
    # query 9 for every sample: nearest is 10 (c), except when 10 is left out (3.5, b)
    queries = np.full((5, 1), 9.0)
    assert leave_one_out(nearest, features, labels, queries).tolist() == list("ccccb")
    assert not hasattr(nearest, "estimator_")  # copies are fitted, never the classifier


def test_shrinkage_lda_on_a_hand_computed_case():
    r"""Class means (0, 0) and (1, 1), pooled covariance diag(0, 4) (tr / p = 2).

    Shrunk: diag(2 g, 4 - 2 g). For q = (0.6, -0.5), d_A - d_B = 0.2 / (2 g) - 2 / (4 - 2 g):
    +0.47 for g = 0.1 (B is nearer), -0.9 for g = 1 (A is nearer, as in Euclidean distance).
    """
    features = np.array([[0.0, -2.0], [0.0, 2.0], [1.0, -1.0], [1.0, 3.0]])
    labels = ["A", "A", "B", "B"]
    query = [[0.6, -0.5]]
    assert ShrinkageLdaClassifier(0.1).fit(features, labels).predict(query)[0] == "B"
    assert ShrinkageLdaClassifier(1.0).fit(features, labels).predict(query)[0] == "A"
    lda = ShrinkageLdaClassifier("auto").fit(features, labels)
    assert lda.estimator_.shrinkage == "auto" and list(lda.classes_) == ["A", "B"]


def test_confusion_matrix_keeps_the_order_of_classes():
    """Rows and columns follow ``classes``; by default the sorted labels."""
    matrix = confusion_matrix([2, 2, 0, 1], [2, 0, 0, 0], classes=[2, 1, 0])
    assert matrix.tolist() == [[1, 0, 1], [0, 0, 1], [0, 0, 1]]
    assert confusion_matrix([2, 2, 0, 1], [2, 0, 0, 0]).tolist() == [
        [1, 0, 0],
        [1, 0, 0],
        [1, 0, 1],
    ]


@pytest.mark.parametrize(
    "call, module, user",
    [
        (
            lambda: NearestNeighbourClassifier().fit(np.eye(2), [0, 1]),
            "sklearn.neighbors",
            "NearestNeighbourClassifier",
        ),
        (
            lambda: ShrinkageLdaClassifier().fit(np.eye(4), [0, 0, 1, 1]),
            "sklearn.discriminant_analysis",
            "ShrinkageLdaClassifier",
        ),
        (lambda: confusion_matrix([0, 1], [0, 0]), "sklearn.metrics", "confusion_matrix"),
        (
            lambda: leave_one_out(NearestNeighbourClassifier(), np.eye(2), [0, 1]),
            "sklearn.model_selection",
            "leave_one_out",
        ),
    ],
)
def test_without_scikit_learn_the_error_names_the_extra(monkeypatch, call, module, user):
    """MissingDependency names the function and the extra that installs scikit-learn."""
    monkeypatch.setitem(sys.modules, module, None)
    extra = re.escape("pip install 'dmpopt[recognition]'")
    message = f"^{user} needs scikit-learn, which is not installed: {extra}$"
    with pytest.raises(MissingDependency, match=message):
        call()


def test_lda_memory_bound():
    """The p x p covariance is bounded (8 p^2 bytes); 700 features are far below it."""
    from dmpopt.exceptions import ResourceLimitError

    with pytest.raises(
        ResourceLimitError,
        match=r"^the covariance of 100000 features needs about 74.5 GiB; .*: reduce the "
        r"features \(e.g. fewer basis functions or path samples\)$",
    ):
        ShrinkageLdaClassifier().fit(np.zeros((3, 10**5)), [0, 1, 1])
    rng = np.random.default_rng(0)
    features = rng.standard_normal((4, 700))
    lda = ShrinkageLdaClassifier().fit(features, [0, 0, 1, 1])
    assert lda.predict(features).tolist() == [0, 0, 1, 1]


def test_error_lda_degenerate_training_sets():
    """One class, or no spread within any class, is refused before scikit-learn sees it."""
    with _raises(
        InvalidInputError, "labels hold the single class 'a'; LDA needs at least two classes"
    ):
        ShrinkageLdaClassifier().fit(np.eye(3), ["a", "a", "a"])
    with _raises(
        InvalidInputError,
        "features do not vary within any class, so LDA has no within-class covariance to "
        "estimate; give some class two distinct samples or use NearestNeighbourClassifier",
    ):
        ShrinkageLdaClassifier().fit(np.array([[0.0], [0.0], [1.0]]), [0, 0, 1])
    with _raises(InvalidInputError, "shrinkage must be a number in (0, 1] or 'auto', got 'ledoit'"):
        ShrinkageLdaClassifier("ledoit").fit(np.eye(3), [0, 1, 1])


def test_error_confusion_matrix_classes():
    """classes must list every label once."""
    with _raises(
        InvalidInputError, "labels ['c'] are not in classes; add them to classes or leave it out"
    ):
        confusion_matrix(["a", "c"], ["a", "a"], classes=["a", "b"])
    with _raises(InvalidInputError, "classes repeats a label: ['a', 'a']; list each once"):
        confusion_matrix(["a"], ["a"], classes=["a", "a"])
    with _raises(ShapeError, "classes has shape (0,), expected (n_classes,)"):
        confusion_matrix(["a"], ["a"], classes=[])


def _line_dmp(n_dofs: int = 2):
    s = np.linspace(0.0, 1.0, 60)
    positions = np.column_stack([s, np.sin(3 * s), s**2][:n_dofs])
    return fit_discrete(Trajectory.from_positions(s, positions), 6)


BAD_INPUTS = {
    "positions 1-D": (lambda d: arc_length_resampled(np.ones(5), 10), ShapeError, "positions"),
    "positions nan": (
        lambda d: arc_length_resampled([[0, 0], [np.nan, 1]], 10),
        InvalidInputError,
        r"positions\[1, 0\] is nan",
    ),
    "resample n_samples": (
        lambda d: arc_length_resampled(np.eye(3), 2),
        InvalidInputError,
        "n_samples",
    ),
    "plan start_velocity": (
        lambda d: normalised_plan(d, [np.nan, 0.0]),
        InvalidInputError,
        r"start_velocity\[0\] is nan",
    ),
    "plan n_samples": (
        lambda d: normalised_plan(d, n_samples=10**6),
        Exception,
        "^n_samples = 1000000 exceeds the bound 100000 of this function; a few hundred suffice$",
    ),
    "factor n_samples": (
        lambda d: plan_metric_factor(d, n_samples=2),
        InvalidInputError,
        "n_samples",
    ),
    "factor dmp": (
        lambda d: plan_metric_factor("x"),
        InvalidInputError,
        "dmp must be a DiscreteDMP",
    ),
    "features start_velocities": (
        lambda d: movement_features([d], start_velocities=[[np.nan, 0.0]]),
        InvalidInputError,
        r"start_velocities\[0, 0\] is nan",
    ),
    "features n_samples": (
        lambda d: movement_features([d], n_samples=1.5),
        InvalidInputError,
        "n_samples",
    ),
    "features dmps str": (
        lambda d: movement_features("abc"),
        InvalidInputError,
        "dmps must be a sequence",
    ),
    "features dmps[1]": (
        lambda d: movement_features([d, 3]),
        InvalidInputError,
        r"dmps\[1\] must be",
    ),
    "partial n_samples": (
        lambda d: PartialObservationClassifier(n_samples=2).fit([d], [0]),
        InvalidInputError,
        "^n_samples",
    ),
    "partial plan_samples": (
        lambda d: PartialObservationClassifier(plan_samples=2).fit([d], [0]),
        InvalidInputError,
        "^plan_samples",
    ),
    "partial fractions nan": (
        lambda d: PartialObservationClassifier(fractions=[np.nan]).fit([d], [0]),
        InvalidInputError,
        r"fractions\[0\] is nan",
    ),
    "partial fractions 0": (
        lambda d: PartialObservationClassifier(fractions=[0.0, 0.5]).fit([d], [0]),
        InvalidInputError,
        "fractions must be",
    ),
    "partial fractions 2-D": (
        lambda d: PartialObservationClassifier(fractions=[[0.5]]).fit([d], [0]),
        InvalidInputError,
        "fractions must be",
    ),
    "partial labels": (
        lambda d: PartialObservationClassifier().fit([d], [0, 1]),
        ShapeError,
        r"labels has shape \(2,\), expected \(1,\)",
    ),
    "partial DOFs": (
        lambda d: PartialObservationClassifier().fit([d, _line_dmp(3)], [0, 1]),
        ShapeError,
        r"dmps\[1\] has 3 DOFs, expected 2",
    ),
    "observation DOFs": (
        lambda d: (
            PartialObservationClassifier()
            .fit([d], [0])
            .match(Trajectory.from_positions(np.arange(5.0), np.arange(5.0)[:, None]))
        ),
        ShapeError,
        "observation has 1 DOFs, expected 2",
    ),
    "partial unfitted": (
        lambda d: PartialObservationClassifier().predict([_shape(0)]),
        InvalidInputError,
        "PartialObservationClassifier is not fitted",
    ),
    "lda unfitted": (
        lambda d: ShrinkageLdaClassifier().predict(np.eye(2)),
        InvalidInputError,
        "ShrinkageLdaClassifier is not fitted",
    ),
    "lda columns": (
        lambda d: ShrinkageLdaClassifier().fit(np.eye(4), [0, 0, 1, 1]).predict(np.eye(2)),
        ShapeError,
        r"features has shape \(2, 2\), expected \(n_samples, 4\)",
    ),
    "knn bool": (
        lambda d: NearestNeighbourClassifier(True).fit(np.eye(3), [0, 1, 1]),
        InvalidInputError,
        "n_neighbours",
    ),
    "knn kneighbours columns": (
        lambda d: NearestNeighbourClassifier().fit(np.eye(3), [0, 1, 1]).kneighbours(np.eye(2)),
        ShapeError,
        r"features has shape \(2, 2\)",
    ),
    "labels nan": (
        lambda d: NearestNeighbourClassifier().fit(np.eye(3), [0, np.nan, 1]),
        InvalidInputError,
        "labels must be integers or strings",
    ),
    "loo one sample": (
        lambda d: leave_one_out(NearestNeighbourClassifier(), np.eye(1), [0]),
        InvalidInputError,
        "at least two samples",
    ),
    "loo samples str": (
        lambda d: leave_one_out(NearestNeighbourClassifier(), "abc", [0, 1, 2]),
        InvalidInputError,
        "samples must be",
    ),
    "loo queries int": (
        lambda d: leave_one_out(NearestNeighbourClassifier(), np.eye(3), [0, 1, 1], 5),
        InvalidInputError,
        "queries must be an array or a list with one entry per sample, got int",
    ),
    "first_part too short": (
        lambda d: first_part(_shape(0), 0.001),
        InvalidInputError,
        r"the first 0% of the trajectory holds 1 samples, at least 3",
    ),
}


@pytest.mark.parametrize("case", BAD_INPUTS, ids=list(BAD_INPUTS))
def test_bad_inputs_name_the_argument(case):
    """Every refused input says which argument was wrong (message checked per case)."""
    call, error, message = BAD_INPUTS[case]
    with pytest.raises(error, match=message):
        call(_line_dmp())


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


def test_feature_checks_at_their_edges():
    """Empty features are named; 1e150 is the largest magnitude accepted."""
    with _raises(ShapeError, "features has shape (0, 3), expected (n_samples, n_features)"):
        NearestNeighbourClassifier().fit(np.zeros((0, 3)), [])
    big = NearestNeighbourClassifier().fit([[1e150], [-1e150]], ["a", "b"])
    assert big.predict([[1e150]]).tolist() == ["a"]


class _FitOnly:
    def fit(self, samples, labels):
        return self


def test_leave_one_out_needs_fit_and_predict():
    """An object without predict is refused before any fit."""
    with _raises(InvalidInputError, "classifier must have fit() and predict(), got _FitOnly"):
        leave_one_out(_FitOnly(), np.eye(3), [0, 1, 1])


def test_arc_length_of_a_short_two_point_segment():
    """Two points of one DOF, half a unit apart: three equally spaced points between them."""
    path = arc_length_resampled([[0.0], [0.5]], 3)
    assert path.shape == (3, 1) and np.allclose(path[:, 0], [0.0, 0.25, 0.5], rtol=0, atol=1e-15)


def test_plan_metric_factor_defaults(dmp):
    """200 samples, weights only (no start-velocity column) unless asked."""
    factor = plan_metric_factor(dmp)
    assert factor.shape == (N_BASIS, N_BASIS)
    np.testing.assert_array_equal(factor, plan_metric_factor(dmp, 200, start_velocity=False))


def test_movement_features_defaults_and_single_dmp(dmp):
    """Defaults: plan metric, path and direction weights 1, 200 samples; one DMP is a list."""
    expected = movement_features(
        [dmp], metric="plan", direction_weight=1.0, path_weight=1.0, n_samples=200
    )
    np.testing.assert_array_equal(movement_features(dmp), expected)
    euclidean = movement_features(dmp, metric="euclidean", path_weight=0.0)
    assert euclidean.shape == (1, 2 * (N_BASIS + 1) + 2)
    assert np.all(np.isfinite(plan_metric_factor(dmp, start_velocity=True)))


def test_start_goal_degeneracy_is_relative_to_the_weights(dmp):
    """|g - y0| must exceed 1e-9 times the largest forcing weight (zero weights: any motion)."""
    flat = dmp.replace(weights=np.zeros_like(dmp.weights), goal_scaling="translation")
    tiny = flat.replace(goal=flat.start + [1e-10, 0.0])
    np.testing.assert_array_equal(normalised_weights(tiny), np.zeros_like(dmp.weights))
    with pytest.raises(InvalidInputError, match="goal equals its start"):
        normalised_weights(flat.replace(goal=flat.start))
    weighted = dmp.replace(goal_scaling="translation")
    size = np.abs(weighted.forcing_weights()).max()
    with pytest.raises(InvalidInputError, match="goal equals its start"):
        normalised_weights(weighted.replace(goal=weighted.start + [0.5e-9 * size, 0.0]))


def test_arc_length_with_a_pause_at_the_start():
    """A repeated first point (zero first step) still has a path."""
    path = arc_length_resampled([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]], 3)
    assert np.allclose(path, [[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]], rtol=0, atol=1e-15)


def test_float_labels_and_the_whole_plan(dmp):
    """Whole-number floats are labels, 2.5 is not; fraction 1 compares the whole plan."""
    features, _ = _line()
    fitted = NearestNeighbourClassifier().fit(features, [0.0, 0.0, 1.0, 1.0, 2.0])
    assert fitted.predict([[9.0]]).tolist() == [2.0]
    with pytest.raises(InvalidInputError, match="^labels must be integers or strings, got dtype"):
        NearestNeighbourClassifier().fit(features, [0.0, 0.0, 1.0, 1.0, 2.5])
    duration = dmp.convergence_time
    plan = dmp.rollout(duration, duration / 100)
    whole = PartialObservationClassifier(fractions=[1.0], plan_samples=101, n_samples=101)
    residuals, fractions = whole.fit([dmp], ["a"]).match(plan)
    assert fractions.tolist() == [1.0] and residuals[0] < 1e-12


def test_documented_defaults_of_the_curves(dmp, demo):
    """normalised_plan samples 200 points; first_part keeps the first half."""
    assert normalised_plan(dmp).shape == (200, 2)
    np.testing.assert_array_equal(first_part(demo).times, first_part(demo, 0.5).times)


def test_plan_metric_factor_of_a_singular_metric_is_finite():
    """Each basis function three times over: the plan metric G is singular and numpy's
    eigenvalues of its null space round to about -1e-19; the factor stays finite (those
    are clipped to 0) and L L^T = G."""
    from dmpopt import DiscreteDMP
    from dmpopt.recognition.features import plan_metric_factor

    centres = np.repeat(np.exp(-np.linspace(0.0, 3.0, 6)), 3)
    dmp = DiscreteDMP(
        weights=np.zeros((2, 18)), start=[0, 0], goal=[1, 1], tau=1.0, centres=centres,
        widths=np.full(18, 20.0), goal_scaling="translation",
    )  # fmt: skip
    factor = plan_metric_factor(dmp)
    unit = dmp.with_tau(1.0)
    duration = unit.convergence_time
    response = unit.affine_plan(duration, duration / 199, start_velocity=0.0).weight_response[0]
    gram = response.T @ response / 200
    assert np.linalg.eigvalsh(gram).min() < 0.0  # the case this test is about
    assert np.isfinite(factor).all()
    np.testing.assert_allclose(factor @ factor.T, gram, rtol=0, atol=1e-12 * np.abs(gram).max())
