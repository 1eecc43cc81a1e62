"""The QP controller under binding constraints: every tick optimal, a defined answer when the
QP is infeasible, joint limits kept by default, and its inputs checked.

The answer key of the optimality tests is Clarabel (an interior-point solver, through
qpsolvers) on the tick's whole QP (every cone, torque and acceleration-bound row), rebuilt
from the controller's arrays after the tick.
"""

import warnings

import numpy as np
import pinocchio as pin
import proxsuite
import pytest
import qpsolvers
import scipy.linalg
import scipy.sparse
from dmpopt_robots import load_talos
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.control import (
    ComputedTorqueController,
    ComTask,
    FrameTask,
    InverseDynamicsController,
    PostureTask,
    SoleContact,
    qp_stages,
)
from dmpopt.control.inverse_dynamics import JOINT_LIMIT_TOLERANCE
from dmpopt.exceptions import InvalidInputError, ShapeError, SimulationDiverged
from dmpopt.sim import GroundContact, Simulator

DT = 1e-3  # [s]
GROUND_STIFFNESS = 2e4  # [N/m] per sole corner


@pytest.fixture(scope="module")
def upper_body():
    return load_talos("full", fixed_base=True)


# ---------------------------------------------------------------- the answer key
def full_qp(public, q, v):
    """The tick's QP over y = (qdd_a, f / weight) with every inequality row, and the constant
    that makes its objective the whole least-squares cost (so that the optimum is > 0)."""
    qp = public.assembled_qp(q, v)
    return dict(
        hessian=qp.hessian,
        gradient=qp.gradient,
        a=qp.equality_matrix,
        b=qp.equality_vector,
        c=qp.inequality_matrix,
        lower=qp.lower,
        upper=qp.upper,
        constant=qp.constant,
    )


def cost(problem, y):
    return 0.5 * y @ problem["hessian"] @ y + problem["gradient"] @ y + problem["constant"]


