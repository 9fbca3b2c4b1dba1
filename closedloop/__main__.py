"""``python -m closedloop``: the ``closedloop`` command (see :mod:`closedloop.cli.app`)."""

import sys

from closedloop.cli.app import main

sys.exit(main())
