r"""The plant: what makes a simulated robot differ from the rigid-body model its controller uses.

A real joint is a motor behind a gearbox: its rotor inertia, reflected through the gear ratio
:math:`N`, adds the *armature* :math:`I_r N^2` to the joint's own inertia; bearings and gears add
viscous *damping* :math:`b \dot q` and dry (Coulomb) *friction* of magnitude :math:`f_c`; the
amplifier saturates at the motor's peak torque; the command reaches the motor some ticks after
the state it was computed from was read; and the encoders and the base estimator measure the
state with noise. :class:`PlantParameters` collects these, per joint, for both simulators:

.. math::

    (M(q) + \mathrm{diag}(I_a))\,\ddot q + h(q, \dot q) =
        \mathrm{sat}(\tau_{k-d}) - b \odot \dot q - f_c \odot \sigma(\dot q) + J^\top f

with :math:`d` the delay in ticks and :math:`\sigma` the sign (MuJoCo's ``frictionloss``, a
constraint that also holds the joint at rest; the native simulator regularises it, see
:class:`dmpopt.sim.Simulator`). The controller reads ``state.q_measured``/``v_measured``, the
true state plus seeded Gaussian noise; ``state.q``/``v`` stay the truth, for measuring.

Per-joint values are a number (every actuated joint) or a mapping from joint-name patterns
(``fnmatch``: ``"arm_*_[5-7]_joint"``) to numbers; later patterns override earlier ones, and
joints no pattern names get 0. :data:`IDEAL` is the plant that is exactly the controller's
model. Realistic presets per robot are in ``robots/plants.py``.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from typing import Mapping

import numpy as np
import pinocchio as pin

from dmpopt.exceptions import InvalidInputError
from dmpopt.sim.kernels import add_noise, apply_torques, scale_noise
from dmpopt.validation import real

__all__ = ["IDEAL", "PlantParameters", "SensorNoise", "base_joint_kind", "with_armature"]

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}
_PER_JOINT = ("armature", "damping", "friction")
_NO_FORCE = np.zeros(0)
NORMAL_BLOCK = 64  # ticks of sensor-noise normals drawn in one call


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of the measurement noise (white, Gaussian, per tick).

    Attributes
    ----------
    joint_position : float
        [rad or m] encoder noise of each actuated joint.
    joint_velocity : float
        [rad/s or m/s] noise of each joint velocity (a differentiated, filtered encoder).
    base_position : float
        [m] noise of the estimated base position (each axis).
    base_orientation : float
        [rad] noise of the estimated base orientation (a rotation vector, each axis).
    base_linear_velocity : float
        [m/s] noise of the estimated base linear velocity (each axis).
    base_angular_velocity : float
        [rad/s] gyroscope noise (each axis).
    """

    joint_position: float = 0.0
    joint_velocity: float = 0.0
    base_position: float = 0.0
    base_orientation: float = 0.0
    base_linear_velocity: float = 0.0
    base_angular_velocity: float = 0.0

    def __post_init__(self):
        for item in dataclasses.fields(self):
            value = real(
                f"noise.{item.name}",
                getattr(self, item.name),
                minimum=0.0,
                expected="a standard deviation >= 0",
            )
            object.__setattr__(self, item.name, value)

    @property
    def any(self) -> bool:
        """Whether any standard deviation is non-zero."""
        return any(getattr(self, item.name) > 0 for item in dataclasses.fields(self))

    def scaled(self, factor: float) -> SensorNoise:
        """Every standard deviation times ``factor``."""
        return SensorNoise(*(factor * getattr(self, f.name) for f in dataclasses.fields(self)))


