"""Constrained DMP fits: every constraint holds on the rollout; no constraint = imitation."""

import dataclasses
import os
import re
import time

import numpy as np
import pytest
import qpsolvers
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.exceptions import FittingFailed, InfeasibleProblem, InvalidInputError, ShapeError
from dmpopt.fitting import groups, qp
from dmpopt.fitting.constrained import (
    Bounds,
    ViaPoint,
    build_fitting_problem,
    diagnose_infeasibility,
    fit_weights_constrained,
    solve_fitting_problem,
)
from dmpopt.fitting.imitation import fit_discrete
from dmpopt.fitting.qp import solve_qp
from dmpopt.trajectory import Trajectory


def demonstration(n_samples=300, n_dofs=2):
    """A smooth 2-DOF reach of 1 s with a bump, from rest to rest."""
    times = np.linspace(0.0, 1.0, n_samples)
    s = 10 * times**3 - 15 * times**4 + 6 * times**5
    positions = np.column_stack([s, 0.3 * np.sin(2 * np.pi * s) + 0.5 * s])[:, :n_dofs]
    return Trajectory.from_positions(times, positions)


DEMO = demonstration()
REFERENCES = {form: fit_discrete(DEMO, 20, form=form) for form in ("velocity", "acceleration")}


def plain_plan(form="velocity"):
    dmp = REFERENCES[form]
    return dmp.rollout(
        DEMO.duration, DEMO.duration / (DEMO.n_steps - 1), start_velocity=DEMO.velocities[0]
    )


def velocity_limited_problem(fraction, n_samples=None):
    """The velocity form's fit with each DOF's speed limited to `fraction` of the plain plan's
    peak speed."""
    peak = np.abs(plain_plan().velocities).max(0)
    extra = {} if n_samples is None else {"n_samples": n_samples}
    return build_fitting_problem(
        DEMO, reference=REFERENCES["velocity"], bounds=Bounds(velocity=fraction * peak), **extra
    )


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_unconstrained_request_reproduces_imitation(form):
    """Without limits the position objective gives the imitation fit's weights."""
    reference = REFERENCES[form]
    dmp, report = fit_weights_constrained(DEMO, reference=reference)
    scale = np.abs(reference.weights).max()
    np.testing.assert_allclose(dmp.weights, reference.weights, atol=1e-6 * scale)
    np.testing.assert_allclose(report.trajectory.positions, plain_plan(form).positions, atol=1e-8)


def test_unconstrained_forcing_objective_returns_reference_weights():
    """The forcing objective without any constraint returns the reference weights exactly."""
    reference = REFERENCES["velocity"]
    dmp, _ = fit_weights_constrained(
        DEMO, reference=reference, objective="forcing", end_position_tolerance=None
    )
    np.testing.assert_allclose(dmp.weights, reference.weights, rtol=1e-8, atol=1e-8)


@settings(max_examples=8, deadline=None)
@given(
    velocity_fraction=st.floats(0.75, 0.95),
    acceleration_fraction=st.floats(0.6, 0.95),
    goal_shift=st.floats(-0.05, 0.05),
    form=st.sampled_from(["velocity", "acceleration"]),
    objective=st.sampled_from(["position", "forcing"]),
)
def test_bounds_hold_on_the_rollout(
    velocity_fraction, acceleration_fraction, goal_shift, form, objective
):
    """Velocity and acceleration limits hold at every sample of the returned DMP's rollout."""
    plan = plain_plan(form)
    velocity = velocity_fraction * np.abs(plan.velocities).max(0)
    acceleration = acceleration_fraction * np.abs(plan.accelerations).max(0)
    goal = DEMO.positions[-1] + goal_shift
    dmp, report = fit_weights_constrained(
        DEMO,
        reference=REFERENCES[form],
        goal=goal,
        objective=objective,
        bounds=Bounds(velocity=velocity, acceleration=acceleration),
    )
    rollout = dmp.rollout(
        DEMO.duration,
        DEMO.duration / (DEMO.n_steps - 1),
        start_velocity=report.problem.start_velocity,
    )
    assert np.all(np.abs(rollout.velocities) <= velocity)
    assert np.all(np.abs(rollout.accelerations) <= acceleration)
    np.testing.assert_allclose(rollout.positions[-1], goal, atol=1e-9)
    np.testing.assert_array_equal(dmp.goal, goal)


def test_position_jerk_via_points_and_end_conditions_hold():
    """Position box, jerk limit, via-points, end velocity and a new duration all hold."""
    plan = plain_plan()
    jerk = np.abs(np.diff(plan.accelerations, axis=0) / np.diff(plan.times)[:, None]).max(0)
    via = ViaPoint(0.5, [0.55, 0.45], tolerance=0.01)
    duration = 1.2
    dmp, report = fit_weights_constrained(
        DEMO,
        reference=REFERENCES["velocity"],
        duration=duration,
        n_samples=241,
        bounds=Bounds(position_lower=[-0.01, -0.2], position_upper=[1.05, 1.0], jerk=0.8 * jerk),
        via_points=[via, ViaPoint(0.9, [0.95, 0.95], tolerance=[0.02, 0.02])],
        end_velocity_tolerance=0.01,
    )
    rollout = dmp.rollout(duration, duration / 240, start_velocity=report.problem.start_velocity)
    assert np.all(rollout.positions >= [-0.01, -0.2]) and np.all(rollout.positions <= [1.05, 1.0])
    fd_jerk = np.diff(rollout.accelerations, axis=0) / np.diff(rollout.times)[:, None]
    assert np.all(np.abs(fd_jerk) <= 0.8 * jerk)
    k = 100  # t = 0.5 s on the 5 ms grid
    assert np.all(np.abs(rollout.positions[k] - via.position) <= 0.01)
    assert np.all(np.abs(rollout.velocities[-1]) <= 0.01)
    assert max(report.problem.relative_violations(report.violations).values()) <= 1e-7


def test_euclidean_via_point_uses_the_nlp():
    """A ball via-point is met (within its radius) by the IPOPT fallback."""
    point = np.array([0.6, 0.5])
    dmp, report = fit_weights_constrained(
        DEMO,
        reference=REFERENCES["velocity"],
        n_samples=101,
        via_points=[ViaPoint(0.5, point, tolerance=0.02, norm="ball")],
    )
    assert report.solver == "ipopt" and report.status == "Solve_Succeeded"
    assert report.iterations > 0 and report.working_sets is None
    assert np.linalg.norm(report.trajectory.positions[50] - point) <= 0.02 + 1e-7
    # a box via-point after the ball one holds too
    box = ViaPoint(0.8, [0.8, 0.95], tolerance=0.01)
    _, both = fit_weights_constrained(
        DEMO, reference=REFERENCES["velocity"], n_samples=101,
        via_points=[ViaPoint(0.5, point, tolerance=0.02, norm="ball"), box],
    )  # fmt: skip
    assert np.linalg.norm(both.trajectory.positions[50] - point) <= 0.02 + 1e-7
    assert np.abs(both.trajectory.positions[80] - box.position).max() <= 0.01 + 1e-7
    assert np.abs(report.trajectory.positions[80] - box.position).max() > 0.02  # it binds


