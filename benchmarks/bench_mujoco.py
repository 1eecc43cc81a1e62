"""Standing Talos drumming: the native simulator against the MuJoCo backend, same everything else.

Both runs use the humanoid study's pieces (:mod:`dmpopt_studies.humanoid`): the learned drumming
DMPs,
``build_controller`` (QP inverse dynamics at 1 kHz with the 12 DMP-driven arm joints as a
posture task, CoM, pelvis orientation and two sole contacts) and the same start state (the
drumming posture on the limit cycle). Only the plant differs:

- native: :class:`dmpopt.sim.Simulator`, compliant ground under the eight sole corners
  (20 kN/m, 300 N s/m, friction 1), as in the study;
- mujoco: :class:`dmpopt.sim.MujocoSimulator` from the same URDF, MuJoCo's soft contacts
  between the floor and a 5 mm sphere at each of the same eight sole corners, friction 1,
  no joint armature, damping or friction (the controller's model exactly).

Printed per backend: tracking RMS and max over the 12 arm joints [rad], whether the robot fell,
the mean vertical ground force over m g, the real-time factor of the whole loop (simulated
time / time of plan + controller + simulator) and of the simulator step alone, each by the
wall clock and by CPU time (process time for the loop, thread time for the step; the CPU
figures are the ones to compare on a loaded machine).

Then the planar biped of the walking study (:func:`dmpopt_studies.biped.walk`: DMP gait, PD, boom,
frequency adaptation) walks ``--biped-seconds`` on each backend: distance, heel strikes, the
adapted frequency, falls (``walk(..., backend=...)``).

First, the model agreement (the answer key of ``tests/sim/test_mujoco.py`` as numbers): over
``--states`` random states, the largest differences between Pinocchio and MuJoCo on the same
URDF in link positions [m] and rotation matrices, link velocities (local frame), the mass matrix
and the bias forces (relative to their largest entry), after the coordinate change.

Last, the step overhead (``--overhead`` prints only this): the CPU time (thread time) of
``MujocoSimulator.step`` against that of the ``mj_step`` it calls, on steps of the same run
drawn at random (seeded): a step is timed whole or times only its ``mj_step``, so neither
reading holds the other's timer (drawn, not alternate: the biped's DMP steps every 4th tick,
and the step after it finds colder caches). The ``mj_step`` is timed inside the step: in the
compiled call (:func:`dmpopt.sim.kernels_mujoco.advance`) by its own clock, on steps through
the Python bindings (a push, or no compiled call) by wrapping the simulator's ``mujoco``
module (``mj_step``, or ``mj_step1`` + ``mj_step2``); the timers' own costs (a reading
around nothing, two thread-time reads in a row), measured in the same run, are taken off. (Earlier
versions ran ``mj_step`` on a copy of the data beside the step: copying before the step
evicted the step's Python objects from the cache (the walking biped's step measured 85-95 us
after a copy, 50 us without), and a copy kept in step and run right after the step found
MuJoCo's code warm (its ``mj_step`` measured 13.5 us against 19 us inside the step). Then
one step held both timers: a cold clock inside the compiled call added about 1 us to the step
that its warm cost, taken off, did not cover.) For Talos drumming and the biped walking, each
on the ideal and the realistic plant (:mod:`dmpopt_robots.plants`). The ratio of the medians
is the overhead (the issue's bound: 1.5); the last column is the share of the timed steps
that went through the compiled call.

``--trace FILE`` records every state of a few runs (:func:`trace`) and ``--compare A B``
compares two such files bitwise: run ``--trace`` on the code before a change and after it.

Run: ``python benchmarks/bench_mujoco.py [--seconds 5] [--variant full] [--biped-seconds 10]
[--states 20] [--video FILE.webp] [--overhead] [--overhead-seconds 2] [--trace FILE]
[--compare A B]``.
"""

import argparse
import dataclasses
import random
import time
from contextlib import contextmanager

import numpy as np
import pinocchio as pin
from dmpopt_robots import load_talos
from dmpopt_robots.biped import BIPED_URDF, load_biped
from dmpopt_robots.plants import realistic_plant
from dmpopt_studies import biped as biped_study
from dmpopt_studies import humanoid

