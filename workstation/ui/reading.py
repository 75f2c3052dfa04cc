"""The fleet read from the broker: whole when it must (as `status` does), else only the robots
whose topics changed, their rows made by `build_rows` and merged (0.4 s less at 10,000 robots)."""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import replace

from configurator.drift import DriftMemo
from contract.wire import ReconcilerStatus, Topics
from reconciler.observed import ReadMemo, parse_retained
from reconciler.retained import RetainedView
from reconciler.verdicts import (
    DesiredRobot,
    FleetStatus,
    RobotRow,
    build_rows,
    desired_from_retained,
)
from workstation.fleet_status import Desired, DesiredCache, fleet_status
from workstation.ui.model import rank

LEAVES = ("launch", "status", "description", "interfaces")
INCREMENTAL_MAX = 500  # robots changed at once beyond which the whole fleet is read again


class FleetReader:
    """Reads the view into a FleetStatus; `touched(topic)` (on paho's thread) says what moved."""

    def __init__(self, view: RetainedView, topics: Topics, desired: DesiredCache) -> None:
        self.view = view
        self.topics = topics
        self._desired = desired
        self._lock = threading.Lock()
        self._moved: set[str] = set()
        self._memos: dict[bool, ReadMemo] = {}
        self._drift = DriftMemo()
        self._wanted: Desired | None = None  # the desired state the rows were made with

    def touched(self, topic: str) -> None:
        with self._lock:
            self._moved.add(topic)

    def read(self, before: FleetStatus | None, whole: bool) -> tuple[FleetStatus, set[str] | None]:
        """The fleet now, and the robots whose rows may differ from `before`'s (None: any)."""
        with self._lock:
            moved, self._moved = self._moved, set()
        robots = {where[0] for topic in moved if (where := self.topics.robot_of(topic))}
        reconciler_moved = self.topics.reconciler_status in moved
        if whole or before is None or self.view.lost is not None or len(robots) > INCREMENTAL_MAX:
            return self._whole(), None
        reconciler = before.reconciler
        if reconciler_moved:
            payload = self.view.get(self.topics.reconciler_status)
            messages = {self.topics.reconciler_status: payload} if payload else {}
            reconciler = parse_retained(messages, self.topics).reconciler
            if _held(reconciler) != _held(before.reconciler):
                return self._whole(), None
        if self._desired.get(reconciler) is not self._wanted:
            return self._whole(), None  # another revision to compare with: every robot
        return self._some(before, robots), robots

    def _whole(self) -> FleetStatus:
        fleet = fleet_status(
            self.view.snapshot(),
            self.topics,
            self._desired,
            self._memos,
            self._drift,
            self.view.lost,
        )
        self._wanted = self._desired.get(fleet.reconciler)
        return fleet

    def _some(self, before: FleetStatus, robots: set[str]) -> FleetStatus:
        """`before` with the rows of `robots` made again from their topics now."""
        messages: dict[str, bytes] = {}
        for robot_id in robots:
            for leaf in LEAVES:
                topic = getattr(self.topics, leaf)(robot_id)
                payload = self.view.get(topic)
                if payload:
                    messages[topic] = payload
        status_payload = self.view.get(self.topics.reconciler_status)
        if status_payload:
            messages[self.topics.reconciler_status] = status_payload
        assert self._wanted is not None
        wanted = self._wanted[0]
        retained = parse_retained(messages, self.topics, requests=wanted is None)
        desired: Mapping[str, DesiredRobot] = (
            {r: wanted[r] for r in robots if r in wanted}
            if wanted is not None
            else desired_from_retained(retained)
        )
        rows: dict[str, RobotRow] = {row.robot_id: row for row in before.rows}
        for robot_id in robots:
            rows.pop(robot_id, None)
        for row in build_rows(desired, retained):
            rows[row.robot_id] = row
        ordered = sorted(rows.values(), key=rank)
        return replace(before, rows=ordered, reconciler=retained.reconciler)


def _held(status: ReconcilerStatus | None) -> list[str]:
    """The robots the reconciler holds back for drift: their rows' reasons say it."""
    return [h.robot for h in status.held] if status is not None else []
