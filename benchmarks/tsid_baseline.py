"""TSID on the humanoid study's tasks: the reference that dmpopt's controller is timed against.

:func:`build_tsid` has the signature of :func:`dmpopt_studies.humanoid.build_controller` and sets up
TSID (``pip install tsid``, C++ with Python bindings, eiquadprog's HQuadProgFast solver) with
the same tasks, weights and gains:

- whole-body posture (weight 1e-2, stiffness 10) and the DMP-driven arm posture or hand
  position task (weight 1, stiffness 100), plus the other arm's posture for the figure-8;
- standing: CoM (weight 10, stiffness 50), pelvis orientation (weight 1, stiffness 50), two
  rigid sole contacts (Baumgarte stiffness 10, friction 0.7, the same sole corners), joint
  torque bounds; damping is critical everywhere, as in dmpopt.

TSID's contact model differs in one detail: it has a 3-D force at each of the four sole
corners (12 variables per foot, friction pyramids at the corners) where dmpopt has one 6-D
wrench with CoP bounds. Both are the standard formulations of a flat-foot contact.
A tick is ``computeProblemData`` + ``solve`` + ``getActuatorForces``.
"""

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

if int(pin.__version__.split(".")[0]) >= 4:
    raise ImportError(
        f"TSID's wheels crash with pin {pin.__version__} (binary mismatch); install the "
        "versions in benchmarks/tsid-constraints.txt in a separate venv"
    )
import tsid  # noqa: E402
from dmpopt_studies import humanoid

if not hasattr(tsid, "RobotWrapper"):  # tsid 1.7 wheels nest the bindings one level down
    from tsid import tsid_pywrap as tsid


@dataclass
class TsidStats:
    """The counters the study's closed loop reads from a controller."""

    n_cold_restarts: int = 0
    n_fallbacks: int = 0  # ticks where the solver failed and the previous torques were kept
    n_direct: int = 0
    n_torque_limited: int = 0  # TSID always solves with its torque rows: not counted


def _gains(task, stiffness: float, size: int) -> None:
    task.setKp(stiffness * np.ones(size))
    task.setKd(2.0 * np.sqrt(stiffness) * np.ones(size))


def _sample(position, velocity=None, acceleration=None, size=None) -> tsid.TrajectorySample:
    position = np.asarray(position, dtype=float)
    size = position.size if size is None else size
    sample = tsid.TrajectorySample(position.size, size)
    sample.value(position)
    sample.derivative(np.zeros(size) if velocity is None else np.asarray(velocity, float))
    sample.second_derivative(
        np.zeros(size) if acceleration is None else np.asarray(acceleration, float)
    )
    return sample


class TsidPosture:
    """The DMP-driven joint posture task: references for some joints, held in a full vector."""

    def __init__(self, task, indices: np.ndarray, reference: np.ndarray):
        self.task, self.indices = task, indices
        self.position = reference.copy()
        self.velocity = np.zeros_like(reference)
        self.acceleration = np.zeros_like(reference)
        self.set_reference(reference[indices])

    def set_reference(self, positions, velocities=None, accelerations=None) -> None:
        self.position[self.indices] = positions
        self.velocity[self.indices] = 0.0 if velocities is None else velocities
        self.acceleration[self.indices] = 0.0 if accelerations is None else accelerations
        self.task.setReference(_sample(self.position, self.velocity, self.acceleration))


class TsidHand:
    """The DMP-driven hand position task (world-aligned, orientation masked out)."""

    def __init__(self, task, placement: pin.SE3):
        self.task, self.placement = task, placement.copy()

    def set_target(self, position, velocity=None, acceleration=None) -> None:
        self.placement.translation = np.asarray(position, dtype=float)
        vector = tsid.SE3ToVector(self.placement)
        self.task.setReference(_sample(vector, velocity, acceleration, size=6))


