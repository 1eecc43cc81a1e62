r"""Biped walking with rhythmic DMPs, phase resetting and resonance tuning (Figs. 6-7).

Claim of [dmpopt-paper] Section 4.3: four phase-oscillator DMPs on one canonical system,
learned from a demonstrated gait and tracked by PD control, drive a planar five-link biped;
with phase resetting at heel strike and the frequency adaptation of eq. (21) the oscillator
frequency converges to a frequency set by the walker's own dynamics (its "resonance").

Set-up (all choices are ours, see ``robots/README.md``):

* robot: ``robots/biped.urdf`` (leg 0.6 m, 7 kg), planar base (x, z, pitch) on a simulated
  boom that holds the torso pitch with a spring-damper torque (``BOOM_PITCH_*``, 500 N m/rad);
  the boom neither lifts nor propels the robot;
* ground: compliant spring-damper contact with Coulomb friction at point feet
  (:mod:`dmpopt.sim`), 1 ms step; the DMP steps every 4 ms (compiled), the PD law every 1 ms;
* demonstration: approximate normative sagittal hip and knee angles over a gait cycle, read
  off the averaged adult curves of D. A. Winter, "Biomechanics and Motor Control of Human
  Movement", 4th ed., Wiley 2009 (Ch. 5, normal cadence) and J. Perry, J. Burnfield, "Gait
  Analysis", 2nd ed., 2010, at 5-15 % steps of the cycle (``HIP_KEYPOINTS``,
  ``KNEE_KEYPOINTS``), joined by a periodic cubic spline; the left leg is the right leg half
  a cycle later. Retargeted to point feet: the trailing knee is flexed 23 deg (not 10) at 50 %
  of the cycle so that both feet reach the ground exactly at heel strike (a human gets the
  same from ankle plantar-flexion, which the robot lacks);
* DMPs: :func:`dmpopt.fit_rhythmic` (phase oscillator, eqs. (11)-(12)), one shared phase;
* control: joint PD on the DMP's position and velocity, torques saturated at the URDF limits;
* eq. (21): :class:`dmpopt.walking.FrequencyAdaptation` at each heel strike;
* simulator (``backend``): MuJoCo by default (:class:`dmpopt.sim.MujocoSimulator` from the same
  URDF, a 5 mm sphere at each point foot, friction 0.8, the boom torque as a generalised force
  on the base pitch), or the native compliant ground (``backend="native"``). With MuJoCo the
  adapted walk is repeated on the native simulator for comparison (``native`` in the
  metrics): the native simulator earns its place as the reference whose ground model
  (stiffness and damping) is written out in :mod:`dmpopt.sim` and as the faster plant of the
  two for a point-foot robot; the claims are checked on the default backend.

What "resonance" means here: with stiff PD tracking the swing leg does not swing passively,
so the swing-leg pendulum frequency (about 5.2 rad/s) is not where the frequency goes. The
independent check is a sweep of fixed frequencies without adaptation
(:func:`fixed_frequency_sweep`): the adapted frequency lands at the frequency of least
mechanical cost of transport, from above and from below.

Run: ``python -m studies.biped OUT_DIR [--quick]``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from dmpopt import Trajectory, fit_rhythmic
from dmpopt.sim import GroundContact, Simulator
from dmpopt.walking import FrequencyAdaptation, HeelStrikeDetector
from robots.biped import Biped, load_biped

from .common import write_metrics

EXPECTED_SECONDS = {"full": 95, "quick": 30}  # CPU seconds on the 2-core machine (MuJoCo)

# Percent of the gait cycle (right heel strike at 0) and joint angle [deg]; flexion positive.
HIP_KEYPOINTS = np.array(
    [
        [0, 25],
        [10, 22],
        [20, 15],
        [30, 7],
        [40, 0],
        [50, -8],
        [55, -10],
        [60, -5],
        [70, 10],
        [80, 22],
        [87, 27],
        [95, 26],
    ],
    dtype=float,
)
KNEE_KEYPOINTS = np.array(
    [
        [0, 5],
        [5, 10],
        [15, 18],
        [25, 12],
        [35, 6],
        [42, 5],
        [50, 23],
        [60, 40],
        [67, 55],
        [72, 60],
        [80, 50],
        [90, 25],
        [95, 8],
    ],
    dtype=float,
)

DT = 1e-3  # [s] simulation and PD step
CONTROL_EVERY = 4  # the DMP steps every CONTROL_EVERY * DT
COMPILE = True  # compiled DMP step (generated C, cached in ~/.cache/dmpopt)
GROUND = GroundContact(stiffness=1e4, damping=150.0, friction=0.8)
FALL_HEIGHT = 0.35  # [m] the walker has fallen when its torso is lower
VIDEO_SECONDS_WALK = 4.0  # [s] the walking clip shows the last seconds of the adapted walk


@dataclass(frozen=True)
class Gains:
    """Joint PD gains: stiffness [N m/rad] and damping [N m s/rad]."""

    hip_stiffness: float = 100.0
    hip_damping: float = 3.0
    knee_stiffness: float = 100.0
    knee_damping: float = 3.0
    swing_hip_stiffness: float = 100.0
    swing_hip_damping: float = 3.0


GAINS = Gains()
BOOM_PITCH_STIFFNESS = 500.0  # [N m/rad]
BOOM_PITCH_DAMPING = 30.0  # [N m s/rad]
ADAPTATION_GAIN = 0.3  # K of eq. (21)
DEMO_FREQUENCY = 5.0  # [rad/s] frequency the DMPs are learned at (period 1.26 s)
WRONG_FREQUENCIES = (5.0, 1.8)  # [rad/s] deliberately wrong starting frequencies (above, below)
SWEEP = (1.8, 2.1, 2.4, 2.8, 3.2, 4.0, 5.0)  # [rad/s] fixed frequencies for the CoT sweep
SWEEP_QUICK = (1.8, 2.4, 3.2, 5.0)
LOG_EVERY = 10  # steps between logged samples


def demonstrated_gait(period: float = 2 * np.pi / DEMO_FREQUENCY, n_samples: int = 400):
    """Two periods of the demonstrated gait, DOFs (right hip, right knee, left hip, left knee).

    Returns
    -------
    Trajectory
        Angles [rad]; the cycle starts at the right heel strike (oscillator phase 0).
    """
    times = np.linspace(0.0, 2 * period, 2 * n_samples + 1)
    cycle = (times / period) % 1.0

    def joint(keypoints):
        x = np.r_[keypoints[:, 0], 100.0] / 100.0
        y = np.radians(np.r_[keypoints[:, 1], keypoints[0, 1]])
        return CubicSpline(x, y, bc_type="periodic")

    hip, knee = joint(HIP_KEYPOINTS), joint(KNEE_KEYPOINTS)
    other = (cycle + 0.5) % 1.0
    positions = np.column_stack([hip(cycle), knee(cycle), hip(other), knee(other)])
    return Trajectory.from_positions(times, positions)


@dataclass
class WalkLog:
    """What one walk produced (samples every ``LOG_EVERY`` steps)."""

    times: list = field(default_factory=list)
    q: list = field(default_factory=list)
    desired: list = field(default_factory=list)
    strikes: list = field(default_factory=list)  # (time, leg, x of the foot)
    frequencies: list = field(default_factory=list)
    positive_work: float = 0.0  # [J] actuator work, sum over joints of max(tau qdot, 0) dt
    absolute_work: float = 0.0  # [J] sum of |tau qdot| dt
    fell: bool = False
    diverged: str = ""
    duration: float = 0.0  # [s] simulated
    wall_time: float = 0.0  # [s]
    cpu_time: float = 0.0  # [s] process time, insensitive to other load on the machine
    distance: float = 0.0  # [m]


def walk(
    biped: Biped,
    dmp,
    duration: float,
    frequency: float,
    adapt: bool = True,
    reset_phase: bool = True,
    push_impulse: float = 0.0,
    push_time: float = 0.0,
    seed: int = 0,
    gains: Gains | None = None,
    log_every: int = LOG_EVERY,
    backend: str = "mujoco",
) -> WalkLog:
    """Simulate the walker for ``duration`` [s] from the demonstrated gait at ``frequency``.

    The robot starts at the right heel strike of the demonstrated posture with a forward speed
    of 0.35 m/s plus a seeded perturbation of +-0.02 m/s. A horizontal ``push_impulse`` [N s]
    on the torso (hip point) is spread over 0.1 s from ``push_time``. The DMP steps at the
    control period ``CONTROL_EVERY * DT``; the PD law and the contact simulation at ``DT``,
    on ``backend`` ("mujoco" or "native", see :func:`make_simulator`).
    """
    gains = GAINS if gains is None else gains
    rng = np.random.default_rng(seed)
    start_position, start_velocity = _limit_cycle_start(dmp, frequency)
    stepper = dmp.stepper(
        CONTROL_EVERY * DT, start=start_position, start_velocity=start_velocity, compile=COMPILE
    )
    stepper.set_time_constant(1.0 / frequency)
    q = biped.configuration(0.0, biped.leg_length, 0.0, stepper.position)
    q[1] -= biped.foot_positions(q)[:, 1].min()
    sim = make_simulator(biped, backend)
    v = np.zeros(biped.model.nv)
    v[0] = 0.35 + rng.uniform(-0.02, 0.02)
    state = sim.reset(q, v)
    # Model order throughout the loop: the gait order is used only for the DMP.
    order = biped.joint_velocity_indices - biped.n_base_dofs
    index = np.sort(biped.joint_velocity_indices)
    stiffness = np.empty(4)
    damping = np.empty(4)
    stiffness[order] = [gains.hip_stiffness, gains.knee_stiffness] * 2
    damping[order] = [gains.hip_damping, gains.knee_damping] * 2
    stance_stiffness, stance_damping = stiffness.copy(), damping.copy()
    swing_stiffness, swing_damping = stiffness.copy(), damping.copy()
    hips = order[[0, 2]]  # model-order slots of the right and left hip
    swing_stiffness[hips] = gains.swing_hip_stiffness
    swing_damping[hips] = gains.swing_hip_damping
    contact = np.ones(2, dtype=bool)
    limit = np.empty(4)
    limit[order] = biped.torque_limit
    detector = HeelStrikeDetector(min_swing_time=0.1)
    adaptation = FrequencyAdaptation(frequency, ADAPTATION_GAIN, reset_phase, adapt)
    log = WalkLog(frequencies=[frequency])
    base_force = np.zeros(3)
    desired = np.empty(4)
    desired_velocity = np.empty(4)
    positive_work = absolute_work = 0.0
    n_steps = int(round(duration / DT))
    push_step = int(round(push_time / DT)) if push_impulse else -1
    start, cpu_start = time.perf_counter(), time.process_time()
    try:
        for k in range(n_steps):
            if k == push_step:
                sim.push_impulse(biped.torso_frame, [push_impulse, 0.0, 0.0], duration=0.1)
            if k % CONTROL_EVERY == 0:
                position, velocity, _ = stepper.step()
                desired[order] = position
                desired_velocity[order] = velocity
            joints, joint_velocities = state.q[index], state.v[index]
            torque = stiffness * (desired - joints) + damping * (
                desired_velocity - joint_velocities
            )
            np.clip(torque, -limit, limit, out=torque)
            base_force[2] = -BOOM_PITCH_STIFFNESS * state.q[2] - BOOM_PITCH_DAMPING * state.v[2]
            state = sim.step(torque, base_force)
            power = torque @ joint_velocities
            work = np.abs(torque * joint_velocities).sum()
            absolute_work += work
            positive_work += 0.5 * (work + power)  # sum of max(p_i, 0) = (|p| + p) / 2
            if (state.in_contact != contact).any():  # stance or swing gains per leg
                contact = state.in_contact
                stiffness[hips] = np.where(contact, stance_stiffness[hips], swing_stiffness[hips])
                damping[hips] = np.where(contact, stance_damping[hips], swing_damping[hips])
            if state.touchdowns or not state.in_contact.all():
                strike = detector.update(state.t, state.in_contact, state.contact_positions)
                if strike is not None:
                    phase, new_frequency = adaptation.on_heel_strike(strike)
                    if phase is not None:
                        stepper.reset_phase(phase)
                    stepper.set_time_constant(1.0 / new_frequency)
                    log.strikes.append((strike.time, strike.leg, float(strike.position[0])))
            if k % log_every == 0:
                log.times.append(state.t)
                log.q.append(state.q)
                log.desired.append(desired[order])
            if state.fallen:
                log.fell = True
                break
    except Exception as error:  # SimulationDiverged counts as a fall, with the reason kept
        log.fell, log.diverged = True, str(error)
    log.wall_time = time.perf_counter() - start
    log.cpu_time = time.process_time() - cpu_start
    log.positive_work, log.absolute_work = DT * positive_work, DT * absolute_work
    log.duration = sim.t
    log.distance = float(sim.q[0] - q[0])
    log.frequencies = adaptation.frequencies
    return log


def make_simulator(biped: Biped, backend: str):
    """The walker's simulator on ``backend``: "mujoco" or "native" (compliant ``GROUND``).

    Both take the same fall options, so both flag a fall when the torso is below
    ``FALL_HEIGHT`` (the other thresholds derived from the biped, :mod:`dmpopt.sim.falls`).
    """
    from .humanoid import check_backend

    if check_backend(backend) == "native":
        return Simulator(
            biped.model,
            DT,
            biped.contact_points,
            GROUND,
            n_base_dofs=3,
            fall_frame=biped.torso_frame,
            fall_height=FALL_HEIGHT,
        )
    from dmpopt.sim import MujocoSimulator
    from robots.biped import BIPED_URDF

    return MujocoSimulator(
        biped.model,
        BIPED_URDF,
        DT,
        biped.contact_points,
        friction=GROUND.friction,
        fall_frame=biped.torso_frame,
        fall_height=FALL_HEIGHT,
    )


def _limit_cycle_start(dmp, frequency: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of the DMP's limit cycle at phase 0 (the right heel strike)."""
    plan = dmp.with_time_constant(1.0 / frequency).rollout(
        duration=3 * 2 * np.pi / frequency, dt=DT
    )
    return plan.positions[-1], plan.velocities[-1]


