r"""Two hands carry a box: standing Talos in MuJoCo, the hands' DMPs coupled and uncoupled.

Part of the primitives study (metrics under ``bimanual``); claim (issue 33): the coupling of
:mod:`dmpopt.bimanual` holds the hands' relative pose when one hand's plan is perturbed, so a
box held between the hands by contact and friction alone is carried; without the coupling the
same perturbation opens or squeezes the grasp.

Set-up (all choices are ours):

* robot: Talos (full model) standing, MuJoCo with the realistic plant
  (:func:`dmpopt_robots.plants.talos_realistic`: armature, damping, friction, torque saturation, one
  tick of delay, sensor noise) and the humanoid study's controller design
  (:mod:`dmpopt_studies.humanoid.controller`): :class:`dmpopt.control.InverseDynamicsController` at
  1 kHz with the nominal armature in its model, friction fed forward, a
  :class:`dmpopt.control.JointImpedance` around the QP's motion; tasks: whole-body posture,
  CoM, pelvis orientation, two sole contacts, and one full-pose :class:`FrameTask` per hand
  (``gripper_*_base_link``, stiffness ``HAND_STIFFNESS``) fed the hand plans' pose,
  velocity and acceleration;
* grasp: arms forward (damped least squares from the drumming posture), the hands
  ``HAND_GAP`` apart and a box of ``BOX_MASS`` (a MuJoCo free body, :class:`FreeBox`, no weld)
  between the grippers, as wide as their gap; the plans ask the hands for ``SQUEEZE`` more
  closure than the box allows, so the hand tasks press on it: the box is held by contact and
  friction (``BOX_FRICTION``) only;
* plans: one :class:`dmpopt.CartesianDMP` per hand fitted to a minimum-jerk carry of the box
  (``LIFT`` up and ``SIDEWAYS`` to the robot's left in ``CARRY_SECONDS``, hands translated
  with it, orientations fixed) after ``HOLD_SECONDS`` of holding; at ``GOAL_CHANGE`` into the
  movement the box's goal moves by ``NEW_GOAL_SHIFT``;
* perturbation: the left hand's plan runs ``LEFT_SLOWER`` times slower (its ``tau``) and
  receives the new goal ``LEFT_GOAL_DELAY`` later than the right hand;
* coupled: :class:`dmpopt.bimanual.BimanualStepper` with the
  :class:`~dmpopt.bimanual.RelativePoseCoupling` of the grasp (defaults: stiffness 1000 1/s^2,
  critical damping, correction shared equally); uncoupled: the same plans without it;
* metrics per run: ``relative_pose_error_mm`` / ``_deg``: largest change of the relative
  pose of the **measured** hands (MuJoCo state, Pinocchio kinematics) from the one at the
  end of the hold (the settled grasp), after the hold; ``plan_relative_error_mm`` /
  ``_deg``: the largest error of the plans against the coupling's ``r*, q*``;
  ``box_drop_mm``: how far the box ends below where the carry should leave it (its start
  height plus ``LIFT`` and the new goal's rise); ``fell``: the robot fell (or the
  simulation diverged);
* quick mode: the plans only, 1.5 s of them (``plan_relative_error_mm``; no MuJoCo run and
  no video: the two robot runs take one to three minutes on the loaded machine); the robot
  runs in the full study;
* video (full mode, MuJoCo's offscreen renderer, ``VIDEO_FPS``): both runs side by side in
  time, ``bimanual_coupled.webp`` and ``bimanual_uncoupled.webp``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from dmpopt_robots.plants import talos_realistic
from dmpopt_studies.common import TIME_BUDGET
from dmpopt_studies.humanoid.demos import drumming_posture
from dmpopt_studies.humanoid.parameters import (
    BASE_WEIGHT,
    COM_WEIGHT,
    CONTROLLER_FRICTION,
    DT,
    FALL_HEIGHT,
    HAND_STIFFNESS,
    JOINT_LIMIT_HORIZON,
    MUJOCO_FRICTION,
    POSTURE_WEIGHT,
)

from dmpopt import fit_cartesian
from dmpopt.bimanual import (
    BimanualStepper,
    RelativePoseCoupling,
    matrix_quaternion,
    relative_pose_error,
)
from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    JointImpedance,
    PostureTask,
    SoleContact,
    control_loop,
)
from dmpopt.exceptions import MissingDependency, SimulationDiverged
from dmpopt.fitting import minimum_jerk
from dmpopt.sim import with_armature
from dmpopt.sim.mujoco_backend import FreeBox, MujocoSimulator

HAND_CENTRE = np.array([0.42, 0.0, 1.0])  # [m] midpoint of the hands at the grasp (world)
HAND_GAP = 0.36  # [m] distance of the two hand frames at the grasp
SQUEEZE = 0.02  # [m] the plans' hands this much closer than the box allows
BOX_MASS = 0.5  # [kg]
BOX_FRICTION = 1.0
BOX_HALF_DEPTH, BOX_HALF_HEIGHT = 0.06, 0.06  # [m] along x and z
HOLD_SECONDS = 0.5  # [s] the grasp settles before the carry
CARRY_SECONDS = 1.5  # [s] of the demonstration
LIFT, SIDEWAYS = 0.08, 0.10  # [m] the carry: up, and to the robot's left (+y)
GOAL_CHANGE = 0.6  # [s] into the carry, the box's goal moves
NEW_GOAL_SHIFT = np.array([0.05, -0.15, 0.02])  # [m] forward, to the right, up
LEFT_SLOWER = 1.3  # the left plan's tau over the right one's
LEFT_GOAL_DELAY = 0.2  # [s] the left plan learns of the new goal this much later
RUN_SECONDS = {"full": 3.5, "quick": 2.0}  # [s] per run, hold included
VIDEO_FPS = 20.0
VIDEO_SIZE = (320, 240)  # [pixels]
HANDS = ("gripper_left_base_link", "gripper_right_base_link")


# ---------------------------------------------------------------------------- the grasp
def grasp_posture(robot) -> np.ndarray:
    """Configuration with the hand frames at ``HAND_CENTRE +- HAND_GAP / 2`` along y, their
    orientations those of the drumming posture (damped least squares on both arms)."""
    q = drumming_posture(robot)
    data = robot.create_data()
    frames = [robot.model.getFrameId(name) for name in HANDS]
    pin.framesForwardKinematics(robot.model, data, q)
    rotations = [data.oMf[f].rotation.copy() for f in frames]
    targets = [HAND_CENTRE + [0.0, HAND_GAP / 2, 0.0], HAND_CENTRE - [0.0, HAND_GAP / 2, 0.0]]
    for side, frame, rotation, target in zip(("left", "right"), frames, rotations, targets):
        rows = robot.configuration_indices(f"{side}_arm")
        columns = robot.velocity_indices(f"{side}_arm")
        wanted = pin.SE3(rotation, target)
        for _ in range(200):
            pin.framesForwardKinematics(robot.model, data, q)
            error = pin.log6(data.oMf[frame].actInv(wanted)).vector
            if np.linalg.norm(error) < 1e-10:
                break
            jacobian = pin.computeFrameJacobian(robot.model, data, q, frame, pin.LOCAL)[:, columns]
            step = jacobian.T @ np.linalg.solve(jacobian @ jacobian.T + 1e-6 * np.eye(6), error)
            q[rows] = np.clip(
                q[rows] + step,
                robot.model.lowerPositionLimit[rows] + 1e-3,
                robot.model.upperPositionLimit[rows] - 1e-3,
            )
    return q


def hand_poses(robot, data, q) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(position, quaternion (w, x, y, z))`` of both hand frames at ``q``."""
    pin.framesForwardKinematics(robot.model, data, q)
    poses = []
    for name in HANDS:
        placement = data.oMf[robot.model.getFrameId(name)]
        poses.append((placement.translation.copy(), matrix_quaternion(placement.rotation)))
    return poses


