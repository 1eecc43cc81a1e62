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

import os
import sys

from dmpopt.symbolic import cache_dir

# numba caches compiled kernels next to their source unless told otherwise: in an installed
# package that is site-packages, where the files outlive an uninstall. Set the user's cache
# folder before numba reads its configuration (at import, and again when it compiles).
if not os.environ.get("NUMBA_CACHE_DIR"):
    os.environ["NUMBA_CACHE_DIR"] = str(cache_dir() / "numba")
    if "numba" in sys.modules:
        sys.modules["numba"].core.config.reload_config()

from dmpopt.control.computed_torque import ComputedTorqueController  # noqa: E402
from dmpopt.control.contacts import (  # noqa: E402
    Contact,
    PointContact,
    SoleContact,
    SurfaceContact,
)
from dmpopt.control.controller import InverseDynamicsController  # noqa: E402
from dmpopt.control.diagnostics import active_constraints, explain  # noqa: E402
from dmpopt.control.inverse_dynamics import AssembledQp, ControllerStats  # noqa: E402
from dmpopt.control.joint_impedance import JointImpedance  # noqa: E402
from dmpopt.control.realtime import control_loop  # noqa: E402
from dmpopt.control.tasks import ComTask, FrameTask, PostureTask, Task  # noqa: E402

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
