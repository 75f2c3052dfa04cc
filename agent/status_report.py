"""The robot's retained status: what the supervisor says, published when it changes.

Also the connection's side of it: the seq of the live connection, and a stale offline status
(an older connection's Last Will) answered with the live one.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from pydantic import ValidationError

from robotconf.agent.broker_link import MAX_STATUS_BYTES, BrokerLink
from robotconf.agent.supervisor import Supervisor
from robotconf.agent.workdir import SeqStore
from robotconf.contract.clock import now as now_wall
from robotconf.contract.safejson import PayloadError, parse_object
from robotconf.contract.wire import AgentState, AgentStatus

log = logging.getLogger("robotconf.agent")

STOPPING_QUIET = 0.05  # seconds a brain may take to stop before `stopping` is published


class StatusReport:
    """The status topic of one robot: published on connecting, then when it changes."""

    def __init__(
        self,
        link: BrokerLink,
        supervisor: Supervisor,
        seq: SeqStore,
        interfaces_error: Callable[[], str | None],
    ) -> None:
        self.link = link
        self.supervisor = supervisor
        self.seq = seq
        self._interfaces_error = interfaces_error
        self.connected = False
        self.conn_seq = 0  # the live connection's, the one its Last Will carries
        self.held_until: float | None = None  # when a status held back is published
        self._last_published: AgentStatus | None = None

    def current(self) -> AgentStatus:
        status = self.supervisor.status(self.conn_seq)
        error = self._interfaces_error()
        if error is not None:
            status.interfaces_error = error
        return status

    def final(self) -> AgentStatus | None:
        """What the agent says as it stops, if it is connected to say it."""
        if not self.connected:
            return None
        return self.supervisor.status(self.conn_seq).model_copy(
            update={
                "state": AgentState.OFFLINE,
                "since": now_wall(),
                "message": "agent stopped",
            }
        )

    def publish(self, force: bool) -> None:
        if not self.connected:
            self.held_until = None  # the connection's first status is published in full
            return
        status = self.current()
        if not force and status == self._last_published:
            return
        delay = 0.0 if force else publish_delay(status, self._last_published)
        if delay > 0:
            now = time.monotonic()
            if self.held_until is None:
                self.held_until = now + delay
            if now < self.held_until:
                return  # `due()` wakes the loop then, should nothing newer come first
        self.held_until = None
        self.link.publish_status(status)
        self._last_published = status

    def seen(self, payload: bytes) -> None:
        """A status on this robot's topic, as the broker has it: its seq is remembered, and a
        stale offline one is overwritten."""
        try:
            seen = AgentStatus.model_validate(parse_object(payload, max_bytes=MAX_STATUS_BYTES))
        except (PayloadError, ValidationError):
            return  # not ours: anything else on this topic is no reason to act
        self.seq.observe(seen.seq)
        if seen.state != AgentState.OFFLINE or not self.connected or self.supervisor.shutting_down:
            return
        # Alive and connected, yet the topic says offline: a Last Will from an older connection
        # (or a previous agent's) arrived after this connection's status. Say again who is live.
        log.warning(
            "overwriting a stale offline status (seq %d; this connection is seq %d)",
            seen.seq,
            self.conn_seq,
        )
        self.publish(force=True)


def publish_delay(status: AgentStatus, last: AgentStatus | None) -> float:
    """Seconds a changed status may wait before it is published; a newer one replaces it.

    A fresh `stopping` waits STOPPING_QUIET: most brains exit on SIGTERM within milliseconds,
    and then the next state (starting, idle) says all there is to say, without one more
    message per robot through the broker to every reader. Anything else goes at once."""
    fresh_stop = last is None or last.state != AgentState.STOPPING
    return STOPPING_QUIET if status.state == AgentState.STOPPING and fresh_stop else 0.0
