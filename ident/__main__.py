"""``python -m ident`` runs the ``ident`` command line."""

import sys

from .cli.main import main

sys.exit(main())
