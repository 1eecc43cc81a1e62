"""Tests of dmpopt.learning: tasks, gradient estimators and the ask/tell optimisers."""

import numpy as np
import pytest
from scipy.optimize import minimize

from dmpopt import symbolic
from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.learning import (
    CMAES,
    PIBB,
    EpisodicNAC,
    EpisodicReinforce,
    enac_gradient,
    make_method,
    multi_dof_reaching_task,
    optimise,
    paper_reaching_task,
    reinforce_gradient,
    via_point_task,
)


@pytest.fixture(scope="module")
def task():
    return paper_reaching_task()


# -- tasks ------------------------------------------------------------------------------


def test_noisy_rollout_matches_step_by_step_integration(task):
    """Plan + H eps equals the symbolic RK4 step run with a per-step coupling tau^2 eps_k."""
    rng = np.random.default_rng(0)
    weights = 50 * rng.standard_normal((1, task.n_basis))
    noise = 20 * rng.standard_normal((1, task.n_actions, 1))
    dmp = task.dmp.replace(weights=weights)
    step = symbolic.step_function(dmp.signature)
    output = symbolic.output_function(dmp.signature)
    parameters = dmp.parameters()
    state = np.zeros(dmp.signature.n_states)
    expected = []
    for k in range(task.n_steps):
        parameters["coupling"] = dmp.tau**2 * noise[0, k, 0] if k < task.n_actions else 0.0
        outputs = output(state=state, **parameters)
        expected.append([float(outputs[name]) for name in ("position", "velocity", "acceleration")])
        state = np.asarray(step(state=state, dt=task.dt, **parameters)["next_state"]).ravel()
    actual = task.rollouts(weights[None], noise)[0, :, :, 0]
    np.testing.assert_allclose(actual, np.array(expected).T, rtol=0, atol=1e-9)


def test_noise_free_rollout_is_the_dmp_plan(task):
    """Without noise the task's roll-out is the DMP's own rollout."""
    weights = np.linspace(-20, 20, task.n_basis)[None]
    reference = task.dmp.replace(weights=weights).rollout(task.duration, task.dt)
    plan = task.rollouts(weights)[0]
    np.testing.assert_allclose(plan[0], reference.positions, atol=1e-12)
    np.testing.assert_allclose(plan[2], reference.accelerations, atol=1e-9)


def test_reward_definition(task):
    """Return = -1000 (y(T)-g)^2 - yd(T)^2 - 1e-3 sum_k ydd_k^2 dt, and delayed sums agree."""
    rng = np.random.default_rng(1)
    weights = 10 * rng.standard_normal((3, 1, task.n_basis))
    noise = 5 * rng.standard_normal((3, task.n_actions, 1))
    plans = task.rollouts(weights, noise)
    y, yd, ydd = plans[:, 0, :, 0], plans[:, 1, :, 0], plans[:, 2, :, 0]
    expected = (
        -1000 * (y[:, -1] - 1) ** 2
        - yd[:, -1] ** 2
        - 1e-3 * task.dt * np.sum(ydd[:, :-1] ** 2, axis=1)
    )
    np.testing.assert_allclose(task.returns(weights, noise), expected, rtol=1e-12)
    delayed = paper_reaching_task(delayed=True).rewards(plans)
    assert np.all(delayed[:, :-1] == 0)
    np.testing.assert_allclose(delayed[:, -1], expected, rtol=1e-12)


def test_exact_optimum_matches_numerical_optimisation(task):
    """The least-squares optimum equals BFGS on the noise-free return, and reaches the goal."""

    def cost(w):
        return -task.deterministic_return(w[None])

    result = minimize(cost, np.zeros(task.n_basis), method="BFGS", options={"gtol": 1e-10})
    assert task.optimum_return == pytest.approx(-result.fun, rel=1e-6)
    assert task.optimum_return >= -result.fun - 1e-12
    final = task.plan.evaluate(task.optimal_weights)[0, -1, 0]
    assert abs(final - 1.0) < 1e-3
    assert task.improvement(task.optimal_weights) == pytest.approx(1.0)
    assert task.improvement(task.initial_weights) == pytest.approx(0.0)