def box_width(simulator: MujocoSimulator) -> float:
    """Gap between the grippers' collision geometry along y at the simulator's state [m]."""
    model, data = simulator.mj_model, simulator.mj_data
    inner = {}
    for side, sign in (("left", 1.0), ("right", -1.0)):
        extremes = []
        for geom in range(model.ngeom):
            body = model.body(model.geom_bodyid[geom]).name
            if not body.startswith(f"gripper_{side}") or model.geom_dataid[geom] < 0:
                continue
            mesh = model.geom_dataid[geom]
            start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
            vertices = model.mesh_vert[start : start + count]
            world = data.geom_xpos[geom] + vertices @ data.geom_xmat[geom].reshape(3, 3).T
            extremes.append(sign * world[:, 1].min() if sign > 0 else world[:, 1].max())
        inner[side] = min(extremes) if sign > 0 else max(extremes)
    return float(inner["left"] - inner["right"])


def box_centre(simulator: MujocoSimulator) -> np.ndarray:
    """Centre of the box between the grippers: mid-gap in y, the middle of the grippers'
    inner geometry in x and z [m]."""
    model, data = simulator.mj_model, simulator.mj_data
    points = []
    for geom in range(model.ngeom):
        if model.body(model.geom_bodyid[geom]).name.startswith("gripper_") and (
            model.geom_dataid[geom] >= 0
        ):
            mesh = model.geom_dataid[geom]
            start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
            vertices = model.mesh_vert[start : start + count]
            points.append(data.geom_xpos[geom] + vertices @ data.geom_xmat[geom].reshape(3, 3).T)
    points = np.vstack(points)
    low, high = points.min(axis=0), points.max(axis=0)
    return np.array([(low[0] + high[0]) / 2, (low[1] + high[1]) / 2, (low[2] + high[2]) / 2])


