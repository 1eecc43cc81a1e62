"""Figures and MuJoCo videos of the humanoid study."""

from __future__ import annotations

import numpy as np

from dmpopt.exceptions import MissingDependency

from ..common import pyplot
from .controller import mujoco_plant
from .demos import DRUM_JOINTS
from .metrics import rms
from .parameters import VIDEO_FPS, VIDEO_SECONDS, VIDEO_SIZE
from .swing import SWING_JOINTS

SWING_CLIP_SECONDS = 1.5  # [s] the forehand's clip: the swing, without the rest after it


def video_clips(robot, study) -> dict:
    """The clips to render from the MuJoCo runs: drumming, figure-8, the push shown and the
    forehand (its first ``SWING_CLIP_SECONDS``)."""
    frames = int(VIDEO_SECONDS * VIDEO_FPS)
    drum, figure8 = study.runs["none"], study.figure8
    push_frames = study.mujoco["push"]["log"].extras["frames"]
    swing = study.swings["demonstrated_goal"].log
    # The push ran in a worker: a simulator of the same scene renders its configurations.
    push_simulator = mujoco_plant()(robot, push_frames[0])[0]
    return {
        "humanoid_drumming": (drum.extras["simulator"], drum.extras["frames"][:frames], 3.0),
        "humanoid_figure8": (figure8.extras["simulator"], figure8.extras["frames"][:frames], 3.0),
        "humanoid_push": (push_simulator, push_frames, 3.5),
        "humanoid_swing": (
            swing.extras["simulator"],
            swing.extras["frames"][: int(SWING_CLIP_SECONDS * VIDEO_FPS)],
            3.0,
        ),
    }


def write_videos(out, clips: dict, skip_reason: str | None = None) -> tuple[list, str | None]:
    """Render ``clips`` (name -> (MujocoSimulator, configurations, camera distance [m])).

    Each becomes ``out / (name + ".webp")`` (at most 5 MB). Returns the file names written
    and why the others were skipped: ``skip_reason`` if given (nothing is rendered), or the
    :class:`MissingDependency` message (no OpenGL context, no Pillow), else None.
    """
    if skip_reason is not None:
        return [], skip_reason
    from dmpopt.sim import render_animation

    written = []
    width, height = VIDEO_SIZE
    for name, (simulator, frames, distance) in clips.items():
        try:
            path = render_animation(
                simulator,
                frames,
                out / f"{name}.webp",
                VIDEO_FPS,
                width,
                height,
                distance,
                shadows=False,  # standing robots; about twice as fast to render
            )
        except MissingDependency as error:
            return written, str(error)
        written.append(path.name)
    return written, None


def plot(out, dmps, demo, study) -> None:
    """Write the study's figures into ``out`` (``study``: a :class:`StudyRuns`)."""
    plt = pyplot()
    _fig4_elbow(plt, study, dmps.elbow_index).savefig(out / "fig4_elbow.png", dpi=120)
    _drumming_tracking(plt, study).savefig(out / "drumming_tracking.png", dpi=110)
    _demonstration(plt, demo).savefig(out / "demonstration.png", dpi=110)
    _figure8(plt, study).savefig(out / "figure8.png", dpi=120)
    _base_com(plt, study).savefig(out / "base_com.png", dpi=110)
    _tick_times(plt, study).savefig(out / "tick_times.png", dpi=110)
    _swing(plt, study).savefig(out / "swing.png", dpi=110)
    plt.close("all")


def _fig4_elbow(plt, study, elbow):
    """Fig. 4 right: the right elbow under each modification (``fig4_elbow.png``)."""
    modifications, plans, runs = study.modifications, study.plans, study.runs
    figure, axes = plt.subplots(len(modifications), 1, figsize=(9, 9), sharex=True)
    base = plans["none"]
    for ax, modification in zip(axes, modifications):
        plan, log = plans[modification.name], runs[modification.name]
        ax.plot(
            base["times"],
            base["positions"][:, elbow],
            "--",
            color="0.6",
            lw=1,
            label="unmodified pattern",
        )
        ax.plot(plan["times"], plan["positions"][:, elbow], color="C0", lw=1.2, label="DMP plan")
        ax.plot(log.times, log.actual[:, elbow], color="C3", lw=0.8, label="Talos (simulated)")
        if modification.name != "none":
            ax.axvspan(modification.start, modification.end, color="C1", alpha=0.12)
        ax.set_ylabel("right elbow [rad]")
        ax.set_title(modification.label, loc="left", fontsize=9)
    axes[0].axvspan(0, 0, color="C1", alpha=0.12, label="change active (a step on and off)")
    axes[0].legend(loc="upper right", fontsize=8, ncol=2)
    axes[-1].set_xlabel("time [s]")
    figure.suptitle("Fig. 4 right: right-elbow DMP modified in the shaded window")
    figure.tight_layout()
    return figure


