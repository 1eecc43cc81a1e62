r"""dmpopt: Dynamic Movement Primitives built on optimisation and real robot models.

Symbols of the paper ([dmpopt-paper]: Schaal, Peters, Nakanishi, Ijspeert, "Learning Movement
Primitives", ISRR 2003) and their names in the API:

==============================  =====================================  =====================
symbol                          meaning                                API name
==============================  =====================================  =====================
:math:`y, \dot y, \ddot y`      position, velocity, acceleration       ``positions`` ...
:math:`z`                       scaled velocity state                  (state)
:math:`g`                       goal / setpoint                        ``goal``, ``setpoint``
:math:`y_0`                     start                                  ``start``
:math:`\tau`                    time constant                          ``tau``
:math:`\alpha_z, \beta_z`       transformation gains (eqs. 5, 10)      ``alpha_z``, ``beta_z``
:math:`\alpha_v, \beta_v`       discrete canonical gains (eq. 6)       ``alpha_v``, ``beta_v``
:math:`\alpha_g`                goal filter rate (eq. 10)              ``alpha_g``
:math:`A, \alpha_r`             amplitude and its rate (eq. 11)        ``amplitude``, ``alpha_r``
:math:`E_0, \alpha_E, k`        energy oscillator (eq. 13)             ``amplitude``, ``alpha_E``, ``k``
:math:`w_i, c_i, h_i`           weights, centres, widths               ``weights``, ``centres``, ``widths``
:math:`f`                       forcing term                           ``forcing_weights()``
==============================  =====================================  =====================

The full table, with units: ``docs/glossary.md``.
"""  # noqa: E501

import os as _os
import sys as _sys

from .symbolic import cache_dir as _cache_dir

# numba caches compiled kernels next to their source unless told otherwise: in an installed
# package that is site-packages, where the files outlive an uninstall. Every module with numba
# kernels (rollouts, rewards, controller, simulator) lies below this package, so setting the
# user's cache folder here, before numba reads its configuration (at import, and again when it
# compiles), covers them all.
if not _os.environ.get("NUMBA_CACHE_DIR"):
    _os.environ["NUMBA_CACHE_DIR"] = str(_cache_dir() / "numba")
    if "numba" in _sys.modules:
        _sys.modules["numba"].core.config.reload_config()

from .cartesian import CartesianDMP, CartesianStepper, CartesianTrajectory
from .dmp import AffinePlan, DiscreteDMP, RhythmicDMP, similarity_transform
from .exceptions import (
    DmpoptError,
    FileFormatError,
    FittingFailed,
    InfeasibleProblem,
    InvalidInputError,
    MissingDependency,
    NoSolutionFound,
    ResourceLimitError,
    ShapeError,
    SimulationDiverged,
)
from .fitting import (
    Bounds,
    ViaPoint,
    build_fitting_problem,
    fit_cartesian,
    fit_discrete,
    fit_keep_out,
    fit_rhythmic,
    fit_to_accuracy,
    fit_weights_constrained,
    minimum_jerk,
    minimum_jerk_constrained,
    minimum_jerk_via_points,
    reproduction_error,
    solve_fitting_problem,
)
from .io import load, save
from .promp import ProMP, blend, coactivate, fit_promp
from .retiming import retime, time_scaled, uniform_time_scaling
from .stepper import Stepper
from .superposition import superpose
from .trajectory import Trajectory

__version__ = "0.1.0"

__all__ = [
    "AffinePlan",
    "Bounds",
    "CartesianDMP",
    "CartesianStepper",
    "CartesianTrajectory",
    "DiscreteDMP",
    "DmpoptError",
    "FileFormatError",
    "FittingFailed",
    "InfeasibleProblem",
    "InvalidInputError",
    "MissingDependency",
    "NoSolutionFound",
    "ProMP",
    "ResourceLimitError",
    "RhythmicDMP",
    "RobotModel",
    "ShapeError",
    "SimulationDiverged",
    "Stepper",
    "Trajectory",
    "ViaPoint",
    "blend",
    "build_fitting_problem",
    "coactivate",
    "fit_cartesian",
    "fit_discrete",
    "fit_keep_out",
    "fit_promp",
    "fit_rhythmic",
    "fit_to_accuracy",
    "fit_weights_constrained",
    "load",
    "minimum_jerk",
    "minimum_jerk_constrained",
    "minimum_jerk_via_points",
    "reproduction_error",
    "retime",
    "save",
    "similarity_transform",
    "solve_fitting_problem",
    "superpose",
    "time_scaled",
    "uniform_time_scaling",
]


def __getattr__(name: str):
    # RobotModel loads Pinocchio: imported on first use, so `import dmpopt` stays light
    if name == "RobotModel":
        from .robot import RobotModel

        return RobotModel
    raise AttributeError(f"module 'dmpopt' has no attribute {name!r}")
