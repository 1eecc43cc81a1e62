r"""Balance feedback on the divergent component of motion (DCM), and capture-point stepping.

The linear inverted pendulum (:mod:`dmpopt.walk_plan`) with CoM :math:`x`, zero-moment point
(ZMP, centre of pressure) :math:`p` and :math:`\omega = \sqrt{g / z_c}` splits into

.. math:: \dot \xi = \omega (\xi - p), \qquad \dot x = \omega (\xi - x),
    \qquad \xi = x + \dot x / \omega,

the DCM (capture point) :math:`\xi` diverging from the ZMP and the CoM converging to the DCM.

DCM feedback [Englsberger2015]_ (Section IV, the DCM tracking controller). A plan gives the
reference ZMP :math:`p_r` and DCM :math:`\xi_r` (with :math:`\dot\xi_r = \omega(\xi_r - p_r)`);
the commanded ZMP

.. math:: p_c = p_r + (1 + k / \omega)(\xi - \xi_r)
    :label: dcm-feedback

makes the DCM error :math:`e = \xi - \xi_r` obey :math:`\dot e = -k\, e`, so
:math:`e(t) = e(0)\, e^{-k t}` (:func:`dcm_feedback_zmp`). A real foot can push only inside
its support polygon: :math:`p_c` is projected onto it (:func:`clip_to_polygon`), and the CoM
is given the LIPM acceleration of the commanded ZMP, :math:`\ddot x = \omega^2 (x - p_c)`
(:func:`lipm_acceleration`).

Stepping. With the ZMP held at :math:`p` the DCM after :math:`t` seconds is
:math:`\xi(t) = p + (\xi_0 - p)\, e^{\omega t}` (:func:`predict_dcm`). Where the foot lands
decides the next ZMP, so the foothold is the DCM's recovery: the capture-point foothold
[Englsberger2015]_ [Khadiv2020]_ keeps the planned offset :math:`b` of the end-of-step DCM
from the next foothold,

.. math:: f = \xi(T) - b, \qquad b = \xi_r(T) - f_r,
    :label: capture-step

with :math:`T` the planned touchdown, :math:`f_r` the planned foothold, and :math:`f`
clipped to the box the leg can reach (:func:`capture_foothold`). It moves the foothold by the
predicted DCM error at touchdown, :math:`f - f_r = \xi(T) - \xi_r(T)`, predicted with the
ZMP the stance sole can give towards cancelling it (:func:`recovery_zmp`): the ankle first,
the step for what is left. When even the farthest reachable foothold is not enough, the
step comes sooner (:func:`capture_time`, step timing adaptation [Khadiv2020]_), and after a
step that could not catch the DCM the double support before the next one is shortened
(:func:`transfer_time`): the DCM keeps diverging while the weight moves over.

Uneven ground. A sole that has come to rest with its corners down lies on the ground, so
its normal :math:`n` is the ground's; the rotation that tilts a level sole onto it (the
smallest one, no turn about the vertical, :func:`ground_tilt`) orients the next footholds.

Symbols: :math:`\xi` ``dcm``, :math:`p` ``zmp``, :math:`\omega` ``omega`` [1/s],
:math:`k` ``gain`` [1/s], :math:`b` ``offset``.
"""

from __future__ import annotations

import math

import numpy as np

from .exceptions import InvalidInputError, ShapeError
from .validation import real, real_array

__all__ = [
    "capture_foothold",
    "capture_time",
    "clip_to_polygon",
    "convex_hull",
    "dcm",
    "dcm_feedback_zmp",
    "edge_signs",
    "ground_tilt",
    "lipm_acceleration",
    "predict_dcm",
    "polygons_overlap",
    "recovery_zmp",
    "transfer_time",
]


def _plane(name: str, value) -> np.ndarray:
    if (
        type(value) is np.ndarray
        and value.shape == (2,)
        and value.dtype == np.float64
        and math.isfinite(value[0])
        and math.isfinite(value[1])
    ):  # already a point (each tick's case): used as it is, not copied
        return value
    point = real_array(name, value)
    if point.shape != (2,):
        raise ShapeError(
            f"{name} has shape {point.shape}, expected (2,): a horizontal point (x, y) [m]"
        )
    return point


