"""Superposition (Section 3.7): a discrete DMP moving the setpoint of a rhythmic one."""

import numpy as np
import pytest
from problems import random_discrete, random_rhythmic

from dmpopt import InvalidInputError, ShapeError, superpose


def test_oscillation_follows_the_discrete_plan():
    discrete = random_discrete(seed=1)
    rhythmic = random_rhythmic(seed=2, setpoint=np.zeros(2))
    duration = 3.0
    combined = superpose(discrete, rhythmic, duration, 0.001)
    alone = rhythmic.rollout(duration, 0.001)
    # once the discrete DMP has converged, the pattern is the rhythmic limit cycle shifted
    # to the discrete goal
    last = slice(-int(rhythmic.period / 0.001), None)
    np.testing.assert_allclose(
        combined.positions[last], alone.positions[last] + discrete.goal, atol=1e-6
    )
    # with a constant setpoint, superposition is the rhythmic rollout
    resting = discrete.replace(weights=np.zeros_like(discrete.weights), goal=discrete.start)
    still = superpose(resting, rhythmic.with_setpoint(discrete.start), 1.0, 0.001)
    reference = rhythmic.with_setpoint(discrete.start).rollout(1.0, 0.001)
    np.testing.assert_allclose(still.positions, reference.positions, atol=1e-12)


def test_errors():
    with pytest.raises(ShapeError, match="discrete has 2 DOFs but rhythmic has 3"):
        superpose(random_discrete(), random_rhythmic(n_dofs=3), 1.0)
    with pytest.raises(InvalidInputError, match="a DiscreteDMP and a RhythmicDMP"):
        superpose(random_rhythmic(), random_discrete(), 1.0)
