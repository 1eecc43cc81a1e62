import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(__file__))


@pytest.fixture(scope="module")
def talos():
    """The full Talos model (floating base), loaded once per test module."""
    from dmpopt_robots import load_talos

    return load_talos("full")


@pytest.fixture(scope="module")
def biped():
    """The planar biped model, loaded once per test module."""
    from dmpopt_robots.biped import load_biped

    return load_biped()