def _omega(omega) -> float:
    if type(omega) is float and 0.0 < omega < math.inf:  # each tick's case
        return omega
    return real("omega", omega, minimum=0.0, open_minimum=True, fix="omega = sqrt(g / z_c)")


def dcm(com, com_velocity, omega: float) -> np.ndarray:
    r"""The DCM :math:`\xi = x + \dot x / \omega` [m] of a horizontal CoM ``com`` [m] and
    ``com_velocity`` [m/s], each shape (2,)."""
    return _plane("com", com) + _plane("com_velocity", com_velocity) / _omega(omega)


def dcm_feedback_zmp(dcm, dcm_reference, zmp_reference, gain: float, omega: float) -> np.ndarray:
    r"""Commanded ZMP of the DCM feedback, eq. :eq:`dcm-feedback` [m], shape (2,).

    Parameters
    ----------
    dcm : array_like, shape (2,)
        Measured DCM :math:`\xi` [m].
    dcm_reference, zmp_reference : array_like, shape (2,)
        The plan's :math:`\xi_r` and :math:`p_r` at the same time [m].
    gain : float
        :math:`k` [1/s], >= 0: the DCM error decays as :math:`e^{-k t}` (0: it is held,
        the ZMP follows the DCM's drift).
    omega : float
        :math:`\omega` [1/s].
    """
    xi = _plane("dcm", dcm)
    error = xi - _plane("dcm_reference", dcm_reference)
    if not (type(gain) is float and 0.0 <= gain < math.inf):  # a float gain: as it is
        gain = real("gain", gain, minimum=0.0)
    return _plane("zmp_reference", zmp_reference) + (1.0 + gain / _omega(omega)) * error


def lipm_acceleration(com, zmp, omega: float) -> np.ndarray:
    r"""Horizontal CoM acceleration of the LIPM, :math:`\omega^2 (x - p)` [m/s^2], shape (2,)."""
    return _omega(omega) ** 2 * (_plane("com", com) - _plane("zmp", zmp))


def predict_dcm(dcm, zmp, omega: float, t: float) -> np.ndarray:
    r"""The DCM after ``t`` seconds with the ZMP held at ``zmp``:
    :math:`p + (\xi_0 - p)\, e^{\omega t}` [m], shape (2,)."""
    p = _plane("zmp", zmp)
    t = real("t", t, minimum=0.0)
    return p + (_plane("dcm", dcm) - p) * np.exp(_omega(omega) * t)


def recovery_zmp(dcm, dcm_reference, zmp_reference, polygon, omega: float, t: float):
    r"""The constant ZMP that brings the DCM back to the plan in ``t`` seconds, clipped to the
    support polygon [m], shape (2,): the ankle's share of a recovery, the step's share being
    what it leaves.

    With the plan's ZMP :math:`p_r` constant (single support), holding
    :math:`p = p_r + \Delta` makes the error :math:`e = \xi - \xi_r` reach
    :math:`e(t) = (e - \Delta)\, E + \Delta`, :math:`E = e^{\omega t}`; it is zero for
    :math:`\Delta = e\, E / (E - 1)`. That ZMP is clipped to ``polygon``
    (:func:`clip_to_polygon`); :func:`predict_dcm` from it gives the DCM at ``t``, and
    :func:`capture_foothold` the foothold that absorbs what is left.

    Parameters
    ----------
    dcm, dcm_reference, zmp_reference : array_like, shape (2,)
        :math:`\xi`, :math:`\xi_r` and :math:`p_r` now [m].
    polygon : array_like, shape (n, 2)
        The support polygon, counter-clockwise (:func:`convex_hull`).
    omega : float
        :math:`\omega` [1/s].
    t : float
        Time to touchdown [s], > 0.
    """
    error = _plane("dcm", dcm) - _plane("dcm_reference", dcm_reference)
    t = real("t", t, minimum=0.0, open_minimum=True)
    growth = np.exp(_omega(omega) * t)
    needed = _plane("zmp_reference", zmp_reference) + error * growth / (growth - 1.0)
    return clip_to_polygon(needed, polygon)


