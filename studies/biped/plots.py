"""Figures of the biped study: Fig. 7 (frequency and sweep), survival, joints, stick figure."""

from __future__ import annotations

import numpy as np

from studies.common import pyplot


def frequency_figure(path, by_start, sweep, resonance, flat_band) -> None:
    """Fig. 7: frequency against heel strike from every start, and the cost sweep.

    ``by_start``: start frequency -> list of frequencies; ``resonance``: label -> rad/s.
    """
    plt = pyplot()
    fig, (ax, ax_cot) = plt.subplots(1, 2, figsize=(11, 4))
    for start, frequencies in by_start.items():
        ax.plot(frequencies, marker=".", ms=3, label=f"start {float(start):.1f} rad/s")
    styles = iter(["--", ":", "-.", (0, (5, 1)), (0, (1, 3))])
    for label, value in resonance.items():
        if value is not None and np.isfinite(value):
            style = next(styles)
            ax.axhline(value, color="k", ls=style, lw=1, label=f"{label} {value:.2f}")
            ax_cot.axvline(value, color="k", ls=style, lw=1, label=f"{label} {value:.2f}")
    ax.set_xlabel("heel strike n")
    ax.set_ylabel(r"oscillator frequency $\omega_n$ [rad/s]")
    ax.set_title("Frequency adaptation, eq. (21), QP walker")
    ax.legend(fontsize=6)
    walked = [row for row in sweep if row["cost_of_transport"] is not None]
    ax_cot.plot(
        [row["frequency"] for row in walked],
        [row["cost_of_transport"] for row in walked],
        "o-",
        label="fixed frequency, reset on",
    )
    fallen = [row["frequency"] for row in sweep if row["cost_of_transport"] is None]
    if fallen:
        ax_cot.plot(fallen, np.zeros(len(fallen)), "rx", label="fell")
    if flat_band:
        ax_cot.axvspan(*flat_band, color="g", alpha=0.15, label="within 5 % of min")
    ax_cot.set_xlabel(r"oscillator frequency $\omega$ [rad/s]")
    ax_cot.set_ylabel("mechanical cost of transport [-]")
    ax_cot.set_title("Fixed-frequency sweep")
    ax_cot.set_xscale("log")
    ax_cot.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def survival_figure(path, survival: dict, ranges) -> None:
    """Survival rate per arm with its Wilson 95 % interval."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.6))
    names = list(survival)
    rates = np.array([survival[name]["rate"] for name in names])
    low = np.array([survival[name]["ci95_wilson"][0] for name in names])
    high = np.array([survival[name]["ci95_wilson"][1] for name in names])
    ax.bar(names, rates, color="C0", alpha=0.7, label="survival rate")
    errors = np.maximum(0.0, [rates - low, high - rates])  # not -1e-17 from rounding
    ax.errorbar(names, rates, yerr=errors, fmt="none", color="k", capsize=5, label="Wilson 95 % CI")
    for k, name in enumerate(names):
        ax.text(k, 0.02, f"n={survival[name]['n']}", ha="center", fontsize=8)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("survived trials [-]")
    ax.set_title(
        f"push {ranges.push_impulse[0]:g}-{ranges.push_impulse[1]:g} N s, masses "
        f"x{ranges.mass_scale[0]:g}-{ranges.mass_scale[1]:g}, slope "
        f"{ranges.slope_deg[0]:g}..{ranges.slope_deg[1]:g} deg",
        fontsize=8,
    )
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def joints_figure(path, biped, log) -> None:
    """Desired (DMP) against actual joint angles, first and last 4 s of a walk."""
    plt = pyplot()
    times = np.asarray(log.times)
    q = np.asarray(log.q)[:, biped.velocity_indices("gait")]
    desired = np.asarray(log.desired)
    fig, axes = plt.subplots(4, 2, figsize=(9, 7), sharex="col")
    windows = [times <= times[0] + 4.0, times >= times[-1] - 4.0]
    for col, window in enumerate(windows):
        for row, name in enumerate(biped.joint_groups["gait"]):
            ax = axes[row, col]
            ax.plot(times[window], np.degrees(desired[window, row]), "--", label="DMP")
            ax.plot(times[window], np.degrees(q[window, row]), label="robot")
            for t, leg, _ in log.strikes:
                if times[window][0] <= t <= times[window][-1]:
                    ax.axvline(t, color="r" if leg == 0 else "b", lw=0.4)
            ax.set_ylabel(f"{name} [deg]", fontsize=8)
    axes[0, 0].set_title("start")
    axes[0, 1].set_title("end")
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("t [s]")
    axes[-1, 1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def stick_figure(path, biped, log, speed) -> None:
    """Stick figures of the last 3 s of a walk."""
    import pinocchio as pin

    plt = pyplot()
    times = np.asarray(log.times)
    fig, ax = plt.subplots(figsize=(10, 2.6))
    window = np.flatnonzero(times >= times[-1] - 3.0)[::8]
    data = biped.model.createData()
    frames = [biped.torso_frame, "right_knee", biped.foot_frames[0], "left_knee"]
    frames.append(biped.foot_frames[1])
    ids = [biped.model.getFrameId(f) for f in frames]
    colours = plt.cm.viridis(np.linspace(0, 1, len(window)))
    for colour, k in zip(colours, window):
        pin.framesForwardKinematics(biped.model, data, log.q[k])
        hip, right_knee, right_foot, left_knee, left_foot = (
            data.oMf[i].translation[[0, 2]] for i in ids
        )
        pitch = log.q[k][2]
        top = hip + 0.3 * np.array([np.sin(pitch), np.cos(pitch)])
        for chain in ([top, hip], [hip, right_knee, right_foot], [hip, left_knee, left_foot]):
            chain = np.array(chain)
            ax.plot(chain[:, 0], chain[:, 1], color=colour, lw=1)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_title(f"last 3 s, {speed:.2f} m/s")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
