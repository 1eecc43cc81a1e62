"""Tests of dmpopt.recognition.classifiers: nearest neighbours and shrinkage LDA."""

import numpy as np
import pytest
from recognition_shapes import N_BASIS, _line, _moved, _raises, _synthetic_set

from dmpopt import fit_discrete
from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.recognition import (
    NearestNeighbourClassifier,
    PartialObservationClassifier,
    ShrinkageLdaClassifier,
    leave_one_out,
    movement_features,
)


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


def test_nearest_neighbours_on_a_hand_computed_line():
    """Query 1.9: distances 1.9, 0.9, 1.1, 1.6, 8.1; 1-NN says a, the 3-NN vote (a, b, b) b."""
    features, labels = _line()
    assert NearestNeighbourClassifier(1).fit(features, labels).predict([[1.9]])[0] == "a"
    three = NearestNeighbourClassifier(3).fit(features, labels)
    assert three.predict([[1.9]])[0] == "b"
    distances, indices = three.kneighbours([[1.9]])
    assert np.allclose(distances, [[0.9, 1.1, 1.6]]) and indices.tolist() == [[1, 2, 3]]
    assert list(three.classes_) == ["a", "b", "c"]


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
    assert lda.estimator_.covariance_estimator.shrinkage == "auto"
    assert list(lda.classes_) == ["A", "B"]


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


@pytest.mark.parametrize("shrinkage", [0.3, "auto"])
def test_lda_without_sklearns_own_checks_is_sklearns_lda_to_the_bit(shrinkage):
    """The shrinkage LDA skips scikit-learn's input checks (dmpopt checks the inputs) and
    recalls the covariances of classes it has seen: the same coefficients and predictions as
    scikit-learn's LDA with its checks and its own covariances, and the checks are back on
    afterwards.

    Answer key: ``LinearDiscriminantAnalysis(solver="lsqr")`` called directly.
    """
    sklearn = pytest.importorskip("sklearn")
    from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

    rng = np.random.default_rng(4)
    features = rng.standard_normal((40, 7)) + np.repeat(np.eye(4, 7) * 2.0, 10, axis=0)
    labels = np.repeat(np.arange(4), 10)
    queries = rng.standard_normal((9, 7))
    # a fit, the same again (its class covariances recalled), one without sample 3 (the
    # other classes' recalled, its class's new), and with a second class changed
    changed = features.copy()
    changed[15] += 0.5
    for rows, samples in (
        (slice(None), features),
        (slice(None), features),
        (np.arange(40) != 3, features),
        (slice(None), changed),
    ):
        reference = LinearDiscriminantAnalysis(solver="lsqr", shrinkage=shrinkage)
        reference.fit(samples[rows], labels[rows])
        classifier = ShrinkageLdaClassifier(shrinkage).fit(samples[rows], labels[rows])
        np.testing.assert_array_equal(classifier.estimator_.coef_, reference.coef_)
        np.testing.assert_array_equal(classifier.predict(queries), reference.predict(queries))
    assert sklearn.get_config()["assume_finite"] is False
    assert sklearn.get_config()["skip_parameter_validation"] is False


def test_leave_one_out_on_a_hand_computed_line():
    """1-NN, each query against the samples but its own, written out on _line (0, 1, 3,
    3.5, 10: a a b b c): the samples themselves give a a b b b (10's nearest other is 3.5);
    queries 0.6, 1.2, 2.0, 3.6, 9.0 give a a a b b (2.0 without 3 is nearest to 1)."""
    features, labels = _line()
    classifier = NearestNeighbourClassifier(1)
    assert classifier.leave_one_out(features, labels, features).tolist() == list("aabbb")
    queries = [[0.6], [1.2], [2.0], [3.6], [9.0]]
    assert classifier.leave_one_out(features, labels, queries).tolist() == list("aaabb")


def test_leave_one_out_names_each_bad_argument():
    features, labels = _line()
    for k in (5, 1.5, True):
        with pytest.raises(InvalidInputError, match="^n_neighbours must be a positive integer"):
            NearestNeighbourClassifier(k).leave_one_out(features, labels, features)
    with pytest.raises(InvalidInputError, match="^queries"):
        NearestNeighbourClassifier(1).leave_one_out(features, labels, features * np.nan)
    with pytest.raises(ShapeError, match="^queries"):
        NearestNeighbourClassifier(1).leave_one_out(features, labels, np.zeros((5, 2)))


@pytest.mark.parametrize(
    "module", ["discriminant_analysis", "_config", "covariance", "preprocessing"]
)
def test_lda_without_scikit_learn_says_which_extra_installs_it(monkeypatch, module):
    """Each scikit-learn module the LDA imports, missing, gives the install hint naming
    ShrinkageLdaClassifier (in fit; and in predict, after a fit with it)."""
    from dmpopt.exceptions import MissingDependency
    from dmpopt.recognition import _checks

    rng = np.random.default_rng(len(module))  # other samples than other tests' (recalled)
    features, labels = rng.normal(size=(20, 3)), np.repeat(["a", "b"], 10)
    fitted = ShrinkageLdaClassifier(shrinkage="auto").fit(features + 1.0, labels)
    imported = _checks.importlib.import_module

    def without(name, *args):
        if name == f"sklearn.{module}":
            raise ImportError(name)
        return imported(name, *args)

    monkeypatch.setattr(_checks.importlib, "import_module", without)
    hint = "^ShrinkageLdaClassifier needs scikit-learn, which is not installed"
    with pytest.raises(MissingDependency, match=hint):
        ShrinkageLdaClassifier(shrinkage="auto").fit(features, labels)
    if module == "_config":
        with pytest.raises(MissingDependency, match=hint):
            fitted.predict(features)


def test_lda_predict_names_features_of_the_wrong_width():
    features, labels = np.random.default_rng(4).normal(size=(20, 3)), np.repeat(["a", "b"], 10)
    fitted = ShrinkageLdaClassifier().fit(features, labels)
    with pytest.raises(ShapeError, match="^features"):
        fitted.predict(np.zeros((2, 4)))
