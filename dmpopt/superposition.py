"""Superposition of primitives (Section 3.7): a discrete DMP moves a rhythmic DMP's setpoint."""

from __future__ import annotations

import numpy as np

from .dmp import DiscreteDMP, RhythmicDMP
from .exceptions import InvalidInputError, ShapeError
from .stepper import Stepper
from .trajectory import Trajectory
from .validation import positive


def superpose(discrete: DiscreteDMP, rhythmic: RhythmicDMP, duration: float, dt: float = 0.001):
    """Oscillate with ``rhythmic`` around the moving plan of ``discrete``.

    At every step the rhythmic DMP's setpoint is the discrete DMP's current position, e.g.
    a point-to-point reach with a periodic pattern on top (ball bouncing while moving).

    Returns
    -------
    Trajectory
        The rhythmic DMP's plan, samples at ``0, dt, ..., duration``.
    """
    if not isinstance(discrete, DiscreteDMP) or not isinstance(rhythmic, RhythmicDMP):
        raise InvalidInputError("superpose takes a DiscreteDMP and a RhythmicDMP, in this order")
    if discrete.n_dofs != rhythmic.n_dofs:
        raise ShapeError(
            f"discrete has {discrete.n_dofs} DOFs but rhythmic has {rhythmic.n_dofs}; "
            "they must drive the same DOFs"
        )
    duration, dt = positive("duration", duration), positive("dt", dt)
    setpoints = discrete.rollout(duration, dt).positions
    # at rest on the first setpoint by design (the Stepper itself: no off-cycle warning)
    stepper = Stepper(rhythmic.with_setpoint(setpoints[0]), dt, setpoints[0])
    samples = np.empty((3, len(setpoints), rhythmic.n_dofs))
    samples[:, 0] = stepper.position, stepper.velocity, stepper.acceleration
    for k in range(1, len(setpoints)):
        stepper.set_setpoint(setpoints[k - 1])
        samples[:, k] = stepper.step()
    return Trajectory(np.arange(len(setpoints)) * dt, *samples)
