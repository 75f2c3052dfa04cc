"""`robotconf`: the command table and the top-level wrapper that turns every failure into one line.

Each command lives in its own module and is imported only when it runs: `robotconf --help`
reads the table below and imports no command module.
"""

from __future__ import annotations

import gc
import os
import sys
from importlib import import_module

import click

from robotconf.configurator import __version__
from robotconf.configurator.gcpause import collector_paused
from robotconf.contract.errors import CliError, ExitCode

# name -> ("module:attribute", the short help `robotconf --help` shows), in the docs' order.
COMMANDS: dict[str, tuple[str, str]] = {
    "validate": ("robotconf.workstation.cli.validate:validate", "validate the whole repository"),
    "catalog": ("robotconf.workstation.cli.views:catalog", "list what exists in the catalogue"),
    "tree": (
        "robotconf.workstation.cli.views:tree",
        "show a capability's tasks > actions > logics",
    ),
    "autofill": (
        "robotconf.workstation.cli.authoring:autofill",
        "write a capability configuration that fits a template",
    ),
    "draft": (
        "robotconf.workstation.cli.draft:draft_command",
        "write a robot template and mapping scheme from a robot's interfaces",
    ),
    "render": ("robotconf.workstation.cli.views:render", "print a robot's Launch Request as JSON"),
    "plan": (
        "robotconf.workstation.cli.views:plan",
        "what would change per robot between two revisions",
    ),
    "schemas": (
        "robotconf.workstation.cli.authoring:schemas",
        "write the JSON Schemas under schemas/",
    ),
    "reconcile": (
        "robotconf.workstation.cli.reconcile:reconcile",
        "make the fleet match a git branch (runs until signalled)",
    ),
    "agent": (
        "robotconf.workstation.cli.robot_agent:agent",
        "run a robot's agent: --config agent.yaml (see robotconf agent --help)",
    ),
    "status": (
        "robotconf.workstation.cli.status:status",
        "show the fleet: desired vs reported, worst first",
    ),
    "history": (
        "robotconf.workstation.cli.history:history",
        "what a revision's robots achieved, beside the revision before (the outcome ledger)",
    ),
    "events": (
        "robotconf.workstation.cli.events:events",
        "the fleet's timeline, newest first: commits, waves, rollbacks, restarts (the ledger)",
    ),
    "ui": (
        "robotconf.workstation.cli.ui:ui",
        "serve the fleet as a live web page (the reconciler, rollouts, every robot)",
    ),
    "logs": (
        "robotconf.workstation.cli.logs:logs",
        "show a robot's brain log from the desk (--follow for new lines)",
    ),
    "restart": (
        "robotconf.workstation.cli.restart:restart",
        "start a robot's brain again from the desk, without a commit",
    ),
    "rollout": (
        "robotconf.workstation.cli.rollout:rollout",
        "resume a paused rollout's wave, or abort the rollout, from the desk",
    ),
    "promote": (
        "robotconf.workstation.cli.rollout:promote",
        "promote the revision under way to a stage by hand (fleet.yaml stages)",
    ),
    "up": (
        "robotconf.workstation.cli.up:up",
        "the whole loop on this machine: broker, reconciler, agents, status",
    ),
    "keys": (
        "robotconf.workstation.cli.security:keys",
        "make the Ed25519 key pair that signs Launch Requests",
    ),
    "broker-config": (
        "robotconf.workstation.cli.security:broker_config",
        "write Mosquitto ACL, password file and TLS listener from configs/fleet.yaml",
    ),
    "hash-token": (
        "robotconf.workstation.cli.hash_token:hash_token_command",
        "hash an operator's token for robotconf ui --operators-file",
    ),
}


# What the `server` extra installs: a command that needs one of them says so in one line.
SERVER_EXTRA = {"rich", "git", "watchfiles", "amqtt"}
# In the context's meta when robotconf is this process (the console script): see get_command.
FREEZE_IMPORTS = "robotconf.freeze_imports"


class LazyGroup(click.Group):
    """click's documented lazy-loading group: a command's module is imported when it runs (or
    its own --help is asked for); the group's help comes from the table."""

    def __init__(self, *args: object, lazy: dict[str, tuple[str, str]], **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.lazy = lazy

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [*super().list_commands(ctx), *self.lazy]

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.lazy:
            return super().get_command(ctx, cmd_name)
        module_name, attribute = self.lazy[cmd_name][0].split(":")
        try:
            # What importing makes (classes, pydantic's validators) lives as long as the process:
            # collecting while it is made, or walking it again in later collections and in the
            # last one at exit, finds nothing (about a tenth of `robotconf validate`'s time).
            with collector_paused():
                module = import_module(module_name)
        except ModuleNotFoundError as exc:
            missing = (exc.name or "").split(".")[0]
            if missing not in SERVER_EXTRA:
                raise
            raise CliError(
                f"robotconf {cmd_name} needs the server extra ({missing} is not installed): "
                "pip install 'robotconf[server]'"
            ) from None
        if ctx.meta.get(FREEZE_IMPORTS):
            gc.freeze()
        command = getattr(module, attribute)
        if not isinstance(command, click.Command):
            raise TypeError(f"{module_name}:{attribute} is not a click command")
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, short) for name, (_, short) in self.lazy.items()]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(
    cls=LazyGroup,
    lazy=COMMANDS,
    context_settings={"help_option_names": ["-h", "--help"]},
)
@click.version_option(__version__, prog_name="robotconf", message="%(prog)s %(version)s")
def cli() -> None:
    """GitOps for a mixed robot fleet: validate, render and deliver Launch Requests."""


def main(argv: list[str] | None = None) -> int:
    """Runs one command; a failure is one line on stderr and an exit code, never a traceback."""
    args = list(sys.argv[1:] if argv is None else argv)
    try:
        with cli.make_context("robotconf", args) as ctx:
            # Only a process of its own: frozen objects are never collected, a caller's either.
            ctx.meta[FREEZE_IMPORTS] = argv is None
            result = cli.invoke(ctx)
        return int(result) if result is not None else ExitCode.OK
    except CliError as exc:
        print(f"robotconf: {exc.message}", file=sys.stderr)
        return exc.code
    except click.exceptions.Exit as exc:  # --help, --version
        return exc.exit_code
    except click.ClickException as exc:  # usage errors: click prints usage and the problem
        exc.show()
        return ExitCode.TOOL if isinstance(exc, click.UsageError) else exc.exit_code
    except (KeyboardInterrupt, click.Abort):
        return ExitCode.INTERRUPTED
    except BrokenPipeError:  # `robotconf ... | head` closed the pipe: nothing left to say
        return ExitCode.OK
    except Exception as exc:  # a tool failure is exit 2 with one line, never a traceback
        from robotconf.configurator.source import SourceError

        if isinstance(exc, SourceError):
            print(f"robotconf: {exc}", file=sys.stderr)
            return ExitCode.TOOL
        if os.environ.get("ROBOTCONF_DEBUG"):
            raise
        from robotconf.contract.textsafe import printable

        print(
            f"robotconf: internal error: {type(exc).__name__}: {printable(str(exc))} "
            "(set ROBOTCONF_DEBUG=1 for the traceback)",
            file=sys.stderr,
        )
        return ExitCode.TOOL
