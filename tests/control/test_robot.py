"""Tests of dmpopt.robot: RobotModel.from_urdf on the shipped and example-robot-data robots."""

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from dmpopt_robots import load_talos
from dmpopt_robots.biped import load_biped

from dmpopt import RobotModel
from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.robot import example_robot_data_dir

ANSWER_KEY = json.loads(
    (Path(__file__).parents[1] / "data" / "robot_models_answer_key.json").read_text()
)


def _loaded(key: str) -> RobotModel:
    if key == "biped":
        return load_biped()
    _, variant, fixed = key.split("_")
    return load_talos(variant, fixed_base=fixed == "True")


@pytest.mark.parametrize("key", sorted(ANSWER_KEY))
def test_loaders_match_the_hand_written_ones(key):
    """Talos (4 variants) and the biped, now uses of from_urdf, equal field by field what the
    hand-written loaders built (tests/data/make_robot_models_answer_key.py, commit 38285f9)."""
    robot, expected = _loaded(key), ANSWER_KEY[key]
    model = robot.model
    assert {
        "name": model.name, "nq": model.nq, "nv": model.nv, "joints": list(model.names),
        "frames": [f.name for f in model.frames], "armature": np.array(model.armature).tolist(),
    } == {k: v for k, v in expected["model"].items() if k != "mass"}  # fmt: skip
    assert pin.computeTotalMass(model) == expected["model"]["mass"]
    for name in robot.__dataclass_fields__:
        value = getattr(robot, name)
        if name == "model":
            continue
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, np.reshape(expected[name], value.shape), name)
        elif name == "joint_groups":
            assert {k: list(v) for k, v in value.items()} == expected[name]
        elif name == "source":
            assert Path(value).name == expected[name]
        else:
            assert (list(value) if isinstance(value, tuple) else value) == expected[name], name


@pytest.fixture(scope="module")
def robot_dir():
    return example_robot_data_dir()


@pytest.fixture(scope="module")
def g1(robot_dir):
    return RobotModel.from_urdf(
        robot_dir / "g1_description" / "urdf" / "g1_29dof_rev_1_0.urdf",
        feet=["left_ankle_roll_link", "right_ankle_roll_link"],
        groups={"left_leg": "left_(hip|knee|ankle)_.*", "waist": "waist_.*"},
        reference={
            f"{side}_{joint}": angle
            for side in ("left", "right")
            for joint, angle in (
                ("hip_pitch_joint", -0.15),
                ("knee_joint", 0.3),
                ("ankle_pitch_joint", -0.15),
            )
        },
    )


def test_panda_from_urdf_and_srdf(robot_dir):
    """Panda: fixed base, limits and groups from the files, the SRDF's only posture."""
    panda_dir = robot_dir / "panda_description"
    panda = RobotModel.from_urdf(
        panda_dir / "urdf" / "panda.urdf", panda_dir / "srdf" / "panda.srdf", hands=["panda_hand"]
    )
    assert panda.base == "fixed" and (panda.nq, panda.nv, panda.n_actuated) == (9, 9, 9)
    assert dict(panda.joint_groups) == {
        "arm": tuple(f"panda_joint{i}" for i in range(1, 8)),
        "hand": ("panda_finger_joint1",),
        "arm_and_hand": tuple(f"panda_joint{i}" for i in range(1, 8)) + ("panda_finger_joint1",),
    }
    # panda.srdf's "default" state, written out; panda_finger_joint2 is not in it (stays 0)
    np.testing.assert_array_equal(
        panda.reference_configuration,
        [0, -0.785398, 0, -2.35619, 0, 1.5707, 0.785398, 0.001, 0],
    )
    # panda.urdf: joint 1 limits [-2.8973, 2.8973] rad, 2.175 rad/s, 87 N m; fingers 100 N
    assert (panda.position_lower[0], panda.position_upper[0]) == (-2.8973, 2.8973)
    assert panda.velocity_limit[0] == 2.175 and panda.torque_limit[0] == 87.0
    assert panda.torque_limit[-1] == 100.0


def test_g1_soles_from_collision_spheres(g1):
    """G1's feet: four spheres of radius 5 mm at z = -0.03 (g1_29dof_rev_1_0.urdf) give a sole
    frame 35 mm under the ankle and the rectangle x in [-0.05, 0.12], y in [-0.03, 0.03]."""
    assert g1.foot_frames == ("left_ankle_roll_link_sole", "right_ankle_roll_link_sole")
    np.testing.assert_allclose(
        g1.sole_corners,
        [[0.12, 0.03, 0], [0.12, -0.03, 0], [-0.05, 0.03, 0], [-0.05, -0.03, 0]],
        atol=1e-15,
    )
    model = g1.model
    sole = model.frames[model.getFrameId("left_ankle_roll_link_sole")]
    ankle = model.frames[model.getFrameId("left_ankle_roll_link")]
    np.testing.assert_allclose(
        ankle.placement.actInv(sole.placement).translation, [0, 0, -0.035], atol=1e-15
    )


def test_g1_stands_on_the_floor(g1):
    """With the base height placed, every sole corner is on z = 0 (hip, knee and ankle pitch
    -0.15, 0.3, -0.15 rad about parallel axes keep the soles level) and the base is upright."""
    model, data = g1.model, g1.create_data()
    q = g1.reference_configuration
    np.testing.assert_array_equal(q[3:7], [0, 0, 0, 1])
    pin.framesForwardKinematics(model, data, q)
    for foot in g1.foot_frames:
        placement = data.oMf[model.getFrameId(foot)]
        corners = g1.sole_corners @ placement.rotation.T + placement.translation
        np.testing.assert_allclose(corners[:, 2], 0.0, atol=1e-12)
    assert 0.6 < q[2] < 0.8  # a 1.3 m robot's pelvis with bent knees


