r"""Movement recognition from DMP weights (Section 3.8 of [dmpopt-paper]).

The forcing weights :math:`w` of a discrete DMP fitted in position space (see
:func:`dmpopt.fit_discrete`) transform with the demonstration in a simple way:

* translating the demonstration leaves :math:`w` unchanged (the transformation system is
  linear and written in :math:`g - y`);
* scaling it uniformly by :math:`s` multiplies :math:`w` by :math:`s`, and rotating it by
  :math:`Q` gives :math:`Q w` (each column of :math:`w` is a vector of the task space);
* stretching it in time changes :math:`\tau` only: :math:`w` is unchanged.

:func:`normalised_weights` undoes the rotation and scaling with the start-goal vector
:math:`d = g - y_0`:

.. math:: \bar w = S(d \to e_1)\, w, \qquad S(d \to e_1) = \frac{1}{\|d\|} R(d \to e_1)

(:func:`dmpopt.similarity_transform`), which is exactly invariant to translation, uniform
scaling and time stretching, and, in two dimensions, to rotation (in more dimensions the
smallest rotation onto :math:`e_1` is not unique up to a rotation about :math:`d`).

:func:`movement_features` turns :math:`\bar w` into a feature vector for classification:

* distances between weight vectors are measured in the metric the DMP induces on them, the
  mean squared difference of the plans they generate (``metric="plan"``, the default):
  with :math:`\Phi` the plan's response to the weights (:class:`dmpopt.dmp.AffinePlan`) in
  normalised time, :math:`\|\bar w_1 - \bar w_2\|_G^2 = \frac{1}{N} \|\Phi (\bar w_1 -
  \bar w_2)^T\|^2`. Raw Euclidean distances between weights are dominated by directions
  the plan hardly sees (nearby Gaussians with opposite weights), more so with many basis
  functions;
* the plan also depends on the initial velocity :math:`\dot y_0` that
  :func:`dmpopt.fit_discrete` starts it from (the demonstration's first velocity), which the
  weights do not hold: a demonstration that starts fast is fitted with weights that assume
  that start. Passed as ``start_velocities``, :math:`\bar v = S(d \to e_1)\, \tau \dot y_0`
  (invariant like :math:`\bar w`) joins the weights, so the metric compares the plans the
  DMPs were fitted to reproduce (:func:`normalised_plan`);
* the same normalised plan resampled at equal arc length (its *path*, ``path_weight``):
  the plan metric compares positions at equal times, so one demonstration that traces the
  path of its class with a different speed profile is far from it; its path is not;
* the unit start-goal direction :math:`d / \|d\|`, times ``direction_weight``, is appended:
  shapes such as a "J" drawn upright or tilted have close :math:`\bar w` and differ in the
  direction in which they travel. Set ``direction_weight=0`` for rotation-invariant features.

Because the features are exactly invariant to uniform scaling, movements that differ only in
size get identical features: classes defined partly by size (in LASA, Multi_Models_4 demos
5-7 are a Trapezoid at half its size) cannot be separated by any classifier on them.

Classifiers follow scikit-learn's conventions (``fit`` returns ``self``, fitted attributes
end in ``_``): :class:`NearestNeighbourClassifier` (the paper's choice) and
:class:`ShrinkageLdaClassifier` (linear discriminant analysis with a shrunk pooled
covariance). :class:`PartialObservationClassifier` recognises a movement from its
beginning only, by matching it against the beginnings of the DMPs' plans.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import numpy as np

from .dmp import DiscreteDMP, similarity_transform
from .exceptions import InvalidInputError, ShapeError
from .trajectory import Trajectory
from .validation import check_resources, integer, real, real_array

METRICS = ("plan", "euclidean")
MAX_SAMPLES = 100_000
"""Largest ``n_samples`` (or ``plan_samples``): each is a step of a DMP rollout."""
MAX_FEATURE = 1e150
"""Features beyond this magnitude would overflow their squared distances."""
DEGENERATE_DISPLACEMENT = 1e-9
"""Start-goal distances at or below this fraction of the forcing weights' size count as zero."""


# ---------------------------------------------------------------------------------------
# Features
# ---------------------------------------------------------------------------------------


def _check_dmp(dmp, name: str = "dmp") -> DiscreteDMP:
    if not isinstance(dmp, DiscreteDMP):
        raise InvalidInputError(
            f"{name} must be a DiscreteDMP, got {type(dmp).__name__}; fit one with "
            "dmpopt.fit_discrete(demo, n_basis)"
        )
    return dmp