def learn_gait():
    """Fit the four rhythmic DMPs (one shared phase) to the demonstrated gait."""
    demo = demonstrated_gait()
    return demo, fit_rhythmic(demo, n_basis=25, period=2 * np.pi / DEMO_FREQUENCY)


def steps_to_within(frequencies, tolerance: float = 0.02) -> int | None:
    """First step after which the frequency stays within ``tolerance`` of its final value."""
    frequencies = np.asarray(frequencies, dtype=float)
    inside = np.abs(frequencies / frequencies[-1] - 1.0) <= tolerance
    outside = np.flatnonzero(~inside)
    return 0 if outside.size == 0 else int(outside[-1] + 1)


def cost_of_transport(log: WalkLog, mass: float, gravity: float = 9.81) -> float | None:
    """Mechanical cost of transport, positive actuator work / (m g |distance|) [-].

    The boom's pitch torque does no work on average and is not counted.
    """
    if log.distance == 0.0:
        return None
    return log.positive_work / (mass * gravity * abs(log.distance))


def survives_push(biped, dmp, frequency, adapt, impulse, seed, backend="mujoco") -> bool:
    """Whether the walker at ``frequency`` survives a forward torso push at 6 s.

    The boom holds the pitch, so the torso rarely drops; surviving therefore also needs the
    gait to go on: at least three alternating heel strikes in the last 5 s of a 12 s walk.
    """
    log = walk(
        biped,
        dmp,
        12.0,
        frequency,
        adapt=adapt,
        push_impulse=impulse,
        push_time=6.0,
        seed=seed,
        backend=backend,
    )
    late = [leg for t, leg, _ in log.strikes if t > 7.0]
    return not log.fell and len(late) >= 3


