r"""Dynamics-feasible DMPs: weights fit under a robot's torque limits and balance (SQP).

For a fixed start, goal and duration the plan is affine in the forcing weights
(:class:`dmpopt.dmp.AffinePlan`); the torques of inverse dynamics,
:math:`\tau = M(q)\ddot q + h(q, \dot q)` (RNEA), are not. The fit keeps the objective and the
kinematic requests of :func:`dmpopt.fitting.constrained.build_fitting_problem` (a
:class:`~dmpopt.fitting.problem.FittingProblem` in the scaled weights :math:`x`) and adds the
requests :class:`~dmpopt.fitting.requests.TorqueLimits` and
:class:`~dmpopt.fitting.requests.Balance` as rows :math:`c(x) \le 0` at every sample.

Model. The DMP drives ``joints`` of ``robot``; every other joint stays at ``posture`` with zero
velocity and acceleration, and the base is still (a standing robot: the feet hold it). The
Pinocchio model is reduced to the driven joints, the torque-limited joints and, for
:class:`Balance`, the free-flyer root (``pinocchio.buildReducedModel`` locks the others at
``posture``, keeping their mass). RNEA of that model gives the limited joints' torques and, in
the root's rows, the wrench :math:`W = (f, n)` the ground must apply to the whole robot: with
the base still, the sum of the contact wrenches (Newton-Euler of the whole robot).

Balance, on the ground plane :math:`z = h` of the (flat) soles, world frame, moments about the
origin: the centre of pressure is :math:`p = ((h f_x - n_y) / f_z, (h f_y + n_x) / f_z)`. With
the support polygon's edges :math:`a_e^T p \le b_e` (convex hull of the soles' corners,
:math:`\|a_e\| = 1`) and :math:`f_z > 0`, a CoP at least ``cop_margin`` :math:`m` inside is

.. math:: a_{e,x} (h f_x - n_y) + a_{e,y} (h f_y + n_x) - (b_e - m) f_z \le 0,

and the net horizontal force within the pyramid inscribed in the friction cone is
:math:`|f_x|, |f_y| \le \mu f_z / \sqrt 2`: rows linear in :math:`W`. These are conditions on
the net wrench (the zero-moment-point conditions): necessary for contact forces inside each
sole's cone, not the distribution between the feet.

Rows, normalised so that one unit means as much in each: torque :math:`\pm\tau_j / \bar\tau_j -
1`; CoP rows divided by :math:`m g` :data:`BALANCE_LENGTH` (a CoP 1 cm outside counts as a
torque 10 % over its limit); friction rows by :math:`m g`.

Sequential QP (an :math:`\ell_\infty`-penalty variant of the trust-region S\ :math:`\ell_1`\ QP
method of [Fletcher1987]_). At the iterate :math:`x`,
the rows are linearised by the chain rule through Pinocchio's analytical derivatives
(``computeRNEADerivatives``):

.. math:: \frac{\partial y_i}{\partial x} = \frac{\partial \tau}{\partial q} G_{0,i}
          + \frac{\partial \tau}{\partial \dot q} G_{1,i}
          + \frac{\partial \tau}{\partial \ddot q} G_{2,i}

(:math:`G_{k,i}` the plan's response to the weights at sample :math:`i`), and the QP in the
step :math:`\delta` and one elastic variable :math:`t \ge 0`,

.. math:: \min_{\delta, t}\; q(\delta) + \rho t \quad\text{s.t.}\quad
          c(x) + \nabla c(x)\,\delta \le t - \text{margin},\quad
          l \le A (x + \delta) \le u,\quad \|\delta\|_\infty \le \Delta,

(:math:`q` the exact quadratic objective, :math:`A` the kinematic rows) is solved by
:func:`dmpopt.fitting.qp.solve_qp`. The step is accepted on the exact torques: the merit
:math:`\phi = f + \rho \max(0, \max c + \text{margin} / 2)` must fall by at least a tenth of
the QP's prediction (half the margin absorbs the curvature of rows held at the margin);
:math:`\Delta` doubles after good steps on the boundary and shrinks by 4 after rejections.
:math:`\rho` grows by 10 if the iterations stall at a violation. The QP's rows are generated
lazily (:func:`dmpopt.fitting.qp.solve_qp`), warm-started by the last working set.

Samples. The rows hold at ``n_samples`` samples (default :data:`DEFAULT_SAMPLES`): the DMP is
integrated by RK4, so its plan on that grid equals the 1 kHz plan the controller steps to about
1e-7 of the motion, and the rows' cost grows with the samples.

Certificate. The final plan is checked by exact inverse dynamics on the sample grid and on a
rollout of the same DMP every ``check_step`` (between the samples). If the finer grid
exceeds a limit, the margin grows by 1.5 times the excess and the iterations go on, at most
:data:`MAX_TIGHTENINGS` times.

Infeasible requests raise :class:`~dmpopt.exceptions.InfeasibleProblem` naming the worst
joint (or the CoP, or friction) and the smallest violation found; ``error.stats["fit"]`` is
that least-violating fit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import NamedTuple, Sequence

import numpy as np

from ..exceptions import InfeasibleProblem, InvalidInputError, ShapeError
from ..trajectory import Trajectory
from ..validation import integer, real, real_array
from .constrained import build_fitting_problem, solve_fitting_problem
from .problem import FittingProblem
from .qp import INFINITY, check_solver, solve_qp
from .requests import Balance, TorqueLimits

BALANCE_LENGTH = 0.1
"""[m] A CoP this far outside its polygon counts as one unit of violation."""
MAX_TIGHTENINGS = 3
"""Rounds of margin growth when the finer grid of the certificate exceeds a limit."""
ACCEPT_RATIO = 0.1
ELASTIC_CURVATURE = 1e-6
"""Curvature of the elastic variable ``t`` in the QP (keeps it strictly convex for DAQP)."""
PENALTY = 1e3
r"""Initial :math:`\rho`; it grows by 10 when the iterations stall at a violation."""
MAX_PENALTY = 1e5
DEFAULT_SAMPLES = 200
"""Samples of the plan at which the rows hold, unless ``n_samples`` says otherwise."""
STEP_TOLERANCE = 1e-6
PREDICTION_TOLERANCE = 1e-6
"""Stop when the QP predicts a merit decrease below this fraction of the merit."""
RESTART_RADIUS = 0.1
FEASIBILITY_TOLERANCE = 1e-6
"""A row within this (normalised) of its tightened bound counts as held by the iterations."""
FLAT_TOLERANCE = 1e-3  # [m] sole corners farther from a common height are not a flat stance


@dataclass(frozen=True, eq=False)
class RobotDynamics:
    """The reduced model of a dynamics-feasible fit and the rows read from its RNEA.

    Attributes
    ----------
    model : pinocchio.Model
        The robot reduced to the driven joints, the limited joints and (balance) the root.
    posture : ndarray, shape (model.nq,)
        Its configuration with the driven joints anywhere.
    driven_q, driven_v : ndarray of int, shape (n_dofs,)
        The DMP's DOFs in the reduced configuration and velocity vectors.
    limited_names : tuple of str
    limited_v : ndarray of int
        Velocity indices of the torque-limited joints.
    torque_limit : ndarray, shape (n_limited,)
        [N m], ``fraction`` applied.
    to_world : ndarray, shape (6, 6) or None
        Maps the root's RNEA rows (local frame) to the world wrench (f, n about the origin).
    rows : ndarray, shape (n_rows, n_limited + 6 or n_limited)
        :math:`R`: normalised rows :math:`c = R y - r_0` of the quantities
        :math:`y = (\\tau_{limited}, f, n)`.
    offset : ndarray, shape (n_rows,)
        :math:`r_0` (1 for torque rows, 0 otherwise).
    row_names : tuple of str
        What each row limits (a joint name, ``"cop"`` or ``"friction"``).
    polygon : ndarray, shape (n_edges, 3) or None
        Support polygon ``(a_x, a_y, b)``: :math:`a^T p \\le b`.
    sole_height : float
        [m]
    weight : float
        [N] :math:`m g` of the whole robot.
    balance : Balance or None
    """

    model: object
    posture: np.ndarray
    driven_q: np.ndarray
    driven_v: np.ndarray
    limited_names: tuple
    limited_v: np.ndarray
    torque_limit: np.ndarray
    to_world: np.ndarray | None
    rows: np.ndarray
    offset: np.ndarray
    row_names: tuple
    polygon: np.ndarray | None
    sole_height: float
    weight: float
    balance: Balance | None

    @property
    def n_outputs(self) -> int:
        """Size of :math:`y`."""
        return self.rows.shape[1]

    def _state(self, positions, velocities, accelerations):
        q = self.posture.copy()
        v = np.zeros(self.model.nv)
        a = np.zeros(self.model.nv)
        q[self.driven_q], v[self.driven_v], a[self.driven_v] = positions, velocities, accelerations
        return q, v, a

    def outputs(self, trajectory: Trajectory) -> np.ndarray:
        """:math:`y` at every sample by exact inverse dynamics, shape (n_steps, n_outputs)."""
        import pinocchio as pin

        data = self.model.createData()
        out = np.empty((trajectory.n_steps, self.n_outputs))
        n_limited = self.limited_v.size
        for i, sample in enumerate(
            zip(trajectory.positions, trajectory.velocities, trajectory.accelerations)
        ):
            tau = pin.rnea(self.model, data, *self._state(*sample))
            out[i, :n_limited] = tau[self.limited_v]
            if self.to_world is not None:
                out[i, n_limited:] = self.to_world @ tau[:6]
        return out

    def derivatives(self, trajectory: Trajectory) -> np.ndarray:
        """:math:`\\partial y / \\partial (q, \\dot q, \\ddot q)` of the driven joints at every
        sample, shape (3, n_steps, n_outputs, n_dofs) (``computeRNEADerivatives``)."""
        import pinocchio as pin

        model, data = self.model, self.model.createData()
        nv = model.nv
        full = np.empty((3, trajectory.n_steps, nv, nv))
        q, v, a = self._state(
            trajectory.positions[0], trajectory.velocities[0], trajectory.accelerations[0]
        )
        for i in range(trajectory.n_steps):
            q[self.driven_q] = trajectory.positions[i]
            v[self.driven_v] = trajectory.velocities[i]
            a[self.driven_v] = trajectory.accelerations[i]
            dq, dv, da = pin.computeRNEADerivatives(model, data, q, v, a)
            full[0, i], full[1, i], full[2, i] = dq, dv, da
        # Pinocchio fills the upper triangle of dtau/da = M: mirror it
        upper = np.triu(np.ones((nv, nv), dtype=bool))
        full[2] = np.where(upper, full[2], np.swapaxes(full[2], 1, 2))
        columns = full[..., self.driven_v]  # (3, n_steps, nv, n_dofs)
        parts = [columns[:, :, self.limited_v]]
        if self.to_world is not None:
            parts.append(np.einsum("wr,ksrd->kswd", self.to_world, columns[:, :, :6]))
        return np.concatenate(parts, axis=2)

    def constraint_values(self, outputs: np.ndarray) -> np.ndarray:
        """:math:`c = R y - r_0`, shape (n_steps, n_rows); <= 0 where every request holds."""
        return outputs @ self.rows.T - self.offset

    def cop(self, outputs: np.ndarray) -> np.ndarray:
        """Centre of pressure on the soles' plane [m], shape (n_steps, 2) (module docstring)."""
        f = outputs[:, self.limited_v.size :][:, :3]
        n = outputs[:, self.limited_v.size :][:, 3:]
        h = self.sole_height
        return np.column_stack([h * f[:, 0] - n[:, 1], h * f[:, 1] + n[:, 0]]) / f[:, 2:3]

    def cop_margin(self, outputs: np.ndarray) -> np.ndarray:
        """Signed distance of the CoP inside the support polygon [m] (negative: outside)."""
        cop = self.cop(outputs)
        return np.min(self.polygon[:, 2] - cop @ self.polygon[:, :2].T, axis=1)

    def friction_use(self, outputs: np.ndarray) -> np.ndarray:
        """``|f_t|_inf sqrt(2) / (mu f_z)``: 1 on the friction pyramid's face."""
        f = outputs[:, self.limited_v.size :][:, :3]
        mu = self.balance.friction / np.sqrt(2.0)
        return np.max(np.abs(f[:, :2]), axis=1) / (mu * f[:, 2])