class TsidController:
    """TSID's formulation and solver behind dmpopt's ``compute_torques(q, v)``."""

    def __init__(self, robot, wrapper, formulation, contacts, parts):
        self.robot, self.wrapper, self.formulation = robot, wrapper, formulation
        self.parts = parts  # TSID keeps raw pointers to its tasks: they must stay alive
        self.contacts = contacts  # (contact, frame id), referenced on the first tick
        self.solver = tsid.SolverHQuadProgFast("eiquadprog-fast")
        self.solver.resize(formulation.nVar, formulation.nEq, formulation.nIn)
        self.stats = TsidStats()
        self.time = 0.0
        self.tau = np.zeros(robot.n_actuated)

    def compute_torques(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        problem = self.formulation.computeProblemData(self.time, q, v)
        if self.contacts:  # hold the soles where the first tick finds them
            for contact, frame_id in self.contacts:
                contact.setReference(self.wrapper.framePosition(self.formulation.data(), frame_id))
            self.contacts = []
            problem = self.formulation.computeProblemData(self.time, q, v)
        solution = self.solver.solve(problem)
        self.time += humanoid.DT
        if solution.status != 0:
            self.stats.n_fallbacks += 1
            return self.tau
        self.tau = self.formulation.getActuatorForces(solution)
        return self.tau


def build_tsid(
    robot, q_start, arm_joints=humanoid.DRUM_JOINTS, hand=None, base_task=True, friction=0.7
):
    """TSID with the tasks of :func:`dmpopt_studies.humanoid.build_controller`, and the driven task;
    ``friction`` is the soles' friction coefficient. The CoM task is ``controller.com``."""
    model = robot.model
    root = tsid.FLOATING_BASE_SYSTEM if robot.floating_base else tsid.FIXED_BASE_SYSTEM
    wrapper = tsid.RobotWrapper(model, root, False)
    formulation = tsid.InverseDynamicsFormulationAccForce("tsid", wrapper, False)
    n_base = model.nv - robot.n_actuated
    data = model.createData()
    pin.framesForwardKinematics(model, data, q_start)
    actuated_reference = q_start[model.nq - robot.n_actuated :]
    parts = []

    def posture(name, joints, weight, stiffness):
        task = tsid.TaskJointPosture(name, wrapper)
        _gains(task, stiffness, robot.n_actuated)
        if joints is not None:
            mask = np.zeros(robot.n_actuated)
            mask[robot.velocity_indices(joints) - n_base] = 1.0
            task.setMask(mask)
        formulation.addMotionTask(task, weight, 1, 0.0)
        parts.append(task)
        return task

    whole = posture("posture", None, humanoid.POSTURE_WEIGHT, 10.0)
    whole.setReference(_sample(actuated_reference))
    if hand is None:
        task = posture("arms", list(arm_joints), 1.0, humanoid.ARM_STIFFNESS)
        driven = TsidPosture(
            task, robot.velocity_indices(list(arm_joints)) - n_base, actuated_reference
        )
    else:
        task = tsid.TaskSE3Equality("hand", wrapper, hand)
        _gains(task, humanoid.HAND_STIFFNESS, 6)
        task.setMask(np.array([1.0, 1, 1, 0, 0, 0]))
        task.useLocalFrame(False)
        formulation.addMotionTask(task, 1.0, 1, 0.0)
        parts.append(task)
        placement = data.oMf[model.getFrameId(hand)]
        driven = TsidHand(task, placement)
        driven.set_target(placement.translation)
        other = "left_arm" if "right" in hand else "right_arm"
        hold = posture("hold", other, 1.0, humanoid.ARM_STIFFNESS)
        hold.setReference(_sample(actuated_reference))
    contacts = []
    if robot.floating_base:
        com = tsid.TaskComEquality("com", wrapper)
        _gains(com, 50.0, 3)
        target = pin.centerOfMass(model, data, q_start) - [0, 0, humanoid._sink(robot)]
        com.setReference(_sample(target))
        formulation.addMotionTask(com, humanoid.COM_WEIGHT, 1, 0.0)
        parts.append(com)
        if base_task:
            base = tsid.TaskSE3Equality("base", wrapper, "base_link")
            _gains(base, 50.0, 6)
            base.setMask(np.array([0.0, 0, 0, 1, 1, 1]))
            base.setReference(
                _sample(tsid.SE3ToVector(data.oMf[model.getFrameId("base_link")]), size=6)
            )
            formulation.addMotionTask(base, humanoid.BASE_WEIGHT, 1, 0.0)
            parts.append(base)
        for foot in robot.foot_frames:
            contact = tsid.Contact6d(
                foot,
                wrapper,
                foot,
                np.asarray(robot.sole_corners).T.copy(),
                np.array([0.0, 0.0, 1.0]),
                friction,
                1.0,
                5000.0,
            )
            _gains(contact, 10.0, 6)
            formulation.addRigidContact(contact, 1e-8, 1.0, 0)
            contacts.append((contact, model.getFrameId(foot)))
            parts.append(contact)
    bounds = tsid.TaskActuationBounds("torque-bounds", wrapper)
    limit = np.asarray(robot.torque_limit, dtype=float)
    bounds.setBounds(-limit, limit)
    formulation.addActuationTask(bounds, 1.0, 0, 0.0)
    parts.append(bounds)
    controller = TsidController(robot, wrapper, formulation, contacts, parts)
    controller.com = com if robot.floating_base else None
    return controller, driven


class TsidWalking:
    """TSID on the walking sequence of ``bench_controller.py --walking`` and
    ``bench_tsid.py``: sole contacts on ``feet``, CoM, pelvis orientation and posture tasks;
    a swing task on the right sole once :meth:`add_swing` is called; targets set per tick."""

    def __init__(
        self, robot, q, swing_weight, swing_stiffness, cop_fraction, feet=("left_sole_link",)
    ):
        model = robot.model
        self.wrapper = wrapper = tsid.RobotWrapper(model, tsid.FLOATING_BASE_SYSTEM, False)
        self.formulation = tsid.InverseDynamicsFormulationAccForce("walk", wrapper, False)
        data = model.createData()
        pin.framesForwardKinematics(model, data, q)
        self.posture = tsid.TaskJointPosture("posture", wrapper)
        _gains(self.posture, 10.0, robot.n_actuated)
        self.posture.setReference(_sample(robot.reference_configuration[7:]))
        self.com = tsid.TaskComEquality("com", wrapper)
        _gains(self.com, 50.0, 3)
        self.pelvis = tsid.TaskSE3Equality("pelvis", wrapper, "base_link")
        _gains(self.pelvis, 50.0, 6)
        self.pelvis.setMask(np.array([0.0, 0, 0, 1, 1, 1]))
        self.pelvis.setReference(
            _sample(tsid.SE3ToVector(data.oMf[model.getFrameId("base_link")]), size=6)
        )
        self.swing = tsid.TaskSE3Equality("swing", wrapper, "right_sole_link")
        _gains(self.swing, swing_stiffness, 6)
        self.swing.useLocalFrame(False)
        self.swing_weight = swing_weight
        for task, weight in ((self.posture, 0.1), (self.com, 10.0), (self.pelvis, 1.0)):
            self.formulation.addMotionTask(task, weight, 1, 0.0)
        self.contacts = []  # TSID keeps raw pointers: they must stay alive
        for foot in feet:
            contact = tsid.Contact6d(
                foot, wrapper, foot,
                cop_fraction * np.asarray(robot.sole_corners).T.copy(), np.array([0.0, 0.0, 1.0]),
                0.7, 1.0, 1500.0,
            )  # fmt: skip
            _gains(contact, 10.0, 6)
            contact.setReference(data.oMf[model.getFrameId(foot)])
            self.formulation.addRigidContact(contact, 1e-8, 1.0, 0)
            self.contacts.append(contact)
        self.bounds = tsid.TaskActuationBounds("torque-bounds", wrapper)
        limit = np.asarray(robot.torque_limit, dtype=float)
        self.bounds.setBounds(-limit, limit)
        self.formulation.addActuationTask(self.bounds, 1.0, 0, 0.0)
        self.solver = tsid.SolverHQuadProgFast("eiquadprog-fast")
        self._resize()
        self.failures = 0
        self.swinging = False

    def _resize(self) -> None:
        form = self.formulation
        self._size = (form.nVar, form.nEq, form.nIn)
        self.solver.resize(*self._size)

    def remove_contact(self, frame: str, transition_time: float) -> None:
        """TSID's ``removeRigidContact``: the normal force ramps down over ``transition_time``."""
        self.formulation.removeRigidContact(frame, transition_time)

    def add_swing(self) -> None:
        """Add the right sole's swing task (weight and stiffness of the constructor)."""
        self.formulation.addMotionTask(self.swing, self.swing_weight, 1, 0.0)
        self.swinging = True

    def set_targets(self, com_target, swing_target: pin.SE3) -> None:
        """The CoM target [m] and, once swinging, the right sole's target placement."""
        self.com.setReference(_sample(com_target))
        if self.swinging:
            self.swing.setReference(_sample(tsid.SE3ToVector(swing_target), size=6))

    def compute_torques(self, q, v, t, com_target=None, swing_target=None) -> np.ndarray:
        """One tick: targets (if given), ``computeProblemData``, ``solve``,
        ``getActuatorForces``."""
        if com_target is not None:
            self.set_targets(com_target, swing_target)
        problem = self.formulation.computeProblemData(t, q, v)
        form = self.formulation
        if self._size != (form.nVar, form.nEq, form.nIn):
            self._resize()  # a contact or task was dropped or added: the problem changed size
        solution = self.solver.solve(problem)
        self.failures += solution.status != 0
        return self.formulation.getActuatorForces(solution)
