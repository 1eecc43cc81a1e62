"""Fitting DMP weights: imitation, constrained fits (QP), minimum-jerk baselines."""

from .cartesian import fit_cartesian
from .constrained import (
    Bounds,
    ConstrainedFit,
    FitReport,
    FittingProblem,
    ViaPoint,
    build_fitting_problem,
    fit_weights_constrained,
    solve_fitting_problem,
)
from .dynamics import (
    DynamicsFit,
    DynamicsProblem,
    DynamicsReport,
    build_dynamics_problem,
    fit_weights_dynamics,
    solve_dynamics_problem,
)
from .imitation import (
    estimate_period,
    fit_discrete,
    fit_rhythmic,
    fit_to_accuracy,
    forcing_targets,
    reproduction_error,
)
from .keep_out import fit_keep_out
from .minimum_jerk import minimum_jerk, minimum_jerk_constrained, minimum_jerk_via_points
from .requests import Balance, TorqueLimits

__all__ = [
    "Balance",
    "Bounds",
    "ConstrainedFit",
    "DynamicsFit",
    "DynamicsProblem",
    "DynamicsReport",
    "FitReport",
    "FittingProblem",
    "TorqueLimits",
    "ViaPoint",
    "build_dynamics_problem",
    "build_fitting_problem",
    "estimate_period",
    "fit_cartesian",
    "fit_discrete",
    "fit_keep_out",
    "fit_rhythmic",
    "fit_to_accuracy",
    "fit_weights_constrained",
    "fit_weights_dynamics",
    "forcing_targets",
    "minimum_jerk",
    "minimum_jerk_constrained",
    "minimum_jerk_via_points",
    "reproduction_error",
    "solve_dynamics_problem",
    "solve_fitting_problem",
]
