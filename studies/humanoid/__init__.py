r"""Humanoid drumming and figure-8 with rhythmic DMPs and QP inverse dynamics (Fig. 4, Sec. 4.1).

Claim of [dmpopt-paper] Sections 3.1, 3.6 and 4.1: joint-space rhythmic DMPs learned by
imitation, all on one canonical system, produce bimanual drumming on a humanoid; their desired
positions, velocities and accelerations become torques through an inverse-dynamics model plus
low-gain feedback in real time. Fig. 4 right: changing the amplitude ``A -> 2A``, the time
constant ``tau -> tau / 2`` or the setpoint ``g -> g + 1`` of the right elbow between t = 3 s
and t = 7 s makes the pattern converge quickly to the new limit cycle, with the same shape.

Set-up (all choices are ours):

* robot: Talos (full URDF, 30+ DOFs, nv = 50) standing on its two feet, floating base, 1 ms
  steps, simulated by ``backend``: MuJoCo (default; :class:`dmpopt.sim.MujocoSimulator` from
  the same URDF, a 5 mm sphere at each sole corner on the floor, friction 1, CoM target at
  the start posture) or the native compliant ground (``"native"``: :mod:`dmpopt.sim`,
  semi-implicit Euler, 20 kN/m per sole corner, CoM target lowered by the static
  compression); and the fixed-base upper body (legs and pelvis locked in half-sitting) for
  comparison;
* where the native simulator stays, and why: the fixed-base upper body (a reduced model with
  no URDF of its own, and the controller's timing reference), and one nominal drumming run
  beside MuJoCo's (``native`` in the metrics: tracking, falls and real-time factor of the
  same loop on the other plant, the check that the results do not hang on one contact model);
* MuJoCo scenarios (``mujoco`` in the metrics; each from the drumming start, no change of
  the plan): every link mass and inertia of the controller's model x 0.9 and x 1.1
  (``LINK_MASS_SCALES``); floor friction 0.4 and 0.7 (``FRICTIONS``; the controller's cone
  at ``min(0.7, floor)``); torque limits of the controller at ``TIGHT_TORQUE`` of the
  nominal run's peak use, so that the QP's torque rows bind; forward pushes on the pelvis
  of every impulse of ``PUSH_LADDER``, then two bisections below its first fall;
* walking (MuJoCo backend only; :mod:`dmpopt_studies.talos_walk`, metrics under ``walk``): Talos
  (``reduced`` model) steps in place, then walks forward on a LIPM/DCM CoM plan with
  swing-foot references from discrete DMPs, through the same controller with contact
  switching (a normal-force ramp over each double support), DCM feedback and step
  adjustment; pushed (``push_recovery``) and on ground it was not told about (``step_down``,
  ``step_up``, ``slope``: fell, touchdowns from contact, foothold error);
* videos (MuJoCo's offscreen renderer, animated WebP of ``VIDEO_SECONDS``): drumming,
  figure-8, the largest survived push and the forehand (with five keyframes,
  ``swing_keyframes.png``); skipped in quick mode and without an OpenGL context, with the
  reason in ``videos_skipped``;
* controller: :class:`dmpopt.control.InverseDynamicsController` at 1 kHz (a least-squares
  solve per tick, proxsuite when a friction, CoP or torque row is active) with the
  DMP-driven arm joints as a posture task (plan acceleration as feed-forward, low-gain PD
  ``ARM_STIFFNESS``), a whole-body posture task, and, standing, a CoM task, a pelvis
  orientation task (alternating hands would otherwise roll the pelvis) and two sole contacts;
* drumming demonstration (synthetic, hand-designed, not motion capture): a task-space stick
  stroke per hand -- asymmetric vertical wrist path (quick rebound after the strike, slow
  preparation, fast downstroke), a small fore-aft loop and a wrist flick that leads the
  stroke -- left hand half a period after the right one, mapped to 6 joints per arm
  (shoulder 1-3, elbow 4, wrist 6-7; forearm roll 5 held) by damped least-squares inverse
  kinematics on the full pose of each hand, from a drumming posture with bent elbows (the
  half-sitting straight elbows make vertical hand motions nearly singular);
* DMPs: :func:`dmpopt.fit_rhythmic`, phase oscillator eqs. (11)-(12), 15 basis functions per
  DOF; 11 DOFs on one oscillator and the right elbow on its own one-DOF DMP with the same
  period and start phase, phase-locked to the shared oscillator by a coupling term
  ``ELBOW_PHASE_COUPLING * sin(phi - phi_elbow)`` (switched off while the elbow runs at
  ``tau / 2``), so that ``A``, ``tau`` and ``g`` can change on the elbow alone;
* Fig. 4 right: ``A -> 2A``, ``tau -> tau / 2`` and ``g -> g + 1 rad`` (``SETPOINT_SHIFT``)
  on the right elbow from 3 s to 7 s, each in its own standing run, as steps (as in the
  paper). The paper prints no unit for its ``+1``; its joint angles are in radians, and one
  radian is feasible here: the elbow's limit cycle (0.29 rad peak to peak, centred at -1.49
  rad) moves to [-0.59, -0.30] rad, inside the elbow's range [-2.23, 0.0035] rad. The
  shift is 3.5 times the cycle's peak-to-peak range. Settle times count from the step to
  the last time the elbow leaves 5 % of the new cycle's peak-to-peak range around it; the
  DMP alone (``plan``) and the robot are reported apart, and the DMP with the change through
  a 0.1 s first-order filter (``PARAMETER_FILTER``, ``plan_filtered``) for comparison with
  earlier versions of this study. The setpoint step asks the elbow for about 19 rad/s; its
  velocity limit (4.58 rad/s) bounds how fast any controller can follow
  (``setpoint_velocity_bound_s``);
* discrete movement (``discrete_swing`` in the metrics; :mod:`.swing`): a forehand of the
  right arm -- a synthetic demonstration of two overlapping minimum-jerk submovements, a
  backswing (0.9 s) then a faster forward swing (0.5 s) through the contact point to the
  follow-through -- learned by one six-DOF discrete DMP (:func:`dmpopt.fit_discrete`,
  library defaults: 30 bases per joint, one canonical system) and executed standing through
  the same controller for the DMP's default plan length; then sent to a new goal, the
  follow-through posture with the hand ``SWING_FINISH_RAISE`` higher;
* figure-8: a 1:2 Lissajous curve of the right hand in the frontal plane, learned as a
  three-DOF task-space rhythmic DMP and tracked by a hand position task while standing;
* ablations: the controller's model with arms 10 % too heavy (``MASS_ERROR``; the simulator
  and the controller otherwise share the exact model, so tracking is near-perfect), and the
  pelvis orientation task left out.

The MuJoCo scenarios and the pushes are independent runs: they go through
:func:`dmpopt.parallel.map_runs` with the ``runner`` given to :func:`run` (serial by
default; ``--workers N`` on the command line). Each stage prints its progress.

Quick mode simulates about 50 s in total (3 s of drumming, Fig. 4 runs of 4 s with the change
between 1 s and 3 s, the two swings, MuJoCo scenarios of 1.5 s, pushes of 10 and 60 N s) and
renders no video.

Run: ``python -m dmpopt_studies.humanoid OUT_DIR [--quick] [--workers N]`` or ``dmpopt study run
humanoid``.

Modules: :mod:`.parameters` (the set-up constants), :mod:`.demos` (the demonstrations and
their inverse kinematics), :mod:`.plan` (the DMPs, their online plan and settle times),
:mod:`.controller` (controller and simulators), :mod:`.loop` (the closed loop),
:mod:`.robustness` (MuJoCo scenarios and pushes), :mod:`.swing` (the discrete forehand),
:mod:`.metrics`, :mod:`.summary` (the opening table and captions), :mod:`.figures` and
:mod:`.study` (``run`` and ``main``).
"""