def _joint_ids(robot, names, argument: str) -> list:
    ids = []
    for name in names:
        if not robot.model.existJointName(name):
            raise InvalidInputError(
                f"{argument} names {name!r}, which is not a joint of {robot.name!r}; expected "
                f"names from robot.actuated_joint_names, e.g. {robot.actuated_joint_names[:3]}"
            )
        joint_id = robot.model.getJointId(name)
        if robot.model.joints[joint_id].nv != 1 or name not in robot.actuated_joint_names:
            raise InvalidInputError(f"{argument}: {name!r} is not an actuated one-DOF joint")
        ids.append(joint_id)
    return ids


def _support_polygon(robot, data, contacts, margin: float):
    """``(polygon (n_edges, 3), sole height)``: hull of the contacts' corners, edges a.p <= b."""
    from scipy.spatial import ConvexHull

    corners = []
    for frame in contacts:
        if frame not in robot.foot_frames:
            raise InvalidInputError(
                f"Balance contacts names {frame!r}, not a foot frame of {robot.name!r}; "
                f"expected some of {robot.foot_frames}"
            )
        placement = data.oMf[robot.model.getFrameId(frame)]
        corners += [placement.act(np.asarray(c, dtype=float)) for c in robot.sole_corners]
    corners = np.array(corners)
    height = float(np.mean(corners[:, 2]))
    if np.ptp(corners[:, 2]) > FLAT_TOLERANCE or len(corners) < 3:
        raise InvalidInputError(
            f"Balance needs flat soles at one height: the corners of {contacts} span "
            f"{np.ptp(corners[:, 2]):.3g} m in height (at most {FLAT_TOLERANCE} m); give a "
            "posture with both feet flat on the ground"
        )
    hull = ConvexHull(corners[:, :2])
    polygon = np.column_stack([hull.equations[:, :2], -hull.equations[:, 2]])
    inradius = float(np.min(polygon[:, 2] - polygon[:, :2] @ corners[:, :2].mean(axis=0)))
    if margin >= inradius:
        raise InvalidInputError(
            f"cop_margin = {margin} m leaves no room in the support polygon (about "
            f"{inradius:.3g} m from its centre to its nearest edge); give a smaller cop_margin"
        )
    return polygon, height