def test_multi_dof_and_via_point_optima():
    """Six DOFs reach their goals; the via-point optimum passes near the via point."""
    six = multi_dof_reaching_task()
    plan = six.plan.evaluate(six.optimal_weights)
    np.testing.assert_allclose(plan[0, -1], six.dmp.goal, atol=2e-3)
    via = via_point_task()
    plan = via.plan.evaluate(via.optimal_weights)
    index = int(round(0.2 / via.dt))
    np.testing.assert_allclose(plan[0, index], [0.3, 0.6], atol=0.02)
    assert via.optimum_return > via.initial_return + 300


# -- gradient estimators -------------------------------------------------------------------


def _linear_gaussian(rng, n_steps=6, n_basis=3):
    """a = M w + eps, R = -||A a - b||^2: closed-form gradient and Fisher."""
    features = rng.standard_normal((n_steps, n_basis))
    a_matrix = rng.standard_normal((4, n_steps))
    target = rng.standard_normal(4)
    weights = rng.standard_normal((1, n_basis))
    return features, a_matrix, target, weights


def test_scores_are_log_likelihood_gradients():
    """scores() equals finite differences of the Gaussian log-likelihood of the actions."""
    rng = np.random.default_rng(2)
    features, _, _, weights = _linear_gaussian(rng)
    sigma = 0.7
    method = EpisodicNAC(features, weights, sigma, n_rollouts=2, learn_exploration=True, seed=0)
    noise = method.ask().acceleration_noise
    actions = (features @ weights[0])[None, :, None] + noise

    def log_likelihood(w, log_std):
        mean = (features @ w)[None, :, None]
        std = np.exp(log_std)
        return np.sum(-0.5 * ((actions - mean) / std) ** 2 - log_std, axis=(1, 2))

    params = np.append(weights[0], np.log(sigma))
    numeric = np.zeros((2, params.size))
    for i in range(params.size):
        delta = np.zeros(params.size)
        delta[i] = 1e-6
        up = log_likelihood(params[:-1] + delta[:-1], params[-1] + delta[-1])
        down = log_likelihood(params[:-1] - delta[:-1], params[-1] - delta[-1])
        numeric[:, i] = (up - down) / 2e-6
    np.testing.assert_allclose(method.scores(noise), numeric, rtol=1e-6, atol=1e-6)


def test_reinforce_and_nac_on_a_linear_gaussian_problem():
    """With many roll-outs, REINFORCE -> grad J and eNAC -> F^-1 grad J (and c -> J)."""
    rng = np.random.default_rng(3)
    features, a_matrix, target, weights = _linear_gaussian(rng)
    sigma, k = 0.5, 400_000
    noise = sigma * rng.standard_normal((k, features.shape[0]))
    actions = features @ weights[0] + noise
    returns = -np.sum((actions @ a_matrix.T - target) ** 2, axis=1)
    scores = noise @ features / sigma**2
    residual = a_matrix @ features @ weights[0] - target
    gradient = -2 * features.T @ a_matrix.T @ residual
    fisher = features.T @ features / sigma**2
    expected_return = -residual @ residual - sigma**2 * np.sum(a_matrix**2)

    vanilla = reinforce_gradient(scores, returns)
    natural, baseline = enac_gradient(scores, returns)
    scale = np.linalg.norm(gradient)
    assert np.linalg.norm(vanilla - gradient) < 0.02 * scale
    assert np.linalg.norm(fisher @ natural - gradient) < 0.02 * scale
    assert np.linalg.norm(fisher @ natural - vanilla) < 0.03 * scale
    assert baseline == pytest.approx(expected_return, rel=0.02)


