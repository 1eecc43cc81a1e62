"""Quick study runs shared by the test modules of one pytest process (run once each)."""

import atexit
import shutil
import tempfile
from functools import lru_cache
from pathlib import Path


@lru_cache(maxsize=None)
def imitation_quick() -> Path:
    """Output folder of one quick imitation run (seed 1), deleted at exit."""
    from dmpopt_studies import imitation

    root = Path(tempfile.mkdtemp(prefix="dmpopt-imitation-"))
    atexit.register(shutil.rmtree, root, ignore_errors=True)
    imitation.run(root / "imitation", quick=True, seed=1)
    return root / "imitation"
