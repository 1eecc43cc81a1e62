r"""Obstacles and the coupling terms that steer a DMP around them online.

Both published forms are terms :math:`C_t` added to the transformation system,
:math:`\tau\dot z = \alpha_z(\beta_z(g - y) - z) + f + C_t` (eqs. (5), (10)); pass them as the
``coupling`` of :meth:`dmpopt.Stepper.step` or :meth:`dmpopt.CartesianStepper.step`, computed
from the stepper's current position :math:`y` and velocity :math:`\dot y` (:func:`run_coupled`
does the loop). Positions in any unit; the terms are in that unit (as :math:`\tau \dot z`).

* :class:`SteeringAngle` ([Hoffmann2009]_): :math:`C_t = \gamma R \dot y\, \varphi
  \exp(-\beta\varphi)` with :math:`\varphi` the angle between the velocity and the direction
  to the obstacle and :math:`R` the rotation by :math:`\pi/2` about :math:`(o - y) \times
  \dot y`: the velocity is turned away from the obstacle, the more the more directly it
  heads at it.
* :class:`PotentialField` ([Park2008]_): :math:`C_t = -\nabla_y U` with the
  dynamic potential :math:`U = \lambda (-\cos\theta)^\beta \|\dot y\| / p(y)` while
  approaching (:math:`\theta > \pi/2`, the angle between the velocity and :math:`y - o`) and
  0 otherwise, :math:`p(y)` the distance to the obstacle's surface.

The optimisation alternative, a constrained fit that keeps every sample of the plan out of
:class:`Sphere` and :class:`Box` regions, is :func:`dmpopt.fitting.keep_out.fit_keep_out`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .exceptions import InvalidInputError, ShapeError
from .trajectory import Trajectory
from .validation import integer, real, real_array, sequence_of


@dataclass(frozen=True, eq=False)
class Sphere:
    """A ball (a disc in 2-D) at ``centre`` of ``radius`` [unit of the positions]."""

    centre: np.ndarray
    radius: float = 0.0

    def __post_init__(self):
        centre = real_array("centre", np.atleast_1d(self.centre), ndim=1)
        centre.setflags(write=False)
        object.__setattr__(self, "centre", centre)
        object.__setattr__(self, "radius", real("radius", self.radius, minimum=0.0))

    def distance(self, positions) -> np.ndarray:
        """Signed distance of each position (rows) to the surface (negative inside)."""
        return np.linalg.norm(np.atleast_2d(positions) - self.centre, axis=1) - self.radius


@dataclass(frozen=True, eq=False)
class Box:
    """An axis-aligned box at ``centre`` with ``half_widths`` per axis [unit]."""

    centre: np.ndarray
    half_widths: np.ndarray

    def __post_init__(self):
        centre = real_array("centre", np.atleast_1d(self.centre), ndim=1)
        half = np.atleast_1d(real_array("half_widths", self.half_widths))
        if half.shape == (1,):
            half = np.full(centre.shape, half[0])
        if half.shape != centre.shape or np.any(half <= 0.0):
            raise InvalidInputError(
                f"half_widths must be positive, one per axis of centre {centre.shape}, got "
                f"{half.tolist()}"
            )
        for name, value in (("centre", centre), ("half_widths", half)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def distance(self, positions) -> np.ndarray:
        """Signed distance of each position (rows) to the surface (negative inside)."""
        offset = np.abs(np.atleast_2d(positions) - self.centre) - self.half_widths
        outside = np.linalg.norm(np.maximum(offset, 0.0), axis=1)
        return outside + np.minimum(offset.max(axis=1), 0.0)


def clearance(positions, obstacles) -> np.ndarray:
    """Signed distance of each position (rows) to the nearest obstacle (negative inside)."""
    obstacles = _obstacles(obstacles, np.atleast_2d(positions).shape[1])
    return np.min([obstacle.distance(positions) for obstacle in obstacles], axis=0)


def _obstacles(obstacles, n_dims: int) -> tuple:
    if isinstance(obstacles, (Sphere, Box)):
        obstacles = (obstacles,)
    obstacles = sequence_of("obstacles", obstacles, (Sphere, Box))
    if not obstacles:
        raise InvalidInputError("obstacles is empty; give at least one Sphere or Box")
    for k, obstacle in enumerate(obstacles):
        if obstacle.centre.shape != (n_dims,):
            raise ShapeError(
                f"obstacles[{k}] has a centre of shape {obstacle.centre.shape}, expected "
                f"({n_dims},) to match the positions"
            )
    return obstacles


def _state(obstacles, position, velocity) -> tuple:
    """``position`` and ``velocity`` checked against the obstacles' dimension, and the speed."""
    n_dims = obstacles[0].centre.size
    position = real_array("position", np.atleast_1d(position), shape=(n_dims,))
    velocity = real_array("velocity", np.atleast_1d(velocity), shape=(n_dims,))
    return position, velocity, float(np.linalg.norm(velocity))