def _displacement(dmp: DiscreteDMP) -> tuple[np.ndarray, np.ndarray]:
    """Return forcing weights and start-goal vector; raise if the vector is (numerically) zero."""
    forcing = np.asarray(dmp.forcing_weights())
    displacement = np.asarray(dmp.goal) - np.asarray(dmp.start)
    size = float(np.abs(forcing).max(initial=0.0))
    if not np.linalg.norm(displacement) > DEGENERATE_DISPLACEMENT * size:
        raise InvalidInputError(
            "the DMP's goal equals its start, so its weights cannot be normalised by the "
            "start-goal vector; recognition needs point-to-point movements (for a closed "
            "movement, compare dmp.forcing_weights() divided by their norm instead)"
        )
    return forcing, displacement


def _start_goal_frame(dmp: DiscreteDMP) -> tuple[np.ndarray, np.ndarray]:
    r"""Forcing weights and :math:`S(d \to e_1)`; raise if :math:`d` is (numerically) zero."""
    forcing, displacement = _displacement(dmp)
    axis = np.zeros_like(displacement)
    axis[0] = 1.0
    return forcing, similarity_transform(displacement, axis)


def normalised_weights(dmp: DiscreteDMP) -> np.ndarray:
    r"""Express the forcing weights in the start-goal frame, per unit of the start-goal distance.

    :math:`\bar w = S(d \to e_1) w` with :math:`d = g - y_0` (module docstring). Exactly
    invariant to translating, uniformly scaling and time-stretching the demonstration the
    DMP was fitted to, and in two dimensions to rotating it.

    Parameters
    ----------
    dmp : DiscreteDMP
        A fitted DMP with ``goal != start``.

    Returns
    -------
    ndarray, shape (n_dofs, n_basis)
    """
    forcing, frame = _start_goal_frame(_check_dmp(dmp))
    return frame @ forcing


def _check_start_velocity(value, n_dofs: int) -> np.ndarray:
    if value is None:
        return np.zeros(n_dofs)
    velocity = np.atleast_1d(real_array("start_velocity", value))
    if velocity.shape != (n_dofs,):
        raise ShapeError(
            f"start_velocity has shape {velocity.shape}, expected ({n_dofs},): the DMP's first "
            "velocity, one value per DOF (fit_discrete starts from demo.velocities[0])"
        )
    return velocity


def _check_n_samples(n_samples, name: str = "n_samples") -> int:
    return integer(name, n_samples, minimum=3, maximum=MAX_SAMPLES, fix="a few hundred suffice")


def normalised_plan(dmp: DiscreteDMP, start_velocity=None, n_samples: int = 200) -> np.ndarray:
    r"""The DMP's plan in the start-goal frame, per unit of the start-goal distance.

    The plan of the DMP with weights :math:`\bar w` (:func:`normalised_weights`), start 0,
    goal :math:`e_1`, :math:`\tau = 1` and initial velocity
    :math:`\bar v = S(d \to e_1)\, \tau \dot y_0`, sampled at ``n_samples`` equally spaced
    times over its convergence time. It is :math:`S(d \to e_1)(y(t) - y_0)` for the DMP's
    own plan from ``start_velocity``, at :math:`t` in :math:`[0, T]` normalised to
    :math:`[0, 1]`, so it is invariant like :math:`\bar w`.

    Parameters
    ----------
    dmp : DiscreteDMP
        A fitted DMP with ``goal != start``.
    start_velocity : array_like, shape (n_dofs,), optional
        Initial velocity [units/s] of the plan; :func:`dmpopt.fit_discrete` fits the weights
        for ``demo.velocities[0]``. Defaults to rest.
    n_samples : int
        Samples of the plan.

    Returns
    -------
    ndarray, shape (n_samples, n_dofs)
        Starts at 0 and ends near :math:`e_1`.
    """
    dmp = _check_dmp(dmp)
    n_samples = _check_n_samples(n_samples)
    velocity = _check_start_velocity(start_velocity, dmp.n_dofs)
    forcing, frame = _start_goal_frame(dmp)
    return _unit_plan(dmp, frame @ forcing, frame @ (dmp.tau * velocity), n_samples)


