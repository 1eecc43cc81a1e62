r"""Computed-torque control, the classic joint-space baseline for fixed-base robots.

.. math:: u = M(q)\, \ddot q_d + h(q, \dot q) + K_p (q_d - q) + K_d (\dot q_d - \dot q)

with :math:`M \ddot q_d + h` evaluated in one recursive Newton-Euler pass (``pinocchio.rnea``).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError, ShapeError

__all__ = ["ComputedTorqueController"]


class ComputedTorqueController:
    """Feed-forward inverse dynamics of the reference plus joint PD feedback.

    Parameters
    ----------
    robot : RobotModel
        A fixed-base robot (``robot.floating_base`` must be False: an unactuated base cannot
        follow a joint-space law).
    stiffness : float or ndarray, shape (nv,)
        :math:`K_p` [N m/rad].
    damping : float or ndarray, shape (nv,)
        :math:`K_d` [N m s/rad].
    clip_to_limits : bool
        Clip the torques to ``robot.torque_limit``.

    Notes
    -----
    Gains must be finite and >= 0 (checked here). At run time a non-finite state or reference
    (NaN, inf) raises :class:`~dmpopt.exceptions.InvalidInputError` naming the argument,
    as :class:`~dmpopt.control.InverseDynamicsController` does for its state: there is no
    torque to return that would be right, and a NaN torque would reach the motors.
    """

    def __init__(self, robot, stiffness=100.0, damping=20.0, clip_to_limits: bool = True):
        if robot.floating_base:
            raise InvalidInputError(
                f"robot {robot.name!r} has a floating base; computed torque needs a fixed base "
                "(load_talos(fixed_base=True)) or use InverseDynamicsController"
            )
        self.robot = robot
        self.model = robot.model
        self.data = robot.create_data()
        self.stiffness = _gain(stiffness, robot.nv, "stiffness")
        self.damping = _gain(damping, robot.nv, "damping")
        self.clip_to_limits = bool(clip_to_limits)

    def compute_torques(
        self, q, v, reference_position, reference_velocity=None, reference_acceleration=None
    ) -> np.ndarray:
        r"""Torques for the state ``(q, v)`` tracking a joint reference.

        Parameters
        ----------
        q, v : ndarray, shape (nq,), (nv,)
            Joint positions [rad] and velocities [rad/s].
        reference_position : ndarray, shape (nq,)
            :math:`q_d`.
        reference_velocity, reference_acceleration : ndarray, shape (nv,), optional
            :math:`\dot q_d, \ddot q_d`; zero if omitted.

        Returns
        -------
        ndarray, shape (nv,)
        """
        nq, nv = self.model.nq, self.model.nv
        zeros = np.zeros(nv)
        arrays = {
            "q": (q, nq),
            "v": (v, nv),
            "reference_position": (reference_position, nq),
            "reference_velocity": (zeros if reference_velocity is None else reference_velocity, nv),
            "reference_acceleration": (
                zeros if reference_acceleration is None else reference_acceleration,
                nv,
            ),
        }
        values = {}
        for name, (value, size) in arrays.items():
            value = _numbers(value, name)
            if value.shape != (size,):
                raise ShapeError(f"{name} has shape {value.shape}, expected ({size},)")
            if not np.isfinite(value).all():
                raise InvalidInputError(
                    f"{name} must be finite; it holds NaN or inf at indices "
                    f"{np.flatnonzero(~np.isfinite(value)).tolist()}"
                )
            values[name] = value
        tau = pin.rnea(
            self.model, self.data, values["q"], values["v"], values["reference_acceleration"]
        )
        tau += self.stiffness * pin.difference(
            self.model, values["q"], values["reference_position"]
        )
        tau += self.damping * (values["reference_velocity"] - values["v"])
        if not np.isfinite(tau).all():
            raise InvalidInputError(
                "the torques overflow (not finite) for these inputs; check the magnitudes of "
                "q, v, the reference and the gains"
            )
        if self.clip_to_limits:
            np.clip(tau, -self.robot.torque_limit, self.robot.torque_limit, out=tau)
        return tau


def _numbers(value, name: str) -> np.ndarray:
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name} must be numbers, got {value!r}") from None


def _gain(value, size: int, name: str) -> np.ndarray:
    """A scalar broadcast to (size,), or a vector of that size; finite and >= 0."""
    array = _numbers(value, name)
    if array.shape not in ((), (size,)):
        raise ShapeError(f"{name} has shape {array.shape}, expected () or ({size},)")
    if not (np.isfinite(array).all() and (array >= 0).all()):
        raise InvalidInputError(f"{name} must be finite and >= 0, got {value!r}")
    return np.broadcast_to(array, (size,)).copy()
