"""MujocoSimulator's compiled step with MuJoCo's C mj_step inside (dmpopt.sim.kernels_mujoco).

Answer key: the step through MuJoCo's Python bindings (``mj_step`` of the bindings, the contact
views, :func:`dmpopt.sim.kernels.settle`), whose every value
``tests/sim/test_mujoco_step.py`` checks against MuJoCo's ``mj_contactForce`` and Pinocchio.
Both paths do the same floating-point operations, so every value must agree bit for bit (no
tolerance). The offsets the compiled step reads ``mjData`` at are checked against the
bindings' own views of a data with contacts.
"""

import copy
import ctypes
import dataclasses
import os
import types

import numpy as np
import pinocchio as pin
import pytest
from dmpopt_robots.biped import BIPED_URDF

from dmpopt.exceptions import InvalidInputError, MissingDependency, ShapeError
from dmpopt.sim import MujocoSimulator, PlantParameters, SensorNoise, kernels_mujoco

os.environ.setdefault("MUJOCO_GL", "egl")
mujoco = pytest.importorskip("mujoco")

NOISY = PlantParameters(  # every branch of the step: saturation, delay, damping, noise
    damping=0.5,
    torque_limit=30.0,
    delay=2,
    noise=SensorNoise(*([1e-3] * 6)),
    seed=7,
)


def biped_simulator(biped, **options):
    return MujocoSimulator(
        biped.model, BIPED_URDF, contact_points=biped.contact_points,
        fall_frame=biped.torso_frame, plant=NOISY, **options,
    )  # fmt: skip


def run(sim, q0, n_steps, seed, frame):
    """Random torques and base forces, a push on ``frame`` from step 40: every step's state."""
    sim.reset(q0)
    rng = np.random.default_rng(seed)
    trace = []
    for k in range(n_steps):
        if k == 40:
            sim.push(frame, [30.0, 0.0, 0.0], 0.01)  # 10 steps through mj_step1/2
        tau, base_force = (
            rng.normal(scale=5.0, size=sim.n_actuated),
            rng.normal(size=sim.n_base_dofs),
        )
        state = sim.step(tau, base_force if k % 2 else None)
        trace.append(state)
        if state.fallen:
            break
    return trace


def assert_same(first, second):
    assert len(first) == len(second)
    for a, b in zip(first, second):
        for field in ("q", "v", "contact_forces", "in_contact", "contact_positions",
                      "q_measured", "v_measured"):  # fmt: skip
            x, y = getattr(a, field), getattr(b, field)
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), (a.t, field)
        assert a.t == b.t and a.fall == b.fall
        assert [(e.time, e.point, e.position.tobytes()) for e in a.touchdowns] == [
            (e.time, e.point, e.position.tobytes()) for e in b.touchdowns
        ]


def test_the_compiled_step_is_the_bindings_step_bit_for_bit(biped):
    """The walking study's biped (noisy, delayed, saturated plant), limp under random torques
    and base forces, pushed, until it falls: the compiled step and the bindings' step return
    the same bits at every step, through touchdowns, the push and the fall."""
    q0 = pin.neutral(biped.model)
    q0[1] = 0.62
    native = biped_simulator(biped)
    assert native.native_step_unavailable is None
    bindings = biped_simulator(biped)
    bindings._leave_native("the answer key")
    first, second = (run(sim, q0, 1500, 4, biped.torso_frame) for sim in (native, bindings))
    assert_same(first, second)
    assert first[-1].fallen and sum(len(s.touchdowns) for s in first) > 0
    assert native._advance is not None  # still compiled after the run
    # MuJoCo kept the data's memory in place through the resets and steps
    layout = kernels_mujoco.native_layout(mujoco, native.mj_model, native.mj_data)
    np.testing.assert_array_equal(native._native_arrays["layout"], layout)


