"""The robot's goals topics: the brain's socket read on the agent's loop, the relay's summary and
records published, the brain's readiness told to the supervisor.

The rules are agent/relay.py's, the socket agent/brain_socket.py's; this is what the agent does
with them: it follows the supervisor (a brain started, exited, a new request), hands the lines
on, and sends what the relay says is due (the summary retained, the records as a stream, both
QoS 1).
"""

from __future__ import annotations

import logging
import secrets
import time

from robotconf.agent.brain_socket import BrainSocket
from robotconf.agent.broker_link import BrokerLink
from robotconf.agent.config import AgentConfig
from robotconf.agent.relay import GoalsRelay, Limits, Now, Signal
from robotconf.agent.supervisor import Effect, Supervisor
from robotconf.agent.workdir import SOCKET_FILE

log = logging.getLogger("robotconf.agent")


def now_pair() -> Now:
    return Now(time.monotonic(), time.time())


def run_id(wall: float) -> str:
    """The agent's id of one brain start: when (UTC, to the second) and a random tail, so that
    two starts never share one, across the agent's own restarts too."""
    return time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(wall)) + "-" + secrets.token_hex(3)


class GoalsReport:
    """One robot's brain socket and goals topics."""

    def __init__(self, config: AgentConfig, link: BrokerLink, supervisor: Supervisor) -> None:
        settings = config.goals
        self.link = link
        self.supervisor = supervisor
        self.socket = BrainSocket(config.workdir / SOCKET_FILE)
        self.relay = GoalsRelay(
            config.robot_id,
            Limits(
                stale_after=settings.stale_after,
                lines_per_second=settings.lines_per_second,
                line_burst=2 * settings.lines_per_second,
                records_per_second=settings.records_per_second,
                record_burst=2 * settings.records_per_second,
            ),
        )
        self._pid: int | None = None

    @property
    def path(self) -> str:
        return str(self.socket.path)

    def begin(self) -> None:
        """Before any brain starts: the socket exists when it looks for it."""
        problem = self.socket.open()
        if problem is not None:
            log.error("%s; the brain's goals are not relayed", problem)

    def close(self) -> None:
        self.socket.close()

    # ------------------------------------------------------------ the loop

    def watches(self, now: float) -> dict[int, object]:
        return self.socket.watches(now)

    def due(self, now: float, connected: bool) -> float | None:
        times = [t for t in (self.relay.due(connected), self.socket.due(now)) if t is not None]
        return min(times) if times else None

    def read(self, ready: set[int], mono: float) -> list[Signal]:
        """What the brain wrote since the last pass, through the relay; the readiness heard."""
        taken = self.socket.service(ready, mono)
        self.relay.refused(taken.refused)
        if not taken.lines:
            return []
        return self.relay.lines(taken.lines, Now(mono, time.time()))

    def tell(self, signals: list[Signal], now: float) -> list[Effect]:
        """The brain's hello and ready, to the supervisor; its effects to be carried out."""
        effects: list[Effect] = []
        for signal in signals:
            if signal is Signal.HELLO:
                effects += self.supervisor.hello(now)
            else:
                effects += self.supervisor.ready(now)
        return effects

    def follow(self, mono: float) -> None:
        """What the supervisor did this pass: a brain started or gone, a new request."""
        sup = self.supervisor
        now = Now(mono, time.time())
        if sup.pid != self._pid:
            if self._pid is not None:
                self.socket.drop_connections()
                self.relay.brain_exited(now)
            self._pid = sup.pid
            if sup.pid is not None:
                self.relay.brain_started(run_id(now.wall), now)
            self.socket.accepting = sup.pid is not None
        brain = sup.brain
        if brain is None:
            self.relay.request(None, None, None, now)
        else:
            request = brain.request
            self.relay.request(request.digest, request.revision, request.scenario.name, now)

    def owns(self, fd: int) -> bool:
        return self.socket.owns(fd)

    def publish(self, mono: float, connected: bool, final: bool = False) -> None:
        now = Now(mono, time.time())
        self.relay.tick(now)
        out = self.relay.publishes(now, connected, final)
        for record in out.records:
            self.link.publish_outcome(record.model_dump_json().encode("utf-8"))
        if out.summary is not None:
            self.link.publish_goals(out.summary.model_dump_json().encode("utf-8"))

    def connected(self) -> None:
        self.relay.connected()
