"""Compiled normal draws of a PCG64 generator: NumPy's own generator is the answer key."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt.learning import EpisodicNAC, paper_reaching_task
from dmpopt.learning.normals import (
    _step,
    fill_standard_normal,
    generator_state,
    set_generator_state,
)

TAIL = 3.6541528853610087963519472518  # start of the ziggurat's tail


def test_raw_outputs_are_numpy_pcg64_outputs():
    """The congruential step and XSL-RR output against ``PCG64.random_raw``; fails if the
    multiplier, the carry of the 128-bit sum or the rotation is wrong."""
    rng = np.random.default_rng(7)
    high, low, increment_high, increment_low = generator_state(rng)
    outputs = []
    for _ in range(1000):
        output, high, low = _step(high, low, increment_high, increment_low)
        outputs.append(int(output))
        high, low = np.uint64(high), np.uint64(low)  # back from Python ints
    assert outputs == [int(v) for v in rng.bit_generator.random_raw(1000)]


@settings(max_examples=20, deadline=None)
@given(
    seed=st.integers(0, 2**63),
    shape=st.tuples(st.integers(1, 7), st.integers(1, 60), st.integers(1, 3)),
    skip=st.integers(0, 5),
)
def test_draws_and_continuation_are_numpy_standard_normal(seed, shape, skip):
    """The same numbers as ``Generator.standard_normal`` and, after writing the state back,
    the same generator: its next draws of another kind (integers, uniforms) agree too."""
    rng, reference = np.random.default_rng(seed), np.random.default_rng(seed)
    rng.random(skip), reference.random(skip)
    words = generator_state(rng)
    out = np.empty(shape)
    fill_standard_normal(words, out)
    set_generator_state(rng, words)
    np.testing.assert_array_equal(out, reference.standard_normal(shape))
    assert rng.integers(2**40) == reference.integers(2**40)
    np.testing.assert_array_equal(rng.random(3), reference.random(3))


def test_tail_and_wedge_draws_are_numpy_ones():
    """300,000 draws hit the tail beyond r (p = 2.7e-4 a draw: ~80 expected) and the layers'
    wedges (extra uniforms per draw); one wrong uniform there shifts every later draw."""
    rng, reference = np.random.default_rng(2026), np.random.default_rng(2026)
    words = generator_state(rng)
    out = np.empty(300_000)
    fill_standard_normal(words, out)
    assert np.sum(np.abs(out) > TAIL) > 10
    np.testing.assert_array_equal(out, reference.standard_normal(out.shape))
    set_generator_state(rng, words)
    assert rng.bit_generator.state == reference.bit_generator.state


def test_another_bit_generator_learns_in_python_rounds():
    """Not PCG64: no compiled draws (``generator_state`` is None) and ``learn`` gives the
    ask/evaluate/tell rounds' numbers, drawing from that generator."""
    task = paper_reaching_task(dt=0.01)
    generators = [np.random.Generator(np.random.MT19937(3)) for _ in range(2)]
    assert generator_state(generators[0]) is None
    methods = [
        EpisodicNAC(task.policy_features, task.initial_weights, 10.0, seed=g) for g in generators
    ]
    means = methods[0].learn(task, 4)
    for _ in range(4):
        methods[1].tell(task.evaluate(methods[1].ask()))
    np.testing.assert_array_equal(means[-1], methods[1].mean)


@pytest.mark.parametrize("seed", [0, 1])
def test_compiled_learning_leaves_the_generator_where_numpy_would(seed):
    """After ``learn`` the generator continues exactly as after the same Python rounds."""
    task = paper_reaching_task(dt=0.01)
    compiled, python = (
        EpisodicNAC(task.policy_features, task.initial_weights, 10.0, seed=seed) for _ in "ab"
    )
    compiled.learn(task, 3)
    for _ in range(3):
        python.tell(task.evaluate(python.ask()))
    assert compiled.rng.bit_generator.state == python.rng.bit_generator.state
