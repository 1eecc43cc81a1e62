r"""Recognition from the beginning of a movement, by matching it against the DMPs' plans.

The weights of a DMP fitted to a partial movement differ from those of the whole one (the
goal is unknown and the phase runs differently), so :class:`PartialObservationClassifier`
compares curves instead: a template matcher (a 1-nearest neighbour in the residual of a
Procrustes fit), which has no scikit-learn counterpart.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..dmp import DiscreteDMP
from ..exceptions import InvalidInputError, ShapeError
from ..trajectory import Trajectory
from ..validation import real, real_array
from ._checks import check_fitted, check_labels, check_n_samples, dmp_list


def _resample(times: np.ndarray, positions: np.ndarray, n_samples: int) -> np.ndarray:
    """Positions at ``n_samples`` equally spaced times over ``times`` (linear)."""
    grid = np.linspace(times[0], times[-1], n_samples)
    return np.stack([np.interp(grid, times, p) for p in positions.T], axis=1)


def _match_residuals(
    templates: np.ndarray, observed: np.ndarray, rotation: bool, template_norms=None
) -> np.ndarray:
    r"""Relative residual of the best similarity fit of each template onto the observation.

    Both are relative to their first sample. ``templates`` (K, n, D), ``observed`` (n, D).
    Minimises :math:`\|O - s T R\|^2` over the scale :math:`s \ge 0` (and a proper
    rotation :math:`R` if ``rotation``) and returns it divided by :math:`\|O\|^2`.
    ``template_norms``: :math:`\|T\|^2` of each template if already known.
    """
    observed_norm = float((observed**2).sum())
    if template_norms is None:
        template_norms = _norms(templates)
    if rotation:
        cross = np.einsum("kni,nj->kij", templates, observed)  # T^T O
        u, singular, vt = np.linalg.svd(cross)
        sign = np.sign(np.linalg.det(u @ vt))
        singular[:, -1] *= sign
        correlation = singular.sum(axis=1)
    else:  # trace(T^T O): its diagonal alone (a D-th of the products), summed as trace sums
        correlation = np.einsum("kni,ni->ki", templates, observed).sum(axis=1)
    correlation = np.maximum(correlation, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        explained = np.where(template_norms > 0, correlation**2 / template_norms, 0.0)
    return 1.0 - explained / observed_norm


def _norms(templates: np.ndarray) -> np.ndarray:
    return (templates**2).sum(axis=(1, 2))


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
            check_n_samples(getattr(self, name), name)
        if not isinstance(self.rotation, (bool, np.bool_)):
            raise InvalidInputError(f"rotation must be True or False, got {self.rotation!r}")
        dmps = dmp_list(dmps)
        labels = check_labels(labels, len(dmps))
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
        # the first fraction of every plan, resampled: the same for every observation
        last = self.plans_.shape[1] - 1
        segments = []
        for fraction in self.fractions_:
            position = np.linspace(0.0, fraction * last, self.n_samples)
            lower = np.minimum(np.floor(position).astype(int), last - 1)
            weight = (position - lower)[None, :, None]
            segments.append(
                (1.0 - weight) * self.plans_[:, lower] + weight * self.plans_[:, lower + 1]
            )
        self._segments = segments
        self._segment_norms = [_norms(segment) for segment in segments]
        return self

    def match(self, observation: Trajectory) -> tuple[np.ndarray, np.ndarray]:
        """Best relative residual and fraction for each stored plan, each (n_templates,)."""
        check_fitted(self, "plans_")
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
        n_samples = self._segments[0].shape[1]  # as fitted
        observed = _resample(observation.times, observation.positions, n_samples)
        observed = observed - observed[0]
        if not np.abs(observed).max() > 0.0:
            raise InvalidInputError("observation does not move, so it matches every shape")
        residuals = np.empty((self.fractions_.size, self.plans_.shape[0]))
        for row, (segments, norms) in enumerate(zip(self._segments, self._segment_norms)):
            residuals[row] = _match_residuals(segments, observed, self.rotation, norms)
        best = np.argmin(residuals, axis=0)
        return residuals[best, np.arange(best.size)], self.fractions_[best]

    def predict(self, observations: Sequence[Trajectory]) -> np.ndarray:
        """Predicted label of each observation, shape (n_observations,)."""
        if isinstance(observations, Trajectory):
            observations = [observations]
        check_fitted(self, "plans_")
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