def convex_hull(points) -> np.ndarray:
    """Vertices of the convex hull of horizontal ``points`` (shape (n, 2), n >= 1),
    counter-clockwise, without repeated or collinear points (Andrew's monotone chain)."""
    points = real_array("points", points, ndim=2, expected="horizontal points, shape (n, 2)")
    if points.shape[1] != 2 or points.shape[0] == 0:
        raise ShapeError(
            f"points has shape {points.shape}, expected (n, 2) with n >= 1: (x, y) rows [m]"
        )
    unique = np.unique(points, axis=0)  # sorted by x, then y
    if len(unique) < 3:
        return unique

    def chain(rows):
        hull = []
        for row in rows:
            while len(hull) >= 2 and _cross(hull[-2], hull[-1], row) <= 0.0:
                hull.pop()
            hull.append(row)
        return hull[:-1]

    return np.array(chain(unique) + chain(unique[::-1]))


def _cross(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def polygons_overlap(first, second, clearance: float = 0.0) -> bool:
    """Whether two convex polygons (vertices in order, either direction, shape (n, 2) and
    (m, 2) [m]) come closer than ``clearance`` [m] along every edge normal of either (the
    separating axis test: convex polygons are apart exactly when some edge normal separates
    their projections). A foothold is checked with it against the standing sole, so that a
    crossing step cannot put one sole on the other."""
    polygons = []
    for name, value in (("first", first), ("second", second)):
        vertices = real_array(name, value, ndim=2)
        if vertices.shape[1] != 2 or vertices.shape[0] < 3:
            raise ShapeError(
                f"{name} has shape {vertices.shape}, expected (n, 2) with n >= 3: a polygon's "
                "vertices in order [m]"
            )
        polygons.append(vertices)
    clearance = real("clearance", clearance, minimum=0.0)
    for vertices in polygons:
        edges = np.roll(vertices, -1, axis=0) - vertices
        for edge in edges:
            length = np.hypot(*edge)
            if length == 0.0:
                continue
            normal = np.array([-edge[1], edge[0]]) / length
            a, b = polygons[0] @ normal, polygons[1] @ normal
            if a.min() - b.max() >= clearance or b.min() - a.max() >= clearance:
                return False
    return True


def edge_signs(px: float, py: float, vertices: list) -> list:
    """The cross product of each edge of a polygon (``vertices``: [x, y] pairs of floats, in
    order) with the point (px, py) [m^2]: >= 0 where the point is on the edge's left, so all
    >= 0 for a point inside a counter-clockwise polygon (:func:`clip_to_polygon`'s test, on
    floats for a controller's tick)."""
    return [
        (bx - ax) * (py - ay) - (by - ay) * (px - ax)
        for (ax, ay), (bx, by) in zip(vertices, vertices[1:] + vertices[:1])
    ]


def clip_to_polygon(point, polygon) -> np.ndarray:
    """The point of the convex ``polygon`` nearest to ``point`` (``point`` itself if inside).

    Parameters
    ----------
    point : array_like, shape (2,)
        [m].
    polygon : array_like, shape (n, 2)
        Vertices of a convex polygon, counter-clockwise (:func:`convex_hull`); one or two
        vertices: a point or a segment.
    """
    x = _plane("point", point)
    vertices = polygon
    if not (
        type(polygon) is np.ndarray
        and polygon.dtype == np.float64
        and polygon.ndim == 2
        and math.isfinite(polygon.sum())  # (a NaN or an infinity makes the sum one)
    ):
        vertices = real_array("polygon", polygon, ndim=2)
    if vertices.shape[1] != 2 or vertices.shape[0] == 0:
        raise ShapeError(
            f"polygon has shape {vertices.shape}, expected (n, 2) with n >= 1: use convex_hull"
        )
    n = len(vertices)
    if n >= 3:
        signs = edge_signs(*x.tolist(), vertices.tolist())
        if min(signs) >= 0.0:
            return x.copy()
        if max(signs) <= 0.0 and min(signs) < 0.0:
            raise InvalidInputError(
                "polygon is clockwise; pass its vertices counter-clockwise (convex_hull)"
            )
    best, best_distance = vertices[0], np.inf
    for k in range(n if n >= 3 else max(n - 1, 1)):
        a, b = vertices[k], vertices[(k + 1) % n]
        edge = b - a
        length2 = float(edge @ edge)
        s = 0.0 if length2 == 0.0 else min(max(float((x - a) @ edge) / length2, 0.0), 1.0)
        candidate = a + s * edge
        distance = float(np.sum((x - candidate) ** 2))
        if distance < best_distance:
            best, best_distance = candidate, distance
    return np.array(best, dtype=float)


def capture_time(dcm, zmp, omega: float, offset, lower, upper, shortest: float, longest: float):
    r"""The longest time to touchdown [s] in ``[shortest, longest]`` whose capture-point
    foothold :math:`f(\tau) = p + (\xi_0 - p)\, e^{\omega \tau} - b` has not run out of the
    reachable box on the side the DCM diverges to (step timing adaptation, after
    [Khadiv2020]_): a DCM pushed far lands the foot sooner, before it has run beyond the
    leg's reach.

    Per axis with :math:`d = \xi_0 - p \ne 0`, :math:`f` stays below ``upper`` (``d > 0``) or
    above ``lower`` (``d < 0``) while :math:`e^{\omega\tau} \le (\text{bound} + b - p) / d`;
    the answer is the smallest such bound, clipped to ``[shortest, longest]`` (``shortest``
    when even that leaves the box: the step goes to the box's edge).

    Parameters
    ----------
    dcm, zmp : array_like, shape (2,)
        :math:`\xi_0` and the stance ZMP :math:`p` held until touchdown [m].
    omega : float
        :math:`\omega` [1/s].
    offset : array_like, shape (2,)
        :math:`b`, the plan's end-of-step DCM minus its foothold [m].
    lower, upper : array_like, shape (2,)
        The reachable box [m].
    shortest, longest : float
        Bounds of the time to touchdown [s], 0 <= ``shortest`` <= ``longest``.
    """
    xi, p, b = _plane("dcm", dcm), _plane("zmp", zmp), _plane("offset", offset)
    lower, upper = _plane("lower", lower), _plane("upper", upper)
    w = _omega(omega)
    shortest = real("shortest", shortest, minimum=0.0)
    longest = real("longest", longest, minimum=shortest, fix="longest >= shortest")
    best = longest
    d = xi - p
    for axis in range(2):
        if d[axis] == 0.0:
            continue
        bound = upper[axis] if d[axis] > 0 else lower[axis]
        room = (bound + b[axis] - p[axis]) * np.sign(d[axis])  # d e^{w tau} may grow this far
        if room < abs(d[axis]):  # out of reach already at tau = 0
            return shortest
        if room >= abs(d[axis]) * np.exp(w * longest):  # not out of reach before longest
            continue
        best = min(best, float(np.log(room / abs(d[axis]))) / w)
    return max(best, shortest)


def transfer_time(
    error, foothold, omega: float, lower, upper, swing: float, shortest: float, longest: float
) -> float:
    r"""The double support [s] before the next step, shortened when that step could not
    catch the DCM in time otherwise (step timing adaptation [Khadiv2020]_ applied to the
    whole step, double support and swing).

    With the ZMP following the plan the DCM error :math:`e = \xi - \xi_r` grows as
    :math:`e\, e^{\omega T}` whatever the plan's ZMP does (:math:`\dot e = \omega e`), so
    the capture-point foothold of the next step, eq. :eq:`capture-step`, lies at
    :math:`f(T) = f_r + e\, e^{\omega T}` if it lands :math:`T` after now. :math:`T^*` is the
    longest :math:`T` in ``[shortest + swing, longest + swing]`` with :math:`f(T)` still in
    the reachable box on the side the error grows to (:func:`capture_time` with
    :math:`\xi_0 = f_r + e`, :math:`p = f_r`, :math:`b = 0`), and the double support takes
    what the planned swing :math:`T_{ss}` leaves of it,

    .. math:: T_{ds}' = \min(\max(T^* - T_{ss},\, T_{ds,\min}),\, T_{ds}),
        :label: transfer-time

    the planned :math:`T_{ds}` when the foothold stays in reach, :math:`T_{ds,\min}` when it
    leaves the box even then (the swing may still be shortened, :func:`capture_time`).

    Parameters
    ----------
    error : array_like, shape (2,)
        :math:`e`, the measured DCM minus the plan's, now [m].
    foothold : array_like, shape (2,)
        :math:`f_r`, the next step's planned foothold [m].
    omega : float
        :math:`\omega` [1/s].
    lower, upper : array_like, shape (2,)
        The box the next step's foot can reach [m].
    swing : float
        :math:`T_{ss}`, the next step's planned swing [s], > 0.
    shortest, longest : float
        :math:`T_{ds,\min}` and the planned :math:`T_{ds}` [s], 0 <= ``shortest`` <=
        ``longest``.
    """
    f = _plane("foothold", foothold)
    swing = real("swing", swing, minimum=0.0, open_minimum=True)
    shortest = real("shortest", shortest, minimum=0.0)
    longest = real("longest", longest, minimum=shortest, fix="longest >= shortest")
    total = capture_time(
        f + _plane("error", error), f, omega, np.zeros(2), lower, upper,
        shortest + swing, longest + swing,
    )  # fmt: skip
    if total <= shortest + swing:  # (not total - swing: its rounding would leave the bounds)
        return shortest
    return longest if total >= longest + swing else total - swing


def capture_foothold(
    dcm, zmp, omega: float, remaining: float, dcm_reference_end, foothold_reference, lower, upper
) -> np.ndarray:
    r"""The capture-point foothold, eq. :eq:`capture-step`, clipped to a reachable box [m].

    Parameters
    ----------
    dcm, zmp : array_like, shape (2,)
        Measured DCM :math:`\xi_0` and the stance foot's ZMP :math:`p` held until touchdown [m].
    omega : float
        :math:`\omega` [1/s].
    remaining : float
        Time to the planned touchdown [s], >= 0.
    dcm_reference_end, foothold_reference : array_like, shape (2,)
        The plan's DCM at touchdown :math:`\xi_r(T)` and its foothold :math:`f_r` [m].
    lower, upper : array_like, shape (2,)
        Corners of the box the swing foot can reach (world frame) [m].

    Returns
    -------
    ndarray, shape (2,)
        :math:`f_r + \xi(T) - \xi_r(T)`, with :math:`\xi(T)` from :func:`predict_dcm`,
        clipped to ``[lower, upper]``.
    """
    lower, upper = _plane("lower", lower), _plane("upper", upper)
    if (lower > upper).any():
        raise InvalidInputError(
            f"lower = {lower} exceeds upper = {upper}; pass the box's low corner first"
        )
    remaining = real("remaining", remaining, minimum=0.0)  # named as the caller passed it
    end = predict_dcm(dcm, zmp, omega, remaining)
    offset = _plane("dcm_reference_end", dcm_reference_end) - _plane(
        "foothold_reference", foothold_reference
    )
    return np.clip(end - offset, lower, upper)


def ground_tilt(normal) -> np.ndarray:
    r"""The rotation (3 x 3) that tilts a level sole onto ground of unit ``normal`` (shape
    (3,), world frame, pointing up): the smallest rotation taking :math:`e_z` to :math:`n`,
    about the horizontal axis :math:`a = e_z \times n / \lVert e_z \times n \rVert` by
    :math:`\theta = \arccos n_z` (Rodrigues: :math:`I + \sin\theta\, [a]_\times +
    (1 - \cos\theta) [a]_\times^2`); it turns nothing about the vertical."""
    n = real_array("normal", normal)
    if n.shape != (3,):
        raise ShapeError(f"normal has shape {n.shape}, expected (3,): a world direction")
    length = np.linalg.norm(n)
    if not length > 0.0 or n[2] <= 0.0:
        raise InvalidInputError(
            f"normal must be a non-zero direction pointing up (z > 0), got {n.tolist()}; pass "
            "the ground's upward normal, e.g. a sole frame's z axis"
        )
    n = n / length
    axis = np.array([-n[1], n[0], 0.0])  # e_z x n
    sine, cosine = np.linalg.norm(axis), n[2]
    if sine < 1e-15:
        return np.eye(3)
    a = axis / sine
    cross = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + sine * cross + (1.0 - cosine) * cross @ cross