def test_a_planar_base_force_in_any_form_steps_as_a_contiguous_float_array(biped):
    """The biped's planar base takes its force without a turn (checked inline in ``step``):
    a list, a strided view, an int array and the contiguous float array (the answer key: the
    same numbers, so the same bits) give the same states; a force of the wrong length or with
    a NaN is refused by name, not written past the base dofs."""
    q0 = pin.neutral(biped.model)
    q0[1] = 0.62
    forces = np.array([[3.0, -2.0, 1.0], [-1.0, 4.0, 0.0]])
    forms = (
        lambda f: f.copy(),
        lambda f: f.tolist(),
        lambda f: np.repeat(f, 2)[::2],  # strided: the same values, not contiguous
        lambda f: f.astype(np.int64),
    )
    traces = []
    for form in forms:
        sim = biped_simulator(biped)
        sim.reset(q0)
        tau = np.full(sim.n_actuated, 0.5)
        trace, kept = [], []
        for k in range(20):
            trace.append(sim.step(tau, form(forces[k % 2])))
            kept.append(copy.deepcopy(trace[-1]))  # what the step returned, as it returned it
        assert_same(trace, kept)  # a state a caller keeps is not changed by later steps
        traces.append(trace)
    for trace in traces[1:]:
        assert_same(traces[0], trace)
    with pytest.raises(ShapeError, match=r"base_force has shape \(2,\), expected \(3,\)"):
        sim.step(tau, np.zeros(2))
    with pytest.raises(InvalidInputError, match=r"base_force\[1\] is nan"):
        sim.step(tau, np.array([0.0, np.nan, 0.0]))


def test_a_free_base_steps_the_same_on_both_paths(talos):
    """Talos (free flyer: quaternion, base force turned to the world frame), 60 steps."""
    points = [(f, c) for f in talos.foot_frames for c in talos.sole_corners]
    sims = [
        MujocoSimulator(talos.model, talos.source, contact_points=points, plant=NOISY)
        for _ in range(2)
    ]
    sims[1]._leave_native("the answer key")
    q0 = pin.neutral(talos.model)
    q0[2] = 1.02
    first, second = (run(sim, q0, 60, 5, "base_link") for sim in sims)
    assert_same(first, second)
    assert any(state.in_contact.any() for state in first)


def test_without_addresses_the_simulator_steps_through_the_bindings(biped, monkeypatch):
    """A mujoco whose MjData gives no C address: the simulator says why and steps through
    the bindings, with the states of the compiled step."""
    real_layout = kernels_mujoco.native_layout

    def no_address(module, model, data):
        return real_layout(module, types.SimpleNamespace(), data)  # no _address

    monkeypatch.setattr(kernels_mujoco, "native_layout", no_address)
    fallback = biped_simulator(biped)
    monkeypatch.undo()
    assert "_address" in fallback.native_step_unavailable
    assert fallback._advance is None
    q0 = pin.neutral(biped.model)
    q0[1] = 0.62
    assert_same(*(run(s, q0, 80, 6, biped.torso_frame) for s in (fallback, biped_simulator(biped))))


def test_a_missing_shared_library_is_named(tmp_path):
    """No libmujoco in the package folder, or one the bindings did not load: the message
    names the folder or the file and what to do."""
    fake = types.SimpleNamespace(__file__=str(tmp_path / "__init__.py"), __version__="0")
    with pytest.raises(MissingDependency, match="no MuJoCo shared library .* in " + str(tmp_path)):
        kernels_mujoco.load_library(fake)
    (tmp_path / "libmujoco.so.0").write_bytes(b"not a library")
    with pytest.raises(MissingDependency, match="is not the one the mujoco bindings loaded"):
        kernels_mujoco.load_library(fake)


def test_a_layout_that_disagrees_with_the_bindings_is_refused():
    """An mjContact declared with its fields shifted: the check against the bindings' views
    names the fields that disagree."""
    data_type, contact_type = kernels_mujoco._ctypes_layout(mujoco)
    shifted = type("mjContact", (ctypes.Structure,), {
        "_fields_": [("padding", ctypes.c_double)] + list(contact_type._fields_)
    })  # fmt: skip
    with pytest.raises(MissingDependency, match="contact geom"):
        kernels_mujoco._check_layout(mujoco, data_type, shifted)
    kernels_mujoco._check_layout(mujoco, data_type, contact_type)  # the real one passes