from dmpopt.sim import MujocoSimulator
from dmpopt.sim.kernels_mujoco import timer_reading

DT = humanoid.DT


def make_plant(backend: str, robot, q_start: np.ndarray, parameters=None):
    """The simulator of ``backend`` (same fall thresholds on both) and its start configuration;
    ``parameters``: the MuJoCo run's plant (default ideal)."""
    if backend == "native":
        return humanoid.make_simulator(robot, q_start)
    if parameters is None:
        return humanoid.mujoco_plant(friction=1.0)(robot, q_start)
    return humanoid.mujoco_plant(friction=1.0, parameters=parameters)(robot, q_start)


class _TimedMujoco:
    """The ``mujoco`` module with ``mj_step`` (and ``mj_step1`` + ``mj_step2``) timed in
    thread time: ``inner`` accumulates the time of the current step's calls."""

    def __init__(self, module):
        self._module, self.inner = module, 0.0

    def __getattr__(self, name):
        return getattr(self._module, name)

    def _timed(self, function, *args):
        begin = time.thread_time()
        function(*args)
        self.inner += time.thread_time() - begin

    def mj_step(self, model, data):
        self._timed(self._module.mj_step, model, data)

    def mj_step1(self, model, data):
        self._timed(self._module.mj_step1, model, data)

    def mj_step2(self, model, data):
        self._timed(self._module.mj_step2, model, data)


def _timer_costs(n: int = 2000) -> float:
    """[s], median: what the wrapped ``mj_step`` of a module whose ``mj_step`` does nothing
    reads (the timer's own cost in its reading)."""
    timed, inner = _TimedMujoco(_NoMujoco), []
    for _ in range(n):
        timed.inner = 0.0
        timed.mj_step(None, None)
        inner.append(timed.inner)
    return float(np.median(inner))


def _native_timer_costs(n: int = 2000) -> float:
    """[s], median: what the timer of the compiled step's ``mj_step``
    (:func:`dmpopt.sim.kernels_mujoco.advance`) reads around nothing."""
    clock, inner = np.zeros(2), []
    for _ in range(n):
        timer_reading(clock)
        inner.append(clock[1])
    return float(np.median(inner))


def _thread_time_cost(n: int = 2000) -> float:
    """[s], median: what two reads of the thread time with nothing between them differ by."""
    readings = []
    for _ in range(n):
        begin = time.thread_time()
        readings.append(time.thread_time() - begin)
    return float(np.median(readings))


class _NoMujoco:
    """A ``mujoco`` whose ``mj_step`` does nothing (the timer's own cost)."""

    @staticmethod
    def mj_step(model, data):
        pass


@contextmanager
def step_timer():
    """Time ``MujocoSimulator.step`` and the ``mj_step`` it calls, each on half the steps
    drawn at random (see the module notes); yields the lists of thread times [s] of the
    steps, of the ``mj_step`` calls and whether each went through the compiled call, filled as
    the steps run (raw: the timers' own costs are taken off in :func:`overhead`)."""
    original = MujocoSimulator.step
    steps, mj_steps, paths, mj_paths = [], [], [], []
    roles = random.Random(0)  # not alternate: the biped's DMP steps every 4th tick

    def timed(simulator, tau, base_force=None):
        module = simulator._mj
        if isinstance(module, _TimedMujoco):
            module = module._module
        inner = roles.random() < 0.5  # this step times its mj_step, else itself
        native = getattr(simulator, "_advance", None) is not None and not simulator._pushes
        simulator._mj = _TimedMujoco(module) if inner and not native else module
        if native:
            simulator._clock[:] = float(inner), 0.0  # advance times its mj_step
        begin = time.thread_time()
        state = original(simulator, tau, base_force)
        elapsed = time.thread_time() - begin
        if not inner:
            steps.append(elapsed)
            paths.append(native)
        elif native:
            mj_steps.append(simulator._clock[1])
            mj_paths.append(True)
        else:
            mj_steps.append(simulator._mj.inner)
            mj_paths.append(False)
        return state

    MujocoSimulator.step = timed
    try:
        yield steps, mj_steps, paths, mj_paths
    finally:
        MujocoSimulator.step = original


