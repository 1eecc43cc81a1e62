"""DCM feedback, support-polygon clipping and the capture-point foothold (dmpopt.balance).

Answer keys: the LIPM's DCM dynamics xi' = omega (xi - p) solved in closed form here
(a constant ZMP: xi(t) = p + (xi0 - p) exp(omega t)) and integrated with a fourth-order
Runge-Kutta written here; the DCM error of the feedback law, e(t) = e(0) exp(-k t); the nearest
point of a polygon found by brute force over densely sampled edges.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.balance import (
    capture_foothold,
    capture_time,
    clip_to_polygon,
    convex_hull,
    dcm,
    dcm_feedback_zmp,
    edge_signs,
    ground_tilt,
    lipm_acceleration,
    polygons_overlap,
    predict_dcm,
    recovery_zmp,
    transfer_time,
)
from dmpopt.exceptions import InvalidInputError, ShapeError

OMEGA = np.sqrt(9.81 / 0.87)  # [1/s] Talos' CoM height
coordinate = st.floats(-0.5, 0.5, allow_nan=False)


def _rk4(rate, x, dt, n):
    for _ in range(n):
        k1 = rate(x)
        k2 = rate(x + 0.5 * dt * k1)
        k3 = rate(x + 0.5 * dt * k2)
        k4 = rate(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


@settings(max_examples=30, deadline=None)
@given(st.tuples(coordinate, coordinate), st.tuples(coordinate, coordinate), st.floats(0.0, 0.8))
def test_predicted_dcm_solves_the_lipm_about_a_constant_zmp(xi0, p, t):
    """The closed form against the LIPM's CoM integrated by RK4 (x'' = omega^2 (x - p)), whose
    DCM x + x'/omega is the prediction; RK4's global error ~ (omega h)^4 / 120 e^{omega t}
    (h = t / 200 <= 4 ms) stays below 1e-8 m here."""
    xi0, p = np.array(xi0), np.array(p)
    x0 = np.zeros(2)
    v0 = OMEGA * (xi0 - x0)  # a CoM at 0 whose DCM is xi0

    def rate(state):
        return np.concatenate([state[2:], OMEGA**2 * (state[:2] - p)])

    n = 200
    end = _rk4(rate, np.concatenate([x0, v0]), t / n, n)
    expected = end[:2] + end[2:] / OMEGA
    assert predict_dcm(xi0, p, OMEGA, t) == pytest.approx(expected, abs=1e-7)
    assert dcm(end[:2], end[2:], OMEGA) == pytest.approx(expected, abs=1e-12)
    assert lipm_acceleration(end[:2], p, OMEGA) == pytest.approx(rate(end)[2:], abs=1e-12)


@settings(max_examples=8, deadline=None)
@given(st.tuples(coordinate, coordinate), st.floats(0.0, 10.0))
def test_dcm_feedback_makes_the_error_decay_at_the_gain(error0, gain):
    """The plan: xi_r(t) = p_r + (xi_r0 - p_r) e^{omega t} about a constant p_r. The plant
    xi' = omega (xi - p_c) under the feedback, integrated by RK4 with h = 4 ms (global error
    ~ (k h)^4 / 120 e(0) < 1e-8 m for k <= 10 1/s), must leave e(t) = e(0) e^{-k t}."""
    p_r, xi_r0 = np.array([0.02, -0.01]), np.array([0.05, 0.03])
    t_end, n = 0.6, 150

    def reference(t):
        return p_r + (xi_r0 - p_r) * np.exp(OMEGA * t)

    def rate(state):  # state: xi, t
        xi, t = state[:2], state[2]
        zmp = dcm_feedback_zmp(xi, reference(t), p_r, gain, OMEGA)
        return np.append(OMEGA * (xi - zmp), 1.0)

    start = np.append(xi_r0 + np.array(error0), 0.0)
    end = _rk4(rate, start, t_end / n, n)
    expected = np.array(error0) * np.exp(-gain * t_end)
    assert end[:2] - reference(t_end) == pytest.approx(expected, abs=1e-7)


def test_zero_gain_holds_the_error_and_the_zmp_moves_by_it():
    # p_c = p_r + (1 + 0) e: the ZMP shifts with the error, so xi' - xi_r' = omega (e - e) = 0
    zmp = dcm_feedback_zmp([0.1, 0.0], [0.0, 0.0], [0.01, 0.02], 0.0, OMEGA)
    assert zmp == pytest.approx([0.11, 0.02], abs=1e-15)


SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def _brute_nearest(point, polygon, n=4001):
    s = np.linspace(0.0, 1.0, n)[:, None]
    edges = [a + s * (b - a) for a, b in zip(polygon, np.roll(polygon, -1, axis=0))]
    samples = np.vstack(edges)
    return samples[np.argmin(np.linalg.norm(samples - point, axis=1))]


@settings(max_examples=50, deadline=None)
@given(st.tuples(st.floats(-2, 3), st.floats(-2, 3)))
def test_clip_keeps_inner_points_and_projects_outer_ones_to_the_nearest_edge_point(point):
    """Brute force over edges sampled every 1/4000 of their length: the nearest sample lies
    within 1/8000 of an edge (x sqrt 2 for the distance) of the exact projection."""
    point = np.array(point)
    clipped = clip_to_polygon(point, SQUARE)
    inside = (0.0 <= point).all() and (point <= 1.0).all()
    if inside:
        assert clipped == pytest.approx(point, abs=0.0)
    else:
        assert clipped == pytest.approx(_brute_nearest(point, SQUARE), abs=2e-4)
        # a box: clip. Two edges whose squared distances tie within rounding (eps d^2) may
        # each win: their points differ by up to sqrt(2 eps) d ~ 1e-7 here (d < 4)
        assert clipped == pytest.approx(np.clip(point, 0.0, 1.0), abs=1e-7)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(-1, 1), st.floats(-1, 1)), min_size=3, max_size=12))
def test_convex_hull_contains_every_point_and_its_vertices_are_input_points(points):
    points = np.array(points)
    hull = convex_hull(points)
    if len(hull) < 3:
        return  # collinear points: a segment or a point
    for vertex in hull:
        assert np.isclose(points, vertex).all(axis=1).any()
    for point in points:  # inside or on the boundary: within rounding of the edge products
        assert np.linalg.norm(clip_to_polygon(point, hull) - point) < 1e-9


def test_two_soles_side_by_side_make_one_hull_of_their_outer_corners():
    left = np.array([[0.1, 0.15], [-0.1, 0.15], [-0.1, 0.02], [0.1, 0.02]])
    right = left * [1, -1]
    hull = convex_hull(np.vstack([left, right]))
    assert sorted(map(tuple, hull)) == sorted([(0.1, 0.15), (-0.1, 0.15), (-0.1, -0.15),
                                               (0.1, -0.15)])  # fmt: skip
    # between the feet, where neither sole is, the ZMP may still be (it is the polygon's)
    assert clip_to_polygon([0.0, 0.0], hull) == pytest.approx([0.0, 0.0])


def test_clip_to_a_segment_and_a_point():
    segment = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert clip_to_polygon([0.5, 2.0], segment) == pytest.approx([0.5, 0.0])
    assert clip_to_polygon([3.0, 1.0], [[0.2, 0.3]]) == pytest.approx([0.2, 0.3])


def test_capture_foothold_moves_by_the_predicted_dcm_error_within_the_box():
    """f = f_r + xi(T) - xi_r(T), xi(T) = p + (xi0 - p) e^{omega T} written here."""
    xi0, p, remaining = np.array([0.03, 0.02]), np.array([0.0, -0.09]), 0.3
    end_reference, foothold_reference = np.array([0.12, -0.01]), np.array([0.2, 0.09])
    xi_end = p + (xi0 - p) * np.exp(OMEGA * remaining)
    expected = foothold_reference + xi_end - end_reference
    wide = capture_foothold(xi0, p, OMEGA, remaining, end_reference, foothold_reference,
                            [-5, -5], [5, 5])  # fmt: skip
    assert wide == pytest.approx(expected, abs=1e-12)
    box = capture_foothold(xi0, p, OMEGA, remaining, end_reference, foothold_reference,
                           [-0.1, 0.15], [0.1, 0.4])  # fmt: skip
    assert box == pytest.approx(np.clip(expected, [-0.1, 0.15], [0.1, 0.4]), abs=1e-12)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.05, 0.4), st.floats(-0.3, 0.3), st.floats(0.0, 0.05))
def test_capture_time_lands_the_foot_on_the_reach_boundary_or_keeps_the_plan(lateral, forward, b):
    """f(tau) = p + (xi0 - p) e^{omega tau} - b written here: at the time returned f has not
    run out of the box on the side the DCM diverges to (d = xi0 - p), and lies on that side
    when the time is strictly between the shortest and the longest."""
    p, xi0 = np.array([0.0, -0.09]), np.array([forward * 0.3, -0.09 + lateral])
    offset = np.array([0.02, b])
    lower, upper = np.array([-0.25, 0.06]), np.array([0.4, 0.31])
    tau = capture_time(xi0, p, OMEGA, offset, lower, upper, 0.15, 0.5)
    assert 0.15 <= tau <= 0.5
    d = xi0 - p
    foothold = p + d * np.exp(OMEGA * tau) - offset
    bound = np.where(d > 0, upper, lower)
    beyond = np.sign(d) * (foothold - bound)  # > 0: out of reach on the diverging side
    if tau > 0.15:
        assert (beyond <= 1e-12).all()
    if 0.15 < tau < 0.5:  # the binding axis touches its bound
        assert np.max(beyond) == pytest.approx(0.0, abs=1e-9)


def test_transfer_time_is_what_the_swing_leaves_of_the_time_to_reach_the_box_edge():
    """Written out: the next foothold f_r + e exp(omega T) reaches the box's forward edge at
    T* = ln((upper - f_r) / e) / omega; the double support is T* minus the 0.6 s swing,
    clipped to [0.05, 0.2]."""
    foothold = np.array([0.2, -0.2])  # the stance foot at the origin, a right step
    lower, upper = np.array([-0.25, -0.3]), np.array([0.4, -0.15])
    for error_x in (0.02, 0.001, 0.05):
        t_star = np.log((0.4 - 0.2) / error_x) / OMEGA  # 0.686, 1.578, 0.413 s
        expected = min(max(t_star - 0.6, 0.05), 0.2)  # 0.086, 0.2, 0.05 s
        got = transfer_time([error_x, 0.0], foothold, OMEGA, lower, upper, 0.6, 0.05, 0.2)
        assert got == pytest.approx(expected, abs=1e-12)
    # an error inwards (towards the stance foot, y > 0) meets the box's inner side instead
    t_star = np.log((-0.15 + 0.2) / 0.004) / OMEGA  # 0.752 s
    got = transfer_time([0.0, 0.004], foothold, OMEGA, lower, upper, 0.6, 0.05, 0.2)
    assert got == pytest.approx(t_star - 0.6, abs=1e-12)


@settings(max_examples=40, deadline=None)
@given(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05))
def test_transfer_time_keeps_the_next_foothold_in_reach(error_x, error_y):
    """f(T) = f_r + e exp(omega T) written here, T = the double support + the 0.6 s swing:
    in the box unless the double support is at its shortest, on its edge when strictly
    between the shortest and the planned one."""
    foothold, error = np.array([0.2, -0.2]), np.array([error_x, error_y])
    lower, upper = np.array([-0.25, -0.3]), np.array([0.4, -0.15])
    transfer = transfer_time(error, foothold, OMEGA, lower, upper, 0.6, 0.05, 0.2)
    assert 0.05 <= transfer <= 0.2
    f = foothold + error * np.exp(OMEGA * (transfer + 0.6))
    outside = np.maximum(lower - f, f - upper)  # > 0: out of the box
    if transfer > 0.05:
        assert (outside <= 1e-12).all()
    if 0.05 < transfer < 0.2:
        assert np.max(outside) == pytest.approx(0.0, abs=1e-9)


def _rectangle(x, y, length=0.21, width=0.138):
    """A Talos sole's outline (0.21 m x 0.138 m) centred at (x, y), counter-clockwise."""
    dx, dy = length / 2, width / 2
    return np.array([[x - dx, y - dy], [x + dx, y - dy], [x + dx, y + dy], [x - dx, y + dy]])


