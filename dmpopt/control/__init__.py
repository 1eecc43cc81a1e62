"""Whole-body control: QP inverse dynamics with tasks and switchable contacts, computed torque.

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
from dmpopt.control.contacts import (
    Contact,
    PointContact,
    SoleContact,
    SurfaceContact,
)
from dmpopt.control.controller import InverseDynamicsController
from dmpopt.control.diagnostics import active_constraints, explain
from dmpopt.control.inverse_dynamics import AssembledQp, ControllerStats
from dmpopt.control.joint_impedance import JointImpedance
from dmpopt.control.realtime import control_loop
from dmpopt.control.tasks import ComTask, FrameTask, PostureTask, Task

__all__ = [
    "AssembledQp",
    "ComTask",
    "ComputedTorqueController",
    "Contact",
    "ControllerStats",
    "FrameTask",
    "InverseDynamicsController",
    "JointImpedance",
    "PointContact",
    "PostureTask",
    "SoleContact",
    "SurfaceContact",
    "Task",
    "active_constraints",
    "control_loop",
    "explain",
]
