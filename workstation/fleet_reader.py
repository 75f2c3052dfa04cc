"""The one incremental fleet reader of `status --watch`, the browser view and `up`'s screen: the
fleet read whole when it must (as `status` does), else only the robots whose topics changed,
their rows made by `build_rows` and merged: a change to one robot costs that robot."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import replace

from robotconf.configurator.drift import DriftMemo
from robotconf.contract.mqtt import Connection
from robotconf.contract.wire import ReconcilerStatus, Topics
from robotconf.readmodel.observed import ReadMemo, parse_retained
from robotconf.readmodel.retained import RetainedView
from robotconf.readmodel.verdicts import (
    DesiredRobot,
    FleetStatus,
    RobotRow,
    build_rows,
    desired_from_retained,
    row_order,
)
from robotconf.workstation.fleet_status import (
    Desired,
    DesiredSource,
    Given,
    change_key,
    fleet_status,
    open_view,
)

LEAVES = ("launch", "status", "description", "interfaces", "goals")
log = logging.getLogger("robotconf.fleet")

INCREMENTAL_MAX = 500  # robots changed at once beyond which the whole fleet is read again


class FleetReader:
    """Reads the view into a FleetStatus; `touched(topic)` (on paho's thread: the view's
    `on_topic`) says what moved. A new revision's desired state is made on a thread of its own
    (10,000 robots: seconds), the rows kept live meanwhile; `wake` is called when it is ready.
    `rows_made`: the robots whose rows the last read made (all of them when read whole)."""

    def __init__(
        self,
        view: RetainedView,
        topics: Topics,
        desired: DesiredSource,
        wake: Callable[[], None] = lambda: None,
    ) -> None:
        self.view = view
        self.topics = topics
        self._desired = desired
        self._wake = wake
        self._lock = threading.Lock()
        self._moved: set[str] = set()
        self._memos: dict[bool, ReadMemo] = {}
        self._drift = DriftMemo()
        self._wanted: Desired | None = None  # the desired state the rows are made with
        self._wanted_for: str | None = None  # ... for this applied revision
        self._loader: threading.Thread | None = None
        self._loaded: tuple[str | None, Desired] | None = None
        self._failed_for: str | None = None
        self.rows_made = 0

    def touched(self, topic: str) -> None:
        with self._lock:
            self._moved.add(topic)

    def read(self, before: FleetStatus | None, whole: bool) -> tuple[FleetStatus, set[str] | None]:
        """The fleet now, and the robots whose rows may differ from `before`'s (None: any)."""
        with self._lock:
            moved, self._moved = self._moved, set()
        robots = {where[0] for topic in moved if (where := self.topics.robot_of(topic))}
        reconciler = before.reconciler if before is not None else None
        if before is None or self.topics.reconciler_status in moved:
            payload = self.view.get(self.topics.reconciler_status)
            messages = {self.topics.reconciler_status: payload} if payload else {}
            reconciler = parse_retained(messages, self.topics).reconciler
        applied = reconciler.last_applied_revision if reconciler is not None else None
        if self._wanted is None:  # nothing to show without it: made here, once
            self._wanted, self._wanted_for = self._desired.get(reconciler), applied
            whole = True
        elif self._adopt():
            whole = True  # another revision to compare with: every robot
        elif applied not in (self._wanted_for, self._failed_for):
            self._load(reconciler, applied)
        if (
            whole
            or before is None
            or self.view.lost is not None
            or len(robots) > INCREMENTAL_MAX
            or _held(reconciler) != _held(before.reconciler)
        ):
            fleet = self._whole()
            self.rows_made = len(fleet.rows)
            return fleet, None
        self.rows_made = len(robots)
        return self._some(before, robots), robots

    def _adopt(self) -> bool:
        """True when a desired state made on the loader's thread is now the one in use."""
        with self._lock:
            loaded, self._loaded = self._loaded, None
        if loaded is None:
            return False
        self._wanted_for, self._wanted = loaded
        return True

    def _load(self, reconciler: ReconcilerStatus | None, applied: str | None) -> None:
        if self._loader is not None and self._loader.is_alive():
            return  # the next read starts the next one, if the revision moved again

        def run() -> None:
            try:
                made = self._desired.get(reconciler)
            except Exception:  # a bug: the rows stay on the revision before, said in the log
                log.exception("ui: the desired state of %s could not be made", applied)
                self._failed_for = applied
            else:
                with self._lock:
                    self._loaded = (applied, made)
            self._wake()

        self._loader = threading.Thread(target=run, name="ui-desired", daemon=True)
        self._loader.start()

    def _whole(self) -> FleetStatus:
        assert self._wanted is not None
        return fleet_status(
            self.view.snapshot(),
            self.topics,
            Given(self._wanted),
            self._memos,
            self._drift,
            self.view.lost,
        )

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
        ordered = sorted(rows.values(), key=row_order)
        return replace(before, rows=ordered, reconciler=retained.reconciler)


def _held(status: ReconcilerStatus | None) -> list[str]:
    """The robots the reconciler holds back for drift: their rows' reasons say it."""
    return [h.robot for h in status.held] if status is not None else []


def open_reader(
    connection: Connection, prefix: str, desired: DesiredSource, on_change: Callable[[], None]
) -> tuple[RetainedView, FleetReader]:
    """A (not yet started) view of the fleet's retained topics, and the reader it tells of
    each topic that moves."""
    readers: list[FleetReader] = []
    view = open_view(connection, prefix, on_change, lambda topic: readers[0].touched(topic))
    readers.append(FleetReader(view, Topics(prefix), desired, on_change))
    return view, readers[0]


def watch(
    view: RetainedView, reader: FleetReader, changed: threading.Event, stop: threading.Event
) -> Iterator[FleetStatus | None]:
    """Each new state of the fleet until `stop` is set; None once when the broker is lost (each
    time). `changed` is set by the view (and by whoever sets `stop`); the view tells `reader`
    of each topic (its `on_topic`), so a change costs the robots it touched."""
    shown: str | None = None
    fleet: FleetStatus | None = None
    while not stop.is_set():
        changed.clear()
        if view.synced:
            fleet, _ = reader.read(fleet, whole=shown in (None, "offline"))
            key = change_key(fleet)
            if key != shown:
                shown = key
                yield fleet
        elif shown != "offline":
            shown = "offline"
            yield None
        changed.wait(5.0)
        time.sleep(0.2)  # coalesce a burst of status messages into one redraw
