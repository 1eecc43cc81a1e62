r"""Compliant ground contact: spring-damper normal force and Coulomb friction with stick and slip.

The ground is a plane :math:`n^\top p = h`. For each contact point at position :math:`p` with
velocity :math:`\dot p`, the penetration is :math:`d = h - n^\top p` and

.. math::

    F_n = \max(0,\; k\, d - c\, n^\top \dot p)  \quad (d > 0), \qquad F_n = 0 \quad (d \le 0),

so the ground pushes and never pulls. Friction uses a tangential spring-damper anchored where
the point touched down (a "bristle"):

.. math::

    F_t^{\mathrm{trial}} = -k_t\, (p_t - a_t) - c_t\, \dot p_t .

If :math:`\|F_t^{\mathrm{trial}}\| \le \mu F_n` the point sticks; otherwise it slips, the force
is clipped to the Coulomb cone, :math:`F_t = \mu F_n\, F_t^{\mathrm{trial}} /
\|F_t^{\mathrm{trial}}\|`, and the anchor slides so that the spring alone carries the clipped
force, :math:`a_t = p_t + F_t / k_t`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dmpopt.exceptions import InvalidInputError
from dmpopt.validation import real, real_array

__all__ = ["GroundContact", "ground_forces"]


@dataclass(frozen=True, eq=False)
class GroundContact:
    """Parameters of a flat, compliant ground plane with Coulomb friction.

    Parameters
    ----------
    stiffness : float
        Normal spring stiffness per contact point [N/m].
    damping : float
        Normal damping per contact point [N s/m].
    friction : float
        Coulomb friction coefficient ``mu`` (static = kinetic) [-].
    tangential_stiffness : float, optional
        Stiffness of the friction anchor spring [N/m]; defaults to ``stiffness``.
    tangential_damping : float, optional
        Damping of the friction anchor [N s/m]; defaults to ``damping``.
    height : float
        Offset ``h`` of the plane along its normal [m] (``n^T p = h`` on the surface).
    normal : array_like, shape (3,)
        Upward normal of the plane in the world frame; normalised on construction. Tilt it to
        make a slope.

    Attributes
    ----------
    frame : ndarray, shape (3, 3)
        Rows: two tangents and the normal of the plane (world frame).
    """

    stiffness: float
    damping: float
    friction: float
    tangential_stiffness: float | None = None
    tangential_damping: float | None = None
    height: float = 0.0
    normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def __post_init__(self):
        for name, default in (
            ("tangential_stiffness", "stiffness"),
            ("tangential_damping", "damping"),
        ):
            if getattr(self, name) is None:
                object.__setattr__(self, name, getattr(self, default))
        for name in ("stiffness", "tangential_stiffness"):
            value = real(
                name,
                getattr(self, name),
                minimum=0.0,
                open_minimum=True,
                expected="a finite stiffness > 0 [N/m]",
            )
            object.__setattr__(self, name, value)
        for name in ("damping", "tangential_damping", "friction"):
            value = real(name, getattr(self, name), minimum=0.0)
            object.__setattr__(self, name, value)
        object.__setattr__(
            self, "height", real("height", self.height, expected="a finite height [m]")
        )
        normal = real_array(
            "normal",
            self.normal,
            shape=(3,),
            expected="the upward normal of the ground plane",
        )
        if not normal[2] > 0:
            raise InvalidInputError(
                f"normal must point up (positive z, the world's up axis), got {self.normal!r}; "
                "e.g. (0, 0, 1) for flat ground"
            )
        normal = normal / np.linalg.norm(normal)
        helper = np.eye(3)[np.argmin(np.abs(normal))]
        tangent_1 = np.cross(helper, normal)
        tangent_1 /= np.linalg.norm(tangent_1)
        frame = np.array([tangent_1, np.cross(normal, tangent_1), normal])
        for array in (normal, frame):
            array.setflags(write=False)
        object.__setattr__(self, "normal", normal)
        object.__setattr__(self, "frame", frame)

    def penetration(self, positions: np.ndarray) -> np.ndarray:
        """Depth below the plane of each point [m] (positive when penetrating).

        Parameters
        ----------
        positions : ndarray, shape (n_points, 3)
        """
        return self.height - positions @ self.normal


def ground_forces(
    ground: GroundContact,
    positions: np.ndarray,
    velocities: np.ndarray,
    anchors: np.ndarray,
    in_contact: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contact forces of all points at once, vectorised over points.

    Parameters
    ----------
    ground : GroundContact
    positions, velocities : ndarray, shape (n_points, 3)
        World positions [m] and velocities [m/s] of the contact points.
    anchors : ndarray, shape (n_points, 2)
        Friction anchors from the previous step, tangential coordinates in the ground frame
        (:attr:`GroundContact.frame`); rows without ``in_contact`` are ignored.
    in_contact : ndarray of bool, shape (n_points,)
        Contact flags from the previous step (a new contact gets a fresh anchor).

    Returns
    -------
    forces : ndarray, shape (n_points, 3)
        World-frame force on each point [N].
    anchors : ndarray, shape (n_points, 2)
        Updated anchors (slid for slipping points).
    touching : ndarray of bool, shape (n_points,)
        Which points penetrate the ground now.
    """
    frame = ground.frame
    local_position = positions @ frame.T  # columns: tangent 1, tangent 2, normal
    depth = ground.height - local_position[:, 2]
    touching = depth > 0.0
    if not touching.any():  # all in the air: nothing to compute
        return np.zeros_like(positions), anchors, touching
    local_velocity = velocities @ frame.T
    normal_force = np.maximum(0.0, ground.stiffness * depth - ground.damping * local_velocity[:, 2])
    normal_force *= touching
    tangent_position = local_position[:, :2]
    fresh = touching & ~in_contact
    if fresh.any():
        anchors = np.where(fresh[:, None], tangent_position, anchors)
    trial = ground.tangential_stiffness * (anchors - tangent_position)
    trial -= ground.tangential_damping * local_velocity[:, :2]
    trial_norm = np.hypot(trial[:, 0], trial[:, 1])
    limit = ground.friction * normal_force
    slipping = trial_norm > limit
    local_force = np.empty_like(positions)
    local_force[:, 2] = normal_force
    if slipping.any():
        scale = np.where(slipping, limit / np.maximum(trial_norm, 1e-300), 1.0) * touching
        local_force[:, :2] = trial * scale[:, None]
        anchors = np.where(
            slipping[:, None],
            tangent_position + local_force[:, :2] / ground.tangential_stiffness,
            anchors,
        )
    else:
        local_force[:, :2] = trial * touching[:, None]
    return local_force @ frame, anchors, touching
