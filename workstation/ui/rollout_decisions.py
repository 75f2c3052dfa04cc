"""The UI's rollout decisions: an operator's resume or abort, sent and confirmed on a thread of
its own exactly as `robotconf rollout` sends it (so the page is never held), and what came of
the latest one."""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from robotconf.contract.errors import CliError
from robotconf.contract.mqtt import Connection
from robotconf.contract.textsafe import printable
from robotconf.workstation.desk.rollout import Action, send_action

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

log = logging.getLogger("robotconf.ui")

State = Literal["pending", "confirmed", "failed"]


@dataclass(frozen=True)
class Decision:
    """A decision the UI sent: still waiting for the reconciler, carried out, or not (why)."""

    action: Action
    state: State
    by: str
    at: float  # wall clock, when it was asked
    text: str = ""  # the reconciler's answer or why it was not done, printable


class Decisions:
    """Resumes and aborts asked from the UI, signed with `key` when given, each answered
    within `wait` seconds; one at a time (a rollout has one wave run to decide about)."""

    def __init__(
        self, connection: Connection, prefix: str, key: Ed25519PrivateKey | None, wait: float = 30.0
    ) -> None:
        self.connection = connection
        self.prefix = prefix
        self.key = key
        self.wait = wait
        self._latest: Decision | None = None
        self._lock = threading.Lock()

    @property
    def latest(self) -> Decision | None:
        with self._lock:
            return self._latest

    def start(self, action: Action, by: str, client: str = "?") -> Literal["started", "already"]:
        """Sends `action` on a thread; "already" while one waits for its answer. `client`:
        where the ask came from (the audit line's)."""
        with self._lock:
            if self._latest is not None and self._latest.state == "pending":
                return "already"
            self._latest = Decision(action, "pending", by, time.time())
        # The audit line before anything is sent, as a restart's (restarts.py).
        log.info("ui: rollout %s asked by %s from %s", action, by, client)
        threading.Thread(
            target=self._send, args=(action, by), name=f"ui-rollout-{action}", daemon=True
        ).start()
        return "started"

    def _send(self, action: Action, by: str) -> None:
        asked = self.latest
        at = asked.at if asked is not None else time.time()
        try:
            _, answer = send_action(self.connection, self.prefix, action, by, self.key, self.wait)
            done = Decision(action, "confirmed", by, at, printable(answer.message))
        except CliError as exc:
            done = Decision(action, "failed", by, at, printable(exc.message))
        except Exception as exc:  # one decision fails, never the UI
            log.error("ui: the rollout %s failed: %s", action, printable(repr(exc))[:300])
            done = Decision(action, "failed", by, at, "internal error (see the UI's log)")
        log.info("ui: rollout %s asked by %s: %s: %s", action, by, done.state, done.text)
        with self._lock:
            self._latest = done
