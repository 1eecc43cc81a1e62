"""Online stepping: equals the rollout, follows online changes, coupling, phase reset."""

import numpy as np
import pytest
from problems import random_discrete, random_rhythmic

from dmpopt import InvalidInputError, ShapeError, Stepper


def _run(stepper, n, **kwargs):
    return np.array([stepper.position] + [stepper.step(**kwargs)[0] for _ in range(n)])


def _run_all(stepper, n):
    """Positions, velocities and accelerations of the start and ``n`` steps, (3, n + 1, D)."""
    first = (stepper.position, stepper.velocity, stepper.acceleration)
    return np.array([first, *(stepper.step() for _ in range(n))]).transpose(1, 0, 2)


def _assert_equal_to_rounding(plan, stepped):
    """The rollout (response matrices) and the stepper (the CasADi step of the whole state)
    take the same RK4 steps, their sums in another order: each step may differ by a few (4)
    rounding errors of the largest value, so after n steps by at most 4 n eps of it."""
    bound = 4 * plan.n_steps * np.finfo(float).eps
    for expected, got in zip(stepped, (plan.positions, plan.velocities, plan.accelerations)):
        np.testing.assert_allclose(got, expected, rtol=0, atol=bound * np.abs(expected).max())


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_stepper_equals_rollout(form):
    """Over the default plan (its settling time): positions, velocities, accelerations."""
    dmp = random_discrete(seed=1, form=form)
    plan = dmp.rollout()
    _assert_equal_to_rounding(plan, _run_all(dmp.stepper(0.001), plan.n_steps - 1))


@pytest.mark.parametrize("form", ["phase", "energy"])
def test_rhythmic_stepper_equals_rollout(form):
    """Over the default plan (three periods, 2828 steps): positions, velocities, accelerations."""
    dmp = random_rhythmic(seed=2, form=form)
    plan = dmp.rollout()
    _assert_equal_to_rounding(plan, _run_all(dmp.stepper(0.001), plan.n_steps - 1))


@pytest.mark.parametrize("form", ["velocity", "acceleration"])
def test_goal_change_mid_run_converges_to_new_goal(form):
    dmp = random_discrete(seed=3, form=form)
    stepper = dmp.stepper(0.001)
    _run(stepper, 100)
    new_goal = dmp.goal + np.array([1.0, -2.0])
    stepper.set_goal(new_goal)
    final = _run(stepper, 4000)[-1]
    np.testing.assert_allclose(final, new_goal, atol=1e-6)


def test_constant_coupling_shifts_equilibrium():
    """tau zdot = alpha (beta (g - y) - z) + C settles at y = g + C / (alpha beta)."""
    dmp = random_discrete(seed=4)
    coupling = np.array([3.0, -5.0])
    final = _run(dmp.stepper(0.001), 4000, coupling=coupling)[-1]
    np.testing.assert_allclose(final, dmp.goal + coupling / (25.0 * 6.25), atol=1e-6)


def test_faster_tau_finishes_sooner():
    dmp = random_discrete(seed=5)
    stepper = dmp.stepper(0.001)
    stepper.set_tau(dmp.tau / 2)
    half = _run(stepper, 1000)
    np.testing.assert_allclose(half, dmp.rollout(2.0, 0.002).positions, atol=1e-12)


def test_phase_reset_and_frequency_change():
    dmp = random_rhythmic(seed=6)
    stepper = dmp.stepper(0.001)
    _run(stepper, 250)
    stepper.reset_phase(0.25)
    assert stepper.phase == 0.25
    stepper.set_tau(dmp.tau / 2)
    stepper.step()
    assert stepper.phase == pytest.approx(0.25 + 0.001 / (dmp.tau / 2), abs=1e-12)


def test_amplitude_change_converges_to_scaled_cycle():
    dmp = random_rhythmic(seed=7, setpoint=np.zeros(2))
    stepper = dmp.stepper(0.001)
    stepper.set_amplitude(2 * dmp.amplitude)
    n = int(6 * dmp.period / 0.001)
    positions = _run(stepper, n)
    reference = dmp.with_amplitude(2 * dmp.amplitude).rollout(n * 0.001, 0.001).positions
    period_steps = int(dmp.period / 0.001)
    np.testing.assert_allclose(positions[-period_steps:], reference[-period_steps:], atol=1e-6)


def test_errors():
    stepper = random_discrete().stepper()
    with pytest.raises(InvalidInputError, match="set_amplitude applies to rhythmic"):
        stepper.set_amplitude(2.0)
    with pytest.raises(InvalidInputError, match="tau must be a finite number > 0, got"):
        stepper.set_tau(0.0)
    with pytest.raises(InvalidInputError, match="reset_phase applies to rhythmic"):
        stepper.reset_phase(0.0)
    with pytest.raises(ShapeError, match=r"coupling has shape \(5,\), expected \(2,\)"):
        stepper.step(coupling=np.zeros(5))


