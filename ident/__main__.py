"""``python -m ident`` runs the ``ident`` command line."""

import sys

from .cli import main

sys.exit(main())