def overhead(robot, dmps, biped, talos_seconds: float, biped_seconds: float) -> dict:
    """Median CPU time per step of ``MujocoSimulator.step`` and of ``mj_step`` [us], and their
    ratio, for Talos drumming and the biped walking on the ideal and the realistic plant."""
    _, gait = biped_study.learn_gait()
    rows = {}
    for plant in ("ideal", "realistic"):
        with step_timer() as timings:
            parameters = realistic_plant(robot) if plant == "realistic" else None
            run("mujoco", robot, dmps, talos_seconds, parameters=parameters)
        rows[f"talos {plant}"] = timings
        with step_timer() as timings:
            parameters = realistic_plant(biped) if plant == "realistic" else None
            biped_study.walk(
                biped, gait, biped_seconds, biped_study.DEMO_FREQUENCY, plant=parameters
            )
        rows[f"biped {plant}"] = timings
    inner = {False: _timer_costs(), True: _native_timer_costs()}
    outer = _thread_time_cost()
    table = {}
    for name, (steps, mj_steps, paths, mj_paths) in rows.items():
        steps = np.asarray(steps) - outer  # the timer around the step
        mj_steps = np.asarray(mj_steps) - np.where(mj_paths, inner[True], inner[False])
        step, mj_step = 1e6 * np.median(steps), 1e6 * np.median(mj_steps)
        table[name] = {
            "steps": len(steps),
            "step_us": step,
            "mj_step_us": mj_step,
            "ratio": step / mj_step,
            "mean_ratio": float(np.sum(steps) / np.sum(mj_steps)),
            "native": float(np.mean(paths)),
            "mj_steps": len(mj_steps),
        }
    return table


def print_overhead(table: dict) -> None:
    print("MujocoSimulator.step against mj_step, median thread time per step")
    header = (
        ("steps", 7), ("step [us]", 11), ("mj_step [us]", 14), ("ratio", 7), ("(means)", 9),
        ("compiled mj_step", 18),
    )  # fmt: skip
    print(f"{'':18s}" + "".join(f"{label:>{width}s}" for label, width in header))
    for name, row in table.items():
        print(
            f"{name:18s}{row['steps']:7d}{row['step_us']:11.1f}{row['mj_step_us']:14.1f}"
            f"{row['ratio']:7.2f}{row['mean_ratio']:9.2f}{row['native']:17.0%}"
        )


def run(backend: str, robot, dmps, seconds: float, video_every: int = 0, parameters=None) -> dict:
    """Drum for ``seconds`` on ``backend``; tracking, falls, timing and recorded frames."""
    q_start = humanoid.drumming_posture(robot)
    q_start[robot.configuration_indices(list(humanoid.DRUM_JOINTS))] = dmps.start
    v_start = np.zeros(robot.nv)
    v_start[robot.velocity_indices(list(humanoid.DRUM_JOINTS))] = dmps.start_velocity
    controller, task = humanoid.build_controller(robot, q_start)
    plan = humanoid.DrumPlan(dmps, DT)
    simulator, q0 = make_plant(backend, robot, q_start, parameters)
    state = simulator.reset(q0, v_start)
    joints = robot.configuration_indices(list(humanoid.DRUM_JOINTS))
    n = int(round(seconds / DT))
    error = np.empty((n, joints.size))
    vertical = np.empty(n)
    frames, fell, sim_wall, sim_cpu = [], False, 0.0, 0.0
    begin, cpu_begin = time.perf_counter(), time.process_time()
    for k in range(n):
        if k:
            plan.step()
        task.set_reference(plan.position, plan.velocity, plan.acceleration)
        tau = controller.compute_torques(state.q, state.v)
        error[k] = state.q[joints] - plan.position
        step_begin, step_cpu = time.perf_counter(), time.thread_time()
        state = simulator.step(tau)
        sim_cpu += time.thread_time() - step_cpu
        sim_wall += time.perf_counter() - step_begin
        vertical[k] = state.contact_forces[:, 2].sum()
        if video_every and k % video_every == 0:
            frames.append(state.q)
        if state.fallen:  # the simulation stops at a fall
            fell, n = True, k + 1
            break
    wall, cpu = time.perf_counter() - begin, time.process_time() - cpu_begin
    weight = pin.computeTotalMass(robot.model) * 9.81
    return {
        "tracking_rms_rad": float(np.sqrt(np.mean(error[:n] ** 2))),
        "tracking_max_rad": float(np.abs(error[:n]).max()),
        "fell": fell,
        "vertical_force_over_weight": float(vertical[:n].mean() / weight),
        "real_time_factor": n * DT / wall,
        "real_time_factor_cpu": n * DT / cpu,
        "simulator_real_time_factor": n * DT / sim_wall,
        "simulator_real_time_factor_cpu": n * DT / sim_cpu,
        "frames": frames,
        "simulator": simulator,
    }


