"""Whole-body control: QP inverse dynamics with tasks and sole contacts, computed torque.

>>> robot = load_talos("full")
>>> posture = PostureTask(robot, weight=1e-2, stiffness=10.0)
>>> arm = PostureTask(robot, "left_arm", weight=1.0, stiffness=25.0)   # fed by a DMP
>>> controller = InverseDynamicsController(
...     robot, [posture, arm, ComTask(robot, weight=10.0), FrameTask(robot, "base_link",
...     components="orientation")], [SoleContact(robot, f) for f in robot.foot_frames])
>>> arm.set_reference(y, yd, ydd)          # every tick
>>> tau = controller.compute_torques(q, v)
"""

from dmpopt.control.computed_torque import ComputedTorqueController
from dmpopt.control.inverse_dynamics import ControllerStats, InverseDynamicsController
from dmpopt.control.tasks import ComTask, FrameTask, PostureTask, SoleContact, Task

__all__ = [
    "ComTask",
    "ComputedTorqueController",
    "ControllerStats",
    "FrameTask",
    "InverseDynamicsController",
    "PostureTask",
    "SoleContact",
    "Task",
]
