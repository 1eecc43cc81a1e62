"""Realistic plants of the two robots: the joint, actuator and sensor values of a real machine.

Sources and choices (each value is per joint; patterns as in :mod:`dmpopt.sim.plant`):

Talos (``talos_realistic``)
    damping 1 N m s/rad and Coulomb friction 1 N m on every joint: the values the Talos URDF
    (example-robot-data) gives its torso and arms (0.5 N m s/rad on the head), which its legs
    get too here (the URDF gives them 0, which no real gearbox has); a tenth of that on the
    gripper fingers. Armature: reflected rotor inertia of the MuJoCo-Menagerie class of humanoid
    models, 0.1 kg m^2 on the legs, torso and the first four arm joints (harmonic drives of
    ratio ~100 behind motors of 1e-5 kg m^2), 0.02 on the wrists and head, 0.005 on the gripper
    fingers; torque saturation at the URDF's effort limits; one tick (1 ms) of delay, an
    EtherCAT loop; noise: 19-bit joint encoders (1e-5 rad), differentiated and filtered joint
    speeds (0.005 rad/s), a base estimator's 1 mm and 1 mrad, 0.01 m/s, and a MEMS gyroscope's
    0.005 rad/s per tick.
Planar biped (``biped_realistic``)
    Talos's values scaled to its size as dynamic similarity (Froude) scales them, with the mass
    ratio 7 / 93 kg and the leg-length ratio 0.6: inertia as m l^2 (armature 0.1 -> 0.003
    kg m^2), torque as m l (friction 1 -> 0.045 N m), angular speed as l^-1/2 (damping 1 ->
    0.035 N m s/rad); torque saturation at its 40 N m, one tick of delay, the same sensor
    noise. (0.02 kg m^2 of armature, tried before, exceeds the hips' own apparent inertia of
    0.014 kg m^2: no real leg of this size has it.)
"""

from __future__ import annotations

from dmpopt.sim import PlantParameters, SensorNoise

__all__ = ["REALISTIC_NOISE", "biped_realistic", "realistic_plant", "talos_realistic"]

REALISTIC_NOISE = SensorNoise(
    joint_position=1e-5,
    joint_velocity=0.005,
    base_position=0.001,
    base_orientation=0.001,
    base_linear_velocity=0.01,
    base_angular_velocity=0.005,
)


def talos_realistic(robot, seed: int = 0) -> PlantParameters:
    """The realistic Talos plant (see the module notes) for ``robot`` (a Talos RobotModel)."""
    armature = {"*": 0.1, "arm_*_[5-7]_joint": 0.02, "head_*": 0.02}
    damping, friction = {"*": 1.0, "head_*": 0.5}, {"*": 1.0}
    if any(name.startswith("gripper_") for name in robot.actuated_joint_names):
        armature["gripper_*"] = 0.005
        damping["gripper_*"] = friction["gripper_*"] = 0.1
    limits = dict(zip(robot.actuated_joint_names, map(float, robot.torque_limit)))
    return PlantParameters(
        armature=armature,
        damping=damping,
        friction=friction,
        torque_limit=limits,
        delay=1,
        noise=REALISTIC_NOISE,
        seed=seed,
        name="talos_realistic",
    )


def biped_realistic(robot, seed: int = 0) -> PlantParameters:
    """The realistic planar-biped plant (see the module notes)."""
    limits = dict(zip(robot.actuated_joint_names, map(float, robot.torque_limit)))
    return PlantParameters(
        armature=0.003,
        damping=0.035,
        friction=0.045,
        torque_limit=limits,
        delay=1,
        noise=REALISTIC_NOISE,
        seed=seed,
        name="biped_realistic",
    )


def realistic_plant(robot, seed: int = 0) -> PlantParameters:
    """The realistic plant of a robot dmpopt ships (Talos or the planar biped), by its name."""
    if robot.name.startswith("talos"):
        return talos_realistic(robot, seed)
    if robot.name.startswith("planar_biped"):
        return biped_realistic(robot, seed)
    raise ValueError(f"no realistic plant for robot {robot.name!r}; build a PlantParameters")
