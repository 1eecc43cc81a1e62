"""dmpopt's QP controller and TSID side by side, tick by tick, on the same recorded states.

Scenarios (full Talos on a floating base, 1 kHz; the humanoid study's tasks and gains):

- ``drumming``: the 12 arm joints follow the learned rhythmic DMPs (the paper's task);
- ``wave``: torque limits x0.3, both arms waving 0.05 rad at 3 Hz: torque rows bind
  (``bench_qp_stress.py``);
- ``com-step``: friction coefficient 0.1, the CoM target stepping (0, 3, -2) cm at 0.1 s:
  cone rows bind (``bench_qp_stress.py``, with the study's arm posture task);
- ``walking``: the CoM moves over the left sole, the right contact is removed with a 0.25 s
  normal-force ramp at 1.1 s, a swing task on the right sole is added at 1.4 s and lifts it
  5 cm (``bench_controller.py --walking``). Rows: ``one foot`` (every tick from 1.45 s),
  ``one foot, QP`` (those whose dmpopt answer needed the QP, not ``direct``), and
  ``switch`` (the ticks where dmpopt's contact set or task set changes: 1.1 s, the end of
  the ramp and 1.4 s; TSID's at the same ticks).

Method: each scenario runs once in closed loop with dmpopt's controller in
:class:`dmpopt.sim.Simulator`, recording the state, time and task targets of every tick. Then
new dmpopt and TSID controllers replay the recording ``--repeats`` times (new controllers
each time), interleaved: on each tick both get the same targets and state, the first of the
two alternating between ticks, and each ``compute_torques`` (model terms, assembly, solve,
torques; targets are set outside the timed call) is timed by the CPU time of the thread
(``time.thread_time_ns``: a busy machine's waiting for a core is not counted). Numbers are
over all repeats, in microseconds; ``ratio`` is dmpopt's median over TSID's, ``p99/T med``
dmpopt's p99 over TSID's median. ``gc`` counts garbage collections started inside dmpopt's
ticks (generation 2 and the longest one).

TSID is optional: without it only dmpopt's columns are printed. Its wheels crash with pin 4
(binary mismatch), so it lives in its own venv, never a dependency of dmpopt; TSID 1.7.1 on
pin 3.4.0 (``benchmarks/tsid-constraints.txt``) runs::

    python3.11 -m venv /path/to/venv-tsid
    /path/to/venv-tsid/bin/pip install -c benchmarks/tsid-constraints.txt tsid pin casadi \\
        proxsuite daqp numba scipy toppra tqdm threadpoolctl example-robot-data mujoco
    PYTHONPATH=.:benchmarks /path/to/venv-tsid/bin/python benchmarks/bench_tsid.py

Run from the repository root: ``PYTHONPATH=.:benchmarks python benchmarks/bench_tsid.py
[--seconds 2] [--repeats 3] [--scenarios drumming wave com-step walking] [--no-freeze]``. After the
walk it prints the CPU time per stage of dmpopt's one-foot QP ticks (one more replay); with
``--stages``, only the stage timers, of each scenario given (the walk's one-foot QP ticks,
every tick of the others), e.g. ``--stages --scenarios drumming``. ``--gc-replays N``: only
dmpopt, N replays of each recording watching the garbage collector (collections started inside
and between ticks, the longest tick by CPU and wall time and the ticks over 2 ms of CPU), e.g.
``--gc-replays 10``.

Garbage collection: dmpopt's tick pauses the collector (``gc in dmpopt ticks`` counts the
collections started inside them: 0 by construction); the closed loop that records each
scenario (controller and simulator) runs inside :func:`dmpopt.control.control_loop`, which
freezes the objects made before it, and ``gc in the closed loop`` counts every collection in
that loop, its generation-2 ones and the longest (``--no-freeze``: without it).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import gc
import os
import time

import numpy as np
import pinocchio as pin
from dmpopt_robots import load_talos
from dmpopt_studies import humanoid

from dmpopt.control import (
    ComTask,
    FrameTask,
    InverseDynamicsController,
    PostureTask,
    SoleContact,
    control_loop,
)

try:
    from tsid_baseline import TsidWalking, build_tsid
except ImportError as error:  # TSID is optional: only its columns need it
    TsidWalking = build_tsid = None
    TSID_MISSING = str(error)

RIGHT, LEFT = "right_sole_link", "left_sole_link"
WAVE_FREQUENCY, WAVE_AMPLITUDE = 3.0, 0.05  # [Hz], [rad]
REMOVE_TICK, SWING_TICK, ONE_FOOT_TICK, RAMP = 1100, 1400, 1450, 0.25


class _GcWatch:
    """Garbage collections that start while ``inside`` is set: count, generation 2, longest
    (CPU time of the thread)."""

    def __init__(self):
        self.inside, self.count, self.gen2, self.longest, self._start = False, 0, 0, 0.0, None

    def __call__(self, phase, info):
        if phase == "start":
            self._start = time.thread_time() if self.inside else None
        elif self._start is not None:
            self.count += 1
            self.gen2 += info["generation"] == 2
            self.longest = max(self.longest, time.thread_time() - self._start)


# ---- scenarios: record(seconds, loop) -> ticks (loop: a context manager around the closed
# loop); dmpopt() / tsid() -> (set_targets, tick)


class Standing:
    """The humanoid study's standing controller; the arms follow ``arm_reference(k)``."""

    def __init__(self, robot, q_start, arm_reference, friction=0.7, com_step=None):
        self.robot, self.q_start, self.arm_reference = robot, q_start, arm_reference
        self.friction, self.com_step = friction, com_step
        self.com0 = pin.centerOfMass(robot.model, robot.create_data(), q_start) - [
            0, 0, humanoid._sink(robot)
        ]  # fmt: skip

    def _com_target(self, k):
        if self.com_step is None or k * humanoid.DT < 0.1:
            return self.com0
        return self.com0 + self.com_step

    def dmpopt(self):
        controller, arms = humanoid.build_controller(
            self.robot, self.q_start, friction=self.friction
        )
        com = next(task for task in controller.tasks if isinstance(task, ComTask))

        def set_targets(k, target):
            arms.set_reference(*target[0])
            com.set_target(target[1])

        return controller, set_targets, lambda q, v, t: controller.compute_torques(q, v)

    def tsid(self):
        controller, arms = build_tsid(self.robot, self.q_start, friction=self.friction)

        def set_targets(k, target):
            arms.set_reference(*target[0])
            controller.com.setReference(_tsid_sample(target[1]))

        return controller, set_targets, lambda q, v, t: controller.compute_torques(q, v)

    def record(self, seconds, loop):
        controller, set_targets, tick = self.dmpopt()
        simulator, q0 = humanoid.make_simulator(self.robot, self.q_start)
        state = simulator.reset(q0, self.v_start)
        ticks = []
        with loop():
            for k in range(int(round(seconds / humanoid.DT))):
                target = (self.arm_reference(k), self._com_target(k))
                set_targets(k, target)
                ticks.append((state.q.copy(), state.v.copy(), k * humanoid.DT, target))
                state = simulator.step(tick(state.q, state.v, None))
                assert not state.fallen, f"fell at tick {k}"
        return ticks

    v_start = None