def test_soles_overlap_checked_on_hand_made_rectangles():
    """Side by side 0.17 m apart the soles are 0.17 - 0.138 = 0.032 m apart; a crossing step
    5 cm past the other sole's line is clear when 0.3 m ahead (gap 0.3 - 0.21 = 0.09 m) and
    not when 0.22 m ahead with a 2 cm clearance (gap 0.01 m)."""
    stance = _rectangle(0.0, 0.0)
    assert not polygons_overlap(stance, _rectangle(0.0, 0.17))
    assert not polygons_overlap(stance, _rectangle(0.0, 0.17), clearance=0.03)
    assert polygons_overlap(stance, _rectangle(0.0, 0.17), clearance=0.04)
    assert polygons_overlap(stance, _rectangle(0.05, 0.1))
    assert not polygons_overlap(stance, _rectangle(0.3, -0.05), clearance=0.02)
    assert polygons_overlap(stance, _rectangle(0.22, -0.05), clearance=0.02)
    assert not polygons_overlap(stance, _rectangle(0.22, -0.05))
    # a diamond (a square turned 45 degrees, vertices 1 from its centre at (2.1, 0)) beside
    # the square [-1, 1]^2: its left vertex is 0.1 from the square's right side
    diamond = np.array([[1.1, 0.0], [2.1, -1.0], [3.1, 0.0], [2.1, 1.0]])
    square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    assert not polygons_overlap(square, diamond, clearance=0.05)
    assert polygons_overlap(diamond, square, clearance=0.15)
    assert polygons_overlap(square[::-1], diamond - [0.2, 0.0])  # clockwise works too
    with pytest.raises(ShapeError, match="^second has shape"):
        polygons_overlap(square, square[:2])


