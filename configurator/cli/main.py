"""`robotconf` entry point (being built; subcommands are dispatched to their modules)."""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] == "agent":
        from agent.cli import main as agent_main

        return agent_main(args[1:])
    print("robotconf: not yet", file=sys.stderr)
    return 2
