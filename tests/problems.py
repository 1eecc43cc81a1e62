"""Shared test problems: seeded DMPs and synthetic demonstrations."""

import numpy as np

from dmpopt import DiscreteDMP, RhythmicDMP, Trajectory
from dmpopt.basis import discrete_basis, rhythmic_basis

DISCRETE_GAINS = (25.0, 6.25, 25.0, 6.25)
FORMS_AND_KERNELS = (
    ("velocity", "gaussian"),
    ("acceleration", "gaussian"),
    ("phase", "von_mises"),
    ("phase", "paper"),
    ("energy", "von_mises"),
    ("energy", "paper"),
)


def random_discrete(seed=0, n_dofs=2, n_basis=20, form="velocity", scale=50.0, **fields):
    """A discrete DMP with seeded random weights in rotation mode."""
    rng = np.random.default_rng(seed)
    centres, widths = discrete_basis(n_basis, DISCRETE_GAINS)
    start = rng.normal(size=n_dofs)
    goal = start + rng.normal(size=n_dofs) + 0.5
    options = dict(
        weights=scale * rng.normal(size=(n_dofs, n_basis)),
        start=start,
        goal=goal,
        tau=0.4,
        centres=centres,
        widths=widths,
        form=form,
        goal_scaling="rotation",
        reference_displacement=goal - start,
    )
    options.update(fields)
    return DiscreteDMP(**options)


def random_rhythmic(seed=0, n_dofs=2, n_basis=12, form="phase", **fields):
    """A rhythmic DMP with seeded random weights."""
    rng = np.random.default_rng(seed)
    centres, widths = rhythmic_basis(n_basis, "von_mises")
    options = dict(
        weights=rng.normal(size=(n_dofs, n_basis, 2)),
        setpoint=rng.normal(size=n_dofs),
        tau=0.15,
        centres=centres,
        widths=widths,
        form=form,
    )
    options.update(fields)
    return RhythmicDMP(**options)


def minimum_jerk_demo(n_dofs=3, duration=1.0, n_steps=1001, seed=0):
    """Point-to-point minimum-jerk movements (closed form), one per DOF."""
    rng = np.random.default_rng(seed)
    times = np.linspace(0.0, duration, n_steps)
    s = times / duration
    profile = 10 * s**3 - 15 * s**4 + 6 * s**5
    start, goal = rng.normal(size=n_dofs), rng.normal(size=n_dofs) + 1.0
    return Trajectory.from_positions(times, start + np.outer(profile, goal - start))


def periodic_demo(period=0.8, duration=2.0, n_steps=2001):
    """A figure-8 in the plane plus a sine with a third harmonic."""
    times = np.linspace(0.0, duration, n_steps)
    w = 2 * np.pi / period
    positions = np.c_[
        np.sin(w * times), 0.5 * np.sin(2 * w * times), 0.2 + 0.1 * np.sin(3 * w * times)
    ]
    return Trajectory.from_positions(times, positions)