@settings(max_examples=40, deadline=None)
@given(coordinate, coordinate, st.floats(0.0, 0.05))
def test_axis_aligned_soles_overlap_when_both_axes_are_closer_than_the_sizes(dx, dy, gap):
    """Two axis-aligned rectangles come within ``gap`` exactly when their centres are closer
    than (length + gap) along x and (width + gap) along y (written here)."""
    expected = abs(dx) < 0.21 + gap and abs(dy) < 0.138 + gap
    assume_clear = min(abs(abs(dx) - 0.21 - gap), abs(abs(dy) - 0.138 - gap)) > 1e-9
    if assume_clear:  # away from the boundary, where rounding decides
        assert polygons_overlap(_rectangle(0, 0), _rectangle(dx, dy), gap) == expected


@settings(max_examples=30, deadline=None)
@given(st.tuples(coordinate, coordinate), st.floats(0.05, 0.6))
def test_recovery_zmp_returns_the_dcm_to_the_plan_or_stays_on_the_sole(error, t):
    """Key: with the ZMP held at p the DCM is p + (xi - p) e^{omega t} (written here), and
    the plan's, about its constant p_r, p_r + (xi_r - p_r) e^{omega t}: equal when the
    needed ZMP lies on the sole; otherwise the ZMP is on the sole's edge."""
    sole = np.array([[-0.1, -0.06], [0.1, -0.06], [0.1, 0.06], [-0.1, 0.06]])
    p_r, xi_r = np.array([0.0, 0.0]), np.array([0.03, -0.02])
    xi = xi_r + np.array(error)
    zmp = recovery_zmp(xi, xi_r, p_r, sole, OMEGA, t)
    growth = np.exp(OMEGA * t)
    needed = p_r + (xi - xi_r) * growth / (growth - 1.0)
    if (np.abs(needed) <= [0.1, 0.06]).all():
        assert zmp == pytest.approx(needed, abs=1e-12)
        dcm_at_t = zmp + (xi - zmp) * growth
        assert dcm_at_t == pytest.approx(p_r + (xi_r - p_r) * growth, abs=1e-9)
    else:
        assert zmp == pytest.approx(np.clip(needed, [-0.1, -0.06], [0.1, 0.06]), abs=1e-12)


