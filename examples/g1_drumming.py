"""Unitree G1 standing and drumming: a rhythmic DMP on both arms, started on its limit cycle,
tracked by the QP controller while the soles hold the robot up, in MuJoCo, on a plant with joint
friction, rotor inertia, delay and sensor noise that the controller knows only nominally. Writes
``g1_drumming.gif`` (``--quick``: a PNG still) into the output folder."""

import argparse
from pathlib import Path

import numpy as np
import pinocchio as pin

from dmpopt import RobotModel, Trajectory, fit_rhythmic
from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    JointImpedance,
    PostureTask,
    SoleContact,
)
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
parser.add_argument("--quick", action="store_true", help="0.5 s instead of 4 s")
args = parser.parse_args()

bent = {"hip_pitch_joint": -0.2, "knee_joint": 0.4, "ankle_pitch_joint": -0.2, "elbow_joint": 1.2}
g1 = RobotModel.from_urdf(
    example_robot_data_dir() / "g1_description/urdf/g1_29dof_rev_1_0.urdf",
    feet=["left_ankle_roll_link", "right_ankle_roll_link"],  # soles from the collision spheres
    reference={f"{side}_{joint}": a for side in ("left", "right") for joint, a in bent.items()},
)
noise = SensorNoise(joint_position=1e-5, joint_velocity=0.005, base_orientation=1e-3)
plant = PlantParameters(armature=0.02, damping=0.2, friction=0.3, delay=1, noise=noise)
g1 = with_armature(g1, plant)  # the controller's model knows the nominal rotor inertia
drum = [
    f"{side}_{joint}"
    for side in ("left", "right")
    for joint in ("shoulder_pitch_joint", "elbow_joint")
]
times, dt = np.linspace(0.0, 1.6, 801), 1e-3  # two beats of 0.8 s, both arms strike together
beat = np.sin(2 * np.pi * times / 0.8)[:, None] * [[-0.25, 0.3, -0.25, 0.3]]
dmp = fit_rhythmic(Trajectory.from_positions(times, [-0.3, 1.2, -0.3, 1.2] + beat), 15, period=0.8)
stepper = dmp.stepper(dt, on_limit_cycle=True)  # no jolt: position and velocity on the cycle
q0, v0 = g1.reference_configuration.copy(), np.zeros(g1.nv)
q0[g1.configuration_indices(drum)], v0[g1.velocity_indices(drum)] = (
    stepper.position,
    stepper.velocity,
)

posture, arms = PostureTask(g1, weight=0.1), PostureTask(g1, drum, weight=1.0, stiffness=100.0)
posture.set_reference(q0[7:])
com = ComTask(g1, weight=10.0)
com.set_target(pin.centerOfMass(g1.model, g1.create_data(), q0))
pelvis = FrameTask(g1, "pelvis", weight=1.0, stiffness=50.0, components="orientation")
soles = [SoleContact(g1, foot, cop_fraction=0.7) for foot in g1.foot_frames]
loop = JointImpedance.for_plant(g1, dt, plant)  # copes with friction, damping and delay
controller = InverseDynamicsController(
    g1, [posture, arms, com, pelvis], soles, joint_impedance=loop
)
simulator = MujocoSimulator(
    g1.model, g1.source, dt, g1.contact_points, fall_frame="pelvis", plant=plant
)
state, frames = simulator.reset(q0, v0), []
for k in range(int((0.5 if args.quick else 4.0) / dt)):
    arms.set_reference(*stepper.step())
    state = simulator.step(controller.compute_torques(state.q_measured, state.v_measured))
    frames += [state.q] if k % 40 == 0 else []
print(f"fell: {state.fallen}; controller answers: {controller.stats}")
args.output.mkdir(parents=True, exist_ok=True)
camera = dict(target="torso_link", distance=2.0, width=320, height=240)
if args.quick:  # one still: software rendering takes about a second per frame
    render_frame(simulator, state.q, args.output / "g1_drumming.png", **camera)
else:
    render_animation(simulator, frames, args.output / "g1_drumming.gif", **camera)