def walk_biped(backend: str, seconds: float) -> dict:
    """The walking study's biped on ``backend`` for ``seconds``."""
    biped = load_biped()
    _, dmp = biped_study.learn_gait()
    log = biped_study.walk(biped, dmp, seconds, biped_study.DEMO_FREQUENCY, backend=backend)
    return {
        "distance_m": log.distance,
        "heel_strikes": len(log.strikes),
        "final_frequency_rad_s": log.frequencies[-1],
        "fell": log.fell,
        "real_time_factor": log.duration / log.wall_time,
        "real_time_factor_cpu": log.duration / log.cpu_time,
    }


def agreement(simulator, n_states: int, seed: int = 0) -> dict:
    """Worst Pinocchio-MuJoCo differences over random states (see the module docstring)."""
    import mujoco  # after MujocoSimulator has defaulted MUJOCO_GL to egl (headless video)

    model, mj_model, mj_data = simulator.model, simulator.mj_model, simulator.mj_data
    data = model.createData()
    rng = np.random.default_rng(seed)
    free = simulator.n_base_dofs == 6
    worst = dict.fromkeys(("position_m", "rotation", "velocity", "mass_rel", "bias_rel"), 0.0)
    bodies = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
    lower = np.where(np.abs(model.lowerPositionLimit) < 1e10, model.lowerPositionLimit, -1)
    upper = np.where(np.abs(model.upperPositionLimit) < 1e10, model.upperPositionLimit, 1)
    for _ in range(n_states):
        q = pin.randomConfiguration(model, lower, upper)
        v = rng.normal(size=model.nv)
        simulator.reset(q, v)
        q = simulator.state.q  # normalised quaternion
        mujoco.mj_forward(mj_model, mj_data)
        pin.forwardKinematics(model, data, q, v)
        pin.updateFramePlacements(model, data)
        for name in bodies:
            body, frame = mj_model.body(name).id, model.getFrameId(name)
            velocity, mj_velocity = pin.getFrameVelocity(model, data, frame), np.empty(6)
            mujoco.mj_objectVelocity(
                mj_model, mj_data, mujoco.mjtObj.mjOBJ_XBODY, body, mj_velocity, 1
            )
            errors = {
                "position_m": mj_data.xpos[body] - data.oMf[frame].translation,
                "rotation": mj_data.xmat[body].reshape(3, 3) - data.oMf[frame].rotation,
                "velocity": mj_velocity - np.r_[velocity.angular, velocity.linear],
            }
            for key, error in errors.items():
                worst[key] = max(worst[key], float(np.abs(error).max()))
        T = np.zeros((mj_model.nv, model.nv))  # qvel_mujoco = T v, joints matched by name
        for joint_id in range(2 if simulator.n_base_dofs else 1, model.njoints):
            address = mj_model.joint(model.names[joint_id]).dofadr[0]
            T[address, model.joints[joint_id].idx_v] = 1.0
        for k in range(simulator.n_base_dofs):  # the base: free joint or planar joints
            name = model.names[1] if free else f"{model.names[1]}_{k}"
            T[mj_model.joint(name).dofadr[0] + (k if free else 0), k] = 1.0
        t_dot_v = np.zeros(mj_model.nv)
        if free:  # linear velocity: local in Pinocchio, world in MuJoCo
            rotation = pin.Quaternion(q[3:7]).toRotationMatrix()
            T[:3, :3] = rotation
            t_dot_v[:3] = rotation @ np.cross(v[3:6], v[:3])
        mass = np.zeros((mj_model.nv, mj_model.nv))
        mujoco.mj_fullM(mj_model, mj_data, mass)
        crba = pin.crba(model, data, q)
        crba = np.triu(crba) + np.triu(crba, 1).T
        rnea = pin.rnea(model, data, q, v, np.zeros(model.nv))
        bias = T.T @ (mj_data.qfrc_bias + mass @ t_dot_v)
        mass_error = np.abs(T.T @ mass @ T - crba).max() / np.abs(crba).max()
        worst["mass_rel"] = max(worst["mass_rel"], float(mass_error))
        bias_error = np.abs(bias - rnea).max() / np.abs(rnea).max()
        worst["bias_rel"] = max(worst["bias_rel"], float(bias_error))
    return worst