def test_ground_tilt_of_a_two_degree_slope_is_the_pitch_written_out():
    """Ground rising along x at angle a has the upward normal (-sin a, 0, cos a); a level sole
    tilted onto it is turned about y by -a: [[cos a, 0, -sin a], [0, 1, 0], [sin a, 0, cos a]]
    (its toe, +x, goes up by sin a)."""
    a = np.radians(2.0)
    tilt = ground_tilt([-np.sin(a), 0.0, np.cos(a)])
    expected = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])
    np.testing.assert_allclose(tilt, expected, atol=1e-15)
    np.testing.assert_array_equal(ground_tilt([0.0, 0.0, 2.0]), np.eye(3))  # level: no tilt


@settings(max_examples=30, deadline=None)
@given(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5))
def test_ground_tilt_takes_up_to_the_normal_without_turning_about_the_vertical(nx, ny):
    """A rotation (R^T R = I, det 1) that maps e_z to the unit normal, about a horizontal axis
    (its axis, the vector of R - R^T, has no vertical part)."""
    normal = np.array([nx, ny, 1.0]) / np.linalg.norm([nx, ny, 1.0])
    tilt = ground_tilt(normal)
    np.testing.assert_allclose(tilt.T @ tilt, np.eye(3), atol=1e-12)
    assert np.linalg.det(tilt) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(tilt @ [0.0, 0.0, 1.0], normal, atol=1e-12)
    assert tilt[1, 0] - tilt[0, 1] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize(
    "call, error, match",
    [
        (lambda: dcm([0, 0, 0], [0, 0], OMEGA), ShapeError, "^com has shape"),
        (lambda: dcm([0, 0], [0, 0], 0.0), InvalidInputError, "^omega"),
        (lambda: dcm_feedback_zmp([0, 0], [0, 0], [0, 0], -1.0, OMEGA), InvalidInputError,
         "^gain"),
        (lambda: predict_dcm([0, 0], [0, 0], OMEGA, -0.1), InvalidInputError, "^t must"),
        (lambda: clip_to_polygon([0, 0], SQUARE[::-1]), InvalidInputError, "clockwise"),
        (lambda: clip_to_polygon([0, 0], np.zeros((0, 2))), ShapeError, "^polygon"),
        (lambda: convex_hull([[0, 0, 0]]), ShapeError, "^points"),
        (lambda: capture_foothold([0, 0], [0, 0], OMEGA, 0.1, [0, 0], [0, 0], [1, 0], [0, 1]),
         InvalidInputError, "^lower"),
        (lambda: ground_tilt([0, 0, -1]), InvalidInputError, "^normal must .* pointing up"),
        (lambda: ground_tilt([0, 1]), ShapeError, "^normal has shape"),
    ],
)  # fmt: skip
def test_bad_input_names_the_argument(call, error, match):
    with pytest.raises(error, match=match):
        call()