def largest_survived_push(
    biped, dmp, frequency, adapt, seed, upper=100.0, tolerance=2.0, backend="mujoco"
):
    """Largest forward impulse [N s] survived, by bisection on ``[0, upper]`` to ``tolerance``.

    Assumes survival is monotonic in the impulse (checked only at the bisection points).
    """
    if survives_push(biped, dmp, frequency, adapt, upper, seed, backend):
        return upper
    low, high = 0.0, upper
    while high - low > tolerance:
        middle = 0.5 * (low + high)
        if survives_push(biped, dmp, frequency, adapt, middle, seed, backend):
            low = middle
        else:
            high = middle
    return low


def fixed_frequency_sweep(
    biped, dmp, frequencies, duration, seed=0, backend="mujoco"
) -> list[dict]:
    """Walk at each fixed frequency (phase resetting on, adaptation off); CoT and step rate.

    The frequency with the lowest cost of transport is the independent estimate of the
    walker's "resonance" that the adapted frequency is compared with.
    """
    rows = []
    for frequency in frequencies:
        log = walk(
            biped,
            dmp,
            duration,
            frequency,
            adapt=False,
            seed=seed,
            log_every=10**9,
            backend=backend,
        )
        durations = np.diff([t for t, _, _ in log.strikes])[2:]
        rows.append(
            {
                "frequency": float(frequency),
                "fell": log.fell,
                "cost_of_transport": cost_of_transport(log, biped.mass),
                "speed_m_per_s": log.distance / log.duration,
                "measured_frequency": float(np.pi / durations.mean()) if durations.size else None,
            }
        )
    return rows