def test_set_goal_scales_the_forcing_term_by_the_stepper_start():
    """Eq. (7): after set_goal, a stepper started elsewhere runs the DMP moved to its own start
    and the new goal (the affine rollout of that DMP is the key)."""
    dmp = random_discrete(seed=9)
    start, goal = dmp.start + np.array([0.4, -0.3]), dmp.goal + np.array([-0.5, 0.2])
    stepper = Stepper(dmp, 0.001, start)
    stepper.set_goal(goal)
    plan = dmp.replace(start=start, goal=goal).rollout(0.3, 0.001, start_velocity=0.0)
    np.testing.assert_allclose(_run(stepper, plan.n_steps - 1), plan.positions, atol=1e-12)


def test_set_tau_refuses_exactly_below_the_stability_limit():
    """The limit on dt is proportional to tau: dt <= tau * max_step / dmp.tau."""
    dmp = random_discrete(seed=2)
    stepper = dmp.stepper(0.001)
    smallest = 0.001 * dmp.tau / dmp.max_step
    stepper.set_tau(1.001 * smallest)
    with pytest.raises(InvalidInputError, match=f"keep tau >= {smallest:.4g} s"):
        stepper.set_tau(0.999 * smallest)


def test_set_amplitude_keeps_the_tau_check():
    """A larger amplitude of the energy oscillator lowers its stable step; set_tau uses it."""
    dmp = random_rhythmic(seed=3, form="energy")
    stepper = dmp.stepper(0.001)
    stepper.set_amplitude(3.0)
    scaled = dmp.replace(amplitude=3.0)
    smallest = 0.001 * scaled.tau / scaled.max_step
    stepper.set_tau(1.001 * smallest)
    with pytest.raises(InvalidInputError, match="keep tau >="):
        stepper.set_tau(0.999 * smallest)


def test_reset_phase_names_its_argument():
    stepper = random_rhythmic().stepper(0.001)
    with pytest.raises(InvalidInputError, match="phase must be a real number"):
        stepper.reset_phase("half")


@pytest.mark.parametrize(
    "changes, error, message",
    [
        (
            {"coupling": [np.nan, 0.0]},
            InvalidInputError,
            r"coupling\[0\] is nan: coupling contains",
        ),
        ({"coupling": ["a", "b"]}, InvalidInputError, "coupling must be an array of real numbers"),
        ({"coupling": np.zeros(0)}, ShapeError, r"coupling has shape \(0,\), expected \(2,\)"),
        ({"coupling": np.zeros(0, int)}, ShapeError, r"coupling has shape \(0,\), expected"),
        (
            {"canonical_coupling": "x"},
            InvalidInputError,
            "canonical_coupling must be a real number",
        ),
    ],
)
def test_bad_coupling_names_the_argument(changes, error, message):
    stepper = random_discrete().stepper(0.001)
    with pytest.raises(error, match=message):
        stepper.step(**changes)


def test_integer_coupling_acts_like_the_same_floats():
    dmp = random_discrete(seed=4)
    first, second = dmp.stepper(0.001), dmp.stepper(0.001)
    np.testing.assert_array_equal(first.step(coupling=[3, -2]), second.step(coupling=[3.0, -2.0]))


def test_compile_must_be_a_bool():
    with pytest.raises(InvalidInputError, match="compile must be True or False, got 'yes'"):
        random_discrete().stepper(0.001, compile="yes")


def test_compiled_steppers_of_one_signature_share_the_library_and_step_as_the_vm(
    monkeypatch, tmp_path
):
    """Two compiled steppers of one DMP signature (a walk's swing steppers, re-targeted at
    each lift-off) load the generated step once and keep their own states: each steps, bit
    for bit, as its own stepper on CasADi's VM (the answer key), interleaved."""
    from dmpopt import symbolic

    monkeypatch.setenv("DMPOPT_CACHE", str(tmp_path))
    monkeypatch.delenv("CC", raising=False)
    if symbolic.c_compiler() is None:
        pytest.skip("no C compiler on this machine")
    dmp = random_discrete(seed=5)
    other = dmp.replace(goal=dmp.goal + 0.3)
    first, second = dmp.stepper(0.001, compile=True), other.stepper(0.001, compile=True)
    assert first.compiled and first._function.function is second._function.function
    vm_first, vm_second = dmp.stepper(0.001), other.stepper(0.001)
    for _ in range(50):
        np.testing.assert_array_equal(first.step(), vm_first.step())
        np.testing.assert_array_equal(second.step(canonical_coupling=0.1),
                                      vm_second.step(canonical_coupling=0.1))  # fmt: skip