def clarabel(hessian, gradient, c, lower, upper, a=None, b=None):
    """min 1/2 y'Hy + g'y  s.t.  lower <= C y <= upper, A y = b, by Clarabel to 1e-9."""
    has_lower, has_upper = lower > -1e19, upper < 1e19
    sparse = scipy.sparse.csc_matrix
    problem = qpsolvers.Problem(
        sparse(hessian), gradient, sparse(np.vstack([c[has_upper], -c[has_lower]])),
        np.concatenate([upper[has_upper], -lower[has_lower]]),
        None if a is None or not a.size else sparse(a), None if b is None or not b.size else b,
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # qpsolvers' note on dense matrices
        solution = qpsolvers.solve_problem(
            problem, solver="clarabel", tol_gap_abs=1e-9, tol_gap_rel=1e-9, tol_feas=1e-9
        )
    if solution.found:
        return solution.x
    # Clarabel stops short on a few badly scaled ticks: proxsuite from scratch to 1e-10,
    # duality gap included, is the second key.
    qp = proxsuite.proxqp.dense.QP(hessian.shape[0], 0 if b is None else b.size, lower.size)
    qp.settings.eps_abs, qp.settings.eps_rel = 1e-10, 0.0
    qp.settings.check_duality_gap, qp.settings.eps_duality_gap_abs = True, 1e-10
    qp.settings.max_iter = 100000
    qp.init(hessian, gradient, a, b, c, lower, upper)
    qp.solve()
    assert qp.results.info.status.name == "PROXQP_SOLVED"
    return qp.results.x


def controller_y(public):
    layout = public._current.layout
    wrenches = public.contact_wrenches.ravel() / layout.force_scale
    return np.concatenate([public.joint_accelerations[layout.n_base :], wrenches])


def standing(robot, q_start, friction=0.7, **options):
    """Posture, CoM and pelvis-orientation tasks, two sole contacts; returns the controller,
    the CoM task and an arm posture task (both arms)."""
    arms = [j for side in ("left", "right") for j in robot.joint_groups[f"{side}_arm"]]
    posture = PostureTask(robot, weight=1e-2, stiffness=10.0)
    posture.set_reference(q_start[7:])
    arm = PostureTask(robot, arms, weight=1.0, stiffness=100.0)
    arm.set_reference(q_start[robot.configuration_indices(arms)])
    com = ComTask(robot, weight=10.0, stiffness=50.0)
    base = FrameTask(robot, "base_link", weight=1.0, stiffness=50.0, components="orientation")
    contacts = [SoleContact(robot, f, friction_coefficient=friction) for f in robot.foot_frames]
    options.setdefault("time_budget", 1.0)  # a busy machine must not turn ticks into holds
    controller = InverseDynamicsController(robot, [posture, arm, com, base], contacts, **options)
    return controller, com, arm


def simulator_for(robot):
    """Simulator (compliant ground under the sole corners if standing) and its start state."""
    q0 = np.array(robot.reference_configuration)
    if not robot.floating_base:
        return Simulator(robot.model, DT), q0
    points = [(f, c) for f in robot.foot_frames for c in robot.sole_corners]
    ground = GroundContact(stiffness=GROUND_STIFFNESS, damping=300.0, friction=1.0)
    q0[2] -= pin.computeTotalMass(robot.model) * 9.81 / len(points) / GROUND_STIFFNESS
    return Simulator(robot.model, DT, contact_points=points, ground=ground), q0


def wave(arm, centre, t, amplitude=0.05, frequency=3.0):
    omega, ones = 2 * np.pi * frequency, np.ones(centre.size)
    s, c = np.sin(omega * t), np.cos(omega * t)
    arm.set_reference(centre + amplitude * s, amplitude * omega * c * ones,
                      -amplitude * omega**2 * s * ones)  # fmt: skip


def gaps_of_run(controller, simulator, q0, reference, n_ticks):
    """Closed loop; the relative objective gap of each tick against Clarabel."""
    state = simulator.reset(q0)
    gaps = []
    for k in range(n_ticks):
        reference(k * DT)
        tau = controller.compute_torques(state.q, state.v)
        assert controller.stats.last_answer in ("direct", "solved")
        if controller.stats.last_answer == "direct" and k % 10:  # exact by construction
            state = simulator.step(tau)
            continue
        problem = full_qp(controller, state.q, state.v)
        best = cost(problem, clarabel(**{k: problem[k] for k in problem if k != "constant"}))
        gaps.append((cost(problem, controller_y(controller)) - best) / best)
        state = simulator.step(tau)
    return np.array(gaps)


# ---------------------------------------------------------------- 1. the optimum
@pytest.mark.parametrize("case", ["weak torques, arm wave", "friction 0.1, CoM step"])
def test_every_tick_is_optimal_standing(talos, case):
    """Standing Talos with torque limits at 0.3 and both arms waving 0.05 rad at 3 Hz, or on
    friction 0.1 with a 3 cm CoM step: torque or friction rows bind on many ticks, and every
    tick's objective is within 1e-6 (relative) of Clarabel's optimum of the whole QP."""
    if case.startswith("weak"):
        controller, com, arm = standing(talos, talos.reference_configuration,
                                        torque_limit_scale=0.3)  # fmt: skip
    else:
        controller, com, arm = standing(talos, talos.reference_configuration, friction=0.1)
    simulator, q0_sim = simulator_for(talos)
    start = pin.centerOfMass(talos.model, talos.create_data(), q0_sim)
    com.set_target(start)
    centre = arm.reference_position.copy()

    def reference(t):
        if case.startswith("weak"):
            wave(arm, centre, t)
        elif t >= 0.02:
            com.set_target(start + [0.0, 0.03, -0.02])

    gaps = gaps_of_run(controller, simulator, q0_sim, reference, 150)
    stats = controller.stats
    assert stats.n_solved >= 50, "the scenario should make inequality rows bind"
    assert gaps.max() < 1e-6


def test_every_tick_is_optimal_fixed_base(upper_body):
    """Fixed upper body, torque limits at 0.3, both arms waving: every tick optimal."""
    arms = [j for side in ("left", "right") for j in upper_body.joint_groups[f"{side}_arm"]]
    posture = PostureTask(upper_body, weight=1e-2, stiffness=10.0)
    arm = PostureTask(upper_body, arms, weight=1.0, stiffness=100.0)
    controller = InverseDynamicsController(
        upper_body, [posture, arm], torque_limit_scale=0.3, time_budget=1.0
    )
    simulator, q0 = simulator_for(upper_body)
    centre = arm.reference_position.copy()
    gaps = gaps_of_run(controller, simulator, q0, lambda t: wave(arm, centre, t), 150)
    assert controller.stats.n_solved >= 50
    assert gaps.max() < 1e-6


def fixed_base_wave(upper_body, **options):
    """Fixed upper body, torque limits at 0.3, both arms waving: torque rows bind."""
    arms = [j for side in ("left", "right") for j in upper_body.joint_groups[f"{side}_arm"]]
    posture = PostureTask(upper_body, weight=1e-2, stiffness=10.0)
    arm = PostureTask(upper_body, arms, weight=1.0, stiffness=100.0)
    controller = InverseDynamicsController(
        upper_body, [posture, arm], torque_limit_scale=0.3, **options
    )
    centre = arm.reference_position.copy()
    return controller, lambda t: wave(arm, centre, t)


def test_binding_ticks_are_deterministic_and_mostly_one_kkt_solve(upper_body):
    """Two controllers fed the same states give bitwise-identical torques while torque rows
    bind; most such ticks are solved from the last tick's active set, without proxsuite."""
    recorder, reference = fixed_base_wave(upper_body, time_budget=1.0)
    simulator, q0 = simulator_for(upper_body)
    state, states = simulator.reset(q0), []
    for k in range(120):
        reference(k * DT)
        states.append((state.q.copy(), state.v.copy()))
        state = simulator.step(recorder.compute_torques(state.q, state.v))
    runs = []
    for _ in range(2):
        controller, reference = fixed_base_wave(upper_body, time_budget=1.0)
        torques, statuses = [], []
        for k, (q, v) in enumerate(states):
            reference(k * DT)
            torques.append(controller.compute_torques(q, v))
            statuses.append(controller.stats.last_status)
        runs.append(np.array(torques))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert controller.stats.n_solved >= 50, "torque rows should bind"
    assert statuses.count("ACTIVE_SET_SOLVED") >= 0.8 * controller.stats.n_solved


def random_qp(seed):
    """A strictly convex QP with 2 equality and 12 inequality rows (4 one-sided)."""
    rng = np.random.default_rng(seed)
    n, m, n_eq = 8, 12, 2
    factor = rng.standard_normal((n, n))
    hessian, gradient = factor @ factor.T + 0.1 * np.eye(n), 3 * rng.standard_normal(n)
    a, b = rng.standard_normal((n_eq, n)), rng.standard_normal(n_eq)
    c = rng.standard_normal((m, n))
    lower, upper = -rng.random(m) - 0.1, rng.random(m) + 0.1
    lower[: m // 3] = -1e20
    return (hessian, gradient, a, b, c, lower, upper), rng


def assert_kkt_point(problem, y, tol=1e-8):
    """The KKT conditions of a convex QP, written out: ``y`` feasible, and multipliers of the
    equality rows and of the inequality rows at a bound (least squares) that cancel the
    gradient, with the inequality ones of the right sign. For a convex QP they are sufficient:
    ``y`` is the optimum."""
    hessian, gradient, a, b, c, lower, upper = problem
    rows = c @ y
    np.testing.assert_allclose(a @ y, b, atol=tol)
    assert np.all(rows <= upper + tol) and np.all(rows >= lower - tol)
    at_upper, at_lower = rows >= upper - tol, rows <= lower + tol
    normals = np.vstack([a, c[at_upper], -c[at_lower]])
    residual_gradient = hessian @ y + gradient
    multipliers = np.linalg.lstsq(normals.T, -residual_gradient, rcond=None)[0]
    scale = 1.0 + np.abs(residual_gradient).max()
    np.testing.assert_allclose(normals.T @ multipliers, -residual_gradient, atol=tol * scale)
    assert np.all(multipliers[a.shape[0] :] >= -tol * scale)


def active_set_matches_clarabel(problem, at_upper) -> bool:
    """Active-set iterations from ``at_upper``; False if they refuse, else their answer
    checked (a wrong point fails the test) by the KKT conditions written out and against
    Clarabel's cost: Clarabel stops at a duality gap of 1e-9 (relative), so its point may lie
    ~sqrt(2 gap / mu) ~ 1e-4 from the optimum (mu >= 0.1, the Hessian's least eigenvalue in
    :func:`random_qp`) and its cost above the optimum by up to the gap, never below it by
    more than its feasibility tolerance allows."""
    hessian, gradient, a, b, c, lower, upper = problem
    solution, solves = qp_stages._active_set(problem, at_upper, np.zeros_like(at_upper), 1e-9, 30)
    assert solves <= 30
    if solution is None:
        return False
    assert_kkt_point(problem, solution)
    reference = clarabel(hessian, gradient, c, lower, upper, a, b)
    cost = lambda y: 0.5 * y @ hessian @ y + gradient @ y  # noqa: E731
    assert cost(solution) <= cost(reference) + 1e-9 * (1.0 + abs(cost(reference)))
    return True


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), start=st.sampled_from(["empty", "all upper", "random"]))
def test_active_set_iterations_reach_the_optimum_or_refuse(seed, start):
    """Random QPs from any starting active set: Clarabel's optimum, or None (never a
    wrong point)."""
    problem, rng = random_qp(seed)
    m = problem[4].shape[0]
    at_upper = {"empty": np.zeros(m, bool), "all upper": np.ones(m, bool),
                "random": rng.random(m) < 0.3}[start]  # fmt: skip
    active_set_matches_clarabel(problem, at_upper)