@dataclass(frozen=True)
class PlantParameters:
    """Joint dynamics, actuators and sensors of a simulated robot (see the module notes).

    Parameters
    ----------
    armature : float or Mapping[str, float]
        Reflected rotor inertia of each actuated joint [kg m^2].
    damping : float or Mapping[str, float]
        Viscous damping [N m s/rad].
    friction : float or Mapping[str, float]
        Coulomb friction torque [N m] (MuJoCo's ``frictionloss``).
    torque_limit : None, float or Mapping[str, float]
        Saturation of the applied torque [N m]; None: no saturation at the plant.
    delay : int
        Ticks between the state a torque was computed from and the step it acts in (0: the
        torque acts in the step right after the state was read, as without a plant).
    noise : SensorNoise
        Measurement noise of ``state.q_measured`` and ``state.v_measured``.
    seed : int
        Seed of the noise.
    name : str
        A label for reports (``"ideal"``, ``"talos_realistic"``, ...).
    """

    armature: float | Mapping[str, float] = 0.0
    damping: float | Mapping[str, float] = 0.0
    friction: float | Mapping[str, float] = 0.0
    torque_limit: float | Mapping[str, float] | None = None
    delay: int = 0
    noise: SensorNoise = field(default_factory=SensorNoise)
    seed: int = 0
    name: str = "custom"

    def __post_init__(self):
        for name in (*_PER_JOINT, "torque_limit"):
            value = getattr(self, name)
            if value is None and name == "torque_limit":
                continue
            if isinstance(value, Mapping):
                checked = {}
                for pattern, number in value.items():
                    if not isinstance(pattern, str):
                        raise InvalidInputError(
                            f"{name} keys must be joint-name patterns (str), got {pattern!r}"
                        )
                    checked[pattern] = _non_negative(f"{name}[{pattern!r}]", number)
                object.__setattr__(self, name, dict(checked))
            else:
                object.__setattr__(self, name, _non_negative(name, value))
        if (
            isinstance(self.delay, (bool, np.bool_))
            or not isinstance(self.delay, (int, np.integer))
            or not 0 <= self.delay <= 1000
        ):
            raise InvalidInputError(
                f"delay must be a whole number of ticks in [0, 1000], got {self.delay!r}"
            )
        if not isinstance(self.noise, SensorNoise):
            raise InvalidInputError(
                f"noise must be a SensorNoise, got {type(self.noise).__name__}; pass "
                "SensorNoise(joint_position=..., ...)"
            )
        if isinstance(self.seed, (bool, np.bool_)) or not isinstance(self.seed, (int, np.integer)):
            raise InvalidInputError(f"seed must be an integer, got {self.seed!r}")

    @property
    def is_ideal(self) -> bool:
        """True if this plant is exactly the rigid-body model (no parameter set)."""
        return (
            all(not _any_positive(getattr(self, name)) for name in _PER_JOINT)
            and self.torque_limit is None
            and self.delay == 0
            and not self.noise.any
        )

    def values(self, name: str, joint_names) -> np.ndarray:
        """Per-joint values of ``name`` (``"armature"``, ..., ``"torque_limit"``) in the order of
        ``joint_names``; ``inf`` for ``torque_limit`` None or unmatched."""
        value = getattr(self, name)
        default = np.inf if name == "torque_limit" else 0.0
        if value is None:
            return np.full(len(joint_names), default)
        if not isinstance(value, Mapping):
            return np.full(len(joint_names), float(value))
        result = np.full(len(joint_names), default)
        for pattern, number in value.items():
            hits = [i for i, joint in enumerate(joint_names) if fnmatchcase(joint, pattern)]
            if not hits:
                raise InvalidInputError(
                    f"{name} pattern {pattern!r} matches no actuated joint; the joints are "
                    f"{list(joint_names)[:6]}... (fnmatch patterns, e.g. 'arm_*')"
                )
            result[hits] = number
        return result

    def scaled(self, **factors) -> PlantParameters:
        """A copy with parameters multiplied: ``scaled(armature=3, noise=2)`` (the delay is a
        whole number of ticks: ``dataclasses.replace(plant, delay=d)``)."""
        changes = {}
        for name, factor in factors.items():
            if name == "noise":
                changes[name] = self.noise.scaled(factor)
            elif name in (*_PER_JOINT, "torque_limit"):
                value = getattr(self, name)
                if isinstance(value, Mapping):
                    changes[name] = {k: factor * v for k, v in value.items()}
                else:
                    changes[name] = None if value is None else factor * value
            else:
                raise InvalidInputError(
                    f"scaled() got {name!r}; expected armature, damping, friction, "
                    "torque_limit or noise (set delay with dataclasses.replace)"
                )
        return dataclasses.replace(self, **changes)

    def describe(self, joint_names) -> dict:
        """The parameters as plain numbers per joint (for metrics files)."""
        return {
            "name": self.name,
            **{
                name: dict(zip(joint_names, self.values(name, joint_names).tolist()))
                for name in (*_PER_JOINT, "torque_limit")
            },
            "delay_ticks": int(self.delay),
            "noise": dataclasses.asdict(self.noise),
            "seed": int(self.seed),
        }