def _tsid_sample(position):
    from tsid_baseline import _sample

    return _sample(position)


def drumming(seconds):
    robot = load_talos("full")
    dmps = humanoid.learn_drumming(humanoid.demonstrate_drumming())
    q_start = humanoid.drumming_posture(robot)
    q_start[robot.configuration_indices(list(humanoid.DRUM_JOINTS))] = dmps.start
    plan = humanoid.DrumPlan(dmps, humanoid.DT)
    references = []
    for k in range(int(round(seconds / humanoid.DT))):
        if k:
            plan.step()
        references.append((plan.position.copy(), plan.velocity.copy(), plan.acceleration.copy()))
    scenario = Standing(robot, q_start, references.__getitem__)
    scenario.v_start = np.zeros(robot.nv)
    scenario.v_start[robot.velocity_indices(list(humanoid.DRUM_JOINTS))] = dmps.start_velocity
    return scenario


def _wave(robot, **options):
    q_start = humanoid.drumming_posture(robot)
    centre = q_start[robot.configuration_indices(list(humanoid.DRUM_JOINTS))]

    def reference(k):
        omega, t = 2 * np.pi * WAVE_FREQUENCY, k * humanoid.DT
        a = WAVE_AMPLITUDE * np.ones(centre.size)
        s, c = np.sin(omega * t), np.cos(omega * t)
        return centre + a * s, a * omega * c, -a * omega**2 * s

    return Standing(robot, q_start, reference, **options)