# ---------------------------------------------------------------------------- controller
def build_controller(robot, q_start: np.ndarray, plant):
    """The humanoid study's controller design with one full-pose task per hand.

    As :func:`dmpopt_studies.humanoid.controller.build_controller` on the realistic plant: the
    nominal armature in the model, friction fed forward, the joint impedance; posture, CoM
    (at the start, no sink: MuJoCo), pelvis orientation, two sole contacts; both arms kept
    within their limits. Returns the controller and the two hand tasks (left, right).
    """
    model_robot = with_armature(robot, plant)
    impedance = JointImpedance.for_plant(model_robot, DT, plant)
    actuated = np.sort(
        np.concatenate(
            [model_robot.configuration_indices([n]) for n in model_robot.actuated_joint_names]
        )
    )
    posture = PostureTask(model_robot, weight=POSTURE_WEIGHT, stiffness=10.0)
    posture.set_reference(q_start[actuated])
    data = model_robot.create_data()
    pin.framesForwardKinematics(model_robot.model, data, q_start)
    hands = []
    for name in HANDS:
        task = FrameTask(model_robot, name, weight=1.0, stiffness=HAND_STIFFNESS)
        task.set_target(data.oMf[model_robot.model.getFrameId(name)].copy())
        hands.append(task)
    com = ComTask(model_robot, weight=COM_WEIGHT, stiffness=50.0)
    com.set_target(pin.centerOfMass(model_robot.model, model_robot.create_data(), q_start))
    base = FrameTask(
        model_robot, "base_link", weight=BASE_WEIGHT, stiffness=50.0, components="orientation"
    )
    contacts = [
        SoleContact(model_robot, f, friction_coefficient=CONTROLLER_FRICTION)
        for f in model_robot.foot_frames
    ]
    controller = InverseDynamicsController(
        model_robot,
        [posture, *hands, com, base],
        contacts,
        joint_limit_horizon=JOINT_LIMIT_HORIZON,
        limited_joints=[*robot.joint_groups["left_arm"], *robot.joint_groups["right_arm"]],
        time_budget=TIME_BUDGET,
        joint_impedance=impedance,
    )
    return controller, hands