def _any_positive(value) -> bool:
    return any(v > 0 for v in value.values()) if isinstance(value, Mapping) else value > 0


def _non_negative(name: str, value) -> float:
    return real(name, value, minimum=0.0, expected="a finite number >= 0")


#: The plant that is exactly the controller's rigid-body model.
IDEAL = PlantParameters(name="ideal")


def with_armature(robot, plant: PlantParameters):
    """A copy of ``robot`` (a :class:`RobotModel`) whose model carries ``plant``'s armature on
    its actuated joints: the controller's nominal rotor inertia (Pinocchio adds it to the mass
    matrix, RNEA and ABA)."""
    model = pin.Model(robot.model)
    armature = np.zeros(model.nv)
    armature[robot.n_base :] = plant.values("armature", robot.actuated_joint_names)
    model.armature = armature
    return dataclasses.replace(robot, model=model)


def base_joint_kind(model: pin.Model):
    """``"free"``, a list of ``(kind, axis)`` (``kind`` "P" or "R") for a composite root, or
    None (fixed base)."""
    if model.njoints < 2:
        return None
    root = model.joints[1]
    name = root.shortname()
    if name == "JointModelFreeFlyer":
        return "free"
    if name != "JointModelComposite":
        if model.names[1] == "root_joint":
            raise InvalidInputError(
                f"root joint {name} is not supported; use a free flyer, a composite of "
                "one-axis joints, or a fixed base"
            )
        return None
    axes = []
    for joint in root.extract().joints:
        match = re.fullmatch(r"JointModel([PR])([XYZ])", joint.shortname())
        if match is None:
            raise InvalidInputError(
                f"composite root joint part {joint.shortname()} is not supported; use "
                "JointModelP{X,Y,Z} and JointModelR{X,Y,Z} parts"
            )
        axes.append((match.group(1), _AXES[match.group(2)]))
    return axes