def test_active_set_iterations_usually_converge_from_an_empty_set():
    """From no active row, most random QPs reach their optimum within 30 KKT solves (28 of
    these 40): the iterations do not merely refuse."""
    converged = [active_set_matches_clarabel(random_qp(seed)[0], np.zeros(12, bool))
                 for seed in range(40)]  # fmt: skip
    assert sum(converged) >= 20


# ---------------------------------------------------------------- 2. bounded, defined answers
def infeasible_tick(upper_body, **options):
    """An elbow 5 mm before its upper limit moving at 4 rad/s toward it, with torque limits
    at 2 %: the acceleration bound asks for more braking than the torque can give."""
    posture = PostureTask(upper_body, weight=1.0, stiffness=10.0)
    controller = InverseDynamicsController(
        upper_body, [posture], torque_limit_scale=0.02, **options
    )
    joint = "arm_left_4_joint"
    i_q, i_v = upper_body.configuration_indices([joint])[0], upper_body.velocity_indices([joint])[0]
    q, v = upper_body.reference_configuration.copy(), np.zeros(upper_body.nv)
    q[i_q], v[i_v] = upper_body.position_upper[i_q] - 0.005, 4.0
    return controller, q, v


def test_infeasible_tick_gives_the_relaxed_answer(upper_body):
    """The QP with bound rows is infeasible; the tick returns the solution of the relaxed QP
    (slacks on the bound rows, weight 1e4, torque rows hard), checked against Clarabel on
    the same relaxed problem written out here."""
    controller, q, v = infeasible_tick(upper_body, time_budget=1.0)  # a busy machine
    tau = controller.compute_torques(q, v)
    assert controller.stats.last_answer == "relaxed" and controller.stats.n_relaxed == 1
    problem = full_qp(controller, q, v)
    n, n_bound = problem["hessian"].shape[0], controller._current.assembly.bounds.v_index.size
    n_act = upper_body.n_actuated
    # min cost(y) + 1e4/2 ||s||^2  s.t.  torque rows;  l <= qdd_j + s_j <= u
    hessian = scipy.linalg.block_diag(problem["hessian"], 1e4 * np.eye(n_bound))
    rows = np.hstack([problem["c"], np.zeros((problem["c"].shape[0], n_bound))])
    rows[n_act:, n:] = np.eye(n_bound)
    solution = clarabel(
        hessian, np.r_[problem["gradient"], np.zeros(n_bound)], rows, problem["lower"],
        problem["upper"],
    )  # fmt: skip
    limit = 0.02 * upper_body.torque_limit
    expected = np.clip(problem["c"][:n_act] @ solution[:n] - problem["lower"][:n_act] - limit,
                       -limit, limit)  # fmt: skip
    np.testing.assert_allclose(tau, expected, atol=1e-4 * limit.max())
    assert np.all(np.abs(tau) <= limit)


