"""Fitting DMP weights: imitation of demonstrations (and, later, constrained fits)."""

from .imitation import (
    estimate_period,
    fit_discrete,
    fit_rhythmic,
    fit_to_accuracy,
    forcing_targets,
    reproduction_error,
)

__all__ = [
    "estimate_period",
    "fit_discrete",
    "fit_rhythmic",
    "fit_to_accuracy",
    "forcing_targets",
    "reproduction_error",
]
