r"""MuJoCo's C step called from compiled code: one call per step of :class:`MujocoSimulator`.

:func:`advance` writes the plant's torques (:func:`dmpopt.sim.kernels.apply_torques`), calls
MuJoCo's own ``mj_step`` of its shared library, and reads the result
(:func:`dmpopt.sim.kernels.settle`), so a step of :class:`dmpopt.sim.MujocoSimulator` makes
one compiled call instead of two calls and ``mj_step`` through the Python bindings (and the
views of the contacts those need).

How the compiled code reaches MuJoCo
    The Python bindings give the C address of a model and a data (``MjModel._address``,
    ``MjData._address``). The shared library the bindings use (``libmujoco.so*`` in the
    ``mujoco`` package, already loaded with them) is made known to numba's linker by path, and
    :func:`advance` calls its ``mj_step(const mjModel*, mjData*)`` by name (the two addresses
    passed as unsigned integers, as pointers are passed on the platforms MuJoCo supports), so
    the kernel stays cached on disk. What moves with each step (the number of contacts, the
    contacts and the constraint forces in MuJoCo's arena, the time, the warning counters) is
    read from the ``mjData`` struct and its arena at offsets from the struct declarations the
    ``mujoco`` package ships (``mujoco.introspect``), laid out by :mod:`ctypes`.
    :func:`native_layout` checks every offset it uses against the bindings' own views of a
    data with contacts; any difference, a ``mujoco`` without those declarations or without
    ``_address``, or a shared library not found raises
    :class:`dmpopt.exceptions.MissingDependency`, and the simulator then steps through the
    bindings (the same states, bit for bit).
Arguments
    A numba call costs about 70 ns per array argument, and more when its caches have gone
    cold between two steps, so :func:`advance` takes the torques, the base force and, as an
    integer, the address of one int64 array of the addresses and sizes of every other array
    it uses (:func:`array_table`:
    MuJoCo's arrays that stay in place, ``qpos``, ``qvel``, ``qfrc_applied``, ``site_xpos``,
    and the simulator's and the plant's buffers, allocated once), and makes arrays of them.
    Whoever builds the table keeps those arrays alive and in place. The table also holds the
    state slots of the simulator's returned states (:func:`enter_slot`, :func:`publish`).
Reference counts
    :func:`publish` reads the first word of a Python object at its address (``id``): in
    CPython with the GIL, its reference count (:func:`counts_references` checks that on a new
    object before the simulator relies on it). The compiled call holds the GIL, so no count
    changes while it reads.
Errors and warnings
    MuJoCo's warnings (counted in ``mjData.warning``, printed by MuJoCo) come out as through
    the bindings. A MuJoCo *error* inside ``mj_step`` (its stack or arena overflowing) is an
    exception through the bindings but would end the process here, so :func:`advance` reports
    a step whose stack and arena use (``maxuse_stack + maxuse_arena``) passed half the arena
    (``MEMORY_BOUND``), and the simulator steps through the bindings from then on. MuJoCo
    does not change the memory of an ``mjData`` after it is made (its arena included).
    :func:`advance` keeps Python's GIL while MuJoCo steps (the bindings release it): other
    Python threads wait the 10-100 us of a step, and no call pays for releasing and taking
    it back.
"""

from __future__ import annotations

import ctypes
import functools
import os
import sys
from pathlib import Path

import numba
import numpy as np
from llvmlite import binding as llvm
from numba import types
from numba.extending import intrinsic

from dmpopt.exceptions import MissingDependency
from dmpopt.sim.kernels import (
    N_BASE_DOFS,
    N_POINTS,
    N_Q,
    N_V,
    NOISY,
    QUATERNION_START,
    STATE_OK,
    TABLES_HEADER,
    apply_torques,
    settle,
)

__all__ = [
    "advance", "array_table", "counts_references", "enter_slot", "fill", "hold_words",
    "load_library", "native_layout", "publish", "timer_reading",
]  # fmt: skip

_compile = numba.njit(cache=True, nogil=False, error_model="numpy")