def _unit_plan(dmp: DiscreteDMP, weights, velocity, n_samples: int) -> np.ndarray:
    r"""Plan of ``dmp``'s system from 0 to :math:`e_1` with :math:`\tau = 1`, normalised
    weights :math:`\bar w` and initial velocity :math:`\bar v` (:func:`normalised_plan`)."""
    unit_goal = np.zeros(dmp.n_dofs)
    unit_goal[0] = 1.0
    unit = dmp.replace(
        weights=weights,
        start=np.zeros(dmp.n_dofs),
        goal=unit_goal,
        tau=1.0,
        goal_scaling="translation",
        reference_displacement=None,
    )
    duration = unit.convergence_time
    plan = unit.rollout(duration, duration / (n_samples - 1), start_velocity=velocity)
    return plan.positions[:n_samples]


def arc_length_resampled(positions, n_samples: int) -> np.ndarray:
    """Points at ``n_samples`` equal arc-length steps along a polyline (linear), (n, n_dofs).

    The path of a curve, independent of the speed at which it is traced.
    """
    positions = real_array("positions", positions)
    n_samples = _check_n_samples(n_samples)
    if positions.ndim != 2 or positions.shape[0] < 2:
        raise ShapeError(f"positions has shape {positions.shape}, expected (n_points, n_dofs)")
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    length = np.concatenate([[0.0], np.cumsum(steps)])
    if not length[-1] > 0.0:
        raise InvalidInputError("positions do not move, so they have no path to resample")
    grid = np.linspace(0.0, length[-1], n_samples)
    return np.stack([np.interp(grid, length, p) for p in positions.T], axis=1)


def plan_metric_factor(
    dmp: DiscreteDMP, n_samples: int = 200, start_velocity: bool = False
) -> np.ndarray:
    r"""Factor :math:`L` with :math:`L L^T = G = \Phi^T \Phi / N`, the plan metric on weights.

    :math:`\Phi` (shape (N, n_basis)) is the response of one DOF's plan to its weights,
    sampled at ``N = n_samples`` equally spaced times over the DMP's convergence time, in
    time normalised by :math:`\tau`. For weights :math:`W` of shape (n_dofs, n_basis),
    :math:`\|W L\|_F^2` is the mean squared (summed over DOFs) position difference that
    :math:`W` makes to the plan. It depends only on the form, basis and gains of ``dmp``.
    With ``start_velocity``, :math:`\Phi` gets one more column, the plan's response to the
    initial velocity :math:`\tau \dot y_0`, and :math:`W` one more column, :math:`\tau \dot y_0`.

    Returns
    -------
    ndarray, shape (n_basis, n_basis), or (n_basis + 1, n_basis + 1) with ``start_velocity``
    """
    dmp = _check_dmp(dmp)
    n_samples = _check_n_samples(n_samples)
    unit = dmp.with_tau(1.0)
    duration = unit.convergence_time
    dt = duration / (n_samples - 1)
    plan = unit.affine_plan(duration, dt, start_velocity=0.0)
    response = plan.weight_response[0][:n_samples]
    if start_velocity:
        push = np.zeros(dmp.n_dofs)
        push[0] = 1.0
        moving = unit.affine_plan(duration, dt, start_velocity=push)
        column = (moving.free[0] - plan.free[0])[:n_samples, 0]
        response = np.column_stack([response, column])
    gram = response.T @ response / response.shape[0]
    eigenvalues, eigenvectors = np.linalg.eigh(gram)
    return eigenvectors * np.sqrt(np.clip(eigenvalues, 0.0, None))


def _same_system(reference: DiscreteDMP, other: DiscreteDMP, index: int):
    if other.weights.shape != reference.weights.shape:
        raise ShapeError(
            f"dmps[{index}] has weights of shape {other.weights.shape}, expected "
            f"{reference.weights.shape} like dmps[0]; fit all movements with the same n_basis "
            "and number of DOFs"
        )
    same = (
        other.form == reference.form
        and np.allclose(other.centres, reference.centres)
        and np.allclose(other.widths, reference.widths)
        and np.allclose(other.gains, reference.gains)
    )
    if not same:
        raise InvalidInputError(
            f"dmps[{index}] has a different form, basis or gains than dmps[0]; weights are "
            "only comparable between DMPs fitted with the same options"
        )


