"""`robotconf rollout resume|abort` and `robotconf promote`: an operator's decision about the
rollout under way, sent by the desk (workstation/desk/rollout.py) and its answer printed."""

from __future__ import annotations

from pathlib import Path

import click

from robotconf.contract.errors import ExitCode
from robotconf.contract.textsafe import printable
from robotconf.contract.wire import short_rev
from robotconf.workstation.cli.broker_options import BrokerOptions, desk_broker_options
from robotconf.workstation.cli.options import F, repo_option
from robotconf.workstation.cli.restart import requester, signing_key_option
from robotconf.workstation.desk.rollout import Action, send_action
from robotconf.workstation.desk.signing import private_key


@click.group("rollout")
def rollout() -> None:
    """Decide for a rollout by hand: resume a wave paused for inconclusive evidence, or abort
    the rollout (its robots go back to the last revision that fully rolled out). The reconciler
    carries out each decision once, keeps it as a git note on the revision (`git log
    --notes=robotconf`) and shows it in its status."""


_REVISION = click.option(
    "--revision", default=None, help="only if the rollout is of this commit (a prefix)"
)


def _options(command: F) -> F:
    for option in reversed(
        [
            repo_option,
            desk_broker_options,
            signing_key_option,
            click.option("--as", "as_name", default=None, help="who decides (default: $USER)"),
            click.option(
                "--wait",
                type=click.FloatRange(min=0.1),
                default=30.0,
                show_default=True,
                help="give up when the reconciler has not answered after S seconds",
            ),
        ]
    ):
        command = option(command)
    return command


def _run(
    action: Action,
    mqtt: BrokerOptions,
    signing_key: Path | None,
    as_name: str | None,
    revision: str | None,
    wait: float,
) -> ExitCode:
    by = requester(as_name, mqtt.username)
    key = private_key(signing_key or mqtt.signing_key)
    before, answer = send_action(mqtt.connection(), mqtt.prefix, action, by, key, wait, revision)
    print(
        f"rollout of {short_rev(before.revision)}, wave '{printable(before.wave_name)}': "
        f"{printable(answer.message)}"
    )
    return ExitCode.OK


@rollout.command("resume")
@_options
@_REVISION
def resume(
    repo: Path,
    mqtt: BrokerOptions,
    signing_key: Path | None,
    as_name: str | None,
    revision: str | None,
    wait: float,
) -> ExitCode:
    """Pass the wave paused for inconclusive evidence (too few goals by rollout.verify's
    timeout): the next wave starts. Exit 0 when the reconciler carried it out, 1 when it
    refused (nothing paused, the rollout moved on, a bad signature), 2 when the broker cannot
    be reached."""
    return _run("resume", mqtt, signing_key, as_name, revision, wait)


@rollout.command("abort")
@_options
@_REVISION
def abort(
    repo: Path,
    mqtt: BrokerOptions,
    signing_key: Path | None,
    as_name: str | None,
    revision: str | None,
    wait: float,
) -> ExitCode:
    """Stop the rollout under way: as a failed wave, its robots get the last revision that
    fully rolled out (rollout.on_failure: halt keeps them where they are). Exit 0 when the
    reconciler carried it out, 1 when it refused, 2 when the broker cannot be reached."""
    return _run("abort", mqtt, signing_key, as_name, revision, wait)


@click.command("promote")
@click.argument("revision", metavar="REV")
@click.option("--to", "stage", required=True, help="the stage (fleet.yaml stages) it goes to")
@_options
def promote(
    revision: str,
    stage: str,
    repo: Path,
    mqtt: BrokerOptions,
    signing_key: Path | None,
    as_name: str | None,
    wait: float,
) -> ExitCode:
    """Promote REV (the revision being rolled out, a commit id or a prefix of it) to STAGE by
    hand, as Kargo allows: every wave and stage gate before that stage passes without waiting
    for its evidence (its robots' health is still waited for). The reconciler keeps the
    promotion, with who asked, as a git note on the revision. Exit 0 when the reconciler
    carried it out, 1 when it refused (another revision under way, no such stage, the revision
    there already), 2 when the broker cannot be reached."""
    by = requester(as_name, mqtt.username)
    key = private_key(signing_key or mqtt.signing_key)
    before, answer = send_action(
        mqtt.connection(), mqtt.prefix, "promote", by, key, wait, revision, stage
    )
    print(
        f"{short_rev(before.revision)} to stage '{printable(stage)}': {printable(answer.message)}"
    )
    return ExitCode.OK