def robot_dynamics(
    robot, joints: Sequence[str], posture=None, torque_limits=None, balance=None
) -> RobotDynamics:
    """The reduced model and rows of a dynamics-feasible fit (module docstring).

    Parameters
    ----------
    robot : dmpopt.robot.RobotModel
    joints : sequence of str
        The joints the DMP drives, in the order of its DOFs.
    posture : array_like, shape (robot.nq,), optional
        Where every other joint (and the base) stays (default: the reference posture).
    torque_limits : TorqueLimits, optional
    balance : Balance, optional
        Needs a free-flyer robot with feet.
    """
    import pinocchio as pin

    from ..robot import RobotModel

    if not isinstance(robot, RobotModel):
        raise InvalidInputError(
            f"robot must be a dmpopt.robot.RobotModel, got {type(robot).__name__}; build one with "
            "RobotModel.from_urdf(...) or dmpopt_robots.load_talos()"
        )
    if torque_limits is not None and not isinstance(torque_limits, TorqueLimits):
        raise InvalidInputError(
            f"torque_limits must be a TorqueLimits or None, got {type(torque_limits).__name__}"
        )
    if balance is not None and not isinstance(balance, Balance):
        raise InvalidInputError(f"balance must be a Balance or None, got {type(balance).__name__}")
    if torque_limits is None and balance is None:
        raise InvalidInputError(
            "give torque_limits=TorqueLimits() and/or balance=Balance(): without either the "
            "fit is the constrained fit (dmpopt.fit_weights_constrained)"
        )
    joints = (joints,) if isinstance(joints, str) else tuple(joints)
    driven = _joint_ids(robot, joints, "joints")
    if len(set(joints)) != len(joints):
        raise InvalidInputError(f"joints repeats a name: {joints}")
    posture = (
        np.array(robot.reference_configuration)
        if posture is None
        else real_array("posture", posture, shape=(robot.nq,))
    )
    limited_names = () if torque_limits is None else (torque_limits.joints or joints)
    limited = _joint_ids(robot, limited_names, "TorqueLimits joints")
    keep_root = balance is not None
    if keep_root and (robot.base != "free_flyer" or not robot.foot_frames):
        raise InvalidInputError(
            f"Balance needs a standing robot (free-flyer base and feet); {robot.name!r} has base "
            f"{robot.base!r} and feet {robot.foot_frames}"
        )
    kept = set(driven) | set(limited) | ({1} if keep_root and robot.floating_base else set())
    locked = [j for j in range(1, robot.model.njoints) if j not in kept]
    model = pin.buildReducedModel(robot.model, locked, posture) if locked else robot.model
    full_data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, full_data, posture)
    # the reduced configuration: the kept joints' values of posture
    q_reduced = np.zeros(model.nq)
    for j in range(1, model.njoints):
        original = robot.model.joints[robot.model.getJointId(model.names[j])]
        joint = model.joints[j]
        q_reduced[joint.idx_q : joint.idx_q + joint.nq] = posture[
            original.idx_q : original.idx_q + original.nq
        ]
    driven_q = np.array([model.joints[model.getJointId(n)].idx_q for n in joints])
    driven_v = np.array([model.joints[model.getJointId(n)].idx_v for n in joints])
    limited_v = np.array([model.joints[model.getJointId(n)].idx_v for n in limited_names], int)
    actuated = list(robot.actuated_joint_names)
    if torque_limits is None:
        limit = np.zeros(0)
    elif torque_limits.limit is None:
        limit = np.array([robot.torque_limit[actuated.index(n)] for n in limited_names])
    else:
        limit = np.broadcast_to(torque_limits.limit, (len(limited_names),)).astype(float)
        if torque_limits.limit.size not in (1, len(limited_names)):
            raise ShapeError(
                f"TorqueLimits limit has {torque_limits.limit.size} entries, expected 1 or "
                f"{len(limited_names)} (one per limited joint {limited_names})"
            )
    if not np.all(limit > 0) and limit.size:
        raise InvalidInputError(
            f"torque limits must be positive, got {dict(zip(limited_names, limit))}; give "
            "TorqueLimits(limit=...) for joints without a limit in the model"
        )
    limit = limit * (1.0 if torque_limits is None else torque_limits.fraction)
    n_limited = limit.size
    gravity = float(np.linalg.norm(robot.model.gravity.linear))
    weight = float(pin.computeTotalMass(robot.model)) * gravity
    rows, offset, names = [], [], []
    for j, (name, value) in enumerate(zip(limited_names, limit)):
        for sign in (1.0, -1.0):
            row = np.zeros(n_limited + 6 * keep_root)
            row[j] = sign / value
            rows.append(row)
            offset.append(1.0)
            names.append(name)
    polygon, height, to_world = None, 0.0, None
    if keep_root:
        data = model.createData()
        pin.forwardKinematics(model, data, q_reduced)
        placement = data.oMi[1]
        rotation, translation = placement.rotation, placement.translation
        skew = pin.skew(translation)
        to_world = np.block([[rotation, np.zeros((3, 3))], [skew @ rotation, rotation]])
        contacts = balance.contacts or robot.foot_frames
        polygon, height = _support_polygon(robot, full_data, contacts, balance.cop_margin)
        base = n_limited
        for a_x, a_y, b in polygon:
            row = np.zeros(n_limited + 6)
            # a_x (h f_x - n_y) + a_y (h f_y + n_x) - (b - m) f_z
            row[base + 0], row[base + 1] = a_x * height, a_y * height
            row[base + 2] = -(b - balance.cop_margin)
            row[base + 3], row[base + 4] = a_y, -a_x
            rows.append(row / (weight * BALANCE_LENGTH))
            offset.append(0.0)
            names.append("cop")
        mu = balance.friction / np.sqrt(2.0)
        for axis in (0, 1):
            for sign in (1.0, -1.0):
                row = np.zeros(n_limited + 6)
                row[base + axis], row[base + 2] = sign, -mu
                rows.append(row / weight)
                offset.append(0.0)
                names.append("friction")
    return RobotDynamics(
        model=model,
        posture=q_reduced,
        driven_q=driven_q,
        driven_v=driven_v,
        limited_names=tuple(limited_names),
        limited_v=limited_v,
        torque_limit=limit,
        to_world=to_world,
        rows=np.array(rows),
        offset=np.array(offset),
        row_names=tuple(names),
        polygon=polygon,
        sole_height=height,
        weight=weight,
        balance=balance,
    )