def _dmp_list(dmps) -> list:
    """``dmps`` as a non-empty list of DiscreteDMP (a single one is wrapped)."""
    if isinstance(dmps, DiscreteDMP):
        dmps = [dmps]
    if dmps is None or isinstance(dmps, (str, bytes)) or not hasattr(dmps, "__iter__"):
        raise InvalidInputError(
            f"dmps must be a sequence of fitted DiscreteDMP, got {type(dmps).__name__}"
        )
    dmps = list(dmps)
    if not dmps:
        raise InvalidInputError("dmps is empty; pass at least one fitted DiscreteDMP")
    for index, dmp in enumerate(dmps):
        _check_dmp(dmp, f"dmps[{index}]")
    return dmps


def _check_weight(name: str, value) -> float:
    return real(name, value, minimum=0.0)


def movement_features(
    dmps: Sequence[DiscreteDMP],
    *,
    start_velocities=None,
    metric: str = "plan",
    direction_weight: float = 1.0,
    path_weight: float = 1.0,
    n_samples: int = 200,
) -> np.ndarray:
    r"""Feature vectors for recognition, one row per DMP (module docstring).

    Each row is :math:`[\mathrm{vec}([\bar w\ \bar v] L),\ \mu\, \mathrm{vec}(P) / \sqrt{n},
    \ \lambda\, d / \|d\|]` with :math:`\bar w` from :func:`normalised_weights`,
    :math:`\bar v = S(d \to e_1) \tau \dot y_0` the normalised start velocity, :math:`L`
    from :func:`plan_metric_factor` (``metric="plan"``) or the identity
    (``metric="euclidean"``), :math:`P` the :func:`normalised_plan` resampled at
    :math:`n` = ``n_samples`` equal arc-length steps (:func:`arc_length_resampled`),
    :math:`\mu` = ``path_weight`` and :math:`\lambda` = ``direction_weight``. Euclidean
    distances between rows are then (squared) the mean squared difference of the normalised
    plans at equal times, plus :math:`\mu^2` times that at equal arc lengths, plus
    :math:`\lambda^2` times the squared chord between the travel directions.

    Parameters
    ----------
    dmps : sequence of DiscreteDMP
        Fitted with the same form, ``n_basis``, gains and number of DOFs.
    start_velocities : array_like, shape (n_dmps, n_dofs), optional
        The velocity each DMP's plan starts with, as in the fit: ``demo.velocities[0]`` for
        :func:`dmpopt.fit_discrete`. Defaults to rest.
    metric : {"plan", "euclidean"}
        How differences of the weights (and start velocities) are measured.
    direction_weight : float
        Weight of the start-goal direction; 0 gives rotation-invariant features (2-D).
    path_weight : float
        Weight of the path; 0 leaves it out (features of the weights alone).
    n_samples : int
        Samples of the plan metric (see :func:`plan_metric_factor`) and of the path.

    Returns
    -------
    ndarray, shape (n_dmps, n_dofs * (n_basis + 1) + n_dofs * n_samples + n_dofs)
        Invariant to translation, uniform scaling and time stretching of the movements (the
        path block is left out when ``path_weight`` is 0).
    """
    if not isinstance(metric, str) or metric not in METRICS:
        raise InvalidInputError(f"metric must be one of {METRICS}, got {metric!r}")
    direction_weight = _check_weight("direction_weight", direction_weight)
    path_weight = _check_weight("path_weight", path_weight)
    dmps = _dmp_list(dmps)
    for index, dmp in enumerate(dmps):
        _same_system(dmps[0], dmp, index)
    n_dofs = dmps[0].n_dofs
    if start_velocities is None:
        start_velocities = np.zeros((len(dmps), n_dofs))
    start_velocities = real_array("start_velocities", start_velocities)
    if start_velocities.shape != (len(dmps), n_dofs):
        raise ShapeError(
            f"start_velocities has shape {start_velocities.shape}, expected "
            f"({len(dmps)}, {n_dofs}): one first velocity per DMP (demo.velocities[0])"
        )
    n_samples = _check_n_samples(n_samples)
    if metric == "plan":
        factor = plan_metric_factor(dmps[0], n_samples, start_velocity=True)
    else:
        factor = np.eye(dmps[0].n_basis + 1)
    rows = []
    for dmp, velocity in zip(dmps, start_velocities):
        forcing, frame = _start_goal_frame(dmp)
        weights = np.column_stack([frame @ forcing, frame @ (dmp.tau * velocity)])
        parts = [(weights @ factor).ravel()]
        if path_weight > 0.0:
            plan = _unit_plan(dmp, weights[:, :-1], weights[:, -1], n_samples)
            path = arc_length_resampled(plan, n_samples)
            parts.append(path_weight / np.sqrt(n_samples) * path.ravel())
        displacement = np.asarray(dmp.goal) - np.asarray(dmp.start)
        parts.append(direction_weight * displacement / np.linalg.norm(displacement))
        rows.append(np.concatenate(parts))
    return np.array(rows)