def test_likelihood_ratio_gradient_bias_on_the_task_is_small(task):
    """E[REINFORCE] = d R / d delta along eps = M delta; it matches dR/dw within 1 %.

    By Stein's lemma the expected likelihood-ratio gradient of a quadratic return is the
    derivative along the per-step commands ``features @ delta``, while the true gradient is
    along the plan's weights; they differ only by the held-vs-integrated forcing term.
    """
    weights = np.zeros((1, task.n_basis))
    h = 1e-3
    true, along_policy = np.zeros(task.n_basis), np.zeros(task.n_basis)
    for i in range(task.n_basis):
        delta = np.zeros(task.n_basis)
        delta[i] = h
        up, down = weights + delta, weights - delta
        true[i] = (task.deterministic_return(up) - task.deterministic_return(down)) / (2 * h)
        noise = (task.policy_features @ delta)[None, :, None]
        along_policy[i] = (task.returns(weights, noise)[0] - task.returns(weights, -noise)[0]) / (
            2 * h
        )
    assert np.linalg.norm(along_policy - true) < 0.01 * np.linalg.norm(true)


# -- optimisers ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name, options",
    [
        ("enac", {"exploration_std": 10.0, "step_size": 10.0}),
        ("enac", {"exploration_std": 10.0, "step_size": 20.0, "step_rule": "constant"}),
        ("ereinforce", {"exploration_std": 10.0, "step_size": 10.0}),
        ("ereinforce", {"exploration_std": 10.0, "step_size": 30.0, "step_rule": "constant"}),
        ("pibb", {"exploration_std": 20.0}),
        ("cmaes", {"exploration_std": 20.0}),
    ],
)
def test_each_method_improves_the_paper_task(task, name, options):
    """300 trials (15 updates of 20 roll-outs) bring the noise-free return >= 80 % of the way."""
    curve = optimise(make_method(name, task, seed=0, **options), task, 300)
    assert curve.trials[-1] == 300
    assert curve.improvement[-1] > 0.8
    assert curve.returns[-1] > task.initial_return


def test_learned_exploration_changes_sigma_and_improves(task):
    """eNAC with learn_exploration updates sigma and still improves the return."""
    method = make_method(
        "enac", task, seed=1, exploration_std=10.0, step_size=10.0, learn_exploration=True
    )
    curve = optimise(method, task, 300)
    assert method.exploration_std != 10.0
    assert curve.improvement[-1] > 0.8


def test_delayed_rewards_give_the_same_learning(task):
    """Episodic methods see the same returns with per-step or end-only rewards."""
    delayed = paper_reaching_task(delayed=True)
    curves = [
        optimise(make_method("enac", t, seed=5, exploration_std=10.0, step_size=10.0), t, 200)
        for t in (task, delayed)
    ]
    np.testing.assert_allclose(curves[0].weights, curves[1].weights, rtol=1e-9, atol=1e-9)


def test_methods_improve_the_via_point_task():
    """KL-normalised eNAC (more roll-outs than its 20 weights) and CMA-ES improve a 2-DOF task."""
    via = via_point_task()
    for name, options in (
        ("enac", {"exploration_std": 30.0, "step_size": 30.0, "n_rollouts": 30}),
        ("cmaes", {"exploration_std": 20.0}),
    ):
        curve = optimise(make_method(name, via, seed=0, **options), via, 400)
        assert curve.improvement[-1] > 0.5


def test_ask_tell_errors(task):
    """tell() needs a pending ask() and rewards of the asked batch size."""
    method = EpisodicReinforce(task.policy_features, task.initial_weights, 10.0, seed=0)
    with pytest.raises(InvalidInputError, match="tell\\(\\) called without a pending ask\\(\\)"):
        method.tell(np.zeros(20))
    method.ask()
    with pytest.raises(ShapeError, match=r"rewards has shape \(3,\), expected \(20,\) returns"):
        method.tell(np.zeros(3))
    with pytest.raises(InvalidInputError, match="step_rule must be one of"):
        EpisodicNAC(task.policy_features, task.initial_weights, 1.0, step_rule="adam")
    with pytest.raises(InvalidInputError, match="method must be one of"):
        make_method("ppo", task)
    pibb = PIBB(task.initial_weights, 5.0, seed=0)
    pibb.tell(task.evaluate(pibb.ask()))
    assert pibb.n_trials == 20
    cma = CMAES(task.initial_weights, 5.0, seed=0)
    cma.tell(task.evaluate(cma.ask()))
    assert cma.n_trials == 20 and cma.mean.shape == (1, task.n_basis)