from ..plant_sweep import with_scaled_masses
from .controller import (
    _sink,
    build_controller,
    make_simulator,
    mujoco_plant,
    with_mass_error,
    with_scaled_torque_limits,
)
from .demos import (
    DRUM_JOINTS,
    Demonstration,
    arm_joint_names,
    demonstrate_drumming,
    drumming_posture,
    figure8_demonstration,
)
from .figures import write_videos
from .loop import RunLog, run_drumming, run_figure8
from .parameters import (
    ARM_STIFFNESS,
    BACKENDS,
    BASE_WEIGHT,
    COM_WEIGHT,
    DT,
    EXPECTED_SECONDS,
    HAND_STIFFNESS,
    PERIOD,
    POSTURE_WEIGHT,
    PUSH_TIME,
    SETPOINT_SHIFT,
    SETTLE_TOLERANCE,
    VIDEO_FPS,
)
from .plan import (
    MODIFICATIONS,
    DrumDmps,
    DrumPlan,
    Modification,
    elbow_limit_cycle,
    ideal_elbow,
    learn_drumming,
    plan_rollout,
    settle_time,
)
from .robustness import Scenario, mujoco_scenarios, push_search, run_scenario
from .study import check_backend, main, run

__all__ = [
    "ARM_STIFFNESS",
    "BACKENDS",
    "BASE_WEIGHT",
    "COM_WEIGHT",
    "DRUM_JOINTS",
    "DT",
    "Demonstration",
    "DrumDmps",
    "DrumPlan",
    "EXPECTED_SECONDS",
    "HAND_STIFFNESS",
    "MODIFICATIONS",
    "Modification",
    "PERIOD",
    "POSTURE_WEIGHT",
    "PUSH_TIME",
    "Scenario",
    "RunLog",
    "SETPOINT_SHIFT",
    "SETTLE_TOLERANCE",
    "VIDEO_FPS",
    "_sink",
    "arm_joint_names",
    "build_controller",
    "check_backend",
    "demonstrate_drumming",
    "drumming_posture",
    "elbow_limit_cycle",
    "figure8_demonstration",
    "ideal_elbow",
    "learn_drumming",
    "main",
    "make_simulator",
    "mujoco_plant",
    "mujoco_scenarios",
    "plan_rollout",
    "push_search",
    "run",
    "run_drumming",
    "run_figure8",
    "run_scenario",
    "settle_time",
    "with_mass_error",
    "with_scaled_masses",
    "with_scaled_torque_limits",
    "write_videos",
]