# ---------------------------------------------------------------------------------------
# Classifiers on feature vectors
# ---------------------------------------------------------------------------------------


def _check_features(features, name: str = "features", n_features: int | None = None):
    if isinstance(features, np.ndarray) and features.ndim == 2 and features.size == 0:
        raise ShapeError(f"{name} has shape {features.shape}, expected (n_samples, n_features)")
    features = real_array(name, features)
    if features.ndim != 2:
        raise ShapeError(f"{name} has shape {features.shape}, expected (n_samples, n_features)")
    if np.abs(features).max() > MAX_FEATURE:
        raise InvalidInputError(
            f"{name} holds values up to {np.abs(features).max():.3g}, beyond {MAX_FEATURE:g} "
            "(their squared distances would overflow); rescale the features"
        )
    if n_features is not None and features.shape[1] != n_features:
        raise ShapeError(
            f"{name} has shape {features.shape}, expected (n_samples, {n_features}) like the "
            "features the classifier was fitted on"
        )
    return features


def _check_labels(labels, n_samples: int) -> np.ndarray:
    labels = np.asarray(labels)
    if labels.dtype.kind not in "iuUSb" and not (
        labels.dtype.kind == "f" and np.all(np.isfinite(labels))
    ):
        raise InvalidInputError(
            f"labels must be integers or strings, got dtype {labels.dtype} ({labels!r:.60})"
        )
    if labels.shape != (n_samples,):
        raise ShapeError(
            f"labels has shape {labels.shape}, expected ({n_samples},): one label per sample"
        )
    return labels


def _check_fitted(classifier, attribute: str):
    if not hasattr(classifier, attribute):
        raise InvalidInputError(
            f"this {type(classifier).__name__} is not fitted yet; call fit(...) first"
        )


