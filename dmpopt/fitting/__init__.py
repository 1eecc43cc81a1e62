"""Fitting DMP weights: imitation of demonstrations (and, later, constrained fits)."""

from .imitation import fit_discrete, fit_to_accuracy, forcing_targets, reproduction_error

__all__ = ["fit_discrete", "fit_to_accuracy", "forcing_targets", "reproduction_error"]