def print_table(title: str, results: dict) -> None:
    """Rows of numbers, one column per backend."""
    print(title)
    print(f"{'':32s}{'native':>12s}{'mujoco':>12s}")
    for key, value in results["native"].items():
        if isinstance(value, (bool, int, float)):
            values = [results[b][key] for b in ("native", "mujoco")]
            print(
                f"{key:32s}"
                + "".join(f"{v!s:>12s}" if isinstance(v, bool) else f"{v:12.4g}" for v in values)
            )


def trace(robot, dmps, biped, path) -> None:
    """Record every state ``MujocoSimulator.step`` returns in a few runs into ``path`` (a
    pickle): Talos drumming 1 s and the biped walking 2 s with a push, each on the ideal and
    the realistic plant; Talos limp under random torques and base forces (ideal) and limp
    (realistic), pushed, until it falls; the biped limp (realistic) until it falls; Talos
    diverging. Two traces of the same code are equal bitwise (``--compare``): one of the code
    before a change and one after show that it kept every value."""
    import pickle

    original, runs, steps = MujocoSimulator.step, {}, []

    def recording(simulator, tau, base_force=None):
        try:
            state = original(simulator, tau, base_force)
        except Exception as error:
            steps.append(("raised", type(error).__name__, str(error)))
            raise
        again = simulator.state
        steps.append(
            (dataclasses.astuple(state), again.q, again.q_measured,
             np.array(simulator.mj_data.qfrc_applied))
        )  # fmt: skip
        return state

    def limp(parameters, base_force):
        simulator, q0 = make_plant("mujoco", robot, humanoid.drumming_posture(robot), parameters)
        simulator.reset(q0)
        rng = np.random.default_rng(1)
        for k in range(3000):
            force = rng.normal(size=6) * 20 if base_force else None
            if simulator.step(rng.normal(size=simulator.n_actuated) * 0.2, force).fallen:
                break
            if k == 100:
                simulator.push("base_link", [60.0, 0, 0], 0.2)

    def biped_limp():
        simulator = biped_study.walker.make_simulator(biped, "mujoco", realistic_plant(biped), None)
        q = pin.neutral(biped.model)
        q[1] = 0.62
        simulator.reset(q)
        rng = np.random.default_rng(2)
        for _ in range(3000):
            if simulator.step(rng.normal(size=simulator.n_actuated), rng.normal(size=3)).fallen:
                break

    def diverge():
        simulator, q0 = make_plant("mujoco", robot, humanoid.drumming_posture(robot))
        simulator.step(np.full(simulator.n_actuated, 1e4))

    _, gait = biped_study.learn_gait()
    scenarios = {}
    for plant in ("ideal", "realistic"):
        talos_plant = realistic_plant(robot) if plant == "realistic" else None
        biped_plant = realistic_plant(biped) if plant == "realistic" else None
        scenarios[f"talos {plant}"] = lambda p=talos_plant: run("mujoco", robot, dmps, 1.0,
                                                                 parameters=p)  # fmt: skip
        scenarios[f"biped {plant} push"] = lambda p=biped_plant: biped_study.walk(
            biped, gait, 2.0, biped_study.DEMO_FREQUENCY, push_impulse=8.0, push_time=0.5,
            plant=p,
        )  # fmt: skip
    scenarios["talos limp ideal"] = lambda: limp(None, True)
    scenarios["talos limp realistic"] = lambda: limp(realistic_plant(robot), False)
    scenarios["biped limp"] = biped_limp
    scenarios["talos diverges"] = diverge
    MujocoSimulator.step = recording
    try:
        for name, scenario in scenarios.items():
            steps.clear()
            try:
                scenario()
            except Exception:  # noqa: BLE001 - recorded in the trace
                pass
            runs[name] = list(steps)
            print(f"{name}: {len(steps)} steps")
    finally:
        MujocoSimulator.step = original
    with open(path, "wb") as file:
        pickle.dump(runs, file)