def test_unreachable_euclidean_via_point_is_reported_as_such():
    """A ball via-point beyond a position box: IPOPT fails; the linear constraints alone can
    hold, so the error points at the via-point, with the solver's status."""
    with pytest.raises(FittingFailed) as caught:
        fit_weights_constrained(
            DEMO,
            reference=REFERENCES["velocity"],
            n_samples=101,
            bounds=Bounds(position_upper=[1.2, 2.0]),
            via_points=[ViaPoint(0.5, [1.5, 0.4], tolerance=0.01, norm="ball")],
        )
    assert not isinstance(caught.value, InfeasibleProblem)
    message = str(caught.value)
    assert message == (
        "the ipopt solver failed (Infeasible_Problem_Detected) although the linear constraints "
        "can hold; so a Euclidean via-point may be out of reach of them: widen its tolerance, "
        "move it or relax the bounds"
    )
    assert caught.value.stats["solver"] == "ipopt" and caught.value.problem is not None
    assert set(caught.value.stats) == {"solver", "status", "solve_time", "iterations"}


def test_problem_is_inspectable_and_warm_starts():
    """The built problem exposes its groups and stacked QP; a second solve reuses it."""
    problem = velocity_limited_problem(0.8)
    assert [g.name for g in problem.groups] == ["velocity", "end_position"]
    hessian, gradient, matrix, lower, upper = problem.full_qp()
    assert hessian.shape == (40, 40) and matrix.shape == (2 * (DEMO.n_steps + 1), 40)
    first, report = solve_fitting_problem(problem)
    second, _ = solve_fitting_problem(problem, warm_start=report)
    np.testing.assert_allclose(first.weights, second.weights, atol=1e-9)
    opti, variable = problem.to_opti()
    assert variable.shape == (20, 2)


def test_infeasible_request_names_the_constraint_group():
    """Too tight a velocity limit raises InfeasibleProblem naming the groups and amounts."""
    problem = velocity_limited_problem(0.2, n_samples=101)
    with pytest.raises(InfeasibleProblem) as caught:
        solve_fitting_problem(problem)
    message = str(caught.value)
    assert message.startswith(f"infeasible constrained fit ({caught.value.stats['status']}): ")
    assert caught.value.stats["solver"] == "daqp+qpoases"
    assert "relax these constraints by at least that much" in message
    assert caught.value.problem is problem
    assert message.startswith(
        "infeasible constrained fit (Initial QP could not be solved due to infeasibility!): "
    )
    assert set(caught.value.relaxations) <= {"velocity", "end_position"}
    assert all(amount > 0 for amount, _ in caught.value.relaxations.values())


def test_two_infeasible_groups_are_listed_in_one_message():
    """A position box below the goal (upper 0.5 for a goal at 1.0 on DOF 0): the end position
    and the box conflict, and the message lists both groups with their amounts, which close
    the 0.5 gap together."""
    problem = build_fitting_problem(DEMO, reference=REFERENCES["velocity"], n_samples=101,
                                    bounds=Bounds(position_upper=[0.5, 0.2]))  # fmt: skip
    with pytest.raises(InfeasibleProblem) as caught:
        solve_fitting_problem(problem)
    amounts = caught.value.relaxations
    assert set(amounts) == {"position", "end_position"}
    assert amounts["position"][0] + amounts["end_position"][0] >= 0.5 - 1e-9
    assert re.search(
        r": 'position' on DOF\(s\) \[0, 1\] by [0-9.]+, 'end_position' on DOF\(s\) \[0, 1\] "
        r"by [0-9.]+ \[physical units\]; relax these constraints",
        str(caught.value),
    )


def test_bounds_of_one_side_equal_limits_and_names():
    """A lower position bound alone is accepted (no upper one) and holds on the rollout;
    position_lower == position_upper is allowed, a crossing refused for the DOF that
    crosses; each field and a via-point's tolerance name themselves."""
    lower = np.array([-0.02, -0.05])
    _, report = fit_weights_constrained(DEMO, reference=REFERENCES["velocity"], n_samples=101,
                                        bounds=Bounds(position_lower=lower))  # fmt: skip
    assert np.all(report.trajectory.positions >= lower - 1e-9)
    pinned = Bounds(position_lower=[0.0, 1.0], position_upper=[0.0, 1.0])
    np.testing.assert_array_equal(pinned.position_lower, pinned.position_upper)
    crossing = r"^position_lower exceeds position_upper for DOF\(s\) \[1\]"
    with pytest.raises(InvalidInputError, match=crossing):
        Bounds(position_lower=[0.0, 1.5], position_upper=[0.0, 1.0])
    for name in ("position_lower", "position_upper", "velocity", "acceleration", "jerk"):
        with pytest.raises(InvalidInputError, match=f"^{name} must be an array of real numbers"):
            Bounds(**{name: "high"})
    with pytest.raises(InvalidInputError, match="^tolerance must be an array of real numbers"):
        ViaPoint(0.5, [0.0, 0.0], tolerance="loose")


def test_invalid_requests_are_rejected():
    """Wrong objective, negative limits and via-points outside the plan are refused."""
    with pytest.raises(InvalidInputError, match="objective must be one of"):
        build_fitting_problem(DEMO, reference=REFERENCES["velocity"], objective="speed")
    with pytest.raises(InvalidInputError, match="velocity must be positive"):
        Bounds(velocity=-1.0)
    with pytest.raises(InvalidInputError, match="outside the plan"):
        build_fitting_problem(
            DEMO, reference=REFERENCES["velocity"], via_points=[ViaPoint(2.0, [0.0, 0.0])]
        )


def test_problem_records_its_request_and_names_each_bad_argument():
    """The problem keeps the objective, bounds and via-points it was built for; a start,
    goal or start velocity that is not numbers, or not one entry per DOF, is refused by name."""
    bounds, via = Bounds(velocity=5.0), ViaPoint(0.5, [0.55, 0.45], tolerance=0.01)
    problem = build_fitting_problem(
        DEMO, reference=REFERENCES["velocity"], n_samples=101, bounds=bounds, via_points=[via]
    )
    assert (problem.objective, problem.bounds, problem.via_points) == ("position", bounds, (via,))
    for name in ("start", "goal", "start_velocity"):
        with pytest.raises(InvalidInputError, match=f"^{name} must be an array of real numbers"):
            build_fitting_problem(DEMO, reference=REFERENCES["velocity"], **{name: "here"})
        with pytest.raises(ShapeError, match=rf"^{name} has shape \(3,\), expected \(2,\)"):
            build_fitting_problem(DEMO, reference=REFERENCES["velocity"], **{name: [0.0] * 3})


