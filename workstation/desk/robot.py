"""The desk's client on one robot: one broker client on its topics that tells what the broker
knows of it, finds it online (or says why not), sends it a request and hands back its answers;
the logs and the restarts (workstation/desk/logs.py, restart.py) stand on it.
"""

from __future__ import annotations

import contextlib
import difflib
import queue
from dataclasses import dataclass
from typing import TypeVar

from pydantic import ValidationError

from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.mqtt import Connection
from robotconf.contract.safejson import PayloadError
from robotconf.contract.textsafe import printable
from robotconf.contract.topics import Role, subscriptions
from robotconf.contract.wire import MAX_LOG_MESSAGE_BYTES, AgentStatus, LogsChunk, Topics
from robotconf.readmodel.observed import RobotSeen, parse_retained
from robotconf.readmodel.retained import RetainedView, read_object, take_snapshot
from robotconf.workstation.desk.broker import wait_for_broker

# Answers are bounded by the agent; anything much larger is not one of its answers.
MAX_ANSWER_BYTES = MAX_LOG_MESSAGE_BYTES + 4096
QUEUE_LIMIT = 10_000  # answers waiting to be printed; beyond, a flood is dropped
T = TypeVar("T")


@dataclass(frozen=True)
class Unknown:
    """The broker knows nothing of the robot: nothing retained under its id."""

    robot_id: str
    known: list[str]

    def message(self, url: str) -> str:
        close = difflib.get_close_matches(self.robot_id, self.known, n=3)
        # Ids come from topic names anyone allowed on the broker may make up: shown escaped.
        hint = f"; did you mean {', '.join(printable(c) for c in close)}?" if close else ""
        count = len(self.known)
        return (
            f"unknown robot {self.robot_id!r}: {url} holds no status, description or launch "
            f"request for it ({count} robot{'s' if count != 1 else ''} known){hint}"
        )


class RobotDesk:
    """A client on one robot's retained topics (status, description, launch) and, with
    `logs`, its log topic; `statuses` and `chunks` queue what arrives, in order."""

    def __init__(self, connection: Connection, prefix: str, robot_id: str, *, logs: bool) -> None:
        self.connection = connection
        self.topics = Topics(prefix)
        self.robot_id = robot_id
        self._status_topic = self.topics.status(robot_id)
        self._logs_topic = self.topics.logs(robot_id)
        self.statuses: queue.Queue[AgentStatus] = queue.Queue(QUEUE_LIMIT)
        self.chunks: queue.Queue[LogsChunk] = queue.Queue(QUEUE_LIMIT)
        keys = ["status", "description", "launch"] + (["logs"] if logs else [])
        self.view = RetainedView(
            connection,
            subscriptions(Role.OPERATOR, prefix, *keys, robot_id=robot_id),
            self.topics.sync,
            role="desk",
            on_payload=self._arrived,
            max_payload=MAX_ANSWER_BYTES,
        )

    def __enter__(self) -> RobotDesk:
        self.view.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.view.stop()

    def robot(self) -> RobotSeen | None:
        """The robot as its retained topics show it; None when nothing is retained for it."""
        retained = parse_retained(self.view.snapshot(), self.topics)
        return retained.robots.get(self.robot_id)

    def unknown(self, timeout: float) -> Unknown:
        """Why the robot is unknown, with the ids the broker does know (for a suggestion)."""
        t = self.topics
        messages = take_snapshot(
            self.connection,
            subscriptions(Role.OPERATOR, t.prefix, "status", "description", "launch"),
            t.sync,
            "desk-robots",
            timeout,
        )
        known = sorted(parse_retained(messages or {}, t, requests=False).robots)
        return Unknown(self.robot_id, known)

    def send(self, topic: str, payload: bytes, timeout: float) -> bool:
        return self.view.publish(topic, payload, timeout)

    # Runs on paho's thread (guarded by the view): parse, queue, nothing else.
    def _arrived(self, topic: str, payload: bytes) -> None:
        try:
            if topic == self._logs_topic:
                chunk = LogsChunk.model_validate(read_object(payload, MAX_ANSWER_BYTES))
                if chunk.robot_id == self.robot_id:
                    _put(self.chunks, chunk)
            elif topic == self._status_topic and payload:
                status = AgentStatus.model_validate(read_object(payload, MAX_ANSWER_BYTES))
                _put(self.statuses, status)
        except (PayloadError, ValidationError, ValueError):
            return  # not an answer of an agent: nothing to show


def online_robot(desk: RobotDesk, wait: float, why_online: str) -> RobotSeen:
    """The robot as the broker knows it, once its retained topics are read; raises CliError
    when the broker does not answer, knows nothing of the robot, or has it offline."""
    url = desk.connection.address.url
    wait_for_broker(desk.view, wait)
    robot = desk.robot()
    if robot is None:
        raise CliError(desk.unknown(wait).message(url), ExitCode.FINDINGS)
    if not robot.online:
        raise CliError(
            f"{desk.robot_id} is offline: {why_online} (robotconf status {desk.robot_id})",
            ExitCode.FINDINGS,
        )
    return robot


def _put(target: queue.Queue[T], item: T) -> None:
    with contextlib.suppress(queue.Full):  # a flood: what does not fit is not shown
        target.put_nowait(item)
