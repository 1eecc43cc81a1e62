"""The demonstrated gait and the four rhythmic DMPs learned from it."""

from __future__ import annotations

import functools

import numpy as np
from scipy.interpolate import CubicSpline

from dmpopt import Trajectory, fit_rhythmic
from dmpopt.exceptions import InvalidInputError

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
HARMONICS = 8  # of a gait cycle learned from a walk
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


@functools.cache
def learn_gait():
    """Fit the four rhythmic DMPs (one shared phase) to the demonstrated gait.

    Fitted once per process (every walk of the study starts from it): each call returns the
    same demonstration and DMP, to be read, not changed."""
    demo = demonstrated_gait()
    return demo, fit_rhythmic(demo, n_basis=25, period=2 * np.pi / DEMO_FREQUENCY)


def limit_cycle_start(dmp, frequency: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of the DMP's limit cycle at phase 0 (the right heel strike)."""
    plan = dmp.with_tau(1.0 / frequency).rollout(duration=3 * 2 * np.pi / frequency, dt=dt)
    return plan.positions[-1], plan.velocities[-1]


def demonstration_from_walk(log, gait_index, after: float, n_samples: int = 200):
    """The mean gait cycle of a walk as a demonstration, and the walk's state at a heel strike.

    The cycles run from one right heel strike to the next, those starting at or after
    ``after`` [s]; each is resampled to ``n_samples`` points of its own phase, the joint
    angles (``gait_index``: their indices in ``q``, gait order) are averaged and the mean is
    kept to its first ``HARMONICS`` harmonics (periodic, the heel strike's kink smoothed).

    Returns
    -------
    demonstration : Trajectory
        Two periods of the mean cycle, starting at the right heel strike (phase 0).
    period : float
        Mean cycle duration [s].
    start : dict
        ``pitch`` [rad] and forward ``speed`` [m/s] of the torso at the last right heel strike
        (the speed by a central difference of the logged samples), ``cycles`` averaged.
    """
    times, q = np.asarray(log.times), np.asarray(log.q)
    right = [t for t, leg, _ in log.strikes if leg == 0 and t >= after]
    if len(right) < 2:
        raise InvalidInputError(
            f"log has {len(right)} right heel strikes at or after {after} s, need 2; "
            "pass a longer walk or an earlier 'after'"
        )
    grid = np.linspace(0.0, 1.0, n_samples, endpoint=False)
    cycles = []
    for begin, end in zip(right, right[1:]):
        inside = (times >= begin) & (times < end)
        phase = (times[inside] - begin) / (end - begin)
        cycles.append(np.column_stack([np.interp(grid, phase, q[inside, j]) for j in gait_index]))
    period = float(np.mean(np.diff(right)))
    # the mean cycle as a Fourier series of HARMONICS harmonics: periodic and smooth
    spectrum = np.fft.rfft(np.mean(cycles, axis=0), axis=0)
    spectrum[HARMONICS + 1 :] = 0.0
    mean = np.fft.irfft(spectrum, n=n_samples, axis=0)
    k = int(np.searchsorted(times, right[-1]))
    speed = (q[k + 1, 0] - q[k - 1, 0]) / (times[k + 1] - times[k - 1])
    demo_times = np.arange(2 * n_samples + 1) * period / n_samples
    demonstration = Trajectory.from_positions(demo_times, np.vstack([mean, mean, mean[:1]]))
    start = {"pitch": float(q[k, 2]), "speed": float(speed), "cycles": len(cycles)}
    return demonstration, period, start


def learn_from_demonstration(demonstration, period: float):
    """Fit the four rhythmic DMPs to a demonstration of one gait cycle of ``period`` [s]."""
    return fit_rhythmic(demonstration, n_basis=25, period=period)