def test_weak_standing_tick_at_rest_is_feasible_and_solved(talos):
    """Standing Talos at rest with torque limits at 2 %: the QP with contacts is feasible
    (Clarabel solves it; proxsuite, started cold, may call it infeasible): the tick gives the
    ``solved`` answer, whose objective is Clarabel's optimum to 1e-7 relative."""
    controller, _, _ = standing(talos, talos.reference_configuration, torque_limit_scale=0.02)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    controller.compute_torques(q, v)
    assert controller.stats.last_answer == "solved"
    problem = full_qp(controller, q, v)
    best = clarabel(problem["hessian"], problem["gradient"], problem["c"], problem["lower"],
                    problem["upper"], problem["a"], problem["b"])  # fmt: skip
    y = controller_y(controller)
    assert abs(cost(problem, y) - cost(problem, best)) < 1e-7 * abs(cost(problem, best))


@pytest.mark.parametrize("elbow_speed", [2.0, 4.0])
def test_infeasible_standing_tick_gives_the_relaxed_answer(talos, elbow_speed):
    """Standing Talos with torque limits at 2 % and an elbow 5 mm before its limit at 2 or 4
    rad/s: the QP with contacts is infeasible (Clarabel finds no solution either: the elbow
    cannot brake in time); the tick returns the relaxed QP's solution (slacks on the contact
    equalities and the bound rows, weight 1e4 each; torque and cone rows hard): its objective
    is Clarabel's optimum of that problem to 1e-7 (the torques themselves are ill-conditioned
    in it)."""
    controller, _, _ = standing(talos, talos.reference_configuration, torque_limit_scale=0.02)
    q, v = talos.reference_configuration.copy(), np.zeros(talos.nv)
    i_q, i_v = (f(["arm_left_4_joint"])[0] for f in (talos.configuration_indices,
                                                     talos.velocity_indices))  # fmt: skip
    q[i_q], v[i_v] = talos.position_upper[i_q] - 0.005, elbow_speed
    tau = controller.compute_torques(q, v)
    assert controller.stats.last_answer == "relaxed"
    problem = full_qp(controller, q, v)
    n, n_force = problem["hessian"].shape[0], problem["a"].shape[0]
    n_bound, n_act = controller._current.assembly.bounds.v_index.size, talos.n_actuated
    assert n_force == 12  # two soles, six rows each
    # min cost(y) + 1e4/2 (|s_c|^2 + |s_b|^2)  s.t.  A y - s_c = b;  torque and cone rows;
    # l <= qdd_j + s_j <= u
    hessian = scipy.linalg.block_diag(problem["hessian"], 1e4 * np.eye(n_force + n_bound))
    equality = np.hstack([problem["a"], -np.eye(n_force), np.zeros((n_force, n_bound))])
    rows = np.hstack([problem["c"], np.zeros((problem["c"].shape[0], n_force + n_bound))])
    bound_rows = slice(n_act, n_act + n_bound)
    rows[bound_rows, n + n_force :] = np.eye(n_bound)
    gradient = np.r_[problem["gradient"], np.zeros(n_force + n_bound)]
    best = clarabel(hessian, gradient, rows, problem["lower"], problem["upper"],
                    equality, problem["b"])  # fmt: skip

    def relaxed_cost(y):  # with the best slacks for y
        bound = problem["c"][bound_rows] @ y
        lower, upper = problem["lower"][bound_rows], problem["upper"][bound_rows]
        slacks = np.r_[problem["a"] @ y - problem["b"], np.clip(bound, lower, upper) - bound]
        return cost(problem, y) + 0.5e4 * slacks @ slacks

    y = controller_y(controller)
    assert np.abs(best[n : n + n_force]).max() > 1e-4  # the feet do accelerate
    assert np.abs(best[n + n_force :]).max() > 1e-3  # the bound gives
    assert abs(relaxed_cost(y) - relaxed_cost(best[:n])) < 1e-7 * abs(relaxed_cost(best[:n]))
    hard = np.r_[np.arange(n_act), np.arange(n_act + n_bound, rows.shape[0])]
    c_y = problem["c"][hard] @ y
    assert np.all(c_y >= problem["lower"][hard] - 1e-6)
    assert np.all(c_y <= problem["upper"][hard] + 1e-6)
    limit = 0.02 * talos.torque_limit
    np.testing.assert_allclose(tau, problem["c"][:n_act] @ y - problem["lower"][:n_act] - limit,
                               atol=1e-6 * limit.max())  # fmt: skip


