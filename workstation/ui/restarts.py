"""The UI's restarts: each operator's request sent and confirmed on a thread of its own (as
`robotconf restart` does it, so the page is never held), and what came of it per robot; each
ask and its outcome a line of the UI's log."""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from robotconf.contract.errors import CliError
from robotconf.contract.mqtt import Connection
from robotconf.contract.textsafe import printable
from robotconf.workstation.desk.restart import request_restart

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

log = logging.getLogger("robotconf.ui")

MAX_PENDING = 8  # restarts waiting for their robots at once: each is a thread and a client
KEEP = 256  # outcomes remembered (one per robot, the latest)

State = Literal["pending", "confirmed", "failed"]


@dataclass(frozen=True)
class Outcome:
    """A restart the UI asked for: still waiting, confirmed by the robot, or not done (why)."""

    robot_id: str
    state: State
    by: str
    at: float  # wall clock, when it was asked
    text: str = ""  # the robot's confirmation or why it was not done, printable


class Restarts:
    """Restarts asked from the UI, signed with `key` when given, each confirmed within
    `wait` seconds; at most `limit` waiting at once, one per robot."""

    def __init__(
        self,
        connection: Connection,
        prefix: str,
        key: Ed25519PrivateKey | None,
        *,
        wait: float = 30.0,
        limit: int = MAX_PENDING,
    ) -> None:
        self.connection = connection
        self.prefix = prefix
        self.key = key
        self.wait = wait
        self.limit = limit
        self._outcomes: OrderedDict[str, Outcome] = OrderedDict()
        self._pending = 0
        self._lock = threading.Lock()

    def outcome(self, robot_id: str) -> Outcome | None:
        with self._lock:
            return self._outcomes.get(robot_id)

    def start(
        self, robot_id: str, by: str, client: str = "?"
    ) -> Literal["started", "already", "busy"]:
        """Asks for a restart of `robot_id` on a thread; "already" when one is waiting for
        that robot, "busy" when `limit` restarts wait. `client`: where the ask came from (the
        audit line's)."""
        with self._lock:
            current = self._outcomes.get(robot_id)
            if current is not None and current.state == "pending":
                return "already"
            if self._pending >= self.limit:
                return "busy"
            self._pending += 1
            self._record(Outcome(robot_id, "pending", by, time.time()))
        # The audit line comes before anything is sent: a UI killed mid-restart loses no
        # record of who asked (what the robot did is its status's and its brain.log's).
        log.info("ui: restart of %s asked by %s from %s", robot_id, by, client)
        threading.Thread(
            target=self._restart, args=(robot_id, by), name=f"ui-restart-{robot_id}", daemon=True
        ).start()
        return "started"

    def _restart(self, robot_id: str, by: str) -> None:
        asked = self.outcome(robot_id)
        at = asked.at if asked is not None else time.time()
        try:
            status = request_restart(
                self.connection, self.prefix, robot_id, by, self.key, self.wait
            )
            said = f"{status.state.value} ({printable(status.message)})"
            done = Outcome(robot_id, "confirmed", by, at, said)
        except CliError as exc:
            done = Outcome(robot_id, "failed", by, at, printable(exc.message))
        except Exception as exc:  # one restart fails, never the UI
            log.error("ui: the restart of %s failed: %s", robot_id, printable(repr(exc))[:300])
            done = Outcome(robot_id, "failed", by, at, "internal error (see the UI's log)")
        log.info("ui: restart of %s asked by %s: %s: %s", robot_id, by, done.state, done.text)
        with self._lock:
            self._pending -= 1
            self._record(done)

    def _record(self, outcome: Outcome) -> None:
        self._outcomes[outcome.robot_id] = outcome
        self._outcomes.move_to_end(outcome.robot_id)
        while len(self._outcomes) > KEEP:
            self._outcomes.popitem(last=False)
