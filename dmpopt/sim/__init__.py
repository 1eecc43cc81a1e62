"""Deterministic simulation: Pinocchio forward dynamics with compliant ground contact.

>>> from dmpopt.sim import Simulator, GroundContact
>>> sim = Simulator(model, dt=1e-3, contact_points=[("foot", (0, 0, -0.02))],
...                 ground=GroundContact(stiffness=2e4, damping=300, friction=0.8))
>>> sim.reset(q, v)
>>> state = sim.step(tau)   # state.q, state.v, state.t, state.contact_forces, state.in_contact
>>> state.fall              # None, or Fall(time, cause, value, threshold, reason)

Fall checks (:mod:`dmpopt.sim.falls`) are backend-independent: :class:`FallDetector` holds the
thresholds and :meth:`FallDetector.check` turns the base's height, tilt, time without contact
and angular speed into a :class:`Fall`.
"""

from dmpopt.sim.contact import GroundContact, ground_forces
from dmpopt.sim.falls import Fall, FallDetector, base_tilt
from dmpopt.sim.mujoco_backend import MujocoSimulator, render_animation, render_frame
from dmpopt.sim.plant import IDEAL, PlantParameters, SensorNoise, with_armature
from dmpopt.sim.simulator import SimState, Simulator, TouchdownEvent

__all__ = [
    "IDEAL",
    "Fall",
    "FallDetector",
    "GroundContact",
    "MujocoSimulator",
    "PlantParameters",
    "SensorNoise",
    "SimState",
    "Simulator",
    "TouchdownEvent",
    "base_tilt",
    "with_armature",
    "ground_forces",
    "render_animation",
    "render_frame",
]
