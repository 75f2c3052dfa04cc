"""Watches the goals topics of every robot: the retained summaries and the outcome records.

For the agent's tests and benches; nothing here asserts on timing.
"""

from __future__ import annotations

import threading
import uuid
from collections.abc import Callable
from typing import Any, TypeVar

import paho.mqtt.client as paho

from robotconf.contract.goals import GoalsSummary, OutcomeRecord
from robotconf.contract.mqtt import Connection, make_client
from robotconf.contract.wire import Topics
from tests.support.watch import TIMEOUT, wait_for

T = TypeVar("T")


class GoalsWatch:
    """Every summary (in arrival order, per robot) and record under a prefix."""

    def __init__(self, broker: str, prefix: str = "robotconf") -> None:
        self.topics = Topics(prefix)
        self._lock = threading.Lock()
        self.summaries: dict[str, list[GoalsSummary]] = {}
        self.records: dict[str, list[OutcomeRecord]] = {}
        self.retained_flags: list[bool] = []
        self._subscribed = threading.Event()
        connection = Connection(url=broker)
        self.client = make_client(connection, client_id=f"goals-watch-{uuid.uuid4().hex[:8]}")
        self.client.on_connect = self._on_connect
        self.client.on_subscribe = lambda *args: self._subscribed.set()
        self.client.on_message = self._on_message
        address = connection.address
        self.client.connect(address.host, address.port)
        self.client.loop_start()
        assert self._subscribed.wait(TIMEOUT), "the goals watcher could not subscribe"

    def _on_connect(self, client: paho.Client, u: Any, f: Any, rc: Any, p: Any) -> None:
        client.subscribe([(self.topics.all_goals, 1), (self.topics.all_goal_outcomes, 1)])

    def _on_message(self, client: paho.Client, u: Any, message: paho.MQTTMessage) -> None:
        parts = message.topic.split("/")
        if len(parts) < 4 or not message.payload:
            return
        robot = parts[2]
        if message.topic.endswith("/goals/outcomes"):
            record = OutcomeRecord.model_validate_json(message.payload)
            with self._lock:
                self.records.setdefault(robot, []).append(record)
                self.retained_flags.append(bool(message.retain))
        else:
            summary = GoalsSummary.model_validate_json(message.payload)
            with self._lock:
                self.summaries.setdefault(robot, []).append(summary)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()

    def latest(self, robot: str) -> GoalsSummary | None:
        with self._lock:
            seen = self.summaries.get(robot)
            return seen[-1] if seen else None

    def records_of(self, robot: str) -> list[OutcomeRecord]:
        with self._lock:
            return list(self.records.get(robot, []))

    def wait_summary(
        self, robot: str, check: Callable[[GoalsSummary], bool], what: str, timeout: float = TIMEOUT
    ) -> GoalsSummary:
        def probe() -> GoalsSummary | None:
            summary = self.latest(robot)
            return summary if summary is not None and check(summary) else None

        try:
            return wait_for(probe, what, timeout)
        except AssertionError as exc:
            raise AssertionError(f"{exc}; the latest summary: {self.latest(robot)}") from None

    def wait_records(self, robot: str, count: int, timeout: float = TIMEOUT) -> list[OutcomeRecord]:
        def probe() -> list[OutcomeRecord] | None:
            records = self.records_of(robot)
            return records if len(records) >= count else None

        return wait_for(probe, f"{count} outcome records of {robot}", timeout)
