"""Fixtures of the recognition tests: a clean synthetic stroke and its DMP."""

import pytest
from recognition_shapes import N_BASIS, _shape

from dmpopt import fit_discrete


@pytest.fixture(scope="module")
def demo():
    """Return a clean synthetic stroke."""
    return _shape(0)


@pytest.fixture(scope="module")
def dmp(demo):
    """Return the DMP fitted to ``demo``."""
    return fit_discrete(demo, N_BASIS)
