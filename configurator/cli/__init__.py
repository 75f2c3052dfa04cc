"""The `robotconf` command line."""

from configurator.cli.main import main

__all__ = ["main"]