def wave(seconds):
    robot = load_talos("full")
    weak = dataclasses.replace(robot, torque_limit=0.3 * np.asarray(robot.torque_limit))
    return _wave(weak)


def com_step(seconds):
    robot = load_talos("full")
    scenario = _wave(robot, friction=0.1, com_step=np.array([0.0, 0.03, -0.02]))
    centre = scenario.arm_reference(0)[0]
    scenario.arm_reference = lambda k: (centre, np.zeros(centre.size), np.zeros(centre.size))
    return scenario


class Walking:
    """Weight onto the left sole, the right contact removed, the right sole lifted."""

    def __init__(self):
        self.robot = robot = load_talos("full")
        self.stiffness = 2e4
        self.q0 = robot.reference_configuration.copy()
        self.q0[2] -= robot.mass * 9.81 / len(robot.contact_points) / self.stiffness
        data = robot.create_data()
        pin.framesForwardKinematics(robot.model, data, self.q0)
        self.c0 = pin.centerOfMass(robot.model, data, self.q0)
        self.left = data.oMf[robot.model.getFrameId(LEFT)].translation.copy()
        self.right0 = data.oMf[robot.model.getFrameId(RIGHT)].copy()

    def targets(self, k):
        t = k * humanoid.DT
        s = min(t, 1.0)
        com = np.r_[self.c0[:2] + s * s * (3 - 2 * s) * (self.left[:2] - self.c0[:2]), self.c0[2]]
        lift = 0.05 * np.sin(np.pi * min(max(t - 1.4, 0.0) / 1.2, 1.0)) ** 2
        swing = pin.SE3(self.right0.rotation, self.right0.translation + [0, 0, lift])
        return com, swing

    def dmpopt(self):
        robot = self.robot
        com = ComTask(robot, weight=10.0, stiffness=50.0)
        tasks = [
            PostureTask(robot, weight=0.1, stiffness=10.0),
            com,
            FrameTask(robot, "base_link", weight=1.0, stiffness=50.0, components="orientation"),
        ]
        contacts = [
            SoleContact(robot, f, max_normal_force=1500.0, cop_fraction=0.7)
            for f in robot.foot_frames
        ]
        controller = InverseDynamicsController(robot, tasks, contacts)
        swing = FrameTask(robot, RIGHT, weight=10.0, stiffness=400.0)
        swing.set_target(self.right0)
        if hasattr(controller, "prepare"):  # the contact sets of the walk, built before it
            controller.prepare([LEFT])
            controller.prepare([LEFT], tasks + [swing])

        def set_targets(k, target):
            com.set_target(target[0])
            if k == REMOVE_TICK:
                controller.remove_contact(RIGHT, transition_time=RAMP)
            if k == SWING_TICK:
                controller.add_task(swing)
            swing.set_target(target[1])

        return controller, set_targets, controller.compute_torques

    def tsid(self):
        controller = TsidWalking(self.robot, self.q0, 10.0, 400.0, 0.7, feet=(LEFT, RIGHT))

        def set_targets(k, target):
            if k == REMOVE_TICK:
                controller.remove_contact(RIGHT, RAMP)
            if k == SWING_TICK:
                controller.add_swing()
            controller.set_targets(*target)

        return controller, set_targets, controller.compute_torques

    def record(self, seconds, loop):
        from dmpopt.sim import GroundContact, Simulator

        robot = self.robot
        ground = GroundContact(stiffness=self.stiffness, damping=300.0, friction=1.0)
        simulator = Simulator(robot.model, humanoid.DT, robot.contact_points, ground)
        state = simulator.reset(self.q0)
        _, set_targets, tick = self.dmpopt()
        ticks = []
        with loop():
            for k in range(max(int(round(seconds / humanoid.DT)), 2600)):
                target = self.targets(k)
                set_targets(k, target)
                ticks.append((state.q.copy(), state.v.copy(), k * humanoid.DT, target))
                state = simulator.step(tick(state.q, state.v, k * humanoid.DT))
                assert not state.fallen, f"fell at tick {k}"
        return ticks