class PlantRuntime:
    """The per-simulator state of a plant: the delay line and the noise generator.

    Parameters
    ----------
    parameters : PlantParameters
    model : pinocchio.Model
        The simulated robot (Pinocchio coordinates).
    base : "free", list of (kind, axis) or None
        The root joint (:func:`base_joint_kind`).
    joint_names : sequence of str
        The actuated joints, in the order of ``tau``.
    """

    def __init__(self, parameters: PlantParameters, model: pin.Model, base, joint_names):
        if not isinstance(parameters, PlantParameters):
            raise InvalidInputError(
                f"plant must be a PlantParameters, got {type(parameters).__name__}; pass e.g. "
                "dmpopt.sim.IDEAL or PlantParameters(armature=0.1, ...)"
            )
        self.parameters = parameters
        self.model = model
        self.joint_names = tuple(joint_names)
        for name in _PER_JOINT:
            setattr(self, name, parameters.values(name, self.joint_names))
        self.torque_limit = parameters.values("torque_limit", self.joint_names)
        n_base = model.nv - len(self.joint_names)
        noise = parameters.noise
        nq, nv = model.nq, model.nv
        self._free = base == "free"
        # one array (kernels.scale_noise): normals | q_std | v_std | rotation_std | noises
        n_draws = nq + nv + (3 if self._free else 0)
        self.noise = np.zeros(n_draws + 2 * (nq + nv) + 4)
        self._draws = self.noise[:n_draws]
        self._q_std = self.noise[n_draws : n_draws + nq]
        self._v_std = self.noise[n_draws + nq : n_draws + nq + nv]
        self._q_noise = self.noise[n_draws + nq + nv + 1 : n_draws + 2 * nq + nv + 1]
        self._v_noise = self.noise[n_draws + 2 * nq + nv + 1 : n_draws + 2 * (nq + nv) + 1]
        self._rotation_noise = self.noise[-3:]
        rotation_std = 0.0
        if self._free:
            self._q_std[:3], rotation_std = noise.base_position, noise.base_orientation
            self._v_std[:3], self._v_std[3:6] = (
                noise.base_linear_velocity,
                noise.base_angular_velocity,
            )
        elif base is not None:
            for k, (kind, _) in enumerate(base):
                positional = kind == "P"
                self._q_std[k] = noise.base_position if positional else noise.base_orientation
                self._v_std[k] = (
                    noise.base_linear_velocity if positional else noise.base_angular_velocity
                )
        self.noise[n_draws + nq + nv] = rotation_std
        base_noise = (
            noise.base_position,
            noise.base_orientation,
            noise.base_linear_velocity,
            noise.base_angular_velocity,
        )
        if n_base and base is None and any(base_noise):
            raise InvalidInputError(
                "base noise needs a free-flyer root joint or a composite of one-axis joints; "
                "set the base_* entries of SensorNoise to 0 for this robot"
            )
        n_base_q = model.nq - len(self.joint_names)
        self._q_std[n_base_q:] = noise.joint_position
        self._v_std[n_base:] = noise.joint_velocity
        self.noisy = noise.any
        self.reset()

    def reset(self) -> None:
        """Empty the delay line and restart the noise from the seed (the arrays stay in place:
        compiled steps hold their addresses)."""
        n = len(self.joint_names)
        if not hasattr(self, "line"):
            self.line = np.zeros((self.parameters.delay, n))  # the commands in flight, a ring
            self.ring = np.zeros(2, dtype=np.int64)  # the oldest command's row, line filled
        self.line[:], self.ring[:] = 0.0, 0
        self._applied = np.zeros(n)
        self._order = np.arange(n)
        self._rng = np.random.default_rng(self.parameters.seed)
        self._q_noise[:], self._v_noise[:], self._rotation_noise[:] = 0.0, 0.0, 0.0
        if not hasattr(self, "normals"):
            # the coming ticks' normals, drawn NORMAL_BLOCK ticks at a time: the same numbers
            # as one draw per tick (NumPy's Generator fills an array draw by draw)
            self.normals = np.zeros((NORMAL_BLOCK if self.noisy else 0, self._draws.size))
            self.next_row = np.zeros(1, dtype=np.int64)  # the row of the next tick's normals
        if self.noisy:
            self.next_row[0] = len(self.normals)
            self.draw_next()  # the first tick's normals

    def actuate(self, tau: np.ndarray) -> np.ndarray:
        """The torque the motors apply this step for the finite command ``tau``: saturated,
        then delayed by ``delay`` ticks (the first command is repeated until the line fills;
        :func:`dmpopt.sim.kernels.apply_torques`).

        Returns a buffer of this runtime, valid until the next call."""
        apply_torques(
            tau, _NO_FORCE, self.torque_limit, self.line, self.ring, self._applied,
            self._order, 0,
        )  # fmt: skip
        return self._applied

    def draw(self) -> None:
        """Turn this tick's normals into its measurement noise (once per step, so repeated
        reads agree; :func:`dmpopt.sim.kernels.scale_noise`), then draw the next tick's
        normals (:meth:`draw_next`)."""
        if not self.noisy:
            return
        scale_noise(self.noise, self.model.nq, self.model.nv, self._free)
        self.draw_next()

    def draw_next(self) -> None:
        """Draw the next tick's normals: those of q, of v, then of the base rotation (the next
        row of ``normals``, refilled when used up). They are drawn a tick ahead, so a step
        that raises before making its noise leaves the sequence as it was."""
        row = self.next_row[0]
        if row == len(self.normals):
            self._rng.standard_normal(out=self.normals)
            row = 0
        self._draws[:] = self.normals[row]
        self.next_row[0] = row + 1

    def measure(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The measured ``(q, v)``: the truth plus this tick's noise (a free base's orientation
        turned by the noise's rotation vector, in the base frame: ``R exp(noise)``)."""
        if not self.noisy:
            return q, v
        q_measured, v_measured = np.empty(q.size), np.empty(v.size)
        add_noise(q, v, self.noise, self._free, q_measured, v_measured)
        return q_measured, v_measured
