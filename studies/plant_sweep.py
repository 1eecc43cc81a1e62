"""Robustness beyond the realistic preset: each plant parameter swept to the point of failure.

The controller keeps believing the preset (its nominal armature, damping, friction and delay);
the simulated plant has one parameter changed at a time: armature, damping and friction x the
preset, the delay in ticks, the sensor noise x the preset, and a link-mass error: every link of
the controller's model x a factor (the plant keeps the URDF's masses). A study runs its closed
loop on each plant of :func:`sweep_cases` and records the result beside the value.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin

from .common import pyplot

#: Values swept per parameter: factors of the preset, ticks of delay, link-mass factors (the
#: preset itself is each study's realistic run).
SWEEP = {
    "full": {
        "armature": (3.0, 10.0, 30.0),
        "damping": (3.0, 10.0, 30.0),
        "friction": (3.0, 10.0, 30.0),
        "delay": (3, 10, 30),
        "noise": (10.0, 100.0, 1000.0),
        "link_mass": (0.8, 1.25, 1.5),
    },
    "quick": {"armature": (3.0,)},
}
UNITS = {
    "armature": "x preset",
    "damping": "x preset",
    "friction": "x preset",
    "delay": "ticks",
    "noise": "x preset",
    "link_mass": "x model's links",
}


def sweep_cases(preset, quick: bool):
    """``(parameter, value, plant, mass_scale)`` for every swept case (see the module notes)."""
    cases = []
    for parameter, values in SWEEP["quick" if quick else "full"].items():
        for value in values:
            if parameter == "link_mass":
                cases.append((parameter, value, preset, value))
            elif parameter == "delay":
                cases.append((parameter, value, dataclasses.replace(preset, delay=value), 1.0))
            else:
                cases.append((parameter, value, preset.scaled(**{parameter: value}), 1.0))
    return cases


def with_scaled_masses(robot, scale: float):
    """A copy of ``robot`` whose every link (pelvis included) has mass and inertia x ``scale``."""
    model = pin.Model(robot.model)
    for joint_id in range(1, model.njoints):
        inertia = model.inertias[joint_id]
        model.inertias[joint_id] = pin.Inertia(
            inertia.mass * scale, inertia.lever, inertia.inertia * scale
        )
    return dataclasses.replace(robot, model=model, name=f"{robot.name}_all_mass_x{scale:g}")


def collect(cases, results) -> dict:
    """``{parameter: [{"value": v, **result}, ...]}`` from the cases and their results."""
    sweep: dict = {}
    for (parameter, value, _, _), result in zip(cases, results):
        sweep.setdefault(parameter, []).append({"value": value, **result})
    return sweep


def plot_sweep(sweep: dict, key: str, label: str, path, log_y: bool = False) -> None:
    """One panel per parameter: ``key`` against the value, falls marked with a red cross."""
    plt = pyplot()
    names = list(sweep)
    fig, axes = plt.subplots(1, len(names), figsize=(2.6 * len(names), 2.8), squeeze=False)
    for ax, name in zip(axes[0], names):
        rows = sweep[name]
        values = np.array([row["value"] for row in rows], dtype=float)
        y = np.array([row[key] for row in rows], dtype=float)
        fell = np.array([row["fell"] for row in rows], dtype=bool)
        ax.plot(values, y, "o-", color="tab:blue")
        ax.plot(values[fell], y[fell], "x", color="tab:red", markersize=10, mew=2, label="fell")
        ax.set_xscale("log")
        if log_y:
            ax.set_yscale("log")
        ax.set_xlabel(f"{name} [{UNITS[name]}]")
        ax.grid(alpha=0.3)
        if fell.any():
            ax.legend(fontsize=7)
    axes[0][0].set_ylabel(label)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
