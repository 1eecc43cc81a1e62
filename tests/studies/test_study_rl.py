"""The rl study's own pieces: rescaled tasks, the invariance they probe, the bell check."""

import numpy as np
import pytest
from dmpopt_studies import rl
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.learning import Exploration, make_method, optimise, paper_reaching_task


@pytest.fixture(scope="module")
def task():
    return paper_reaching_task()


def _scale(task, condition=2170.0):
    return np.array(rl.column_scaling(task.policy_features, condition))


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_scaled_task_gives_the_plans_of_the_original_weights(seed):
    """Answer key: the original task's returns at ``scale * v`` (same noise)."""
    base = rl._base_task("paper")
    scale = np.random.default_rng(seed).uniform(0.05, 3.0, base.n_basis)
    scaled = rl.ScaledTask(base, scale)
    rng = np.random.default_rng(seed + 1)
    weights = rng.normal(0, 50, (4, 1, base.n_basis))
    noise = rng.normal(0, 10, (4, base.n_actions, 1))
    expected = base.returns(weights * scale, noise)
    got = scaled.evaluate(Exploration(weights, noise)).sum(axis=1)
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    np.testing.assert_allclose(scaled.returns(weights), base.returns(weights * scale), rtol=1e-12)
    np.testing.assert_allclose(scaled.policy_features, base.policy_features * scale)


def test_column_scaling_reaches_the_condition_number_asked(task):
    """Answer key: numpy's condition number of D Phi^T Phi D, written out here."""
    gram = task.policy_features.T @ task.policy_features
    for target in (500.0, 2170.0, 1e4):
        scale = _scale(task, target)
        assert np.linalg.cond(np.diag(scale) @ gram @ np.diag(scale)) == pytest.approx(target)
        assert scale[0] == 1.0 and np.all(np.diff(scale) < 0)  # later columns shrink
    assert rl.fisher_condition(task.policy_features) == pytest.approx(np.linalg.cond(gram))
    equal = task.policy_features * rl.equilibrated_scaling(task.policy_features)
    norms = np.linalg.norm(equal, axis=0)
    np.testing.assert_allclose(norms, norms[0])


def _final_weights(task, name, seed=3, **options):
    method = make_method(
        name, task, seed=seed, exploration_std=10.0, n_rollouts=20, step_rule="constant", **options
    )
    return optimise(method, task, 400).final_weights


def test_natural_gradient_is_invariant_to_the_feature_scaling(task):
    """Answer key: the natural gradient is covariant, so eNAC on the rescaled task follows the
    same plans (weights ``D v`` equal the unscaled run's) with the same noise; eREINFORCE's
    vanilla gradient moves the original weights by ``D^2 g`` and does not."""
    scale = _scale(task)
    scaled = rl.ScaledTask(task, scale)
    plain = _final_weights(task, "enac", step_size=40.0)
    rescaled = _final_weights(scaled, "enac", step_size=40.0) * scale
    np.testing.assert_allclose(rescaled, plain, rtol=1e-6, atol=1e-6 * np.abs(plain).max())
    plain = _final_weights(task, "ereinforce", step_size=40.0)
    rescaled = _final_weights(scaled, "ereinforce", step_size=40.0) * scale
    assert np.abs(rescaled - plain).max() > 0.05 * np.abs(plain).max()


def _minimum_jerk(n=501):
    """Velocity and position of the minimum-jerk reach 0 -> 1 in unit time (a bell)."""
    s = np.linspace(0, 1, n)
    return 30 * s**2 * (1 - s) ** 2, 10 * s**3 - 15 * s**4 + 6 * s**5


def test_bell_check_accepts_a_bell_and_rejects_each_failure():
    """Answer keys written plainly: the minimum-jerk profile passes; a second hump, a
    reversal, a profile ending at speed and one falling short each fail."""
    velocity, position = _minimum_jerk()
    check = rl.bell_check(velocity, position, 0.0, 1.0)
    assert check["passed"] and check["end_speed"] < 1e-12 and check["goal_error"] < 1e-12
    s = np.linspace(0, 1, velocity.size)
    hump = velocity + 0.4 * np.exp(-(((s - 0.85) / 0.03) ** 2))
    assert not rl.bell_check(hump, position, 0.0, 1.0)["passed"]
    assert rl.bell_check(hump, position, 0.0, 1.0)["rebound"] > 0.01
    reversing = velocity - 0.1 * s**8  # still falling after the peak, but goes backwards
    assert rl.bell_check(reversing, position, 0.0, 1.0)["rebound"] == 0.0
    assert rl.bell_check(reversing, position, 0.0, 1.0)["reversal"] == pytest.approx(
        0.1 / reversing.max()
    )
    assert not rl.bell_check(reversing, position, 0.0, 1.0)["passed"]
    moving = velocity + 0.2 * s
    assert rl.bell_check(moving, position, 0.0, 1.0)["end_speed"] == pytest.approx(
        0.2 / moving.max()
    )
    assert not rl.bell_check(moving, position, 0.0, 1.0)["passed"]
    assert not rl.bell_check(velocity, 0.97 * position, 0.0, 1.0)["passed"]
    assert not rl.bell_check(velocity, position, 0.0, 1.1)["passed"]  # another goal
    assert not rl.bell_check(s, s**2 / 2, 0.0, 0.5)["passed"]  # peak at the end


