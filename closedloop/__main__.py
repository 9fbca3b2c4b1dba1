"""``python -m closedloop``: the ``closedloop`` command (see :mod:`closedloop.cli`)."""

import sys

from .cli import main

sys.exit(main())