@pytest.mark.parametrize("form, norm", [("velocity", "box"), ("acceleration", "box"),
                                        ("velocity", "ball")])  # fmt: skip
def test_constrained_fit_scales_with_the_demonstration(form, norm):
    """Eq. (1)-(4) are linear in the positions: a demonstration, its limits and via-points all
    scaled by s = 40 (metres instead of 2.5 cm units) give weights scaled by s, the fit being
    the same problem in other units (a QP, or IPOPT's NLP for a Euclidean via-point)."""
    s = 40.0
    plan = plain_plan(form)
    limit = 0.8 * np.abs(plan.velocities).max(0)
    via = [0.55, 0.45]
    small, _ = fit_weights_constrained(
        DEMO, reference=REFERENCES[form], n_samples=101, bounds=Bounds(velocity=limit),
        via_points=[ViaPoint(0.5, via, tolerance=0.01, norm=norm)],
    )  # fmt: skip
    large_demo = Trajectory.from_positions(DEMO.times, s * DEMO.positions)
    large, _ = fit_weights_constrained(
        large_demo, reference=fit_discrete(large_demo, 20, form=form), n_samples=101,
        bounds=Bounds(velocity=s * limit),
        via_points=[ViaPoint(0.5, s * np.array(via), tolerance=s * 0.01, norm=norm)],
    )  # fmt: skip
    scale, tolerance = np.abs(small.weights).max(), 1e-6 if norm == "box" else 1e-4
    np.testing.assert_allclose(large.weights, s * small.weights, rtol=0,
                               atol=tolerance * s * scale)  # fmt: skip


# ---------------------------------------------------------------------------------------
# The QP layer, against a second solver (Clarabel through qpsolvers)
# ---------------------------------------------------------------------------------------


def clarabel(hessian, gradient, matrix=None, lower=None, upper=None, eq=None, eq_rhs=None):
    """``min 1/2 x'Hx + g'x`` s.t. ``lower <= A x <= upper`` (finite sides) with Clarabel."""
    rows, rhs = [], []
    if matrix is not None:
        for sign, bound in ((1.0, upper), (-1.0, lower)):
            finite = np.abs(bound) < 1e19
            rows.append(sign * matrix[finite])
            rhs.append(sign * bound[finite])
    x = qpsolvers.solve_qp(
        hessian,
        gradient,
        np.vstack(rows) if rows else None,
        np.concatenate(rhs) if rhs else None,
        eq,
        eq_rhs,
        solver="clarabel",
        tol_gap_abs=1e-12,
        tol_gap_rel=1e-12,
        tol_feas=1e-12,
    )
    assert x is not None, "the answer key failed"
    return x


def random_qp(seed, n, m):
    """A feasible strictly convex QP; some rows one-sided, one an equality."""
    rng = np.random.default_rng(seed)
    factor = rng.normal(size=(n, n))
    hessian = factor @ factor.T + np.eye(n)
    gradient = 3 * rng.normal(size=n)
    matrix = rng.normal(size=(m, n))
    inside = matrix @ rng.normal(size=n)
    lower = inside - rng.uniform(0.1, 1.0, m)
    upper = inside + rng.uniform(0.1, 1.0, m)
    lower[::4] = -1e20  # one-sided rows
    lower[1], upper[1] = inside[1], inside[1]  # an equality
    return hessian, gradient, matrix, lower, upper


@settings(max_examples=12, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    n=st.integers(2, 8),
    m=st.integers(2, 40),
    solver=st.sampled_from(["daqp", "qpoases"]),
    stride=st.sampled_from([1, 3, 10]),
)
def test_solve_qp_matches_a_second_solver(seed, n, m, solver, stride):
    """Row generation with the active-set backends reaches Clarabel's optimum of the whole QP.
    (Standalone ProxQP may stop with a wrong infeasibility status, e.g. seed 1, n 3, m 24,
    stride 1: reported as a failure, as documented in solve_qp; it is checked below.)"""
    hessian, gradient, matrix, lower, upper = random_qp(seed, n, m)
    key = clarabel(hessian, gradient, matrix, lower, upper)
    solution = solve_qp(hessian, gradient, matrix, lower, upper, solver=solver, stride=stride)
    assert solution.success
    np.testing.assert_allclose(solution.x, key, atol=1e-5 * (1 + np.abs(key).max()))
    values = matrix @ solution.x
    on_bound = np.minimum(np.abs(values - lower), np.abs(values - upper))
    assert np.all(on_bound[solution.active] < 1e-6)  # the working set is at its bounds


def test_a_failed_backend_solve_ends_the_row_generation(monkeypatch):
    """A backend that reports failure ends solve_qp after that round, even with a finite x
    that violates rows not yet selected (no more rows are added to a failed solve)."""
    hessian, gradient, matrix, lower, upper = random_qp(3, 4, 12)
    real_backend = qp._backend_solve

    def fails_off_target(solver, *args):
        x, z, _, status = real_backend(solver, *args)
        return x + 10.0, z, False, "stalled"  # finite, far outside the other rows

    monkeypatch.setattr(qp, "_backend_solve", fails_off_target)
    solution = qp.solve_qp(hessian, gradient, matrix, lower, upper, solver="daqp", stride=12)
    assert (solution.success, solution.status, solution.iterations) == (False, "stalled", 1)


def test_solve_blocks_falls_back_and_stops_at_an_infeasible_block(monkeypatch):
    """A block the first backend fails is solved by qpOASES; an infeasible block stops the
    loop and is named."""
    hessian, gradient, matrix, lower, upper = random_qp(3, 4, 12)
    real_backend = qp._backend_solve

    def daqp_fails(solver, *args):
        x, z, success, status = real_backend(solver, *args)
        return x, z, success and solver != "daqp", status

    monkeypatch.setattr(qp, "_backend_solve", daqp_fails)
    both = qp.solve_blocks(
        hessian,
        np.stack([gradient, -gradient]),
        matrix,
        np.stack([lower, lower]),
        np.stack([upper, upper]),
        solver="daqp",
    )
    assert both.success and both.solver == "daqp+qpoases" and both.failed_block == -1
    np.testing.assert_allclose(
        both.x[1], clarabel(hessian, -gradient, matrix, lower, upper), atol=1e-6
    )
    monkeypatch.setattr(qp, "_backend_solve", real_backend)
    twice = np.vstack([matrix, matrix[:1]])  # row 0 twice: disjoint bounds make it infeasible
    low, high = np.append(lower, lower[0]), np.append(upper, upper[0])
    apart_low, apart_high = low.copy(), high.copy()
    apart_low[-1], apart_high[-1] = upper[0] + 1.0, upper[0] + 2.0
    stopped = qp.solve_blocks(
        hessian,
        np.stack([gradient] * 3),
        twice,
        np.stack([low, apart_low, low]),
        np.stack([high, apart_high, high]),
    )
    assert not stopped.success and stopped.failed_block == 1
    assert np.all(np.isnan(stopped.x[1:]))


