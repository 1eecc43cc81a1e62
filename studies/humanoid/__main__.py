"""``python -m studies.humanoid OUT_DIR [--quick]``."""

from .study import main

main()
