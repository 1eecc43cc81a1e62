"""``python -m studies.biped OUT_DIR [--quick]``."""

from . import main

main()