def squared_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances between the rows of ``a`` and ``b``, shape (n_a, n_b)."""
    distances = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
    return np.maximum(distances, 0.0)


class NearestNeighbourClassifier:
    """k-nearest-neighbour classification in Euclidean feature space (Section 3.8).

    Parameters
    ----------
    n_neighbours : int
        Neighbours that vote; ties go to the class of the nearest of the tied neighbours.

    Attributes
    ----------
    features_ : ndarray, shape (n_samples, n_features)
    labels_ : ndarray, shape (n_samples,)
    classes_ : ndarray, shape (n_classes,)
        Sorted distinct labels.
    """

    def __init__(self, n_neighbours: int = 1):
        self.n_neighbours = n_neighbours

    def fit(self, features, labels) -> NearestNeighbourClassifier:
        """Store the training set; returns ``self``."""
        n = self.n_neighbours
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise InvalidInputError(f"n_neighbours must be a positive integer, got {n!r}")
        features = _check_features(features)
        labels = _check_labels(labels, features.shape[0])
        if n > features.shape[0]:
            raise InvalidInputError(
                f"n_neighbours = {n} exceeds the {features.shape[0]} training samples"
            )
        self.features_ = features.copy()
        self.labels_ = labels.copy()
        self.classes_ = np.unique(labels)
        return self

    def kneighbours(self, features) -> tuple[np.ndarray, np.ndarray]:
        """Distances and indices of the nearest training samples, each (n_queries, k)."""
        _check_fitted(self, "features_")
        features = _check_features(features, n_features=self.features_.shape[1])
        distances = squared_distances(features, self.features_)
        order = np.argsort(distances, axis=1, kind="stable")[:, : self.n_neighbours]
        return np.sqrt(np.take_along_axis(distances, order, axis=1)), order

    def predict(self, features) -> np.ndarray:
        """Predicted label of each row of ``features``, shape (n_queries,)."""
        _, neighbours = self.kneighbours(features)
        votes = self.labels_[neighbours]
        if self.n_neighbours == 1:
            return votes[:, 0]
        predictions = []
        for row in votes:
            names, counts = np.unique(row, return_counts=True)
            tied = set(names[counts == counts.max()].tolist())
            predictions.append(next(label for label in row if label in tied))
        return np.array(predictions)


class ShrinkageLdaClassifier:
    r"""Linear discriminant analysis with a shrunk pooled covariance.

    Predicts the class whose mean is nearest in the Mahalanobis distance of the pooled
    within-class covariance :math:`\Sigma`, shrunk towards a multiple of the identity:
    :math:`(1 - \gamma)\Sigma + \gamma\, \mathrm{tr}(\Sigma)/p\, I` (equal class priors).

    Parameters
    ----------
    shrinkage : float
        :math:`\gamma` in (0, 1]; needed when there are fewer samples than features.

    Attributes
    ----------
    classes_ : ndarray, shape (n_classes,)
    means_ : ndarray, shape (n_classes, n_features)
    whitening_ : ndarray, shape (n_features, n_features)
        :math:`\Sigma_\gamma^{-1/2}`.
    """

    def __init__(self, shrinkage: float = 0.1):
        self.shrinkage = shrinkage

    def fit(self, features, labels) -> ShrinkageLdaClassifier:
        """Class means and the whitening of the shrunk pooled covariance; returns ``self``."""
        shrinkage = real("shrinkage", self.shrinkage, minimum=0.0, maximum=1.0, open_minimum=True)
        features = _check_features(features)
        check_resources(
            f"the covariance of {features.shape[1]} features",
            8.0 * (features.shape[1] ** 2),
            "reduce the features (e.g. fewer basis functions or path samples)",
        )
        labels = _check_labels(labels, features.shape[0])
        classes, index = np.unique(labels, return_inverse=True)
        membership = np.eye(classes.size)[index]  # (n_samples, n_classes)
        means = membership.T @ features / membership.sum(axis=0)[:, None]
        residuals = features - means[index]
        covariance = residuals.T @ residuals / features.shape[0]
        scale = np.trace(covariance) / covariance.shape[0]
        if not scale > 0.0:
            scale = 1.0  # every class is a single point: plain nearest class mean
        covariance = (1.0 - shrinkage) * covariance + shrinkage * scale * np.eye(len(covariance))
        eigenvalues, eigenvectors = np.linalg.eigh(covariance)
        self.classes_ = classes
        self.means_ = means
        self.whitening_ = eigenvectors / np.sqrt(eigenvalues)
        return self

    def decision_distances(self, features) -> np.ndarray:
        """Squared Mahalanobis distance of each row to each class mean, (n_queries, n_classes)."""
        _check_fitted(self, "means_")
        features = _check_features(features, n_features=self.means_.shape[1])
        return squared_distances(features @ self.whitening_, self.means_ @ self.whitening_)

    def predict(self, features) -> np.ndarray:
        """Predicted label of each row of ``features``, shape (n_queries,)."""
        return self.classes_[np.argmin(self.decision_distances(features), axis=1)]


def _take(samples, indices):
    if isinstance(samples, np.ndarray):
        return samples[indices]
    return [samples[i] for i in indices]


def leave_one_out(classifier, samples, labels, queries=None) -> np.ndarray:
    """Leave-one-out predictions: sample ``i`` classified by a copy fitted on all others.

    Parameters
    ----------
    classifier
        Any object with ``fit(samples, labels)`` and ``predict(queries)``; it is copied,
        never fitted itself.
    samples : ndarray, shape (n_samples, ...) or sequence
        Training samples: feature rows, or DMPs for :class:`PartialObservationClassifier`.
    labels : array_like, shape (n_samples,)
    queries : ndarray or sequence, optional
        What is classified in place of sample ``i`` when it is left out (for example a
        transformed copy of it, or its first half); defaults to ``samples``.

    Returns
    -------
    ndarray, shape (n_samples,)
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
    labels = _check_labels(labels, len(samples))
    if labels.size < 2:
        raise InvalidInputError("leave_one_out needs at least two samples")
    queries = samples if queries is None else queries
    if len(queries) != labels.size:
        raise ShapeError(
            f"queries has {len(queries)} entries, expected {labels.size}: one per sample"
        )
    predictions = []
    everything = np.arange(labels.size)
    for i in everything:
        others = everything[everything != i]
        fitted = copy.deepcopy(classifier).fit(_take(samples, others), labels[others])
        predictions.append(fitted.predict(_take(queries, [i]))[0])
    return np.array(predictions)


