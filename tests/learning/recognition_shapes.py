"""Synthetic strokes and small helpers shared by the recognition tests (tests/learning)."""

import re

import numpy as np
import pytest

from dmpopt import Trajectory, fit_discrete

N_BASIS = 12


N_STEPS = 200


def _shape(kind: int, rng=None, duration: float = 1.0) -> Trajectory:
    """Make a 2-D point-to-point synthetic stroke of one of three kinds (optionally perturbed)."""
    s = np.linspace(0.0, 1.0, N_STEPS)
    progress = 10 * s**3 - 15 * s**4 + 6 * s**5  # minimum jerk
    start, goal = np.array([-3.0, 1.0]), np.array([2.0, 0.5])
    bumps = (np.sin(np.pi * progress), np.sin(2 * np.pi * progress), np.sin(np.pi * progress) ** 3)
    amplitudes = (1.5, 1.0, -2.0)
    amplitude = amplitudes[kind]
    if rng is not None:
        amplitude *= 1.0 + 0.05 * rng.standard_normal()
        goal = goal + 0.05 * rng.standard_normal(2)
    direction = goal - start
    normal = np.array([-direction[1], direction[0]]) / np.linalg.norm(direction)
    positions = start + progress[:, None] * direction + amplitude * bumps[kind][:, None] * normal
    return Trajectory.from_positions(duration * s, positions)


def _moved(demo: Trajectory, scale=3.7, angle=0.0, offset=(40.0, -12.0), stretch=2.5):
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    positions = scale * demo.positions @ rotation.T + np.asarray(offset)
    return Trajectory.from_positions(stretch * demo.times + 0.3, positions)


def _synthetic_set(n_per_class: int = 4, seed: int = 0):
    rng = np.random.default_rng(seed)
    demos, labels = [], []
    for kind in range(3):
        for _ in range(n_per_class):
            demos.append(_shape(kind, rng, duration=rng.uniform(0.8, 1.5)))
            labels.append(f"kind{kind}")
    return demos, np.array(labels)


def _raises(error, message):
    return pytest.raises(error, match=f"^{re.escape(message)}$")


def _line():
    """Five 1-D samples: a, a at 0 and 1; b, b at 3 and 3.5; c at 10."""
    return np.array([[0.0], [1.0], [3.0], [3.5], [10.0]]), np.array(list("aabbc"))


def _line_dmp(n_dofs: int = 2):
    s = np.linspace(0.0, 1.0, 60)
    positions = np.column_stack([s, np.sin(3 * s), s**2][:n_dofs])
    return fit_discrete(Trajectory.from_positions(s, positions), 6)
