"""Obstacle coupling terms (Hoffmann 2009, Park 2008), their use in both steppers."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt import fit_cartesian, fit_discrete
from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.fitting import minimum_jerk
from dmpopt.obstacles import (
    Box,
    PotentialField,
    Sphere,
    SteeringAngle,
    clearance,
    run_coupled,
)

vectors = st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3).map(np.array)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' formula, written out."""
    k = axis / np.linalg.norm(axis)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


@settings(max_examples=40, deadline=None)
@given(vectors, vectors, vectors)
def test_steering_angle_is_hoffmanns_rotated_velocity(position, velocity, centre):
    """Answer key: gamma R v phi exp(-beta phi), R the rotation by pi/2 about (o - y) x v
    (Rodrigues), phi from arccos, written plainly."""
    towards = centre - position
    axis = np.cross(towards, velocity)
    if np.linalg.norm(axis) < 1e-3 or np.linalg.norm(velocity) < 1e-3:
        return
    phi = np.arccos(towards @ velocity / np.linalg.norm(towards) / np.linalg.norm(velocity))
    expected = 1000.0 * _rotation(axis, np.pi / 2) @ velocity * phi * np.exp(-20 / np.pi * phi)
    got = SteeringAngle(Sphere(centre))(position, velocity)
    np.testing.assert_allclose(got, expected, atol=1e-9 * np.abs(expected).max() + 1e-12)


def test_steering_angle_in_2d_turns_in_the_plane_away_from_the_obstacle():
    """Heading along +x with the obstacle up and ahead: the term points down (-y)."""
    term = SteeringAngle(Sphere([1.0, 0.5]))([0.0, 0.0], [1.0, 0.0])
    assert term[0] == pytest.approx(0.0, abs=1e-12) and term[1] < 0.0


@settings(max_examples=40, deadline=None)
@given(vectors, vectors, st.floats(0.0, 0.3), st.floats(1.0, 3.0))
def test_potential_field_term_is_minus_the_gradient_of_parks_potential(
    position, velocity, radius, exponent
):
    """Answer key: central finite differences of U = lambda (-cos theta)^beta |v| / p, the
    potential written plainly here (step 1e-6, error ~1e-12 / 1e-6 on smooth U)."""
    centre = np.zeros(3)
    distance = np.linalg.norm(position)
    if distance < radius + 0.2 or np.linalg.norm(velocity) < 1e-2:
        return

    def potential(y):
        x = y - centre
        cosine = x @ velocity / np.linalg.norm(x) / np.linalg.norm(velocity)
        p = np.linalg.norm(x) - radius
        return 2.0 * max(-cosine, 0.0) ** exponent * np.linalg.norm(velocity) / p

    cosine = position @ velocity / distance / np.linalg.norm(velocity)
    if abs(cosine) < 1e-3:  # the switch at theta = pi/2 (not smooth for exponent < 2)
        return
    h = 1e-6
    gradient = np.array(
        [(potential(position + h * e) - potential(position - h * e)) / (2 * h) for e in np.eye(3)]
    )
    field = PotentialField(Sphere(centre, radius), strength=2.0, exponent=exponent)
    got = field(position, velocity)
    np.testing.assert_allclose(got, -gradient, atol=1e-5 * (1 + np.abs(gradient).max()))
    assert field.potential(position, velocity) == pytest.approx(potential(position))


def test_box_and_sphere_distances():
    """Signed distances against hand-computed values."""
    box = Box([0.0, 0.0], [1.0, 0.5])
    points = np.array([[2.0, 0.0], [2.0, 1.5], [0.0, 0.25]])
    np.testing.assert_allclose(box.distance(points), [1.0, np.sqrt(2.0), -0.25])
    np.testing.assert_allclose(Sphere([0.0, 0.0], 0.5).distance([[0.0, 2.0]]), [1.5])
    np.testing.assert_allclose(
        clearance(points, [box, Sphere([2.0, 1.5], 0.1)]), [1.0, -0.1, -0.25]
    )


def _line_demo():
    return minimum_jerk(np.zeros(2), np.array([1.0, 0.0]), 1.0, 0.002)


