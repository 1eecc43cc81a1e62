"""Time-stamped positions, velocities and accelerations of several DOFs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .exceptions import InvalidInputError, ShapeError
from .validation import check_resources, integer, real_array

MIN_SAMPLES = 3


def check_times(times: np.ndarray, name: str = "times") -> np.ndarray:
    """Validate sample times: finite, 1-D, at least three, strictly increasing."""
    times = real_array(name, times, ndim=1, empty=True)
    if times.size < MIN_SAMPLES:
        raise InvalidInputError(
            f"{name} has {times.size} samples, at least {MIN_SAMPLES} are needed"
        )
    steps = np.diff(times)
    if np.any(steps <= 0.0):
        first = int(np.argmax(steps <= 0.0))
        raise InvalidInputError(
            f"{name} must be strictly increasing; {name}[{first + 1}] = {times[first + 1]!r} "
            f"does not exceed {name}[{first}] = {times[first]!r}"
        )
    return times


def _as_2d(name: str, value, n_samples: int) -> np.ndarray:
    array = real_array(name, value, empty=True)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2 or array.shape[0] != n_samples or array.shape[1] == 0:
        raise ShapeError(
            f"{name} has shape {array.shape}, expected ({n_samples}, n_dofs) with n_dofs >= 1 "
            f"to match {n_samples} time samples"
        )
    return array


def differentiate(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Second-order accurate derivative along axis 0, also on non-uniform grids."""
    return np.gradient(values, times, axis=0, edge_order=2)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Positions, velocities and accelerations of ``n_dofs`` DOFs at ``n_steps`` times.

    Attributes
    ----------
    times : ndarray, shape (n_steps,)
        Strictly increasing sample times [s].
    positions, velocities, accelerations : ndarray, shape (n_steps, n_dofs)
        Samples and their first and second time derivatives.

    Arrays are copied and made read-only, so a trajectory never changes.
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray

    def __post_init__(self):
        times = check_times(self.times)
        n = times.size
        positions = _as_2d("positions", self.positions, n)
        velocities = _as_2d("velocities", self.velocities, n)
        accelerations = _as_2d("accelerations", self.accelerations, n)
        for name, array in (("velocities", velocities), ("accelerations", accelerations)):
            if array.shape != positions.shape:
                raise ShapeError(
                    f"{name} has shape {array.shape}, expected {positions.shape} like positions"
                )
        for name, array in (
            ("times", times),
            ("positions", positions),
            ("velocities", velocities),
            ("accelerations", accelerations),
        ):
            array = np.array(array, dtype=float)
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @classmethod
    def trusted(cls, times, positions, velocities, accelerations) -> Trajectory:
        """A trajectory from arrays that the library has just computed and that nothing else
        references: float64, of matching shapes (n_steps, n_dofs), ``times`` strictly
        increasing. They are made read-only, not validated or copied (a rollout would spend
        most of its time on that). Arrays from users go through the constructor."""
        trajectory = object.__new__(cls)
        for name, array in (
            ("times", times),
            ("positions", positions),
            ("velocities", velocities),
            ("accelerations", accelerations),
        ):
            array.setflags(write=False)
            object.__setattr__(trajectory, name, array)
        return trajectory

    @classmethod
    def from_positions(cls, times, positions, smoothing_window: int = 0) -> Trajectory:
        """Build a trajectory from sampled positions by differentiation.

        Derivatives use second-order central differences (one-sided second order at the
        ends), valid on non-uniform grids.

        Parameters
        ----------
        times : array_like, shape (n_steps,)
        positions : array_like, shape (n_steps,) or (n_steps, n_dofs)
        smoothing_window : int
            If > 0, odd number of samples of a cubic Savitzky-Golay filter applied to the
            positions (uniform grids only) before differentiating noisy data.
        """
        times = check_times(times)
        positions = _as_2d("positions", positions, times.size)
        smoothing_window = integer("smoothing_window", smoothing_window, minimum=0)
        if smoothing_window:
            positions = _smooth(times, positions, smoothing_window)
        velocities = differentiate(times, positions)
        accelerations = differentiate(times, velocities)
        return cls(times, positions, velocities, accelerations)

    @property
    def n_steps(self) -> int:
        """Number of samples."""
        return self.times.size

    @property
    def n_dofs(self) -> int:
        """Number of degrees of freedom."""
        return self.positions.shape[1]

    @property
    def duration(self) -> float:
        """Time from the first to the last sample [s]."""
        return float(self.times[-1] - self.times[0])

    @property
    def is_uniform(self) -> bool:
        """True if the samples are equally spaced (to 1e-9 relative)."""
        steps = np.diff(self.times)
        return bool(np.ptp(steps) <= 1e-9 * max(abs(steps.mean()), 1e-300))

    def resampled(self, n_steps: int) -> Trajectory:
        """Return the trajectory on ``n_steps`` equally spaced times (cubic Hermite)."""
        n_steps = integer("n_steps", n_steps, minimum=MIN_SAMPLES)
        check_resources(
            f"resampled({n_steps})",
            8.0 * n_steps * (1 + 6 * self.n_dofs),
            "ask for fewer samples",
            n_samples=n_steps,
        )
        from scipy.interpolate import CubicHermiteSpline

        new_times = np.linspace(self.times[0], self.times[-1], n_steps)
        spline = CubicHermiteSpline(self.times, self.positions, self.velocities, axis=0)
        velocity_spline = CubicHermiteSpline(
            self.times, self.velocities, self.accelerations, axis=0
        )
        return Trajectory(
            new_times,
            spline(new_times),
            velocity_spline(new_times),
            velocity_spline.derivative()(new_times),
        )


def _smooth(times: np.ndarray, positions: np.ndarray, window: int) -> np.ndarray:
    from scipy.signal import savgol_filter

    if window < 5 or window % 2 == 0 or window > times.size:
        raise InvalidInputError(
            f"smoothing_window must be an odd number between 5 and {times.size}, got {window}"
        )
    return savgol_filter(positions, window, 3, axis=0)