# ------------------------------------------------------------- answer keys (mutation run)
BOX = ([-1.0, -1.0], [1.0, 1.0])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: dcm([0, 0], [0], OMEGA), r"^com_velocity has shape"),
        (lambda: dcm([np.nan, 0], [0, 0], OMEGA), r"^com\[0\] is nan"),
        (lambda: dcm([0, 0], [0, 0], 0.0),
         r"^omega must be a finite number > 0, got 0\.0; omega = sqrt\(g / z_c\)$"),
        (lambda: dcm_feedback_zmp([0], [0, 0], [0, 0], 1.0, OMEGA), r"^dcm has shape"),
        (lambda: dcm_feedback_zmp([0, 0], [0], [0, 0], 1.0, OMEGA), r"^dcm_reference has"),
        (lambda: dcm_feedback_zmp([0, 0], [0, 0], [0], 1.0, OMEGA), r"^zmp_reference has"),
        (lambda: lipm_acceleration([0], [0, 0], OMEGA), r"^com has shape"),
        (lambda: lipm_acceleration([0, 0], [0], OMEGA), r"^zmp has shape"),
        (lambda: predict_dcm([0], [0, 0], OMEGA, 0.1), r"^dcm has shape"),
        (lambda: predict_dcm([0, 0], [0], OMEGA, 0.1), r"^zmp has shape"),
        (lambda: clip_to_polygon([0], SQUARE), r"^point has shape"),
        (lambda: clip_to_polygon([0, 0], [0, 0]), r"^polygon has shape \(2,\), expected 2 dim"),
        (lambda: clip_to_polygon([0, 0], np.zeros((3, 3))), r"^polygon has shape \(3, 3\)"),
        (lambda: recovery_zmp([0], [0, 0], [0, 0], SQUARE, OMEGA, 0.1), r"^dcm has shape"),
        (lambda: recovery_zmp([0, 0], [0], [0, 0], SQUARE, OMEGA, 0.1), r"^dcm_reference has"),
        (lambda: recovery_zmp([0, 0], [0, 0], [0], SQUARE, OMEGA, 0.1), r"^zmp_reference has"),
        (lambda: recovery_zmp([0, 0], [0, 0], [0, 0], SQUARE, OMEGA, 0.0),
         r"^t must be a finite number > 0, got 0"),
        (lambda: polygons_overlap([0, 0, 0], SQUARE), r"^first has shape \(3,\), expected 2 dim"),
        (lambda: polygons_overlap(SQUARE, SQUARE, -0.01),
         r"^clearance must be a finite number >= 0"),
        (lambda: transfer_time([0, 0], [0], OMEGA, *BOX, 0.6, 0.05, 0.2), r"^foothold has"),
        (lambda: transfer_time([0], [0, 0], OMEGA, *BOX, 0.6, 0.05, 0.2), r"^error has"),
        (lambda: transfer_time([0, 0], [0, 0], OMEGA, *BOX, 0.0, 0.05, 0.2),
         r"^swing must be a finite number > 0, got 0"),
        (lambda: transfer_time([0, 0], [0, 0], OMEGA, *BOX, 0.6, -0.01, 0.2),
         r"^shortest must be a finite number >= 0, got -0\.01"),
        (lambda: transfer_time([0, 0], [0, 0], OMEGA, *BOX, 0.6, 0.05, 0.01),
         r"^longest must be a finite number >= 0\.05, got 0\.01; longest >= shortest$"),
        (lambda: capture_foothold([0, 0], [0, 0], OMEGA, 0.1, [0, 0], [0, 0], [0], [1, 1]),
         r"^lower has shape"),
        (lambda: capture_foothold([0, 0], [0, 0], OMEGA, 0.1, [0, 0], [0, 0], [0, 0], [1]),
         r"^upper has shape"),
        (lambda: capture_foothold([0, 0], [0, 0], OMEGA, 0.1, [0], [0, 0], *BOX),
         r"^dcm_reference_end has shape"),
        (lambda: capture_foothold([0, 0], [0, 0], OMEGA, -0.1, [0, 0], [0, 0], *BOX),
         r"^remaining must be"),
        (lambda: capture_foothold([0, 0], [0, 0], OMEGA, 0.1, [0, 0], [0], *BOX),
         r"^foothold_reference has shape"),
        (lambda: ground_tilt([[0, 0, 1]]), r"^normal has shape"),
        (lambda: ground_tilt([0, np.nan, 1]), r"^normal\[1\] is nan"),
        (lambda: ground_tilt([1.0, 0.0, 0.0]), r"^normal must .* pointing up"),  # n_z = 0
        (lambda: capture_time([0], [0, 0], OMEGA, [0, 0], *BOX, 0.1, 0.5), r"^dcm has shape"),
        (lambda: capture_time([0, 0], [0], OMEGA, [0, 0], *BOX, 0.1, 0.5), r"^zmp has shape"),
        (lambda: capture_time([0, 0], [0, 0], OMEGA, [0], *BOX, 0.1, 0.5), r"^offset has"),
        (lambda: capture_time([0, 0], [0, 0], OMEGA, [0, 0], [0], BOX[1], 0.1, 0.5),
         r"^lower has shape"),
        (lambda: capture_time([0, 0], [0, 0], OMEGA, [0, 0], BOX[0], [0], 0.1, 0.5),
         r"^upper has shape"),
        (lambda: capture_time([0, 0], [0, 0], OMEGA, [0, 0], *BOX, -0.1, 0.5),
         r"^shortest must be a finite number >= 0, got -0\.1"),
        (lambda: capture_time([0, 0], [0, 0], OMEGA, [0, 0], *BOX, 0.1, 0.05),
         r"^longest must be a finite number >= 0\.1, got 0\.05; longest >= shortest$"),
        (lambda: convex_hull([0, 0]),
         r"^points has shape \(2,\), expected 2 dim.*\(horizontal points, shape \(n, 2\)\)$"),
    ],
)  # fmt: skip
def test_each_argument_is_named_with_its_bound(call, match):
    from dmpopt.exceptions import DmpoptError

    with pytest.raises(DmpoptError, match=match):
        call()