def make_simulator(robot, q_start: np.ndarray, plant):
    """MuJoCo with the realistic plant, soles on the floor and the box between the grippers
    (as wide as their gap); returns the simulator and the box's start centre."""
    points = [(f, c) for f in robot.foot_frames for c in robot.sole_corners]
    options = {"fall_frame": "base_link", "fall_height": FALL_HEIGHT, "plant": plant}
    probe = MujocoSimulator(robot.model, robot.source, DT, points, MUJOCO_FRICTION, **options)
    probe.reset(q_start)
    width, centre = box_width(probe), box_centre(probe)
    box = FreeBox(
        "box",
        (BOX_HALF_DEPTH, width / 2, BOX_HALF_HEIGHT),
        BOX_MASS,
        tuple(centre),
        friction=BOX_FRICTION,
    )
    simulator = MujocoSimulator(
        robot.model, robot.source, DT, points, MUJOCO_FRICTION, free_bodies=[box], **options
    )
    return simulator, centre


# ---------------------------------------------------------------------------- the plans
def hand_dmps(start_poses):
    """One Cartesian DMP per hand, fitted to the minimum-jerk carry of the box (the hand
    translated with it, orientation fixed; one fit, moved to each hand); the left one
    ``LEFT_SLOWER`` times slower."""
    carry = np.array([0.0, SIDEWAYS, LIFT])
    path = minimum_jerk(np.zeros(3), carry, CARRY_SECONDS, 0.002)
    (position, orientation) = start_poses[0]
    orientations = np.tile(orientation, (path.times.size, 1))
    fitted = fit_cartesian(path.times, position + path.positions, orientations)
    dmps = []
    for (position, orientation), slower in zip(start_poses, (LEFT_SLOWER, 1.0)):
        dmp = fitted.with_start(position, orientation).with_goal(position + carry, orientation)
        dmps.append(dmp.with_tau(dmp.tau * slower))
    return dmps


def grasp_coupling(start_poses) -> tuple:
    """The coupling of the squeezed grasp (the hands ``SQUEEZE`` nearer each other) and the
    squeezed hand poses."""
    (left, left_q), (right, right_q) = start_poses
    inward = (left - right) / np.linalg.norm(left - right)
    squeezed = [(left - inward * SQUEEZE / 2, left_q), (right + inward * SQUEEZE / 2, right_q)]
    (left, left_q), (right, right_q) = squeezed
    return RelativePoseCoupling.from_poses(left, left_q, right, right_q), squeezed


# ---------------------------------------------------------------------------- a run
def carry_setup(robot) -> tuple:
    """The grasp configuration, its coupling and the two hands' plans (left, right)."""
    q_start = grasp_posture(robot)
    coupling, squeezed = grasp_coupling(hand_poses(robot, robot.create_data(), q_start))
    return q_start, coupling, *hand_dmps(squeezed)