def test_spent_time_budget_gives_the_hold_answer(upper_body):
    """With no time left, the tick holds the last valid torque: its one solver call (DAQP,
    which finds the QP infeasible) is made, and the relaxed QP is not tried."""
    controller, q, v = infeasible_tick(upper_body, time_budget=1.0, max_iterations=30)
    first = controller.compute_torques(upper_body.reference_configuration, np.zeros(upper_body.nv))
    assert controller.stats.last_answer in ("direct", "solved")
    controller.time_budget = 1e-12
    tau = controller.compute_torques(q, v)
    stats = controller.stats
    assert stats.last_answer == "hold" and stats.n_fallbacks == 1 and stats.n_relaxed == 0
    assert stats.last_status == "DAQP_INFEASIBLE"
    np.testing.assert_array_equal(tau, first)


def test_relaxed_answers_keep_the_robot_finite_in_closed_loop(upper_body):
    """Torque limits at 2 % on the fixed upper body: the arms fall, the bound rows cannot all
    be met; every tick returns finite torques within the limits, and the counters add up."""
    posture = PostureTask(upper_body, weight=1.0, stiffness=10.0)
    controller = InverseDynamicsController(
        upper_body, [posture], torque_limit_scale=0.02, time_budget=1.0
    )
    simulator, q0 = simulator_for(upper_body)
    state = simulator.reset(q0)
    limit = 0.02 * upper_body.torque_limit
    for _ in range(300):
        tau = controller.compute_torques(state.q, state.v)
        assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= limit)
        state = simulator.step(tau)
    stats = controller.stats
    assert stats.n_relaxed > 0
    assert stats.n_direct + stats.n_solved + stats.n_relaxed + stats.n_fallbacks == 300


