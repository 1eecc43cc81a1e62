"""Unitree G1 standing and drumming: a rhythmic DMP on both arms, started on its limit cycle,
tracked by the QP controller while the soles hold the robot up, in MuJoCo, on a plant with joint
friction, rotor inertia, delay and sensor noise that the controller knows only nominally. Writes
``g1_drumming.gif`` (``--quick``: a PNG still) into the output folder."""

import argparse
from pathlib import Path

import numpy as np

from dmpopt import RobotModel, Trajectory, control, fit_rhythmic, sim
from dmpopt.robot import example_robot_data_dir

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("output", type=Path, help="folder for the animation")
parser.add_argument("--quick", action="store_true", help="0.5 s instead of 4 s")
args = parser.parse_args()

times, dt = np.linspace(0.0, 1.6, 801), 1e-3  # two beats of 0.8 s, both arms strike together
beat = np.sin(2 * np.pi * times / 0.8)[:, None] * [[-0.25, 0.3, -0.25, 0.3]]
dmp = fit_rhythmic(Trajectory.from_positions(times, [-0.3, 1.2, -0.3, 1.2] + beat), 15, period=0.8)
stepper = dmp.stepper(dt, on_limit_cycle=True)  # no jolt: position and velocity on the cycle
bent = {"hip_pitch_joint": -0.2, "knee_joint": 0.4, "ankle_pitch_joint": -0.2}
g1 = RobotModel.from_urdf(
    example_robot_data_dir() / "g1_description/urdf/g1_29dof_rev_1_0.urdf",
    feet=["left_ankle_roll_link", "right_ankle_roll_link"],  # soles from the collision spheres
    groups={"drum": "(left|right)_(shoulder_pitch|elbow)_joint"},  # in the DMP's order
    reference={f"{side}_{joint}": a for side in ("left", "right") for joint, a in bent.items()},
)
noise = sim.SensorNoise(joint_position=1e-5, joint_velocity=0.005, base_orientation=1e-3)
plant = sim.PlantParameters(armature=0.02, damping=0.2, friction=0.3, delay=1, noise=noise)
g1 = sim.with_armature(g1, plant)  # the controller's model knows the nominal rotor inertia
q0, v0 = g1.reference_state("drum", stepper.position, stepper.velocity)  # arms on the cycle

posture = control.PostureTask(g1, weight=0.1)
posture.set_reference(q0[7:])
arms = control.PostureTask(g1, "drum", weight=1.0, stiffness=100.0)
com = control.ComTask(g1, weight=10.0)
com.set_target(g1.center_of_mass(q0))
pelvis = control.FrameTask(g1, "pelvis", weight=1.0, stiffness=50.0, components="orientation")
soles = [control.SoleContact(g1, foot, cop_fraction=0.7) for foot in g1.foot_frames]
loop = control.JointImpedance.for_plant(g1, dt, plant)  # copes with friction, damping and delay
tasks = [posture, arms, com, pelvis]
controller = control.InverseDynamicsController(g1, tasks, soles, joint_impedance=loop)
simulator = sim.MujocoSimulator(g1.model, g1.source, dt, g1.contact_points, plant=plant)
state, frames = simulator.reset(q0, v0), []
for k in range(int((0.5 if args.quick else 4.0) / dt)):
    arms.set_reference(*stepper.step())
    state = simulator.step(controller.compute_torques(state.q_measured, state.v_measured))
    frames += [state.q] if k % 40 == 0 else []
print(f"fell: {state.fallen}; controller answers: {controller.stats}")
args.output.mkdir(parents=True, exist_ok=True)
camera = dict(target="torso_link", distance=2.0, width=320, height=240)
if args.quick:  # one still: software rendering takes about a second per frame
    sim.render_frame(simulator, state.q, args.output / "g1_drumming.png", **camera)
else:
    sim.render_animation(simulator, frames, args.output / "g1_drumming.gif", **camera)
