"""The one fleet watcher of the tests and benches: the retained topics as `robotconf status`
reads them, every agent status in arrival order, and the live launches, with waits on them.

Built on the reconciler's own RetainedView; nothing here asserts on timing.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol, TypeVar

import paho.mqtt.client as paho
from pydantic import ValidationError

from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.mqtt import Connection
from robotconf.contract.safejson import PayloadError
from robotconf.contract.wire import (
    AgentState,
    AgentStatus,
    ReconcilerStatus,
    RobotDescription,
    Topics,
)
from robotconf.readmodel.observed import parse_retained
from robotconf.readmodel.retained import RetainedView, read_object

TIMEOUT = 60.0  # generous: CI machines are slow and shared
T = TypeVar("T")


class HasLog(Protocol):
    def log_tail(self, lines: int = 30) -> str: ...


class StatusListener(Protocol):
    """Called on the network thread for every readable agent status, with its arrival time
    (time.perf_counter()); must not block."""

    def __call__(self, robot_id: str, status: AgentStatus, arrived: float, /) -> None: ...


def wait_for(probe: Callable[[], T | None], what: str, timeout: float = TIMEOUT) -> T:
    """Polls until `probe` returns something truthy, and returns it."""
    deadline = time.monotonic() + timeout
    while True:
        found = probe()
        if found:
            return found
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.05)


class FleetWatch:
    """Every retained robot and reconciler topic under a prefix, the history of each robot's
    statuses, and a log of live (not retained) launches."""

    def __init__(
        self,
        broker: str | Connection,
        prefix: str = "robotconf",
        *,
        listener: StatusListener | None = None,
        timeout: float = TIMEOUT,
    ) -> None:
        self.topics = Topics(prefix)
        self.timeout = timeout
        self._listener = listener
        self._cond = threading.Condition()
        self.statuses: dict[str, list[AgentStatus]] = {}
        self.timeline: list[tuple[float, str, AgentStatus]] = []  # (arrival, robot, status)
        self.live_launches: list[tuple[str, bytes, float]] = []
        self.view = RetainedView(
            broker if isinstance(broker, Connection) else Connection(broker),
            [
                self.topics.all_launch,
                self.topics.all_status,
                self.topics.all_description,
                self.topics.reconciler_status,
            ],
            f"{prefix}/sync",
            role="watch",
            on_change=self._changed,
        )
        # A second paho handler on the view's client sees each message once, with its retain
        # flag and before the view files it: the history and the live launches.
        client: paho.Client = self.view._client
        client.message_callback_add(self.topics.all_launch, self._on_launch)
        client.message_callback_add(self.topics.all_status, self._on_status)
        self.view.start()
        assert self.view.wait_synced(timeout), "the watcher could not reach the broker"

    # ------------------------------------------------------------------ paho thread

    def _changed(self) -> None:
        with self._cond:
            self._cond.notify_all()

    def _on_launch(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        if not message.retain:
            with self._cond:
                self.live_launches.append(
                    (message.topic, bytes(message.payload), time.perf_counter())
                )
        self.view._handle_message(client, userdata, message)

    def _on_status(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        arrived = time.perf_counter()
        found = self.topics.robot_of(message.topic)
        if found is not None and message.payload:
            try:  # tests publish garbage on these topics too: only agents' statuses count
                status = AgentStatus.model_validate(read_object(bytes(message.payload)))
            except (PayloadError, ValidationError):
                status = None
            if status is not None:
                with self._cond:
                    self.statuses.setdefault(found[0], []).append(status)
                    self.timeline.append((arrived, found[0], status))
                if self._listener is not None:
                    self._listener(found[0], status, arrived)
        self.view._handle_message(client, userdata, message)

    def close(self) -> None:
        self.view.stop()

    # ------------------------------------------------------------------ what the broker holds

    def retained(self) -> dict[str, bytes]:
        return self.view.snapshot()

    def launch(self, robot_id: str) -> dict[str, Any] | None:
        payload = self.retained().get(self.topics.launch(robot_id))
        return read_object(payload) if payload else None

    def digest(self, robot_id: str) -> str | None:
        """The digest retained on a robot's launch topic; "unreadable", or None for nothing."""
        payload = self.retained().get(self.topics.launch(robot_id))
        if not payload:
            return None
        seen = parse_retained({self.topics.launch(robot_id): payload}, self.topics, requests=False)
        robot = seen.robots.get(robot_id)
        if robot is None or not robot.launch_retained:
            return None
        return robot.launch_digest or "unreadable"

    def status(self, robot_id: str) -> AgentStatus | None:
        """The retained status of a robot; None when there is none or it is unreadable."""
        payload = self.retained().get(self.topics.status(robot_id))
        try:
            return AgentStatus.model_validate(read_object(payload)) if payload else None
        except (PayloadError, ValidationError):
            return None

    def description(self, robot_id: str) -> RobotDescription | None:
        payload = self.retained().get(self.topics.description(robot_id))
        try:
            return RobotDescription.model_validate(read_object(payload)) if payload else None
        except (PayloadError, ValidationError):
            return None

    def reconciler(self) -> ReconcilerStatus | None:
        """The retained reconciler status; None when there is none or it is unreadable."""
        return parse_retained(
            {
                self.topics.reconciler_status: self.retained().get(
                    self.topics.reconciler_status, b""
                )
            },
            self.topics,
        ).reconciler

    # ------------------------------------------------------------------ history

    def history(self, robot_id: str) -> list[AgentStatus]:
        with self._cond:
            return list(self.statuses.get(robot_id, []))

    def latest(self, robot_id: str) -> AgentStatus | None:
        seen = self.history(robot_id)
        return seen[-1] if seen else None

    # ------------------------------------------------------------------ waiting

    def wait(self, probe: Callable[[], T | None], what: str, timeout: float | None = None) -> T:
        """Whatever `probe` returns once it is truthy; woken by every message."""
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        with self._cond:
            while True:
                found = probe()
                if found:
                    return found
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise AssertionError(f"timed out waiting for {what}")
                self._cond.wait(min(remaining, 0.5))

    def wait_for(
        self,
        robot_id: str,
        predicate: Callable[[AgentStatus], bool],
        what: str,
        timeout: float | None = None,
        agent: HasLog | None = None,
    ) -> AgentStatus:
        """The robot's latest status once it satisfies `predicate`."""

        def probe() -> AgentStatus | None:
            latest = self.latest(robot_id)
            return latest if latest is not None and predicate(latest) else None

        try:
            return self.wait(probe, f"{robot_id}: {what}", timeout)
        except AssertionError:
            trail = "\n".join(
                f"  {s.state.value} pid={s.pid} seq={s.seq} {s.message}"
                for s in self.history(robot_id)[-10:]
            )
            log = f"\nagent log:\n{agent.log_tail()}" if agent is not None else ""
            raise AssertionError(
                f"timed out waiting for {robot_id}: {what}; statuses:\n{trail}{log}"
            ) from None

    def wait_seen(
        self,
        robot_id: str,
        predicate: Callable[[AgentStatus], bool],
        what: str,
        since: int = 0,
        timeout: float | None = None,
    ) -> AgentStatus:
        """A status from `since` (a history index) on that satisfies `predicate`, even if a
        newer one has replaced it already."""

        def probe() -> AgentStatus | None:
            return next((s for s in self.history(robot_id)[since:] if predicate(s)), None)

        return self.wait(probe, f"{robot_id}: {what}", timeout)

    def wait_state(
        self, robot_id: str, state: AgentState, agent: HasLog | None = None, **fields: Any
    ) -> AgentStatus:
        def matches(status: AgentStatus) -> bool:
            return status.state == state and all(
                getattr(status, key) == value for key, value in fields.items()
            )

        described = ", ".join(f"{k}={v}" for k, v in fields.items())
        return self.wait_for(robot_id, matches, f"state {state.value} {described}", agent=agent)

    def running(self, requests: Mapping[str, RenderedRequest]) -> dict[str, AgentStatus] | None:
        """Every robot's status when each one runs its request's digest, else None."""
        found = {}
        for robot_id, request in requests.items():
            status = self.status(robot_id)
            if status is None or status.state is not AgentState.RUNNING:
                return None
            if status.digest != request.digest or status.pid is None:
                return None
            found[robot_id] = status
        return found

    def wait_running(self, requests: Mapping[str, RenderedRequest]) -> dict[str, AgentStatus]:
        return self.wait(lambda: self.running(requests), f"{sorted(requests)} running")

    def wait_reconciler(
        self, predicate: Callable[[ReconcilerStatus], bool], what: str
    ) -> ReconcilerStatus:
        def probe() -> ReconcilerStatus | None:
            status = self.reconciler()
            return status if status is not None and predicate(status) else None

        return self.wait(probe, f"reconciler status: {what}")