@dataclass(frozen=True, eq=False)
class DynamicsProblem:
    """A dynamics-feasible fit, ready to solve: the kinematic fit and the robot's rows.

    Attributes
    ----------
    kinematic : FittingProblem
        Objective, plan and kinematic requests (:func:`build_fitting_problem`).
    dynamics : RobotDynamics
    torque_limits : TorqueLimits or None
    balance : Balance or None
    margin : float
        Tightening of the normalised rows in the QP (the certificate uses none).
    check_step : float
        [s] Step of the certificate's finer grid (at most half the sample step).
    max_iterations : int
    solver : str
        QP backend (:func:`dmpopt.fitting.qp.solve_qp`).
    fine_plan : AffinePlan
        The plan every ``check_step``, affine in the weights (the certificate's grid).
    """

    kinematic: FittingProblem
    dynamics: RobotDynamics
    torque_limits: TorqueLimits | None
    balance: Balance | None
    margin: float
    check_step: float
    max_iterations: int
    solver: str
    fine_plan: object = None

    def response(self) -> np.ndarray:
        """Plan response to the scaled variables: shape (3, n_steps, n_basis)."""
        kinematic = self.kinematic
        return kinematic.plan.weight_response * (kinematic.length_scale * kinematic.scale)


class GridCheck(NamedTuple):
    """Exact inverse dynamics of a plan against the requests on one grid."""

    dt: float  # [s]
    torque_use: dict  # joint -> max |tau| / limit (the limit with its fraction)
    cop_margin_min: float  # [m], nan without balance
    friction_use_max: float  # nan without balance
    worst: float  # largest normalised row value (<= 0: every request holds)


