"""Bad inputs to the constrained fit, minimum jerk, retiming, learning, recognition, walking and
metrics: each is a named error (never NaN, a silently wrong answer or a bare traceback), and
requests beyond the allocation bound are refused before allocating."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from dmpopt import frequency_adaptation, metrics, recognition, validation
from dmpopt.exceptions import InvalidInputError, ResourceLimitError, ShapeError
from dmpopt.fitting.constrained import (
    Bounds,
    ViaPoint,
    build_fitting_problem,
    diagnose_infeasibility,
    fit_weights_constrained,
    solve_fitting_problem,
    solve_qp,
)
from dmpopt.fitting.imitation import fit_discrete
from dmpopt.fitting.minimum_jerk import (
    MIN_SEGMENT_FRACTION,
    jerk_response,
    minimum_jerk,
    minimum_jerk_constrained,
    minimum_jerk_via_points,
)
from dmpopt.learning import (
    CMAES,
    PIBB,
    EpisodicNAC,
    EpisodicReinforce,
    LearningCurve,
    RewardTask,
    enac_gradient,
    make_method,
    multi_dof_reaching_task,
    optimise,
    paper_reaching_task,
    via_point_task,
)
from dmpopt.retiming import retime, time_scaled, uniform_time_scaling
from dmpopt.trajectory import Trajectory

TIMES = np.linspace(0.0, 1.0, 101)
SHAPE = 10 * TIMES**3 - 15 * TIMES**4 + 6 * TIMES**5  # minimum jerk from 0 to 1 in 1 s
DEMO = Trajectory.from_positions(TIMES, np.column_stack([SHAPE, 0.5 * SHAPE]))
DEMO_1 = Trajectory.from_positions(TIMES, SHAPE[:, None])
REFERENCE = fit_discrete(DEMO, 10)
PLAN = minimum_jerk([0.0, 0.0], [1.0, 0.5], 1.0, n_samples=101)
TASK = paper_reaching_task(dt=0.01)
WEIGHTS = TASK.initial_weights
FEATURES = TASK.policy_features
NAN = float("nan")
CURVE = LearningCurve(
    trials=np.array([0.0, 5.0]),
    returns=np.array([-2.0, -1.0]),
    improvement=np.array([0.0, 0.5]),
    weights=np.zeros((2, 1, 10)),
)


def fit(**options):
    return fit_weights_constrained(DEMO, 10, reference=REFERENCE, **options)


PROBLEM = build_fitting_problem(DEMO, reference=REFERENCE)


def report_of_another_size():
    return solve_fitting_problem(
        build_fitting_problem(DEMO, reference=REFERENCE, bounds=Bounds(velocity=10.0))
    )[1]


def told(learner, rewards):
    learner.ask()
    learner.tell(rewards)


BAD_INPUTS = {
    # constrained fit: NaN tolerances used to leave the goal free and report success
    "end_position_tolerance nan": (lambda: fit(end_position_tolerance=NAN), "end_position_tol"),
    "end_velocity_tolerance inf": (lambda: fit(end_velocity_tolerance=np.inf), "end_velocity"),
    "end_position_tolerance str": (lambda: fit(end_position_tolerance="0.1"), "end_position"),
    "end_position_tolerance bool": (lambda: fit(end_position_tolerance=True), "end_position"),
    "end_position_tolerance complex": (lambda: fit(end_position_tolerance=1j), "end_position"),
    "duration inf": (lambda: fit(duration=np.inf), "duration"),
    "n_samples nan": (lambda: fit(n_samples=NAN), "n_samples"),
    "regularization nan": (lambda: fit(regularization=NAN), "regularization"),
    "margin negative": (lambda: fit(margin=-1.0), "margin"),
    "goal str": (lambda: fit(goal="a"), "goal"),
    "start_velocity complex": (lambda: fit(start_velocity=[1j, 0.0]), "start_velocity"),
    "start_velocity empty": (lambda: fit(start_velocity=[]), "start_velocity"),
    "via_points single": (lambda: fit(via_points=ViaPoint(0.5, [0.5, 0.2])), "via_points"),
    "via_points None": (lambda: fit(via_points=None), "via_points"),
    "via position dofs": (lambda: fit(via_points=[ViaPoint(0.5, [0, 0, 0])]), "via_points"),
    "fit warm_start str": (lambda: fit(warm_start="last"), "warm_start"),
    "diagnose None": (lambda: diagnose_infeasibility(None), "problem"),
    "fit a built problem": (
        lambda: fit_weights_constrained(PROBLEM),
        "got a FittingProblem; solve a built problem with solve_fitting_problem",
    ),
    "solve a Trajectory": (lambda: solve_fitting_problem(DEMO), "problem must be a FittingProblem"),
    "solve warm_start problem": (
        lambda: solve_fitting_problem(PROBLEM, warm_start=PROBLEM),
        "warm_start must be a FitReport",
    ),
    "solve warm_start other size": (
        lambda: solve_fitting_problem(PROBLEM, warm_start=report_of_another_size()),
        "warm_start comes from a problem with",
    ),
    "fit solver unknown": (lambda: fit(solver="osqp"), "solver must be 'auto' or one of"),
    "solve_qp solver None": (
        lambda: solve_qp(np.eye(2), [0.0, 0.0], np.eye(2), [0, 0], [1, 1], solver=None),
        "solver",
    ),
    "solve_qp hessian 3x3": (
        lambda: solve_qp(np.eye(3), [0.0, 0.0], np.eye(2), [0, 0], [1, 1]),
        r"hessian \(3, 3\), constraint_matrix \(2, 2\), lower \(2,\) and upper \(2,\) do not fit",
    ),
    "solve_qp lower of 3 rows": (
        lambda: solve_qp(np.eye(2), [0.0, 0.0], np.eye(2), [0, 0, 0], [1, 1]),
        r"lower \(3,\) and upper \(2,\) do not fit a gradient of 2 entries",
    ),
    "solve_qp upper of 3 rows": (
        lambda: solve_qp(np.eye(2), [0.0, 0.0], np.eye(2), [0, 0], [1, 1, 1]),
        r"upper \(3,\) do not fit",
    ),
    "solve_qp hessian 1d": (
        lambda: solve_qp(np.ones(2), [0.0, 0.0], np.eye(2), [0, 0], [1, 1]),
        r"hessian has shape \(2,\), expected 2 dimension",
    ),
    "solve_qp gradient 2d": (
        lambda: solve_qp(np.eye(2), np.zeros((2, 1)), np.eye(2), [0, 0], [1, 1]),
        r"gradient has shape \(2, 1\), expected 1 dimension",
    ),
    "solve_qp matrix nan": (
        lambda: solve_qp(np.eye(2), [0.0, 0.0], [[NAN, 0.0], [0.0, 1.0]], [0, 0], [1, 1]),
        r"constraint_matrix must be finite and lower, upper free of NaN",
    ),
    "solve_qp lower above upper": (
        lambda: solve_qp(np.eye(2), [0.0, 0.0], np.eye(2), [0, 2], [1, 1]),
        r"lower exceeds upper in row\(s\) \[1\]",
    ),
    "solve_qp rows of another width": (
        lambda: solve_qp(np.eye(2), [0.0, 0.0], np.eye(3), [0, 0, 0], [1, 1, 1]),
        "constraint_matrix",
    ),
    "RewardTask with a constraint ViaPoint": (
        lambda: RewardTask(TASK.dmp, via_points=[ViaPoint(0.1, [0.0])]),
        r"via_points\[0\] must be a ViaPointReward.*ViaPointReward\(time, position, weight\)",
    ),
    "solve_qp nan gradient": (
        lambda: solve_qp(np.eye(2), [NAN, 0.0], np.eye(2), [0, 0], [1, 1]),
        "gradient",
    ),
    "solve_qp nan bound": (
        lambda: solve_qp(np.eye(2), [0.0, 0.0], np.eye(2), [NAN, 0], [1, 1]),
        "lower",
    ),
    "fit margin 0.5": (
        lambda: fit(margin=0.5),
        r"margin must be a finite number >= 0 and <= 0.1, got 0.5; keep it tiny, e.g. 1e-6",
    ),
    "fit n_samples 2": (lambda: fit(n_samples=2), r"n_samples must be an integer >= 3, got 2"),
    "fit duration 0": (lambda: fit(duration=0.0), r"duration must be a finite number > 0, got 0"),
    "fit regularization -1": (
        lambda: fit(regularization=-1.0),
        r"regularization must be a finite number >= 0, got -1",
    ),
    "fit end_velocity_tolerance -1": (
        lambda: fit(end_velocity_tolerance=-1.0),
        r"end_velocity_tolerance must be a finite number >= 0, got -1.0; pass None to leave it",
    ),
    "fit end_acceleration_tolerance -1": (
        lambda: fit(end_acceleration_tolerance=-1.0),
        r"end_acceleration_tolerance must be a finite number >= 0, got -1.0; pass None to lea",
    ),
    "fit goal dofs": (
        lambda: fit(goal=[1.0, 1.0, 1.0]),
        r"goal has shape \(3,\), expected \(2,\) for 2 DOFs",
    ),
    "fit via_points str": (
        lambda: fit(via_points="via"),
        r"via_points must be a sequence of ViaPoint, got str",
    ),
    "fit duration nan": (
        lambda: fit(duration=NAN),
        r"duration must be a finite number > 0, got nan",
    ),
    "fit end tolerance -1": (
        lambda: fit(end_position_tolerance=-1.0),
        r"end_position_tolerance must be a finite number >= 0, got -1.0; pass None to leave it",
    ),
    "fit reference of 1 DOF": (
        lambda: fit_weights_constrained(DEMO, reference=fit_discrete(DEMO_1, 10)),
        r"reference must be a DiscreteDMP with the demonstration's 2 DOFs, got a DiscreteDMP "
        r"with 1 DOFs; pass fit_discrete\(demo, n_basis\) or None",
    ),
    "fit reference str": (
        lambda: fit_weights_constrained(DEMO, reference="dmp"),
        r"reference must be a DiscreteDMP with the demonstration's 2 DOFs, got str",
    ),
    "fit objective speed": (
        lambda: fit(objective="speed"),
        r"objective must be one of \('position', 'forcing'\), got 'speed'",
    ),
    "fit bounds dict": (lambda: fit(bounds={}), r"bounds must be a Bounds, got dict; write"),
    "fit via tolerance dofs": (
        lambda: fit(via_points=[ViaPoint(0.5, [0.5, 0.2], [0.1, 0.1, 0.1])]),
        r"via_points\[0\].tolerance has shape \(3,\), expected \(2,\) for 2 DOFs",
    ),
    "fit start dofs": (
        lambda: fit(start=[0.0, 0.0, 0.0]),
        r"start has shape \(3,\), expected \(2,\) for 2 DOFs",
    ),
    "fit via after the end": (
        lambda: fit(via_points=[ViaPoint(1.5, [0.5, 0.2])]),
        r"via_points\[0\] time 1.5 s is outside the plan \[0, 1(.0)?\] s",
    ),
    "Bounds position_lower dofs": (
        lambda: fit(bounds=Bounds(position_lower=[0.0, 0.0, 0.0])),
        r"position_lower has shape \(3,\), expected \(2,\) for 2 DOFs",
    ),
    "Bounds position_upper dofs": (
        lambda: fit(bounds=Bounds(position_upper=[1.0, 1.0, 1.0])),
        r"position_upper has shape \(3,\), expected \(2,\) for 2 DOFs",
    ),
    "Bounds lower above upper": (
        lambda: Bounds(position_lower=[0.0, 1.0], position_upper=[1.0, 0.5]),
        r"position_lower exceeds position_upper for DOF\(s\) \[1\] \(1 > 0.5\); give",
    ),
    "Bounds jerk 0": (lambda: Bounds(jerk=0.0), r"jerk must be positive, got \[0.0\]"),
    "Bounds acceleration 2d": (
        lambda: Bounds(acceleration=np.ones((2, 2))),
        r"acceleration has shape \(2, 2\), expected \(n_dofs,\) or a scalar",
    ),
    "ViaPoint tolerance negative": (
        lambda: ViaPoint(0.5, [0.0], -1.0),
        r"tolerance must be a number >= 0 or one per DOF, got \[-1.0\]; give the half-width",
    ),
    "ViaPoint tolerance 2d": (
        lambda: ViaPoint(0.5, [0.0], np.ones((2, 2))),
        r"tolerance must be a number >= 0 or one per DOF, got \[\[1.0, 1.0\]",
    ),
    "ViaPoint ball two radii": (
        lambda: ViaPoint(0.5, [0.0, 0.0], [0.1, 0.1], "ball"),
        r"a 'ball' via-point takes one scalar tolerance \(its radius\)",
    ),
    "ViaPoint norm l1": (
        lambda: ViaPoint(0.5, [0.0], norm="l1"),
        r"norm must be 'box' or 'ball', got 'l1'",
    ),
    "ViaPoint time negative": (
        lambda: ViaPoint(-0.5, [0.0]),
        r"time must be a finite number >= 0, got -0.5",
    ),
    "ViaPoint position 2d": (
        lambda: ViaPoint(0.5, np.ones((2, 2))),
        r"position has shape \(2, 2\), expected \(n_dofs,\) or a scalar",
    ),
    "mj duration 0": (
        lambda: minimum_jerk(0, 1, 0.0),
        r"duration must be a finite number > 0, got 0",
    ),
    "mj dt 0.6 of 1 s": (
        lambda: minimum_jerk(0, 1, 1.0, 0.6),
        r"dt must be a finite number > 0 and <= 0.5, got 0.6; or give n_samples",
    ),
    "mj dt 0.4 of 0.7 s": (lambda: minimum_jerk(0, 1, 0.7, 0.4), r"<= 0.35, got 0.4"),
    "mj n_samples 2": (
        lambda: minimum_jerk(0, 1, 1.0, n_samples=2),
        r"n_samples must be an integer >= 3, got 2",
    ),
    "mjc margin 0.5": (
        lambda: minimum_jerk_constrained(0, 1, 1.0, margin=0.5),
        r"margin must be a finite number >= 0 and <= 0.1, got 0.5; keep it tiny, e.g. 1e-6",
    ),
    "mjc margin -0.1": (
        lambda: minimum_jerk_constrained(0, 1, 1.0, margin=-0.1),
        r"margin must be a finite number >= 0",
    ),
    "mjc n_segments 2": (
        lambda: minimum_jerk_constrained(0, 1, 1.0, n_segments=2),
        r"n_segments must be an integer >= 3, got 2",
    ),
    "mjc duration -1": (
        lambda: minimum_jerk_constrained(0, 1, -1.0),
        r"duration must be a finite number > 0, got -1",
    ),
    "jerk_response times 2d": (
        lambda: jerk_response(np.ones((2, 2)), 3),
        r"times has shape \(2, 2\), expected 1 dimension",
    ),
    "jerk_response n_segments 0 message": (
        lambda: jerk_response(TIMES, 0),
        r"n_segments must be an integer >= 1, got 0",
    ),
    "Bounds velocity bool": (lambda: Bounds(velocity=True), "velocity"),
    "Bounds velocity empty": (lambda: Bounds(velocity=[]), "velocity"),
    "Bounds velocity dofs": (lambda: fit(bounds=Bounds(velocity=[1, 2, 3])), "velocity"),
    "ViaPoint time str": (lambda: ViaPoint("0.5", [0.0]), "time"),
    "ViaPoint position None": (lambda: ViaPoint(0.5, None), "position"),
    "ViaPoint tolerance bool": (lambda: ViaPoint(0.5, [0.0], True), "tolerance"),
    "ViaPoint norm None": (lambda: ViaPoint(0.5, [0.0], norm=None), "norm"),
    # minimum jerk
    "mj dt str": (lambda: minimum_jerk(0, 1, 1.0, "0.1"), "dt"),
    "mj dt above duration": (lambda: minimum_jerk(0, 1, 1.0, 2.0), "dt"),
    "mj n_samples float": (lambda: minimum_jerk(0, 1, 1.0, n_samples=2.7), "n_samples"),
    "mj start empty": (lambda: minimum_jerk([], [], 1.0), "start"),
    "mj start bool": (lambda: minimum_jerk(True, 1, 1.0), "start"),
    "mj dofs differ": (lambda: minimum_jerk([0, 0], [1, 1, 1], 1.0), "start"),
    "mjv via at 1e-12 s": (
        lambda: minimum_jerk_via_points(0, 1, 1.0, [ViaPoint(1e-12, [0.5])]),
        "via_points",
    ),
    "mjv vias 1e-9 s apart": (
        lambda: minimum_jerk_via_points(
            0, 1, 1.0, [ViaPoint(0.5, [0.5]), ViaPoint(0.5 + 1e-9, [0.6])]
        ),
        "via_points",
    ),
    "mjv via not a ViaPoint": (lambda: minimum_jerk_via_points(0, 1, 1.0, [1]), "via_points"),
    "jerk_response n_segments 0": (lambda: jerk_response(TIMES, 0), "n_segments"),
    "mjc n_segments str": (lambda: minimum_jerk_constrained(0, 1, 1.0, n_segments="60"), "n_seg"),
    "mjc margin nan": (lambda: minimum_jerk_constrained(0, 1, 1.0, margin=NAN), "margin"),
    "mjc bounds dict": (lambda: minimum_jerk_constrained(0, 1, 1.0, bounds={}), "bounds"),
    "mjc ball via": (
        lambda: minimum_jerk_constrained(0, 1, 1.0, via_points=[ViaPoint(0.5, [0.5], 0.1, "ball")]),
        r"via_points\[0\] has norm 'ball'",
    ),
    "mjc via after end": (
        lambda: minimum_jerk_constrained(0, 1, 1.0, via_points=[ViaPoint(2.0, [0.5])]),
        "via_points",
    ),
    # retiming
    "retime dt zero": (lambda: retime(PLAN, 1.0, 1.0, dt=0.0), "dt"),
    "retime dt negative": (lambda: retime(PLAN, 1.0, 1.0, dt=-1.0), "dt"),
    "retime dt str": (lambda: retime(PLAN, 1.0, 1.0, dt="0.01"), "dt"),
    "retime velocity_limit bool": (lambda: retime(PLAN, True), "velocity_limit"),
    "retime velocity_limit str": (lambda: retime(PLAN, "1"), "velocity_limit"),
    "retime velocity_limit dofs": (lambda: retime(PLAN, [1, 1, 1]), "velocity_limit"),
    "retime n_gridpoints zero": (lambda: retime(PLAN, 1.0, n_gridpoints=0), "n_gridpoints"),
    "retime robot str": (lambda: retime(PLAN, 1.0, robot="x", torque_limit=1.0), "robot"),
    "retime trajectory None": (lambda: retime(None, 1.0), "trajectory"),
    "uniform scaling without limits": (lambda: uniform_time_scaling(PLAN), "velocity_limit"),
    "time_scaled factor bool": (lambda: time_scaled(PLAN, True), "factor"),
    "time_scaled factor underflows": (lambda: time_scaled(PLAN, 1e-320), "factor"),
    # learning: NaN initial weights used to sample NaN
    "PIBB weights nan": (lambda: PIBB([[NAN, 0.0]], 1.0), "initial_weights"),
    "CMAES weights nan": (lambda: CMAES([[NAN, 0.0]], 1.0), "initial_weights"),
    "eNAC weights nan": (lambda: EpisodicNAC(FEATURES, WEIGHTS * NAN, 1.0), "initial_weights"),
    "eREINFORCE weights nan": (
        lambda: EpisodicReinforce(FEATURES, WEIGHTS * NAN, 1.0),
        "initial_weights",
    ),
    "eNAC features nan": (lambda: EpisodicNAC(FEATURES * NAN, WEIGHTS, 1.0), "features"),
    "PIBB weights None": (lambda: PIBB(None, 1.0), "initial_weights"),
    "PIBB weights 3-D": (lambda: PIBB(np.zeros((2, 2, 2)), 1.0), "initial_weights"),
    "PIBB std str": (lambda: PIBB(WEIGHTS, "1"), "exploration_std"),
    "CMAES std zero": (lambda: CMAES(WEIGHTS, 0.0), "exploration_std"),
    "CMAES options unknown": (lambda: CMAES(WEIGHTS, 1.0, options={"nonsense": 1}), "options"),
    "PIBB eliteness nan": (lambda: PIBB(WEIGHTS, 1.0, eliteness=NAN), "eliteness"),
    "PIBB covariance_rate 2": (lambda: PIBB(WEIGHTS, 1.0, covariance_rate=2.0), "covariance"),
    "PIBB n_rollouts nan": (lambda: PIBB(WEIGHTS, 1.0, n_rollouts=NAN), "n_rollouts"),
    "eNAC step_rule None": (lambda: EpisodicNAC(FEATURES, WEIGHTS, 1.0, step_rule=None), "step"),
    "PIBB tell nan": (lambda: told(PIBB(WEIGHTS, 1.0, n_rollouts=5), [NAN] * 5), "rewards"),
    "PIBB tell count": (lambda: told(PIBB(WEIGHTS, 1.0, n_rollouts=5), [0.0] * 4), "rewards"),
    "PIBB tell complex": (lambda: told(PIBB(WEIGHTS, 1.0, n_rollouts=5), [1j] * 5), "rewards"),
    "CMAES tell nan": (lambda: told(CMAES(WEIGHTS, 1.0, n_rollouts=5), [NAN] * 5), "rewards"),
    "CMAES tell count": (lambda: told(CMAES(WEIGHTS, 1.0, n_rollouts=5), [0.0] * 6), "rewards"),
    "eNAC tell nan": (
        lambda: told(EpisodicNAC(FEATURES, WEIGHTS, 1.0, n_rollouts=5), [NAN] * 5),
        "rewards",
    ),
    "eREINFORCE tell count": (
        lambda: told(EpisodicReinforce(FEATURES, WEIGHTS, 1.0, n_rollouts=5), [0.0] * 3),
        "rewards",
    ),
    "enac_gradient returns count": (
        lambda: enac_gradient(np.zeros((5, 2)), np.zeros(4)),
        "returns",
    ),
    "curve weights_at before start": (lambda: CURVE.weights_at(-1), "trials"),
    "curve trials_to nan": (lambda: CURVE.trials_to(NAN), "fraction"),
    "make_method without std": (lambda: make_method("pibb", TASK), "exploration_std"),
    "optimise n_trials nan": (lambda: optimise(PIBB(WEIGHTS, 1.0), TASK, NAN), "n_trials"),
    "optimise method None": (lambda: optimise(None, TASK, 10), "method"),
    "task dt zero": (lambda: paper_reaching_task(dt=0.0), "dt"),
    "task jerk_weight str": (lambda: paper_reaching_task(jerk_weight="1"), "jerk_weight"),
    "task goals empty": (lambda: multi_dof_reaching_task(goals=[], dt=0.01), "goals"),
    "task via time nan": (lambda: via_point_task(via_time=NAN, dt=0.01), r"via_points\[0\]"),
    "task via position nan": (
        lambda: via_point_task(via_position=(NAN, 0.0), dt=0.01),
        r"via_points\[0\]",
    ),
    "task rollouts weights nan": (lambda: TASK.rollouts(WEIGHTS * NAN), "weights"),
    "task rewards shape": (lambda: TASK.rewards(np.zeros((2, 3))), "plans"),
    "task evaluate None": (lambda: TASK.evaluate(None), "exploration"),
    # recognition
    "features direction_weight str": (
        lambda: recognition.movement_features([REFERENCE], direction_weight="a"),
        "direction_weight",
    ),
    "features dmps None": (lambda: recognition.movement_features(None), "dmps"),
    "features complex": (
        lambda: recognition.NearestNeighbourClassifier().fit(np.eye(3) * 1j, [0, 1, 2]),
        "features",
    ),
    "features without columns": (
        lambda: recognition.NearestNeighbourClassifier().fit(np.zeros((3, 0)), [0, 1, 2]),
        "features",
    ),
    "features overflow": (
        lambda: recognition.NearestNeighbourClassifier().fit(np.eye(3) * 1e200, [0, 1, 2]),
        "features",
    ),
    "shrinkage None": (
        lambda: recognition.ShrinkageLdaClassifier(None).fit(np.eye(3), [0, 1, 2]),
        "shrinkage",
    ),
    "leave_one_out classifier None": (
        lambda: recognition.leave_one_out(None, np.eye(3), [0, 1, 2]),
        "classifier",
    ),
    "confusion labels 2-D": (lambda: recognition.confusion_matrix([[0]], [[0]]), "labels"),
    "partial rotation str": (
        lambda: recognition.PartialObservationClassifier(rotation="yes").fit([REFERENCE], [0]),
        "rotation",
    ),
    "first_part fraction bool": (lambda: recognition.first_part(DEMO, True), "fraction"),
    "first_part trajectory None": (lambda: recognition.first_part(None, 0.5), "trajectory"),
    # walking
    "measured_frequency None": (
        lambda: frequency_adaptation.measured_frequency(None),
        "step_duration",
    ),
    "measured_frequency bool": (
        lambda: frequency_adaptation.measured_frequency(True),
        "step_duration",
    ),
    "adapt_frequency nan": (
        lambda: frequency_adaptation.adapt_frequency(NAN, 0.5, 0.3),
        "frequency",
    ),
    "adapt_frequency gain str": (
        lambda: frequency_adaptation.adapt_frequency(1.0, 0.5, "a"),
        "gain",
    ),
    "heel_strike_phase leg bool": (lambda: frequency_adaptation.heel_strike_phase(True), "leg"),
    "heel_strike_phase oscillator_leg 5": (
        lambda: frequency_adaptation.heel_strike_phase(0, 5),
        "oscillator_leg",
    ),
    "HeelStrike time nan": (lambda: frequency_adaptation.HeelStrike(NAN, 0, np.zeros(3)), "time"),
    "HeelStrike leg 3": (lambda: frequency_adaptation.HeelStrike(0.0, 3, np.zeros(3)), "leg"),
    "detector min_swing_time None": (
        lambda: frequency_adaptation.HeelStrikeDetector(None),
        "min_swing",
    ),
    "detector in_contact short": (
        lambda: frequency_adaptation.HeelStrikeDetector().update(0.0, [True]),
        "in_contact",
    ),
    "adaptation oscillator_leg 5": (
        lambda: frequency_adaptation.FrequencyAdaptation(1.0, oscillator_leg=5),
        "oscillator_leg",
    ),
    "adaptation strike None": (
        lambda: frequency_adaptation.FrequencyAdaptation(1.0).on_heel_strike(None),
        "strike",
    ),
    # metrics
    "jerk None": (lambda: metrics.jerk(None), "trajectory"),
    "limit_use nan": (lambda: metrics.limit_use(PLAN, NAN), "velocity_limit"),
    "limit_use zero": (lambda: metrics.limit_use(PLAN, 0.0), "velocity_limit"),
    "path_distance nan": (
        lambda: metrics.path_distance(np.full((3, 2), NAN), np.eye(2)),
        "positions",
    ),
    "path_distance dofs": (
        lambda: metrics.path_distance(np.zeros((3, 2)), np.zeros((3, 3))),
        "reference",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_is_a_named_error(case):
    """Each bad argument raises InvalidInputError or ShapeError naming the argument."""
    call, name = BAD_INPUTS[case]
    with pytest.raises((InvalidInputError, ShapeError), match=name):
        call()


RESOURCE_REQUESTS = {
    "fit n_samples 1e9": (lambda: fit(n_samples=10**9), "1000000000 samples"),
    "fit 1e5 via-points": (
        lambda: fit(via_points=[ViaPoint(0.5, [0.5, 0.2], 0.1)] * 10**5),
        "merge them",
    ),
    "fit n_basis 1e6": (lambda: fit_weights_constrained(DEMO, 10**6), "1000000 basis"),
    "mj dt 1e-12": (lambda: minimum_jerk(0, 1, 1.0, 1e-12), "every 1e-12 s"),
    "mj n_samples 1e12": (lambda: minimum_jerk(0, 1, 1.0, n_samples=10**12), "n_samples"),
    "mjc n_segments 1e6": (
        lambda: minimum_jerk_constrained(0, 1, 1.0, n_segments=10**6),
        "1000000 jerk segments",
    ),
    "retime n_gridpoints 1e9": (lambda: retime(PLAN, 1.0, n_gridpoints=10**9), "n_gridpoints"),
    "PIBB n_rollouts 1e9": (lambda: PIBB(WEIGHTS, 1.0, n_rollouts=10**9), "n_rollouts"),
    "CMAES n_rollouts 1e9": (lambda: CMAES(WEIGHTS, 1.0, n_rollouts=10**9), "n_rollouts"),
    "eNAC n_rollouts 1e7": (
        lambda: EpisodicNAC(FEATURES, WEIGHTS, 1.0, n_rollouts=10**7),
        "n_rollouts",
    ),
    "PIBB 1e5 weights": (lambda: PIBB(np.zeros((1, 10**5)), 1.0), "covariance"),
    "task dt 1e-7": (lambda: paper_reaching_task(dt=1e-7), "raise dt"),
    "plan_metric_factor 1e7": (
        lambda: recognition.plan_metric_factor(REFERENCE, n_samples=10**7),
        "n_samples",
    ),
    "LDA 1e5 features": (
        lambda: recognition.ShrinkageLdaClassifier().fit(np.zeros((3, 10**5)), [0, 1, 2]),
        "covariance",
    ),
    "path_distance 1e6 x 1e6": (
        lambda: metrics.path_distance(np.zeros((10**6, 1)), np.zeros((10**6, 1))),
        "subsample",
    ),
}


@pytest.mark.parametrize("case", sorted(RESOURCE_REQUESTS))
def test_oversized_request_is_refused_before_allocating(case):
    """Requests beyond the allocation (or time) bound raise ResourceLimitError with the fix."""
    call, text = RESOURCE_REQUESTS[case]
    with pytest.raises(ResourceLimitError, match=text):
        call()


def test_retime_with_a_tiny_velocity_limit_states_the_duration_estimate():
    """The lower bound of the duration is the travel over the limit: 1 / 1e-9 s for DOF 0."""
    with pytest.raises(ResourceLimitError, match=r"1e\+09 s sampled every 0\.01 s"):
        retime(PLAN, 1e-9)


@settings(max_examples=15, deadline=None)
@given(
    duration=st.floats(1e-3, 1e3),
    fraction=st.floats(MIN_SEGMENT_FRACTION, 1 - MIN_SEGMENT_FRACTION),
)
@example(duration=128.5, fraction=0.99)  # the gap to the end rounds below 0.01 of the duration
def test_via_point_on_the_plain_optimum_gives_the_closed_form(duration, fraction):
    """A via-point on the rest-to-rest minimum-jerk curve does not change the optimum, at
    any time scale: y = y0 + (g - y0)(10 s^3 - 15 s^4 + 6 s^5), s = t / T, and derivatives."""
    s = fraction
    via = ViaPoint(fraction * duration, [10 * s**3 - 15 * s**4 + 6 * s**5])
    result = minimum_jerk_via_points(0.0, 1.0, duration, [via], n_samples=201)
    s = result.times / duration
    np.testing.assert_allclose(result.positions[:, 0], 10 * s**3 - 15 * s**4 + 6 * s**5, atol=1e-7)
    velocity = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
    np.testing.assert_allclose(result.velocities[:, 0] * duration, velocity * duration, atol=1e-6)
    acceleration = (60 * s - 180 * s**2 + 120 * s**3) / duration**2
    np.testing.assert_allclose(
        result.accelerations[:, 0] * duration**2, acceleration * duration**2, atol=1e-5
    )


def test_via_points_at_the_minimum_spacing_are_accepted_below_it_refused():
    """Gaps of exactly MIN_SEGMENT_FRACTION of the duration are allowed; smaller are not."""
    gap = MIN_SEGMENT_FRACTION * 2.0
    result = minimum_jerk_via_points(0.0, 1.0, 2.0, [ViaPoint(gap, [0.0])], n_samples=401)
    assert np.all(np.isfinite(result.positions))
    with pytest.raises(InvalidInputError, match="closer than 0.01 of the duration"):
        minimum_jerk_via_points(0.0, 1.0, 2.0, [ViaPoint(0.99 * gap, [0.0])])


def test_uniform_time_scaling_matches_the_closed_form_peak_velocity():
    """Minimum jerk peaks at 1.875 (g - y0) / T: the factor is 1.875 * 1 / (1 s * limit)."""
    factor = uniform_time_scaling(PLAN, velocity_limit=[0.5, 10.0])
    assert factor == pytest.approx(1.875 / 0.5, rel=1e-9)


def test_uniform_time_scaling_of_a_motionless_trajectory_is_refused():
    """Every factor respects the limits of a motionless plan: there is no smallest one."""
    still = Trajectory(TIMES, np.ones((101, 1)), np.zeros((101, 1)), np.zeros((101, 1)))
    with pytest.raises(InvalidInputError, match="neither moves nor accelerates"):
        uniform_time_scaling(still, velocity_limit=1.0)


@pytest.mark.parametrize("value", [0.3, -7.0, 0.0])
def test_a_constant_path_with_rounding_velocities_is_refused_as_retime_refuses_it(value):
    """Positions constant, velocities and accelerations from finite differences (rounding,
    once a factor of 5.7e-14): the same refusal as retime's."""
    times = np.linspace(0.0, 1.0, 50)
    still = Trajectory.from_positions(times, np.c_[np.full(50, value), np.full(50, 2 * value)])
    message = (
        "trajectory neither moves nor accelerates, so every time scaling respects the limits "
        "and there is no smallest factor"
    )
    for call in (uniform_time_scaling, retime):
        with pytest.raises(InvalidInputError) as error:
            call(still, [1.0, 1.0], [1.0, 1.0])
        assert str(error.value) == message


