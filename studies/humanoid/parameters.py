"""Set-up constants of the humanoid study: timing, drumming pattern, gains, scenarios."""

import numpy as np

# CPU seconds (process and workers, user + sys; dmpopt.cli): the main job, warm, quiet, on the
# 2-core AMD EPYC machine of 2026-11-28 (full 134, quick 76)
EXPECTED_SECONDS = {"full": 134, "quick": 76}

DT = 1e-3  # [s] control, DMP and simulation period (1 kHz)
PERIOD = 1.5  # [s] drumming period (one stroke per hand per period; 80 beats per minute)
FIGURE8_PERIOD = 2.0  # [s]
N_BASIS = 15  # basis functions per DOF, as in the paper
ARM_JOINTS = (1, 2, 3, 4, 6, 7)  # Talos arm joints driven by DMPs (6 per arm); 5 is held
ELBOW = "arm_right_4_joint"
CHANGE_START, CHANGE_END = 3.0, 7.0  # [s] Fig. 4 right: modification window
# Fig. 4's "g -> g + 1" in radians (the paper's joint angles; it prints no unit): the new
# elbow cycle [-0.59, -0.30] rad stays inside the Talos elbow range [-2.23, 0.0035] rad.
SETPOINT_SHIFT = 1.0  # [rad]
ELBOW_PHASE_COUPLING = 2.0  # gain of the elbow's phase lock to the shared oscillator
SETTLE_TOLERANCE = 0.05  # fraction of the new peak-to-peak amplitude
# The robot runs take A, tau and g as steps, as in the paper. For comparison only, the plan
# is also rolled out with the parameters passed through a first-order filter of this time
# constant (like the goal filter of eq. (10)), which an earlier version of the study used.
PARAMETER_FILTER = 0.1  # [s]

# Drumming posture (bent elbows, hands in front of the belly); arm joints 1..7, left arm.
# The right arm mirrors it (joints 1, 2, 3, 5, 6 change sign).
DRUM_POSTURE_LEFT = (0.35, 0.30, -0.30, -1.45, 0.0, 0.0, 0.0)
STROKE_HEIGHT = 0.09  # [m] vertical travel of the wrist
STROKE_LOOP = 0.015  # [m] fore-aft amplitude of the wrist loop
WRIST_FLICK = 0.15  # [rad] amplitude of the wrist pitch
# Stroke profile over one period (fraction of the cycle, normalised height), strike at 0:
# quick rebound, slow lift to the top, fast downstroke.
HEIGHT_KEYPOINTS = np.array(
    [[0.0, 0.0], [0.1, 0.45], [0.25, 0.8], [0.45, 1.0], [0.65, 0.92], [0.8, 0.6], [0.92, 0.2]]
)
# Wrist pitch (positive: stick down) leads the height: cocked up while rising, snap down.
PITCH_KEYPOINTS = np.array(
    [[0.0, 0.8], [0.1, 0.1], [0.25, -0.6], [0.45, -1.0], [0.65, -0.7], [0.8, 0.0], [0.92, 0.9]]
)
FIGURE8_SIZE = (0.10, 0.06)  # [m] half width (lateral) and half height of the figure-8

ARM_STIFFNESS = 100.0  # [1/s^2] low-gain feedback around the DMP plan (damping critical)
HAND_STIFFNESS = 100.0  # [1/s^2] figure-8 hand task
JOINT_LIMIT_HORIZON = 0.05  # [s] the DMP-driven joints brake for their position/velocity limits
POSTURE_WEIGHT = 1e-2
COM_WEIGHT, BASE_WEIGHT = 10.0, 1.0
GROUND_STIFFNESS = 2e4  # [N/m] per sole corner
FALL_HEIGHT = 0.7  # [m] the pelvis (base_link) has fallen when lower, on either backend
MASS_ERROR = 1.1  # the controller's arms (and hands) are 10 % heavier than the simulated ones

BACKENDS = ("mujoco", "native")
MUJOCO_FRICTION = 1.0  # floor-sole friction coefficient of the nominal MuJoCo runs
CONTROLLER_FRICTION = (
    0.7  # the controller's friction cone (SoleContact default), at most the floor's
)
FRICTIONS = (0.4, 0.7)  # floor friction of the low-friction scenarios (1.0 is the nominal run)
LINK_MASS_SCALES = (0.9, 1.1)  # every link of the controller's model, mass and inertia
TIGHT_TORQUE = 0.8  # torque limits at this fraction of the nominal run's peak QP torque use
PUSH_TIME = 0.5  # [s] when the push on the pelvis starts
PUSH_DURATION = 0.1  # [s] the impulse is spread over this time
PUSH_LADDER = (10.0, 20.0, 30.0, 40.0, 60.0, 80.0)  # [N s] forward impulses tried, in order
PUSH_LADDER_QUICK = (10.0, 60.0)
PUSH_BISECTIONS = 2  # halvings after the ladder (none in quick mode)
SCENARIO_SECONDS = {"quick": 1.5, "full": 4.0}  # [s] each MuJoCo scenario run
PUSH_RUN_SECONDS = {"quick": 1.5, "full": 2.5}  # [s] each push run (push at PUSH_TIME)
VIDEO_FPS = 20.0
VIDEO_SECONDS = 3.0  # [s] of each clip (from the start of its run)
VIDEO_SIZE = (320, 240)  # [pixels]

# Discrete movement: a forehand of the right arm (joints 1..7; 5 held), from the drumming
# posture. The demonstration is two overlapping minimum-jerk submovements: a backswing, then a
# faster forward swing through the contact point to the follow-through (peak joint speeds
# 74-85 % of the Talos velocity limits).
SWING_BACK = (-0.55, -0.55, -0.20, -1.25, 0.0, 0.25, -0.25)
SWING_FOLLOW = (0.05, -0.20, 0.70, -1.70, 0.0, -0.15, 0.15)
SWING_BACK_SECONDS = 0.9  # [s] backswing duration
SWING_FORWARD_START = 0.75  # [s] the forward swing starts before the backswing ends
SWING_FORWARD_SECONDS = 0.5  # [s]
SWING_HOLD = 0.75  # [s] simulated after the demonstrated duration
SWING_FINISH_RAISE = 0.12  # [m] the new goal: the follow-through hand this much higher
