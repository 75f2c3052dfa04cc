"""The `robotconf` command line; importing the package stays cheap (see main.py and errors.py)."""

from __future__ import annotations

import sys

from robotconf.contract.errors import ExitCode


def main(argv: list[str] | None = None) -> int:
    """The `robotconf` entry point: click and the commands load only when it runs.

    A robot-only install (`pip install robotconf`, no `[server]` extra) has no click: there
    `robotconf agent ...` still runs the agent, and any other command says what to install."""
    from robotconf.configurator.gcpause import collector_paused

    try:
        with collector_paused():  # as in LazyGroup.get_command: what importing makes lives on
            from robotconf.workstation.cli.main import main as run
    except ModuleNotFoundError as exc:
        if exc.name != "click":
            raise
        args = sys.argv[1:] if argv is None else argv
        if args[:1] == ["agent"]:
            from robotconf.agent.cli import main as run_agent

            return run_agent(args[1:])
        print(
            "robotconf: this is a robot-only install: only `robotconf agent` (or "
            "`robotconf-agent`) runs here; the other commands need the server side: "
            "pip install 'robotconf[server]'",
            file=sys.stderr,
        )
        return int(ExitCode.TOOL)
    return run(argv)


__all__ = ["main"]
