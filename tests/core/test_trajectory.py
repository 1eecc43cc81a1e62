"""Trajectory construction, differentiation and validation."""

import numpy as np
import pytest

from dmpopt import InvalidInputError, ShapeError, Trajectory


def test_from_positions_differentiates_polynomials_exactly():
    times = np.sort(np.random.default_rng(0).uniform(0, 1, 200))  # non-uniform grid
    positions = np.c_[1 + 2 * times - times**2, 3 * times**2]
    demo = Trajectory.from_positions(times, positions)
    np.testing.assert_allclose(demo.velocities, np.c_[2 - 2 * times, 6 * times], atol=1e-9)
    np.testing.assert_allclose(
        demo.accelerations[2:-2], np.c_[-2 + 0 * times, 6 + 0 * times][2:-2], atol=1e-6
    )


def test_resampled_keeps_the_curve():
    times = np.linspace(0, 1, 101) ** 1.5
    demo = Trajectory.from_positions(times, np.sin(3 * times))
    uniform = demo.resampled(301)
    assert uniform.is_uniform and not demo.is_uniform
    np.testing.assert_allclose(uniform.positions[:, 0], np.sin(3 * uniform.times), atol=1e-5)


@pytest.mark.parametrize(
    "times, positions, error, message",
    [
        ([0, 1], [0, 1], InvalidInputError, "times has 2 samples, at least 3"),
        ([0, 1, 1], [0, 1, 2], InvalidInputError, r"times must be strictly increasing; times\[2\]"),
        ([0, 1, np.nan], [0, 1, 2], InvalidInputError, "times contains 1 NaN"),
        ([0, 1, 2], [0, np.inf, 2], InvalidInputError, "positions contains 1 NaN or infinite"),
        (
            [0, 1, 2],
            [[0, 1], [1, 2]],
            ShapeError,
            r"positions has shape \(2, 2\), expected \(3, n_dofs\)",
        ),
        ([[0, 1, 2]], [0, 1, 2], ShapeError, r"times has shape \(1, 3\), expected 1 dimension"),
    ],
)
def test_bad_input_names_the_argument(times, positions, error, message):
    with pytest.raises(error, match=message):
        Trajectory.from_positions(times, positions)


def test_velocity_shape_must_match_positions():
    with pytest.raises(ShapeError, match=r"velocities has shape \(3, 2\), expected \(3, 1\)"):
        Trajectory([0, 1, 2], [0, 1, 2], np.zeros((3, 2)), np.zeros(3))


def test_trajectory_is_read_only():
    demo = Trajectory.from_positions([0, 1, 2], [0, 1, 4])
    with pytest.raises(ValueError):
        demo.positions[0, 0] = 5.0