@dataclass(frozen=True, eq=False)
class Certificate:
    """The final plan checked by exact inverse dynamics on the samples and between them.

    Attributes
    ----------
    samples, fine : GridCheck
        On the fit's grid and on a rollout every ``check_step``.
    feasible : bool
        Every request holds on both grids (to 1e-9 of a unit).
    """

    samples: GridCheck
    fine: GridCheck
    feasible: bool


@dataclass(frozen=True, eq=False)
class DynamicsReport:
    """What a dynamics-feasible fit did.

    Attributes
    ----------
    status : str
        ``"converged"``, ``"max_iterations"`` or ``"infeasible"``.
    iterations : int
        SQP iterations (QPs solved).
    solve_time : float
        [s] wall time of the whole fit (kinematic start, SQP, certificate).
    qp_time : float
        [s] of which in the QP solver.
    certificate : Certificate
    shape_error : ndarray, shape (n_dofs,)
        Largest ``|q - target|`` per DOF over the samples (the moved demonstration).
    history : ndarray, shape (n_iterations, 4)
        Per iteration: objective, violation (largest normalised row, 0 if none), trust
        radius, accepted (1/0).
    trajectory : Trajectory
    problem : DynamicsProblem
    """

    status: str
    iterations: int
    solve_time: float
    qp_time: float
    certificate: Certificate
    shape_error: np.ndarray
    history: np.ndarray
    trajectory: Trajectory
    problem: DynamicsProblem


class DynamicsFit(NamedTuple):
    """``(dmp, report)`` of :func:`solve_dynamics_problem`."""

    dmp: object
    report: DynamicsReport