def _drumming_tracking(plt, study):
    """Drumming joint tracking, floating base, unmodified (``drumming_tracking.png``)."""
    drum = study.runs["none"]
    figure, axes = plt.subplots(6, 2, figsize=(10, 10), sharex=True)
    shown = drum.times <= 3.0
    for j, name in enumerate(DRUM_JOINTS):
        ax = axes[j % 6, j // 6]
        ax.plot(drum.times[shown], drum.desired[shown, j], color="C0", lw=1.2, label="plan")
        ax.plot(drum.times[shown], drum.actual[shown, j], "--", color="C3", lw=1, label="robot")
        ax.set_title(
            f"{name}  rms {1e3 * rms(drum.actual[:, j] - drum.desired[:, j]):.2f} mrad",
            fontsize=8,
            loc="left",
        )
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7)
    for ax in axes[:, 0]:
        ax.set_ylabel("[rad]", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    figure.suptitle("Drumming on standing Talos: DMP plan and joint angles [rad]")
    figure.tight_layout()
    return figure


def _demonstration(plt, demo):
    """The task-space stroke and the joint trajectories from IK (``demonstration.png``)."""
    figure, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    times = demo.joints.times
    axes[0].plot(times, demo.hand_targets[:, 0, 2], label="left wrist height [m]")
    axes[0].plot(times, demo.hand_targets[:, 1, 2], label="right wrist height [m]")
    axes[0].plot(
        times,
        0.1 * demo.hand_pitch[:, 1] + demo.hand_targets[:, 1, 2].mean(),
        ":",
        label="right wrist pitch (x0.1 rad, offset)",
    )
    axes[0].set_xlabel("time [s]")
    axes[0].set_ylabel("height [m]")
    axes[0].legend(fontsize=7)
    axes[0].set_title("task-space stroke", fontsize=9)
    for j, name in enumerate(DRUM_JOINTS[6:]):
        axes[1].plot(times, demo.joints.positions[:, 6 + j], label=name.replace("_joint", ""))
    axes[1].set_xlabel("time [s]")
    axes[1].set_ylabel("joint angle [rad]")
    axes[1].legend(fontsize=7, ncol=2)
    axes[1].set_title("right-arm joints from IK (demonstration)", fontsize=9)
    figure.tight_layout()
    return figure


def _figure8(plt, study):
    """The figure-8 hand path, plan and robot, in mm around its centre (``figure8.png``)."""
    log = study.figure8
    centre = log.desired.mean(axis=0)
    plan, hand = 1e3 * (log.desired - centre), 1e3 * (log.actual - centre)
    figure, ax = plt.subplots(figsize=(6, 4.5))
    ax.plot(plan[:, 1], plan[:, 2], color="C0", lw=1.5, label="task-space DMP plan")
    ax.plot(hand[:, 1], hand[:, 2], "--", color="C3", lw=1, label="right hand (simulated)")
    ax.set_xlabel("lateral y from the centre [mm]")
    ax.set_ylabel("height z from the centre [mm]")
    ax.set_aspect("equal")
    ax.locator_params(nbins=6)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2)
    ax.set_title("Figure-8 with the right hand, Talos standing", fontsize=9)
    figure.tight_layout()
    return figure


def _base_com(plt, study):
    """Pelvis orientation and CoM while drumming (``base_com.png``)."""
    no_base_task = study.no_base_task
    drum = study.runs["none"]
    figure, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for k, label in enumerate(("roll", "pitch", "yaw")):
        axes[0].plot(drum.times, np.degrees(drum.base[:, 3 + k] - drum.base[0, 3 + k]), label=label)
    roll = np.degrees(no_base_task.base[:, 3] - no_base_task.base[0, 3])
    axes[0].plot(no_base_task.times, roll, ":", color="C0", label="roll, no pelvis task")
    axes[0].set_ylabel("pelvis orientation change [deg]")
    axes[0].legend(fontsize=8)
    for k, label in enumerate("xyz"):
        axes[1].plot(drum.times, 1e3 * (drum.com[:, k] - drum.com[0, k]), label=f"CoM {label}")
    axes[1].set_ylabel("CoM displacement [mm]")
    axes[1].set_xlabel("time [s]")
    axes[1].legend(fontsize=8)
    figure.suptitle("Standing balance while drumming (floating base, two sole contacts)")
    figure.tight_layout()
    return figure