def test_a_rhythmic_start_of_the_wrong_size_is_named():
    with pytest.raises(
        ShapeError, match=r"start has shape \(5,\), expected \(2,\) to match 2 DOFs"
    ):
        random_rhythmic().rollout(0.1, 0.001, start=np.zeros(5))


def _two_harmonics():
    """A rhythmic DMP fitted to y = (0.3 sin wt + 0.1 sin 2wt, 0.2 cos wt), period 1 s."""
    from dmpopt import Trajectory, fit_rhythmic

    times = np.linspace(0.0, 2.0, 2001)
    w = 2 * np.pi
    y = np.column_stack(
        [0.3 * np.sin(w * times) + 0.1 * np.sin(2 * w * times), 0.2 * np.cos(w * times)]
    )
    return fit_rhythmic(Trajectory.from_positions(times, y), 25, period=1.0)


@pytest.mark.parametrize("phase", [0.0, np.pi / 2])
def test_start_on_limit_cycle(phase):
    """on_limit_cycle=True starts where the demonstration is at that phase (t = phase / w),
    with its velocity, and the plan repeats after one period (1000 steps of 1 ms).

    Bounds: the 25-basis fit reproduces this signal's velocity to 0.4 % of its 3.1 rad/s peak
    (measured), so 1 %; a start off by a tenth of a period would be off by ~40 %. Periodicity:
    the transient decays by exp(-alpha_z pi) ~ 1e-34 per period, so only rounding remains."""
    w, t = 2 * np.pi, phase / (2 * np.pi)
    stepper = _two_harmonics().stepper(0.001, phase=phase, on_limit_cycle=True)
    demo_position = [0.3 * np.sin(w * t) + 0.1 * np.sin(2 * w * t), 0.2 * np.cos(w * t)]
    demo_velocity = [
        0.3 * w * np.cos(w * t) + 0.2 * w * np.cos(2 * w * t),
        -0.2 * w * np.sin(w * t),
    ]
    np.testing.assert_allclose(stepper.position, demo_position, atol=1e-3)
    np.testing.assert_allclose(stepper.velocity, demo_velocity, atol=0.01 * np.pi)
    start = stepper.position, stepper.velocity
    _run(stepper, 1000)
    np.testing.assert_allclose(stepper.position, start[0], atol=1e-9)
    np.testing.assert_allclose(stepper.velocity, start[1], atol=1e-9)


def test_start_off_the_limit_cycle_warns():
    """Starting at rest asks far more acceleration than the cycle has (the demonstration's
    largest is 0.7 w^2 = 27.6 rad/s^2 on DOF 0) and warns with the fix; on the cycle it is
    quiet; start and on_limit_cycle together are refused."""
    dmp = _two_harmonics()
    with pytest.warns(
        UserWarning,
        match=r"times the largest acceleration of the limit cycle.*"
        r"pass on_limit_cycle=True to start on the cycle",
    ):
        dmp.stepper(0.001, start=[0.0, 0.2])
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dmp.stepper(0.001, on_limit_cycle=True)
    with pytest.raises(InvalidInputError, match="pass either start .* or on_limit_cycle=True"):
        dmp.stepper(0.001, start=[0.0, 0.2], on_limit_cycle=True)


def test_energy_oscillator_phase_and_reset_keep_its_amplitude():
    """Energy form, eq. (13), with k = 2: the stepper starts on the cycle at x = A cos(p),
    v = A k sin(p); its phase is the angle atan2(v, x) of eq. (14); a phase reset moves the
    state round the ellipse of its current energy E = (v^2 + k^2 x^2) / 2, i.e. keeps
    hypot(x, v / k), all written out here."""
    dmp = random_rhythmic(seed=9, form="energy", k=2.0, amplitude=1.5)
    assert dmp.period == 2 * np.pi * dmp.tau / 2.0  # x'' = -k^2 x / tau^2 on the cycle
    stepper = dmp.stepper(0.001, phase=0.7)
    x, v = stepper.state[:2]
    np.testing.assert_allclose([x, v], [1.5 * np.cos(0.7), 1.5 * 2.0 * np.sin(0.7)], rtol=1e-15)
    assert stepper.phase == np.arctan2(v, x)
    _run(stepper, 300)
    x, v = stepper.state[:2]
    amplitude = np.hypot(x, v / 2.0)
    stepper.reset_phase(2.0)
    np.testing.assert_allclose(
        stepper.state[:2], [amplitude * np.cos(2.0), amplitude * 2.0 * np.sin(2.0)], rtol=1e-14
    )
