"""The live fleet: the viewer's broker client and the repository, one Snapshot per change, each
robot's recent history, and each open page's event stream fed with what changed for it."""

from __future__ import annotations

import collections
import itertools
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

from robotconf.configurator.gcpause import collector_paused
from robotconf.contract.mqtt import Connection
from robotconf.contract.textsafe import printable
from robotconf.contract.wire import Topics
from robotconf.readmodel.verdicts import FleetStatus, reconciler_health
from robotconf.workstation.fleet_reader import FleetReader
from robotconf.workstation.fleet_status import DesiredCache, open_view
from robotconf.workstation.ui.changes import Shown, Views, change, changed_rows, first
from robotconf.workstation.ui.model import HISTORY, HistoryEntry, Snapshot

log = logging.getLogger("robotconf.ui")

TICK = 1.0  # seconds between looks at what time alone changes (the broker lost, a heartbeat)
COALESCE = 0.05  # seconds a burst of messages is gathered into one change
MAX_STREAMS = 1000  # event streams at once (the edge's connection cap is lower)


class Sink(Protocol):
    """Where one stream's events go (readmodel.http_edge.FedStream)."""

    closed: bool

    def put(self, chunk: bytes) -> None: ...

    def end(self) -> None: ...


@dataclass
class _Stream:
    shown: Shown
    sink: Sink
    page_version: int | None
    started: bool = False


class LiveFleet:
    """Reads the broker on paho's thread and works out each new state on a thread of its own;
    `snapshot` is the latest, read from any thread."""

    def __init__(
        self, connection: Connection, prefix: str, repo: Path, rev: str | None = None
    ) -> None:
        self.topics = Topics(prefix)
        self.broker = connection.address.url
        self._dirty = threading.Event()  # the broker's topics changed
        self._wake = threading.Event()  # ... or a stream wants its first event
        self.view = open_view(connection, prefix, self._touched, self._topic)
        self._reader = FleetReader(self.view, self.topics, DesiredCache(repo, rev), self._touched)
        self._snap = Snapshot(0, None, self.broker, False, "connecting", time.time())
        self._lock = threading.Lock()
        self._streams: dict[int, _Stream] = {}
        self._ids = itertools.count(1)
        self._history: dict[str, collections.deque[HistoryEntry]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ui-fleet", daemon=True)
        self.on_step: Callable[[Snapshot, float], None] | None = None  # for the bench

    def _touched(self) -> None:
        self._dirty.set()
        self._wake.set()

    def _topic(self, topic: str) -> None:
        self._reader.touched(topic)

    def start(self) -> None:
        self.view.start()
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(10)
        self.view.stop()
        with self._lock:
            streams, self._streams = list(self._streams.values()), {}
        for stream in streams:
            stream.sink.end()

    @property
    def snapshot(self) -> Snapshot:
        return self._snap

    def payload(self, topic: str) -> bytes | None:
        return self.view.get(topic)

    # ------------------------------------------------------------------ streams (any thread)

    def subscribe(self, shown: Shown, sink: Sink, page_version: int | None) -> int | None:
        """A page's stream, fed from the next step on; None when too many are open."""
        with self._lock:
            if len(self._streams) >= MAX_STREAMS:
                return None
            key = next(self._ids)
            self._streams[key] = _Stream(shown, sink, page_version)
        self._wake.set()
        return key

    def unsubscribe(self, key: int) -> None:
        with self._lock:
            self._streams.pop(key, None)

    # ------------------------------------------------------------------ the worker

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(TICK)
            if self._stop.is_set():
                return
            if self._dirty.is_set():
                time.sleep(COALESCE)  # a burst of status messages is one change
            self._wake.clear()
            try:
                self.step()
            except Exception:  # a bug in one step: logged, the next step tries again
                log.exception("ui: working out the fleet's state failed")
                time.sleep(TICK)

    def step(self) -> None:
        """One new state (when anything changed) and the events it makes."""
        # A first read makes 10,000 rows and history entries that all live on: collections of
        # the young objects meanwhile would walk them again and again.
        with collector_paused():
            self._step()

    def _step(self) -> None:
        started = time.monotonic()
        before = self._snap
        now = time.time()
        fleet = before.fleet
        connected = self.view.synced
        touched: set[str] | None = set()
        if connected and (self._dirty.is_set() or not before.connected or fleet is None):
            self._dirty.clear()
            fleet, touched = self._reader.read(fleet, whole=not before.connected)
        error = None if connected else printable(self.view.last_error or "reconnecting")[:300]
        after = self._next(before, fleet, connected, error, now)
        changed = _changed(before, after, touched)
        if changed:
            after = replace(after, history=self._remember(after, changed, now))
        self._snap = after
        self._feed(before, after, changed)
        if self.on_step is not None:
            self.on_step(after, time.monotonic() - started)

    def _next(
        self,
        before: Snapshot,
        fleet: FleetStatus | None,
        connected: bool,
        error: str | None,
        now: float,
    ) -> Snapshot:
        """The next state; its version moves only when something a page shows may differ."""
        by_id = (
            before.by_id
            if fleet is before.fleet
            else {r.robot_id: r for r in (fleet.rows if fleet else [])}
        )
        after = Snapshot(
            before.version, fleet, self.broker, connected, error, now, before.history, by_id
        )
        if _looks(before) != _looks(after) or fleet is not before.fleet:
            after = replace(after, version=before.version + 1)
        return after

    def _remember(
        self, snap: Snapshot, changed: set[str], now: float
    ) -> dict[str, tuple[HistoryEntry, ...]]:
        """Each changed robot's new status at the end of its history (a bounded one)."""
        for robot_id in changed:
            row = snap.by_id.get(robot_id)
            if row is None:
                self._history.pop(robot_id, None)
                continue
            entry = HistoryEntry.of(row, now)
            kept = self._history.setdefault(robot_id, collections.deque(maxlen=HISTORY))
            if not kept or not kept[-1].same(entry):
                kept.append(entry)
        history = dict(snap.history)
        for robot_id in changed:
            if robot_id in self._history:
                history[robot_id] = tuple(self._history[robot_id])
            else:
                history.pop(robot_id, None)
        return history

    def _feed(self, before: Snapshot, after: Snapshot, changed: set[str]) -> None:
        """Each stream's event: the first for a new one, else what changed for it."""
        with self._lock:
            streams = list(self._streams.items())
        views = Views(after)  # pages of one query share their rows and boxes
        for key, stream in streams:
            if stream.sink.closed:
                self.unsubscribe(key)
                continue
            if not stream.started:
                stream.started = True
                message = first(after, stream.shown, stream.page_version, views)
            elif after.version != before.version:
                message = change(after, stream.shown, changed, views)
            else:
                continue
            if message is not None:
                stream.sink.put(message)


def _changed(before: Snapshot, after: Snapshot, touched: set[str] | None) -> set[str]:
    """The robots whose rows differ: among those touched, when the reader knows them."""
    if after.fleet is before.fleet:
        return set()
    if touched is None:
        return changed_rows(before, after)
    return {r for r in touched if before.by_id.get(r) != after.by_id.get(r)}


def _looks(snap: Snapshot) -> tuple[object, ...]:
    """What a page shows of a state besides its rows: the broker, the reconciler's health."""
    fleet = snap.fleet
    status = fleet.reconciler if fleet is not None else None
    health = reconciler_health(status, snap.at) if fleet is not None else None
    return (snap.connected, snap.broker_error, health)
