"""Panda reach: a DMP drives the hand to a goal that moves mid-way, through the QP controller
in MuJoCo (fixed base), on a plant with the joint friction, rotor inertia, delay and sensor noise
of a real arm, which the controller knows only nominally. Writes ``panda_reach.gif``
(``--quick``: a PNG still) into the output folder."""

import argparse
from pathlib import Path

import numpy as np

from dmpopt import RobotModel, fit_discrete, minimum_jerk, sim
from dmpopt.control import FrameTask, InverseDynamicsController, JointImpedance, PostureTask
from dmpopt.robot import example_robot_data_dir

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("output", type=Path, help="folder for the animation")
parser.add_argument("--quick", action="store_true", help="0.5 s instead of 2 s")
args = parser.parse_args()

noise = sim.SensorNoise(joint_position=1e-5, joint_velocity=0.005)
plant = sim.PlantParameters(armature=0.05, damping=0.5, friction=0.5, delay=1, noise=noise)
files = example_robot_data_dir() / "panda_description"
panda = RobotModel.from_urdf(files / "urdf/panda.urdf", files / "srdf/panda.srdf")
panda = sim.with_armature(panda, plant)  # the controller's model knows the nominal rotor inertia
dt, start = 1e-3, panda.frame_placement("panda_hand").translation  # in the reference posture
stepper = fit_discrete(minimum_jerk(start, start + [0.1, 0.2, -0.2], 1.0), 20).stepper(dt)

posture = PostureTask(panda, weight=0.01, stiffness=10.0)  # the elbow's null space
hand = FrameTask(panda, "panda_hand", weight=1.0, stiffness=400.0, components="position")
loop = JointImpedance.for_plant(panda, dt, plant)  # copes with friction, damping and delay
controller = InverseDynamicsController(panda, [posture, hand], [], joint_impedance=loop)
simulator = sim.MujocoSimulator(panda.model, panda.source, dt, plant=plant)
state, frames = simulator.reset(panda.reference_configuration), []
n_steps = int((0.5 if args.quick else 2.0) / dt)
for k in range(n_steps):
    if k == n_steps // 4:
        stepper.set_goal(start + [0.2, -0.1, -0.1])  # the goal moves: the plan bends smoothly
    position, velocity, acceleration = stepper.step()
    hand.set_target(position, velocity, acceleration)
    state = simulator.step(controller.compute_torques(state.q_measured, state.v_measured))
    frames += [state.q] if k % 40 == 0 else []
error = np.linalg.norm(panda.frame_placement("panda_hand", state.q).translation - position)
print(f"hand {1e3 * error:.1f} mm from the plan after {n_steps * dt:g} s")
args.output.mkdir(parents=True, exist_ok=True)
camera = dict(target="panda_hand", distance=1.5, width=320, height=240)
if args.quick:  # one still: software rendering takes about a second per frame
    sim.render_frame(simulator, state.q, args.output / "panda_reach.png", **camera)
else:
    sim.render_animation(simulator, frames, args.output / "panda_reach.gif", **camera)
