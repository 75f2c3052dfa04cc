"""An operator's decision about the rollout under way (resume, abort, promote), sent to the
reconciler (signed when the lab signs) and confirmed by its status: the one way `robotconf
rollout`, `robotconf promote` and the browser view's operators decide."""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING, Literal

from pydantic import ValidationError

from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.launch import RolloutAction
from robotconf.contract.mqtt import Connection
from robotconf.contract.safejson import PayloadError
from robotconf.contract.textsafe import printable
from robotconf.contract.topics import Role, subscriptions
from robotconf.contract.wire import (
    OperatorAnswer,
    ReconcilerStatus,
    RolloutStatus,
    Topics,
    short_rev,
)
from robotconf.readmodel.retained import RetainedView, read_object
from robotconf.workstation.desk.broker import wait_for_broker

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
            from robotconf.contract.signing import sign

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