def carry(robot, setup, coupled: bool, duration: float, record_every: int = 0, seed=0) -> dict:
    """One carry (module docstring) from ``setup`` (:func:`carry_setup`); returns its
    metrics and time series."""
    plant = talos_realistic(robot, seed)
    q_start, coupling, left_dmp, right_dmp = setup
    controller, tasks = build_controller(robot, q_start, plant)
    simulator, box_start = make_simulator(robot, q_start, plant)
    data = robot.create_data()
    pair = BimanualStepper(left_dmp, right_dmp, coupling if coupled else None, DT)
    hold = int(round(HOLD_SECONDS / DT))
    change = hold + int(round(GOAL_CHANGE / DT))
    left_change = change + int(round(LEFT_GOAL_DELAY / DT))
    n = int(round(duration / DT))
    state = simulator.reset(q_start)
    held = coupling  # the measured grasp, from the end of the hold
    plan_error, measured_error = np.zeros((n, 2)), np.zeros((n, 2))
    box = np.zeros((n, 3))
    frames, box_frames = [], []
    fell = False
    with control_loop():
        for k in range(n):
            if k > hold:
                pair.step()
            if k == change:
                pair.set_goal("right", position=right_dmp.goal + NEW_GOAL_SHIFT)
            if k == left_change:
                pair.set_goal("left", position=left_dmp.goal + NEW_GOAL_SHIFT)
            for hand, task in zip(("left", "right"), tasks):
                position, velocity, orientation, angular = pair.state(hand)
                stepper = getattr(pair, hand)
                w, x, y, z = orientation
                placement = pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), position)
                task.set_target(
                    placement,
                    np.concatenate((velocity, angular)),
                    np.concatenate((stepper.acceleration, stepper.angular_acceleration)),
                )
            plans = [pair.state(hand)[::2] for hand in ("left", "right")]
            plan_error[k] = relative_pose_error(coupling, *plans)
            measured = hand_poses(robot, data, state.q)
            if k == hold:
                (left, left_q), (right, right_q) = measured
                held = RelativePoseCoupling.from_poses(left, left_q, right, right_q)
            measured_error[k] = relative_pose_error(held, *measured)
            box[k] = simulator.free_body_qpos[:3]
            if record_every and k % record_every == 0:
                frames.append(state.q.copy())
                box_frames.append(simulator.free_body_qpos)
            tau = controller.compute_torques(state.q_measured, state.v_measured)
            try:
                state = simulator.step(tau)
            except SimulationDiverged:
                fell = True
            if fell or state.fallen:
                fell, n = True, k + 1
                break
    after = slice(hold, n)
    before_hold = np.arange(n) < hold  # measured against the settled grasp from the hold on
    lifted = box_start[2] + LIFT + NEW_GOAL_SHIFT[2]
    return {
        "relative_pose_error_mm": 1e3 * float(measured_error[after, 0].max()),
        "relative_pose_error_deg": float(np.degrees(measured_error[after, 1].max())),
        "plan_relative_error_mm": 1e3 * float(plan_error[after, 0].max()),
        "plan_relative_error_deg": float(np.degrees(plan_error[after, 1].max())),
        "box_drop_mm": 1e3 * float(max(0.0, lifted - box[n - 1, 2])),
        "fell": bool(fell),
        "series": {
            "times": np.arange(n) * DT,
            "measured_mm": np.where(before_hold, np.nan, 1e3 * measured_error[:n, 0]),
            "measured_deg": np.where(before_hold, np.nan, np.degrees(measured_error[:n, 1])),
            "plan_mm": 1e3 * plan_error[:n, 0],
            "box_z": box[:n, 2],
        },
        "frames": frames,
        "box_frames": box_frames,
        "simulator": simulator,
    }


def plans_only(setup, coupled: bool, duration: float) -> dict:
    """The carry's plans without the robot (quick mode), from ``setup``
    (:func:`carry_setup`), the same perturbation; the plans' relative pose error."""
    _, coupling, left_dmp, right_dmp = setup
    pair = BimanualStepper(left_dmp, right_dmp, coupling if coupled else None, DT)
    change = int(round(GOAL_CHANGE / DT))
    left_change = change + int(round(LEFT_GOAL_DELAY / DT))
    n = int(round((duration - HOLD_SECONDS) / DT))
    errors = np.zeros((n, 2))
    for k in range(n):
        if k:
            pair.step()
        if k == change:
            pair.set_goal("right", position=right_dmp.goal + NEW_GOAL_SHIFT)
        if k == left_change:
            pair.set_goal("left", position=left_dmp.goal + NEW_GOAL_SHIFT)
        plans = [pair.state(hand)[::2] for hand in ("left", "right")]
        errors[k] = relative_pose_error(coupling, *plans)
    return {
        "plan_relative_error_mm": 1e3 * float(errors[:, 0].max()),
        "plan_relative_error_deg": float(np.degrees(errors[:, 1].max())),
        "series": {"times": HOLD_SECONDS + np.arange(n) * DT, "plan_mm": 1e3 * errors[:, 0]},
    }