def _walk_summary(log: WalkLog) -> dict:
    """Steps, fall, distance, final frequency and real-time factor of one walk."""
    return {
        "steps_walked": len(log.strikes),
        "fell": log.fell,
        "simulated_time_s": log.duration,
        "distance_m": log.distance,
        "frequency_final": log.frequencies[-1],
        "real_time_factor": log.duration / log.wall_time,
        "real_time_factor_cpu": log.duration / log.cpu_time,
    }


def run(out_dir, quick: bool = False, seed: int = 0, backend: str = "mujoco") -> dict:
    """Run the study; write ``metrics.json`` and the figures to ``out_dir``; return metrics.

    Every walk runs on ``backend`` ("mujoco", default, or "native"); with MuJoCo the adapted
    walk is repeated natively for comparison and a video of it is written (not in quick mode).
    """
    from .humanoid import VIDEO_FPS, check_backend, write_videos

    backend = check_backend(backend)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    biped = load_biped()
    demo, dmp = learn_gait()
    duration = 20.0 if quick else 150.0
    start_frequency = WRONG_FREQUENCIES[0]

    on = {"seed": seed, "backend": backend}
    adapted = walk(biped, dmp, duration, start_frequency, adapt=True, **on)
    fixed = walk(biped, dmp, 10.0 if quick else 40.0, start_frequency, adapt=False, **on)
    others = [
        walk(biped, dmp, 15.0 if quick else 60.0, f, adapt=True, **on)
        for f in WRONG_FREQUENCIES[1:]
    ]
    final = adapted.frequencies[-1]
    n_to_2pct = steps_to_within(adapted.frequencies)
    sweep = fixed_frequency_sweep(
        biped, dmp, SWEEP_QUICK if quick else SWEEP, 8.0 if quick else 20.0, seed, backend
    )
    walked = [row for row in sweep if not row["fell"]]
    cheapest = min(walked, key=lambda row: row["cost_of_transport"])["frequency"]
    natural_straight = biped.swing_leg_natural_frequency(0.0)
    stance_pendulum = float(np.sqrt(9.81 / biped.leg_length))
    mass = biped.mass

    # After adaptation: the same walk restarted at the adapted frequency, adaptation off.
    converged = walk(biped, dmp, 10.0 if quick else 30.0, final, adapt=False, **on)
    tolerance = 25.0 if quick else 2.0
    push = {
        label: largest_survived_push(
            biped, dmp, final, adapt, seed, tolerance=tolerance, backend=backend
        )
        for label, adapt in (("with_adaptation", True), ("without_adaptation", False))
    }
    speed = adapted.distance / adapted.duration
    metrics = {
        "steps_walked": len(adapted.strikes),
        "fell": adapted.fell,
        "simulated_time_s": adapted.duration,
        "distance_m": adapted.distance,
        "speed_m_per_s": speed,
        "start_frequency": start_frequency,
        "frequency_final": final,
        "steps_to_2pct": n_to_2pct,
        "frequency_vs_step": adapted.frequencies,
        "frequency_error_vs_step": list(np.asarray(adapted.frequencies) / final - 1.0),
        "frequency_vs_step_other_starts": {
            f"{f:g}": log.frequencies for f, log in zip(WRONG_FREQUENCIES[1:], others)
        },
        "natural_frequency_estimate": {
            "min_cost_of_transport_fixed_frequency": cheapest,
            "swing_leg_pendulum_straight_knee": natural_straight,
            "stance_inverted_pendulum_sqrt_g_over_l": stance_pendulum,
        },
        "final_over_min_cot_frequency": final / cheapest,
        "final_over_swing_leg_pendulum": final / natural_straight,
        "fixed_frequency_sweep": sweep,
        "cost_of_transport": {
            "adapted_run": cost_of_transport(adapted, mass),
            "with_adaptation_fixed_at_final_frequency": cost_of_transport(converged, mass),
            "without_adaptation_fixed_at_start_frequency": cost_of_transport(fixed, mass),
        },
        "without_adaptation": {
            "steps_walked": len(fixed.strikes),
            "fell": fixed.fell,
            "speed_m_per_s": fixed.distance / fixed.duration,
            "distance_m": fixed.distance,
        },
        "push_survived_ns": push,
        "push_bisection_tolerance_ns": tolerance,
        "boom_pitch_stiffness_N_m_per_rad": BOOM_PITCH_STIFFNESS,
        "real_time_factor": adapted.duration / adapted.wall_time,
        "real_time_factor_cpu": adapted.duration / adapted.cpu_time,
        "sim_step_s": DT,
        "dmp_step_s": CONTROL_EVERY * DT,
        "quick": quick,
        "seed": seed,
    }
    metrics["backend"] = backend
    metrics[backend] = _walk_summary(adapted)
    clips = {}
    if backend == "mujoco":
        native = walk(
            biped, dmp, duration, start_frequency, adapt=True, seed=seed, backend="native"
        )
        metrics["native"] = _walk_summary(native)
        every = max(1, int(round(1.0 / (VIDEO_FPS * DT * LOG_EVERY))))
        shown = int(VIDEO_SECONDS_WALK * VIDEO_FPS)
        frames = np.asarray(adapted.q)[::every][-shown:]
        clips["biped_walking"] = (make_simulator(biped, "mujoco"), frames, 2.0)
    skip = "quick run" if quick else None if backend == "mujoco" else "native backend"
    metrics["videos"], metrics["videos_skipped"] = write_videos(out_dir, clips, skip)
    if metrics["videos_skipped"]:
        print(f"videos skipped: {metrics['videos_skipped']}")
    _plot(out_dir, biped, adapted, others, final, natural_straight, sweep, metrics)
    parameters = {
        "duration_s": duration,
        "start_frequencies_rad_s": WRONG_FREQUENCIES,
        "sim_step_s": DT,
        "dmp_step_s": CONTROL_EVERY * DT,
        "boom_pitch_stiffness_N_m_per_rad": BOOM_PITCH_STIFFNESS,
    }
    return write_metrics(out_dir, "biped", metrics, parameters, seed, quick)