def build_dynamics_problem(
    demo: Trajectory,
    robot,
    joints: Sequence[str],
    n_basis: int = 30,
    *,
    posture=None,
    torque_limits: TorqueLimits | None = None,
    balance: Balance | None = None,
    margin: float = 1e-3,
    check_step: float = 1e-3,
    max_iterations: int = 60,
    solver: str = "auto",
    **options,
) -> DynamicsProblem:
    """Build the fit of a discrete DMP to ``demo`` under a robot's torque limits and balance.

    Solve it with :func:`solve_dynamics_problem`.

    Parameters
    ----------
    demo : Trajectory
        The demonstration of ``joints`` [rad].
    robot : dmpopt.robot.RobotModel
    joints : sequence of str
        The joints the DMP drives (its DOFs, in order).
    n_basis : int
    posture : array_like, shape (robot.nq,), optional
        Where the other joints and the base stay (default: the robot's reference posture).
    torque_limits : TorqueLimits, optional
    balance : Balance, optional
        At least one of the two.
    margin : float
        Tightening of the normalised rows in the QP (1e-3: 0.1 % of a torque limit).
    check_step : float
        [s] The certificate checks a rollout with this step (at most half the sample step;
        default the 1 kHz of a controller).
    max_iterations : int
        SQP iterations.
    solver : {"auto", "daqp", "qpoases", "proxsuite"}
        QP backend.
    **options
        Keywords of :func:`dmpopt.fitting.constrained.build_fitting_problem` (``bounds``,
        ``duration``, ``n_samples`` (default :data:`DEFAULT_SAMPLES`), ``start``, ``goal``,
        end tolerances, ...).

    Returns
    -------
    DynamicsProblem
    """
    if not isinstance(demo, Trajectory):
        raise InvalidInputError(
            f"demo must be a Trajectory, got {type(demo).__name__}; build one with "
            "Trajectory.from_positions(times, positions)"
        )
    dynamics = robot_dynamics(robot, joints, posture, torque_limits, balance)
    if demo.n_dofs != dynamics.driven_v.size:
        raise ShapeError(
            f"demo has {demo.n_dofs} DOFs but joints names {dynamics.driven_v.size}; give one "
            "joint per DOF of the demonstration"
        )
    if options.get("n_samples") is None:
        options["n_samples"] = min(DEFAULT_SAMPLES, demo.n_steps)
    kinematic = build_fitting_problem(demo, n_basis, solver=solver, **options)
    step = min(real("check_step", check_step, minimum=1e-5), kinematic.dt / 2)
    fine_plan = kinematic.dmp.affine_plan(
        kinematic.duration, step, start_velocity=kinematic.start_velocity
    )
    return DynamicsProblem(
        fine_plan=fine_plan,
        kinematic=kinematic,
        dynamics=dynamics,
        torque_limits=torque_limits,
        balance=balance,
        margin=real("margin", margin, minimum=0.0, maximum=0.1, fix="keep it small, e.g. 1e-3"),
        check_step=step,
        max_iterations=integer("max_iterations", max_iterations, minimum=1, maximum=10_000),
        solver=check_solver(solver),
    )


class _Iterate(NamedTuple):
    x: np.ndarray  # (n_dofs * n_basis,) scaled variables, DOF-major
    trajectory: Trajectory
    outputs: np.ndarray
    values: np.ndarray  # (n_steps, n_rows) normalised rows, <= 0 where they hold
    objective: float

    def violation(self, margin: float = 0.0) -> float:
        """``max(0, max(c + margin))``: the penalised violation."""
        return max(0.0, float(self.values.max()) + margin)


def _evaluate(problem: DynamicsProblem, x: np.ndarray, hessian, gradient) -> _Iterate:
    kinematic = problem.kinematic
    trajectory = kinematic.plan.trajectory(kinematic.forcing_weights(x))
    outputs = problem.dynamics.outputs(trajectory)
    values = problem.dynamics.constraint_values(outputs)
    objective = float(0.5 * x @ hessian @ x + gradient @ x)
    return _Iterate(x, trajectory, outputs, values, objective)


def _linearised_rows(problem: DynamicsProblem, iterate: _Iterate, response: np.ndarray):
    """``matrix`` (n_steps * n_rows, n_x) of the rows: ``c(x + delta) ~ c(x) + matrix delta``.

    Chain rule (module docstring): ``d c / d x = R (dy/dq G0 + dy/dv G1 + dy/da G2)``.
    """
    dynamics = problem.dynamics
    derivative = dynamics.derivatives(iterate.trajectory)  # (3, n_steps, n_y, n_dofs)
    row_derivative = np.einsum("ry,ksyd->ksrd", dynamics.rows, derivative)
    matrix = np.einsum("ksrd,ksb->srdb", row_derivative, response)
    return matrix.reshape(-1, problem.kinematic.n_dofs * response.shape[2])


def _grid_check(dynamics: RobotDynamics, trajectory: Trajectory) -> GridCheck:
    outputs = dynamics.outputs(trajectory)
    n_limited = dynamics.limited_v.size
    use = np.abs(outputs[:, :n_limited]).max(axis=0) / dynamics.torque_limit
    cop_margin = friction = float("nan")
    if dynamics.balance is not None:
        cop_margin = float(dynamics.cop_margin(outputs).min())
        friction = float(dynamics.friction_use(outputs).max())
    worst = float(dynamics.constraint_values(outputs).max())
    return GridCheck(
        float(trajectory.times[1] - trajectory.times[0]),
        dict(zip(dynamics.limited_names, use.tolist())),
        cop_margin,
        friction,
        worst,
    )


def certify(problem: DynamicsProblem, dmp) -> Certificate:
    """Check ``dmp`` against ``problem``'s requests by exact inverse dynamics (no margin).

    On the problem's samples and on a rollout every ``problem.check_step`` (between them).
    """
    if not isinstance(problem, DynamicsProblem):
        raise InvalidInputError(f"problem must be a DynamicsProblem, got {type(problem).__name__}")
    kinematic = problem.kinematic
    samples = _grid_check(problem.dynamics, kinematic.plan.trajectory(dmp.forcing_weights()))
    fine_trajectory = problem.fine_plan.trajectory(dmp.forcing_weights())
    fine = _grid_check(problem.dynamics, fine_trajectory)
    feasible = samples.worst <= 1e-9 and fine.worst <= 1e-9
    return Certificate(samples, fine, feasible)


