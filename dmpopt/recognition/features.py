r"""Invariant features of DMP weights for recognition (Section 3.8 of [dmpopt-paper]).

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
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..dmp import DiscreteDMP, similarity_transform
from ..exceptions import InvalidInputError, ShapeError
from ..validation import real, real_array
from ._checks import check_dmp, check_n_samples, dmp_list

METRICS = ("plan", "euclidean")
DEGENERATE_DISPLACEMENT = 1e-9
"""Start-goal distances at or below this fraction of the forcing weights' size count as zero."""


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
    forcing, frame = _start_goal_frame(check_dmp(dmp))
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
    dmp = check_dmp(dmp)
    n_samples = check_n_samples(n_samples)
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
    n_samples = check_n_samples(n_samples)
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
    dmp = check_dmp(dmp)
    n_samples = check_n_samples(n_samples)
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
    return movement_feature_sets(
        dmps,
        [(direction_weight, path_weight)],
        start_velocities=start_velocities,
        metric=metric,
        n_samples=n_samples,
    )[0]


def movement_feature_sets(
    dmps: Sequence[DiscreteDMP],
    weightings,
    *,
    start_velocities=None,
    metric: str = "plan",
    n_samples: int = 200,
) -> list:
    """:func:`movement_features` for several ``(direction_weight, path_weight)`` pairs at once.

    The plans and paths are computed once for all pairs (they do not depend on the weights);
    each matrix equals that of :func:`movement_features` with the pair's weights.

    Parameters
    ----------
    dmps, start_velocities, metric, n_samples
        As for :func:`movement_features`.
    weightings : sequence of (float, float)
        ``(direction_weight, path_weight)`` pairs.

    Returns
    -------
    list of ndarray
        One feature matrix per pair, in the order of ``weightings``.
    """
    if not isinstance(metric, str) or metric not in METRICS:
        raise InvalidInputError(f"metric must be one of {METRICS}, got {metric!r}")
    if isinstance(weightings, (str, bytes)) or not hasattr(weightings, "__iter__"):
        raise InvalidInputError(
            f"weightings must be a sequence of (direction_weight, path_weight) pairs, got "
            f"{weightings!r}"
        )
    pairs = []
    for i, pair in enumerate(weightings):
        if isinstance(pair, (str, bytes)) or not hasattr(pair, "__len__") or len(pair) != 2:
            raise InvalidInputError(
                f"weightings[{i}] must be a (direction_weight, path_weight) pair, got {pair!r}"
            )
        pairs.append(
            (
                _check_weight("direction_weight", pair[0]),
                _check_weight("path_weight", pair[1]),
            )
        )
    dmps = dmp_list(dmps)
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
    n_samples = check_n_samples(n_samples)
    if metric == "plan":
        factor = plan_metric_factor(dmps[0], n_samples, start_velocity=True)
    else:
        factor = np.eye(dmps[0].n_basis + 1)
    with_path = any(path_weight > 0.0 for _, path_weight in pairs)
    blocks = []  # per DMP: the weights block, the path (or None), the start-goal vector
    for dmp, velocity in zip(dmps, start_velocities):
        forcing, frame = _start_goal_frame(dmp)
        weights = np.column_stack([frame @ forcing, frame @ (dmp.tau * velocity)])
        path = None
        if with_path:
            plan = _unit_plan(dmp, weights[:, :-1], weights[:, -1], n_samples)
            path = arc_length_resampled(plan, n_samples).ravel()
        displacement = np.asarray(dmp.goal) - np.asarray(dmp.start)
        blocks.append(((weights @ factor).ravel(), path, displacement))
    sets = []
    for direction_weight, path_weight in pairs:
        rows = []
        for weights, path, displacement in blocks:
            parts = [weights]
            if path_weight > 0.0:
                parts.append(path_weight / np.sqrt(n_samples) * path)
            parts.append(direction_weight * displacement / np.linalg.norm(displacement))
            rows.append(np.concatenate(parts))
        sets.append(np.array(rows))
    return sets
