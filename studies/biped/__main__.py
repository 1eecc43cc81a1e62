"""``python -m dmpopt_studies.biped OUT_DIR [--quick]``."""

from . import main

main()