SCENARIOS = {
    "drumming": drumming,
    "wave": wave,
    "com-step": com_step,
    "walking": lambda seconds: Walking(),
}


def _watched(loop, watch: _GcWatch):
    """``loop`` (a context manager around a closed loop) with ``watch`` inside it: the
    collections of the loop itself, not control_loop's full collection on entry."""

    @contextlib.contextmanager
    def watched():
        with loop():
            watch.inside = True
            try:
                yield
            finally:
                watch.inside = False

    return watched


def replay(scenario, ticks, with_tsid: bool, watch: _GcWatch):
    """Both controllers on the recorded ticks, interleaved: CPU us per tick (dmpopt, TSID),
    dmpopt's answer per tick and whether its contact or task set changed on that tick."""
    sides = [scenario.dmpopt()] + ([scenario.tsid()] if with_tsid else [])
    cpu = np.zeros((len(sides), len(ticks)))
    answers, switched, last = [], [], None
    for k, (q, v, t, target) in enumerate(ticks):
        order = range(len(sides)) if k % 2 == 0 else reversed(range(len(sides)))
        for i in order:
            controller, set_targets, tick = sides[i]
            set_targets(k, target)
            watch.inside = i == 0
            begin = time.thread_time_ns()
            tick(q, v, t)
            cpu[i, k] = (time.thread_time_ns() - begin) / 1e3
            watch.inside = False
        controller = sides[0][0]
        answers.append(controller.stats.last_answer)
        sets = (controller.active_contacts, controller.tasks)
        switched.append(last is not None and sets != last)
        last = sets
    return cpu, answers, switched


STAGES = {  # (part of the QP, method): label
    ("Tick", "_tick"): "whole tick",
    ("Assembly", "assemble"): "model terms, task and contact rows, posture",
    ("Assembly", "_update_rows"): "  of which task and contact rows, posture",
    ("Assembly", "eliminated_tick"): "elimination and direct solve (level 0)",
    ("Assembly", "assemble_eliminated"): "elimination (levels 1, 2)",
    ("Assembly", "assemble_y"): "base elimination over y",
    ("Assembly", "assemble_torque_rows"): "torque rows",
    ("Assembly", "assemble_eliminated_torque_rows"): "torque rows over z",
    ("Tick", "_solve"): "QP solve (active set, proxsuite)",
}


