"""Measured differences between the library and the answer keys of tests/core/test_answer_keys.py.

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

from dmpopt import DiscreteDMP

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))

from test_answer_keys import (  # noqa: E402
    FORMS,
    affine_errors,
    coupling_errors,
    discrete_case,
    goal_change_errors,
    grid,
    initial_state,
    integrate,
    kick_errors,
    paper_kernel_errors,
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
    "affine": (FORMS, affine_errors),
    "paper": (["phase", "energy"], paper_kernel_errors),
    "kick": (["velocity", "acceleration"], kick_errors),
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


def unforced_constants(n_draws=60):
    """Worst error / ((|e0| + |e0'| / w) (w dt)^4 w^k) of the unforced velocity form, and
    worst error / (|e0| w^k) of the unforced acceleration form (first 30 draws)."""
    rng = np.random.default_rng(0)
    worst_velocity, worst_acceleration = np.zeros(3), np.zeros(3)
    for i in range(n_draws):
        tau, start, goal = rng.uniform(0.2, 3), rng.uniform(-5, 5), rng.uniform(-5, 5)
        v0, k = rng.uniform(-3, 3), rng.uniform(5, 60)
        v0 = 0.0 if i % 3 == 0 else v0
        goal = start if i % 3 == 1 else goal
        dt, e0 = 1e-3 * tau, start - goal
        dmp = DiscreteDMP(
            np.zeros((1, 3)), start, goal, tau, np.zeros(3), np.ones(3),
            goal_scaling="translation", alpha_z=k,
        )  # fmt: skip
        plan = plan_of(dmp.rollout(2.0 * tau, dt, start_velocity=v0))[:, :, 0]
        w = k / (2 * tau)
        t = np.arange(plan.shape[1]) * dt
        e = (e0 + (v0 + w * e0) * t) * np.exp(-w * t)
        de = (v0 - w * (v0 + w * e0) * t) * np.exp(-w * t)
        key = np.array([e + goal, de, -2 * w * de - w**2 * e])
        scale = (abs(e0) + abs(v0) / w) * (w * dt) ** 4 * w ** np.arange(3)
        worst_velocity = np.maximum(worst_velocity, np.abs(plan - key).max(axis=1) / scale)
        if i < 30 and goal != start:
            dmp = DiscreteDMP(
                np.zeros((1, 3)), start, goal, tau, np.zeros(3), np.ones(3),
                form="acceleration", goal_scaling="translation",
            )  # fmt: skip
            plan = plan_of(dmp.rollout(2.0 * tau, dt))[:, :, 0]
            w = 12.5 / tau
            decay = np.exp(-w * t)
            key = e0 * np.array(
                [(1 + w * t + (w * t) ** 2 / 2), -(w**3) * t**2 / 2, -(w**3) * (t - w * t**2 / 2)]
            ) * decay + np.array([[goal], [0], [0]])
            scale = abs(e0) * w ** np.arange(3)
            worst_acceleration = np.maximum(
                worst_acceleration, np.abs(plan - key).max(axis=1) / scale
            )
    return worst_velocity, worst_acceleration


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
    print("unforced velocity form C, acceleration form relative:", *unforced_constants())


if __name__ == "__main__":
    main()