def _spheres(obstacles, kind: str) -> tuple:
    """The obstacles as spheres: a coupling term steers around centres and radii."""
    spheres = tuple(obstacles)
    if any(not isinstance(obstacle, Sphere) for obstacle in spheres):
        raise InvalidInputError(
            f"{kind} takes Sphere obstacles (a point is a Sphere of radius 0); for a Box, "
            "use the constrained fit dmpopt.fitting.keep_out.fit_keep_out"
        )
    if len({sphere.centre.size for sphere in spheres}) > 1:
        raise ShapeError("obstacles have centres of different sizes; give one size")
    if spheres and spheres[0].centre.size not in (2, 3):
        raise ShapeError(
            f"obstacle centres have {spheres[0].centre.size} entries; coupling terms steer in "
            "2-D or 3-D positions"
        )
    return spheres


@dataclass(frozen=True, eq=False)
class SteeringAngle:
    r"""Steering-angle coupling term of [Hoffmann2009]_, summed over obstacles.

    .. math:: C_t = \gamma\, R\,\dot y\; \varphi \exp(-\beta\varphi), \qquad
              \varphi = \arccos\frac{(o - y)^T \dot y}{\|o - y\|\,\|\dot y\|}

    :math:`R \dot y = \hat r \times \dot y` is :math:`\dot y` turned by :math:`\pi/2` about
    :math:`\hat r \propto (o - y) \times \dot y` (2-D positions are turned in their plane).
    Only the direction to each centre counts, not the radius.

    Attributes
    ----------
    obstacles : Sphere or sequence of Sphere
    gamma : float
        :math:`\gamma` [s] (:math:`C_t` in the unit of the positions), the strength
        (Hoffmann: 1000).
    beta : float
        :math:`\beta` [1/rad], how fast the term fades with the angle (Hoffmann: 20/pi).
    """

    obstacles: tuple
    gamma: float = 1000.0
    beta: float = 20.0 / np.pi

    def __post_init__(self):
        obstacles = self.obstacles
        obstacles = (obstacles,) if isinstance(obstacles, (Sphere, Box)) else obstacles
        object.__setattr__(self, "obstacles", _spheres(obstacles, "SteeringAngle"))
        object.__setattr__(self, "gamma", real("gamma", self.gamma, minimum=0.0))
        object.__setattr__(self, "beta", real("beta", self.beta, minimum=0.0))

    def __call__(self, position, velocity) -> np.ndarray:
        """The coupling term at ``position`` moving at ``velocity``, shape (n_dims,)."""
        position, velocity, speed = _state(self.obstacles, position, velocity)
        term = np.zeros(position.size)
        if speed == 0.0:
            return term
        for obstacle in self.obstacles:
            towards = obstacle.centre - position
            distance = np.linalg.norm(towards)
            if distance == 0.0:
                continue
            cosine = np.clip(towards @ velocity / (distance * speed), -1.0, 1.0)
            angle = np.arccos(cosine)
            # r x v with r along (o - y) x v, v perpendicular to r: rotation of v by pi/2
            side = towards - cosine * distance * velocity / speed  # part of o - y normal to v
            norm = np.linalg.norm(side)
            if norm == 0.0:  # heading straight at or away from the centre: no side chosen
                continue
            turned = -speed * side / norm
            term += self.gamma * turned * angle * np.exp(-self.beta * angle)
        return term


