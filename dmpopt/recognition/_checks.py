"""Checks shared by the recognition modules: DMPs, features, labels, scikit-learn."""

from __future__ import annotations

import importlib

import numpy as np

from ..dmp import DiscreteDMP
from ..exceptions import InvalidInputError, MissingDependency, ShapeError
from ..validation import integer, real_array

MAX_SAMPLES = 100_000
"""Largest ``n_samples`` (or ``plan_samples``): each is a step of a DMP rollout."""
MAX_FEATURE = 1e150
"""Features beyond this magnitude would overflow their squared distances."""


def sklearn(module: str, user: str):
    """Import ``sklearn.<module>``; without scikit-learn, say which extra installs it."""
    try:
        return importlib.import_module(f"sklearn.{module}")
    except ImportError as error:
        raise MissingDependency(
            f"{user} needs scikit-learn, which is not installed: pip install 'dmpopt[recognition]'"
        ) from error


def checked_by_dmpopt(user: str):
    """Context in which scikit-learn skips its own input and parameter checks, for calls
    whose arrays (finite, 2-D) and parameters dmpopt has checked already. The answers are
    the same; the checks were a third of a small LDA fit (44 vs 68 ms on 209 x 62)."""
    return sklearn("_config", user).config_context(
        assume_finite=True, skip_parameter_validation=True
    )


def check_dmp(dmp, name: str = "dmp") -> DiscreteDMP:
    """``dmp`` if it is a DiscreteDMP."""
    if not isinstance(dmp, DiscreteDMP):
        raise InvalidInputError(
            f"{name} must be a DiscreteDMP, got {type(dmp).__name__}; fit one with "
            "dmpopt.fit_discrete(demo, n_basis)"
        )
    return dmp


def dmp_list(dmps) -> list:
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
        check_dmp(dmp, f"dmps[{index}]")
    return dmps


def check_n_samples(n_samples, name: str = "n_samples") -> int:
    """A number of samples of a curve, 3 to :data:`MAX_SAMPLES`."""
    return integer(name, n_samples, minimum=3, maximum=MAX_SAMPLES, fix="a few hundred suffice")


def check_features(features, name: str = "features", n_features: int | None = None):
    """A finite (n_samples, n_features) array, optionally with ``n_features`` columns."""
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


def check_labels(labels, n_samples: int) -> np.ndarray:
    """One integer or string label per sample."""
    labels = np.asarray(labels)
    integral = labels.dtype.kind == "f" and np.all(np.isfinite(labels) & (labels % 1 == 0))
    if labels.dtype.kind not in "iuUSb" and not integral:
        raise InvalidInputError(
            f"labels must be integers or strings, got dtype {labels.dtype} ({labels!r:.60})"
        )
    if labels.shape != (n_samples,):
        raise ShapeError(
            f"labels has shape {labels.shape}, expected ({n_samples},): one label per sample"
        )
    return labels


def check_fitted(classifier, attribute: str) -> None:
    """Refuse to use ``classifier`` before ``fit`` has set ``attribute``."""
    if not hasattr(classifier, attribute):
        raise InvalidInputError(
            f"this {type(classifier).__name__} is not fitted yet; call fit(...) first"
        )
