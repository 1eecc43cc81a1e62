"""Tests of dmpopt.recognition.features: invariant features, the plan metric, arc-length paths."""

import numpy as np
import pytest
from recognition_shapes import N_BASIS, N_STEPS, _moved, _raises, _shape

from dmpopt import Trajectory, fit_discrete
from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.recognition import (
    NearestNeighbourClassifier,
    arc_length_resampled,
    first_part,
    movement_feature_sets,
    movement_features,
    normalised_plan,
    normalised_weights,
    plan_metric_factor,
)


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


def test_feature_sets_are_the_blocks_weighted_per_pair(dmp, demo):
    """Each pair's matrix: the weights block alone, then path_weight / sqrt(n) times the
    resampled normalised plan, then direction_weight times the unit start-goal vector."""
    dmps = [dmp, fit_discrete(_moved(demo, angle=0.7), N_BASIS)]
    velocity = np.array([[0.3, -0.2], [0.0, 0.1]])
    pairs = [(1.0, 0.0), (0.5, 2.0), (0.0, 1.5)]
    sets = movement_feature_sets(dmps, pairs, start_velocities=velocity, n_samples=40)
    n_plan = 2 * (N_BASIS + 1)
    for row, (one, velocity_row) in enumerate(zip(dmps, velocity)):
        path = arc_length_resampled(normalised_plan(one, velocity_row, n_samples=40), 40).ravel()
        displacement = np.asarray(one.goal) - np.asarray(one.start)
        unit = displacement / np.linalg.norm(displacement)
        for (direction, weight), features in zip(pairs, sets):
            assert np.array_equal(features[row, :n_plan], sets[0][row, :n_plan])
            middle = features[row, n_plan:-2]
            assert middle.size == (path.size if weight > 0 else 0)
            if weight > 0:  # the same plan as normalised_plan's, up to the rollout's rounding
                assert np.allclose(middle, weight / np.sqrt(40) * path, rtol=0, atol=1e-12)
            assert np.allclose(features[row, -2:], direction * unit, rtol=0, atol=1e-15)
    with _raises(
        InvalidInputError, "weightings[0] must be a (direction_weight, path_weight) pair, got 1.0"
    ):
        movement_feature_sets(dmps, [1.0])
    with _raises(InvalidInputError, "path_weight must be a finite number >= 0, got -2.0"):
        movement_feature_sets(dmps, [(1.0, -2.0)])