# ---------------------------------------------------------------- 5. joint limits by default
def joint_excursion(robot, state_q, state_v):
    """How far each actuated joint is past its position and velocity limits (<= 0 inside)."""
    names = robot.actuated_joint_names
    i_q, i_v = robot.configuration_indices(names), robot.velocity_indices(names)
    lower, upper = robot.position_lower[i_q], robot.position_upper[i_q]
    position = np.maximum(lower - state_q[i_q], state_q[i_q] - upper)
    return position, np.abs(state_v[i_v]) - robot.velocity_limit[i_v]


def run_fixed(robot, controller, n_ticks):
    """Closed loop; the largest excursions past the position and velocity limits."""
    simulator, q0 = simulator_for(robot)
    state = simulator.reset(q0)
    worst_position = worst_velocity = -np.inf
    for _ in range(n_ticks):
        try:
            state = simulator.step(controller.compute_torques(state.q, state.v))
        except SimulationDiverged:  # a joint spins: far past its limits
            return np.inf, np.inf
        position, velocity = joint_excursion(robot, state.q, state.v)
        worst_position = max(worst_position, position.max())
        worst_velocity = max(worst_velocity, velocity.max())
    return worst_position, worst_velocity


TOLERANCE = JOINT_LIMIT_TOLERANCE + 1e-3  # [rad] the bounds' margin, plus integration error