def test_scale_rows_is_the_same_constraint_in_units():
    """Each scaled row, times its norm and the unit, plus the offset, is the original row;
    its bounds are the requested ones tightened by ``margin`` units, or free."""
    rng = np.random.default_rng(1)
    matrix, offset = rng.normal(size=(5, 3)), rng.normal(size=(5, 2))
    lower = np.array([[-1.0, -np.inf], [0.0, 0.0], [-2.0, -1.0], [-np.inf, -1.0], [0.5, 0.5]])
    upper = np.array([[1.0, 2.0], [0.0, 3.0], [np.inf, 1.0], [1.0, np.inf], [0.5, 0.502]])
    unit, margin = 0.7, 1e-3  # the last row: 0.002 wide, above 2 margin unit = 0.0014
    rows = qp.scale_rows(matrix, offset, lower, upper, unit, margin)
    np.testing.assert_allclose(np.linalg.norm(rows.matrix, axis=1), 1.0)
    np.testing.assert_allclose(rows.matrix * rows.norms[:, None] * unit, matrix)
    wide = (upper - lower) > 2 * margin * unit
    expected_lower = np.where(np.isinf(lower), -1e20, lower - offset + margin * unit * wide)
    expected_upper = np.where(np.isinf(upper), 1e20, upper - offset - margin * unit * wide)
    finite_l, finite_u = np.isfinite(lower), np.isfinite(upper)
    scale = rows.norms[:, None] * unit
    np.testing.assert_allclose((rows.lower * scale)[finite_l], expected_lower[finite_l])
    np.testing.assert_allclose((rows.upper * scale)[finite_u], expected_upper[finite_u])
    assert np.all(rows.lower[~finite_l] == -1e20) and np.all(rows.upper[~finite_u] == 1e20)


def test_constrained_fit_matches_the_plain_qp_solved_by_a_second_solver():
    """The fit equals, per DOF, min ||F0 + G0 w - y_demo||^2 + lambda ||w||^2 subject to
    |F1 + G1 w| <= v, |F2 + G2 w| <= a and F0[-1] + G0[-1] w = g, written plainly and
    solved by Clarabel on the library's affine plan (F, G)."""
    plan = plain_plan()
    velocity = 0.8 * np.abs(plan.velocities).max(0)
    acceleration = 0.7 * np.abs(plan.accelerations).max(0)
    dmp, report = fit_weights_constrained(
        DEMO,
        reference=REFERENCES["velocity"],
        bounds=Bounds(velocity=velocity, acceleration=acceleration),
    )
    affine = report.problem.plan
    free, response = affine.free, affine.weight_response
    gram = response[0].T @ response[0]
    ridge = 1e-9 * np.trace(gram) / gram.shape[0]
    weights = []
    for d in range(2):
        limits = np.concatenate(
            [np.full(DEMO.n_steps, velocity[d]), np.full(DEMO.n_steps, acceleration[d])]
        )
        offset = np.concatenate([free[1, :, d], free[2, :, d]])
        weights.append(
            clarabel(
                gram + ridge * np.eye(gram.shape[0]),
                -response[0].T @ (DEMO.positions[:, d] - free[0, :, d]),
                np.vstack([response[1], response[2]]),
                -limits - offset,
                limits - offset,
                response[0, -1:],
                np.array([DEMO.positions[-1, d] - free[0, -1, d]]),
            )
        )
    key_positions = free[0] + response[0] @ np.array(weights).T
    extent = np.ptp(DEMO.positions, axis=0).max()
    np.testing.assert_allclose(report.trajectory.positions, key_positions, atol=1e-4 * extent)


# ---------------------------------------------------------------------------------------
# Build and solve: a frozen problem, explicit warm start, the process's stdout untouched
# ---------------------------------------------------------------------------------------


def test_problem_is_frozen_and_solving_leaves_it_unchanged():
    """A FittingProblem is a value: no attribute can be set, and two solves of it, the second
    warm-started, return the same weights and working sets (no state kept between them)."""
    problem = velocity_limited_problem(0.8)
    with pytest.raises(dataclasses.FrozenInstanceError):
        problem.solver = "qpoases"
    assert not hasattr(problem, "cache")
    lower = problem.lower.copy()
    first, report = solve_fitting_problem(problem)
    second, again = solve_fitting_problem(problem, warm_start=report)
    np.testing.assert_array_equal(problem.lower, lower)
    np.testing.assert_allclose(second.weights, first.weights, atol=1e-9)
    assert report.working_sets.shape == problem.lower.shape and report.working_sets.any()
    np.testing.assert_array_equal(again.working_sets, report.working_sets)


def test_solving_never_redirects_the_process_stdout():
    """qpOASES (fallback and infeasibility diagnosis) runs without touching file descriptor 1."""

    def refuse(*args):
        raise AssertionError("file descriptors must not be redirected")

    plan = plain_plan()
    peak = np.abs(plan.velocities).max(0)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(os, "dup", refuse)
        patch.setattr(os, "dup2", refuse)
        _, report = fit_weights_constrained(
            DEMO,
            reference=REFERENCES["velocity"],
            n_samples=101,
            solver="qpoases",
            bounds=Bounds(velocity=0.9 * peak),
        )
        with pytest.raises(InfeasibleProblem):
            fit_weights_constrained(
                DEMO,
                reference=REFERENCES["velocity"],
                n_samples=101,
                bounds=Bounds(velocity=0.2 * peak),
            )
    assert report.solver == "qpoases"


def test_diagnosis_relaxes_a_via_point_against_a_position_box_by_their_gap():
    """A via-point 0.3 above the position box: the elastic problem relaxes the two groups by
    0.3 in total (plus the safety margins), and nothing else."""
    problem = build_fitting_problem(
        DEMO,
        reference=REFERENCES["velocity"],
        n_samples=101,
        bounds=Bounds(position_upper=[1.2, 2.0]),
        via_points=[ViaPoint(0.5, [1.5, 0.4])],
    )
    relaxations = diagnose_infeasibility(problem)
    assert set(relaxations) <= {"position", "via_point[0]"}
    total = sum(amount for amount, _ in relaxations.values())
    assert 0.3 <= total <= 0.3 + 1e-3
    assert all(dofs == [0] for _, dofs in relaxations.values())
    with pytest.raises(
        InfeasibleProblem, match="'(position|via_point\\[0\\])' on DOF\\(s\\) \\[0\\]"
    ):
        solve_fitting_problem(problem)


