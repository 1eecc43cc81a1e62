"""Figures of the biped study: Fig. 7 (frequency and sweep), survival, joints, stick figure."""

from __future__ import annotations

import numpy as np
from dmpopt_studies.common import pyplot


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
    ax.legend(fontsize=7, ncol=2)
    walked = [row for row in sweep if row["cost_of_transport"] is not None]
    ax_cot.plot(
        [row["frequency"] for row in walked],
        [row["cost_of_transport"] for row in walked],
        "o-",
        label="fixed frequency, reset on",
    )
    fallen = [row["frequency"] for row in sweep if row["cost_of_transport"] is None]
    if fallen:
        ax_cot.plot(fallen, np.zeros(len(fallen)), "rx", label="fell (no cost)")
    if flat_band:
        ax_cot.axvspan(*flat_band, color="g", alpha=0.15, label="within 5 % of min")
    ax_cot.set_xlabel(r"oscillator frequency $\omega$ [rad/s]")
    ax_cot.set_ylabel("mechanical cost of transport [-]")
    ax_cot.set_title("Fixed-frequency sweep")
    ax_cot.set_xscale("log")
    ticks = [4, 5, 6, 8, 10, 12, 16, 20]
    ax_cot.set_xticks(ticks, [str(t) for t in ticks])
    ax_cot.minorticks_off()
    ax_cot.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def survival_figure(path, survival: dict, ranges) -> None:
    """Survival rate per arm with its Wilson 95 % interval, coloured by phase resetting."""
    from .analysis import ARMS

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.8))
    names = [name for name in ARMS if name in survival]
    rates = np.array([survival[name]["rate"] for name in names])
    low = np.array([survival[name]["ci95_wilson"][0] for name in names])
    high = np.array([survival[name]["ci95_wilson"][1] for name in names])
    colours = ["C0" if ARMS[name][0] else "C3" for name in names]
    labels = [
        f"reset {'on' if ARMS[name][0] else 'off'}\nadaptation {'on' if ARMS[name][1] else 'off'}"
        f"\n{survival[name]['survived']}/{survival[name]['n']} survived"
        for name in names
    ]
    ax.bar(labels, rates, color=colours, alpha=0.75)
    errors = np.maximum(0.0, [rates - low, high - rates])  # not -1e-17 from rounding
    ax.errorbar(labels, rates, yerr=errors, fmt="none", color="k", capsize=5)
    handles = [
        plt.Rectangle((0, 0), 1, 1, color="C0", alpha=0.75, label="phase resetting on"),
        plt.Rectangle((0, 0), 1, 1, color="C3", alpha=0.75, label="phase resetting off"),
        plt.Line2D([], [], color="k", marker="_", ls="none", ms=10, label="Wilson 95 % CI"),
    ]
    ax.legend(handles=handles, fontsize=8, loc="upper center", ncol=3)
    ax.set_ylim(0, 1.25)
    ax.set_ylabel("survived trials [fraction]")
    ax.set_title(
        f"push {ranges.push_impulse[0]:g}-{ranges.push_impulse[1]:g} N s, masses "
        f"x{ranges.mass_scale[0]:g}-{ranges.mass_scale[1]:g}, slope "
        f"{ranges.slope_deg[0]:g} to {ranges.slope_deg[1]:g} deg",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def joints_figure(path, biped, log, seconds: float = 3.0) -> None:
    """Desired (DMP) against actual joint angles, first and last ``seconds`` of a walk;
    vertical lines mark the heel strikes (red right foot, blue left)."""
    plt = pyplot()
    times = np.asarray(log.times)
    q = np.asarray(log.q)[:, biped.velocity_indices("gait")]
    desired = np.asarray(log.desired)
    fig, axes = plt.subplots(4, 2, figsize=(9, 7), sharex="col")
    windows = [times <= times[0] + seconds, times >= times[-1] - seconds]
    for col, window in enumerate(windows):
        for row, name in enumerate(biped.joint_groups["gait"]):
            ax = axes[row, col]
            ax.plot(times[window], np.degrees(desired[window, row]), "--", label="DMP reference")
            ax.plot(times[window], np.degrees(q[window, row]), label="robot")
            for t, leg, _ in log.strikes:
                if times[window][0] <= t <= times[window][-1]:
                    ax.axvline(t, color="r" if leg == 0 else "b", lw=0.6, alpha=0.6)
            ax.set_ylabel(f"{name.replace('_', ' ')} [deg]", fontsize=8)
    axes[0, 0].set_title(f"first {seconds:g} s")
    axes[0, 1].set_title(f"last {seconds:g} s")
    strikes = [
        plt.Line2D([], [], color="r", lw=0.8, label="right heel strike"),
        plt.Line2D([], [], color="b", lw=0.8, label="left heel strike"),
    ]
    handles = axes[0, 0].get_legend_handles_labels()[0] + strikes
    fig.legend(handles=handles, loc="upper center", ncol=4, fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    axes[-1, 1].set_xlabel("t [s]")
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def stick_figure(path, biped, log, speed) -> None:
    """Stick figures of the last 3 s of a walk."""
    import pinocchio as pin

    plt = pyplot()
    times = np.asarray(log.times)
    window = np.flatnonzero(times >= times[-1] - 3.0)[::8]
    data = biped.model.createData()
    frames = [biped.torso_frame, "right_knee", biped.foot_frames[0], "left_knee"]
    frames.append(biped.foot_frames[1])
    ids = [biped.model.getFrameId(f) for f in frames]
    colours = plt.cm.viridis(np.linspace(0, 1, len(window)))
    chains = []
    for k in window:
        pin.framesForwardKinematics(biped.model, data, log.q[k])
        hip, right_knee, right_foot, left_knee, left_foot = (
            data.oMf[i].translation[[0, 2]] for i in ids
        )
        pitch = log.q[k][2]
        top = hip + 0.3 * np.array([np.sin(pitch), np.cos(pitch)])
        chains.append(
            [
                np.array(c)
                for c in ([top, hip], [hip, right_knee, right_foot], [hip, left_knee, left_foot])
            ]
        )
    points = np.concatenate([np.concatenate(c) for c in chains])
    low, high = points.min(axis=0) - 0.05, points.max(axis=0) + 0.05
    low[1] = min(low[1], -0.05)
    width = 9.0  # [in]; the height follows the data at equal scales, plus the margins
    fig, ax = plt.subplots(figsize=(width, 0.9 + width * (high[1] - low[1]) / (high[0] - low[0])))
    for colour, chain in zip(colours, chains):
        for segment in chain:
            ax.plot(segment[:, 0], segment[:, 1], color=colour, lw=1.2)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlim(low[0], high[0])
    ax.set_ylim(low[1], high[1])
    ax.set_aspect("equal")
    clock = plt.cm.ScalarMappable(cmap="viridis", norm=plt.Normalize(*times[window[[0, -1]]]))
    fig.colorbar(clock, ax=ax, label="t [s]", fraction=0.025, pad=0.01)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_title(f"last 3 s, {speed:.2f} m/s")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def controls_figure(path, baseline, gravity, legs, insensitivity) -> None:
    """The sceptic's controls: settled frequency against gravity and leg-length factors beside
    the resonance prediction (sqrt(g / l) from the baseline) and a controller-locked one (flat);
    and against controller settings. Rows are :func:`dmpopt_studies.biped.fig7.settled` rows."""
    plt = pyplot()
    fig, (ax, ax_set) = plt.subplots(1, 2, figsize=(11, 4))
    for label, rows, sign, marker in (
        ("gravity x factor", gravity, 0.5, "o"),
        ("leg length x factor", legs, -0.5, "s"),
    ):
        factors = sorted(rows)
        values = [rows[f]["frequency_settled"] for f in factors]
        fell = [rows[f]["fell"] for f in factors]
        line = ax.plot(factors, values, marker=marker, label=f"{label} (measured)")[0]
        for f, v, down in zip(factors, values, fell):
            if down:
                ax.plot(f, v, "rx", ms=9)
        span = np.linspace(min(factors), max(factors), 50)
        ax.plot(
            span,
            baseline * span**sign,
            ls="--",
            color=line.get_color(),
            lw=1,
            label=f"resonance-locked: x factor^{sign:g}",
        )
    ax.axhline(baseline, color="k", lw=1, ls=":", label="controller-locked (flat)")
    ax.set_xlabel("factor on g or on leg length l")
    ax.set_ylabel(r"settled $\omega$ [rad/s]")
    ax.set_title("Scaling controls (red x: fell)")
    ax.legend(fontsize=7)
    names = list(insensitivity)
    values = [insensitivity[n]["frequency_settled"] for n in names]
    colours = ["C3" if insensitivity[n]["fell"] else "C0" for n in names]
    ax_set.barh(names, values, color=colours, alpha=0.8)
    ax_set.set_xlim(0.8 * min(values + [baseline]), 1.1 * max(values + [baseline]))
    ax_set.axvline(baseline, color="k", lw=1, label=f"baseline {baseline:.2f}")
    ax_set.axvspan(0.95 * baseline, 1.05 * baseline, color="g", alpha=0.15, label="within 5 %")
    ax_set.set_xlabel(r"settled $\omega$ [rad/s] (red: fell)")
    ax_set.set_title("Controller settings (not leg dynamics)")
    ax_set.tick_params(axis="y", labelsize=7)
    ax_set.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