def test_bell_check_fails_the_unforced_plan_and_passes_the_optimum(task):
    """``w = 0`` is bell-like but ends still moving and 5 % short of the goal."""
    start = rl._bell_of(task, task.initial_weights)
    assert not start["passed"]
    assert start["goal_error"] == pytest.approx(0.05, abs=1e-3)  # 95 % converged by design
    assert rl._bell_of(task, task.optimal_weights)["passed"]


def test_ratio_is_a_lower_bound_when_ereinforce_misses_the_fraction():
    """budget / eNAC's trials when eREINFORCE's median is missing; None without eNAC's."""
    metrics = {
        "ereinforce": {"trials_to_99": {"median": None}, "trials_to_95": {"median": 300.0}},
        "enac": {"trials_to_99": {"median": 1000.0}, "trials_to_95": {"median": 100.0}},
    }
    assert rl._ratio(metrics, "ereinforce", "enac", "trials_to_99", 3000) == (3.0, True)
    assert rl._ratio(metrics, "ereinforce", "enac", "trials_to_95", 3000) == (3.0, False)
    metrics["enac"]["trials_to_95"]["median"] = None
    assert rl._ratio(metrics, "ereinforce", "enac", "trials_to_95", 3000) == (None, False)


class _Curve:
    def __init__(self, t95, t99, final):
        self.t, self.improvement = {0.95: t95, 0.99: t99}, np.array([0.0, final])

    def trials_to(self, fraction):
        return self.t[fraction]


def test_tuning_prefers_99_percent_and_reports_the_edge():
    """Fewest trials to 99 % wins over fewer to 95 %; the best at an end is an edge."""
    tried = {
        1.0: [_Curve(100, np.inf, 0.98)],
        2.0: [_Curve(300, 900, 0.995)],
        4.0: [_Curve(200, 1200, 0.995)],
    }
    assert rl._best(tried) == (2.0, None)
    tried[8.0] = [_Curve(200, 800, 0.995)]
    assert rl._best(tried) == (8.0, "upper")
    tried[0.5] = [None]  # diverged
    assert rl._best({0.5: [None], 1.0: [_Curve(np.inf, np.inf, 0.5)]}) == (1.0, "upper")


@pytest.mark.slow
def test_results_do_not_depend_on_the_runner():
    """Two local processes return the serial run's curves, in the order of the inputs."""
    from dmpopt.parallel import Runner, map_runs

    options = rl._options("enac", 40.0, rl.EXPLORATION_STD, rl.BATCH, 10)
    jobs = [(("paper", None), "enac", options, seed, 200) for seed in (0, 1, 2)]
    serial = map_runs(rl.learn, jobs, Runner(1))
    parallel = map_runs(rl.learn, jobs, Runner(2))
    for a, b in zip(serial, parallel):
        np.testing.assert_array_equal(a.weights, b.weights)


def test_compiled_loop_on_a_scaled_task_follows_its_python_rounds():
    """Answer key: ask, ScaledTask.evaluate (the original task at ``scale * v``), tell, in
    Python. The compiled loop reads the rows ``G D`` instead: the same plans up to the
    rounding of ``(D v) G`` against ``v (D G)`` (a few ulps), which ten eNAC updates carry
    over amplified by the regression's condition number (below 1e3): far below 1e-9."""
    base = rl._base_task("paper")
    scaled = rl.ScaledTask(base, rl.column_scaling(base.policy_features, 2170.0))
    compiled, python = (
        make_method("enac", scaled, seed=2, exploration_std=10.0, n_rollouts=20, step_size=10.0)
        for _ in range(2)
    )
    means = np.stack(compiled.learn(scaled, 10))
    expected = []
    for _ in range(10):
        python.tell(scaled.evaluate(python.ask()))
        expected.append(python.mean)
    np.testing.assert_allclose(
        means, np.stack(expected), rtol=1e-9, atol=1e-9 * np.abs(means).max()
    )