def confusion_matrix(labels, predictions, classes=None) -> np.ndarray:
    """Count the samples of class ``classes[i]`` predicted as ``classes[j]``, at ``[i, j]``.

    ``classes`` defaults to the sorted distinct values of ``labels`` and ``predictions``.
    """
    labels = np.asarray(labels)
    if labels.ndim != 1:
        raise ShapeError(f"labels has shape {labels.shape}, expected (n_samples,)")
    labels = _check_labels(labels, labels.size)
    predictions = _check_labels(predictions, labels.size)
    if classes is None:
        classes = np.unique(np.concatenate([labels, predictions]))
    classes = list(np.asarray(classes).tolist())
    position = {label: i for i, label in enumerate(classes)}
    unknown = sorted(
        {str(v) for v in np.concatenate([labels, predictions]).tolist() if v not in position}
    )
    if unknown:
        raise InvalidInputError(f"labels {unknown} are not in classes")
    matrix = np.zeros((len(classes), len(classes)), dtype=int)
    for truth, guess in zip(labels.tolist(), predictions.tolist()):
        matrix[position[truth], position[guess]] += 1
    return matrix


# ---------------------------------------------------------------------------------------
# Partial observations
# ---------------------------------------------------------------------------------------


def _resample(times: np.ndarray, positions: np.ndarray, n_samples: int) -> np.ndarray:
    """Positions at ``n_samples`` equally spaced times over ``times`` (linear)."""
    grid = np.linspace(times[0], times[-1], n_samples)
    return np.stack([np.interp(grid, times, p) for p in positions.T], axis=1)


