"""``python -m daq`` runs the ``daq`` command line."""

import sys

from .cli import main

sys.exit(main())
