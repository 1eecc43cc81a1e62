"""Properties of the public API on random demonstrations (hypothesis).

Demonstrations: 1-5 DOFs, 50-2000 samples, 0.1-20 s, 2-100 basis functions, start-goal gaps
from zero to ten times the shape's size, starting at rest or moving, ending at rest. The
number of samples times the number of bases is capped (one fit integrates one response per
basis function over the samples) to keep this file within its time budget. The amplification
of goal changes, max_t |y(t) - y0| / |g - y0|, is computed here from the samples.
"""

import dataclasses
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from dmpopt import InvalidInputError, Trajectory, fit_discrete, load, save

BOUND = 10.0  # the documented MAX_GOAL_AMPLIFICATION
PLAN_STEPS = 400
GAPS = (0.0, 1e-6, 1e-4, 1e-3, 1e-2, 0.05, 0.3, 1.0, 10.0)
SETTINGS = settings(max_examples=12, deadline=None)


@st.composite
def demonstrations(draw):
    """(demo, n_basis): a random shape from start to start + gap, sampled uniformly."""
    n_dofs = draw(st.integers(1, 5))
    n_samples = draw(st.integers(50, 2000))
    n_basis = draw(st.integers(2, 100))
    assume(n_basis <= n_samples)  # more weights than samples is refused (tested elsewhere)
    assume(n_samples * (n_basis + 3) <= 30_000)
    duration = draw(st.floats(0.1, 20.0))
    size = 10.0 ** draw(st.floats(-3.0, 3.0))
    moving = draw(st.booleans())
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    # start-goal gap per unit of the shape's size: every decade is drawn as often
    gap = draw(st.sampled_from(GAPS)) * rng.uniform(0.5, 2.0)

    u = np.linspace(0.0, 1.0, n_samples)[:, None]
    k = np.arange(1, 4)[None, :]
    bumps = np.sin(k * np.pi * u) * (1 - u) ** 2 * (1.0 if moving else u**2)  # (n, 3)
    shape = bumps @ rng.normal(size=(3, n_dofs))
    direction = rng.normal(size=n_dofs)
    profile = 10 * u**3 - 15 * u**4 + 6 * u**5
    start = rng.normal(size=n_dofs) * size
    positions = start + size * (shape + gap * profile * direction / np.linalg.norm(direction))
    demo = Trajectory.from_positions(np.linspace(0.0, duration, n_samples), positions)
    return demo, n_basis


def _amplification(positions, start) -> float:
    offsets = np.linalg.norm(positions - start, axis=1)
    return offsets.max() / offsets[-1] if offsets[-1] > 0 else np.inf


def _plan(dmp):
    """The default-duration plan, on a grid of PLAN_STEPS steps."""
    return dmp.rollout(dt=dmp.settling_time / PLAN_STEPS)


