"""What binds a tick of the inverse-dynamics controller, in words a user can act on.

:func:`active_constraints` reads the last solution of an :class:`InverseDynamicsController`
(its torques, joint accelerations and contact wrenches) and names every inequality row at
its bound: a torque limit, a joint-limit acceleration bound, a friction, centre-of-pressure
or normal-force row of a contact. :func:`explain` adds what the last answer was and, for a
relaxed or hold answer, why. Neither changes the controller; both cost a few microseconds
per row and are meant for a printout, not for every tick of a real-time loop.
"""

from __future__ import annotations

import numpy as np

from . import kernels

__all__ = ["active_constraints", "explain"]

#: A row is reported when its slack is below this fraction of its scale: the robot's weight
#: for contact rows [N, or N m for the centre-of-pressure and yaw rows], the torque limit for
#: torque rows (the controller's own release margins, 0.1 % and 1 %).
CONE_MARGIN = 1e-3
TORQUE_MARGIN = 1e-2
#: Joint-limit acceleration bounds within this of the joint acceleration [rad/s^2].
BOUND_MARGIN = 1e-2

_STATUS = {
    "PROXQP_MAX_ITER_REACHED": "out of iterations (max_iterations) or of its share of the time "
    "budget",
    "PROXQP_PRIMAL_INFEASIBLE": "infeasible: no accelerations and wrenches meet every row at once",
    "PROXQP_DUAL_INFEASIBLE": "unbounded (a task leaves a direction free)",
    "DAQP_INFEASIBLE": "infeasible: no accelerations and wrenches meet every row at once",
    "DAQP_ITERATION_LIMIT": "out of iterations",
    "DAQP_CYCLING": "the active-set iterations cycled (nearly dependent rows)",
    "DAQP_NONCONVEX": "the Hessian is not positive definite (a task leaves a direction free)",
    "NON_FINITE_PROBLEM": "a NaN or inf in a task target or the state",
}


def active_constraints(controller) -> list[str]:
    """Names of the inequality rows at their bound in the controller's last solution.

    Parameters
    ----------
    controller : InverseDynamicsController
        After at least one :meth:`~InverseDynamicsController.compute_torques`.

    Returns
    -------
    list of str
        E.g. ``"CoP of right_sole_link at its heel edge (0.4 mm)"``, ``"torque limit of
        leg_left_4_joint (upper)"``, ``"friction cone of left_sole_link (+x)"``,
        ``"joint limit of arm_left_4_joint (lower acceleration bound)"``: contacts first (in
        the order of :attr:`~InverseDynamicsController.active_contacts`), then torques, then
        joint limits. Empty if nothing binds (a ``direct`` answer).
    """
    qp = controller._current
    robot = qp.robot
    names = []
    weight = qp.layout.force_scale
    offset = 0
    for contact, padded in zip(qp.contacts, qp.contact_wrenches):
        wrench = padded[: contact.n_force]
        rows = contact.row_names
        size = len(rows)
        slack = qp.assembly.cone_upper[offset : offset + size] - contact.wrench_matrix @ wrench
        offset += size
        for index in np.flatnonzero(slack <= CONE_MARGIN * weight):
            name = rows[index]
            if name.startswith("CoP") and wrench[contact.normal_index] > 0:
                name += f" ({1e3 * max(slack[index], 0.0) / wrench[contact.normal_index]:.1f} mm)"
            names.append(name)
    torques, limit = qp.torques, qp.torque_limit
    for index in np.flatnonzero(np.abs(torques) >= (1.0 - TORQUE_MARGIN) * limit):
        side = "upper" if torques[index] > 0 else "lower"
        names.append(f"torque limit of {robot.actuated_joint_names[index]} ({side})")
    bounds = qp.assembly.bounds
    if bounds.v_index.size:
        lower, upper = np.empty(bounds.v_index.size), np.empty(bounds.v_index.size)
        bounds = bounds._replace(lower=lower, upper=upper)  # the QP's own arrays untouched
        kernels.acceleration_bounds(bounds, qp.assembly.q, qp.assembly.v)
        accelerations = qp.joint_accelerations[bounds.v_index]
        joints = {
            robot.model.joints[j].idx_v: robot.model.names[j] for j in range(1, robot.model.njoints)
        }
        for side, binding in (
            ("upper", accelerations >= upper - BOUND_MARGIN),
            ("lower", accelerations <= lower + BOUND_MARGIN),
        ):
            for index in np.flatnonzero(binding):
                joint = joints[bounds.v_index[index]]
                names.append(f"joint limit of {joint} ({side} acceleration bound)")
    return names


def explain(controller) -> str:
    """The last tick's answer, why (for a relaxed or hold answer), and what binds.

    Returns
    -------
    str
        One line, e.g. ``"relaxed: the QP with its inequality rows was not solved
        (DAQP_INFEASIBLE: infeasible ...); the contact rows and joint-limit
        bounds were relaxed, torque and cone rows kept. At their bounds: CoP of ..."``.
    """
    stats = controller.stats
    status = stats.last_status
    if stats.last_answer == "relaxed":  # last_status is the relaxed QP's: ask the exact one
        status = controller._current.tick.limited.status
    reason = f"{status}: {_STATUS[status]}" if status in _STATUS else status
    binding = active_constraints(controller)
    rows = "; ".join(binding) if binding else "nothing"
    if stats.last_answer == "direct":
        return "direct: no inequality row was needed"
    if stats.last_answer == "solved":
        return f"solved; at their bounds: {rows}"
    if stats.last_answer == "relaxed":
        return (
            f"relaxed: the QP with its inequality rows was not solved ({reason}); the contact "
            f"rows and joint-limit bounds were relaxed, torque and cone rows kept. At their "
            f"bounds: {rows}"
        )
    return (
        f"hold: neither the QP nor its relaxation was solved in the time budget ({reason}); "
        f"the torques are the last valid ones, clipped to the limits. At their "
        f"bounds on the last solved tick: {rows}"
    )
