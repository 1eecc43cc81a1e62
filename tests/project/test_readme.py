"""The README's quickstart runs as written, each of its comments holds, and its commands
match .ci/run."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from dmpopt import DiscreteDMP, RhythmicDMP, Stepper

ROOT = Path(__file__).resolve().parents[2]
# [units] and [units/s] for "at rest at the goal", relative to the movement's extent
POSITION_TOLERANCE, SPEED_TOLERANCE = 2e-3, 1e-2


def _quickstart() -> str:
    text = (ROOT / "README.md").read_text()
    return re.search(r"```python\n(.*?)```", text, re.S).group(1)


@pytest.fixture(scope="module")
def quickstart(tmp_path_factory):
    """The names the quickstart defines, after running it in a fresh directory."""
    folder = tmp_path_factory.mktemp("quickstart")
    namespace = {}
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(folder)
        exec(compile(_quickstart(), "README quickstart", "exec"), namespace)
    return namespace


def _extent(start, positions) -> float:
    return float(np.linalg.norm(np.asarray(positions) - start, axis=1).max())


def _at_rest_at(goal, position, velocity, extent):
    np.testing.assert_allclose(position, goal, atol=POSITION_TOLERANCE * extent)
    np.testing.assert_allclose(velocity, 0.0, atol=SPEED_TOLERANCE * extent)


def _demo_positions(times):
    """The quickstart's demonstration, written out: (sin(pi t), t^2)."""
    return np.c_[np.sin(np.pi * times), times**2]


def _imitation(ns):
    dmp, demo = ns["dmp"], ns["demo"]
    assert isinstance(dmp, DiscreteDMP) and dmp.n_basis == 30
    np.testing.assert_array_equal(dmp.start, _demo_positions(np.array([0.0]))[0])
    np.testing.assert_allclose(dmp.goal, _demo_positions(np.array([1.0]))[0], atol=1e-15)
    assert demo.n_steps == 500 and dmp.convergence_time == pytest.approx(1.0, rel=1e-9)


def _plan_is_demo_then_rest(ns):
    plan, dmp = ns["plan"], ns["dmp"]
    inside = plan.times <= 1.0
    reference = _demo_positions(plan.times[inside])
    errors = np.linalg.norm(plan.positions[inside] - reference, axis=1)
    extent = _extent(reference[0], reference)
    assert np.sqrt(np.mean(errors**2)) < 1e-4 * extent  # measured 5e-5
    np.testing.assert_allclose(plan.velocities[0], [np.pi, 0.0], atol=1e-3)
    assert plan.times[-1] > 1.0  # the demo ends at 3.7 units/s: the plan goes on to rest
    _at_rest_at(dmp.goal, plan.positions[-1], plan.velocities[-1], extent)


def _rotated_and_scaled(ns):
    """Answer key: the demo mapped by the complex factor (g' - y0) / (g - y0) about y0."""
    far, dmp = ns["far"], ns["dmp"]
    new_goal = np.array([0.5, 2.0])
    factor = complex(*(new_goal - dmp.start)) / complex(*(dmp.goal - dmp.start))
    times = far.times[far.times <= 1.0]
    offsets = _demo_positions(times) - dmp.start
    mapped = (offsets[:, 0] + 1j * offsets[:, 1]) * factor
    expected = dmp.start + np.c_[mapped.real, mapped.imag]
    extent = _extent(dmp.start, expected)
    np.testing.assert_allclose(far.positions[: len(times)], expected, atol=2e-4 * extent)
    _at_rest_at(new_goal, far.positions[-1], far.velocities[-1], extent)


def _twice_as_slow(ns):
    """slow(2 t) = plan(t): at dt = 0.001 s, every second sample of slow is a plan sample.
    Each plan lasts its settling time S rounded to the nearest ms, so the ends differ from
    2 S and S by 0.5 ms at most: |slow end - 2 plan end| <= 0.5 + 2 x 0.5 = 1.5 ms."""
    plan, slow = ns["plan"], ns["slow"]
    assert slow.times[-1] == pytest.approx(2 * plan.times[-1], abs=1.5e-3 + 1e-9)
    n = min(plan.n_steps, (slow.n_steps + 1) // 2)
    np.testing.assert_allclose(slow.times[: 2 * n : 2], 2 * plan.times[:n], atol=1e-12)
    np.testing.assert_allclose(slow.positions[: 2 * n : 2], plan.positions[:n], atol=1e-8)
    np.testing.assert_allclose(2 * slow.velocities[: 2 * n : 2], plan.velocities[:n], atol=1e-7)


def _online(ns):
    stepper, dmp = ns["stepper"], ns["dmp"]
    assert isinstance(stepper, Stepper)
    assert stepper.time == pytest.approx(dmp.settling_time, abs=1e-3)


def _ends_at_new_goal(ns):
    goal = np.array([1.0, 1.5])
    extent = _extent(ns["dmp"].start, [goal, ns["dmp"].goal])
    _at_rest_at(goal, ns["position"], ns["velocity"], extent)


def _rhythmic_period(ns):
    assert isinstance(ns["drum"], RhythmicDMP)
    assert ns["drum"].period == pytest.approx(0.5, rel=1e-3)


def _loaded_equals_saved(ns):
    dmp, same = ns["dmp"], ns["same"]
    assert type(same) is DiscreteDMP
    for field in dataclasses.fields(dmp):
        saved, loaded = getattr(dmp, field.name), getattr(same, field.name)
        if isinstance(saved, np.ndarray):
            assert saved.dtype == loaded.dtype and np.array_equal(saved, loaded), field.name
        else:
            assert saved == loaded, field.name
    np.testing.assert_array_equal(same.rollout().positions, dmp.rollout().positions)


CHECKS = {
    "imitation, Section 3.4": _imitation,
    "Trajectory: the demo, then at rest at its goal": _plan_is_demo_then_rest,
    "same shape, rotated and scaled onto the new goal": _rotated_and_scaled,
    "twice as slow": _twice_as_slow,
    "online, for control loops": _online,
    "change the goal mid-movement; it ends there": _ends_at_new_goal,
    "rhythmic, its period (0.5 s) estimated": _rhythmic_period,
    "same equals dmp, field by field": _loaded_equals_saved,
}


def test_every_comment_has_a_check():
    """A comment added or changed in the quickstart needs its check here."""
    comments = re.findall(r"#\s*(.+?)\s*$", _quickstart(), re.M)
    assert comments == list(CHECKS)


@pytest.mark.parametrize("comment", list(CHECKS))
def test_quickstart_comment_holds(quickstart, comment):
    CHECKS[comment](quickstart)


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    command = [line for line in readme.splitlines() if "pytest" in line and "venv" in line][0]
    assert command.strip() in (ROOT / ".ci" / "run").read_text()