@settings(max_examples=20, deadline=None)
@given(time=st.floats(0.0, 1.0), n_steps=st.integers(3, 50))
def test_sample_interpolates_like_np_interp_and_jerk_is_the_difference(time, n_steps):
    """A group's value at a time is the linear interpolation of the samples (np.interp); its
    jerk is the forward difference of the accelerations divided by dt."""
    rng = np.random.default_rng(n_steps)
    times = np.linspace(0.0, 1.0, n_steps)
    dt = times[1] - times[0]
    values = rng.normal(size=(3, n_steps, 2))
    at = groups.interpolation(time, dt, n_steps, "via")
    for k, quantity in enumerate(["position", "velocity", "acceleration"]):
        key = [np.interp(time, times, values[k, :, d]) for d in range(2)]
        np.testing.assert_allclose(groups.sample(values, dt, quantity, at)[0], key, atol=1e-12)
        np.testing.assert_array_equal(groups.sample(values, dt, quantity), values[k])
    jerk = (values[2, 1:] - values[2, :-1]) / dt
    np.testing.assert_allclose(groups.sample(values, dt, "jerk"), jerk)


DEMO_10 = Trajectory(DEMO.times, 10 * DEMO.positions, 10 * DEMO.velocities, 10 * DEMO.accelerations)
REFERENCE_10 = fit_discrete(DEMO_10, 20)


def test_diagnosis_amounts_are_the_fixed_start_against_the_limits():
    """The first sample's position and velocity do not depend on the weights. A start velocity
    of 4 against a limit of 0.5, and a via-point at t = 0 five units from the start, need
    relaxations of exactly 3.5 and 5 (plus margins, physical units, on DOF 0 only); the
    message lists the larger first."""
    problem = build_fitting_problem(
        DEMO_10,
        reference=REFERENCE_10,
        n_samples=101,
        start_velocity=[4.0, 0.0],
        bounds=Bounds(velocity=[0.5, 1e3]),
        via_points=[ViaPoint(0.0, [5.0, 0.0])],
        end_position_tolerance=None,
    )
    relaxations = diagnose_infeasibility(problem)
    assert set(relaxations) == {"velocity", "via_point[0]"}
    np.testing.assert_allclose(relaxations["velocity"][0], 3.5, atol=1e-3)
    np.testing.assert_allclose(relaxations["via_point[0]"][0], 5.0, atol=1e-3)
    assert relaxations["velocity"][1] == [0] and relaxations["via_point[0]"][1] == [0]
    with pytest.raises(
        InfeasibleProblem,
        match=r"'via_point\[0\]' on DOF\(s\) \[0\] by 5.*"
        r"'velocity' on DOF\(s\) \[0\] by 3.5",
    ) as caught:
        solve_fitting_problem(problem)
    assert caught.value.relaxations == relaxations and caught.value.problem is problem


def test_a_single_infeasible_group_is_diagnosed():
    """With one constraint group only (the velocity limit) the diagnosis still names it."""
    problem = build_fitting_problem(
        DEMO_10,
        reference=REFERENCE_10,
        n_samples=101,
        start_velocity=[4.0, 0.0],
        bounds=Bounds(velocity=[0.5, 1e3]),
        end_position_tolerance=None,
    )
    assert len(problem.groups) == 1
    relaxations = diagnose_infeasibility(problem)
    np.testing.assert_allclose(relaxations["velocity"][0], 3.5, atol=1e-3)


def test_interpolation_of_a_time_on_the_grid():
    """Times on the grid give the sample itself; the end is the last interval's far end;
    times beyond half a step outside the plan are refused."""
    assert groups.interpolation(0.5, 0.25, 5, "t") == (2, 0.0)
    assert groups.interpolation(0.625, 0.25, 5, "t") == (2, 0.5)
    assert groups.interpolation(1.0, 0.25, 5, "t") == (3, 1.0)
    assert groups.interpolation(1.0 + 1e-12, 0.25, 5, "t") == (3, 1.0)
    assert groups.interpolation(0.0, 0.25, 5, "t") == (0, 0.0)
    assert groups.interpolation(-1e-12, 0.25, 5, "t") == (0, 0.0)
    for outside in (-0.125, 1.125):
        with pytest.raises(InvalidInputError, match=r"via_points\[3\] time .* outside the plan"):
            groups.interpolation(outside, 0.25, 5, "via_points[3]")


def test_variables_and_forcing_weights_are_inverse_maps():
    """x -> W = L s x -> x is the identity (the NLP's initial guess goes through it)."""
    problem = build_fitting_problem(DEMO_10, reference=REFERENCE_10, n_samples=101)
    x = np.random.default_rng(0).normal(size=(2, 20))
    weights = problem.forcing_weights(x)
    np.testing.assert_allclose(weights, problem.length_scale * x * problem.scale[None, :])
    np.testing.assert_allclose(problem.variables(weights), x, rtol=1e-12)


@pytest.mark.parametrize("quantity", ["position", "velocity", "acceleration", "jerk"])
def test_active_limits_are_tightened_by_the_margin_in_their_unit(quantity):
    """On a plan of duration T = 1.5 s, an active limit is reached up to a gap of exactly
    margin * L / T^k (L the demonstration's largest extent, k = 0..3 for position ... jerk)."""
    duration, margin = 1.5, 1e-3
    length = np.ptp(DEMO.positions, axis=0).max()
    goal = [1.0, 0.2]  # below the bump of DOF 1, whose peak is then inside the motion
    free = build_fitting_problem(
        DEMO, reference=REFERENCES["velocity"], duration=duration, goal=goal
    )
    plan = free.rollout(free.dmp)
    dt = plan.times[1] - plan.times[0]
    series = {
        "position": plan.positions[:, 1],
        "velocity": plan.velocities[:, 1],
        "acceleration": plan.accelerations[:, 1],
        "jerk": np.diff(plan.accelerations[:, 1]) / dt,
    }
    peak = np.abs(series[quantity]).max()
    if quantity == "position":
        assert 0 < np.argmax(plan.positions[:, 1]) < plan.times.size - 1
        limit = plan.positions[:, 1].max() - 0.02
        bounds = Bounds(position_upper=[2.0, limit])
    else:
        limit = 0.9 * peak
        bounds = Bounds(**{quantity: [1e3 * peak, limit]})
    _, report = fit_weights_constrained(
        DEMO,
        reference=REFERENCES["velocity"],
        duration=duration,
        goal=goal,
        bounds=bounds,
        margin=margin,
    )
    result = report.trajectory
    values = {
        "position": result.positions[:, 1],
        "velocity": result.velocities[:, 1],
        "acceleration": result.accelerations[:, 1],
        "jerk": np.diff(result.accelerations[:, 1]) / dt,
    }[quantity]
    power = ["position", "velocity", "acceleration", "jerk"].index(quantity)
    reached = values.max() if quantity == "position" else np.abs(values).max()
    np.testing.assert_allclose(reached, limit - margin * length / duration**power, rtol=1e-7)