def _tick_times(plt, study):
    """Histogram of the controller's CPU time per tick (``tick_times.png``)."""
    runs, fixed_log = study.runs, study.fixed
    figure, ax = plt.subplots(figsize=(7, 4))
    floating = np.concatenate([log.tick_cpu_us for log in runs.values()])
    top = np.percentile(np.r_[floating, fixed_log.tick_cpu_us], 99.5)
    bins = np.linspace(0, top, 80)
    ax.hist(fixed_log.tick_cpu_us, bins, alpha=0.6, label="fixed-base upper body (nv = 32)")
    ax.hist(floating, bins, alpha=0.6, label="floating base, 2 contacts (nv = 50)")
    ax.axvline(1000.0, color="k", lw=0.8)
    ax.set_xlabel("compute_torques CPU time per tick [us] (1 kHz budget: 1000 us)")
    ax.set_ylabel("ticks")
    ax.legend(fontsize=8)
    figure.tight_layout()
    return figure


def _swing(plt, study):
    """The forehand, plan vs executed, demonstrated and new goal (``swing.png``)."""
    runs = study.swings
    figure, axes = plt.subplots(2, 2, figsize=(10, 8))
    top, front, joints, speed = axes.ravel()
    styles = {"demonstrated_goal": ("C0", "demonstrated goal"), "new_goal": ("C2", "new goal")}
    for name, run in runs.items():
        colour, label = styles[name]
        plan, hand = 1e3 * run.plan_hand, 1e3 * run.log.extras["hand_world"]
        plan_speed = np.linalg.norm(np.gradient(run.plan_hand, run.log.times, axis=0), axis=1)
        hand_speed = np.linalg.norm(np.gradient(hand / 1e3, run.log.times, axis=0), axis=1)
        contact = int(np.argmax(hand_speed))
        for ax, (i, j) in ((top, (1, 0)), (front, (1, 2))):
            ax.plot(plan[:, i], plan[:, j], color=colour, lw=1.5, label=f"plan, {label}")
            ax.plot(hand[:, i], hand[:, j], "--", color="k", lw=0.8)
            ax.plot(hand[contact, i], hand[contact, j], "o", color=colour, ms=5)
        speed.plot(run.log.times, plan_speed, color=colour, lw=1.5, label=f"plan, {label}")
        speed.plot(run.log.times, hand_speed, "--", color="k", lw=0.8)
    for ax in (top, front, speed):
        ax.plot([], [], "--", color="k", lw=0.8, label="executed (simulated)")
    top.plot([], [], "o", color="0.4", ms=5, label="contact point (peak speed)")
    top.set(xlabel="lateral y [mm] (robot's left +)", ylabel="forward x [mm]", title="from above")
    top.invert_xaxis()  # seen from above with forward up, the robot's left is on the left
    front.set(xlabel="lateral y [mm] (robot's left +)", ylabel="height z [mm]",
               title="seen from the front")  # fmt: skip
    for ax in (top, front):
        ax.set_aspect("equal", adjustable="datalim")
        ax.locator_params(nbins=6)
        ax.legend(fontsize=7)
    demonstrated = runs["demonstrated_goal"].log
    shown = demonstrated.times <= 2.0
    for j, name in enumerate(SWING_JOINTS):
        colour = f"C{j}"
        joints.plot(demonstrated.times[shown], demonstrated.desired[shown, j], color=colour,
                    lw=1.5, label=name.replace("_joint", ""))  # fmt: skip
        joints.plot(demonstrated.times[shown], demonstrated.actual[shown, j], "--", color="k",
                    lw=0.6)  # fmt: skip
    joints.plot([], [], "--", color="k", lw=0.6, label="executed")
    joints.set(xlabel="time [s]", ylabel="joint angle [rad]",
               title="joints, demonstrated goal: plan (colours), executed")  # fmt: skip
    joints.legend(fontsize=7, ncol=2)
    speed.set(xlabel="time [s]", ylabel="hand speed [m/s]", title="hand speed")
    speed.set_xlim(0, 2.0)
    speed.legend(fontsize=7)
    figure.suptitle("Forehand of the right arm: one discrete DMP, Talos standing (simulated)")
    figure.tight_layout()
    return figure
