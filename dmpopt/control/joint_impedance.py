r"""Joint-level impedance around the QP's motion: what lets the controller cope with a real plant.

The QP inverse dynamics computes the torques of the rigid-body model; friction, damping and
armature the model lacks act on the joints unseen, and the tasks' low gains (set for smooth
whole-body motion) leave them mostly uncorrected. Real torque-controlled humanoids close a stiff
loop per joint around the motion the whole-body QP intends; :class:`JointImpedance` does the
same. Each tick the QP's joint accelerations :math:`\ddot q^*` are integrated into a desired
joint state, pulled back towards the measured one with time constant :math:`T` so that it never
drifts away:

.. math::

    \dot q_d \leftarrow \dot q_d + \Delta t\,\ddot q^* - \tfrac{\Delta t}{T}(\dot q_d - \dot q),
    \qquad q_d \leftarrow q_d + \Delta t\,\dot q_d - \tfrac{\Delta t}{T}(q_d - q)

(semi-implicit Euler, the velocity first, as the simulators integrate),

and the torque sent to each actuated joint is

.. math::

    \tau = \tau^* + K (q_d - q) + D (\dot q_d - \dot q) + \hat b\,\dot q_d
        + \hat f_c \tanh(\dot q_d / v_s),

clipped to the torque limits: :math:`\tau^*` the QP's torque, then the impedance, then the
nominal viscous and Coulomb friction fed forward (:math:`v_s` = 0.05 rad/s). The gains come from
the joint's inertia and a bandwidth, not from tuning: :math:`K = m\omega^2`,
:math:`D = 2\zeta m\omega`, with :math:`m = 1 / (M^{-1})_{jj}` in the reference posture
(armature included): the inertia the joint drives when the base and every other joint are free,
the lightest it ever sees, so that the loop's bandwidth is at most :math:`\omega` in any
contact state (on the 7 kg planar biped a ninth of :math:`M_{jj}` at the hips). The default
bandwidth is the largest a loop delay of :math:`(d + 1)\,\Delta t` allows with a quarter
radian of phase lost at the crossover, :math:`\omega = 0.25 / ((d + 1)\Delta t)` (125 rad/s at
1 kHz with one tick of delay).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError
from dmpopt.validation import real

__all__ = ["JointImpedance"]

FRICTION_SPEED = 0.05  # [rad/s] v_s: the Coulomb feed-forward's tanh saturates beyond it
PHASE_MARGIN_USED = 0.25  # [rad] phase the loop delay may cost at the bandwidth


class JointImpedance:
    """Stiff joint-level tracking of the QP's intended motion (see the module notes).

    Parameters
    ----------
    robot : RobotModel
        The controller's robot; its model should carry the nominal armature
        (:func:`dmpopt.sim.with_armature`).
    dt : float
        Control period [s].
    delay : int
        Nominal ticks of delay in the loop (sets the default bandwidth).
    bandwidth : float, optional
        :math:`\\omega` [rad/s]; default from ``delay`` and ``dt``; 0 leaves only the
        feed-forward.
    damping_ratio : float
        :math:`\\zeta`.
    time_constant : float
        :math:`T` [s] of the pull of the desired state towards the measured one.
    damping, friction : float or array_like, shape (n_actuated,)
        Nominal viscous damping [N m s/rad] and Coulomb friction [N m] fed forward.
    """

    def __init__(
        self,
        robot,
        dt: float,
        delay: int = 1,
        bandwidth: float | None = None,
        damping_ratio: float = 1.0,
        time_constant: float = 0.5,
        damping=0.0,
        friction=0.0,
    ):
        self.dt = real("dt", dt, minimum=0.0, open_minimum=True, expected="a period [s] > 0")
        if isinstance(delay, bool) or not isinstance(delay, (int, np.integer)) or delay < 0:
            raise InvalidInputError(f"delay must be a whole number of ticks >= 0, got {delay!r}")
        if bandwidth is None:
            bandwidth = PHASE_MARGIN_USED / ((delay + 1) * self.dt)
        self.bandwidth = real(
            "bandwidth", bandwidth, minimum=0.0, expected="[rad/s] >= 0 (0: no feedback)"
        )
        zeta = real("damping_ratio", damping_ratio, minimum=0.0, expected="a number >= 0")
        self.time_constant = real(
            "time_constant", time_constant, minimum=self.dt, expected=f"[s] >= dt = {self.dt}"
        )
        self.n_base = robot.n_base
        n = robot.n_actuated
        self.damping = self._per_joint("damping", damping, n)
        self.friction = self._per_joint("friction", friction, n)
        model = robot.model
        mass = pin.crba(model, model.createData(), robot.reference_configuration)
        mass = np.triu(mass) + np.triu(mass, 1).T
        self.inertia = 1.0 / np.diag(np.linalg.inv(mass))[self.n_base :]
        self.stiffness = self.inertia * self.bandwidth**2
        self.damping_gain = 2.0 * zeta * self.inertia * self.bandwidth
        self.torque_limit = np.asarray(robot.torque_limit, dtype=float)
        self._q_index = np.array(
            [model.joints[model.getJointId(name)].idx_q for name in robot.actuated_joint_names]
        )
        self._q_desired: np.ndarray | None = None
        self._v_desired = np.zeros(n)

    @classmethod
    def for_plant(
        cls, robot, dt: float, plant, feedback: bool = True, feedforward: bool = True, **options
    ) -> JointImpedance:
        """The joint loop for a plant believed to be ``plant`` (a
        :class:`dmpopt.sim.PlantParameters`): its delay sets the bandwidth, its damping and
        friction are fed forward. ``robot`` should carry its armature
        (:func:`dmpopt.sim.with_armature`). ``feedback=False`` leaves only the feed-forward
        (bandwidth 0), ``feedforward=False`` only the impedance."""
        names = robot.actuated_joint_names
        if not feedback:
            options["bandwidth"] = 0.0
        return cls(
            robot,
            dt,
            delay=plant.delay,
            damping=plant.values("damping", names) if feedforward else 0.0,
            friction=plant.values("friction", names) if feedforward else 0.0,
            **options,
        )

    @staticmethod
    def _per_joint(name: str, value, n: int) -> np.ndarray:
        array = np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()
        if not np.isfinite(array).all() or (array < 0).any():
            raise InvalidInputError(f"{name} must be finite numbers >= 0, one per actuated joint")
        return array

    def reset(self) -> None:
        """Forget the desired state: the next tick starts it at the measured one."""
        self._q_desired = None

    def torques(self, q, v, accelerations: np.ndarray, torques: np.ndarray) -> np.ndarray:
        """The torque to send: the QP's ``torques`` plus the joint loop (see the module notes).

        Parameters
        ----------
        q, v : ndarray, shape (nq,) and (nv,)
            The measured state.
        accelerations : ndarray, shape (nv,)
            The QP's accelerations for this tick.
        torques : ndarray, shape (n_actuated,)
            The QP's torques for this tick.
        """
        joints, speeds = q[self._q_index], v[self.n_base :]
        if self._q_desired is None:
            self._q_desired, self._v_desired = joints.copy(), speeds.copy()
        feedback = self.stiffness * (self._q_desired - joints) + self.damping_gain * (
            self._v_desired - speeds
        )
        feedforward = self.damping * self._v_desired + self.friction * np.tanh(
            self._v_desired / FRICTION_SPEED
        )
        dt, pull = self.dt, self.dt / self.time_constant  # the desired state of the next tick
        self._v_desired += dt * accelerations[self.n_base :] - pull * (self._v_desired - speeds)
        self._q_desired += dt * self._v_desired - pull * (self._q_desired - joints)
        return np.clip(torques + feedback + feedforward, -self.torque_limit, self.torque_limit)
