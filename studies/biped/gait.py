"""The demonstrated gait and the four rhythmic DMPs learned from it."""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from dmpopt import Trajectory, fit_rhythmic

# Percent of the gait cycle (right heel strike at 0) and joint angle [deg]; flexion positive.
HIP_KEYPOINTS = np.array(
    [
        [0, 25],
        [10, 22],
        [20, 15],
        [30, 7],
        [40, 0],
        [50, -8],
        [55, -10],
        [60, -5],
        [70, 10],
        [80, 22],
        [87, 27],
        [95, 26],
    ],
    dtype=float,
)
KNEE_KEYPOINTS = np.array(
    [
        [0, 5],
        [5, 10],
        [15, 18],
        [25, 12],
        [35, 6],
        [42, 5],
        [50, 23],
        [60, 40],
        [67, 55],
        [72, 60],
        [80, 50],
        [90, 25],
        [95, 8],
    ],
    dtype=float,
)
DEMO_FREQUENCY = 5.0  # [rad/s] frequency the DMPs are learned at (period 1.26 s)


def demonstrated_gait(period: float = 2 * np.pi / DEMO_FREQUENCY, n_samples: int = 400):
    """Two periods of the demonstrated gait, DOFs (right hip, right knee, left hip, left knee).

    Returns
    -------
    Trajectory
        Angles [rad]; the cycle starts at the right heel strike (oscillator phase 0).
    """
    times = np.linspace(0.0, 2 * period, 2 * n_samples + 1)
    cycle = (times / period) % 1.0

    def joint(keypoints):
        x = np.r_[keypoints[:, 0], 100.0] / 100.0
        y = np.radians(np.r_[keypoints[:, 1], keypoints[0, 1]])
        return CubicSpline(x, y, bc_type="periodic")

    hip, knee = joint(HIP_KEYPOINTS), joint(KNEE_KEYPOINTS)
    other = (cycle + 0.5) % 1.0
    positions = np.column_stack([hip(cycle), knee(cycle), hip(other), knee(other)])
    return Trajectory.from_positions(times, positions)


def learn_gait():
    """Fit the four rhythmic DMPs (one shared phase) to the demonstrated gait."""
    demo = demonstrated_gait()
    return demo, fit_rhythmic(demo, n_basis=25, period=2 * np.pi / DEMO_FREQUENCY)


def limit_cycle_start(dmp, frequency: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of the DMP's limit cycle at phase 0 (the right heel strike)."""
    plan = dmp.with_tau(1.0 / frequency).rollout(duration=3 * 2 * np.pi / frequency, dt=dt)
    return plan.positions[-1], plan.velocities[-1]