def test_constrained_fit_holds_a_finite_end_tolerance_and_refuses_nan():
    """A finite tolerance bounds |y(T) - g|; NaN, which read as 'no limit', is refused."""
    _, report = fit(end_position_tolerance=1e-3)
    end = report.trajectory.positions[-1]
    assert np.all(np.abs(end - DEMO.positions[-1]) <= 1e-3 * (1 + 1e-6))
    with pytest.raises(InvalidInputError, match="end_position_tolerance must be a finite number"):
        fit(end_position_tolerance=NAN)


@pytest.mark.parametrize("method", ["pibb", "cmaes", "enac", "ereinforce"])
def test_a_refused_tell_keeps_the_batch_pending(method):
    """After a tell() with NaN rewards the same batch can still be told once, correctly."""
    learner = make_method(method, TASK, seed=0, exploration_std=1.0, n_rollouts=5)
    exploration = learner.ask()
    with pytest.raises(InvalidInputError, match="rewards"):
        learner.tell([NAN] * 5)
    learner.tell(TASK.evaluate(exploration))
    assert learner.n_trials == 5
    with pytest.raises(InvalidInputError, match="without a pending ask"):
        learner.tell(TASK.evaluate(exploration))


def test_detector_refuses_time_running_backwards():
    """Heel strikes need increasing time; a decreasing one would give a negative step."""
    detector = frequency_adaptation.HeelStrikeDetector(min_swing_time=0.0)
    detector.update(1.0, [False, False])
    with pytest.raises(InvalidInputError, match="time must not decrease"):
        detector.update(0.5, [True, False])


