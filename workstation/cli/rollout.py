"""`robotconf rollout resume|abort`: an operator's decision about the rollout under way, sent
to the reconciler (signed when the lab signs) and confirmed by its status."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import click
from pydantic import ValidationError

from contract.errors import CliError, ExitCode
from contract.launch import RolloutAction
from contract.mqtt import Connection
from contract.safejson import PayloadError
from contract.textsafe import printable
from contract.topics import Role, subscriptions
from contract.wire import OperatorAnswer, ReconcilerStatus, RolloutStatus, Topics, short_rev
from reconciler.retained import RetainedView, read_object
from workstation.cli.broker_options import BrokerOptions, desk_broker_options, wait_for_broker
from workstation.cli.options import F, repo_option
from workstation.cli.restart import private_key, requester, signing_key_option

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

Action = Literal["resume", "abort", "promote"]


class ReconcilerDesk:
    """A client on the reconciler's status that sends it an action and waits for its answer."""

    def __init__(self, connection: Connection, prefix: str) -> None:
        self.topics = Topics(prefix)
        self._changed = threading.Condition()
        self.view = RetainedView(
            connection,
            subscriptions(Role.OPERATOR, prefix, "reconciler_status"),
            self.topics.sync,
            role="desk-rollout",
            on_change=self._notify,
        )

    def __enter__(self) -> ReconcilerDesk:
        self.view.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.view.stop()

    def _notify(self) -> None:
        with self._changed:
            self._changed.notify_all()

    def status(self) -> ReconcilerStatus | None:
        payload = self.view.get(self.topics.reconciler_status)
        if not payload:
            return None
        try:
            return ReconcilerStatus.model_validate(read_object(payload))
        except (PayloadError, ValidationError):
            return None

    def answer(self, issued_at: float, wait: float) -> OperatorAnswer | None:
        """The reconciler's answer naming `issued_at`, within `wait` seconds."""
        deadline = time.monotonic() + wait
        with self._changed:
            while True:
                status = self.status()
                rollout = status.rollout if status is not None else None
                answer = rollout.answer if rollout is not None else None
                if answer is not None and answer.issued_at == issued_at:
                    return answer
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._changed.wait(min(left, 0.5))


def current_rollout(desk: ReconcilerDesk, url: str, wait: float) -> RolloutStatus:
    wait_for_broker(desk.view, min(wait, 10.0))
    status = desk.status()
    if status is None:
        raise CliError(f"{url} holds no reconciler status: is a reconciler running?")
    if status.rollout is None:
        raise CliError(
            "no rollout: the reconciler's fleet.yaml has no rollout policy, or none started",
            ExitCode.FINDINGS,
        )
    return status.rollout


def send_action(
    connection: Connection,
    prefix: str,
    action: Action,
    by: str,
    key: Ed25519PrivateKey | None,
    wait: float,
    revision: str | None = None,
    stage: str | None = None,
) -> tuple[RolloutStatus, OperatorAnswer]:
    """Sends `action` about the rollout's current wave run and waits for the reconciler's
    answer: the one way the desk and the browser view resume or abort. CliError says why it
    was not carried out."""
    with ReconcilerDesk(connection, prefix) as desk:
        rollout = current_rollout(desk, connection.address.url, wait)
        if revision is not None and not rollout.revision.startswith(revision):
            raise CliError(
                f"the rollout under way is of {short_rev(rollout.revision)}, not {revision}",
                ExitCode.FINDINGS,
            )
        if rollout.wave_started_at is None or rollout.state not in ("Progressing", "Paused"):
            raise CliError(
                f"the rollout of {short_rev(rollout.revision)} is {rollout.state}: "
                f"nothing to {action}",
                ExitCode.FINDINGS,
            )
        issued_at = round(time.time(), 6)
        request = RolloutAction(
            action=action,
            revision=rollout.revision,
            wave=rollout.wave,
            wave_started_at=rollout.wave_started_at,
            requested_by=by,
            issued_at=issued_at,
            stage=stage,
        )
        if key is not None:
            from contract.signing import sign

            request = sign(request, key, issued_at)
        if not desk.view.publish(desk.topics.rollout_request, request.payload(), min(wait, 10.0)):
            raise CliError(
                "the broker did not take the request "
                f"({desk.view.last_error or 'no acknowledgement'}): the ACL lets operators only"
            )
        answer = desk.answer(request.issued_at, wait)
    if answer is None:
        raise CliError(
            f"the reconciler did not answer within {wait:g} s: it is not running, or it never "
            "got the request (the broker's ACL lets only the operator user send it)",
            ExitCode.FINDINGS,
        )
    if not answer.accepted:
        raise CliError(f"refused: {printable(answer.message)}", ExitCode.FINDINGS)
    return rollout, answer


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