@SETTINGS
@given(case=demonstrations())
def test_default_plan_starts_like_the_demo_and_rests_at_its_goal(case):
    demo, n_basis = case
    dmp = fit_discrete(demo, n_basis)
    plan = _plan(dmp)
    extent = np.linalg.norm(plan.positions - dmp.start, axis=1).max()
    speed = max(np.linalg.norm(demo.velocities, axis=1).max(), extent / demo.duration)
    assert np.all(np.isfinite(plan.positions)) and np.all(np.isfinite(plan.accelerations))
    np.testing.assert_array_equal(dmp.start, demo.positions[0])
    np.testing.assert_array_equal(dmp.goal, demo.positions[-1])
    np.testing.assert_allclose(plan.positions[0], demo.positions[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(plan.velocities[0], demo.velocities[0], atol=1e-9 * speed)
    np.testing.assert_allclose(plan.positions[-1], dmp.goal, atol=2e-3 * extent + 1e-12)
    np.testing.assert_allclose(plan.velocities[-1], 0.0, atol=2e-2 * speed + 1e-12)


@settings(max_examples=20, deadline=None)
@given(
    case=demonstrations(),
    shift=st.floats(-3.0, 1.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_goal_changes_are_bounded(case, shift, seed):
    """A goal moved by delta moves the plan by at most BOUND |delta| (times the plan's own
    excursion over the demo's, which differ by the fit error).

    'auto' picks rotation iff the demo's amplification is at most BOUND. Rotation maps the plan
    by a similarity S with |S - I| = |delta| / |g - y0|, so the change is at most
    |delta| max|y - y0| / |g - y0|, with equality for 1 or 2 DOFs (S - I is then a complex
    factor); translation adds the unforced step response, between 0 and delta. Relative to
    the new movement: max|y' - y0| <= max(BOUND |g' - y0|, E + |delta|).
    """
    demo, n_basis = case
    dmp = fit_discrete(demo, n_basis)
    demo_amplification = _amplification(demo.positions, demo.positions[0])
    assert dmp.goal_scaling == ("rotation" if demo_amplification <= BOUND else "translation")

    plan = _plan(dmp).positions
    demo_extent = np.linalg.norm(demo.positions - demo.positions[0], axis=1).max()
    plan_extent = np.linalg.norm(plan - dmp.start, axis=1).max()
    direction = np.random.default_rng(seed).normal(size=dmp.n_dofs)
    delta = 10.0**shift * max(demo_extent, 1e-300) * direction / np.linalg.norm(direction)
    moved = dmp.with_goal(dmp.goal + delta)
    moved_plan = _plan(moved)  # same tau, so the same grid
    change = np.linalg.norm(moved_plan.positions - plan, axis=1).max()
    size = np.linalg.norm(delta)
    assert np.all(np.isfinite(moved_plan.positions))
    ratio = max(1.0, plan_extent / demo_extent) if demo_extent > 0 else 1.0
    assert change <= BOUND * size * ratio * (1 + 1e-9) + 1e-12 * plan_extent
    if dmp.goal_scaling == "rotation":
        gap = np.linalg.norm(dmp.goal - dmp.start)
        largest = size * plan_extent / gap
        assert change <= largest * (1 + 1e-9)
        if dmp.n_dofs <= 2:
            assert change == pytest.approx(largest, rel=1e-6, abs=1e-12 * size)
    else:
        assert change <= size * (1 + 1e-9) + 1e-12 * plan_extent
    new_extent = np.linalg.norm(moved_plan.positions - dmp.start, axis=1).max()
    new_gap = np.linalg.norm(moved.goal - dmp.start)
    limit = max(BOUND * ratio * new_gap, plan_extent + size)
    assert new_extent <= limit * (1 + 1e-9) + 1e-12 * plan_extent


@SETTINGS
@given(case=demonstrations(), scale=st.floats(-2.0, 2.0))
def test_explicit_scalings_are_refused_exactly_beyond_the_bound(case, scale):
    """'rotation' and 'paper' are accepted iff their amplification (per DOF for 'paper') is at
    most BOUND; then a plan to a new goal is the plan mapped by the scaling's matrix."""
    demo, n_basis = case
    start, end = demo.positions[0], demo.positions[-1]
    per_dof = np.abs(demo.positions - start).max(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):  # x / 0 = inf, 0 / 0 = nan: inf
        paper_amplification = np.nan_to_num(per_dof / np.abs(end - start), nan=np.inf)
    if np.all(paper_amplification <= BOUND):
        dmp = fit_discrete(demo, n_basis, goal_scaling="paper")
        factors = np.full(dmp.n_dofs, 10.0**scale)
        factors[0] *= -1.0
        plan = _plan(dmp).positions
        moved = dmp.with_goal(start + factors * (end - start))
        moved_plan = _plan(moved)
        extent = np.abs(plan - start).max()
        np.testing.assert_allclose(
            moved_plan.positions - start,
            (plan - start) * factors,
            atol=1e-9 * extent * max(1.0, 10.0**scale),
        )
    else:
        bad = np.nonzero(paper_amplification > BOUND)[0].tolist()
        with pytest.raises(InvalidInputError, match=re.escape(f"DOF(s) {bad} (largest: ")):
            fit_discrete(demo, n_basis, goal_scaling="paper")
    if _amplification(demo.positions, start) > BOUND:
        with pytest.raises(InvalidInputError, match="goal_scaling='rotation' would amplify"):
            fit_discrete(demo, n_basis, goal_scaling="rotation")
    else:
        assert fit_discrete(demo, n_basis, goal_scaling="rotation").goal_scaling == "rotation"


@settings(max_examples=8, deadline=None)
@given(case=demonstrations(), goal_scaling=st.sampled_from(["auto", "translation"]))
def test_save_load_is_exact(case, goal_scaling):
    """Every field comes back bit for bit (a DMP's plans are functions of its fields)."""
    demo, n_basis = case
    dmp = fit_discrete(demo, n_basis, goal_scaling=goal_scaling)
    with tempfile.TemporaryDirectory() as folder:
        same = load(save(dmp, Path(folder) / "dmp"))
    for field in dataclasses.fields(dmp):
        saved, loaded = getattr(dmp, field.name), getattr(same, field.name)
        if isinstance(saved, np.ndarray):
            assert saved.dtype == loaded.dtype and np.array_equal(saved, loaded), field.name
        else:
            assert saved == loaded, field.name
