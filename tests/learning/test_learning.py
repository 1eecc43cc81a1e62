"""Tests of dmpopt.learning: tasks, gradient estimators and the ask/tell optimisers."""

import numpy as np
import pytest
from scipy.optimize import minimize

from dmpopt import symbolic
from dmpopt.exceptions import DmpoptError, InvalidInputError, ShapeError
from dmpopt.learning import (
    CMAES,
    PIBB,
    EpisodicNAC,
    EpisodicReinforce,
    Exploration,
    RewardTask,
    ViaPointReward,
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


# -- answer keys: the update rules written plainly ---------------------------------------------

FEATURES = np.array([[1.0, 0.2], [0.5, -0.3], [-0.4, 1.1], [0.9, 0.7], [0.1, -0.8]])  # (5, 2)
SIGMA = 0.5


def _plain_scores(noise, features, sigma, with_log_std=False):
    """psi_k[(d, b)] = sum_t eps_{k,t,d} phi_{t,b} / sigma^2 (and sum (eps^2/sigma^2 - 1))."""
    k, n_actions, n_dofs = noise.shape
    scores = np.zeros((k, n_dofs * features.shape[1] + with_log_std))
    for r in range(k):
        for d in range(n_dofs):
            for b in range(features.shape[1]):
                total = sum(noise[r, t, d] * features[t, b] for t in range(n_actions))
                scores[r, d * features.shape[1] + b] = total / sigma**2
        if with_log_std:
            scores[r, -1] = np.sum(noise[r] ** 2 / sigma**2 - 1.0)
    return scores


def _plain_fisher(features, sigma, n_dofs):
    """F[(d, b), (d', b')] = [d = d'] sum_t phi_{t,b} phi_{t,b'} / sigma^2."""
    n_basis = features.shape[1]
    fisher = np.zeros((n_dofs * n_basis, n_dofs * n_basis))
    for d in range(n_dofs):
        for b in range(n_basis):
            for c in range(n_basis):
                fisher[d * n_basis + b, d * n_basis + c] = features[:, b] @ features[:, c]
    return fisher / sigma**2


def test_enac_gradient_recovers_returns_linear_in_the_scores():
    """Returns R = Psi a + c exactly: the regression of eq. (19) gives g = a and baseline c."""
    rng = np.random.default_rng(10)
    scores = rng.standard_normal((12, 3))
    a, c = np.array([0.5, -2.0, 1.25]), 3.5
    natural, baseline = enac_gradient(scores, scores @ a + c)
    np.testing.assert_allclose(natural, a, rtol=0, atol=1e-12)
    assert baseline == pytest.approx(c, abs=1e-12)


def test_enac_step_is_the_natural_gradient_f_inverse_g():
    """One constant step of eNAC moves W by alpha F^-1 grad J; the vanilla gradient does not.

    With R = Psi a + c, the likelihood-ratio gradient is grad J = E[psi R] = F a, so the
    natural gradient F^-1 grad J is a. Two DOFs check the (DOF, basis) layout.
    """
    weights = np.array([[1.0, -1.0], [0.5, 2.0]])
    method = EpisodicNAC(
        FEATURES, weights, SIGMA, n_rollouts=10, step_size=0.3, step_rule="constant", seed=4
    )
    noise = method.ask().acceleration_noise
    scores = _plain_scores(noise, FEATURES, SIGMA)
    a = np.array([0.2, -0.1, 0.4, 0.3])
    returns = scores @ a + 7.0
    natural = np.linalg.solve(
        _plain_fisher(FEATURES, SIGMA, 2), _plain_fisher(FEATURES, SIGMA, 2) @ a
    )
    vanilla = reinforce_gradient(scores, returns)
    assert np.linalg.norm(vanilla - natural) > 0.1 * np.linalg.norm(natural)
    method.tell(returns)
    np.testing.assert_allclose(
        method.mean, weights + 0.3 * natural.reshape(2, 2), rtol=0, atol=1e-12
    )
    assert method.n_trials == 10 and method.n_updates == 1


def test_kl_step_length_and_decay():
    """step_rule "kl": alpha = sqrt(2 eps / (g^T F g)), divided by 1 + decay * n_updates."""
    weights = np.array([[1.0, -1.0]])
    method = EpisodicNAC(FEATURES, weights, SIGMA, n_rollouts=6, step_size=0.02, decay=0.5, seed=5)
    fisher = _plain_fisher(FEATURES, SIGMA, 1)
    a = np.array([1.5, -0.5])
    expected = weights.copy()
    for update in range(3):
        scores = _plain_scores(method.ask().acceleration_noise, FEATURES, SIGMA)
        method.tell(scores @ a - 1.0)
        alpha = np.sqrt(2 * 0.02 / (a @ fisher @ a)) / (1 + 0.5 * update)
        expected = expected + alpha * a
        np.testing.assert_allclose(method.mean, expected, rtol=1e-10, atol=1e-12)
    assert method.fisher() == pytest.approx(fisher, rel=1e-12)


def test_learned_exploration_step_on_log_sigma():
    """With learn_exploration, log sigma moves by alpha times its natural-gradient entry."""
    weights = np.array([[0.0, 0.0]])
    method = EpisodicNAC(
        FEATURES,
        weights,
        SIGMA,
        n_rollouts=8,
        step_size=0.5,
        step_rule="constant",
        learn_exploration=True,
        seed=6,
    )
    noise = method.ask().acceleration_noise
    scores = _plain_scores(noise, FEATURES, SIGMA, with_log_std=True)
    np.testing.assert_allclose(method.scores(noise), scores, rtol=1e-12, atol=1e-12)
    a = np.array([0.4, -0.2, 0.1])
    method.tell(scores @ a)
    np.testing.assert_allclose(method.mean, [[0.2, -0.1]], rtol=0, atol=1e-12)
    assert method.exploration_std == pytest.approx(SIGMA * np.exp(0.05), rel=1e-12)
    fisher = method.fisher()
    assert fisher.shape == (3, 3) and fisher[-1, -1] == 2.0 * FEATURES.shape[0]
    assert np.all(fisher[-1, :-1] == 0) and np.all(fisher[:-1, -1] == 0)


def test_reinforce_gradient_plain_formula():
    """g_h = mean_k psi_kh (R_k - b_h), b_h = sum psi_kh^2 R_k / sum psi_kh^2; zero column -> 0."""
    scores = 0.01 * np.array([[1.0, 0.0, 2.0], [-2.0, 0.0, 1.0], [0.5, 0.0, -1.0], [3.0, 0.0, 0.0]])
    returns = np.array([1.0, -2.0, 0.5, 4.0])
    expected = np.zeros(3)
    for h in range(3):
        psi = scores[:, h]
        baseline = (psi**2 @ returns) / (psi**2).sum() if np.any(psi) else 0.0
        expected[h] = np.mean(psi * (returns - baseline))
    np.testing.assert_allclose(reinforce_gradient(scores, returns), expected, rtol=1e-12, atol=0)
    method = EpisodicReinforce(
        FEATURES, [[0.0, 0.0]], SIGMA, n_rollouts=4, step_size=2.0, step_rule="constant", seed=7
    )
    noise = method.ask().acceleration_noise
    psi = _plain_scores(noise, FEATURES, SIGMA)
    method.tell(returns)
    np.testing.assert_allclose(method.mean[0], 2.0 * reinforce_gradient(psi, returns), rtol=1e-12)


def _pibb_expected(samples, returns, mean, covariance, eliteness, decay, rate, adapt, floor):
    """PI-BB update written plainly."""
    scaled = (returns - returns.max()) / (returns.max() - returns.min())
    p = np.exp(eliteness * scaled)
    p = p / p.sum()
    new_mean = sum(p[k] * samples[k] for k in range(len(p)))
    if adapt:
        estimate = sum(p[k] * np.outer(samples[k] - mean, samples[k] - mean) for k in range(len(p)))
        covariance = (1 - rate) * covariance + rate * estimate
    return new_mean, decay * covariance + floor * np.eye(len(mean))


@pytest.mark.parametrize("adapt", [True, False])
def test_pibb_update_plain_formula(adapt):
    """Reward-weighted mean and (adapted or shrunk) covariance, with the 1e-6 sigma^2 floor."""
    start = np.array([[0.5, -1.0, 2.0]])
    method = PIBB(
        start,
        2.0,
        n_rollouts=5,
        eliteness=3.0,
        decay=0.9,
        adapt_covariance=adapt,
        covariance_rate=0.25,
        seed=8,
    )
    samples = method.ask().weights.reshape(5, 3)
    returns = np.array([1.0, 4.0, -2.0, 0.5, 3.0])
    method.tell(returns)
    mean, covariance = _pibb_expected(
        samples, returns, start[0], 4.0 * np.eye(3), 3.0, 0.9, 0.25, adapt, 4e-6
    )
    np.testing.assert_allclose(method.mean, mean[None], rtol=1e-12)
    np.testing.assert_allclose(method.covariance, covariance, rtol=1e-12, atol=1e-15)
    assert method.n_trials == 5 and method.n_updates == 1


def test_pibb_defaults_and_equal_returns():
    """Defaults: 20 roll-outs, eliteness 10, decay 0.98, adapted covariance at rate 0.5.

    Equal returns weigh every sample equally (no division by a zero spread).
    """
    start = np.array([[0.0, 1.0]])
    method = PIBB(start, 3.0, seed=9)
    np.testing.assert_allclose(method.covariance, 9.0 * np.eye(2))
    samples = method.ask().weights.reshape(20, 2)
    assert samples.shape == (20, 2) and method.n_updates == 0 and method.n_trials == 0
    returns = np.linspace(-1.0, 2.0, 20)
    method.tell(returns)
    mean, covariance = _pibb_expected(
        samples, returns, start[0], 9.0 * np.eye(2), 10.0, 0.98, 0.5, True, 9e-6
    )
    np.testing.assert_allclose(method.mean[0], mean, rtol=1e-12)
    np.testing.assert_allclose(method.covariance, covariance, rtol=1e-12)
    samples = method.ask().weights.reshape(20, 2)
    method.tell(np.zeros(20))
    np.testing.assert_allclose(method.mean[0], samples.mean(axis=0), rtol=1e-12)


def test_same_seed_same_exploration(task):
    """A seed fixes every method's exploration; another seed changes it."""
    for name, options in (
        ("enac", {"exploration_std": 1.0}),
        ("pibb", {"exploration_std": 1.0}),
        ("cmaes", {"exploration_std": 1.0}),
    ):
        first, again, other = (make_method(name, task, seed=s, **options).ask() for s in (3, 3, 4))
        np.testing.assert_array_equal(first.weights, again.weights)
        if name == "enac":
            first, again, other = (e.acceleration_noise for e in (first, again, other))
        else:
            first, other = first.weights, other.weights
        assert not np.allclose(first, other)


def test_learning_curve_lookups():
    """weights_at: the last update within the trials; trials_to: the first reaching a fraction."""
    curve = optimise(
        make_method("pibb", paper_reaching_task(), seed=0, exploration_std=20.0),
        paper_reaching_task(),
        60,
    )
    assert curve.trials.tolist() == [0.0, 20.0, 40.0, 60.0] and curve.trials.dtype == float
    np.testing.assert_array_equal(curve.weights_at(39.5), curve.weights[1])
    np.testing.assert_array_equal(curve.weights_at(40), curve.weights[2])
    np.testing.assert_array_equal(curve.weights_at(0), curve.weights[0])
    np.testing.assert_array_equal(curve.final_weights, curve.weights[3])
    target = float(curve.improvement[2])
    first = int(np.argmax(curve.improvement >= target))
    assert curve.trials_to(target) == curve.trials[first]
    assert curve.trials_to(2.0) == float("inf")
    with pytest.raises(InvalidInputError, match="trials"):
        curve.weights_at(-1)
    with pytest.raises(InvalidInputError, match="fraction"):
        curve.trials_to(np.nan)


def test_task_defaults():
    """The paper's task: 1 DOF, 0 -> 1 in 0.5 s at 1 ms, 10 bases, tau from the convergence time."""
    from dmpopt import basis

    task = paper_reaching_task()
    assert (task.n_dofs, task.n_basis, task.n_steps, task.dt, task.duration) == (
        1,
        10,
        501,
        0.001,
        0.5,
    )
    assert task.jerk_weight == 0.0 and task.delayed is False
    assert (task.goal_weight, task.velocity_weight, task.acceleration_weight) == (1000.0, 1.0, 1e-3)
    np.testing.assert_array_equal(task.dmp.start, [0.0])
    np.testing.assert_array_equal(task.dmp.goal, [1.0])
    tau = 0.5 / basis.convergence_time("acceleration", task.dmp.gains)
    assert task.dmp.tau == pytest.approx(tau, rel=1e-12)
    np.testing.assert_array_equal(task.initial_weights, np.zeros((1, 10)))
    six = multi_dof_reaching_task()
    np.testing.assert_array_equal(six.dmp.goal, [1.0, -0.5, 0.8, 0.3, -1.2, 0.6])
    assert (six.n_dofs, six.n_basis, six.dt, six.duration, six.delayed) == (
        6,
        10,
        0.001,
        0.5,
        False,
    )
    via = via_point_task()
    assert (via.n_dofs, via.n_basis, via.dt, via.duration, via.delayed) == (
        2,
        10,
        0.001,
        0.5,
        False,
    )
    np.testing.assert_array_equal(via.dmp.goal, [1.0, 0.0])
    assert via.via_points[0].time == 0.2 and via.via_points[0].position == (0.3, 0.6)


def test_improvement_of_one_or_a_batch(task):
    """improvement(W) is a float; of a batch (K, n_dofs, n_basis), an array of K fractions."""
    half = 0.5 * task.optimal_weights
    single = task.improvement(half)
    assert isinstance(single, float)
    expected = (task.deterministic_return(half) - task.initial_return) / (
        task.optimum_return - task.initial_return
    )
    assert single == pytest.approx(expected, rel=1e-12)
    batch = task.improvement(np.stack([task.initial_weights, half, task.optimal_weights]))
    np.testing.assert_allclose(batch, [0.0, expected, 1.0], rtol=1e-12, atol=1e-12)


# -- bad inputs: each names its argument; values on the bounds are accepted -------------------


@pytest.fixture(scope="module")
def coarse():
    return paper_reaching_task(dt=0.01)


def _pibb(coarse, **options):
    return PIBB(coarse.initial_weights, options.pop("std", 1.0), **options)


def _told(method, rewards):
    method.ask()
    method.tell(rewards)


BAD = {
    "task form": (
        lambda t: RewardTask(t.dmp.replace(form="velocity")),
        "dmp must be a DiscreteDMP with form='acceleration'",
    ),
    "goal_weight": (
        lambda t: RewardTask(t.dmp, goal_weight=-1),
        "goal_weight must be a finite number >= 0",
    ),
    "velocity_weight": (
        lambda t: RewardTask(t.dmp, velocity_weight=np.nan),
        "velocity_weight must",
    ),
    "acceleration_weight": (
        lambda t: RewardTask(t.dmp, acceleration_weight=-1),
        "acceleration_weight must",
    ),
    "jerk_weight": (lambda t: RewardTask(t.dmp, jerk_weight=-1), "jerk_weight must"),
    "duration": (lambda t: RewardTask(t.dmp, duration=0), "duration must be a finite number > 0"),
    "dt": (
        lambda t: RewardTask(t.dmp, dt=0.3),
        r"dt must be a finite number > 0 and <= 0.25, got 0.3",
    ),
    "delayed": (
        lambda t: RewardTask(t.dmp, dt=0.01, delayed="yes"),
        "delayed must be True or False",
    ),
    "via single": (
        lambda t: RewardTask(t.dmp, dt=0.01, via_points=ViaPointReward(0.1, (0.5,))),
        "via_points must be a sequence of ViaPoint",
    ),
    "via time": (
        lambda t: RewardTask(t.dmp, dt=0.01, via_points=(ViaPointReward(0.7, (0.5,)),)),
        r"via_points\[0\].time must be a finite number >= 0 and <= 0.5",
    ),
    "via position": (
        lambda t: RewardTask(t.dmp, dt=0.01, via_points=(ViaPointReward(0.1, (0.5, 1.0)),)),
        r"via_points\[0\].position has shape \(2,\), expected \(1,\)",
    ),
    "via weight": (
        lambda t: RewardTask(t.dmp, dt=0.01, via_points=(ViaPointReward(0.1, (0.5,), -1.0),)),
        r"via_points\[0\].weight must",
    ),
    "task size": (
        lambda t: RewardTask(t.dmp, duration=100.0, dt=1e-4),
        "a task of 100 s with dt = 0.0001 s",
    ),
    "rollout weights": (
        lambda t: t.rollouts(np.zeros((2, 2, 10))),
        r"weights has shape \(2, 2, 10\), expected \(K, 1, 10\)",
    ),
    "rollout noise": (
        lambda t: t.rollouts(np.zeros((1, 1, 10)), np.zeros((1, 3, 1))),
        r"acceleration_noise has shape \(1, 3, 1\), expected \(1, 50, 1\)",
    ),
    "rewards plans": (
        lambda t: t.rewards(np.zeros((1, 3, 5, 1))),
        r"plans has shape \(1, 3, 5, 1\), expected \(K, 3, 51, 1\)",
    ),
    "evaluate": (lambda t: t.evaluate(3), "exploration must be an Exploration"),
    "evaluate without noise": (
        lambda t: t.evaluate(type("Half", (), {"weights": t.initial_weights[None]})()),
        r"^exploration must be an Exploration .*, got Half",
    ),
    "plans not finite": (
        lambda t: t.rewards(np.full((1, 3, t.n_steps, 1), np.nan)),
        r"^plans\[0, 0, 0, 0\] is nan",
    ),
    "noise not finite": (
        lambda t: t.rollouts(t.initial_weights, np.full((1, t.n_actions, 1), np.nan)),
        r"^acceleration_noise\[0, 0, 0\] is nan",
    ),
    "weights not finite": (
        lambda t: t.rollouts(np.full((1, 10), np.inf)),
        r"^weights\[0, 0\] is inf",
    ),
    "goals not finite": (lambda t: multi_dof_reaching_task(goals=[np.nan]), r"^goals\["),
    "n_basis": (lambda t: paper_reaching_task(n_basis=0), "n_basis must be an integer >= 1"),
    "goals": (
        lambda t: multi_dof_reaching_task(goals=[[1.0]]),
        r"goals has shape \(1, 1\), expected \(n_dofs,\)",
    ),
    "goal": (lambda t: via_point_task(goal=[np.nan, 1]), r"goal\[0\] is nan"),
    "start": (lambda t: multi_dof_reaching_task(duration=-1.0), "duration must be"),
    "features": (
        lambda t: EpisodicNAC(np.zeros((5, 3)), t.initial_weights, 1.0),
        r"features has shape \(5, 3\), expected \(n_actions, 10\)",
    ),
    "nac std": (
        lambda t: EpisodicNAC(t.policy_features, t.initial_weights, 0.0),
        "exploration_std must be a finite number > 0",
    ),
    "nac n_rollouts": (
        lambda t: EpisodicNAC(t.policy_features, t.initial_weights, 1.0, n_rollouts=1),
        "n_rollouts must be an integer >= 2",
    ),
    "nac step_size": (
        lambda t: EpisodicNAC(t.policy_features, t.initial_weights, 1.0, step_size=0),
        "step_size must be a finite number > 0",
    ),
    "nac decay": (
        lambda t: EpisodicNAC(t.policy_features, t.initial_weights, 1.0, decay=-1),
        "decay must be a finite number >= 0",
    ),
    "initial_weights": (
        lambda t: EpisodicNAC(t.policy_features, np.zeros((1, 1, 10)), 1.0),
        r"initial_weights has shape \(1, 1, 10\)",
    ),
    "initial_weights nan": (
        lambda t: PIBB([[np.nan, 0.0]], 1.0),
        r"^initial_weights\[0, 0\] is nan",
    ),
    "nac size": (
        lambda t: EpisodicNAC(np.zeros((2, 17_000)), np.zeros((1, 17_000)), 1.0),
        r"^a covariance over 17001 weights needs .*: "
        r"learn fewer weights \(fewer basis functions or DOFs\)$",
    ),
    "pibb n_rollouts": (lambda t: _pibb(t, n_rollouts=1), "n_rollouts must be an integer >= 2"),
    "pibb std": (lambda t: _pibb(t, std=-1.0), "exploration_std must be a finite number > 0"),
    "pibb decay": (lambda t: _pibb(t, decay=0.0), "decay must be a finite number > 0 and <= 1"),
    "pibb eliteness": (lambda t: _pibb(t, eliteness=0.0), "eliteness must be a finite number > 0"),
    "pibb covariance_rate": (
        lambda t: _pibb(t, covariance_rate=1.5),
        "covariance_rate must be a finite number >= 0 and <= 1",
    ),
    "pibb size": (lambda t: PIBB(np.zeros((1, 20_000)), 1.0), "a covariance over 20000 weights"),
    "cma size": (
        lambda t: CMAES(np.zeros((1, 20_000)), 1.0),
        "a covariance over 20000 weights",
    ),
    "cma n_rollouts": (
        lambda t: CMAES(t.initial_weights, 1.0, n_rollouts=1),
        "n_rollouts must be an integer >= 2",
    ),
    "cma std": (
        lambda t: CMAES(t.initial_weights, 0.0),
        "exploration_std must be a finite number > 0",
    ),
    "cma options": (
        lambda t: CMAES(t.initial_weights, 1.0, options=[1]),
        "options must be a dict of cma options, got list",
    ),
    "cma option": (
        lambda t: CMAES(t.initial_weights, 1.0, options={"nonsense": 1}),
        "options were refused by cma",
    ),
    "make std": (
        lambda t: make_method("pibb", t),
        r"make_method\('pibb', ...\) needs exploration_std",
    ),
    "optimise method": (lambda t: optimise(3, t, 10), "method must be a PolicySearch"),
    "optimise task": (lambda t: optimise(_pibb(t), 3, 10), "task must be a RewardTask"),
    "n_trials": (lambda t: optimise(_pibb(t), t, -1), "n_trials must be an integer >= 0"),
    "rewards nan": (
        lambda t: _told(_pibb(t), np.full(20, np.nan)),
        r"^rewards\[0\] is nan: .*; a failed roll-out needs a finite \(e.g. very low\) reward$",
    ),
    "rewards overflow": (
        lambda t: _told(_pibb(t), np.full((20, 3), 1e308)),
        "rewards overflow when summed",
    ),
    "returns": (
        lambda t: enac_gradient(np.zeros((3, 2)), np.zeros(2)),
        r"returns has shape \(2,\), expected \(3,\): one per row of scores",
    ),
    "scores": (lambda t: enac_gradient(np.zeros(3), np.zeros(3)), r"scores has shape \(3,\)"),
    "returns 2-D": (
        lambda t: reinforce_gradient(np.zeros((3, 2)), np.zeros((3, 1))),
        r"returns has shape \(3, 1\), expected 1 dimension",
    ),
}


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("case", BAD, ids=list(BAD))
def test_bad_inputs_name_the_argument(coarse, case):
    """Each refused input is named in the message (checked per case)."""
    call, message = BAD[case]
    with pytest.raises(DmpoptError, match=message):
        call(coarse)


def test_values_on_the_bounds_are_accepted(coarse):
    """The bounds are inclusive where the messages say so."""
    RewardTask(coarse.dmp, duration=0.02, dt=0.01)
    RewardTask(coarse.dmp, dt=0.01, via_points=(ViaPointReward(0.5, (0.5,), 0.0),), goal_weight=0.0)
    for rate in (0.0, 1.0):
        _pibb(coarse, decay=1.0, covariance_rate=rate)
    EpisodicNAC(coarse.policy_features, coarse.initial_weights, 1.0, n_rollouts=2, decay=0.0)
    CMAES(coarse.initial_weights, 1.0, n_rollouts=2)
    PIBB(np.zeros((1, 700)), 1.0)  # 8 p^2 bytes: 3.9 MB
    assert optimise(_pibb(coarse), coarse, 0).trials.tolist() == [0.0]


def _weighted_task(dmp, via_point):
    """A 0.5 s task at dt = 0.01 with every reward term weighted: goal 500, final velocity 2,
    acceleration 0.01, jerk 1e-6, and ``via_point`` at 0.2 s weighted 50."""
    return RewardTask(
        dmp,
        duration=0.5,
        dt=0.01,
        goal_weight=500.0,
        velocity_weight=2.0,
        acceleration_weight=0.01,
        jerk_weight=1e-6,
        via_points=(ViaPointReward(0.2, via_point, 50.0),),
    )


def test_per_step_rewards_with_jerk_and_via_point():
    """Per-step rewards written plainly: acceleration and jerk at their step, the via point at
    its sample, goal and velocity at the last; the exact optimum is the least-squares one."""
    task = _weighted_task(paper_reaching_task(dt=0.01).dmp, (0.3,))
    rng = np.random.default_rng(11)
    weights = 20 * rng.standard_normal((2, 1, task.n_basis))
    noise = rng.standard_normal((2, task.n_actions, 1))
    plans = task.rollouts(weights, noise)
    y, yd, ydd = plans[:, 0, :, 0], plans[:, 1, :, 0], plans[:, 2, :, 0]
    dt, n = 0.01, task.n_steps
    expected = np.zeros((2, n))
    for k in range(n - 1):
        jerk = (ydd[:, k + 1] - ydd[:, k]) / dt
        expected[:, k] = -0.01 * dt * ydd[:, k] ** 2 - 1e-6 * dt * jerk**2
    expected[:, 20] -= 50.0 * (y[:, 20] - 0.3) ** 2
    expected[:, -1] -= 500.0 * (y[:, -1] - 1.0) ** 2 + 2.0 * yd[:, -1] ** 2
    np.testing.assert_allclose(task.rewards(plans), expected, rtol=1e-12, atol=1e-12)

    def cost(w):
        return -task.deterministic_return(w[None])

    result = minimize(cost, np.zeros(task.n_basis), method="BFGS", options={"gtol": 1e-9})
    assert task.optimum_return == pytest.approx(-result.fun, rel=1e-6)
    np.testing.assert_allclose(
        task.optimal_weights[0], result.x, rtol=1e-3, atol=1e-3 * abs(result.x).max()
    )


def test_noisy_rollouts_of_several_dofs_are_plan_plus_h_eps():
    """Each DOF of each roll-out is the plan of its weights plus H @ eps of its own noise."""
    via = via_point_task(dt=0.01)
    rng = np.random.default_rng(12)
    weights = 10 * rng.standard_normal((3, 2, via.n_basis))
    noise = rng.standard_normal((3, via.n_actions, 2))
    plans = via.rollouts(weights, noise)
    response = via.noise_response
    for k in range(3):
        expected = via.plan.evaluate(weights[k]) + np.einsum("ist,td->isd", response, noise[k])
        np.testing.assert_allclose(plans[k], expected, rtol=1e-10, atol=1e-10)
    assert response.shape == (3, via.n_steps, via.n_actions)
    assert np.all(np.triu(response[0], 1) == 0.0)  # causal: no effect before the input


@pytest.mark.parametrize("shared", [False, True])
@pytest.mark.parametrize("noisy", [False, True])
def test_evaluate_gives_the_rewards_of_the_full_plans(shared, noisy):
    """evaluate() reads only the samples the reward needs; its rewards are the plain formula
    on the full plans Y = F + G W^T + H eps (H applied by einsum, not by the state-space
    recurrence of evaluate), for distinct weights and for roll-outs sharing one weight vector
    (action-space exploration)."""
    task = _weighted_task(via_point_task(dt=0.01).dmp, (0.3, 0.6))
    rng = np.random.default_rng(21)
    weights = 10 * rng.standard_normal((4, 2, task.n_basis))
    if shared:
        weights = np.broadcast_to(weights[0], weights.shape)
    noise = rng.standard_normal((4, task.n_actions, 2)) if noisy else None
    rewards = task.evaluate(Exploration(weights, noise))
    dt, n = 0.01, task.n_steps
    expected = np.zeros((4, n))
    for k in range(4):
        y, yd, ydd = task.plan.evaluate(weights[k])
        if noisy:
            y, yd, ydd = (y, yd, ydd) + np.einsum("ist,td->isd", task.noise_response, noise[k])
        jerk = np.diff(ydd, axis=0) / dt
        expected[k, :-1] = -0.01 * dt * np.sum(ydd[:-1] ** 2, 1) - 1e-6 * dt * np.sum(jerk**2, 1)
        expected[k, 20] -= 50.0 * np.sum((y[20] - [0.3, 0.6]) ** 2)
        expected[k, -1] -= 500.0 * np.sum((y[-1] - [1.0, 0.0]) ** 2) + 2.0 * np.sum(yd[-1] ** 2)
    # round-off of a sum over at most n = 51 inputs: about n ulps of the largest plan value,
    # far below 1e-9
    np.testing.assert_allclose(rewards, expected, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(task.returns(weights, noise), expected.sum(1), rtol=1e-9)


def test_pibb_weights_ignore_a_shift_of_the_returns_and_count_updates():
    """Two updates with returns near 1e6 and a spread of 0.5: the plain formula, no overflow."""
    start = np.array([[0.5, -1.0]])
    method = PIBB(start, 1.0, n_rollouts=4, seed=13)
    mean, covariance = start[0], np.eye(2)
    for update in range(2):
        samples = method.ask().weights.reshape(4, 2)
        returns = 1e6 + np.array([0.0, 0.5, 0.2, 0.4])
        method.tell(returns)
        mean, covariance = _pibb_expected(
            samples, returns, mean, covariance, 10.0, 0.98, 0.5, True, 1e-6
        )
        np.testing.assert_allclose(method.mean[0], mean, rtol=1e-9)
        np.testing.assert_allclose(method.covariance, covariance, rtol=1e-9)
    assert method.n_updates == 2 and method.n_trials == 8


def test_learning_curve_messages():
    """weights_at and trials_to name their argument."""
    curve = optimise(_pibb(paper_reaching_task(dt=0.01)), paper_reaching_task(dt=0.01), 20)
    with pytest.raises(InvalidInputError, match="^trials must be a finite number >= 0"):
        curve.weights_at(-1)
    with pytest.raises(InvalidInputError, match="^fraction must be a finite number"):
        curve.trials_to(np.nan)


def test_action_space_defaults_and_counters(coarse):
    """Defaults: 20 roll-outs, KL steps of 0.1, no decay, fixed exploration; counters add up."""
    method = EpisodicNAC(coarse.policy_features, coarse.initial_weights, 2.0, seed=0)
    assert (method.n_rollouts, method.step_size, method.step_rule) == (20, 0.1, "kl")
    assert (method.decay, method.learn_exploration, method.exploration_std) == (0.0, False, 2.0)
    cma = CMAES(coarse.initial_weights, 2.0, seed=0)
    for _ in range(3):
        method.tell(coarse.evaluate(method.ask()))
        cma.tell(coarse.evaluate(cma.ask()))
    assert (method.n_updates, method.n_trials, cma.n_updates, cma.n_trials) == (3, 60, 3, 60)


def test_zero_gradient_gives_no_step(coarse):
    """Equal returns: no direction, so the KL step leaves the weights.

    Before, the regression returned round-off (~1e-16) and the KL rule scaled it to a full
    step: weights moved by up to 0.42 in a random direction.
    """
    method = EpisodicNAC(coarse.policy_features, coarse.initial_weights, 2.0, seed=1)
    method.ask()
    method.tell(np.full(20, 3.0))
    np.testing.assert_array_equal(method.mean, coarse.initial_weights)


def test_fisher_of_log_sigma_counts_every_dof():
    """The log-sigma entry of F is 2 n_actions n_dofs (one Gaussian per step and DOF)."""
    method = EpisodicNAC(FEATURES, np.zeros((3, 2)), SIGMA, learn_exploration=True)
    fisher = method.fisher()
    assert fisher.shape == (7, 7) and fisher[-1, -1] == 2.0 * 5 * 3
    np.testing.assert_allclose(fisher[:-1, :-1], _plain_fisher(FEATURES, SIGMA, 3), rtol=1e-12)


@pytest.mark.parametrize("name", ["pibb", "cmaes"])
def test_tell_before_ask_is_refused(coarse, name):
    """Every method refuses rewards it did not ask for."""
    method = make_method(name, coarse, exploration_std=1.0)
    with pytest.raises(InvalidInputError, match=r"^tell\(\) called without a pending ask\(\)"):
        method.tell(np.zeros(20))


def test_batch_memory_bound_counts_steps_times_dofs():
    """K roll-outs of n_actions x n_dofs noise values are bounded (8 bytes each)."""
    with pytest.raises(
        DmpoptError, match=r"^1000000 roll-outs of 1000 values each needs .*: lower n_rollouts$"
    ):
        EpisodicNAC(np.ones((500, 10)), np.zeros((2, 10)), 1.0, n_rollouts=10**6)
    with pytest.raises(InvalidInputError, match=r"^features\[0, 0\] is nan"):
        EpisodicNAC(np.full((5, 2), np.nan), np.zeros((1, 2)), 1.0)


@pytest.mark.parametrize(
    "name, kind",
    [("enac", EpisodicNAC), ("ereinforce", EpisodicReinforce), ("pibb", PIBB), ("cmaes", CMAES)],
)
def test_make_method_builds_the_named_method_from_the_task(coarse, name, kind, capsys):
    """Each name gives its class, started at the task's weights, seeded, and silent."""
    first = make_method(name, coarse, seed=2, exploration_std=1.5)
    assert type(first) is kind
    np.testing.assert_array_equal(first.mean, coarse.initial_weights)
    a = first.ask()
    # one after the other: cma draws from numpy's global generator, seeded at construction
    b = make_method(name, coarse, seed=2, exploration_std=1.5).ask()
    np.testing.assert_array_equal(a.weights, b.weights)
    if a.acceleration_noise is not None:
        np.testing.assert_array_equal(a.acceleration_noise, b.acceleration_noise)
        assert first.exploration_std == 1.5
    first.tell(coarse.evaluate(a))
    assert capsys.readouterr().out == ""


def test_task_builders_pass_duration_step_and_delay_on():
    """The builders' duration, dt and delayed reach the task (not the RewardTask defaults)."""
    for build in (multi_dof_reaching_task, via_point_task):
        task = build(duration=0.3, dt=0.01, delayed=True)
        assert (task.duration, task.dt, task.delayed, task.n_steps) == (0.3, 0.01, True, 31)
    task = paper_reaching_task(dt=0.01, delayed=True)
    assert (task.duration, task.dt, task.delayed) == (0.5, 0.01, True)


def test_task_arrays_are_read_only(coarse):
    """The class docstring promises read-only values: H, the features and the optimum."""
    for values in (coarse.noise_response, coarse.policy_features, coarse.optimal_weights):
        with pytest.raises(ValueError, match="read-only"):
            values.flat[0] = 1.0


def test_memory_bounds_of_a_task_and_of_a_batch_count_their_bytes():
    """Bytes written plainly: H holds 3 n^2 values, the optimum's unit roll-outs
    (D N + 1) 3 n D, a batch K 3 n D, 8 bytes each; the messages state them in GiB."""
    from dmpopt.exceptions import ResourceLimitError

    small = paper_reaching_task(dt=0.01)
    dofs, n_basis, n = 10, 2000, 501
    wide = small.dmp.replace(
        weights=np.zeros((dofs, n_basis)),
        start=np.zeros(dofs),
        goal=np.ones(dofs),
        centres=np.linspace(0.0, 1.0, n_basis),
        widths=np.ones(n_basis),
    )
    needed = 8 * (dofs * n_basis + 1) * 3 * n * dofs / 1024**3
    with pytest.raises(
        ResourceLimitError,
        match=rf"^a task of 0.5 s with dt = 0.001 s \(501 steps\) needs about {needed:.3g} GiB;"
        r" .*: raise dt \(the paper uses 1 ms over 0.5 s\) or shorten the duration$",
    ):
        RewardTask(wide)
    six = multi_dof_reaching_task(dt=0.01, n_basis=2)
    k = 400_000
    needed = 8 * k * 3 * six.n_steps * 6 / 1024**3
    with pytest.raises(
        ResourceLimitError,
        match=rf"^plans of {k} roll-outs needs about {needed:.3g} GiB; .*: evaluate the batch in "
        "smaller chunks$",
    ):
        six.rollouts(np.zeros((k, 6, 2)))


def test_batch_and_covariance_bounds_are_eight_bytes_a_value(monkeypatch):
    """PI-BB with 10 weights and 10 roll-outs needs 8 * 10 * 10 bytes for a batch and as much
    for its covariance: a budget of exactly 800 bytes is enough, 799 is not."""
    from dmpopt import validation
    from dmpopt.exceptions import ResourceLimitError

    monkeypatch.setattr(validation, "MEMORY_BUDGET", 800.0)
    PIBB(np.zeros((2, 5)), 0.1, n_rollouts=10)
    monkeypatch.setattr(validation, "MEMORY_BUDGET", 799.0)
    with pytest.raises(ResourceLimitError, match="^10 roll-outs of 10 values each needs about"):
        PIBB(np.zeros((2, 5)), 0.1, n_rollouts=10)
    monkeypatch.setattr(validation, "MEMORY_BUDGET", 8.0 * 10 * 12)  # batches of 12 values
    with pytest.raises(ResourceLimitError, match="^a covariance over 12 weights needs about"):
        PIBB(np.zeros((2, 6)), 0.1, n_rollouts=10)


def test_task_basis_and_builder_checks():
    """The builders' DMP has the discrete basis of its own gains (distinct centres); a goal
    of the wrong shape and a zero duration are refused by name."""
    from dmpopt import basis

    task = paper_reaching_task(dt=0.01)
    centres, widths = basis.discrete_basis(10, task.dmp.gains[:4])
    np.testing.assert_array_equal(task.dmp.centres, centres)
    np.testing.assert_array_equal(task.dmp.widths, widths)
    assert np.unique(task.dmp.centres).size == 10
    with pytest.raises(ShapeError, match=r"^goal has shape \(1, 2\), expected \(2,\)"):
        via_point_task(goal=[[1.0, 0.0]])
    with pytest.raises(InvalidInputError, match=r"^goal\[0\] is nan"):
        via_point_task(goal=[np.nan, 0.0])
    with pytest.raises(InvalidInputError, match=r"^duration must be a finite number > 0, got 0"):
        multi_dof_reaching_task(duration=0.0)


def test_memory_bound_of_the_plan_grid_and_of_many_dofs():
    """The two terms of the task's estimate, each where it dominates: 3 n^2 (H) for a fine
    grid, (D N + 1) 3 n D (the optimum's unit roll-outs) for 100 DOFs of one basis each."""
    from dmpopt.exceptions import ResourceLimitError

    one = paper_reaching_task(dt=0.01).dmp
    n = 50_001
    with pytest.raises(ResourceLimitError, match=rf"needs about {8 * 3 * n**2 / 1024**3:.3g} GiB"):
        RewardTask(one, dt=0.5 / (n - 1))
    dofs, n = 100, 10_001
    many = one.replace(
        weights=np.zeros((dofs, 1)),
        start=np.zeros(dofs),
        goal=np.ones(dofs),
        centres=np.array([0.5]),
        widths=np.ones(1),
    )
    needed = 8 * (dofs + 1) * 3 * n * dofs / 1024**3
    assert needed > 8 * 3 * n**2 / 1024**3  # the second term dominates
    with pytest.raises(ResourceLimitError, match=rf"\(1e\+04 steps\) needs about {needed:.3g} GiB"):
        RewardTask(many, dt=0.5 / (n - 1))


def test_policy_features_are_the_command_derivative_at_each_state(coarse):
    """d mu_k / d w_i at the state of step k, by the symbolic output function with the weight
    raised by one (the command is affine in the weights): phi_i(x_k) / tau^2."""
    dmp = coarse.dmp
    step = symbolic.step_function(dmp.signature)
    output = symbolic.output_function(dmp.signature)
    parameters = dmp.parameters()
    state = np.zeros(dmp.signature.n_states)
    expected = []
    for _ in range(coarse.n_actions):
        base = float(output(state=state, **parameters)["acceleration"])
        row = []
        for i in range(coarse.n_basis):
            raised = dict(parameters, forcing_weights=np.eye(coarse.n_basis)[i][None])
            row.append(float(output(state=state, **raised)["acceleration"]) - base)
        expected.append(row)
        state = np.asarray(step(state=state, dt=coarse.dt, **parameters)["next_state"]).ravel()
    np.testing.assert_allclose(coarse.policy_features, expected, rtol=1e-9, atol=1e-12)


def test_via_point_at_the_horizon_scores_the_last_sample(coarse):
    """A via point at t = T is rewarded on the last sample (written plainly)."""
    task = RewardTask(coarse.dmp, dt=0.01, via_points=(ViaPointReward(0.5, (0.4,), 7.0),))
    plans = task.rollouts(np.ones((1, 1, 10)))
    y, yd = plans[0, 0, -1, 0], plans[0, 1, -1, 0]
    expected = -7.0 * (y - 0.4) ** 2 - 1000 * (y - 1.0) ** 2 - yd**2
    assert task.rewards(plans)[0, -1] == pytest.approx(expected, rel=1e-12)
    with pytest.raises(
        InvalidInputError,
        match=r"^via_points\[0\] must be a ViaPointReward, got int; a reward task scores "
        r"closeness: ViaPointReward\(time, position, weight\)$",
    ):
        RewardTask(coarse.dmp, dt=0.01, via_points=(1,))


def _one_update(cls, rule, scale, step_size=0.01):
    rng = np.random.default_rng(0)
    features = rng.normal(size=(20, 4))
    optimizer = cls(
        features, np.zeros((1, 4)), 0.5, n_rollouts=10, step_rule=rule, step_size=step_size, seed=1
    )
    noise = optimizer.ask().acceleration_noise[:, :, 0]
    optimizer.tell(-np.sum((noise - 1.0) ** 2, axis=1) * scale)
    return optimizer.mean


@pytest.mark.parametrize("cls", [EpisodicNAC, EpisodicReinforce])
def test_a_kl_step_does_not_depend_on_the_scale_of_the_returns(cls):
    """Both gradients are linear in the returns and the KL rule normalises the step, so
    returns times 2^990 (exact) give the same update bit for bit, and times 1e300 (each
    return rounded to 2^-53 relative, a perturbation the update's linear map carries over,
    amplified at most by the regression's condition number, below 1e3 here) to 1e-12; once
    the update became 0 silently (its curvature overflowed)."""
    reference = _one_update(cls, "kl", 1.0)
    assert np.all(reference != 0.0)
    np.testing.assert_array_equal(_one_update(cls, "kl", 2.0**990), reference)
    np.testing.assert_allclose(_one_update(cls, "kl", 1e300), reference, rtol=1e-12)
    scaled = _one_update(cls, "constant", 2.0**-20)  # a constant step scales with the returns
    np.testing.assert_array_equal(scaled * 2.0**20, _one_update(cls, "constant", 1.0))


def test_a_constant_step_beyond_the_float_range_is_refused():
    with pytest.raises(InvalidInputError) as error:
        _one_update(EpisodicNAC, "constant", 1e306, step_size=1e10)
    assert str(error.value).startswith("the update overflows: returns up to ")
    assert str(error.value).endswith(
        " times step_size = 1e+10 (step_rule='constant') exceed the float range; rescale the "
        "rewards or lower step_size"
    )


def _at_offset(array, offset, keep):
    """A copy of ``array`` starting ``offset`` bytes after a 64-byte boundary."""
    buffer = np.empty(array.nbytes + 128, np.uint8)
    keep.append(buffer)
    start = (-buffer.ctypes.data) % 64 + offset
    placed = np.frombuffer(buffer, np.float64, array.size, offset=start).reshape(array.shape)
    placed[...] = array
    assert placed.ctypes.data % 64 == offset
    return placed


def test_pibb_samples_do_not_depend_on_where_the_covariance_lies():
    """Bitwise the same PI-BB batch with the covariance at offsets 0-48 B of a 64 B line.

    Serial, worker and Ray runs must agree bit for bit (issue 30); a factorisation whose
    SIMD path followed the address of its input would break that here. The answer key is
    the batch with the covariance on the boundary; the draws are also checked against
    ``mean + z F`` with ``F^T F = C`` from an eigendecomposition, to the rounding of a
    backward-stable factorisation, ``|F^T F - C| <= c n eps |C|`` (Higham, Accuracy and
    Stability of Numerical Algorithms, 2002, Thm. 10.3; c = 10 here).
    """
    n, keep = 60, []  # 60 weights: the six-DOF task of the rl study
    root = np.random.default_rng(1).standard_normal((n, n))
    covariance = 100.0 * root @ root.T / n + 1e-4 * np.eye(n)
    batches = []
    for offset in (0, 16, 32, 48):
        method = PIBB(np.zeros((6, 10)), 10.0, seed=5)
        method.covariance = _at_offset(covariance, offset, keep)
        batches.append(method.ask().weights.reshape(20, n))
    for batch in batches[1:]:
        np.testing.assert_array_equal(batch.view(np.uint64), batches[0].view(np.uint64))
    values, vectors = np.linalg.eigh(covariance)
    factor = np.sqrt(values)[:, None] * vectors.T
    bound = 10 * n * np.finfo(float).eps * np.abs(covariance).max()
    assert np.abs(factor.T @ factor - covariance).max() <= bound
    # the draws are mean + z F for some F with F^T F = C: z = draws F^-1 has unit covariance
    z = batches[0] @ np.linalg.inv(factor)
    assert np.abs(z).max() < 6.0  # 1200 standard normals: P(|z| > 6) < 1200 * 2e-9


def test_cmaes_keeps_away_from_the_global_generator(coarse):
    """CMA-ES draws what ``cma`` draws after seeding NumPy's global generator, without it.

    Answer key: ``cma`` itself, seeded through the global generator (its documented
    behaviour). The dmpopt run is interleaved with draws from, and a reseed of, the global
    generator, and must neither see them nor change the user's global state.
    """
    cma = pytest.importorskip("cma")
    seed = int(np.random.default_rng(4).integers(1, 2**31 - 1))  # as CMAES derives it
    settings = {"popsize": 6, "seed": seed, "verbose": -9}
    reference = cma.CMAEvolutionStrategy(coarse.initial_weights.ravel(), 2.0, settings)
    expected = []
    for _ in range(3):
        batch = np.asarray(reference.ask())
        expected.append(batch)
        reference.tell(list(batch), list(np.arange(6.0)))
    np.random.seed(99)
    state = np.random.get_state()[1].copy()
    method = CMAES(coarse.initial_weights, 2.0, n_rollouts=6, seed=4)
    for batch in expected:
        np.testing.assert_array_equal(np.random.get_state()[1], state)
        drawn = method.ask().weights.reshape(6, -1)
        np.random.seed(7)  # someone else reseeds and draws between the batches
        np.random.standard_normal(5)
        state = np.random.get_state()[1].copy()
        np.testing.assert_array_equal(drawn.view(np.uint64), batch.view(np.uint64))
        method.tell(-np.arange(6.0))


def test_pibb_batches_and_updates_do_not_depend_on_blas_threads():
    """Bitwise the same PI-BB batches and updates with two BLAS threads as with one.

    The SVD of a 60 x 60 covariance rounds differently on two OpenBLAS threads (423 of
    1200 draws of ``multivariate_normal`` differed by up to 7e-15 on the 2-core machine),
    and PI-BB turns that into another learning curve. Answer key: the one-thread run.
    """
    threadpoolctl = pytest.importorskip("threadpoolctl")
    n = 60
    root = np.random.default_rng(1).standard_normal((n, n))
    covariance = 100.0 * root @ root.T / n + 1e-4 * np.eye(n)
    runs = []
    for threads in (1, 2):
        with threadpoolctl.threadpool_limits(limits=threads, user_api="blas"):
            method = PIBB(np.zeros((6, 10)), 10.0, seed=5)
            method.covariance = covariance.copy()
            draws = []
            for _ in range(3):
                batch = method.ask().weights.reshape(20, n)
                method.tell(-np.sum(batch**2, axis=1))
                draws.append(np.concatenate([batch.ravel(), method.covariance.ravel()]))
            runs.append(np.concatenate(draws))
    np.testing.assert_array_equal(runs[1].view(np.uint64), runs[0].view(np.uint64))


def test_one_blas_thread_is_set_once_for_nested_entries_and_restored():
    """``ask``/``tell`` inside ``learn`` run on one BLAS thread without setting it again,
    and the caller's thread count comes back when the outermost entry ends.

    Answer key: threadpoolctl's own report of the BLAS libraries' thread counts.
    """
    threadpoolctl = pytest.importorskip("threadpoolctl")
    from dmpopt.learning import policy_search

    def counts():
        return [
            info["num_threads"]
            for info in threadpoolctl.threadpool_info()
            if info["user_api"] == "blas"
        ]

    guard = policy_search._one_blas_thread
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        before = counts()
        with guard:
            limiter = guard._limiter
            with guard:
                assert guard._limiter is limiter  # nested: not set again
                assert all(n == 1 for n in counts())
            assert all(n == 1 for n in counts())  # the inner exit keeps the limit
        assert counts() == before
        assert guard._depth == 0 and guard._limiter is None


def _python_rounds(method, task, n_updates):
    """Answer key of the compiled loop: ask, task.evaluate, tell, written out in Python."""
    means = []
    for _ in range(n_updates):
        exploration = method.ask()
        method.tell(task.evaluate(exploration))
        means.append(method.mean)
    return np.stack(means)


@pytest.mark.parametrize(
    "name, options, builder",
    [
        ("enac", {"step_rule": "kl", "decay": 0.05, "step_size": 10.0}, paper_reaching_task),
        ("enac", {"step_rule": "constant", "step_size": 20.0}, via_point_task),
        ("ereinforce", {"step_rule": "constant", "step_size": 40.0}, paper_reaching_task),
        ("ereinforce", {"step_rule": "kl", "step_size": 3.0}, via_point_task),
        ("enac", {"step_size": 1.0, "learn_exploration": True}, paper_reaching_task),
        ("enac", {"step_size": 10.0}, lambda: paper_reaching_task(delayed=True, jerk_weight=1e-5)),
    ],
)
def test_compiled_learning_loop_is_the_python_rounds_bit_for_bit(name, options, builder):
    """learn() runs ask/evaluate/tell in one compiled loop: the same normal draws, rewards and
    updates, so the same bits as the rounds in Python (and the generator ends in the same
    state); a one-line slip (a draw order, a missed decay, a stale sigma) breaks equality."""
    task = builder()
    n_rollouts = max(20, task.n_dofs * task.n_basis + 2)
    compiled, python = (
        make_method(name, task, seed=4, exploration_std=10.0, n_rollouts=n_rollouts, **options)
        for _ in range(2)
    )
    means = np.stack(compiled.learn(task, 12))
    np.testing.assert_array_equal(means, _python_rounds(python, task, 12))
    assert compiled.log_std == python.log_std and compiled.n_updates == python.n_updates == 12
    assert compiled.n_trials == python.n_trials == 12 * n_rollouts
    np.testing.assert_array_equal(compiled.rng.standard_normal(3), python.rng.standard_normal(3))


def test_compiled_learning_loop_refuses_an_overflowing_update_like_tell():
    """The compiled loop stops where tell would raise, with tell's message and the updates
    done so far kept."""
    task = paper_reaching_task()
    compiled, python = (
        make_method(
            "enac", task, seed=0, exploration_std=10.0, step_rule="constant", step_size=1e308
        )
        for _ in range(2)
    )
    with pytest.raises(InvalidInputError) as expected:
        _python_rounds(python, task, 5)
    with pytest.raises(InvalidInputError) as error:
        compiled.learn(task, 5)
    assert str(error.value) == str(expected.value)
    assert str(error.value).startswith("the update overflows")
    assert compiled.n_updates == python.n_updates


def test_compiled_six_dof_enac_does_not_depend_on_blas_threads():
    """The compiled loop's regression (62 x 61, LAPACK gelsd through SciPy's OpenBLAS) gives
    the same bits with two BLAS threads as with one, like PI-BB's pinned linear algebra.
    Answer key: the one-thread run."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    six = multi_dof_reaching_task()
    runs = []
    for threads in (1, 2):
        with threadpoolctl.threadpool_limits(limits=threads, user_api="blas"):
            method = make_method("enac", six, seed=1, exploration_std=10.0, n_rollouts=62)
            runs.append(np.stack(method.learn(six, 10)))
    np.testing.assert_array_equal(runs[1].view(np.uint64), runs[0].view(np.uint64))


def test_per_step_rewards_of_two_dofs_and_two_via_points():
    """As test_per_step_rewards_with_jerk_and_via_point on 2 DOFs with via points at 0.1 s
    and 0.3 s: each term summed over the DOFs (squared distances and norms)."""
    base = via_point_task(dt=0.01)
    task = RewardTask(
        base.dmp,
        duration=0.5,
        dt=0.01,
        goal_weight=500.0,
        velocity_weight=2.0,
        acceleration_weight=0.01,
        via_points=(ViaPointReward(0.1, (0.3, 0.6), 50.0), ViaPointReward(0.3, (0.1, -0.2), 7.0)),
    )
    rng = np.random.default_rng(13)
    plans = task.rollouts(20 * rng.standard_normal((2, 2, task.n_basis)))
    y, yd, ydd = plans[:, 0], plans[:, 1], plans[:, 2]  # (K, n_steps, 2)
    goal = np.asarray(base.dmp.goal)
    expected = np.zeros((2, task.n_steps))
    expected[:, :-1] = -0.01 * 0.01 * np.sum(ydd[:, :-1] ** 2, axis=2)
    expected[:, 10] -= 50.0 * np.sum((y[:, 10] - [0.3, 0.6]) ** 2, axis=1)
    expected[:, 30] -= 7.0 * np.sum((y[:, 30] - [0.1, -0.2]) ** 2, axis=1)
    expected[:, -1] -= 500.0 * np.sum((y[:, -1] - goal) ** 2, axis=1)
    expected[:, -1] -= 2.0 * np.sum(yd[:, -1] ** 2, axis=1)
    np.testing.assert_allclose(task.rewards(plans), expected, rtol=1e-12, atol=1e-12)


def test_policy_features_scale_as_one_over_tau_squared():
    """d mu_k / d w_i = phi_i(x_k) / tau^2: a DMP twice as slow sampled at twice the step has
    the same phases, so its policy features are a quarter of the first's (a power of two:
    exactly); both tasks keep them and the noise response read-only (shared arrays)."""
    fast = RewardTask(paper_reaching_task(dt=0.01).dmp, duration=0.5, dt=0.01)
    slow = RewardTask(fast.dmp.with_tau(2.0 * fast.dmp.tau), duration=1.0, dt=0.02)
    assert fast.n_steps == slow.n_steps
    np.testing.assert_array_equal(slow.policy_features, fast.policy_features / 4.0)
    for array in (fast.policy_features, fast.noise_response):
        assert not array.flags.writeable


def test_a_via_point_position_that_is_not_numbers_is_named():
    dmp = via_point_task(dt=0.01).dmp
    with pytest.raises(InvalidInputError, match=r"^via_points\[0\]\.position"):
        RewardTask(dmp, dt=0.01, via_points=(ViaPointReward(0.1, ("a", "b")),))