def stage_timers(scenario, ticks) -> None:
    """CPU time per stage of dmpopt's ticks (mean us per tick; each stage inclusive of the
    ones it calls), on one replay: of the walk's one-foot ticks that need the QP, or of every
    tick of another scenario."""
    from dmpopt.control.assembly import Assembly
    from dmpopt.control.tick import Tick

    parts = {"Tick": Tick, "Assembly": Assembly}
    totals = {name: np.zeros(len(ticks)) for name in STAGES}
    current = [0]
    originals = {name: getattr(parts[name[0]], name[1]) for name in STAGES}

    def timed(name, method):
        def wrapper(self, *args):
            begin = time.thread_time_ns()
            try:
                return method(self, *args)
            finally:
                totals[name][current[0]] += (time.thread_time_ns() - begin) / 1e3

        return wrapper

    for name, method in originals.items():
        setattr(parts[name[0]], name[1], timed(name, method))
    try:
        controller, set_targets, tick = scenario.dmpopt()
        answers = []
        for k, (q, v, t, target) in enumerate(ticks):
            current[0] = k
            set_targets(k, target)
            tick(q, v, t)
            answers.append(controller.stats.last_answer)
    finally:
        for name, method in originals.items():
            setattr(parts[name[0]], name[1], method)
    if isinstance(scenario, Walking):
        mask = (np.arange(len(ticks)) >= ONE_FOOT_TICK) & (np.array(answers) != "direct")
        which = "the one-foot QP ticks"
    else:
        mask, which = np.ones(len(ticks), dtype=bool), "every tick"
    print(f"stage timers of {which} ({mask.sum()} ticks), mean CPU us per tick:")
    for name, label in STAGES.items():
        print(f"  {label:45s} {totals[name][mask].mean():7.1f}")


def gc_replays(names, seconds: float, replays: int, loop) -> None:
    """dmpopt alone on each scenario's recording, ``replays`` times (new controllers each
    time, in ``loop`` as the closed loop), watching Python's garbage collector through
    ``gc.callbacks``: the collections that start inside a tick (count, generation 2, longest
    [ms]) and those between ticks, the longest tick by thread CPU and by wall time (which counts
    waiting for a core on a busy machine too), and the ticks over 2 ms of CPU."""
    where = "without" if loop is contextlib.nullcontext else "in"
    print(f"{replays} replays of dmpopt per scenario, {where} control_loop")
    print(
        f"{'':16s} {'ticks':>6s} {'gc in ticks':>11s} {'gen 2':>5s} {'longest':>8s} "
        f"{'gc between':>10s} {'longest':>8s} {'max CPU':>8s} {'max wall':>8s} "
        f"{'CPU > 2 ms':>10s}"
    )
    for name in names:
        scenario = SCENARIOS[name](seconds)
        ticks = scenario.record(seconds, loop)
        inside, between = _GcWatch(), _GcWatch()  # collections started in / between ticks
        cpu, wall, started = [], [], [None]

        def watch(phase, info):  # a collection goes to the watch where it started
            if phase == "start":
                started[0] = inside if inside.inside else between
            started[0](phase, info)

        gc.callbacks.append(watch)
        try:
            for _ in range(replays):
                controller, set_targets, tick = scenario.dmpopt()
                with loop():  # its collection on entry is not counted
                    between.inside = True
                    for k, (q, v, t, target) in enumerate(ticks):
                        set_targets(k, target)
                        inside.inside = True
                        begin, begin_wall = time.thread_time_ns(), time.perf_counter_ns()
                        tick(q, v, t)
                        cpu.append(time.thread_time_ns() - begin)
                        wall.append(time.perf_counter_ns() - begin_wall)
                        inside.inside = False
                    between.inside = False
        finally:
            gc.callbacks.remove(watch)
        cpu, wall = np.array(cpu) / 1e6, np.array(wall) / 1e6  # [ms]
        print(
            f"{name:16s} {cpu.size:6d} {inside.count:11d} {inside.gen2:5d} "
            f"{1e3 * inside.longest:6.2f}ms {between.count:10d} {1e3 * between.longest:6.2f}ms "
            f"{cpu.max():6.2f}ms {wall.max():6.2f}ms {int((cpu > 2).sum()):10d}"
        )


def _counts(answers) -> dict:
    values, counts = np.unique(answers, return_counts=True)
    return {str(value): int(count) for value, count in zip(values, counts)}


