"""The `robotconf` command line; importing the package stays cheap (see main.py and errors.py)."""

from __future__ import annotations


def main(argv: list[str] | None = None) -> int:
    """The `robotconf` entry point: click and the commands load only when it runs."""
    from configurator.gcpause import collector_paused

    with collector_paused():  # as in LazyGroup.get_command: what importing makes lives on
        from workstation.cli.main import main as run

    return run(argv)


__all__ = ["main"]
