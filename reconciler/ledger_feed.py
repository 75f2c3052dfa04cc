"""The ledger's feed: the robots' `goal_outcomes` stream, taken from the broker into the ledger.

A persistent MQTT session (a fixed client id, clean_session false) subscribed at QoS 1: while
the reconciler is down the broker queues what the robots report (up to its per-client queue,
Mosquitto's max_queued_messages). Each message is acknowledged only once the batch that holds
it is committed, so a kill at any moment loses nothing the broker still holds: what was not
acknowledged comes again at the next start, and the ledger keeps a record once.

Off the reconcile loop: paho's network thread queues, a writer thread of its own checks the
records (`outcomes.check_record`), commits them in batches (as many as arrived while the
previous batch was written), acknowledges them, counts them (metrics) and tells failing and
recovered robots (notify). No record, however broken, stops it; a ledger that turns out
corrupt is set aside and a new one started.

The same thread keeps the fleet's timeline: the events the reconciler tells or notes (`keep`,
called from the telemetry's thread, never waits) are queued, a bounded queue, and committed
each batch in one transaction. An event that cannot be kept is counted and said (throttled),
never a stop: the timeline is history, not control.
"""

from __future__ import annotations

import collections
import hashlib
import logging
import sqlite3
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import paho.mqtt.client as paho

from robotconf.contract.backoff import Backoff
from robotconf.contract.goals import OutcomeRecord
from robotconf.contract.mqtt import Connection, make_client
from robotconf.contract.throttle import Throttle
from robotconf.contract.wire import Topics
from robotconf.readmodel.ledger import (
    DEFAULT_MAX_AGE,
    DEFAULT_MAX_EVENTS,
    DEFAULT_MAX_RECORDS,
    PRUNE_CHUNK,
    Added,
    Ledger,
    LedgerError,
    ledger_path,
    set_aside,
)
from robotconf.readmodel.outcomes import DEFAULT_STREAK, RecordRefused, check_record, streak_event
from robotconf.readmodel.retained import Ignored, _guarded

if TYPE_CHECKING:
    from robotconf.readmodel.events import Event
    from robotconf.reconciler.metrics import Metrics

log = logging.getLogger("robotconf.reconciler")

MAX_BATCH = 2000  # records committed at once at most
MAX_EVENTS_QUEUED = 10_000  # events waiting to be kept; past it the oldest are dropped (counted)
PRUNE_EVERY = 60.0  # seconds between prunings of the ledger
RETRY_INITIAL, RETRY_MAX = 0.5, 30.0  # a ledger that cannot be written (disk full), tried again
STOP_TIMEOUT = 10.0


@dataclass(frozen=True)
class LedgerSettings:
    """How the reconciler keeps its ledger (`reconcile --state-dir`, `--ledger-*`)."""

    state_dir: Path
    max_age: float = DEFAULT_MAX_AGE
    max_records: int = DEFAULT_MAX_RECORDS
    streak: int = DEFAULT_STREAK  # failed goals in a row before a robot is told failing
    max_events: int = DEFAULT_MAX_EVENTS  # timeline events kept at most (the newest)

    @property
    def path(self) -> Path:
        return ledger_path(self.state_dir)


@dataclass(frozen=True)
class _Arrived:
    mid: int
    qos: int
    topic: str
    payload: bytes
    connection: int  # which connection delivered it: a PUBACK goes back on that one only


def session_id(prefix: str, state_dir: Path) -> str:
    """The feed's client id: the same at every start of a reconciler of this prefix and state
    folder (the broker keeps its session by it), another for another folder."""
    key = f"{prefix}\n{state_dir.absolute()}".encode()
    return f"robotconf-ledger-{hashlib.sha256(key).hexdigest()[:16]}"


