"""Tests of robots/: the generic RobotModel and the Talos loader."""

import importlib.metadata

import numpy as np
import pinocchio as pin
import pytest
from dmpopt_robots import RobotModel, example_robot_data_dir, load_talos

import dmpopt.robot
from dmpopt.exceptions import InvalidInputError, MissingDependency


@pytest.fixture(scope="module")
def talos_full():
    return load_talos("full")


@pytest.mark.parametrize(
    "variant, fixed_base, nq, nv, n_actuated",
    [
        ("full", False, 51, 50, 44),
        ("reduced", False, 39, 38, 32),
        ("full", True, 32, 32, 32),
        ("reduced", True, 20, 20, 20),
    ],
)
def test_talos_sizes(variant, fixed_base, nq, nv, n_actuated):
    """Each variant has the documented dimensions and one torque limit per actuated joint."""
    robot = load_talos(variant, fixed_base=fixed_base)
    assert (robot.nq, robot.nv, robot.n_actuated) == (nq, nv, n_actuated)
    assert robot.floating_base is not fixed_base
    assert robot.torque_limit.shape == (n_actuated,)
    assert np.all(robot.torque_limit > 0) and np.all(np.isfinite(robot.torque_limit))
    assert len(robot.actuated_joint_names) == n_actuated


def test_talos_joint_groups(talos_full):
    """Groups partition the actuated joints, in model order, with the expected sizes."""
    sizes = {name: len(joints) for name, joints in talos_full.joint_groups.items()}
    assert sizes == {
        "left_leg": 6,
        "right_leg": 6,
        "torso": 2,
        "left_arm": 7,
        "right_arm": 7,
        "head": 2,
        "left_gripper": 7,
        "right_gripper": 7,
    }
    grouped = sorted(j for joints in talos_full.joint_groups.values() for j in joints)
    assert grouped == sorted(talos_full.actuated_joint_names)
    indices = talos_full.velocity_indices("left_arm")
    assert indices.tolist() == list(range(indices[0], indices[0] + 7))
    assert talos_full.configuration_indices("left_arm").tolist() == (indices + 1).tolist()


def test_half_sitting_matches_srdf(talos_full):
    """The reference posture is the SRDF's half_sitting: base at 1.01927 m, soles on z = 0."""
    q = talos_full.reference_configuration
    assert q[2] == pytest.approx(1.01927, abs=1e-12)
    left_arm_1 = talos_full.configuration_indices(["arm_left_1_joint"])[0]
    assert q[left_arm_1] == pytest.approx(0.25847, abs=1e-12)
    model = talos_full.model
    data = talos_full.create_data()
    pin.framesForwardKinematics(model, data, q)
    for foot in talos_full.foot_frames:
        placement = data.oMf[model.getFrameId(foot)]
        corners = talos_full.sole_corners @ placement.rotation.T + placement.translation
        np.testing.assert_allclose(corners[:, 2], 0.0, atol=2e-4)  # soles roll 1.7 mrad
        np.testing.assert_allclose(placement.rotation[:, 2], [0, 0, 1], atol=2e-3)


def test_upper_body_keeps_world_placements(talos_full):
    """The fixed-base upper body puts the hands where the standing robot has them."""
    upper = load_talos("full", fixed_base=True)
    assert "left_leg" not in upper.joint_groups and upper.foot_frames == ()
    data_full, data_upper = talos_full.create_data(), upper.create_data()
    pin.framesForwardKinematics(talos_full.model, data_full, talos_full.reference_configuration)
    pin.framesForwardKinematics(upper.model, data_upper, upper.reference_configuration)
    for hand in upper.hand_frames:
        full_placement = data_full.oMf[talos_full.model.getFrameId(hand)]
        upper_placement = data_upper.oMf[upper.model.getFrameId(hand)]
        np.testing.assert_allclose(
            upper_placement.homogeneous, full_placement.homogeneous, atol=1e-12
        )


def test_robot_model_is_frozen(talos_full):
    """Fields cannot be reassigned and arrays cannot be written."""
    with pytest.raises(AttributeError):
        talos_full.torque_limit = np.zeros(44)
    with pytest.raises(ValueError):
        talos_full.reference_configuration[0] = 1.0
    with pytest.raises(TypeError):
        talos_full.joint_groups["new"] = ()


def test_free_flyer_limits_are_infinite(talos_full):
    """Pinocchio's float-max placeholders become inf; joint limits stay finite."""
    assert np.all(np.isinf(talos_full.position_lower[:7]))
    assert np.all(np.isfinite(talos_full.position_lower[7:]))
    assert np.all(np.isinf(talos_full.velocity_limit[:6]))


def test_unknown_variant_message():
    """A wrong variant names the argument and the choices."""
    with pytest.raises(InvalidInputError) as error:
        load_talos("tiny")
    assert str(error.value) == (
        "variant='tiny' is not a Talos model; expected one of ['full', 'reduced']"
    )


def test_unknown_group_message(talos_full):
    """An unknown joint group lists the available ones."""
    with pytest.raises(InvalidInputError) as error:
        talos_full.velocity_indices("tail")
    assert str(error.value).startswith("joints='tail' is not a joint group of 'talos_full'")


def test_missing_data_package(monkeypatch):
    """Without example-robot-data the loader says what to install."""

    def not_installed(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(dmpopt.robot.importlib.metadata, "distribution", not_installed)
    with pytest.raises(MissingDependency) as error:
        load_talos()
    assert str(error.value) == (
        "the robot data package example-robot-data is not installed; install it with "
        "`pip install example-robot-data` or `pip install 'dmpopt[robots]'`"
    )


def test_locator_finds_talos():
    """The located directory holds the Talos URDFs and SRDF."""
    talos = example_robot_data_dir() / "talos_data"
    assert (talos / "robots" / "talos_full_v2.urdf").is_file()
    assert (talos / "srdf" / "talos.srdf").is_file()


def test_robot_model_checks_shapes(talos_full):
    """A RobotModel with a wrongly sized limit array is rejected with the expected shape."""
    with pytest.raises(InvalidInputError) as error:
        RobotModel(
            name="bad",
            model=talos_full.model,
            joint_groups={},
            reference_configuration=talos_full.reference_configuration,
            position_lower=talos_full.position_lower,
            position_upper=talos_full.position_upper,
            velocity_limit=talos_full.velocity_limit,
            torque_limit=np.ones(3),
            base="free_flyer",
        )
    assert str(error.value) == (
        "torque_limit has shape (3,), expected (44,) to match the Pinocchio model (nq=51, nv=50)"
    )
