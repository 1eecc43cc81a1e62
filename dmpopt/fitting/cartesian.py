"""Fitting a Cartesian DMP (:class:`dmpopt.cartesian.CartesianDMP`) to a pose demonstration."""

from __future__ import annotations

import numpy as np

from ..cartesian import CartesianDMP, continuous, orientation_log, unit_quaternions
from ..exceptions import InvalidInputError
from ..trajectory import Trajectory, check_times
from ..validation import real_array
from .imitation import fit_discrete


def _path_log(orientations: np.ndarray) -> np.ndarray:
    r"""Rotation vectors :math:`e_k = 2 \log(q_k \otimes \bar q_T)` of continuous
    orientations, unwrapped along the path from the last sample back, shape (n, 3).

    The logarithm gives angles in :math:`[0, 2\pi)`; a path that turns further wraps round.
    Each :math:`e_k` is one of :math:`e + 2 \pi m\, e / |e|` (:math:`m` integer, the same
    rotation): the one nearest :math:`e_{k+1}`, so that :math:`|e_k|` is the angle turned
    along the path (a demonstration turning 361 degrees about one axis gives 361, not 359).
    Each sample's logarithm is taken on its own side, so no sample is at the antipode.
    """
    goal = orientations[-1]
    relative_w = orientations @ goal
    near = np.where(relative_w[:, None] < 0.0, -orientations, orientations)
    log = orientation_log(near, goal)
    log[-1] = 0.0  # exactly the goal
    for k in range(len(log) - 2, -1, -1):
        norm = np.linalg.norm(log[k])
        if norm > 0.0:
            axis = log[k] / norm
            turns = np.round((log[k + 1] @ axis - norm) / (2 * np.pi))
            log[k] = log[k] + 2 * np.pi * turns * axis
    return log


def fit_cartesian(
    times,
    positions,
    orientations,
    n_basis: int = 30,
    *,
    form: str = "velocity",
    method: str = "position",
    goal_scaling: str = "auto",
    regularization: float = 1e-9,
    alpha_z: float = 25.0,
    alpha_v: float = 25.0,
) -> CartesianDMP:
    """Fit a Cartesian DMP to a pose demonstration.

    Both parts are fitted by :func:`dmpopt.fit_discrete` with the same ``tau`` and basis:
    the positions as they are, the orientations as their logarithm about the last one,
    :math:`e = 2\\log(q \\otimes \\bar q_T)` (module docstring). Velocities come from
    second-order differences of the samples.

    Parameters
    ----------
    times : array_like, shape (n_steps,)
        Strictly increasing sample times [s].
    positions : array_like, shape (n_steps, 3)
        Positions [m].
    orientations : array_like, shape (n_steps, 4)
        Unit quaternions ``(w, x, y, z)``, in any sign (made continuous here); the last is
        the goal, and every sample must be at most a half turn from it, counted along the
        path (a demonstration that turns 540 degrees is refused, though its first and last
        samples are 180 degrees apart).
    n_basis, form, method, goal_scaling, regularization, alpha_z, alpha_v
        As in :func:`dmpopt.fit_discrete`; ``goal_scaling`` applies to each part.
    """
    times = check_times(times)
    n = times.size
    positions = real_array("positions", positions, shape=(n, 3), expected=f"{n} 3-D positions")
    orientations = continuous(unit_quaternions("orientations", orientations, (n, 4)))
    log = _path_log(orientations)
    angles = np.linalg.norm(log, axis=1)
    k = int(np.argmax(angles))
    if angles[k] > np.pi * (1.0 + 1e-12):
        where = "the first sample" if k == 0 else f"orientations[{k}]"
        raise InvalidInputError(
            f"orientations turn by {np.degrees(angles[k]):.1f} degrees along the path from "
            f"{where} to the last (the goal), more than a half turn: a Cartesian DMP turns to "
            "its goal the short way (at most 180 degrees from every sample); split the "
            "demonstration"
        )
    options = {"n_basis": n_basis, "form": form, "method": method}
    options |= {"goal_scaling": goal_scaling, "regularization": regularization}
    options |= {"alpha_z": alpha_z, "alpha_v": alpha_v}
    position = fit_discrete(Trajectory.from_positions(times, positions), **options)
    rotation = fit_discrete(Trajectory.from_positions(times, log), **options)
    return CartesianDMP(
        position_weights=position.weights,
        orientation_weights=rotation.weights,
        start=position.start,
        goal=position.goal,
        start_orientation=orientations[0],
        goal_orientation=orientations[-1],
        tau=position.tau,
        centres=position.centres,
        widths=position.widths,
        form=form,
        position_scaling=position.goal_scaling,
        orientation_scaling=rotation.goal_scaling,
        position_reference=position.reference_displacement,
        orientation_reference=rotation.reference_displacement,
        scaled_start_velocity=position.scaled_start_velocity,
        scaled_start_log_rate=rotation.scaled_start_velocity,
        alpha_z=alpha_z,
        alpha_v=alpha_v,
    )