def _describe_violation(problem: DynamicsProblem, iterate: _Iterate) -> str:
    """The worst row of ``iterate``, named by joint, in physical units."""
    dynamics = problem.dynamics
    row = int(np.argmax(iterate.values.max(axis=0)))
    step = int(np.argmax(iterate.values[:, row]))
    name = dynamics.row_names[row]
    time_s = float(iterate.trajectory.times[step])
    if name == "cop":
        margin = float(dynamics.cop_margin(iterate.outputs[step : step + 1])[0])
        return (
            f"the CoP {-margin * 1e3:.1f} mm outside the support polygon (asked: "
            f"{dynamics.balance.cop_margin * 1e3:.1f} mm inside) at t = {time_s:.3f} s"
        )
    if name == "friction":
        use = float(dynamics.friction_use(iterate.outputs[step : step + 1])[0])
        return f"friction at {100 * use:.1f} % of the cone at t = {time_s:.3f} s"
    j = dynamics.limited_names.index(name)
    tau = float(iterate.outputs[step, j])
    return (
        f"{name} at {100 * abs(tau) / dynamics.torque_limit[j]:.1f} % of its torque limit "
        f"({abs(tau):.3g} N m for {dynamics.torque_limit[j]:.3g} N m) at t = {time_s:.3f} s"
    )


def solve_dynamics_problem(problem: DynamicsProblem) -> DynamicsFit:
    """Solve a dynamics-feasible fit by sequential QP (module docstring).

    Starts from the kinematic fit (:func:`solve_fitting_problem`), which holds the kinematic
    requests; ends with the certificate (exact inverse dynamics on the samples and between).

    Returns
    -------
    DynamicsFit
        ``(dmp, report)``.

    Raises
    ------
    InfeasibleProblem
        No plan found meets the requests: the message names the worst joint (or the CoP, or
        friction) at the least-violating plan found; ``error.stats["fit"]`` is that plan's
        :class:`DynamicsFit` and ``error.stats["violation"]`` its normalised violation.
    InvalidInputError
        ``problem`` is not a :class:`DynamicsProblem`.
    """
    if not isinstance(problem, DynamicsProblem):
        raise InvalidInputError(
            f"problem must be a DynamicsProblem, got {type(problem).__name__}; build one with "
            "build_dynamics_problem(demo, robot, joints, ...)"
        )
    begin = time.perf_counter()
    kinematic = problem.kinematic
    start = solve_fitting_problem(kinematic)
    qp = kinematic.full_qp()
    hessian, gradient = qp[0], qp[1]
    x = kinematic.variables(start.dmp.goal_map() @ start.dmp.weights).ravel()
    response = problem.response()
    iterate = best = _evaluate(problem, x, hessian, gradient)
    rho, radius, margin = PENALTY, 1.0, problem.margin
    history, qp_time, iterations, tightenings = [], 0.0, 0, 0
    status, working_set, merit = "max_iterations", None, 0.0
    while iterations < problem.max_iterations:
        if radius >= STEP_TOLERANCE:
            matrix = _linearised_rows(problem, iterate, response)
            values = iterate.values.ravel()
            solution = _step_qp(
                qp, iterate.x, matrix, values, margin, rho, radius, problem.solver, working_set
            )
            qp_time += solution.solve_time
            iterations += 1
            if not solution.success:
                radius, working_set = 0.25 * radius, None
                history.append((iterate.objective, iterate.violation(), radius, 0.0))
                continue
            step, working_set = solution.x[:-1], solution.active
            merit = iterate.objective + rho * iterate.violation(0.5 * margin)
            trial = iterate.x + step
            model = 0.5 * trial @ hessian @ trial + gradient @ trial
            model += rho * max(0.0, float((values + matrix @ step).max()) + margin)
            predicted, size = merit - model, float(np.abs(step).max())
            tiny = size <= STEP_TOLERANCE * (1.0 + float(np.abs(iterate.x).max()))
            if not (tiny or predicted <= PREDICTION_TOLERANCE * (1.0 + abs(merit))):
                candidate = _evaluate(problem, trial, hessian, gradient)
                actual = merit - (candidate.objective + rho * candidate.violation(0.5 * margin))
                accepted = actual >= ACCEPT_RATIO * predicted
                history.append((candidate.objective, candidate.violation(), radius, accepted))
                if accepted:
                    iterate = candidate
                    if actual >= 0.75 * predicted and size >= 0.99 * radius:
                        radius *= 2.0
                    if (iterate.violation(), iterate.objective) < (
                        best.violation(),
                        best.objective,
                    ):
                        best = iterate
                else:
                    radius = 0.25 * size
                continue
        # a stationary point of the merit (or a trust region too small to move)
        if iterate.violation(0.5 * margin) > FEASIBILITY_TOLERANCE and rho < MAX_PENALTY:
            rho, radius = 10.0 * rho, max(radius, RESTART_RADIUS)  # weigh the violation more
            continue
        status = "converged" if iterate.violation() <= 0.0 else "infeasible"
        if status == "converged" and tightenings < MAX_TIGHTENINGS:
            dmp = kinematic.dmp_for(kinematic.forcing_weights(iterate.x))
            certificate = certify(problem, dmp)
            if not certificate.feasible:  # between the samples: tighten and go on
                tightenings += 1
                margin += 1.5 * max(certificate.fine.worst, certificate.samples.worst)
                radius = max(radius, RESTART_RADIUS)
                continue
        break
    final = iterate if iterate.violation() <= best.violation() else best
    dmp = kinematic.dmp_for(kinematic.forcing_weights(final.x))
    certificate = certify(problem, dmp)
    report = DynamicsReport(
        status=status if final.violation() <= 0.0 else "infeasible",
        iterations=iterations,
        solve_time=time.perf_counter() - begin,
        qp_time=qp_time,
        certificate=certificate,
        shape_error=np.abs(final.trajectory.positions - kinematic.target).max(axis=0),
        history=np.array(history).reshape(-1, 4),
        trajectory=final.trajectory,
        problem=problem,
    )
    fit = DynamicsFit(dmp, report)
    if final.violation() > 0.0:
        raise InfeasibleProblem(
            f"the requests cannot all hold at this duration: the least-violating plan found "
            f"has {_describe_violation(problem, final)} (after {iterations} SQP iterations); "
            "lengthen the duration, raise the limits"
            + (" or lower cop_margin" if problem.balance is not None else "")
            + ", or keep the path and retime it (dmpopt.retiming.retime)",
            problem=problem,
            stats={"fit": fit, "violation": final.violation()},
        )
    return fit