def test_posture_target_beyond_limits_warns_and_is_stopped(upper_body):
    """A stiff posture target 0.5 rad past the elbow's and the torso's limits warns once,
    naming the joints, and the default controller keeps every joint within its limits."""
    posture = PostureTask(upper_body, weight=1.0, stiffness=400.0)
    reference = posture.reference_position.copy()
    names = list(posture.joint_names)
    elbow, torso = names.index("arm_left_4_joint"), names.index("torso_1_joint")
    reference[elbow] = posture._upper[elbow] + 0.5
    reference[torso] = posture._lower[torso] - 0.5
    with pytest.warns(UserWarning, match="'arm_left_4_joint' is outside its position limits"):
        posture.set_reference(reference)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per joint: no second warning
        posture.set_reference(reference)
    controller = InverseDynamicsController(upper_body, [posture], time_budget=1.0)
    worst_position, worst_velocity = run_fixed(upper_body, controller, 800)
    assert worst_position <= TOLERANCE
    assert worst_velocity <= 1e-3
    assert controller.stats.n_fallbacks == 0


def test_unreachable_frame_target_keeps_joints_within_limits(upper_body):
    """A hand target 1.5 m away pulls the arm to full stretch: with the default joint
    limits every joint stays within its limits; without them (the check of the test) some
    joint passes its limits."""

    def controller(**options):
        posture = PostureTask(upper_body, weight=1e-3, stiffness=1.0)
        hand = FrameTask(upper_body, "gripper_left_base_link", weight=10.0, stiffness=400.0,
                         components="position")  # fmt: skip
        hand.set_target(hand.target_placement.translation + [1.0, 1.0, 0.5])
        return InverseDynamicsController(upper_body, [posture, hand], **options)

    worst_position, worst_velocity = run_fixed(upper_body, controller(), 800)
    assert worst_position <= TOLERANCE and worst_velocity <= 1e-3
    unlimited, _ = run_fixed(upper_body, controller(joint_limit_horizon=None), 800)
    assert unlimited > 0.05


def test_joints_resting_at_a_limit_leave_the_bounds_inactive(upper_body):
    """Talos's grippers rest exactly at a limit: the default controller holding the
    reference posture solves every tick directly (no bound row kept active)."""
    at_limit = [
        j for j in range(upper_body.model.nq)
        if upper_body.reference_configuration[j] in (upper_body.position_lower[j],
                                                     upper_body.position_upper[j])
    ]  # fmt: skip
    assert len(at_limit) >= 10
    controller = InverseDynamicsController(upper_body, [PostureTask(upper_body)])
    run_fixed(upper_body, controller, 200)
    assert controller.stats.n_direct == 200


# ---------------------------------------------------------------- 4. computed torque, no NaN
def test_computed_torque_refuses_non_finite_inputs(upper_body):
    """NaN or inf in the state or the reference raises the named error; bad gains are
    refused at construction."""
    controller = ComputedTorqueController(upper_body)
    q, v = upper_body.reference_configuration.copy(), np.zeros(upper_body.nv)
    bad_q = q.copy()
    bad_q[3] = np.nan
    with pytest.raises(InvalidInputError, match=r"^q must be finite; .* indices \[3\]"):
        controller.compute_torques(bad_q, v, q)
    with pytest.raises(InvalidInputError, match="reference_position must be finite"):
        controller.compute_torques(q, v, bad_q)
    with pytest.raises(InvalidInputError, match="reference_acceleration must be finite"):
        controller.compute_torques(q, v, q, v, np.full(upper_body.nv, np.inf))
    with pytest.raises(InvalidInputError, match="v must be numbers"):
        controller.compute_torques(q, "fast", q)
    for gain in (np.nan, -1.0, np.inf):
        with pytest.raises(InvalidInputError, match="stiffness must be finite and >= 0"):
            ComputedTorqueController(upper_body, stiffness=gain)
    with pytest.raises(ShapeError, match=r"damping has shape \(3,\), expected \(\) or \(32,\)"):
        ComputedTorqueController(upper_body, damping=np.ones(3))
    tau = controller.compute_torques(q, v, q)
    np.testing.assert_allclose(
        tau, pin.rnea(upper_body.model, upper_body.create_data(), q, v, 0 * v), atol=1e-9
    )


