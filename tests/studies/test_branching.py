"""The shared fork helper of the studies (dmpopt_studies.branching.Branch): a run simulated
once up to a branch point and continued once per arm in forked processes gives, per arm,
the same bits as that arm's run from the start."""

import numpy as np
import pytest
from dmpopt_studies.branching import Branch, BranchFailed

PART = 300  # the branch point (iterations)


def chaotic_run(rates, n=600, branch=None):
    """The logistic map x <- r x (1 - x) from x = 0.2 (chaotic for r near 3.9: any bit lost
    before the end shows); ``rates`` = (rate before PART, rate after), the one after chosen
    at PART by ``rates[1](branch)`` when callable. The history as an array."""
    x, rate, history = 0.2, rates[0], []
    for k in range(n):
        if k == PART:
            rate = rates[1](branch) if callable(rates[1]) else rates[1]
        x = rate * x * (1.0 - x)
        history.append(x)
    return np.array(history)


def plain_run(rate_before, rate_after, n=600):
    """The answer key: the same map written out, no branch."""
    x, history = 0.2, []
    for k in range(n):
        r = rate_before if k < PART else rate_after
        x = r * x * (1.0 - x)
        history.append(x)
    return np.array(history)


def test_each_arm_continues_bit_for_bit_as_its_run_from_the_start():
    after = (3.91, 3.95, 3.99)
    branch = Branch(len(after))
    history = chaotic_run((3.9, lambda b: after[b.arm()]), branch=branch)
    logs = branch.logs(history)
    assert len(logs) == 3
    for log, rate in zip(logs, after):
        np.testing.assert_array_equal(log, plain_run(3.9, rate))  # bitwise
    assert not np.array_equal(logs[0], logs[1])  # the arms did part


def test_an_arm_sees_the_results_of_the_arms_that_ran_before_it():
    """Children run first, in order, then the parent (arm 0): a bisection's next trial may
    be chosen from the earlier ones."""
    seen = {}
    branch = Branch(3)

    def rate(b):
        index = b.arm()
        seen_now = sorted(b.children)
        seen[index] = seen_now
        return (3.9, 3.91, 3.92)[len(seen_now)]  # for arms 1, 2, 0

    history = chaotic_run((3.9, rate), branch=branch)
    logs = branch.logs((history[-1], seen.get(branch.index)))
    assert [s for _, s in logs] == [[1, 2], [], [1]]
    for (last, _), rate_after in zip(logs, (3.92, 3.9, 3.91)):
        assert last == plain_run(3.9, rate_after)[-1]


def test_a_run_that_ends_before_the_branch_gives_copies():
    branch = Branch(2)
    history = chaotic_run((3.9, lambda b: 3.99 + b.arm()), n=PART, branch=branch)
    logs = branch.logs(history)
    assert branch.index is None and len(logs) == 2
    np.testing.assert_array_equal(logs[1], plain_run(3.9, 3.9, n=PART))
    assert logs[0] is not logs[1]


def test_an_arm_that_fails_is_reported_by_the_parent():
    """A child that raises ends through ``abandon`` (no result): the parent raises
    BranchFailed instead of taking the arm for a run."""
    branch = Branch(2)

    def rate(b):
        if b.arm() == 1:
            b.abandon()
        return 3.95

    with pytest.raises(BranchFailed, match="arm 1 ended without"):
        chaotic_run((3.9, rate), branch=branch)
