r"""Classifiers of feature vectors, computed by scikit-learn (extra `recognition`).

Each wraps a scikit-learn estimator (``estimator_`` once fitted) and checks its inputs first,
so a bad input is refused with a message that names it. They follow scikit-learn's
conventions: ``__init__`` stores the hyper-parameters, ``fit`` returns ``self``, fitted
attributes end in ``_``.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import InvalidInputError
from ..fitting._recall import Recall, exact
from ..validation import check_resources, real
from ._checks import check_features, check_fitted, check_labels, checked_by_dmpopt, sklearn


class NearestNeighbourClassifier:
    """k-nearest-neighbour vote in Euclidean feature space, the paper's choice (Section 3.8).

    ``sklearn.neighbors.KNeighborsClassifier`` with uniform votes, searching a k-d tree:
    exact distances, and on the 209 x 464 features of the LASA study a fit and a query cost
    about 5 ms of CPU against 36-46 ms for scikit-learn's brute-force search (measured on a
    loaded 2-core machine). A vote tied between classes goes to the first of them in
    ``classes_`` (sorted labels).

    Parameters
    ----------
    n_neighbours : int
        Neighbours that vote.

    Attributes
    ----------
    classes_ : ndarray, shape (n_classes,)
        Sorted distinct labels.
    estimator_ : sklearn.neighbors.KNeighborsClassifier
    """

    def __init__(self, n_neighbours: int = 1):
        self.n_neighbours = n_neighbours

    def fit(self, features, labels) -> NearestNeighbourClassifier:
        """Store the training set; returns ``self``."""
        n = self.n_neighbours
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise InvalidInputError(f"n_neighbours must be a positive integer, got {n!r}")
        features = check_features(features)
        labels = check_labels(labels, features.shape[0])
        if n > features.shape[0]:
            raise InvalidInputError(
                f"n_neighbours = {n} exceeds the {features.shape[0]} training samples"
            )
        neighbors = sklearn("neighbors", "NearestNeighbourClassifier")
        self.estimator_ = neighbors.KNeighborsClassifier(int(n), algorithm="kd_tree")
        self.estimator_.fit(features, labels)
        self.classes_ = self.estimator_.classes_
        return self

    def kneighbours(self, features) -> tuple[np.ndarray, np.ndarray]:
        """Distances and indices of the nearest training samples, each (n_queries, k)."""
        queries = self._queries(features)
        return self.estimator_.kneighbors(queries)

    def predict(self, features) -> np.ndarray:
        """Predicted label of each row of ``features``, shape (n_queries,)."""
        queries = self._queries(features)
        return self.estimator_.predict(queries)

    def leave_one_out(self, features, labels, queries) -> np.ndarray:
        """Leave-one-out predictions from one tree: query ``i`` against all samples but ``i``.

        Each query's ``n_neighbours + 1`` nearest samples, sample ``i`` dropped (else the
        farthest), vote as :meth:`predict` (ties to the first class in sorted order). The
        distances are the same sums as in a tree fitted on the others, so the predictions
        are those of :func:`~dmpopt.recognition.leave_one_out` refitting for every sample
        (the order of exactly equal distances aside); one fit instead of ``n_samples``.
        """
        features = check_features(features)
        labels = check_labels(labels, features.shape[0])
        n = features.shape[0]
        k = self.n_neighbours
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k < n:
            raise InvalidInputError(
                f"n_neighbours must be a positive integer below the {n} samples (one is left "
                f"out), got {k!r}"
            )
        queries = check_features(queries, "queries", n_features=features.shape[1])
        if queries.shape[0] != n:
            raise InvalidInputError(
                f"queries has {queries.shape[0]} rows, expected {n}: one per sample"
            )
        fitted = NearestNeighbourClassifier(int(k) + 1).fit(features, labels)
        _, nearest = fitted.estimator_.kneighbors(queries)
        classes, index = np.unique(labels, return_inverse=True)
        predictions = []
        for i, row in enumerate(nearest):
            kept = row[row != i][:k]
            predictions.append(classes[np.argmax(np.bincount(index[kept], minlength=classes.size))])
        return np.array(predictions)

    def _queries(self, features) -> np.ndarray:
        check_fitted(self, "estimator_")
        return check_features(features, n_features=self.estimator_.n_features_in_)


class ShrinkageLdaClassifier:
    r"""Linear discriminant analysis with a shrunk pooled covariance.

    ``sklearn.discriminant_analysis.LinearDiscriminantAnalysis(solver="lsqr", shrinkage)``:
    the class whose mean is nearest in the Mahalanobis distance of the pooled within-class
    covariance :math:`\Sigma` (the mean of the samples' outer products about their class
    mean), shrunk towards a multiple of the identity,
    :math:`(1 - \gamma)\Sigma + \gamma\, \mathrm{tr}(\Sigma)/p\, I`, less the log of the
    class's share of the training samples.

    Parameters
    ----------
    shrinkage : float or "auto"
        :math:`\gamma` in (0, 1], or ``"auto"`` for the Ledoit-Wolf estimate of
        :math:`\gamma` (on standardised features). Needed when there are fewer samples than
        features.

    Attributes
    ----------
    classes_ : ndarray, shape (n_classes,)
    estimator_ : sklearn.discriminant_analysis.LinearDiscriminantAnalysis
    """

    def __init__(self, shrinkage: float | str = 0.1):
        self.shrinkage = shrinkage

    def fit(self, features, labels) -> ShrinkageLdaClassifier:
        """Class means and the shrunk pooled covariance; returns ``self``."""
        shrinkage = self.shrinkage
        if isinstance(shrinkage, str) and shrinkage != "auto":
            raise InvalidInputError(
                f"shrinkage must be a number in (0, 1] or 'auto', got {shrinkage!r}"
            )
        if shrinkage != "auto":
            shrinkage = real("shrinkage", shrinkage, minimum=0.0, maximum=1.0, open_minimum=True)
        features = check_features(features)
        check_resources(
            f"the covariance of {features.shape[1]} features",
            8.0 * (features.shape[1] ** 2),
            "reduce the features (e.g. fewer basis functions or path samples)",
        )
        labels = check_labels(labels, features.shape[0])
        classes, index = np.unique(labels, return_inverse=True)
        if classes.size < 2:
            raise InvalidInputError(
                f"labels hold the single class {classes[0].item()!r}; LDA needs at least two "
                "classes"
            )
        means = np.stack([features[index == k].mean(axis=0) for k in range(classes.size)])
        if not np.any(features - means[index]):
            raise InvalidInputError(
                "features do not vary within any class, so LDA has no within-class covariance "
                "to estimate; give some class two distinct samples or use "
                "NearestNeighbourClassifier"
            )
        analysis = sklearn("discriminant_analysis", "ShrinkageLdaClassifier")
        self.estimator_ = analysis.LinearDiscriminantAnalysis(
            solver="lsqr", covariance_estimator=_ClassCovariance(shrinkage)
        )
        with checked_by_dmpopt("ShrinkageLdaClassifier"):
            self.estimator_.fit(features, labels)
        self.classes_ = self.estimator_.classes_
        return self

    def predict(self, features) -> np.ndarray:
        """Predicted label of each row of ``features``, shape (n_queries,)."""
        check_fitted(self, "estimator_")
        features = check_features(features, n_features=self.estimator_.n_features_in_)
        with checked_by_dmpopt("ShrinkageLdaClassifier"):
            return self.estimator_.predict(features)


class _ClassCovariance:
    """The covariance of one class's samples as ``LinearDiscriminantAnalysis(shrinkage=...)``
    estimates it: the empirical covariance shrunk by ``shrinkage``, or for ``"auto"`` the
    Ledoit-Wolf estimate of the standardised samples scaled back (scikit-learn's functions,
    composed as that estimator composes them, so the same bits).

    Recalled for samples seen before: the fits of a leave-one-out share every class but the
    held-out sample's (29 of 30 covariances of each LASA fit).
    """

    def __init__(self, shrinkage: float | str):
        self.shrinkage = shrinkage

    def fit(self, samples: np.ndarray) -> _ClassCovariance:
        key = (self.shrinkage, exact(samples))
        self.covariance_ = _COVARIANCES(key, lambda: self._estimate(samples))
        return self

    def _estimate(self, samples: np.ndarray) -> np.ndarray:
        covariance = sklearn("covariance", "ShrinkageLdaClassifier")
        if self.shrinkage == "auto":
            scaler = sklearn("preprocessing", "ShrinkageLdaClassifier").StandardScaler()
            standardised = covariance.ledoit_wolf(scaler.fit_transform(samples))[0]
            return scaler.scale_[:, np.newaxis] * standardised * scaler.scale_[np.newaxis, :]
        return covariance.shrunk_covariance(
            covariance.empirical_covariance(samples), self.shrinkage
        )


_COVARIANCES = Recall(96)
"""Class covariances of the last exact samples (a leave-one-out over 30 classes reuses 29 of
them in each fit)."""
