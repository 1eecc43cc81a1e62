"""The robot model now lives in the library (:mod:`dmpopt.robot`); this module keeps old imports."""

from dmpopt.robot import BASES, RobotModel, example_robot_data_dir

__all__ = ["BASES", "RobotModel", "example_robot_data_dir"]