def test_adaptation_refuses_strikes_out_of_order():
    """Eq. (21) needs T_n > 0: a strike at or before the previous one is refused."""
    adaptation = frequency_adaptation.FrequencyAdaptation(frequency=3.0)
    adaptation.on_heel_strike(frequency_adaptation.HeelStrike(1.0, 0, np.zeros(3)))
    with pytest.raises(InvalidInputError, match="strike.time"):
        adaptation.on_heel_strike(frequency_adaptation.HeelStrike(1.0, 1, np.zeros(3)))


def test_path_distance_in_chunks_equals_the_brute_force_distance(monkeypatch):
    """With a tiny allocation bound (many chunks) the distance equals the point-to-segment
    minimum written out in full."""
    rng = np.random.default_rng(0)
    points, polyline = rng.standard_normal((37, 2)), rng.standard_normal((11, 2))

    def brute(a, b):
        best = []
        for p in a:
            candidates = []
            for start, end in zip(b[:-1], b[1:]):
                segment = end - start
                t = np.clip((p - start) @ segment / (segment @ segment), 0.0, 1.0)
                candidates.append(np.linalg.norm(p - (start + t * segment)))
            best.append(min(candidates))
        return np.mean(best)

    expected = 0.5 * (brute(points, polyline) + brute(polyline, points))
    monkeypatch.setattr(validation, "MEMORY_BUDGET", 200 * 8 * 16)  # two rows per chunk
    assert metrics.path_distance(points, polyline) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("n_dofs", [1, 2, 3])
