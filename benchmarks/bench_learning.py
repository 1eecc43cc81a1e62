"""CPU time of batched roll-outs and of the updates of each method, in thread time.

Run: ``python benchmarks/bench_learning.py``. Not collected by pytest. Times are thread CPU
(``time.thread_time``), the best of five repeats, so that other processes on a shared machine
inflate them less than wall time; state the load beside them.
"""

import time

import numpy as np

from dmpopt.learning import (
    PolicySearch,
    make_method,
    multi_dof_reaching_task,
    paper_reaching_task,
)
from dmpopt.learning.normals import fill_standard_normal, generator_state
from dmpopt.learning.policy_search import _enac_solution, _scores
from dmpopt.learning.rewards import _plan_samples, _reward_kernel, _row_sums

OPTIONS = {
    "enac": {"exploration_std": 10.0, "step_size": 10.0},
    "ereinforce": {"exploration_std": 10.0, "step_size": 10.0},
    "pibb": {"exploration_std": 20.0},
    "cmaes": {"exploration_std": 20.0},
}
N_UPDATES = 50


def _per_call(function, repeats=50):
    """Best of five: CPU seconds per call."""
    function()
    best = np.inf
    for _ in range(5):
        start = time.thread_time()
        for _ in range(repeats):
            function()
        best = min(best, (time.thread_time() - start) / repeats)
    return best


def loop_stages(task, label: str, n_rollouts: int) -> None:
    """Thread CPU of each stage of one update of the compiled eNAC loop (``learn``)."""
    arrays = task.reward_arrays()
    shape = (n_rollouts, task.n_actions, task.n_dofs)
    rng = np.random.default_rng(0)
    words = generator_state(rng)
    noise = 10.0 * rng.standard_normal(shape)
    weights = np.ascontiguousarray(task.initial_weights[None])
    plan = _plan_samples(weights, *arrays[:6])
    rewards = np.zeros((n_rollouts, task.n_steps))

    def reward():
        rewards[:] = 0.0
        _reward_kernel(*plan, noise, *arrays[6:], rewards)

    reward()
    returns = _row_sums(rewards) / 1e3
    scores = _scores(noise, task.policy_features, 100.0, False)
    stages = {
        "normals (NumPy)": lambda: rng.standard_normal(shape),
        "normals (compiled)": lambda: fill_standard_normal(words, noise),
        "shared plan": lambda: _plan_samples(weights, *arrays[:6]),
        "rewards": reward,
        "scores": lambda: _scores(noise, task.policy_features, 100.0, False),
        "eNAC solve": lambda: _enac_solution(scores, returns),
    }
    times = ", ".join(f"{name} {1e6 * _per_call(f):.0f}" for name, f in stages.items())
    print(f"{label}, {n_rollouts} roll-outs, one update's stages [us]: {times}")


def main():
    start = time.thread_time()
    task = paper_reaching_task()
    seconds = time.thread_time() - start
    print(f"paper task build (response matrices, exact optimum): {seconds:.3f} s")
    start = time.thread_time()
    six = multi_dof_reaching_task()
    print(f"6-DOF task build: {time.thread_time() - start:.3f} s")
    rng = np.random.default_rng(0)
    for t, name in ((task, "1 DOF"), (six, "6 DOF")):
        for k in (20, 100):
            weights = rng.standard_normal((k, t.n_dofs, t.n_basis))
            noise = rng.standard_normal((k, t.n_actions, t.n_dofs))
            seconds = _per_call(lambda: t.returns(weights, noise))
            print(f"{name}: {k} noisy roll-outs + returns: {1e3 * seconds:.3f} ms")
            seconds = _per_call(lambda: t.returns(weights))
            print(f"{name}: {k} noise-free plans + returns (PI-BB, CMA-ES): {1e3 * seconds:.3f} ms")
    loop_stages(task, "1 DOF", 20)
    loop_stages(six, "6 DOF", 62)
    cma_split(task, "1 DOF", 10)
    cma_split(six, "6 DOF", 16)
    for t, label in ((task, "1 DOF"), (six, "6 DOF")):
        for name, options in OPTIONS.items():
            n_rollouts = max(20, t.n_dofs * t.n_basis + 2) if name in ("enac", "ereinforce") else 20
            method = make_method(name, t, seed=0, n_rollouts=n_rollouts, **options)
            rounds = _per_call(lambda: PolicySearch.learn(method, t, N_UPDATES), 1) / N_UPDATES
            learned = _per_call(lambda: method.learn(t, N_UPDATES), 1) / N_UPDATES
            print(
                f"{label} {name}: one update of {n_rollouts} roll-outs: ask/evaluate/tell in "
                f"Python {1e3 * rounds:.3f} ms, learn() {1e3 * learned:.3f} ms"
            )


def cma_split(task, label: str, n_rollouts: int) -> None:
    """Thread CPU of one CMA-ES update: ``cma``'s ask and tell, and the rewards between them."""
    method = make_method("cmaes", task, seed=0, n_rollouts=n_rollouts, exploration_std=20.0)
    method.learn(task, 5)
    spent = {"ask": 0.0, "rewards": 0.0, "tell": 0.0}
    n_updates = 100
    for _ in range(n_updates):
        start = time.thread_time()
        exploration = method.ask()
        asked = time.thread_time()
        rewards = task.evaluate(exploration)
        evaluated = time.thread_time()
        method.tell(rewards)
        spent["ask"] += asked - start
        spent["rewards"] += evaluated - asked
        spent["tell"] += time.thread_time() - evaluated
    times = ", ".join(f"{name} {1e6 * value / n_updates:.0f}" for name, value in spent.items())
    print(f"{label} cmaes, {n_rollouts} roll-outs, one update [us]: {times}")


if __name__ == "__main__":
    main()
