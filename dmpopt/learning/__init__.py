r"""Reinforcement learning of DMP weights (Section 3.5 and Fig. 5 of [dmpopt-paper]).

:mod:`~dmpopt.learning.policy_search`: one ask/tell interface for episodic Natural
Actor-Critic (eqs. 17-19), episodic REINFORCE, PI-BB and CMA-ES.
:mod:`~dmpopt.learning.rewards`: reward tasks (not the QP tasks of :mod:`dmpopt.control`):
the paper's reaching task, a multi-DOF and a via-point task, each with its exact optimum
(the plan is affine in the weights).
"""

from .policy_search import (
    CMAES,
    METHODS,
    PIBB,
    EpisodicNAC,
    EpisodicReinforce,
    Exploration,
    LearningCurve,
    PolicySearch,
    enac_gradient,
    make_method,
    optimise,
    reinforce_gradient,
)
from .rewards import (
    RewardTask,
    ViaPointReward,
    multi_dof_reaching_task,
    paper_reaching_task,
    via_point_task,
)

__all__ = [
    "CMAES",
    "METHODS",
    "PIBB",
    "EpisodicNAC",
    "EpisodicReinforce",
    "Exploration",
    "LearningCurve",
    "PolicySearch",
    "RewardTask",
    "ViaPointReward",
    "enac_gradient",
    "make_method",
    "multi_dof_reaching_task",
    "optimise",
    "paper_reaching_task",
    "reinforce_gradient",
    "via_point_task",
]


def __getattr__(name):
    """No ``ViaPoint`` here: an AttributeError that names the two classes it could mean."""
    if name == "ViaPoint":
        raise AttributeError(
            "dmpopt.learning has no ViaPoint: a rewarded point of a task is ViaPointReward, "
            "the hard constraint of a fit is dmpopt.ViaPoint"
        )
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
