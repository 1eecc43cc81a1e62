"""The layout of the inverse-dynamics QP of one contact set: its sizes, blocks and names.

Built once per set of active contacts and tasks (:func:`build_layout`) and read by the
assembly, the tick and the inspection (:meth:`InverseDynamicsController.assembled_qp`). The
unknowns are :math:`x = (\\ddot q, f / s)` with s the robot's weight (``force_scale``), or
:math:`y = x[n_b:]` once the base rows are eliminated (see
:mod:`dmpopt.control.inverse_dynamics`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

__all__ = ["QpLayout", "build_layout"]


@dataclass(frozen=True, eq=False)
class QpLayout:
    """Sizes, blocks and row names of one contact set's QP.

    Attributes
    ----------
    nv, n_base, n_act : int
        Velocity, base and actuated coordinates.
    n_force, n_cone, n_task, n_bound : int
        Force unknowns, cone rows, least-squares task rows (tasks other than posture tasks)
        and joint-limit acceleration bounds.
    n, n_x, n_cost, n_limit, dynamics_start : int
        Unknowns over y and over x, cost rows (task rows and base regularisation), torque
        and bound rows, and the first base-dynamics row of the linear rows.
    force_scale : float
        The robot's weight [N] (1 without contacts): the wrench unknowns are f / force_scale.
    force_slices, cone_slices, task_rows : tuple of slice
        Each contact's forces (in f) and cone rows, each stacked task's rows.
    normal_rows : tuple of (int, int)
        Each contact's normal-force cone rows (its last two), which a transition changes.
    variable_names, equality_names, inequality_names : tuple of str
        The names of y, of the contact rows and of the inequality rows (torques, bounds,
        cones), as in :class:`~dmpopt.control.inverse_dynamics.AssembledQp`.
    """

    nv: int
    n_base: int
    n_act: int
    n_force: int
    n_cone: int
    n_task: int
    n_bound: int
    n: int
    n_x: int
    n_cost: int
    n_limit: int
    dynamics_start: int
    force_scale: float
    force_slices: tuple
    cone_slices: tuple
    task_rows: tuple
    normal_rows: tuple
    variable_names: tuple
    equality_names: tuple
    inequality_names: tuple


def _velocity_names(model: pin.Model) -> list[str]:
    """Names of the velocity coordinates (``joint`` or ``joint[k]``)."""
    names = []
    for joint, name in zip(model.joints[1:], model.names[1:]):
        names += [name] if joint.nv == 1 else [f"{name}[{k}]" for k in range(joint.nv)]
    return names


def _slices(sizes) -> tuple:
    offsets = np.cumsum([0, *sizes]).astype(int)
    return tuple(slice(int(a), int(b)) for a, b in zip(offsets[:-1], offsets[1:]))


def build_layout(robot, stacked_tasks, contacts, bounded: np.ndarray) -> QpLayout:
    """The layout of the QP of ``contacts`` and the least-squares ``stacked_tasks`` (posture
    tasks add no rows), with acceleration bounds on the velocity indices ``bounded``."""
    nv, n_act = robot.nv, robot.n_actuated
    n_base = nv - n_act
    force_slices = _slices([c.n_force for c in contacts])
    cone_slices = _slices([c.wrench_upper.size for c in contacts])
    task_rows = _slices([task.target.size for task in stacked_tasks])
    n_force = force_slices[-1].stop if contacts else 0
    n_cone = cone_slices[-1].stop if contacts else 0
    n_task = task_rows[-1].stop if stacked_tasks else 0
    n_bound = int(np.asarray(bounded).size)
    force_scale = pin.computeTotalMass(robot.model) * 9.81 if contacts else 1.0
    names = _velocity_names(robot.model)
    joints = names[n_base:]
    forces = [(contact, name) for contact in contacts for name in contact.force_names]
    return QpLayout(
        nv=nv,
        n_base=n_base,
        n_act=n_act,
        n_force=n_force,
        n_cone=n_cone,
        n_task=n_task,
        n_bound=n_bound,
        n=n_act + n_force,
        n_x=nv + n_force,
        n_cost=n_task + n_base,
        n_limit=n_act + n_bound,
        dynamics_start=n_task + n_base + n_force,
        force_scale=float(force_scale),
        force_slices=force_slices,
        cone_slices=cone_slices,
        task_rows=task_rows,
        normal_rows=tuple((rows.stop - 2, rows.stop - 1) for rows in cone_slices),
        variable_names=tuple(
            [f"acceleration of {name}" for name in joints]
            + [f"{name} of {contact.frame} / force_scale" for contact, name in forces]
        ),
        equality_names=tuple(f"contact {contact.frame} ({name})" for contact, name in forces),
        inequality_names=tuple(
            [f"torque limit of {name}" for name in joints]
            + [f"joint limit of {names[i]} (acceleration bound)" for i in bounded]
            + [name for contact in contacts for name in contact.row_names]
        ),
    )
