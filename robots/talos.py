"""The Talos humanoid (PAL Robotics) from example-robot-data, as a :class:`RobotModel`.

Two URDFs are shipped: ``"full"`` (``talos_full_v2.urdf``, 44 actuated joints including seven per
gripper) and ``"reduced"`` (``talos_reduced.urdf``, 32 actuated joints, one per gripper). Either
can be loaded with a floating base (the standing robot) or as a fixed-base upper body whose
base link and legs are locked in the half-sitting posture.
"""

from __future__ import annotations

import numpy as np

from dmpopt.exceptions import InvalidInputError

from .model import RobotModel, example_robot_data_dir

__all__ = ["TALOS_SOLE_CORNERS", "load_talos"]

_URDF_FILES = {"full": "talos_full_v2.urdf", "reduced": "talos_reduced.urdf"}

#: Corners of a Talos sole in its sole frame [m]: 0.10 m to the toe, 0.11 m to the heel,
#: 0.069 m to each side (the dimensions TSID's Talos examples use).
TALOS_SOLE_CORNERS = np.array(
    [[0.10, 0.069, 0.0], [0.10, -0.069, 0.0], [-0.11, 0.069, 0.0], [-0.11, -0.069, 0.0]]
)
TALOS_SOLE_CORNERS.setflags(write=False)


#: Joint groups of Talos: the joints whose names start with each prefix, in model order.
_GROUP_PREFIXES = {
    "left_leg": "leg_left_",
    "right_leg": "leg_right_",
    "torso": "torso_",
    "left_arm": "arm_left_",
    "right_arm": "arm_right_",
    "head": "head_",
    "left_gripper": "gripper_left_",
    "right_gripper": "gripper_right_",
}


def load_talos(variant: str = "full", fixed_base: bool = False) -> RobotModel:
    """Load Talos from the installed example-robot-data URDFs (no meshes are read).

    Parameters
    ----------
    variant : {"full", "reduced"}
        ``"full"``: ``talos_full_v2.urdf`` (all gripper joints); ``"reduced"``:
        ``talos_reduced.urdf`` (one joint per gripper).
    fixed_base : bool
        ``False``: the whole robot on a free-flyer base (nq = nv + 1). ``True``: the upper body
        (torso, arms, grippers, head) on a fixed base; the free flyer and the legs are locked
        in the half-sitting posture, so frames keep their standing world placement.

    Returns
    -------
    RobotModel
        With joint groups ``left_leg, right_leg, torso, left_arm, right_arm, head, left_gripper,
        right_gripper`` (the legs only with a floating base), the half-sitting reference
        configuration from ``talos.srdf``, foot frames ``left_sole_link, right_sole_link``
        (floating base only) and hand frames ``gripper_left_base_link, gripper_right_base_link``.

    Raises
    ------
    InvalidInputError
        If ``variant`` is unknown.
    MissingDependency
        If example-robot-data is not installed.
    """
    if variant not in _URDF_FILES:
        raise InvalidInputError(
            f"variant={variant!r} is not a Talos model; expected one of {sorted(_URDF_FILES)}"
        )
    talos_dir = example_robot_data_dir() / "talos_data"
    feet = ("left_sole_link", "right_sole_link")
    return RobotModel.from_urdf(
        talos_dir / "robots" / _URDF_FILES[variant],
        talos_dir / "srdf" / "talos.srdf",
        base="free_flyer",
        groups={group: prefix + ".*" for group, prefix in _GROUP_PREFIXES.items()},
        feet={} if fixed_base else dict.fromkeys(feet, TALOS_SOLE_CORNERS),
        hands=("gripper_left_base_link", "gripper_right_base_link"),
        reference="half_sitting",
        locked=("root_joint", "leg_.*") if fixed_base else (),
        name=f"talos_{variant}" + ("_upper_body" if fixed_base else ""),
    )