def test_separating_axes_of_slanted_edges_and_of_unit_edges():
    """Hand geometry. The triangle (0,0), (1,0), (0,1) and a square [0.6, 0.9]^2 overlap on x
    and on y; only the hypotenuse x + y = 1 separates them, by (1.2 - 1) / sqrt 2 = 0.1414 m.
    A repeated vertex (an edge of length 0) is skipped, not the end of the search. Two unit
    squares side by side 0.2 apart are separated by their unit-length edges' normals; touching
    ones are exactly 0 apart, which is not closer than a clearance of 0."""
    triangle = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    square = np.array([[0.6, 0.6], [0.9, 0.6], [0.9, 0.9], [0.6, 0.9]])
    assert not polygons_overlap(triangle, square, clearance=0.14)
    assert polygons_overlap(triangle, square, clearance=0.15)
    assert not polygons_overlap(triangle[1:], square + 0.3, clearance=0.56)  # gap 0.5657
    assert polygons_overlap(triangle[1:], square + 0.3, clearance=0.57)
    unit = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert not polygons_overlap(unit, unit + [1.2, 0.0], clearance=0.19)
    assert polygons_overlap(unit, unit + [1.2, 0.0], clearance=0.21)
    assert not polygons_overlap(unit + [1.0, 0.0], unit)  # touching, either order
    assert not polygons_overlap(unit, unit + [1.0, 0.0])
    # a triangle's vertex touching the other's edge: x = 1 is the only axis on which they
    # meet (0 apart), and neither has the opposite normal (-1, 0) to see it from the other side
    right = np.array([[1.0, 0.0], [2.0, 0.0], [1.0, 1.0]])
    left = np.array([[0.0, 0.0], [1.0, 0.5], [0.0, 1.0]])
    assert not polygons_overlap(right, left)
    assert not polygons_overlap(left, right)
    assert polygons_overlap(right - [0.01, 0.0], left)