def test_path_distance_measures_only_candidate_segments_without_changing_the_result(n_dofs):
    """Pruned to the segments that can be nearest, every closest distance is the same float
    as the all-pairs minimum (written out here), on random walks with a zero-length segment
    and with a few chunks; a pruning that dropped the nearest segment would differ."""
    rng = np.random.default_rng(n_dofs)
    points = np.cumsum(rng.standard_normal((300, n_dofs)), axis=0)
    polyline = np.cumsum(rng.standard_normal((200, n_dofs)), axis=0)
    polyline[5] = polyline[4]
    start, segment = polyline[:-1], np.diff(polyline, axis=0)
    length2 = np.maximum(np.sum(segment**2, axis=1), 1e-300)
    offset = points[:, None, :] - start[None]
    fraction = np.clip(np.sum(offset * segment[None], axis=2) / length2, 0.0, 1.0)
    nearest = start[None] + fraction[..., None] * segment[None]
    expected = np.linalg.norm(points[:, None, :] - nearest, axis=2).min(axis=1)
    assert np.array_equal(metrics._closest_distances(points, polyline), expected)


def test_the_learning_via_point_is_a_reward_term_under_its_own_name():
    """A task's via-point is a weighted reward, not the fit's hard ViaPoint: it is called
    ViaPointReward; the former name dmpopt.learning.ViaPoint (deprecated in 0.1.0) is gone,
    and asking for it names both classes."""
    from dmpopt import learning

    with pytest.raises(AttributeError) as error:
        learning.ViaPoint  # noqa: B018
    assert str(error.value) == (
        "dmpopt.learning has no ViaPoint: a rewarded point of a task is ViaPointReward, the "
        "hard constraint of a fit is dmpopt.ViaPoint"
    )
    with pytest.raises(AttributeError, match="ViaPointt"):
        learning.ViaPointt  # noqa: B018
    task = via_point_task(via_time=0.2, via_position=(0.3, 0.6), dt=0.01)
    assert isinstance(task.via_points[0], learning.ViaPointReward)
    assert task.via_points[0].weight == 1000.0


def test_a_via_point_stores_validated_read_only_copies():
    """ViaPoint turns its time into a float and its position and tolerance into read-only
    float arrays (one tolerance broadcasts); a Euclidean via-point keeps its one radius."""
    position = [1, 2]
    via = ViaPoint(1, position, 0.25)
    assert type(via.time) is float and via.time == 1.0
    assert via.position.dtype == float and not via.position.flags.writeable
    np.testing.assert_array_equal(via.position, [1.0, 2.0])
    np.testing.assert_array_equal(via.tolerance, [0.25])
    assert not via.tolerance.flags.writeable and via.norm == "box"
    ball = ViaPoint(0.5, [0.0, 1.0], 0.1, "ball")
    assert ball.norm == "ball" and ball.tolerance.shape == (1,)
    bounds = Bounds(position_lower=-1, position_upper=[1.0, 2.0], velocity=3)
    np.testing.assert_array_equal(bounds.position_lower, [-1.0])
    assert not bounds.velocity.flags.writeable and bounds.jerk is None
