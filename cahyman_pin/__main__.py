"""``python -m cahyman_pin``: the ``cahyman`` command line."""

from cahyman_pin.cli import main

raise SystemExit(main())