# advance's status beyond settle's: a non-finite torque or base force (nothing written)
STATE_BAD_INPUT = 3
MEMORY_BOUND = 0.5  # of the arena: above it, the simulator leaves the compiled mj_step

# native_layout's entries: offsets in the mjData struct (NCON, NEFC, WARNINGS and the size of
# an mjWarningStat in int32 words,
# the others in 8-byte words), in an mjContact (GEOM, EFC_ADDRESS in int32 words, FRAME, POS
# in 8-byte words), sizes in 8-byte words, and the addresses of the model, the data, the arena
(
    NCON, NEFC, WARNINGS, WARNING_SIZE, TIME, CONTACT, EFC_FORCE, MAXUSE_STACK, MAXUSE_ARENA,
    HEADER_WORDS, ARENA, ARENA_WORDS, CONTACT_SIZE, GEOM, EFC_ADDRESS, FRAME, POS, MODEL, DATA,
) = range(19)  # fmt: skip
LAYOUT_SIZE = 19
UNSTABLE_WARNINGS = 3  # MuJoCo's warnings BADQPOS, BADQVEL, BADQACC: the first of them ...
FIRST_UNSTABLE = 3  # ... is warning 3 (the simulator checks MuJoCo's numbering)

# advance's arrays, in this order (array_table)
ARRAYS = (
    "torque_limit", "line", "ring", "layout", "clock", "qpos", "qvel", "qfrc_applied",
    "site_xpos", "tables", "constants", "work", "flags", "noise", "normals", "next_row",
    "contact_time",
)  # fmt: skip
(
    TORQUE_LIMIT, LINE, RING, LAYOUT, CLOCK, QPOS, QVEL, QFRC_APPLIED, SITE_XPOS, TABLES,
    CONSTANTS, WORK, FLAGS, NOISE, NORMALS, NEXT_ROW, CONTACT_TIME,
) = range(len(ARRAYS))  # fmt: skip
# the returned states' slots, after ARRAYS in the table (enter_slot): per slot the block's
# address and size, how many objects, then each object's address and reference word
STATE_SLOTS, SLOT_OBJECTS = 2, 9
SLOT_WORDS = 3 + 2 * SLOT_OBJECTS
SLOTS = 2 * len(ARRAYS)  # the table entry of the first slot
TABLE_SIZE = SLOTS + STATE_SLOTS * SLOT_WORDS
NEVER = -1  # a reference word no object has: the slot counts as held at every step
# advance's events: what the caller does after a step (bits)
TOUCHDOWN, CHECK_FALL, MEMORY_FULL, DRAW, SLOT_HELD = 1, 2, 4, 8, 16
_TYPES = {
    "ring": np.int64, "layout": np.int64, "tables": np.int64, "flags": np.bool_,
    "next_row": np.int64,
}  # fmt: skip


_PROBE = """<mujoco><worldbody><geom type="plane" size="1 1 1"/>
<body pos="0 0 0.05"><freejoint/><geom size="0.1"/></body></worldbody></mujoco>"""

_mj_step = types.ExternalFunction("mj_step", types.void(types.uintp, types.uintp))
_clock_gettime = types.ExternalFunction("clock_gettime", types.int32(types.int32, types.uintp))
try:  # the benchmarks' clock of mj_step
    from time import CLOCK_THREAD_CPUTIME_ID as _CLOCK_THREAD_CPUTIME_ID
except ImportError:  # pragma: no cover - not a Unix: the clock reads nonsense
    _CLOCK_THREAD_CPUTIME_ID = 3


def load_library(mujoco) -> Path:
    """Make the shared library of the loaded ``mujoco`` package callable from compiled code.

    Returns
    -------
    Path
        The library.

    Raises
    ------
    MissingDependency
        If the package holds no ``libmujoco`` library, the library is not the one the bindings
        loaded, or it has no ``mj_step``; the message names the package directory.
    """
    folder = Path(mujoco.__file__).parent
    candidates = sorted(folder.glob("libmujoco.so*")) + sorted(folder.glob("libmujoco*.dylib"))
    if not candidates:
        raise MissingDependency(
            f"no MuJoCo shared library (libmujoco.so* or libmujoco*.dylib) in {folder}; "
            "install the mujoco wheel pinned by dmpopt[mujoco] (the simulator steps through "
            "the Python bindings without it)"
        )
    path = candidates[0]
    try:  # only the copy the bindings loaded (RTLD_NOLOAD): a second copy has its own state
        library = ctypes.CDLL(str(path), mode=os.RTLD_NOLOAD)
    except OSError as error:
        raise MissingDependency(
            f"the MuJoCo shared library {path} is not the one the mujoco bindings loaded "
            f"({error}); reinstall the mujoco package"
        ) from None
    if not hasattr(library, "mj_step"):
        raise MissingDependency(f"the MuJoCo shared library {path} has no mj_step")
    llvm.load_library_permanently(str(path))
    return path