def test_g1_limits_groups(g1):
    """Float-max limits of the free flyer become inf, its effort limits are dropped; regex
    groups match in model order."""
    assert np.all(np.isinf(g1.position_lower[:7])) and np.all(np.isinf(g1.velocity_limit[:6]))
    assert g1.torque_limit.shape == (29,) and np.all(np.isfinite(g1.torque_limit))
    assert g1.torque_limit[0] == 88.0  # left_hip_pitch_joint effort="88"
    assert g1.joint_groups["left_leg"] == (
        "left_hip_pitch_joint", "left_hip_roll_joint", "left_hip_yaw_joint", "left_knee_joint",
        "left_ankle_pitch_joint", "left_ankle_roll_joint",
    )  # fmt: skip
    assert len(g1.joint_groups["waist"]) == 3


def test_talos_sole_from_mesh(robot_dir):
    """Talos' sole from its ankle mesh: the mesh bottom is 0.4 mm under left_sole_link (no
    frame added) and spans about the TSID rectangle (0.10 / -0.11 m, +-0.069 m)."""
    talos_dir = robot_dir / "talos_data"
    talos = RobotModel.from_urdf(
        talos_dir / "robots" / "talos_reduced.urdf", feet=["left_sole_link", "right_sole_link"]
    )
    assert talos.foot_frames == ("left_sole_link", "right_sole_link")
    (x_max, y_max, _), (x_min, y_min, _) = talos.sole_corners[0], talos.sole_corners[3]
    np.testing.assert_allclose(
        [x_max, x_min, y_max, y_min], [0.10, -0.11, 0.069, -0.069], atol=8e-3
    )


def test_bad_input_messages(robot_dir):
    """A typo in a frame suggests the right name; a group pattern matching nothing lists the
    joints; a zero quaternion in the reference is refused."""
    urdf = robot_dir / "g1_description" / "urdf" / "g1_29dof_rev_1_0.urdf"
    with pytest.raises(InvalidInputError, match="did you mean 'left_ankle_roll_link'"):
        RobotModel.from_urdf(urdf, feet={"left_ankle_rol_link": None})
    with pytest.raises(InvalidInputError, match=r"groups\['arm'\] = 'arm_.\*' matches no"):
        RobotModel.from_urdf(urdf, groups={"arm": "arm_.*"})
    q = np.zeros(36)
    with pytest.raises(InvalidInputError, match=r"quaternion .* must have norm 1, got \[0.0"):
        RobotModel.from_urdf(urdf, base="free_flyer", reference=q)


def test_armature_and_bad_reference_name(robot_dir):
    """armature fills model.armature on the actuated joints; an unknown SRDF posture lists
    the SRDF's postures."""
    panda_dir = robot_dir / "panda_description"
    urdf, srdf = panda_dir / "urdf" / "panda.urdf", panda_dir / "srdf" / "panda.srdf"
    panda = RobotModel.from_urdf(urdf, srdf, armature=0.1)
    np.testing.assert_array_equal(panda.model.armature, np.full(9, 0.1))
    with pytest.raises(InvalidInputError) as error:
        RobotModel.from_urdf(urdf, srdf, reference="home")
    assert str(error.value) == (
        "reference='home' is not a posture of the SRDF; expected one of ['default']"
    )


def test_g1_placements_com_sole_centre_and_start_state(g1):
    """Set-up helpers: a frame's placement and the CoM (Pinocchio's own calls written out);
    the sole centre is the middle of x in [-0.05, 0.12], y in [-0.03, 0.03] on the sole
    frame, (0.035, 0, 0) in it; a start state sets the given joints and nothing else."""
    model, data = g1.model, g1.create_data()
    q = pin.integrate(model, g1.reference_configuration, np.full(g1.nv, 0.1))
    pin.framesForwardKinematics(model, data, q)
    sole = data.oMf[model.getFrameId(g1.foot_frames[0])]
    assert g1.frame_placement(g1.foot_frames[0], q).isApprox(sole, 1e-12)
    np.testing.assert_allclose(g1.center_of_mass(q), pin.centerOfMass(model, data, q), atol=1e-12)
    np.testing.assert_allclose(
        g1.sole_center(g1.foot_frames[0], q), sole.act(np.array([0.035, 0.0, 0.0])), atol=1e-12
    )
    arm = ["left_shoulder_pitch_joint", "left_elbow_joint"]
    q0, v0 = g1.reference_state(arm, [0.3, 1.1], [2.0, -1.0])
    changed = np.flatnonzero(q0 != g1.reference_configuration)
    assert changed.tolist() == sorted(g1.configuration_indices(arm).tolist())
    assert q0[g1.configuration_indices(arm)].tolist() == [0.3, 1.1]
    assert np.flatnonzero(v0).tolist() == sorted(g1.velocity_indices(arm).tolist())
    assert v0[g1.velocity_indices(arm)].tolist() == [2.0, -1.0]
    with pytest.raises(InvalidInputError, match="frame 'left_sole' is not in the URDF"):
        g1.frame_placement("left_sole")
    with pytest.raises(InvalidInputError, match="^frame='pelvis' is not a foot frame"):
        g1.sole_center("pelvis")
    with pytest.raises(ShapeError, match="^positions"):
        g1.reference_state(arm, [0.3])