def test_a_restored_snapshot_continues_as_the_run_from_the_start(biped):
    """Answer key: one uninterrupted run from reset (noisy, delayed plant; random torques and
    base forces; a push across the snapshot). A second run takes a snapshot at step 30, takes
    50 other steps (other torques, its own push, touchdowns, the plant's next block of noise
    draws), restores, and continues with the
    first run's inputs: every later state must be the first run's, bit for bit."""
    q0 = pin.neutral(biped.model)
    q0[1] = 0.62
    rng = np.random.default_rng(3)
    inputs = [(rng.normal(scale=5.0, size=4), rng.normal(size=3)) for _ in range(120)]
    sim = biped_simulator(biped)

    def steps(first, last, push_at, scale=1.0):
        states = []
        for k in range(first, last):
            if k == push_at:
                sim.push(biped.torso_frame, [30.0, 0.0, 0.0], 0.02)  # 20 steps
            tau, base_force = inputs[k]
            states.append(sim.step(scale * tau, base_force))
        return states

    sim.reset(q0)
    uninterrupted = steps(0, 120, push_at=20)
    sim.reset(q0)
    steps(0, 30, push_at=20)
    snapshot = sim.snapshot()
    detour = steps(30, 80, push_at=35, scale=-1.0)  # past a block of noise draws (64)
    restored = sim.restore(snapshot)
    assert detour[-1].q.tobytes() != uninterrupted[79].q.tobytes()  # the detour went elsewhere
    assert restored.q.tobytes() == uninterrupted[29].q.tobytes()
    assert restored.t == uninterrupted[29].t
    assert_same(steps(30, 120, push_at=-1), uninterrupted[30:])
    assert [e.time for e in sim.touchdown_events] == [
        e.time for state in uninterrupted for e in state.touchdowns
    ]
    with pytest.raises(InvalidInputError, match="snapshot"):
        sim.restore(uninterrupted[0])


@pytest.mark.parametrize("recycles", [True, False])
def test_what_a_caller_holds_of_a_state_no_later_step_changes(biped, monkeypatch, recycles):
    """The simulator recycles the objects of states nobody holds (module notes of
    ``mujoco_backend``, Returned states). Answer key: deep copies of what the caller holds,
    made when the step returned it: a whole state, one of its arrays, a view of one, a
    state rebuilt with ``dataclasses.replace``; 45 later steps must leave each as it was,
    bit for bit. Without reference counts (``recycles`` False, as on a free-threaded Python)
    every step makes new objects, with the same states."""
    if not recycles:
        monkeypatch.setattr(kernels_mujoco, "counts_references", lambda: False)
    sim = biped_simulator(biped)
    assert sim._recycles is recycles
    q0 = pin.neutral(biped.model)
    q0[1] = 0.62
    sim.reset(q0)
    rng = np.random.default_rng(8)
    held, keys = [], []
    for k in range(130):  # the feet touch down after step 60
        state = sim.step(rng.normal(scale=5.0, size=sim.n_actuated), rng.normal(size=3))
        kept = {
            66: state,
            68: state.q,
            71: state.contact_forces[:, 2],  # a view of a view of the slot's block
            74: state.in_contact,
            77: state.v_measured,
            80: dataclasses.replace(state, q=state.q_measured),
            83: state.q[1:4],
        }.get(k)
        if kept is not None:
            held.append(kept)
            keys.append(copy.deepcopy(kept))
    assert held[0].in_contact.any() and held[3].any() and held[2].any()  # forces read
    for item, key in zip(held, keys):
        if isinstance(item, np.ndarray):
            assert item.dtype == key.dtype and item.tobytes() == key.tobytes()
        else:
            assert_same([item], [key])


def test_the_usual_loop_recycles_its_states(biped, monkeypatch):
    """``state = sim.step(tau)`` holds only the last state during a step: no step of such a
    loop makes new objects (the speed of ``benchmarks/bench_mujoco.py --overhead`` rests on
    it), and each state is the one the bindings' path leaves (answer key: a simulator
    stepping through the bindings, read through its ``state`` property: copies of its
    buffers, not its slots)."""
    fresh = []
    original = MujocoSimulator._fresh_slot
    monkeypatch.setattr(
        MujocoSimulator, "_fresh_slot", lambda sim, slot: fresh.append(slot) or original(sim, slot)
    )
    sims = [biped_simulator(biped) for _ in range(2)]
    sims[1]._leave_native("the answer key")
    q0 = pin.neutral(biped.model)
    q0[1] = 0.62
    for sim in sims:
        sim.reset(q0)
    fresh.clear()
    rng = np.random.default_rng(9)
    state = None
    for _ in range(50):
        tau, force = rng.normal(scale=5.0, size=4), rng.normal(size=3)
        state = sims[0].step(tau, force)
        sims[1].step(tau, force)
        key = dataclasses.replace(sims[1].state, touchdowns=sims[1]._last_touchdowns)
        assert_same([state], [key])
    assert fresh == []
