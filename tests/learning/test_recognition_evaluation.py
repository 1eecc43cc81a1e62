"""Tests of dmpopt.recognition.evaluation: leave-one-out and the confusion matrix."""

import numpy as np
from recognition_shapes import _line, _raises

from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.recognition import (
    NearestNeighbourClassifier,
    confusion_matrix,
    leave_one_out,
    leave_one_out_sets,
)


def test_confusion_matrix_counts():
    """Rows are true classes, columns predictions."""
    matrix = confusion_matrix(["a", "a", "b", "c"], ["a", "b", "b", "a"], classes=["a", "b", "c"])
    assert matrix.tolist() == [[1, 1, 0], [0, 1, 0], [1, 0, 0]]


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


def test_leave_one_out_on_a_hand_computed_line():
    """Each sample (or its query) classified by 1-NN fitted on the four others."""
    features, labels = _line()
    nearest = NearestNeighbourClassifier()
    assert leave_one_out(nearest, features, labels).tolist() == list("aabbb")
    # query 9 for every sample: nearest is 10 (c), except when 10 is left out (3.5, b)
    queries = np.full((5, 1), 9.0)
    assert leave_one_out(nearest, features, labels, queries).tolist() == list("ccccb")
    assert not hasattr(nearest, "estimator_")  # copies are fitted, never the classifier


def test_confusion_matrix_keeps_the_order_of_classes():
    """Rows and columns follow ``classes``; by default the sorted labels."""
    matrix = confusion_matrix([2, 2, 0, 1], [2, 0, 0, 0], classes=[2, 1, 0])
    assert matrix.tolist() == [[1, 0, 1], [0, 0, 1], [0, 0, 1]]
    assert confusion_matrix([2, 2, 0, 1], [2, 0, 0, 0]).tolist() == [
        [1, 0, 0],
        [1, 0, 0],
        [1, 0, 1],
    ]


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


class _FitOnly:
    def fit(self, samples, labels):
        return self


def test_leave_one_out_needs_fit_and_predict():
    """An object without predict is refused before any fit."""
    with _raises(InvalidInputError, "classifier must have fit() and predict(), got _FitOnly"):
        leave_one_out(_FitOnly(), np.eye(3), [0, 1, 1])


def test_nearest_neighbour_leave_one_out_matches_refitting_for_every_sample():
    """One tree queried for k + 1 neighbours gives the predictions of a classifier refitted
    without each sample (the answer key: a fit per held-out sample, queried alone), for
    several k, with the samples themselves and with moved queries as the held-out inputs."""
    rng = np.random.default_rng(8)
    features = rng.normal(size=(20, 4))
    labels = rng.choice(np.array(["a", "b", "c"]), size=20)
    moved = features + 0.8 * rng.normal(size=features.shape)
    for k in (1, 4):
        for queries in (features, moved):
            expected = []
            for i in range(20):
                others = np.arange(20) != i
                fitted = NearestNeighbourClassifier(k).fit(features[others], labels[others])
                expected.append(fitted.predict(queries[[i]])[0])
            got = leave_one_out(NearestNeighbourClassifier(k), features, labels, queries)
            assert got.tolist() == expected


class _CountingNearest:
    """1-NN in plain numpy that counts its fits (shared by its copies)."""

    fits = [0]

    def fit(self, features, labels):
        self.fits[0] += 1
        self.features, self.labels = np.asarray(features), np.asarray(labels)
        return self

    def predict(self, queries):
        distances = np.abs(np.asarray(queries)[:, None, 0] - self.features[None, :, 0])
        return self.labels[np.argmin(distances, axis=1)]


def test_leave_one_out_sets_fit_each_split_once():
    """Two query sets, one fit per split; on the line 0, 1, 3, 3.5, 10 (a a b b c) sample i
    is classified by the nearest other sample, and so is its moved query (sample + 2.2)."""
    features, labels = _line()
    _CountingNearest.fits[0] = 0
    plain, moved = leave_one_out_sets(_CountingNearest(), features, labels, [None, features + 2.2])
    assert _CountingNearest.fits[0] == 5
    assert plain.tolist() == list("aabbb")  # 0->1, 1->0, 3->3.5, 3.5->3, 10->3.5
    assert moved.tolist() == list("bbbbb")  # 2.2->3, 3.2->3, 5.2->3.5, 5.7->3, 12.2->3.5