def _plot(out_dir, biped, adapted, others, final, natural, sweep, metrics) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # Fig. 7: frequency against step, and the fixed-frequency cost-of-transport sweep.
    fig, (ax, ax_cot) = plt.subplots(1, 2, figsize=(10, 3.6))
    for log in [adapted, *others]:
        ax.plot(log.frequencies, marker=".", label=f"start {log.frequencies[0]:.1f} rad/s")
    ax.axhline(natural, color="k", ls="--", lw=1, label="swing-leg pendulum (straight)")
    cheapest = metrics["natural_frequency_estimate"]["min_cost_of_transport_fixed_frequency"]
    ax.axhline(cheapest, color="g", ls=":", lw=1.2, label="min CoT, fixed frequency")
    ax.set_xlabel("heel strike n")
    ax.set_ylabel(r"oscillator frequency $\omega_n$ [rad/s]")
    ax.set_title("Frequency adaptation, eq. (21)")
    ax.legend(fontsize=7)
    walked = [row for row in sweep if not row["fell"]]
    ax_cot.plot(
        [row["frequency"] for row in walked],
        [row["cost_of_transport"] for row in walked],
        "o-",
        label="fixed frequency (no adaptation)",
    )
    ax_cot.axvline(final, color="r", lw=1, label=f"adapted {final:.2f} rad/s")
    ax_cot.axvline(natural, color="k", ls="--", lw=1, label="swing-leg pendulum")
    ax_cot.set_xlabel(r"oscillator frequency $\omega$ [rad/s]")
    ax_cot.set_ylabel("mechanical cost of transport [-]")
    ax_cot.set_title("Cost of transport vs fixed frequency")
    ax_cot.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / "biped_frequency.png", dpi=120)
    plt.close(fig)

    # Joint trajectories, desired against actual, first and last seconds.
    times = np.asarray(adapted.times)
    q = np.asarray(adapted.q)[:, biped.joint_velocity_indices]
    desired = np.asarray(adapted.desired)
    fig, axes = plt.subplots(4, 2, figsize=(9, 7), sharex="col")
    windows = [times <= times[0] + 4.0, times >= times[-1] - 4.0]
    for col, window in enumerate(windows):
        for row, name in enumerate(biped.joint_names):
            ax = axes[row, col]
            ax.plot(times[window], np.degrees(desired[window, row]), "--", label="DMP")
            ax.plot(times[window], np.degrees(q[window, row]), label="robot")
            for t, leg, _ in adapted.strikes:
                if times[window][0] <= t <= times[window][-1]:
                    ax.axvline(t, color="r" if leg == 0 else "b", lw=0.4)
            ax.set_ylabel(f"{name} [deg]", fontsize=8)
    axes[0, 0].set_title("start (wrong frequency)")
    axes[0, 1].set_title("end (adapted)")
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("t [s]")
    axes[-1, 1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(out_dir / "biped_joints.png", dpi=120)
    plt.close(fig)

    # Stick-figure strip of the last gait cycles.
    fig, ax = plt.subplots(figsize=(10, 2.6))
    window = np.flatnonzero(times >= times[-1] - 3.0)[::8]
    import pinocchio as pin

    data = biped.model.createData()
    frames = ["torso", "right_knee", "right_foot", "left_knee", "left_foot"]
    ids = {f: biped.model.getFrameId(f) for f in frames}
    colours = plt.cm.viridis(np.linspace(0, 1, len(window)))
    for colour, k in zip(colours, window):
        pin.framesForwardKinematics(biped.model, data, adapted.q[k])
        p = {f: data.oMf[i].translation[[0, 2]] for f, i in ids.items()}
        top = p["torso"] + 0.3 * np.array([np.sin(adapted.q[k][2]), np.cos(adapted.q[k][2])])
        for chain in (
            [top, p["torso"]],
            [p["torso"], p["right_knee"], p["right_foot"]],
            [p["torso"], p["left_knee"], p["left_foot"]],
        ):
            chain = np.array(chain)
            ax.plot(chain[:, 0], chain[:, 1], color=colour, lw=1)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_title(f"last 3 s, {metrics['speed_m_per_s']:.2f} m/s")
    fig.tight_layout()
    fig.savefig(out_dir / "biped_stick_figure.png", dpi=120)
    plt.close(fig)


def main(argv=None) -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--backend", choices=("mujoco", "native"), default="mujoco")
    args = parser.parse_args(argv)
    metrics = run(args.out_dir, quick=args.quick, seed=args.seed, backend=args.backend)
    summary = {
        k: metrics[k]
        for k in (
            "steps_walked",
            "fell",
            "simulated_time_s",
            "speed_m_per_s",
            "frequency_final",
            "steps_to_2pct",
            "natural_frequency_estimate",
            "cost_of_transport",
            "push_survived_ns",
            "real_time_factor",
            "real_time_factor_cpu",
            "native",
            "mujoco",
            "videos",
        )
        if k in metrics
    }
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
