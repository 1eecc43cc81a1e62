"""A Cartesian DMP (position and orientation) on the Panda's hand: a demonstrated reach that
tilts the hand 60 degrees, replayed to a new goal pose through the QP controller in MuJoCo.
Writes ``cartesian_hand.gif`` (``--quick``: a PNG still) into the output folder."""

import argparse
from pathlib import Path

import numpy as np
import pinocchio as pin

from dmpopt import RobotModel, fit_cartesian
from dmpopt.control import FrameTask, InverseDynamicsController, PostureTask
from dmpopt.robot import example_robot_data_dir
from dmpopt.sim import MujocoSimulator, render_animation, render_frame

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("output", type=Path, help="folder for the animation")
parser.add_argument("--quick", action="store_true", help="0.4 s instead of 1.5 s")
args = parser.parse_args()

files = example_robot_data_dir() / "panda_description"
panda = RobotModel.from_urdf(files / "urdf/panda.urdf", files / "srdf/panda.srdf")
dt, start = 1e-3, panda.frame_placement("panda_hand")  # in the reference posture


def tilted(angles):
    """The start orientation turned by a rotation vector, as (w, x, y, z)."""
    q = pin.Quaternion(start.rotation @ pin.exp3(np.asarray(angles, dtype=float)))
    return [q.w, q.x, q.y, q.z]


times = np.linspace(0.0, 1.0, 201)  # the demonstration: 15 cm forward while tilting about y
s = 10 * times**3 - 15 * times**4 + 6 * times**5
positions = start.translation + np.outer(s, [0.15, 0.0, -0.1])
dmp = fit_cartesian(times, positions, [tilted([0, np.pi / 3 * a, 0]) for a in s], n_basis=20)
goal = start.translation + [0.1, 0.15, -0.15]
stepper = dmp.with_goal(position=goal, orientation=tilted([0, np.pi / 4, 0.3])).stepper(dt)

posture = PostureTask(panda, weight=0.01, stiffness=10.0)  # the elbow's null space
hand = FrameTask(panda, "panda_hand", weight=1.0, stiffness=400.0)  # position and orientation
controller = InverseDynamicsController(panda, [posture, hand], [])
simulator = MujocoSimulator(panda.model, panda.source, dt)
state, frames = simulator.reset(panda.reference_configuration), []
for k in range(int((0.4 if args.quick else 1.5) / dt)):
    position, velocity, acceleration, (w, x, y, z), omega, alpha = stepper.step()
    target = pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), position)
    hand.set_target(target, np.r_[velocity, omega], np.r_[acceleration, alpha])
    state = simulator.step(controller.compute_torques(state.q, state.v))
    frames += [state.q] if k % 40 == 0 else []
error = pin.log6(panda.frame_placement("panda_hand", state.q).actInv(target)).vector
millimetres, degrees = 1e3 * np.linalg.norm(error[:3]), np.degrees(np.linalg.norm(error[3:]))
print(f"hand {millimetres:.1f} mm, {degrees:.2f} deg from the plan")
args.output.mkdir(parents=True, exist_ok=True)
camera = dict(target="panda_hand", distance=1.2, width=320, height=240)
if args.quick:  # one still: software rendering takes about a second per frame
    render_frame(simulator, state.q, args.output / "cartesian_hand.png", **camera)
else:
    render_animation(simulator, frames, args.output / "cartesian_hand.gif", **camera)
