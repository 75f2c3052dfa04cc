"""`robotconf agent`: hands its arguments to agent.cli, which declares and parses them itself.

The robot side needs neither click nor rich, so its options stay in agent/cli.py (argparse).
"""

from __future__ import annotations

import click


@click.command(
    "agent",
    add_help_option=False,  # `robotconf agent --help` is the agent's own help
    context_settings={"ignore_unknown_options": True, "allow_extra_args": True},
)
@click.argument("args", nargs=-1, type=click.UNPROCESSED)
def agent(args: tuple[str, ...]) -> int:
    """Run a robot's agent: robotconf agent --config agent.yaml [--broker URL] [--check]."""
    from robotconf.agent.cli import main

    return main(list(args))
