"""The ``closedloop`` command line (entry point ``closedloop.cli:main``)."""

from __future__ import annotations


def __getattr__(name: str):
    """``main``, the entry point, from :mod:`closedloop.cli.app` on first use (so that
    importing :mod:`closedloop.cli.common` loads no subcommand)."""
    if name == "main":
        from closedloop.cli.app import main

        return main
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