class LedgerFeed:
    """Started before the controller runs, stopped after; `start` opens the ledger (raising
    LedgerError when none can be made at all), connects in the background and writes."""

    def __init__(
        self,
        connection: Connection,
        prefix: str,
        settings: LedgerSettings,
        *,
        metrics: Metrics | None = None,
        tell: Callable[[Sequence[Event]], None] | None = None,
    ) -> None:
        self.connection = connection
        self.topics = Topics(prefix)
        self.settings = settings
        self.metrics = metrics
        self._tell = tell
        self.client_id = session_id(prefix, settings.state_dir)
        self.ignored = Ignored(log)
        self._lock = threading.Lock()
        self._arrived: collections.deque[_Arrived] = collections.deque()
        self._ready = threading.Event()
        self._stop = threading.Event()
        self._connection = 0  # the current connection's number; 0 while disconnected
        self._connections = 0
        self._last_error: str | None = None
        self._says = Throttle(60.0)
        self.ledger: Ledger | None = None
        self.kept = self.duplicates = self.refused = 0  # since start
        self._events: collections.deque[Event] = collections.deque()
        self.events_kept = self.events_lost = 0  # timeline events, since start
        self._pruned = 0  # removed by the pruning under way
        self.committed = threading.Condition()  # notified after each commit (tests, benches)
        self._client = self._paho_client()
        self._thread = threading.Thread(target=self._run, name="ledger", daemon=True)

    def _paho_client(self) -> paho.Client:
        client = make_client(self.connection, self.client_id, session=True)
        client.suppress_exceptions = True
        client.manual_ack_set(True)
        client.max_inflight_messages_set(0)
        client.on_connect = self._handle_connect
        client.on_disconnect = self._handle_disconnect
        client.on_message = self._handle_message
        client.on_subscribe = self._handle_subscribe
        return client

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        self.ledger = Ledger.open_or_start(self.settings.path, log.error)
        log.info("ledger: %s", self.settings.path)
        address = self.connection.address
        self._client.connect_async(address.host, address.port, keepalive=30)
        self._client.loop_start()
        self._thread.start()

    def stop(self, timeout: float = STOP_TIMEOUT) -> None:
        """Writes what arrived, then leaves: the broker keeps the session (and queues for it)."""
        self._stop.set()
        self._ready.set()
        self._thread.join(timeout)
        try:
            self._client.disconnect()
        finally:
            self._client.loop_stop()
        if self.ledger is not None and not self._thread.is_alive():
            self.ledger.close()

    def keep(self, events: Sequence[Event]) -> None:
        """Queues `events` for the timeline (any thread; never waits on the ledger)."""
        if not events:
            return
        with self._lock:
            self._events.extend(events)
            over = len(self._events) - MAX_EVENTS_QUEUED
            for _ in range(max(over, 0)):
                self._events.popleft()
            self.events_lost += max(over, 0)
        self._ready.set()

    @property
    def pending(self) -> int:
        with self._lock:
            return len(self._arrived)

    # ------------------------------------------------------------------ paho callbacks

    @_guarded
    def _handle_connect(
        self, client: paho.Client, userdata: Any, flags: Any, reason: Any, properties: Any
    ) -> None:
        if getattr(reason, "is_failure", False):
            error = f"ledger: the broker refused the connection: {reason}"
            if error != self._last_error:
                log.warning("%s", error)
            self._last_error = error
            return
        self._last_error = None
        with self._lock:
            self._connections += 1
            self._connection = self._connections
        # Again at every connection: a broker that lost the session (restarted without
        # persistence) has the subscription back; one that kept it changes nothing.
        client.subscribe([(self.topics.all_goal_outcomes, 1)])
        if not getattr(flags, "session_present", True):
            log.info("ledger: a new session on the broker (nothing was queued for this one)")

    @_guarded
    def _handle_subscribe(
        self, client: paho.Client, userdata: Any, mid: int, reasons: Any, properties: Any
    ) -> None:
        failed = [r for r in reasons if getattr(r, "is_failure", False)]
        if failed:
            log.error(
                "ledger: the broker refused the subscription to %s (%s): no goal outcome "
                "is kept; its ACL must let the reconciler read it (robotconf broker-config)",
                self.topics.all_goal_outcomes,
                failed[0],
            )

    @_guarded
    def _handle_disconnect(
        self, client: paho.Client, userdata: Any, flags: Any, reason: Any, properties: Any
    ) -> None:
        with self._lock:
            self._connection = 0
        if not self._stop.is_set():
            log.info("ledger: disconnected from the broker (%s); reconnecting", reason)

    @_guarded
    def _handle_message(
        self, client: paho.Client, userdata: Any, message: paho.MQTTMessage
    ) -> None:
        with self._lock:
            self._arrived.append(
                _Arrived(
                    message.mid,
                    message.qos,
                    message.topic,
                    bytes(message.payload),
                    self._connection,
                )
            )
        self._ready.set()

    # ------------------------------------------------------------------ the writer

    def _run(self) -> None:
        next_prune = time.monotonic()  # what went past the bounds while it was down, first
        backoff = Backoff(RETRY_INITIAL, RETRY_MAX)
        while True:
            self._keep_events()
            batch = self._take()
            if not batch:
                if self._stop.is_set():
                    self._keep_events()  # what the last steps told, before leaving
                    return
                self._ready.wait(max(0.0, next_prune - time.monotonic()))
                self._ready.clear()
            else:
                try:
                    self._write(batch)
                    backoff.reset()
                except Exception as exc:  # cannot be written now: not acknowledged, retried
                    self._put_back(batch)
                    self._failed(exc)
                    if self._stop.wait(backoff.next()):
                        return  # the broker keeps what was not acknowledged
            if time.monotonic() >= next_prune:
                # A chunk at a time between batches: more left, the next comes at once.
                more = self._prune()
                next_prune = time.monotonic() + (0.0 if more else PRUNE_EVERY)

    def _keep_events(self) -> None:
        """The events queued, in one transaction; when they cannot be written they are
        counted lost and said (throttled): the records' batches, not these, are retried."""
        with self._lock:
            events = list(self._events)
            self._events.clear()
        if not events or self.ledger is None:
            return
        try:
            self.events_kept += self.ledger.add_events(events)
        except (sqlite3.Error, LedgerError) as exc:
            self.events_lost += len(events)
            line = self._says.admit(
                f"ledger: cannot keep {len(events)} timeline event(s): {exc}", time.monotonic()
            )
            if line is not None:
                log.error("%s (lost: %d since start)", line, self.events_lost)

    def _take(self) -> list[_Arrived]:
        with self._lock:
            count = min(len(self._arrived), MAX_BATCH)
            return [self._arrived.popleft() for _ in range(count)]

    def _put_back(self, batch: list[_Arrived]) -> None:
        with self._lock:
            self._arrived.extendleft(reversed(batch))

    def _write(self, batch: list[_Arrived]) -> None:
        """Checks, commits and acknowledges one batch, in the order it arrived."""
        records: list[OutcomeRecord] = []
        refused = 0
        for item in batch:
            found = self.topics.robot_of(item.topic.removesuffix("/outcomes"))
            try:
                if found is None or found[1] != "goals":
                    raise RecordRefused("not an outcomes topic")
                records.append(check_record(found[0], item.payload))
            except RecordRefused as exc:
                refused += 1
                self.ignored.note("outcome record", item.topic, item.payload, str(exc))
        added = self._add(records) if records else Added([], 0, [])
        self._acknowledge(batch)
        self.kept += len(added.kept)
        self.duplicates += added.duplicates
        self.refused += refused
        if self.metrics is not None:
            self.metrics.outcomes(added.kept)
            self.metrics.ledger(len(added.kept), added.duplicates, refused)
        if added.events:
            told = [streak_event(event) for event in added.events]
            if self._tell is not None:
                self._tell(told)
            self.keep(told)
        with self.committed:
            self.committed.notify_all()

    def _add(self, records: list[OutcomeRecord]) -> Added:
        assert self.ledger is not None
        try:
            return self.ledger.add(records, streak=self.settings.streak)
        except sqlite3.DatabaseError as exc:
            if isinstance(exc, sqlite3.OperationalError):
                raise  # busy, full, read-only: the file is fine, try again later
            self._start_again(exc)
            return self.ledger.add(records, streak=self.settings.streak)

    def _start_again(self, exc: Exception) -> None:
        """The ledger turned out corrupt while running: set aside, a new one started."""
        assert self.ledger is not None
        path = self.ledger.path
        self.ledger.close()
        aside = set_aside(path)
        log.error(
            "ledger: %s is corrupt (%s); kept aside as %s, starting a new ledger",
            path,
            exc,
            aside.name,
        )
        self.ledger = Ledger.open_or_start(path, log.error, check=False)

    def _acknowledge(self, batch: list[_Arrived]) -> None:
        """PUBACKs, once committed: those of an earlier connection are not sent (the broker
        sends their messages again, and the ledger keeps them once)."""
        with self._lock:
            current = self._connection
        for item in batch:
            if item.qos > 0 and item.connection == current and current:
                self._client.ack(item.mid, item.qos)

    def _failed(self, exc: Exception) -> None:
        line = self._says.admit(
            f"ledger: cannot write {self.settings.path}: {exc}", time.monotonic()
        )
        if line is not None:
            log.error("%s; the broker keeps the records until it can (retrying)", line)

    def _prune(self) -> bool:
        """One chunk of what is past the ledger's bounds removed; whether more may be left."""
        if self.ledger is None:
            return False
        try:
            removed = self.ledger.prune(self.settings.max_age, self.settings.max_records, chunks=1)
            gone = self.ledger.prune_events(self.settings.max_age, self.settings.max_events)
            self.ledger.checkpoint()
        except (sqlite3.Error, LedgerError) as exc:
            log.warning("ledger: pruning failed: %s", exc)
            return False
        self._pruned += removed
        if removed < PRUNE_CHUNK and self._pruned:
            log.info("ledger: %d outcome(s) past its bounds removed", self._pruned)
            self._pruned = 0
        return removed >= PRUNE_CHUNK or gone >= PRUNE_CHUNK