@pytest.mark.parametrize(
    "solver, status",
    [
        ("daqp", "1"),
        ("qpoases", "Successful return."),
        ("proxsuite", "QPSolverOutput.PROXQP_SOLVED"),
    ],
)
def test_solve_qp_reports_each_backend_s_own_status(solver, status):
    """The status is the backend's own word for success, one round when every row holds."""
    solution = solve_qp(np.eye(2), [1.0, 1.0], np.eye(2), [-5.0, 0.5], [5.0, 5.0], solver=solver)
    assert solution.success and solution.status == status and solution.iterations == 1
    np.testing.assert_allclose(solution.x, [-1.0, 0.5], atol=1e-7)  # the clipped minimiser
    np.testing.assert_array_equal(solution.active, [False, True])


def test_first_rows_of_the_row_generation():
    """Every stride-th row, the last row, the equalities and (warm start) the given rows,
    on a grid five times sparser when rows are given."""
    lower = np.full(23, -1.0)
    upper = np.full(23, 1.0)
    lower[[4, 7]] = upper[[4, 7]] = 0.5  # equalities
    lower[9], upper[11] = -np.inf, np.inf  # one-sided rows are not equalities
    expected = np.zeros(23, dtype=bool)
    expected[::3] = expected[-1] = expected[4] = expected[7] = True
    np.testing.assert_array_equal(qp._first_rows(lower, upper, 3, None), expected)
    rows = np.zeros(23, dtype=bool)
    rows[[5, 13]] = True
    warm = np.zeros(23, dtype=bool)
    warm[::15] = warm[-1] = warm[4] = warm[7] = warm[5] = warm[13] = True
    np.testing.assert_array_equal(qp._first_rows(lower, upper, 3, rows), warm)
    np.testing.assert_array_equal(qp._first_rows(lower, upper, 0, None), np.ones(23, bool))


def test_warm_start_from_the_working_sets_needs_one_round_per_dof():
    """Started from its own working sets, a fit adds no row: one round per DOF; the cold
    start needed more. Times and rounds are summed over the DOFs."""
    plan = plain_plan()
    problem = build_fitting_problem(
        DEMO,
        reference=REFERENCES["velocity"],
        bounds=Bounds(acceleration=0.6 * np.abs(plan.accelerations).max(0)),
    )
    _, cold = solve_fitting_problem(problem)
    _, warm = solve_fitting_problem(problem, warm_start=cold)
    assert cold.iterations > problem.n_dofs and warm.iterations == problem.n_dofs
    assert warm.solve_time > 0 and cold.status == warm.status == "1"


def test_an_answer_that_violates_a_limit_on_the_rollout_is_refused(monkeypatch):
    """If the solver's answer breaks a limit on the rollout although the limits can hold
    (here: the answer is spoilt on purpose), the fit fails and names the group."""
    from dmpopt.fitting import constrained

    plan = plain_plan()
    real_solve = constrained.solve_blocks

    def spoilt(*args, **kwargs):
        solution = real_solve(*args, **kwargs)
        return solution._replace(x=1.5 * solution.x)

    monkeypatch.setattr(constrained, "solve_blocks", spoilt)
    with pytest.raises(
        FittingFailed, match=r"the daqp answer violates '(velocity|end_position)' by"
    ):
        fit_weights_constrained(
            DEMO,
            reference=REFERENCES["velocity"],
            n_samples=101,
            bounds=Bounds(velocity=0.9 * np.abs(plan.velocities).max(0)),
        )
    # with a generous velocity limit only the end position is violated: that one is named
    with pytest.raises(FittingFailed, match=r"^the daqp answer violates 'end_position' by"):
        fit_weights_constrained(
            DEMO, reference=REFERENCES["velocity"], n_samples=101,
            bounds=Bounds(velocity=5.0 * np.abs(plan.velocities).max(0)),
        )  # fmt: skip


def test_a_failed_qp_solve_is_reported_with_its_status_and_remedy(monkeypatch):
    """A QP solve that reports failure, even with a finite answer, is not used: the error
    names the solver, its status and the remedy."""
    from dmpopt.fitting import constrained

    real_solve = constrained.solve_blocks

    def failing(*args, **kwargs):
        return real_solve(*args, **kwargs)._replace(success=False, status="stalled")

    monkeypatch.setattr(constrained, "solve_blocks", failing)
    with pytest.raises(FittingFailed) as caught:
        fit_weights_constrained(DEMO, reference=REFERENCES["velocity"], n_samples=101,
                                bounds=Bounds(velocity=5.0))  # fmt: skip
    assert str(caught.value) == (
        "the daqp solver failed (stalled) although the linear constraints can hold; try "
        "another solver ('daqp', 'qpoases') or a larger regularization"
    )


def test_relative_violations_divide_by_each_group_s_unit():
    """Violations in physical units divided by L, L/T... (L for Euclidean via-points)."""
    problem = build_fitting_problem(
        DEMO_10, reference=REFERENCE_10, duration=2.0, bounds=Bounds(velocity=50.0)
    )
    length = problem.length_scale
    relative = problem.relative_violations({"velocity": 3.0, "via_point_ball[0]": 4.0})
    np.testing.assert_allclose(relative["velocity"], 3.0 / (length / 2.0))
    np.testing.assert_allclose(relative["via_point_ball[0]"], 4.0 / length)


def test_a_requested_start_velocity_is_kept_by_the_returned_dmp():
    """The fit starts with the requested velocity, and so does the returned DMP's own rollout."""
    dmp, report = fit_weights_constrained(
        DEMO, reference=REFERENCES["velocity"], n_samples=101, start_velocity=[0.5, -0.2]
    )
    np.testing.assert_allclose(report.trajectory.velocities[0], [0.5, -0.2], atol=1e-12)
    own = dmp.rollout(DEMO.duration, DEMO.duration / 100)
    np.testing.assert_allclose(own.positions, report.trajectory.positions, atol=1e-10)