def _match_residuals(templates: np.ndarray, observed: np.ndarray, rotation: bool) -> np.ndarray:
    r"""Relative residual of the best similarity fit of each template onto the observation.

    Both are relative to their first sample. ``templates`` (K, n, D), ``observed`` (n, D).
    Minimises :math:`\|O - s T R\|^2` over the scale :math:`s \ge 0` (and a proper
    rotation :math:`R` if ``rotation``) and returns it divided by :math:`\|O\|^2`.
    """
    observed_norm = float((observed**2).sum())
    template_norms = (templates**2).sum(axis=(1, 2))
    cross = np.einsum("kni,nj->kij", templates, observed)  # T^T O
    if rotation:
        u, singular, vt = np.linalg.svd(cross)
        sign = np.sign(np.linalg.det(u @ vt))
        singular[:, -1] *= sign
        correlation = singular.sum(axis=1)
    else:
        correlation = np.trace(cross, axis1=1, axis2=2)
    correlation = np.maximum(correlation, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        explained = np.where(template_norms > 0, correlation**2 / template_norms, 0.0)
    return 1.0 - explained / observed_norm


class PartialObservationClassifier:
    r"""Recognise a movement from its beginning by matching it against the DMPs' plans.

    The weights of a DMP fitted to a partial movement differ from those of the whole one
    (the goal is unknown and the phase runs differently), so the weights are not compared
    directly. Instead each training DMP generates its plan; an observation (the first part
    of a movement, of unknown length relative to the whole) is compared with the first
    ``fraction`` of each plan, for every ``fraction`` in ``fractions``, after
    both are resampled to ``n_samples`` equally spaced times (so time stretching does not
    matter) and the plan is fitted onto the observation by the best translation (start onto
    start), uniform scaling and, if ``rotation``, rotation (Procrustes). The prediction is
    the label of the best-matching plan (1-nearest neighbour in the relative residual).

    Parameters
    ----------
    fractions : array_like
        Candidate fractions of the whole movement that the observation covers, in (0, 1].
    n_samples : int
        Samples of the compared curves.
    rotation : bool
        Also fit a rotation (then the direction of travel is ignored, like
        ``direction_weight=0`` in :func:`movement_features`).
    plan_samples : int
        Samples of each stored plan.

    Attributes
    ----------
    plans_ : ndarray, shape (n_templates, plan_samples, n_dofs)
        The training DMPs' plans relative to their start, on normalised time [0, 1].
    labels_ : ndarray, shape (n_templates,)
    classes_ : ndarray
    """

    def __init__(
        self,
        fractions=(0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7),
        n_samples: int = 50,
        rotation: bool = False,
        plan_samples: int = 400,
    ):
        self.fractions = fractions
        self.n_samples = n_samples
        self.rotation = rotation
        self.plan_samples = plan_samples

    def fit(self, dmps: Sequence[DiscreteDMP], labels) -> PartialObservationClassifier:
        """Roll out and store each DMP's plan over its fitted duration; returns ``self``."""
        fractions = np.atleast_1d(real_array("fractions", self.fractions))
        if (
            fractions.ndim != 1
            or fractions.size == 0
            or np.any(fractions <= 0)
            or np.any(fractions > 1)
        ):
            raise InvalidInputError(
                f"fractions must be a non-empty list of numbers in (0, 1], got {self.fractions!r}"
            )
        for name in ("n_samples", "plan_samples"):
            _check_n_samples(getattr(self, name), name)
        if not isinstance(self.rotation, (bool, np.bool_)):
            raise InvalidInputError(f"rotation must be True or False, got {self.rotation!r}")
        dmps = _dmp_list(dmps)
        labels = _check_labels(labels, len(dmps))
        plans = []
        for index, dmp in enumerate(dmps):
            if dmp.n_dofs != dmps[0].n_dofs:
                raise ShapeError(
                    f"dmps[{index}] has {dmp.n_dofs} DOFs, expected {dmps[0].n_dofs} like dmps[0]"
                )
            duration = dmp.convergence_time
            positions = dmp.rollout(duration, duration / (self.plan_samples - 1)).positions
            plans.append(positions[: self.plan_samples] - positions[0])
        self.fractions_ = np.sort(fractions)
        self.plans_ = np.array(plans)
        self.labels_ = labels.copy()
        self.classes_ = np.unique(labels)
        return self

    def match(self, observation: Trajectory) -> tuple[np.ndarray, np.ndarray]:
        """Best relative residual and fraction for each stored plan, each (n_templates,)."""
        _check_fitted(self, "plans_")
        if not isinstance(observation, Trajectory):
            raise InvalidInputError(
                f"observation must be a Trajectory, got {type(observation).__name__}; build "
                "one with Trajectory.from_positions(times, positions)"
            )
        if observation.n_dofs != self.plans_.shape[2]:
            raise ShapeError(
                f"observation has {observation.n_dofs} DOFs, expected {self.plans_.shape[2]} "
                "like the fitted DMPs"
            )
        observed = _resample(observation.times, observation.positions, self.n_samples)
        observed = observed - observed[0]
        if not np.abs(observed).max() > 0.0:
            raise InvalidInputError("observation does not move, so it matches every shape")
        last = self.plans_.shape[1] - 1
        residuals = np.empty((self.fractions_.size, self.plans_.shape[0]))
        for row, fraction in enumerate(self.fractions_):
            position = np.linspace(0.0, fraction * last, self.n_samples)
            lower = np.minimum(np.floor(position).astype(int), last - 1)
            weight = (position - lower)[None, :, None]
            segments = (1.0 - weight) * self.plans_[:, lower] + weight * self.plans_[:, lower + 1]
            residuals[row] = _match_residuals(segments, observed, self.rotation)
        best = np.argmin(residuals, axis=0)
        return residuals[best, np.arange(best.size)], self.fractions_[best]

    def predict(self, observations: Sequence[Trajectory]) -> np.ndarray:
        """Predicted label of each observation, shape (n_observations,)."""
        if isinstance(observations, Trajectory):
            observations = [observations]
        _check_fitted(self, "plans_")
        return np.array([self.labels_[np.argmin(self.match(o)[0])] for o in observations])


def first_part(trajectory: Trajectory, fraction: float = 0.5) -> Trajectory:
    """Keep the samples of ``trajectory`` in the first ``fraction`` of its duration."""
    if not isinstance(trajectory, Trajectory):
        raise InvalidInputError(f"trajectory must be a Trajectory, got {type(trajectory).__name__}")
    fraction = real("fraction", fraction, minimum=0.0, maximum=1.0, open_minimum=True)
    end = trajectory.times[0] + fraction * trajectory.duration
    keep = trajectory.times <= end + 1e-12 * max(trajectory.duration, 1.0)
    if keep.sum() < 3:
        raise InvalidInputError(
            f"the first {fraction:.0%} of the trajectory holds {int(keep.sum())} samples, "
            "at least 3 are needed; observe a longer part"
        )
    return Trajectory(
        trajectory.times[keep],
        trajectory.positions[keep],
        trajectory.velocities[keep],
        trajectory.accelerations[keep],
    )
