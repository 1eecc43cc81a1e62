"""``python -m dmpopt_studies.humanoid OUT_DIR [--quick]``."""

from .study import main

main()