@dataclass(frozen=True, eq=False)
class PotentialField:
    r"""Dynamic potential field of [Park2008]_, summed over obstacles.

    With :math:`x = y - o`, :math:`\cos\theta = \dot y^T x / (\|\dot y\|\|x\|)` and
    :math:`p = \|x\| - \rho` the distance to the sphere of radius :math:`\rho`,

    .. math:: U = \lambda (-\cos\theta)^\beta \frac{\|\dot y\|}{p}
              \ (\theta > \pi/2), \qquad C_t = -\nabla_y U
              = \lambda (-\cos\theta)^{\beta - 1} \frac{\|\dot y\|}{p}
              \Big(\beta \nabla\cos\theta - \frac{\cos\theta}{p} \hat x\Big),

    :math:`\nabla\cos\theta = (\dot y / \|\dot y\| - \cos\theta\, \hat x) / \|x\|`; zero while
    moving away (:math:`\theta \le \pi/2`).

    Attributes
    ----------
    obstacles : Sphere or sequence of Sphere
    strength : float
        :math:`\lambda` [unit^2 s] (:math:`C_t` in the unit of the positions); Park: 1.
    exponent : float
        :math:`\beta` (Park: 2).
    """

    obstacles: tuple
    strength: float = 1.0
    exponent: float = 2.0

    def __post_init__(self):
        obstacles = self.obstacles
        obstacles = (obstacles,) if isinstance(obstacles, (Sphere, Box)) else obstacles
        object.__setattr__(self, "obstacles", _spheres(obstacles, "PotentialField"))
        object.__setattr__(self, "strength", real("strength", self.strength, minimum=0.0))
        object.__setattr__(self, "exponent", real("exponent", self.exponent, minimum=1.0))

    def potential(self, position, velocity) -> float:
        """:math:`U` summed over the obstacles (``inf`` inside one)."""
        position, velocity, speed = _state(self.obstacles, position, velocity)
        total = 0.0
        for obstacle in self.obstacles:
            x = position - obstacle.centre
            distance = np.linalg.norm(x)
            p = distance - obstacle.radius
            if p <= 0.0:
                return np.inf
            cosine = x @ velocity / (distance * speed) if speed > 0.0 else 0.0
            if cosine < 0.0:
                total += self.strength * (-cosine) ** self.exponent * speed / p
        return float(total)

    def __call__(self, position, velocity) -> np.ndarray:
        """The coupling term :math:`-\\nabla_y U` at ``position`` and ``velocity``."""
        position, velocity, speed = _state(self.obstacles, position, velocity)
        term = np.zeros(position.size)
        if speed == 0.0:
            return term
        for obstacle in self.obstacles:
            x = position - obstacle.centre
            distance = np.linalg.norm(x)
            p = distance - obstacle.radius
            if p <= 0.0 or distance == 0.0:  # inside: no gradient defined; leave it
                continue
            unit = x / distance
            cosine = unit @ velocity / speed
            if cosine >= 0.0:
                continue
            gradient_cosine = (velocity / speed - cosine * unit) / distance
            scale = self.strength * (-cosine) ** (self.exponent - 1.0) * speed / p
            term += scale * (self.exponent * gradient_cosine - cosine / p * unit)
        return term


def run_coupled(stepper, coupling, n_steps: int) -> Trajectory:
    """Step ``stepper`` ``n_steps`` times with ``coupling(position, velocity)`` as its
    coupling term; return the positions (first DOFs for a Cartesian stepper) as a
    :class:`~dmpopt.Trajectory` starting at the stepper's current state."""
    n_steps = integer("n_steps", n_steps, minimum=2)
    if not callable(coupling):
        raise InvalidInputError(
            f"coupling must be callable as coupling(position, velocity), got "
            f"{type(coupling).__name__}"
        )
    positions = [stepper.position.copy()]
    start = stepper.time
    for _ in range(n_steps):
        stepper.step(coupling=coupling(stepper.position, stepper.velocity))
        positions.append(stepper.position.copy())
    times = start + stepper.dt * np.arange(n_steps + 1)
    return Trajectory.from_positions(times, np.array(positions))
