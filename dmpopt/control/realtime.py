"""Keeping Python's garbage collector out of a control loop's timing.

Every tick of :class:`~dmpopt.control.InverseDynamicsController` pauses the cyclic garbage
collector while it runs, so no collection starts inside a tick. Between ticks a collection of
the oldest generation scans every object the process holds: with Pinocchio models, CasADi
functions and the study's logs that took 68-70 ms on Talos. :func:`control_loop` moves the
objects alive when the loop starts into the collector's permanent generation
(``gc.freeze``), so that the collections during the loop scan only the objects the loop
itself made. It collects only the youngest generation before freezing: a full collection
there scanned every object of the process at every loop (81-108 ms per walk of a biped
study, 175 thousand objects), and the older generations' garbage is collected anyway once
the loop ends and unfreezes it.
"""

from __future__ import annotations

import gc
from contextlib import contextmanager

__all__ = ["control_loop"]


@contextmanager
def control_loop():
    """Run a control loop with the objects made before it out of the collector's scans.

    On entry: a collection of the youngest generation (the garbage just made while setting
    up goes now, at the cost of scanning only the objects made since the last collection),
    then ``gc.freeze()``; on exit ``gc.unfreeze()``, which returns the frozen objects to the
    oldest generation (its garbage is collected by its next collection). Objects frozen are
    never collected while frozen, so keep the loop's setup before it and its garbage inside
    it.

    Examples
    --------
    >>> with control_loop():
    ...     for k in range(n_ticks):
    ...         tau = controller.compute_torques(q, v)
    ...         q, v = robot_step(tau)
    """
    gc.collect(0)
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