def test_capture_time_written_out_for_a_dcm_behind_and_one_a_metre_ahead():
    """tau = ln(room / |d|) / omega with room the distance from the ZMP to the box's side the
    DCM diverges to (b = 0): 0.3 m behind for d = -0.015 m (ratio 20, tau = 0.892 s), 5 m
    ahead for d = 1 m (ratio 5, 0.479 s); both inside [0.1, 2] s."""
    lower, upper = np.array([-0.3, -0.2]), np.array([5.0, 0.2])
    behind = capture_time([-0.015, 0.0], [0.0, 0.0], OMEGA, [0, 0], lower, upper, 0.1, 2.0)
    assert behind == pytest.approx(np.log(0.3 / 0.015) / OMEGA, rel=1e-14)
    ahead = capture_time([1.0, 0.0], [0.0, 0.0], OMEGA, [0, 0], lower, upper, 0.1, 2.0)
    assert ahead == pytest.approx(np.log(5.0) / OMEGA, rel=1e-14)


def test_clip_to_a_triangle_reaches_its_closing_edge_and_a_point_needs_no_division():
    """The triangle (0,0), (1,0), (0,1): (-0.5, 0.5) is nearest to (0, 0.5) on the closing edge
    from (0,1) back to (0,0) (the others' nearest points are the corners, 0.707 away). A
    one-point polygon has an edge of length 0, whose projection is not divided out."""
    triangle = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert clip_to_polygon([-0.5, 0.5], triangle) == pytest.approx([0.0, 0.5], abs=1e-15)
    with np.errstate(all="raise"):
        np.testing.assert_array_equal(clip_to_polygon([3.0, 1.0], [[0.2, 0.3]]), [0.2, 0.3])


def test_a_slow_pendulum_omega_below_one_is_accepted():
    """xi = x + v / omega = 0 + 0.1 / 0.5 = 0.2 m (omega = 0.5 1/s: a 39 m tall pendulum)."""
    assert dcm([0.0, 0.0], [0.1, 0.0], 0.5) == pytest.approx([0.2, 0.0], abs=1e-15)


def test_convex_hull_of_one_point_is_that_point():
    np.testing.assert_array_equal(convex_hull([[0.3, 0.2]]), [[0.3, 0.2]])


def test_capture_foothold_clips_to_both_corners_and_a_box_may_be_flat():
    """f = f_r + xi(T) - xi_r(T) written here, below the box's low corner in x and above its
    high one in y; a box with lower = upper along y holds the foot's y there."""
    xi0, p = np.array([-0.03, 0.02]), np.array([0.0, 0.0])
    f = p + (xi0 - p) * np.exp(OMEGA * 0.3)  # xi_r(T) = f_r = 0
    assert f[0] < -0.05 and f[1] > 0.03
    got = capture_foothold(xi0, p, OMEGA, 0.3, [0, 0], [0, 0], [-0.05, -0.03], [0.05, 0.03])
    assert got == pytest.approx([-0.05, 0.03], abs=0.0)
    flat = capture_foothold(xi0, p, OMEGA, 0.3, [0, 0], [0, 0], [-1.0, 0.01], [1.0, 0.01])
    assert flat == pytest.approx([f[0], 0.01], abs=1e-15)


def test_ground_tilt_of_a_normal_not_of_unit_length():
    """Twice the 10-degree slope's normal (-sin a, 0, cos a) gives the pitch written out."""
    a = np.radians(10.0)
    tilt = ground_tilt([-2 * np.sin(a), 0.0, 2 * np.cos(a)])
    expected = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])
    np.testing.assert_allclose(tilt, expected, atol=1e-15)