def compare(first, second) -> int:
    """Print, per run of two traces, how many steps differ in any bit; 0 if none."""
    import pickle

    def same(a, b) -> bool:
        if isinstance(a, np.ndarray):
            return isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape and (
                a.tobytes() == b.tobytes()
            )  # fmt: skip
        if isinstance(a, (tuple, list)):
            return type(a) is type(b) and len(a) == len(b) and all(map(same, a, b))
        if dataclasses.is_dataclass(a):
            return same(dataclasses.astuple(a), dataclasses.astuple(b))
        return a == b

    traces = []
    for path in (first, second):
        with open(path, "rb") as file:
            traces.append(pickle.load(file))
    differing = 0
    for name in sorted(set(traces[0]) | set(traces[1])):
        a, b = traces[0].get(name, []), traces[1].get(name, [])
        n = sum(not same(x, y) for x, y in zip(a, b)) + abs(len(a) - len(b))
        print(f"{name}: {len(a)} / {len(b)} steps, {n} differ")
        differing += n
    print("identical" if not differing else f"{differing} steps differ")
    return differing


def main():
    """Command line: run both backends and print the side-by-side table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated time [s]")
    parser.add_argument("--variant", default="full", choices=("full", "reduced"))
    parser.add_argument("--biped-seconds", type=float, default=10.0, help="walking time [s]")
    parser.add_argument("--states", type=int, default=20, help="random states for agreement")
    parser.add_argument("--video", help="write the MuJoCo run as an animated .webp or .gif")
    parser.add_argument("--overhead", action="store_true", help="only the step overhead")
    parser.add_argument(
        "--overhead-seconds", type=float, default=2.0, help="simulated time per overhead run [s]"
    )
    parser.add_argument("--trace", help="record the states of a few runs into this file")
    parser.add_argument("--compare", nargs=2, help="compare two --trace files bitwise")
    args = parser.parse_args()
    if args.compare:
        raise SystemExit(1 if compare(*args.compare) else 0)
    robot = load_talos(args.variant)
    biped = load_biped()
    if args.trace:
        trace(robot, humanoid.learn_drumming(humanoid.demonstrate_drumming()), biped, args.trace)
        return
    if args.overhead:
        dmps = humanoid.learn_drumming(humanoid.demonstrate_drumming())
        seconds = args.overhead_seconds
        print_overhead(overhead(robot, dmps, biped, seconds, seconds))
        return
    models = {
        # model agreement only: no floor needed (falls=False: floating is meant)
        f"talos_{args.variant}": MujocoSimulator(robot.model, robot.source, falls=False),
        "planar_biped": MujocoSimulator(biped.model, BIPED_URDF, falls=False),
    }
    print(f"Model agreement, worst over {args.states} random states (Pinocchio vs MuJoCo)")
    for name, simulator in models.items():
        worst = agreement(simulator, args.states)
        print(f"{name:14s}" + "  ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    dmps = humanoid.learn_drumming(humanoid.demonstrate_drumming())
    every = int(round(1 / (25 * DT))) if args.video else 0
    results = {b: run(b, robot, dmps, args.seconds, every) for b in ("native", "mujoco")}
    print_table(
        f"Talos {args.variant}, {args.seconds:g} s of standing drumming, dt = {DT} s", results
    )
    walks = {b: walk_biped(b, args.biped_seconds) for b in ("native", "mujoco")}
    print_table(f"Planar biped, {args.biped_seconds:g} s of walking", walks)
    print_overhead(overhead(robot, dmps, biped, args.overhead_seconds, args.overhead_seconds))
    if args.video:
        from dmpopt.sim import render_animation

        mujoco_run = results["mujoco"]
        path = render_animation(mujoco_run["simulator"], mujoco_run["frames"], args.video)
        print(f"video: {path} ({path.stat().st_size / 1e6:.2f} MB)")


if __name__ == "__main__":
    main()
