"""``python -m replay`` runs the ``replay`` command line."""

import sys

from .cli import main

sys.exit(main())
