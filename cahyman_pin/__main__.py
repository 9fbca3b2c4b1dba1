"""``python -m cahyman_pin``: the ``cahyman`` command line."""

from .cli import main

raise SystemExit(main())