def bimanual_metrics(out, quick: bool, progress=None) -> dict:
    """The ``bimanual`` metrics (module docstring), the figure ``primitives_bimanual.png`` and,
    in full mode, the two videos."""
    from dmpopt_robots import load_talos

    duration = RUN_SECONDS["quick" if quick else "full"]
    robot = load_talos("full")
    setup = carry_setup(robot)
    runs = {}
    for name, coupled in (("coupled", True), ("uncoupled", False)):
        if progress is not None:
            progress(f"bimanual carry, {name}" + (" (plans only)" if quick else ", MuJoCo"))
        if quick:
            runs[name] = plans_only(setup, coupled, duration)
        else:
            record = int(round(1.0 / (VIDEO_FPS * DT)))
            runs[name] = carry(robot, setup, coupled, duration, record_every=record)
    plot(out, runs, quick)
    metrics = {name: {k: v for k, v in run.items() if k not in ("series", "frames",
               "box_frames", "simulator")} for name, run in runs.items()}  # fmt: skip
    metrics["robot"] = "plans only (quick mode)" if quick else "Talos in MuJoCo, realistic plant"
    metrics["videos"], metrics["videos_skipped"] = (
        ([], "quick mode") if quick else write_videos(out, runs)
    )
    return metrics


def write_videos(out, runs: dict) -> tuple[list, str | None]:
    """``bimanual_<run>.webp`` of each run's recorded frames, the camera on the box."""
    from dmpopt.sim import render_animation

    written = []
    for name, run in runs.items():
        try:
            path = render_animation(
                run["simulator"],
                run["frames"],
                out / f"bimanual_{name}.webp",
                VIDEO_FPS,
                *VIDEO_SIZE,
                distance=1.8,
                target=tuple(HAND_CENTRE),
                azimuth=150.0,
                shadows=False,  # a standing robot; about twice as fast to render
                free_body_qpos=run["box_frames"],
            )
        except MissingDependency as error:
            return written, str(error)
        written.append(path.name)
    return written, None


def plot(out, runs: dict, quick: bool) -> None:
    """primitives_bimanual.png: relative pose error over time, coupled and uncoupled (and the
    box's height on the robot)."""
    from dmpopt_studies.common import pyplot

    plt = pyplot()
    columns = 1 if quick else 2
    figure, axes = plt.subplots(1, columns, figsize=(5 * columns, 3.6), squeeze=False)
    axis = axes[0, 0]
    for (name, run), colour in zip(runs.items(), ("tab:blue", "tab:red")):
        series = run["series"]
        axis.plot(series["times"], series["plan_mm"], color=colour, ls="--", label=f"{name}, plans")
        if not quick:
            axis.plot(series["times"], series["measured_mm"], color=colour, label=f"{name}, robot")
    axis.axvline(HOLD_SECONDS + GOAL_CHANGE, color="grey", lw=0.8)
    axis.set(xlabel="time [s]", ylabel="relative position error [mm]", title="hands' relative pose")
    axis.legend(fontsize=7)
    if not quick:
        axis = axes[0, 1]
        for (name, run), colour in zip(runs.items(), ("tab:blue", "tab:red")):
            axis.plot(run["series"]["times"], run["series"]["box_z"], color=colour, label=name)
        axis.set(xlabel="time [s]", ylabel="box height [m]", title="the box (MuJoCo free body)")
        axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(out / "primitives_bimanual.png", dpi=120)
    plt.close(figure)