@pytest.mark.parametrize("goal_scaling", ["paper", "rotation", "translation"])
def test_moved_demonstration_follows_the_goal_scaling_written_plainly(goal_scaling):
    """The target of a request with a new start, goal and twice the duration is the
    demonstration (same samples, time stretched) mapped by the goal scaling: per DOF by
    (g - s) / (g0 - s0) ("paper"), by the planar similarity taking g0 - s0 to g - s, written
    as a complex product ("rotation"), or shifted ("translation"); its start velocity is the
    demonstration's mapped the same way and halved."""
    times = np.linspace(0.5, 2.5, 201)  # 2 s, not starting at 0, from (0.3, -0.2)
    s = times - 0.5
    positions = np.column_stack([0.3 + s + s**2, -0.2 + 0.5 * s**3])
    demo = Trajectory.from_positions(times, positions)
    reference = fit_discrete(demo, 15, goal_scaling=goal_scaling)
    start, goal = np.array([0.2, -0.1]), np.array([1.5, 0.9])
    problem = build_fitting_problem(
        demo, reference=reference, start=start, goal=goal, duration=4.0, n_samples=201
    )
    old_start, old_goal = demo.positions[0], demo.positions[-1]
    offsets, velocity = demo.positions - old_start, demo.velocities[0]
    if goal_scaling == "paper":
        ratio = (goal - start) / (old_goal - old_start)
        moved, moved_velocity = offsets * ratio, velocity * ratio
    elif goal_scaling == "rotation":
        factor = complex(*(goal - start)) / complex(*(old_goal - old_start))
        as_complex = (offsets[:, 0] + 1j * offsets[:, 1]) * factor
        moved = np.column_stack([as_complex.real, as_complex.imag])
        turned = complex(*velocity) * factor
        moved_velocity = np.array([turned.real, turned.imag])
    else:
        moved, moved_velocity = offsets, velocity
    np.testing.assert_allclose(problem.target, start + moved, atol=1e-12)
    np.testing.assert_allclose(problem.start_velocity, moved_velocity / 2.0, atol=1e-12)
    np.testing.assert_array_equal(problem.dmp.start, start)
    np.testing.assert_array_equal(problem.dmp.goal, goal)
    assert problem.duration == 4.0 and problem.dt == 0.02
    np.testing.assert_allclose(problem.dmp.tau, 2.0 * reference.tau)


def test_build_defaults_and_its_own_imitation_fit():
    """Without a reference the build fits one with the given options (30 basis functions,
    form "velocity", goal scaling "auto" and ridge 1e-9 by default)."""
    problem = build_fitting_problem(DEMO)
    default = fit_discrete(DEMO, 30)
    assert problem.n_basis == 30 and problem.dmp.form == "velocity"
    np.testing.assert_allclose(problem.dmp.weights, default.weights, rtol=1e-12)
    assert problem.dmp.goal_scaling == default.goal_scaling and problem.solver == "daqp"
    options = dict(form="acceleration", goal_scaling="paper", regularization=1e-4)
    other = build_fitting_problem(DEMO, 12, **options)
    np.testing.assert_allclose(other.dmp.weights, fit_discrete(DEMO, 12, **options).weights)
    assert fit_weights_constrained(DEMO, n_samples=51).dmp.n_basis == 30


def test_forcing_objective_matches_the_plain_qp_solved_by_a_second_solver():
    """The objective "forcing" is, per DOF, min ||Phi (w - w0)||^2 + lambda ||w - w0||^2 with
    Phi the phase features and w0 the reference's forcing weights, here under a velocity
    limit and the goal held (Clarabel on the library's affine plan)."""
    plan = plain_plan()
    velocity = 0.8 * np.abs(plan.velocities).max(0)
    _, report = fit_weights_constrained(
        DEMO,
        reference=REFERENCES["velocity"],
        objective="forcing",
        bounds=Bounds(velocity=velocity),
        margin=0.0,
    )
    problem = report.problem
    free, response = problem.plan.free, problem.plan.weight_response
    features = problem.dmp.phase_features(DEMO.n_steps, DEMO.duration / (DEMO.n_steps - 1))
    gram = features.T @ features
    ridge = 1e-9 * np.trace(gram) / gram.shape[0]
    prior = problem.dmp.forcing_weights()
    key = []
    for d in range(2):
        key.append(
            clarabel(
                gram + ridge * np.eye(20),
                -(gram + ridge * np.eye(20)) @ prior[d],
                response[1],
                -velocity[d] - free[1, :, d],
                velocity[d] - free[1, :, d],
                response[0, -1:],
                np.array([DEMO.positions[-1, d] - free[0, -1, d]]),
            )
        )
    key_positions = free[0] + response[0] @ np.array(key).T
    np.testing.assert_allclose(report.trajectory.positions, key_positions, atol=1e-6)


def test_proxsuite_failure_is_reported_not_returned_as_an_answer():
    """On the QP where standalone ProxQP stops early, solve_qp says so (success False, the
    solver's status) instead of passing its point off as the optimum."""
    hessian, gradient, matrix, lower, upper = random_qp(1, 3, 24)
    key = clarabel(hessian, gradient, matrix, lower, upper)
    solution = solve_qp(hessian, gradient, matrix, lower, upper, solver="proxsuite", stride=1)
    if solution.success:
        np.testing.assert_allclose(solution.x, key, atol=1e-5 * (1 + np.abs(key).max()))
    else:
        assert solution.status != "QPSolverOutput.PROXQP_SOLVED"


def test_nlp_without_balls_reaches_clarabels_optimum_of_the_same_qp():
    """IPOPT on the NLP with only linear rows (2 DOFs, velocity limits active) returns
    Clarabel's solution of the stacked QP: the objective of every DOF, its Hessian and
    gradient, and the rows are the QP's."""
    from dmpopt.fitting import nlp

    problem = velocity_limited_problem(0.8, n_samples=101)
    key = clarabel(*problem.full_qp())
    begin = time.perf_counter()
    x, success, status, solve_time, iterations = nlp.solve_nlp(problem)
    assert 0.0 <= solve_time <= time.perf_counter() - begin  # within the call's wall time
    assert success and status == "Solve_Succeeded" and iterations > 0
    np.testing.assert_allclose(x.ravel(), key, atol=1e-5)


def test_euclidean_via_point_off_the_path_is_met_on_its_sphere():
    """The via point lies off the unconstrained plan, so its ball is active: the plan passes
    on its sphere, at the radius minus a margin of 1e-6 (units of the length scale, 1 here)
    to IPOPT's accuracy."""
    point = np.array([0.6, 0.5])
    problem = build_fitting_problem(
        DEMO,
        reference=REFERENCES["velocity"],
        n_samples=101,
        via_points=[ViaPoint(0.5, point, tolerance=0.02, norm="ball")],
    )
    fit, report = solve_fitting_problem(problem)
    distance = np.linalg.norm(report.trajectory.positions[50] - point)
    assert problem.length_scale == 1.0
    assert 0.02 - 2e-6 <= distance <= 0.02


