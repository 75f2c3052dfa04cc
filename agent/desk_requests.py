"""What the desk asks of a robot's agent: a restart of its brain, and the brain's log.

Admitted or refused here; what the brain must do about an admitted restart is the supervisor's.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from robotconf.agent import admission, process
from robotconf.agent.broker_link import BrokerLink
from robotconf.agent.events import RestartMessage
from robotconf.agent.logs import LogStream
from robotconf.agent.supervisor import Effect, Supervisor
from robotconf.agent.workdir import RestartLedger
from robotconf.contract.clock import now as now_wall
from robotconf.contract.throttle import Throttle

log = logging.getLogger("robotconf.agent")

REFUSAL_LOG_EVERY = 10.0  # seconds: at most a few lines per this about refused desk requests


class DeskRequests:
    """Restart and logs requests from the desk, and the log's answers going out."""

    def __init__(
        self,
        robot_id: str,
        workdir: Path,
        verify: admission.Verifier | None,
        supervisor: Supervisor,
        logs: LogStream,
        brain_log: process.BrainLog,
        link: BrokerLink,
    ) -> None:
        self.robot_id = robot_id
        self.verify = verify
        self.supervisor = supervisor
        self.logs = logs
        self.brain_log = brain_log
        self.link = link
        self.restarts = RestartLedger(workdir)
        self.refusals = Throttle(REFUSAL_LOG_EVERY, limit=5)

    def restart(self, event: RestartMessage, now: float) -> list[Effect]:
        """A restart from the desk: carried out (the effects returned) once verified, fresh and
        addressed here; anything else does nothing but a (throttled) line in the agent's and
        the brain's log."""
        if event.retained:
            self.refused(
                "restart refused: it came retained, and a retained restart would fire at "
                "every reconnect; publish it without the retain flag"
            )
            return []
        memory = admission.RestartMemory.of(self.restarts.watermark, self.restarts.ahead)
        wall = now_wall()
        outcome = admission.interpret_restart(
            event.payload, self.robot_id, self.verify, memory, wall
        )
        if isinstance(outcome, admission.Reject):
            self.refused(f"restart refused: {outcome.reason}")
            return []
        # Remembered before it is carried out: whatever follows, it is not carried out twice.
        done = memory.carried_out(outcome, wall)
        self.restarts.record(done.watermark, done.ahead_entries())
        effects, problem = self.supervisor.restart(outcome.requested_by, outcome.issued_at, now)
        if problem is not None:
            self.refused(f"restart requested by {outcome.requested_by} not carried out: {problem}")
            return []
        log.info("restart requested by %s", outcome.requested_by)
        self.brain_log.note(f"restart requested by {outcome.requested_by}")
        return effects

    def ask_logs(self, payload: bytes, now: float) -> None:
        request = admission.interpret_logs_request(payload)
        if isinstance(request, admission.Reject):
            self.refused(f"logs request refused: {request.reason}")
            return
        if not self.logs.following and request.follow:
            log.info("streaming the brain's log to the desk while asked")
        refusal = self.logs.ask(request, now)
        if refusal is not None:
            self.refused(f"logs request ignored: {refusal}")

    def refused(self, line: str) -> None:
        """A desk request that does nothing: said in the agent's log and, for the operator
        (`robotconf logs`), in the brain's; a few times per REFUSAL_LOG_EVERY at most, since
        anyone who may publish on this robot's topics could otherwise fill its disk."""
        said = self.refusals.admit(line, time.monotonic())
        if said is not None:
            log.warning("%s", said)
            self.brain_log.note(said)

    def send_logs(self, now: float) -> None:
        """The log answers due now (the link is up); a bug here stops the stream, never the
        agent."""
        try:
            self.logs.poll(now)
            for chunk in self.logs.take(now):
                self.link.publish_logs(chunk.model_dump_json().encode("utf-8"))
        except Exception:
            log.exception("internal error while sending the brain's log; the stream stops")
            self.logs.stop()