# ------------------------------------------------- the per-tick inputs (float64 arrays, floats)
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: dcm(np.array([np.nan, 0.0]), np.zeros(2), OMEGA), r"^com\[0\] is nan"),
        (lambda: dcm(np.zeros(2), np.array([0.0, np.inf]), OMEGA), r"^com_velocity\[1\] is inf"),
        (lambda: dcm(np.zeros(2), np.zeros(2), float("inf")), r"^omega must be a finite"),
        (lambda: dcm(np.zeros(2), np.zeros(2), float("nan")), r"^omega must be a finite"),
        (lambda: dcm_feedback_zmp(np.zeros(2), np.zeros(2), np.zeros(2), float("nan"), OMEGA),
         r"^gain must be a finite number >= 0, got nan"),
        (lambda: dcm_feedback_zmp(np.zeros(2), np.zeros(2), np.zeros(2), -1.0, OMEGA),
         r"^gain must be a finite number >= 0, got -1\.0"),
        (lambda: clip_to_polygon(np.zeros(2), np.array([[0.0, 0.0], [1.0, 0.0], [np.nan, 1.0]])),
         r"^polygon\[2, 0\] is nan"),
        (lambda: clip_to_polygon(np.zeros(2), np.array([[0.0, 0.0], [1.0, 0.0], [0.0, np.inf]])),
         r"^polygon\[2, 1\] is inf"),
        (lambda: clip_to_polygon(np.array([np.nan, 0.0]), SQUARE), r"^point\[0\] is nan"),
    ],
)  # fmt: skip
def test_float64_arrays_and_floats_are_checked_as_well(call, match):
    """A tick passes float64 arrays and floats, which take the quick check: a NaN or an
    infinity is still refused with the argument named."""
    from dmpopt.exceptions import DmpoptError

    with pytest.raises(DmpoptError, match=match):
        call()


def test_clip_returns_a_new_point_and_leaves_its_inputs_alone():
    """An inner float64 point comes back equal but as a new array (changing the answer does
    not change the caller's point); an outer one is the nearest edge point, (1, 0.5) for
    (2, 0.5) and the unit square (answer written here)."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    inner = np.array([0.25, 0.5])
    clipped = clip_to_polygon(inner, square)
    assert clipped is not inner
    clipped[0] = 9.0
    assert inner.tolist() == [0.25, 0.5]
    outer = np.array([2.0, 0.5])
    assert clip_to_polygon(outer, square).tolist() == [1.0, 0.5]
    assert outer.tolist() == [2.0, 0.5] and square[1].tolist() == [1.0, 0.0]


def test_edge_signs_are_each_edges_cross_product_with_the_point():
    """The unit square, counter-clockwise: edge k from v_k to v_(k+1) has cross product
    (b - a) x (p - a); inside all are positive (0.5 at the centre), on an edge one is zero,
    outside to the right the right edge's is negative."""
    square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    assert edge_signs(0.5, 0.5, square) == [0.5, 0.5, 0.5, 0.5]
    assert edge_signs(0.25, 0.0, square) == [0.0, 0.75, 1.0, 0.25]
    assert edge_signs(2.0, 0.25, square) == [0.25, -1.0, 0.75, 2.0]


def test_each_ticks_fast_path_names_what_it_refuses():
    """The checks a float or a float64 point skips stay for everything else: a string omega
    or gain, an infinite gain, a float64 array of three entries or a polygon array of the
    wrong rank or of strings are refused with the argument's name, not a numpy error."""
    point = np.array([0.1, 0.2])
    with pytest.raises(InvalidInputError, match="^omega"):
        dcm(point, point, "3.4")
    with pytest.raises(InvalidInputError, match="^gain"):
        dcm_feedback_zmp(point, point, point, "2.0", 3.4)
    with pytest.raises(InvalidInputError, match="^gain"):
        dcm_feedback_zmp(point, point, point, float("inf"), 3.4)
    with pytest.raises(ShapeError, match=r"^com has shape \(3,\)"):
        dcm(np.zeros(3), point, 3.4)
    for polygon in (np.zeros(4), np.zeros((3, 2, 1))):
        with pytest.raises(ShapeError, match="^polygon"):
            clip_to_polygon(point, polygon)
    with pytest.raises(InvalidInputError, match="^polygon"):
        clip_to_polygon(point, np.array([["0", "0"], ["1", "0"], ["0", "1"]]))


def test_a_point_given_as_integers_comes_back_as_floats():
    """clip_to_polygon returns a float point, also for an integer array inside the square."""
    square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    inside = clip_to_polygon(np.array([0, 0]), square)
    assert inside.dtype == np.float64 and inside.tolist() == [0.0, 0.0]


def test_a_point_on_an_edge_is_inside_and_returned_as_it_is():
    """(1/3, 1) lies on the edge (0, 0) -> (1, 3) of a counter-clockwise triangle: its cross
    product 1 x 1 - 3 x (1/3) is 0 in floats, so it is inside and returned bit for bit (the
    nearest point on the edge, s (1, 3) with s = (1/3 + 3) / 10, is an ulp off)."""
    triangle = np.array([[0.0, 0.0], [1.0, 3.0], [-1.0, 3.0]])
    point = np.array([1.0 / 3.0, 1.0])
    assert (1.0 / 3.0 + 3.0) / 10.0 * 1.0 != point[0]
    assert clip_to_polygon(point, triangle).tolist() == point.tolist()