def _ctypes_layout(mujoco):
    """``(mjData, mjContact)`` as :mod:`ctypes` structures, from ``mujoco.introspect``."""
    try:
        from mujoco.introspect import ast_nodes, structs
    except ImportError as error:
        raise MissingDependency(
            f"this mujoco {mujoco.__version__} has no struct declarations ({error})"
        ) from None
    values = {
        "int": ctypes.c_int, "float": ctypes.c_float, "mjtNum": ctypes.c_double,
        "mjtSize": ctypes.c_int64, "size_t": ctypes.c_size_t, "uintptr_t": ctypes.c_size_t,
        "uint64_t": ctypes.c_uint64, "mjtBool": ctypes.c_ubyte, "mjtByte": ctypes.c_ubyte,
    }  # fmt: skip
    made = {}

    def ctype(node):
        if isinstance(node, ast_nodes.PointerType):
            return ctypes.c_void_p
        if isinstance(node, ast_nodes.ArrayType):
            inner = ctype(node.inner_type)
            for extent in reversed(node.extents):
                inner = inner * int(extent)
            return inner
        if isinstance(node, ast_nodes.ValueType) and node.name in values:
            return values[node.name]
        if isinstance(node, ast_nodes.ValueType) and node.name in structs.STRUCTS:
            return struct(node.name)
        raise MissingDependency(f"mujoco's struct declarations hold a type {node} unknown here")

    def struct(name):
        if name not in made:
            fields = [(f.name, ctype(f.type)) for f in structs.STRUCTS[name].fields]
            made[name] = type(name, (ctypes.Structure,), {"_fields_": fields})
        return made[name]

    try:
        return struct("mjData"), struct("mjContact")
    except (KeyError, AttributeError, TypeError) as error:
        raise MissingDependency(
            f"this mujoco {mujoco.__version__}'s struct declarations lack a field ({error})"
        ) from None


def native_layout(mujoco, mj_model, mj_data) -> np.ndarray:
    """The offsets :func:`advance` reads ``mj_data`` at, checked, and the addresses it uses.

    Parameters
    ----------
    mujoco : module
    mj_model, mj_data : mujoco.MjModel, mujoco.MjData
        The simulator's.

    Returns
    -------
    ndarray of int64, shape (LAYOUT_SIZE,)
        The entries named in this module.

    Raises
    ------
    MissingDependency
        If the bindings give no addresses, the declarations are missing, or an offset disagrees
        with the bindings.
    """
    if not (hasattr(mj_model, "_address") and hasattr(mj_data, "_address")):
        raise MissingDependency(
            f"this mujoco {mujoco.__version__} does not give the C address of its MjModel and "
            "MjData (_address)"
        )
    data_type, contact_type = _checked_layout(mujoco)
    struct = data_type.from_address(mj_data._address)
    if struct.arena % 8:
        raise MissingDependency("MuJoCo's arena is not aligned to 8 bytes")
    warning = type(struct.warning[0])
    layout = np.zeros(LAYOUT_SIZE, dtype=np.int64)
    layout[NCON], layout[NEFC] = data_type.ncon.offset // 4, data_type.nefc.offset // 4
    layout[WARNINGS] = (
        data_type.warning.offset + FIRST_UNSTABLE * ctypes.sizeof(warning) + warning.number.offset
    ) // 4
    layout[WARNING_SIZE] = ctypes.sizeof(warning) // 4
    layout[TIME], layout[CONTACT] = data_type.time.offset // 8, data_type.contact.offset // 8
    layout[EFC_FORCE] = data_type.efc_force.offset // 8
    layout[MAXUSE_STACK] = data_type.maxuse_stack.offset // 8
    layout[MAXUSE_ARENA] = data_type.maxuse_arena.offset // 8
    layout[HEADER_WORDS] = ctypes.sizeof(data_type) // 8
    layout[ARENA], layout[ARENA_WORDS] = struct.arena, struct.narena // 8
    layout[CONTACT_SIZE] = ctypes.sizeof(contact_type) // 8
    layout[GEOM] = contact_type.geom.offset // 4
    layout[EFC_ADDRESS] = contact_type.efc_address.offset // 4
    layout[FRAME], layout[POS] = contact_type.frame.offset // 8, contact_type.pos.offset // 8
    layout[MODEL], layout[DATA] = mj_model._address, mj_data._address
    return layout


