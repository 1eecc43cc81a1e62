"""Timing of batched roll-outs and of one ask/evaluate/tell update per method.

Run: ``python benchmarks/bench_learning.py``. Not collected by pytest.
"""

import time

import numpy as np

from dmpopt.learning import make_method, multi_dof_reaching_task, paper_reaching_task

OPTIONS = {
    "enac": {"exploration_std": 10.0, "step_size": 10.0},
    "ereinforce": {"exploration_std": 10.0, "step_size": 10.0},
    "pibb": {"exploration_std": 20.0},
    "cmaes": {"exploration_std": 20.0},
}


def _per_call(function, repeats=50):
    function()
    start = time.perf_counter()
    for _ in range(repeats):
        function()
    return (time.perf_counter() - start) / repeats


def main():
    start = time.perf_counter()
    task = paper_reaching_task()
    seconds = time.perf_counter() - start
    print(f"paper task build (response matrices, exact optimum): {seconds:.3f} s")
    start = time.perf_counter()
    six = multi_dof_reaching_task()
    print(f"6-DOF task build: {time.perf_counter() - start:.3f} s")
    rng = np.random.default_rng(0)
    for t, name in ((task, "1 DOF"), (six, "6 DOF")):
        for k in (20, 100):
            weights = rng.standard_normal((k, t.n_dofs, t.n_basis))
            noise = rng.standard_normal((k, t.n_actions, t.n_dofs))
            seconds = _per_call(lambda: t.returns(weights, noise))
            print(f"{name}: {k} noisy roll-outs + returns: {1e3 * seconds:.2f} ms")
    for name, options in OPTIONS.items():
        method = make_method(name, task, seed=0, **options)
        seconds = _per_call(lambda: method.tell(task.evaluate(method.ask())))
        print(f"{name}: one update of 20 roll-outs: {1e3 * seconds:.2f} ms")


if __name__ == "__main__":
    main()
