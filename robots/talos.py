"""The Talos humanoid (PAL Robotics) from example-robot-data, as a :class:`RobotModel`.

Two URDFs are shipped: ``"full"`` (``talos_full_v2.urdf``, 44 actuated joints including seven per
gripper) and ``"reduced"`` (``talos_reduced.urdf``, 32 actuated joints, one per gripper). Either
can be loaded with a floating base (the standing robot) or as a fixed-base upper body whose
base link and legs are locked in the half-sitting posture.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

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


def _joint_groups(model: pin.Model) -> dict[str, tuple[str, ...]]:
    prefixes = {
        "left_leg": "leg_left_",
        "right_leg": "leg_right_",
        "torso": "torso_",
        "left_arm": "arm_left_",
        "right_arm": "arm_right_",
        "head": "head_",
        "left_gripper": "gripper_left_",
        "right_gripper": "gripper_right_",
    }
    names = list(model.names)
    groups = {
        group: tuple(name for name in names if name.startswith(prefix))
        for group, prefix in prefixes.items()
    }
    return {group: joints for group, joints in groups.items() if joints}


def _finite_or_inf(values: np.ndarray) -> np.ndarray:
    values = np.array(values, dtype=float)
    values[np.abs(values) >= 1e300] = np.inf * np.sign(values[np.abs(values) >= 1e300])
    return values


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
    urdf_path = talos_dir / "robots" / _URDF_FILES[variant]
    model = pin.buildModelFromUrdf(str(urdf_path), pin.JointModelFreeFlyer())
    pin.loadReferenceConfigurations(model, str(talos_dir / "srdf" / "talos.srdf"), False)
    half_sitting = np.array(model.referenceConfigurations["half_sitting"])

    feet: tuple[str, ...] = ("left_sole_link", "right_sole_link")
    if fixed_base:
        locked_names = ["root_joint"] + [n for n in model.names if n.startswith("leg_")]
        locked_ids = [model.getJointId(name) for name in locked_names]
        kept_names = [n for n in model.names[1:] if n not in locked_names]
        full_model = model
        model = pin.buildReducedModel(full_model, locked_ids, half_sitting)
        half_sitting = np.array(
            [half_sitting[full_model.joints[full_model.getJointId(n)].idx_q] for n in kept_names]
        )
        feet = ()

    actuated_v = slice(6, None) if not fixed_base else slice(0, None)
    return RobotModel(
        name=f"talos_{variant}" + ("_upper_body" if fixed_base else ""),
        model=model,
        joint_groups=_joint_groups(model),
        reference_configuration=half_sitting,
        position_lower=_finite_or_inf(model.lowerPositionLimit),
        position_upper=_finite_or_inf(model.upperPositionLimit),
        velocity_limit=_finite_or_inf(model.velocityLimit),
        torque_limit=np.array(model.effortLimit)[actuated_v],
        base="fixed" if fixed_base else "free_flyer",
        foot_frames=feet,
        hand_frames=("gripper_left_base_link", "gripper_right_base_link"),
        sole_corners=TALOS_SOLE_CORNERS if feet else np.zeros((0, 3)),
        source=str(urdf_path),
    )