@pytest.mark.parametrize(
    ("n_steps", "n_basis", "n_dofs", "bounds", "n_via", "values"),
    [
        (10_000_000, 10, 1, None, 0, 3 * 10_000_000 * 10),  # 3 n N: the plan's responses
        (7_000_000, 10, 1, "limits", 0, (4 * 7_000_000 + 3) * 10),  # rows N: 4 limits a sample
        (70_000_000, 1, 4, None, 0, 70_000_000 * 4),  # n D: the demonstration's samples
        (10, 17_000, 1, None, 0, 17_000**2),  # N^2: the Hessian
    ],
)
def test_problem_size_bound_counts_each_term_in_bytes(
    n_steps, n_basis, n_dofs, bounds, n_via, values
):
    """Each term of the size estimate where it dominates, 8 bytes a value (written plainly):
    the message states it in GiB to three digits, so a wrong factor shows."""
    from dmpopt.exceptions import ResourceLimitError
    from dmpopt.fitting.constrained import _check_problem_size

    limits = Bounds(velocity=1.0) if bounds else None
    with pytest.raises(
        ResourceLimitError,
        match=rf"^a constrained fit with {n_steps} samples, {n_basis} basis functions, {n_dofs} "
        rf"DOFs and {n_via} via-points needs about {8 * values / 1024**3:.3g} GiB; .*: lower "
        r"n_samples \(constraints hold at every sample; a few hundred suffice\), n_basis or the "
        "number of via-points$",
    ):
        _check_problem_size(n_steps, n_basis, n_dofs, limits, n_via)


def test_problem_size_accepts_the_via_point_bound_itself():
    from dmpopt.exceptions import ResourceLimitError
    from dmpopt.fitting.constrained import MAX_VIA_POINTS, _check_problem_size

    _check_problem_size(10, 5, 2, None, MAX_VIA_POINTS)
    with pytest.raises(InvalidInputError, match=r"^n_basis must be an integer >= 1"):
        _check_problem_size(10, 0, 2, None, 0)
    with pytest.raises(ResourceLimitError, match=r"^via_points holds 10001 via-points"):
        _check_problem_size(10, 5, 2, None, MAX_VIA_POINTS + 1)


def test_infeasibility_message_lists_every_dof_of_a_group_in_full():
    """A velocity limit far too tight for both DOFs: one group, both DOFs, the whole message."""
    problem = velocity_limited_problem(0.05, n_samples=101)
    with pytest.raises(InfeasibleProblem) as caught:
        solve_fitting_problem(problem)
    assert list(caught.value.relaxations) == ["end_position"]
    assert caught.value.relaxations["end_position"][1] == [0, 1]
    amount = caught.value.relaxations["end_position"][0]
    assert str(caught.value) == (
        f"infeasible constrained fit ({caught.value.stats['status']}): 'end_position' on DOF(s) "
        f"[0, 1] by {amount:.4g} [physical units]; relax these constraints by at least that "
        "much (plus the safety margin of 1e-06 units), lengthen the duration or move the goal "
        "(the problem is attached as .problem)"
    )


def test_solve_qp_reports_a_solve_time_within_the_call():
    hessian, gradient, matrix, lower, upper = random_qp(5, 4, 12)
    begin = time.perf_counter()
    solution = solve_qp(hessian, gradient, matrix, lower, upper)
    assert solution.success and 0.0 <= solution.solve_time <= time.perf_counter() - begin


def test_solve_blocks_adds_the_time_and_iterations_of_every_solve(monkeypatch):
    """Each solve reports 0.25 s and 3 iterations (patched): two blocks, each failed by the
    first backend and solved by the fallback, sum to 1 s and 12 iterations; a block both
    fail returns its state so far (success False, the working sets of the solved blocks)."""
    hessian, gradient, matrix, lower, upper = random_qp(3, 4, 12)
    real_backend, real_solve = qp._backend_solve, qp.solve_qp

    def daqp_fails(solver, *args):
        x, z, success, status = real_backend(solver, *args)
        return x, z, success and solver != "daqp", status

    def fixed_cost(*args, **kwargs):
        return real_solve(*args, **kwargs)._replace(solve_time=0.25, iterations=3)

    monkeypatch.setattr(qp, "_backend_solve", daqp_fails)
    monkeypatch.setattr(qp, "solve_qp", fixed_cost)
    blocks = (hessian, np.stack([gradient, -gradient]), matrix)
    both = qp.solve_blocks(*blocks, np.stack([lower] * 2), np.stack([upper] * 2), solver="daqp")
    assert (both.solve_time, both.iterations, both.status) == (1.0, 12, "Successful return.")
    twice = np.vstack([matrix, matrix[:1]])  # row 0 twice: disjoint bounds, infeasible
    low, high = np.append(lower, lower[0]), np.append(upper, upper[0])
    apart_low, apart_high = low.copy(), high.copy()
    apart_low[-1], apart_high[-1] = upper[0] + 1.0, upper[0] + 2.0
    stopped = qp.solve_blocks(
        hessian,
        np.stack([gradient] * 3),
        twice,
        np.stack([low, apart_low, low]),
        np.stack([high, apart_high, high]),
        solver="daqp",
    )
    assert stopped.success is False and stopped.failed_block == 1
    assert (stopped.solve_time, stopped.iterations) == (1.0, 12)
    assert stopped.active.dtype == bool and stopped.active.shape == (3, twice.shape[0])
    np.testing.assert_array_equal(stopped.active[0, :-1], both.active[0])
    assert not stopped.active[1:].any()


def test_recalled_objective_is_the_fresh_one():
    """Fits of one demo and request under other constraints recall its objective; answer key:
    the objective built with nothing recalled, equal bit for bit (a key of the response
    alone would give the moved goal the first goal's gradient)."""
    from dmpopt.fitting import constrained

    reference = REFERENCES["velocity"]
    goals = [DEMO.positions[-1], DEMO.positions[-1] + [0.2, -0.1]]
    recalled = []
    for goal in goals:
        build_fitting_problem(DEMO, reference=reference, goal=goal)  # fills the store
        bounded = Bounds(velocity=[3.0, 3.0])
        recalled.append(build_fitting_problem(DEMO, reference=reference, goal=goal, bounds=bounded))
    for goal, problem in zip(goals, recalled):
        constrained._OBJECTIVES.clear()
        fresh = build_fitting_problem(DEMO, reference=reference, goal=goal)
        np.testing.assert_array_equal(problem.hessian, fresh.hessian)
        np.testing.assert_array_equal(problem.gradient, fresh.gradient)
        assert not problem.gradient.flags.writeable  # shared: no caller may change it