@pytest.mark.parametrize("term", ["steering", "potential"])
def test_coupled_stepper_avoids_an_obstacle_on_the_straight_path(term):
    """A straight line through a disc of radius 0.1: uncoupled it enters the disc by 70 mm
    (geometry: the line passes 30 mm from the centre); with either published term (published
    gains) it stays outside and still ends within 2 cm of the goal."""
    dmp = fit_discrete(_line_demo(), 20)
    disc = Sphere([0.5, 0.03], 0.1)
    coupling = SteeringAngle(disc) if term == "steering" else PotentialField(disc)
    plain = run_coupled(dmp.stepper(0.001), lambda p, v: np.zeros(2), 2000)
    assert clearance(plain.positions, disc).min() == pytest.approx(-0.07, abs=1e-3)
    path = run_coupled(dmp.stepper(0.001), coupling, 2000)
    assert clearance(path.positions, disc).min() > 0.0
    assert np.linalg.norm(path.positions[-1] - [1.0, 0.0]) < 0.02


def test_coupled_cartesian_stepper_avoids_a_sphere():
    """A hand moving 1 m along x while turning, a ball of radius 0.1 m 30 mm off its path:
    the steering-angle term fed by the Cartesian stepper keeps it outside (geometry:
    uncoupled it passes 70 mm inside)."""
    times = np.linspace(0.0, 1.0, 201)
    s = 10 * times**3 - 15 * times**4 + 6 * times**5
    positions = np.column_stack([s, 0 * s, 0 * s])
    angles = 0.5 * s
    orientations = np.column_stack([np.cos(angles / 2), 0 * s, 0 * s, np.sin(angles / 2)])
    dmp = fit_cartesian(times, positions, orientations, 15)
    ball = Sphere([0.5, 0.0, 0.03], 0.1)
    plain = run_coupled(dmp.stepper(0.001), lambda p, v: np.zeros(3), 1500)
    assert clearance(plain.positions, ball).min() == pytest.approx(-0.07, abs=1e-3)
    path = run_coupled(dmp.stepper(0.001), SteeringAngle(ball), 1500)
    assert clearance(path.positions, ball).min() > 0.0


def test_cartesian_stepper_coupling_acts_as_on_the_position_dmp():
    """Answer key: the position part of a Cartesian DMP is its position DMP (same equations),
    so under the same coupling sequence its positions equal a dmpopt.Stepper's."""
    times = np.linspace(0.0, 1.0, 201)
    positions = np.column_stack([times, times**2, np.sin(times)])
    angles = 0.3 * times
    orientations = np.column_stack([np.cos(angles / 2), np.sin(angles / 2), 0 * times, 0 * times])
    dmp = fit_cartesian(times, positions, orientations, 10)
    cartesian, plain = dmp.stepper(0.001), dmp.position_dmp.stepper(0.001)
    rng = np.random.default_rng(0)
    for _ in range(300):
        term = rng.normal(size=3)
        cartesian.step(coupling=term)
        plain.step(coupling=term)
    np.testing.assert_allclose(cartesian.position, plain.position, atol=1e-12)
    free = dmp.stepper(0.001)
    for _ in range(300):
        free.step()
    assert np.linalg.norm(free.position - cartesian.position) > 1e-4  # the term acted
    np.testing.assert_allclose(free.orientation, cartesian.orientation, atol=1e-12)
    cartesian.step(angular_coupling=[0.0, 0.0, 50.0])
    free.step()
    assert not np.allclose(free.orientation, cartesian.orientation)


def test_errors_name_the_argument():
    with pytest.raises(InvalidInputError, match="takes Sphere obstacles"):
        SteeringAngle(Box([0.0, 0.0], 1.0))
    with pytest.raises(ShapeError, match=r"coupling has shape \(2,\), expected \(3,\)"):
        fit_cartesian(
            np.linspace(0, 1, 5), np.zeros((5, 3)), np.tile([1.0, 0, 0, 0], (5, 1)), 3
        ).stepper().step(coupling=[1.0, 2.0])
    with pytest.raises(InvalidInputError, match="half_widths must be positive"):
        Box([0.0, 0.0], [1.0, -1.0])
    with pytest.raises(ShapeError, match=r"position has shape"):
        PotentialField(Sphere([0.0, 0.0], 0.1))([0.0, 0.0, 0.0], [1.0, 0.0])
