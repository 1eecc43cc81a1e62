"""The constrained fit with keep-out regions (spheres, boxes)."""

import numpy as np
import pytest

from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.fitting import fit_weights_constrained, minimum_jerk
from dmpopt.fitting.keep_out import fit_keep_out
from dmpopt.obstacles import Box, Sphere


@pytest.fixture(scope="module")
def demo():
    return minimum_jerk(np.zeros(2), np.array([1.0, 0.0]), 1.0, 0.01)


def test_plan_clears_a_sphere_at_every_sample(demo):
    """Answer key: the distance of each planned sample to the centre, computed here, is at
    least the radius; the demonstration itself entered the disc (it passes 30 mm from the
    centre of a 100 mm disc)."""
    centre = np.array([0.5, 0.03])
    assert np.linalg.norm(demo.positions - centre, axis=1).min() < 0.1
    dmp, report = fit_keep_out(demo, [Sphere(centre, 0.1)], 15)
    distances = np.linalg.norm(report.trajectory.positions - centre, axis=1)
    assert distances.min() >= 0.1 - 1e-9  # IPOPT tolerance 1e-8 on rows of order one
    np.testing.assert_allclose(report.trajectory.positions[-1], [1.0, 0.0], atol=1e-9)


def test_plan_clears_a_box_at_every_sample(demo):
    """Answer key: each sample lies beyond the box's half-width along some axis."""
    centre, half = np.array([0.5, 0.03]), np.array([0.05, 0.1])
    _, report = fit_keep_out(demo, [Box(centre, half)], 15)
    outside = (np.abs(report.trajectory.positions - centre) >= half - 1e-9).any(axis=1)
    assert outside.all()


def test_far_region_leaves_the_unconstrained_qp_answer(demo):
    """Second solver: with the region far from the path, the NLP's answer is the QP's
    (fit_weights_constrained with the same defaults), to IPOPT's tolerance."""
    _, report = fit_keep_out(demo, [Sphere([0.5, 5.0], 0.1)], 15)
    _, qp = fit_weights_constrained(demo, 15)
    scale = np.abs(qp.trajectory.positions).max()
    np.testing.assert_allclose(
        report.trajectory.positions, qp.trajectory.positions, atol=1e-6 * scale
    )


def test_errors_name_the_region(demo):
    with pytest.raises(ShapeError, match=r"keep_out\[0\] has a centre of shape \(3,\)"):
        fit_keep_out(demo, [Sphere([0.0, 0.0, 0.0], 0.1)], 10)
    with pytest.raises(InvalidInputError, match=r"start or goal lies inside keep_out\[0\]"):
        fit_keep_out(demo, [Sphere([0.0, 0.0], 0.1)], 10)
    with pytest.raises(InvalidInputError, match="keep_out is empty"):
        fit_keep_out(demo, [], 10)