def _step_qp(qp, x, matrix, values, margin, rho, radius, solver, working_set):
    """The step: the QP with the linearised rows held, or if that fails (no step within the
    trust region holds them) the elastic QP in ``z = (delta, t)`` (module docstring).

    Rows: kinematic (never forbidding ``delta = 0``: the iterate meets them to the solver's
    tolerance), dynamic (unit norm, as the kinematic rows), the trust region (and ``t >= 0``);
    ``working_set`` warm-starts the row generation of :func:`solve_qp`. Returns the
    :class:`~dmpopt.fitting.qp.QpSolution` with ``x = (delta, t)``.
    """
    hessian, gradient, kin_matrix, kin_lower, kin_upper = qp
    n = x.size
    kinematic_values = kin_matrix @ x
    kin_lower = np.minimum(kin_lower - kinematic_values, 0.0)
    kin_upper = np.maximum(kin_upper - kinematic_values, 0.0)
    total = 0.0
    for elastic in (False, True):
        k = n + elastic
        norms = np.sqrt(np.einsum("ij,ij->i", matrix, matrix) + float(elastic))
        hessian_z = np.zeros((k, k))
        hessian_z[:n, :n] = hessian
        gradient_z = hessian @ x + gradient
        dynamic = matrix / norms[:, None]
        if elastic:
            hessian_z[n, n] = ELASTIC_CURVATURE
            gradient_z = np.append(gradient_z, rho)
            dynamic = np.hstack([dynamic, -1.0 / norms[:, None]])
        rows = np.vstack([np.hstack([kin_matrix, np.zeros((kin_matrix.shape[0], k - n))]),
                          dynamic, np.eye(k)])  # fmt: skip
        box_lower = np.append(np.full(n, -radius), [0.0][:elastic])
        box_upper = np.append(np.full(n, radius), [INFINITY][:elastic])
        lower = np.concatenate([kin_lower, np.full(values.size, -INFINITY), box_lower])
        upper = np.concatenate([kin_upper, -(values + margin) / norms, box_upper])
        solution = solve_qp(
            hessian_z,
            gradient_z,
            rows,
            np.clip(lower, -INFINITY, INFINITY),
            np.clip(upper, -INFINITY, INFINITY),
            solver=solver,
            rows=None if working_set is None or working_set.size != lower.size else working_set,
        )
        total += solution.solve_time
        if solution.success and np.all(np.isfinite(solution.x)):
            break
    step = solution.x if elastic else np.append(solution.x, 0.0)
    return solution._replace(x=step, solve_time=total)


def fit_weights_dynamics(
    demo: Trajectory, robot, joints: Sequence[str], n_basis: int = 30, **options
) -> DynamicsFit:
    """Build and solve a dynamics-feasible fit in one call.

    ``solve_dynamics_problem(build_dynamics_problem(demo, robot, joints, n_basis,
    **options))``; the errors are those of both.
    """
    return solve_dynamics_problem(build_dynamics_problem(demo, robot, joints, n_basis, **options))


__all__ = [
    "BALANCE_LENGTH",
    "Certificate",
    "DynamicsFit",
    "DynamicsProblem",
    "DynamicsReport",
    "GridCheck",
    "RobotDynamics",
    "build_dynamics_problem",
    "certify",
    "fit_weights_dynamics",
    "robot_dynamics",
    "solve_dynamics_problem",
]
