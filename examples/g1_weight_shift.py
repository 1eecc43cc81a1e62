"""Unitree G1 shifts its weight onto the left foot, lifts the right foot 5 cm and puts it back:
contact switching in the QP controller, in MuJoCo. Writes ``g1_weight_shift.gif`` (``--quick``:
a PNG still).

Balance recipe (docs/your_own_robot.md): the CoM target goes over the centre of the stance
sole's rectangle (not over the ankle) in 1 s (in 0.5 s the centre of pressure reaches the side
edges of the 6 cm wide soles and a tick holds), the foot is unloaded only then, and
``cop_fraction=0.7`` keeps the centre of pressure off the sole's edges. ``explain`` prints
what binds."""

import argparse
from pathlib import Path

import numpy as np

from dmpopt import RobotModel, control
from dmpopt.robot import example_robot_data_dir
from dmpopt.sim import MujocoSimulator, render_animation, render_frame

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("output", type=Path, help="folder for the animation")
parser.add_argument("--quick", action="store_true", help="the first 0.3 s only")
args = parser.parse_args()

bent = {"hip_pitch_joint": -0.2, "knee_joint": 0.4, "ankle_pitch_joint": -0.2, "elbow_joint": 1.2}
g1 = RobotModel.from_urdf(
    example_robot_data_dir() / "g1_description/urdf/g1_29dof_rev_1_0.urdf",
    feet=["left_ankle_roll_link", "right_ankle_roll_link"],  # soles from the collision spheres
    reference={f"{side}_{joint}": a for side in ("left", "right") for joint, a in bent.items()},
)
(left, right), dt = g1.foot_frames, 1e-3
c0, middle, foot = g1.center_of_mass(), g1.sole_center(left), g1.frame_placement(right)

posture, com = control.PostureTask(g1, weight=0.1), control.ComTask(g1, weight=10.0)
pelvis = control.FrameTask(g1, "pelvis", weight=1.0, stiffness=50.0, components="orientation")
soles = [control.SoleContact(g1, foot, cop_fraction=0.7) for foot in g1.foot_frames]
# time_budget: CPU seconds per tick; 1 s in simulation (the 5 ms default is for a real robot)
controller = control.InverseDynamicsController(g1, [posture, com, pelvis], soles, time_budget=1.0)
swing = control.FrameTask(g1, right, weight=10.0, stiffness=400.0)
simulator = MujocoSimulator(g1.model, g1.source, dt, g1.contact_points)
state, frames = simulator.reset(g1.reference_configuration), []
for k in range(300 if args.quick else 3500):
    t, s = k * dt, min(k * dt / 1.0, 1.0)  # over 1 s: the soles are 6 cm wide
    com.set_target(np.r_[c0[:2] + s * s * (3 - 2 * s) * (middle[:2] - c0[:2]), c0[2]])
    if k == 1100:  # the CoM is over the left sole: unload the right one in 0.1 s
        controller.remove_contact(right, transition_time=0.1)
    if k == 1250:
        controller.add_task(swing)
    if 1250 <= k < 2750:  # up 5 cm and down again (pressed 2 mm into the floor on landing)
        up = np.sin(np.pi * min((t - 1.25) / 1.2, 1.0)) ** 2
        swing.set_target(foot.translation + [0, 0, 0.05 * up - 0.002 * (t > 1.85)])
    if k == 2750:
        controller.remove_task(swing)
        controller.add_contact(right, transition_time=0.2)
    state = simulator.step(controller.compute_torques(state.q, state.v, t))
    if controller.stats.last_answer in ("relaxed", "hold") or k in (1150, 1850):
        print(f"t = {t:.3f} s: {control.explain(controller)}")  # what binds, and why
    frames += [state.q] if k % 40 == 0 else []
print(f"fell: {state.fallen}; active contacts {controller.active_contacts}; {controller.stats}")
args.output.mkdir(parents=True, exist_ok=True)
camera = dict(target="pelvis", distance=2.0, width=320, height=240)
if args.quick:  # one still: software rendering takes about a second per frame
    render_frame(simulator, state.q, args.output / "g1_weight_shift.png", **camera)
else:
    render_animation(simulator, frames, args.output / "g1_weight_shift.gif", **camera)