def array_table(arrays: dict) -> np.ndarray:
    """The address and size of each array :func:`advance` takes (``ARRAYS``, in order), then
    room for ``STATE_SLOTS`` slots of returned states (:func:`enter_slot`), as one int64
    array. The arrays must live, in place, as long as the table is used."""
    table = np.zeros(TABLE_SIZE, dtype=np.int64)
    for k, name in enumerate(ARRAYS):
        array = arrays[name]
        expected = np.dtype(_TYPES.get(name, np.float64))
        if array.dtype != expected or not array.flags.c_contiguous:
            raise MissingDependency(  # pragma: no cover - the simulator's own arrays
                f"{name} must be a contiguous {expected} array, got {array.dtype} "
                f"(contiguous: {array.flags.c_contiguous})"
            )
        table[2 * k], table[2 * k + 1] = array.ctypes.data, array.size
    return table


def enter_slot(table: np.ndarray, slot: int, block: np.ndarray, objects) -> None:
    """Enter the block and the objects of state slot ``slot`` into an :func:`array_table`.

    ``block`` (contiguous float64) receives each step's state (:func:`publish`); ``objects``
    (at most ``SLOT_OBJECTS``) are what a caller may hold of it: the returned state, the block
    and its views. Their reference words are read now, with no other holder
    (:func:`hold_words`, or ``NEVER`` where those words are not reference counts); all must
    live, in place, while entered."""
    if block.dtype != np.float64 or not block.flags.c_contiguous:
        raise MissingDependency(  # pragma: no cover - the simulator's own blocks
            f"a state block must be a contiguous float64 array, got {block.dtype}"
        )
    at = SLOTS + slot * SLOT_WORDS
    table[at : at + 3] = block.ctypes.data, block.size, len(objects)
    table[at + 3 : at + 3 + 2 * len(objects) : 2] = [id(item) for item in objects]
    table[at + 4 : at + 4 + 2 * len(objects) : 2] = NEVER


def counts_references() -> bool:
    """Whether an object's first word is its reference count (CPython with the GIL: the
    simulator then recycles slots nobody holds), checked on a new object: one more
    reference adds one to the word, and dropping it takes it back."""
    if getattr(sys, "_is_gil_enabled", lambda: True)() is False:
        return False  # a free-threaded CPython keeps its counts elsewhere
    probe = np.zeros(1)
    words = np.zeros(3, dtype=np.int64)
    address = np.array([id(probe)], dtype=np.int64)
    _read_word(address, words, 0)
    holder = [probe]
    _read_word(address, words, 1)
    holder.clear()
    _read_word(address, words, 2)
    return bool(words[1] == words[0] + 1 and words[2] == words[0])


@_compile
def _read_word(addresses, words, k):
    """``words[k]``: the first word of the object at ``addresses[0]``."""
    words[k] = numba.carray(_pointer(addresses[0], np.int64), 1)[0]


@_compile
def hold_words(arrays, slot):
    """Record the reference words of state slot ``slot``'s objects as they are now."""
    at = SLOTS + slot * SLOT_WORDS
    for k in range(arrays[at + 2]):
        address = arrays[at + 3 + 2 * k]
        arrays[at + 4 + 2 * k] = numba.carray(_pointer(address, np.int64), 1)[0]