# ---------------------------------------------------------------- inputs of the QP controller
def test_controller_inputs_get_named_errors(upper_body, talos):
    """Each bad construction argument is refused with its name."""
    posture = PostureTask(upper_body)
    build = InverseDynamicsController
    for name in ("torque_limit_scale", "time_budget", "tolerance", "acceleration_regularization"):
        for value in (0.0, -1.0, np.nan, "big"):
            with pytest.raises(InvalidInputError, match=f"{name} must be a finite number > 0"):
                build(upper_body, [posture], **{name: value})
    with pytest.raises(InvalidInputError, match="max_iterations must be an integer >= 1"):
        build(upper_body, [posture], max_iterations=0)
    with pytest.raises(InvalidInputError, match="wrap a single one in a list"):
        build(upper_body, posture)
    with pytest.raises(InvalidInputError, match="tasks holds str, expected Task"):
        build(upper_body, ["posture"])
    with pytest.raises(ShapeError, match="tasks: a PostureTask was built for another robot"):
        build(upper_body, [PostureTask(talos, "right_leg")])
    with pytest.raises(ShapeError, match="tasks: a ComTask was built for another robot"):
        build(upper_body, [posture, ComTask(talos)])
    with pytest.raises(InvalidInputError, match="contacts holds str, expected Contact"):
        build(talos, [PostureTask(talos)], ["left_sole_link"])


def test_task_inputs_get_named_errors(upper_body, talos):
    """Weights, gains, targets and frames: wrong values, shapes and types are refused by name."""
    for weight in (-1.0, 0.0, np.nan, "heavy", [1.0, 2.0]):
        with pytest.raises(InvalidInputError, match="weight must be"):
            PostureTask(upper_body, weight=weight)
    with pytest.raises(InvalidInputError, match="stiffness must be numbers"):
        ComTask(upper_body, stiffness="stiff")
    with pytest.raises(InvalidInputError, match="frame='palm' is not a frame"):
        FrameTask(upper_body, "palm")
    with pytest.raises(InvalidInputError, match="joint 'elbow' is not in the model"):
        PostureTask(upper_body, ["elbow"])
    hand = FrameTask(upper_body, "gripper_left_base_link")
    with pytest.raises(ShapeError, match=r"placement has shape \(2,\)"):
        hand.set_target([0.1, 0.2])
    with pytest.raises(InvalidInputError, match="placement must be finite with a rotation"):
        hand.set_target(pin.SE3(2.0 * np.eye(3), np.zeros(3)))
    with pytest.raises(ShapeError, match=r"velocity has shape \(4,\), expected \(\), \(3,\) or"):
        hand.set_target(np.zeros(3), velocity=np.zeros(4))
    com = ComTask(upper_body)
    with pytest.raises(InvalidInputError, match="position must be finite"):
        com.set_target([0.0, np.nan, 1.0])
    with pytest.raises(InvalidInputError, match="position must be finite"):
        com.set_target(np.array([0.0, np.nan, 1.0]))  # an array of the right type and shape
    with pytest.raises(InvalidInputError, match="velocity must be finite"):
        com.set_target(np.zeros(3), velocity=np.array([0.0, 0.0, -np.inf]))
    arm = PostureTask(upper_body, "left_arm")
    with pytest.raises(InvalidInputError, match="positions must be numbers"):
        arm.set_reference(["a"] * 7)
    for value in (np.nan, "slippery", -0.5):
        with pytest.raises(InvalidInputError, match="friction_coefficient must be"):
            SoleContact(talos, "left_sole_link", friction_coefficient=value)
    with pytest.raises(InvalidInputError, match="min_normal_force < max_normal_force"):
        SoleContact(talos, "left_sole_link", min_normal_force=10.0, max_normal_force=5.0)