def _row(name, d, t, target=""):
    text = f"{name:16s} {d.size:6d} {np.median(d):8.1f} {np.percentile(d, 99):7.1f} {d.max():8.1f}"
    if t is not None:
        text += f" {np.median(t):8.1f} {np.percentile(t, 99):7.1f} {t.max():8.1f}"
        text += f" {np.median(d) / np.median(t):6.2f} {np.percentile(d, 99) / np.median(t):9.2f}"
    print(f"{text}  {target}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated time [s]")
    parser.add_argument("--repeats", type=int, default=3, help="replays of each recording")
    parser.add_argument("--scenarios", nargs="*", default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument(
        "--stages", action="store_true",
        help="only the stage timers (the walk's one-foot QP ticks, every tick of the others)",
    )  # fmt: skip
    parser.add_argument(
        "--no-freeze", action="store_true",
        help="record the closed loops without dmpopt.control.control_loop (gc.freeze)",
    )  # fmt: skip
    parser.add_argument(
        "--gc-replays", type=int, default=0, metavar="N",
        help="only replay dmpopt N times per scenario, watching the garbage collector",
    )  # fmt: skip
    args = parser.parse_args()
    loop = contextlib.nullcontext if args.no_freeze else control_loop
    if args.gc_replays:
        gc_replays(args.scenarios, args.seconds, args.gc_replays, loop)
        return
    if args.stages:
        for name in args.scenarios:
            scenario = SCENARIOS[name](args.seconds)
            print(f"{name}:")
            stage_timers(scenario, scenario.record(args.seconds, loop))
        return
    with_tsid = build_tsid is not None
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}; pin {pin.__version__}")
    if not with_tsid:
        print(f"TSID columns skipped ({TSID_MISSING}); see the module docstring to install it")
    head = f"{'':16s} {'ticks':>6s} {'dmpopt med':>10s} {'p99':>6s} {'max':>8s}"
    if with_tsid:
        head += f" {'TSID med':>8s} {'p99':>7s} {'max':>8s} {'ratio':>6s} {'p99/T med':>9s}"
    print(head + "  [CPU us per tick]")
    for name in args.scenarios:
        scenario = SCENARIOS[name](args.seconds)
        in_loop = _GcWatch()  # every collection of the closed loop (controller and simulator)
        gc.callbacks.append(in_loop)
        try:
            ticks = scenario.record(args.seconds, _watched(loop, in_loop))
        finally:
            gc.callbacks.remove(in_loop)
        watch = _GcWatch()
        gc.callbacks.append(watch)
        try:
            runs = [replay(scenario, ticks, with_tsid, watch) for _ in range(args.repeats)]
        finally:
            gc.callbacks.remove(watch)
        cpu = np.concatenate([run[0] for run in runs], axis=1)
        answers = np.concatenate([run[1] for run in runs])
        switched = np.concatenate([run[2] for run in runs])
        tsid_cpu = cpu[1] if with_tsid else None
        index = np.arange(cpu.shape[1]) % len(ticks)
        if name != "walking":
            target = {"drumming": "[ratio <= 0.25]"}.get(name, "[p99/T med <= 1]")
            _row(name, cpu[0], tsid_cpu, target)
        else:
            rows = {
                "one foot": index >= ONE_FOOT_TICK,
                "one foot, QP": (index >= ONE_FOOT_TICK) & (answers != "direct"),
                "switch": switched,
            }
            targets = ("", "[ratio <= 0.8, p99 <= TSID p99]", "[max < 1000]")
            for (label, mask), target in zip(rows.items(), targets):
                _row(label, cpu[0][mask], None if tsid_cpu is None else tsid_cpu[mask], target)
        print(
            f"{'':16s} gc in dmpopt ticks: {watch.count} (generation 2: {watch.gen2}, longest "
            f"{1e3 * watch.longest:.2f} ms); answers {_counts(answers)}"
        )
        print(
            f"{'':16s} gc in the closed loop ({'without' if args.no_freeze else 'in'} "
            f"control_loop): {in_loop.count} (generation 2: {in_loop.gen2}, longest "
            f"{1e3 * in_loop.longest:.2f} ms)"
        )
        if name == "walking":
            stage_timers(scenario, ticks)
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}")


if __name__ == "__main__":
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # tiny matrices: threads only cost
        main()