@functools.cache
def _checked_layout(mujoco):
    """:func:`_ctypes_layout`, checked against the bindings (:func:`_check_layout`), once
    per ``mujoco`` module."""
    data_type, contact_type = _ctypes_layout(mujoco)
    if ctypes.sizeof(data_type) % 8 or ctypes.sizeof(contact_type) % 8:
        raise MissingDependency("mjData or mjContact is not laid out in 8-byte words")
    _check_layout(mujoco, data_type, contact_type)
    return data_type, contact_type


def _check_layout(mujoco, data_type, contact_type) -> None:
    """Every offset :func:`advance` uses against the bindings' reading, on the data of a ball
    sunk into the floor (contacts and constraint forces; the layout does not depend on the
    model)."""
    model = mujoco.MjModel.from_xml_string(_PROBE)
    data = mujoco.MjData(model)
    data.time = 0.125
    mujoco.mj_forward(model, data)
    struct = data_type.from_address(data._address)
    contacts = data.contact
    if data.ncon == 0 or data.nefc == 0:
        raise MissingDependency("the layout check found no contact to check against")
    found = {
        "ncon": (struct.ncon, data.ncon),
        "nefc": (struct.nefc, data.nefc),
        "time": (struct.time, data.time),
        "qpos": (struct.qpos, data.qpos.ctypes.data),
        "efc_force": (struct.efc_force, data.efc_force.ctypes.data),
        "contact geom": (struct.contact + contact_type.geom.offset, contacts.geom.ctypes.data),
        "contact pos": (struct.contact + contact_type.pos.offset, contacts.pos.ctypes.data),
        "contact frame": (struct.contact + contact_type.frame.offset, contacts.frame.ctypes.data),
        "efc_address": (
            struct.contact + contact_type.efc_address.offset,
            contacts.efc_address.ctypes.data,
        ),
        "contact size": (ctypes.sizeof(contact_type), contacts.geom.strides[0]),
        "warnings": (
            ctypes.addressof(struct.warning[FIRST_UNSTABLE])
            + type(struct.warning[0]).number.offset,
            data.warning.number[FIRST_UNSTABLE:].ctypes.data,
        ),
        "warning size": (ctypes.sizeof(type(struct.warning[0])), data.warning.number.strides[0]),
        "arena": (struct.arena <= struct.contact < struct.arena + struct.narena, True),
        "efc in arena": (struct.arena <= struct.efc_force < struct.arena + struct.narena, True),
    }
    wrong = {name: pair for name, pair in found.items() if pair[0] != pair[1]}
    if wrong:
        raise MissingDependency(
            f"mujoco {mujoco.__version__}'s mjData differs from its declarations at {wrong}"
        )


@intrinsic
def _pointer(typingctx, address, dtype):
    """The integer ``address`` as a pointer to ``dtype`` (a NumPy scalar type)."""
    pointer = types.CPointer(dtype.instance_type)

    def codegen(context, builder, signature, arguments):
        return builder.inttoptr(arguments[0], context.get_value_type(pointer))

    return pointer(address, dtype), codegen


@_compile
def _array(arrays, k, dtype):
    """Array ``k`` of an :func:`array_table`, as a 1-D array of ``dtype``."""
    return numba.carray(_pointer(arrays[2 * k], dtype), arrays[2 * k + 1])


@_compile
def publish(arrays, slot):
    """:func:`fill` state slot ``slot`` unless someone holds a part of it (an object's
    reference word is not the recorded one): then False, and nothing written."""
    at = SLOTS + slot * SLOT_WORDS
    for k in range(arrays[at + 2]):
        address = arrays[at + 3 + 2 * k]
        if numba.carray(_pointer(address, np.int64), 1)[0] != arrays[at + 4 + 2 * k]:
            return False
    fill(arrays, slot)
    return True


