"""``python -m gearsym`` runs the command line."""

import sys

from gearsym.cli import main

sys.exit(main())
