"""Leave-one-out evaluation and confusion matrices, with scikit-learn's splitter and counter."""

from __future__ import annotations

import copy

import numpy as np

from ..exceptions import InvalidInputError, ShapeError
from ._checks import check_labels, sklearn
from .classifiers import NearestNeighbourClassifier


def _take(samples, indices):
    if isinstance(samples, np.ndarray):
        return samples[indices]
    return [samples[i] for i in indices]


def leave_one_out(classifier, samples, labels, queries=None) -> np.ndarray:
    """Leave-one-out predictions: sample ``i`` classified by a copy fitted on all others.

    The splits are ``sklearn.model_selection.LeaveOneOut``'s. Unlike
    ``sklearn.model_selection.cross_val_predict``, the held-out sample may be replaced by a
    query (a transformed copy of it, or its first part), and the samples may be DMPs.

    Parameters
    ----------
    classifier
        Any object with ``fit(samples, labels)`` and ``predict(queries)``; it is copied,
        never fitted itself.
    samples : ndarray, shape (n_samples, ...) or sequence
        Training samples: feature rows, or DMPs for
        :class:`~dmpopt.recognition.PartialObservationClassifier`.
    labels : array_like, shape (n_samples,)
    queries : ndarray or sequence, optional
        What is classified in place of sample ``i`` when it is left out; defaults to
        ``samples``.

    Returns
    -------
    ndarray, shape (n_samples,)
    """
    return leave_one_out_sets(classifier, samples, labels, [queries])[0]


def leave_one_out_sets(classifier, samples, labels, query_sets) -> list:
    """:func:`leave_one_out` for several query sets, each split's copy fitted once for all.

    Parameters
    ----------
    classifier, samples, labels
        As for :func:`leave_one_out`.
    query_sets : sequence
        Query sets as ``queries`` of :func:`leave_one_out` (None: ``samples`` themselves).

    Returns
    -------
    list of ndarray, shape (n_samples,) each
        The predictions of each query set, equal to :func:`leave_one_out` on it.
    """
    if not (hasattr(classifier, "fit") and hasattr(classifier, "predict")):
        raise InvalidInputError(
            f"classifier must have fit() and predict(), got {type(classifier).__name__}"
        )
    if not hasattr(samples, "__len__") or isinstance(samples, (str, bytes)):
        raise InvalidInputError(
            f"samples must be an array of feature rows or a list of DMPs, got "
            f"{type(samples).__name__}"
        )
    labels = check_labels(labels, len(samples))
    if labels.size < 2:
        raise InvalidInputError("leave_one_out needs at least two samples")
    if not hasattr(query_sets, "__iter__") or isinstance(query_sets, (str, bytes)):
        raise InvalidInputError(
            f"query_sets must be a list of query sets, got {type(query_sets).__name__}"
        )
    query_sets = [samples if queries is None else queries for queries in query_sets]
    for queries in query_sets:
        if not hasattr(queries, "__len__") or isinstance(queries, (str, bytes)):
            raise InvalidInputError(
                f"queries must be an array or a list with one entry per sample, got "
                f"{type(queries).__name__}"
            )
        if len(queries) != labels.size:
            raise ShapeError(
                f"queries has {len(queries)} entries, expected {labels.size}: one per sample"
            )
    if isinstance(classifier, NearestNeighbourClassifier):  # one tree serves every split
        return [classifier.leave_one_out(samples, labels, queries) for queries in query_sets]
    splits = sklearn("model_selection", "leave_one_out").LeaveOneOut().split(labels)
    predictions = [[] for _ in query_sets]
    for others, held_out in splits:
        fitted = copy.deepcopy(classifier).fit(_take(samples, others), labels[others])
        for found, queries in zip(predictions, query_sets):
            found.append(fitted.predict(_take(queries, held_out))[0])
    return [np.array(found) for found in predictions]


def confusion_matrix(labels, predictions, classes=None) -> np.ndarray:
    """Count the samples of class ``classes[i]`` predicted as ``classes[j]``, at ``[i, j]``.

    ``sklearn.metrics.confusion_matrix``; ``classes`` defaults to the sorted distinct values
    of ``labels`` and ``predictions``, and must hold every one of them.
    """
    labels = np.asarray(labels)
    if labels.ndim != 1:
        raise ShapeError(f"labels has shape {labels.shape}, expected (n_samples,)")
    labels = check_labels(labels, labels.size)
    predictions = check_labels(predictions, labels.size)
    seen = np.unique(np.concatenate([labels, predictions]))
    classes = seen if classes is None else np.asarray(classes)
    if classes.ndim != 1 or classes.size == 0:
        raise ShapeError(f"classes has shape {classes.shape}, expected (n_classes,)")
    known = classes.tolist()
    if len(set(known)) != len(known):
        raise InvalidInputError(f"classes repeats a label: {known!r:.80}; list each once")
    unknown = sorted({str(v) for v in seen.tolist() if v not in set(known)})
    if unknown:
        raise InvalidInputError(
            f"labels {unknown} are not in classes; add them to classes or leave it out"
        )
    metrics = sklearn("metrics", "confusion_matrix")
    return metrics.confusion_matrix(labels, predictions, labels=classes)
