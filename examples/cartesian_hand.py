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
q0, dt, data = panda.reference_configuration, 1e-3, panda.create_data()
pin.framesForwardKinematics(panda.model, data, q0)
start = data.oMf[panda.model.getFrameId("panda_hand")].copy()

times = np.linspace(0.0, 1.0, 201)  # the demonstration: 15 cm forward while tilting about y
s = 10 * times**3 - 15 * times**4 + 6 * times**5
positions = start.translation + np.outer(s, [0.15, 0.0, -0.1])
tilts = [pin.Quaternion(start.rotation @ pin.exp3(np.array([0.0, np.pi / 3 * a, 0.0]))) for a in s]
dmp = fit_cartesian(times, positions, [[q.w, q.x, q.y, q.z] for q in tilts], n_basis=20)
goal = pin.Quaternion(start.rotation @ pin.exp3(np.array([0.0, np.pi / 4, 0.3])))  # another tilt
dmp = dmp.with_goal(
    position=start.translation + [0.1, 0.15, -0.15], orientation=[goal.w, goal.x, goal.y, goal.z]
)
stepper = dmp.stepper(dt)

posture = PostureTask(panda, weight=0.01, stiffness=10.0)
posture.set_reference(q0)
hand = FrameTask(panda, "panda_hand", weight=1.0, stiffness=400.0)  # position and orientation
controller = InverseDynamicsController(panda, [posture, hand], [])
simulator = MujocoSimulator(panda.model, panda.source, dt)
state, frames = simulator.reset(q0), []
for k in range(int((0.4 if args.quick else 1.5) / dt)):
    position, velocity, acceleration, quaternion, omega, alpha = stepper.step()
    w, x, y, z = quaternion
    target = pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), position)
    hand.set_target(target, np.r_[velocity, omega], np.r_[acceleration, alpha])
    state = simulator.step(controller.compute_torques(state.q, state.v))
    frames += [state.q] if k % 40 == 0 else []
pin.framesForwardKinematics(panda.model, data, state.q)
error = pin.log6(data.oMf[panda.model.getFrameId("panda_hand")].actInv(target)).vector
millimetres, degrees = 1e3 * np.linalg.norm(error[:3]), np.degrees(np.linalg.norm(error[3:]))
print(f"hand {millimetres:.1f} mm, {degrees:.2f} deg from the plan")
args.output.mkdir(parents=True, exist_ok=True)
camera = dict(target="panda_hand", distance=1.2, width=320, height=240)
if args.quick:  # one still: software rendering takes about a second per frame
    render_frame(simulator, state.q, args.output / "cartesian_hand.png", **camera)
else:
    render_animation(simulator, frames, args.output / "cartesian_hand.gif", **camera)
