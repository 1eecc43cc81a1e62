"""Panda reach: a DMP drives the hand to a goal that moves mid-way, through the QP controller
in MuJoCo (fixed base), on a plant with the joint friction, rotor inertia, delay and sensor noise
of a real arm, which the controller knows only nominally. Writes ``panda_reach.gif``
(``--quick``: a PNG still) into the output folder."""

import argparse
from pathlib import Path

import numpy as np
import pinocchio as pin

from dmpopt import RobotModel, fit_discrete, minimum_jerk
from dmpopt.control import FrameTask, InverseDynamicsController, JointImpedance, PostureTask
from dmpopt.robot import example_robot_data_dir
from dmpopt.sim import (
    MujocoSimulator,
    PlantParameters,
    SensorNoise,
    render_animation,
    render_frame,
    with_armature,
)

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("output", type=Path, help="folder for the animation")
parser.add_argument("--quick", action="store_true", help="0.5 s instead of 2 s")
args = parser.parse_args()

noise = SensorNoise(joint_position=1e-5, joint_velocity=0.005)
plant = PlantParameters(armature=0.05, damping=0.5, friction=0.5, delay=1, noise=noise)
files = example_robot_data_dir() / "panda_description"
panda = RobotModel.from_urdf(files / "urdf/panda.urdf", files / "srdf/panda.srdf")
panda = with_armature(panda, plant)  # the controller's model knows the nominal rotor inertia
q0, dt = panda.reference_configuration, 1e-3
data = panda.create_data()
pin.framesForwardKinematics(panda.model, data, q0)
start = data.oMf[panda.model.getFrameId("panda_hand")].translation.copy()
dmp = fit_discrete(minimum_jerk(start, start + [0.1, 0.2, -0.2], 1.0), 20)  # a 1 s reach
stepper = dmp.stepper(dt)

posture = PostureTask(panda, weight=0.01, stiffness=10.0)  # the elbow's null space
posture.set_reference(q0)
hand = FrameTask(panda, "panda_hand", weight=1.0, stiffness=400.0, components="position")
loop = JointImpedance.for_plant(panda, dt, plant)  # copes with friction, damping and delay
controller = InverseDynamicsController(panda, [posture, hand], [], joint_impedance=loop)
simulator = MujocoSimulator(panda.model, panda.source, dt, plant=plant)
state = simulator.reset(q0)
n_steps, frames = int((0.5 if args.quick else 2.0) / dt), []
for k in range(n_steps):
    if k == n_steps // 4:
        stepper.set_goal(start + [0.2, -0.1, -0.1])  # the goal moves: the plan bends smoothly
    position, velocity, acceleration = stepper.step()
    hand.set_target(position, np.r_[velocity, 0, 0, 0], np.r_[acceleration, 0, 0, 0])
    state = simulator.step(controller.compute_torques(state.q_measured, state.v_measured))
    if k % 40 == 0:
        frames.append(state.q)
pin.framesForwardKinematics(panda.model, data, state.q)
error = np.linalg.norm(data.oMf[panda.model.getFrameId("panda_hand")].translation - position)
print(f"hand {1e3 * error:.1f} mm from the plan after {n_steps * dt:g} s")
args.output.mkdir(parents=True, exist_ok=True)
camera = dict(target="panda_hand", distance=1.5, width=320, height=240)
if args.quick:  # one still: software rendering takes about a second per frame
    render_frame(simulator, state.q, args.output / "panda_reach.png", **camera)
else:
    render_animation(simulator, frames, args.output / "panda_reach.gif", **camera)
