"""Constrained DMP fits: every constraint holds on the rollout; no constraint = imitation."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.exceptions import InfeasibleProblem, InvalidInputError
from dmpopt.fitting.constrained import (
    Bounds,
    ViaPoint,
    build_fitting_problem,
    fit_weights_constrained,
    solve_fitting_problem,
)
from dmpopt.fitting.imitation import fit_discrete
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
    assert report.solver == "ipopt"
    assert np.linalg.norm(report.trajectory.positions[50] - point) <= 0.02 + 1e-7


def test_problem_is_inspectable_and_warm_starts():
    """The built problem exposes its groups and stacked QP; a second solve reuses it."""
    plan = plain_plan()
    problem = build_fitting_problem(
        DEMO,
        reference=REFERENCES["velocity"],
        bounds=Bounds(velocity=0.8 * np.abs(plan.velocities).max(0)),
    )
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
    plan = plain_plan()
    problem = build_fitting_problem(
        DEMO,
        reference=REFERENCES["velocity"],
        n_samples=101,
        bounds=Bounds(velocity=0.2 * np.abs(plan.velocities).max(0)),
    )
    with pytest.raises(InfeasibleProblem) as caught:
        solve_fitting_problem(problem)
    message = str(caught.value)
    assert message.startswith("infeasible constrained fit")
    assert "relax these constraints by at least that much" in message
    assert caught.value.problem is problem
    assert set(caught.value.relaxations) <= {"velocity", "end_position"}
    assert all(amount > 0 for amount, _ in caught.value.relaxations.values())


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
