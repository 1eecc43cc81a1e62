"""Measured differences between the library and the answer keys of tests/test_answer_keys.py.

For each case and form, prints the largest error of positions, velocities and accelerations
relative to the key's peak at three steps. Halving the step divides RK4's error by about 16:
a ratio near 16 shows that the difference is the library's discretisation, not a mismatch
of equations (which would not shrink). The dt = 1 ms row is the MEASURED table of the tests.
Then the constant C of error = C (dt / tau)^4 over 40 random discrete systems (the
hypothesis test's bound).

    python benchmarks/answer_key_errors.py
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))

from test_answer_keys import (  # noqa: E402
    FORMS,
    coupling_errors,
    discrete_case,
    goal_change_errors,
    grid,
    initial_state,
    integrate,
    phase_reset_errors,
    plan_of,
    relative_error,
    rollout_errors,
)

CASES = {
    "rollout": (FORMS, lambda form, dt: rollout_errors(form, dt)[0]),
    "stepper": (FORMS, lambda form, dt: rollout_errors(form, dt)[1]),
    "coupling": (FORMS, coupling_errors),
    "goal": (["velocity", "acceleration"], goal_change_errors),
    "reset": (["phase", "energy"], lambda form, dt: phase_reset_errors(form, dt)[1]),
}


def random_discrete_constants(n_draws=40, dt=2e-3):
    rng = np.random.default_rng(123)
    worst = np.zeros(3)
    for i in range(n_draws):
        seed, tau, scale = int(rng.integers(0, 2**16)), rng.uniform(0.3, 2.0), rng.uniform(1, 50)
        dmp, eq = discrete_case(("velocity", "acceleration")[i % 2], seed, 6, tau, scale)
        times = grid(1.5 * tau, dt)
        _, key = integrate(eq, initial_state(eq, dmp.start, 0.0, np.zeros(2)), times)
        errors = relative_error(plan_of(dmp.rollout(times[-1], dt)), key)
        worst = np.maximum(worst, errors / (dt / tau) ** 4)
    return worst


def main():
    np.set_printoptions(precision=2)
    for name, (forms, measure) in CASES.items():
        for form in forms:
            errors = {dt: measure(form, dt) for dt in (2e-3, 1e-3, 5e-4)}
            ratio = errors[1e-3] / errors[5e-4]
            print(
                f"{name:8s} {form:12s} dt=1ms {errors[1e-3]}  2ms {errors[2e-3]}  "
                f"0.5ms {errors[5e-4]}  ratio 1ms/0.5ms {ratio}"
            )
    print("random discrete systems, worst C:", random_discrete_constants())


if __name__ == "__main__":
    main()
