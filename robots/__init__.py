"""Robot models: loaders for example-robot-data robots and the URDFs dmpopt ships."""

from .model import RobotModel, example_robot_data_dir
from .talos import load_talos

__all__ = ["RobotModel", "example_robot_data_dir", "load_talos"]