@_compile
def fill(arrays, slot):
    """Copy the state a step left in ``work`` and ``flags`` (:func:`dmpopt.sim.kernels.settle`)
    into the block of state slot ``slot`` (:func:`enter_slot`): ``work`` as it is, then the
    ``in_contact`` flags as bytes."""
    at = SLOTS + slot * SLOT_WORDS
    work = _array(arrays, WORK, np.float64)
    numba.carray(_pointer(arrays[at], np.float64), work.size)[:] = work
    n_points = _array(arrays, TABLES, np.int64)[N_POINTS]
    in_contact = _array(arrays, FLAGS, np.bool_)[:n_points]
    numba.carray(_pointer(arrays[at] + 8 * work.size, np.bool_), n_points)[:] = in_contact


@_compile
def advance(tau, base_force, table, slot):
    """One step of the MuJoCo simulator: torques, MuJoCo's ``mj_step``, the read-out.

    Writes the torques as :func:`dmpopt.sim.kernels.apply_torques` (returns
    ``STATE_BAD_INPUT`` and does nothing else if it refuses them), calls ``mj_step`` on the
    model and data of the layout (:func:`native_layout`), then reads as
    :func:`dmpopt.sim.kernels.settle`, with MuJoCo's contacts, constraint forces and warning
    counters found through the layout.

    Parameters
    ----------
    tau, base_force : ndarray
        As :func:`dmpopt.sim.kernels.apply_torques`, contiguous or not; of the wrong length
        (``tau`` one entry per actuated dof, ``base_force`` none or one per base dof):
        ``STATE_BAD_INPUT``, nothing done.
    table : int
        The address of the :func:`array_table` (an int64 array of ``TABLE_SIZE``: one array
        argument fewer to convert) of the arrays named in ``ARRAYS`` and of the state slots:
        the plant's torque limits, delay line (rows of ``tau.size``) and ring, the layout,
        the clock (with ``clock[0]`` non-zero, ``clock[1]`` is set to the thread time of
        ``mj_step`` [s], for benchmarks), MuJoCo's ``qpos``, ``qvel``, ``qfrc_applied`` and
        ``site_xpos`` (rows of 3), :func:`~dmpopt.sim.kernels.settle`'s ``tables``,
        ``constants``, ``work``, ``flags`` and ``noise``, the plant's block of ``normals``
        and ``next_row`` (:class:`dmpopt.sim.PlantRuntime`), and ``contact_time``: the end
        of the last step with a contact [s] (NaN: none yet), updated here.
    slot : int
        The state slot the step's state is copied into (:func:`publish`), after a step in
        ``STATE_OK``.

    Returns
    -------
    status : int
        As :func:`dmpopt.sim.kernels.settle` (or ``STATE_BAD_INPUT`` above).
    time : float
        MuJoCo's time after the step [s].
    events : int
        Bits, after a step in ``STATE_OK``: ``TOUCHDOWN`` (some point started touching),
        ``CHECK_FALL`` (settle's ``check_fall``), ``MEMORY_FULL`` (the stack and arena use
        passed ``MEMORY_BOUND`` of the arena), ``DRAW`` (the plant's block of normals is used
        up: the caller draws the next tick's, :func:`_next_normals`), ``SLOT_HELD`` (someone
        holds a part of state slot ``slot``: nothing copied there, the caller makes new
        objects for it and fills them, :func:`fill`).
    """
    arrays = numba.carray(_pointer(table, np.int64), TABLE_SIZE)
    layout = _array(arrays, LAYOUT, np.int64)
    tables = _array(arrays, TABLES, np.int64)
    nq, nv, n_base = tables[N_Q], tables[N_V], tables[N_BASE_DOFS]
    if tau.size != nv - n_base or base_force.size not in (0, n_base):
        return STATE_BAD_INPUT, 0.0, 0
    qfrc_applied = _array(arrays, QFRC_APPLIED, np.float64)
    torque_limit = _array(arrays, TORQUE_LIMIT, np.float64)
    line = _array(arrays, LINE, np.float64).reshape(-1, tau.size)
    ring = _array(arrays, RING, np.int64)
    clock = _array(arrays, CLOCK, np.float64)
    dof_index = tables[TABLES_HEADER + nq : TABLES_HEADER + nq + nv]
    if not apply_torques(
        tau, base_force, torque_limit, line, ring, qfrc_applied, dof_index, n_base
    ):
        return STATE_BAD_INPUT, 0.0, 0
    if clock[0]:
        begin = _thread_time()
        _mj_step(layout[MODEL], layout[DATA])
        clock[1] = _thread_time() - begin
    else:
        _mj_step(layout[MODEL], layout[DATA])
    header = numba.carray(_pointer(layout[DATA], np.int64), layout[HEADER_WORDS])
    arena = numba.carray(_pointer(layout[ARENA], np.float64), layout[ARENA_WORDS])
    ints, reals = header.view(np.int32), header.view(np.float64)
    time = reals[layout[TIME]]
    stride = layout[WARNING_SIZE]
    warnings = ints[layout[WARNINGS] : layout[WARNINGS] + stride * UNSTABLE_WARNINGS : stride]
    ncon, nefc = ints[layout[NCON]], ints[layout[NEFC]]
    width = layout[CONTACT_SIZE]  # words of one mjContact
    start = (header[layout[CONTACT]] - layout[ARENA]) // 8
    contacts = arena[start : start + ncon * width].reshape(ncon, width)
    contact_ints = arena[start : start + ncon * width].view(np.int32).reshape(ncon, 2 * width)
    geom = contact_ints[:, layout[GEOM] : layout[GEOM] + 2]
    efc_address = contact_ints[:, layout[EFC_ADDRESS]]
    frame = contacts[:, layout[FRAME] : layout[FRAME] + 9]
    position = contacts[:, layout[POS] : layout[POS] + 3]
    first = (header[layout[EFC_FORCE]] - layout[ARENA]) // 8
    efc_force = arena[first : first + nefc]
    noise = _array(arrays, NOISE, np.float64)
    contact_time = _array(arrays, CONTACT_TIME, np.float64)
    status, any_contact, n_started, check_fall = settle(
        _array(arrays, QPOS, np.float64), _array(arrays, QVEL, np.float64), warnings, geom,
        efc_address, frame, position, efc_force,
        _array(arrays, SITE_XPOS, np.float64).reshape(-1, 3), tables,
        _array(arrays, CONSTANTS, np.float64), _array(arrays, WORK, np.float64),
        _array(arrays, FLAGS, np.bool_), noise, time, contact_time[0],
    )  # fmt: skip
    if status != STATE_OK:
        return status, time, 0
    if any_contact:
        contact_time[0] = time
    events = (TOUCHDOWN if n_started else 0) | (CHECK_FALL if check_fall else 0)
    used = header[layout[MAXUSE_STACK]] + header[layout[MAXUSE_ARENA]]
    if used > MEMORY_BOUND * 8 * layout[ARENA_WORDS]:
        events |= MEMORY_FULL
    next_row = _array(arrays, NEXT_ROW, np.int64)
    if not _next_normals(tables, noise, _array(arrays, NORMALS, np.float64), next_row):
        events |= DRAW
    if not publish(arrays, slot):
        events |= SLOT_HELD
    return status, time, events


@_compile
def _next_normals(tables, noise, normals, next_row):
    """The plant's :meth:`~dmpopt.sim.PlantRuntime.draw_next` while its block of normals
    lasts: the next row into the normals at the start of ``noise``. True if done or not
    needed (no noise), False if the block is used up (the caller draws)."""
    if not tables[NOISY]:
        return True
    n_draws = tables[N_Q] + tables[N_V] + (3 if tables[QUATERNION_START] >= 0 else 0)
    row = next_row[0]
    if row == normals.size // n_draws:
        return False
    for i in range(n_draws):
        noise[i] = normals[row * n_draws + i]
    next_row[0] = row + 1
    return True


@_compile
def _thread_time():
    """The calling thread's CPU time [s] (``clock_gettime``)."""
    spec = np.zeros(2, dtype=np.int64)
    _clock_gettime(_CLOCK_THREAD_CPUTIME_ID, spec.ctypes.data)
    return spec[0] + 1e-9 * spec[1]


@_compile
def timer_reading(clock):
    """``clock[1]``: what :func:`advance`'s timer reads around nothing [s] (its own cost)."""
    begin = _thread_time()
    clock[1] = _thread_time() - begin
