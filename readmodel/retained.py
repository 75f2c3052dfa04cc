"""The MQTT edge: a live copy of retained topics (complete once a marker returns) and publishing.

Shared by the reconciler (launch topics) and `robotconf status` (every robot topic).
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import functools
import hashlib
import itertools
import logging
import os
import socket
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, ParamSpec

import paho.mqtt.client as paho
from paho.mqtt.enums import MQTTProtocolVersion
from paho.mqtt.subscribeoptions import SubscribeOptions

from robotconf.configurator.gcpause import collector_paused
from robotconf.contract.mqtt import Connection, connect_failure, make_client
from robotconf.contract.safejson import MAX_PAYLOAD_BYTES, PayloadError, parse_object
from robotconf.contract.throttle import Throttle

log = logging.getLogger("robotconf.mqtt")

_ids = itertools.count(1)
P = ParamSpec("P")

# Kept in place of a payload dropped for its size: the topic holds something, and it is
# unreadable (a NUL byte never starts JSON). Only ever in memory.
_OVERSIZED = b"\x00oversized "
KEEPALIVE_TIMEOUT = 0x8D  # MQTT 5's reason code, which paho also gives an MQTT 3.1.1 client
LOG_EVERY = 60.0  # seconds: at most one line per this about payloads that were skipped


def oversized(size: int) -> bytes:
    return _OVERSIZED + str(size).encode()


def read_object(payload: bytes, max_bytes: int = MAX_PAYLOAD_BYTES) -> dict[str, Any]:
    """A retained payload as a JSON object, size and depth bounded; PayloadError says why not."""
    size = payload[len(_OVERSIZED) :]
    if payload.startswith(_OVERSIZED) and size.isdigit() and len(size) < 12:
        raise PayloadError(f"payload is {int(size):,} bytes, over the limit of {max_bytes:,}")
    return parse_object(payload, max_bytes=max_bytes)


class Ignored:
    """Payloads skipped as unreadable: counted by kind, each distinct payload of a topic once
    (a resync reads the same ones again), and logged at most once a minute, because any
    robot may publish garbage in a loop."""

    MAX_TOPICS = 10_000

    def __init__(self, logger: logging.Logger = log, every: float = LOG_EVERY) -> None:
        self._lock = threading.Lock()
        self._seen: dict[str, bytes] = {}  # topic -> fingerprint of the payload last counted
        self._counts: dict[str, int] = {}
        self._log = logger
        self._throttle = Throttle(every)

    def note(self, kind: str, topic: str, payload: bytes, reason: str) -> None:
        fingerprint = hashlib.sha256(payload).digest()
        with self._lock:
            if self._seen.get(topic) == fingerprint:
                return
            if len(self._seen) >= self.MAX_TOPICS:
                self._seen.clear()
            self._seen[topic] = fingerprint
            self._counts[kind] = self._counts.get(kind, 0) + 1
            line = self._throttle.admit(
                f"ignored the {kind} payload on {topic!r}: {reason}", time.monotonic()
            )
        if line is not None:
            self._log.warning("%s", line)

    def counts(self) -> dict[str, int]:
        with self._lock:
            return dict(sorted(self._counts.items()))


def _guarded(handler: Callable[P, None]) -> Callable[P, None]:
    """A paho callback that never raises: paho 2 re-raises into its network thread, which
    would end the connection for good."""

    @functools.wraps(handler)
    def run(*args: P.args, **kwargs: P.kwargs) -> None:
        try:
            handler(*args, **kwargs)
        except Exception:
            log.exception("MQTT %s failed; ignored, the connection goes on", handler.__name__)

    return run


# Messages in flight at once when publishing many: enough to keep a broker busy (a PUBACK
# comes back within a millisecond on a LAN), few enough that what paho holds stays small.
PUBLISH_WINDOW = 2000
# ... and at most this many payload bytes: the default lab's 2,000 requests of 3 KB; 6.6 KB
# ones (each robot in its own namespace) are fewer at once (paho holds two copies of each).
PUBLISH_WINDOW_BYTES = 6 * 1024 * 1024
# Seconds without a message before a snapshot's marker is sent again (it may have been dropped).
MARKER_QUIET = 0.5
# Topics missing from a snapshot read again, alone, to tell a lossy read from absent robots.
CONFIRM_SAMPLE = 100


# A message's payload, or what makes it: 10,000 requests of 6.6 KB are made one by one as
# they are sent, not all held at once (66 MB).
Payload = bytes | Callable[[], bytes]


def made(payload: Payload) -> bytes:
    return payload if isinstance(payload, bytes) else payload()


def _settled(info: paho.MQTTMessageInfo, deadline: float) -> None:
    """Waits until `info` is acknowledged, failed or the deadline passed (the caller reads
    which when it collects every outcome)."""
    with contextlib.suppress(RuntimeError, ValueError):
        info.wait_for_publish(max(0.0, deadline - time.monotonic()))


class _Window:
    """The messages of one publish in flight, at most PUBLISH_WINDOW of them and
    PUBLISH_WINDOW_BYTES: paho holds each message's packet until it is written and its
    payload until the PUBACK, 60 MB for 10,000 at once."""

    def __init__(self, deadline: float) -> None:
        self.deadline = deadline
        self.flight: collections.deque[tuple[paho.MQTTMessageInfo, int]] = collections.deque()
        self.size = 0

    def make_room(self, size: int) -> None:
        """Waits for the oldest in flight until one more of `size` bytes fits (or none is)."""
        flight = self.flight
        while flight and (len(flight) >= PUBLISH_WINDOW or self.size + size > PUBLISH_WINDOW_BYTES):
            info, sent = flight.popleft()
            _settled(info, self.deadline)
            self.size -= sent

    def add(self, info: paho.MQTTMessageInfo, size: int) -> None:
        self.flight.append((info, size))
        self.size += size

    def send(
        self,
        client: paho.Client,
        items: Sequence[tuple[str, Payload]],
        copies: Sequence[bytes],
    ) -> list[tuple[str, bytes, paho.MQTTMessageInfo]]:
        """Publishes each item retained, QoS 1, each payload made as it is sent; each with
        the copy to keep of it, and what tells its acknowledgement."""
        infos: list[tuple[str, bytes, paho.MQTTMessageInfo]] = []
        # 10,000 publishes allocate enough to set off collections that walk every object
        # the reconciler holds (its whole rendered fleet); none of them is a cycle.
        with collector_paused():
            for (topic, payload), copy in zip(items, copies, strict=True):
                data = made(payload)
                self.make_room(len(data))
                info = client.publish(topic, data, qos=1, retain=True)
                self.add(info, len(data))
                infos.append((topic, copy, info))
        return infos


def client_id(role: str) -> str:
    """Unique per process and instance: two clients with one id would kick each other off."""
    host = socket.gethostname().split(".")[0][:20] or "host"
    return f"robotconf-{role}-{host}-{os.getpid()}-{next(_ids)}"


class RetainedView:
    """Subscribes to `filters` in on_connect and mirrors every retained message under them.

    After subscribing, it publishes a marker to its own private topic: the broker queues the
    retained messages of a subscription before anything published later, so when the marker
    comes back the snapshot is complete. Every reconnect starts a new snapshot.
    """

    def __init__(
        self,
        connection: Connection,
        filters: Sequence[str],
        marker_topic: str,
        *,
        role: str = "view",
        on_change: Callable[[], None] | None = None,
        on_synced: Callable[[], None] | None = None,
        on_topic: Callable[[str], None] | None = None,
        on_payload: Callable[[str, bytes], None] | None = None,
        max_inflight: int = 0,
        max_payload: int = MAX_PAYLOAD_BYTES,
        no_local: bool = False,
        keep: Callable[[str, bytes], bytes] | None = None,
    ) -> None:
        self.connection = connection
        self.filters = list(filters)
        self.client_id = client_id(role)
        self.marker_topic = f"{marker_topic}/{self.client_id}"
        self._marker_base = marker_topic
        self.role = role
        self._on_change = on_change
        self._on_synced = on_synced
        self._on_topic = on_topic
        self._on_payload = on_payload  # each message as it comes (a stream, not a copy)
        # What is kept of each payload (a summary that reads the same to the owner): 10,000
        # launch requests are 30 MB whole and a megabyte as their kind and digest.
        self._keep = keep
        self.max_payload = max_payload
        self.oversized = 0  # payloads dropped on arrival for their size
        self._dropped = Ignored()
        self._lock = threading.Lock()
        self._topics: dict[str, bytes] = {}
        self._arrivals: dict[str, int] = {}  # topic -> messages received on it
        self._generation = 0
        self._subscribe_mid: int | None = None
        self._synced = threading.Event()
        self._connected = False
        self.last_error: str | None = None
        # Why the broker refused our CONNECT (a login, an ACL), until it accepts one: a command
        # says so at once instead of waiting for an answer that will not come.
        self.refused: str | None = None
        # Why the last attempt could not connect when the network answered it (refused, reset,
        # closed before CONNACK, an unknown host, a failed TLS handshake), until one connects:
        # a command says so at once; a silent network is waited out.
        self.closed: str | None = None
        self.connections = 0
        self.reached = False  # a TCP connection was made, whether or not MQTT answered on it
        # How this snapshot is known to lack retained messages the broker holds (it dropped
        # them: a queue limit), or None; each connection starts a new snapshot.
        self.lost: str | None = None
        self._received = 0  # messages received, to tell a quiet connection from a busy one
        # MQTT 5's No Local: what this client publishes on `filters` is not sent back to it
        # (its copy is updated at the PUBACK instead); retained messages still come at each
        # subscription, so a reconnect still reads back what is published.
        self.no_local = no_local
        self._client = self._paho_client(connection, max_inflight)
        self._started = False

    def _paho_client(self, connection: Connection, max_inflight: int) -> paho.Client:
        """The MQTT client, its handlers ours (MQTT 5 when asked for No Local)."""
        if self.no_local:
            connection = dataclasses.replace(connection, protocol=MQTTProtocolVersion.MQTTv5)
        client = make_client(connection, self.client_id)
        client.suppress_exceptions = True  # and every handler is guarded besides
        # Many retained QoS 1 publishes in flight at once: waiting for each PUBACK in turn
        # would make a 1,000-robot rollout as slow as 1,000 round trips. 0 is unlimited, and
        # also spares paho its scan of every message in flight at each PUBACK (a limit makes
        # a rollout quadratic in the number of robots).
        client.max_inflight_messages_set(max_inflight)
        client.on_connect = self._handle_connect
        client.on_disconnect = self._handle_disconnect
        client.on_subscribe = self._handle_subscribe
        client.on_message = self._handle_message
        client.on_connect_fail = self._handle_connect_fail
        client.on_socket_open = self._handle_socket_open
        return client

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Connects in the background; paho retries with backoff until the broker answers."""
        address = self.connection.address
        self._client.connect_async(address.host, address.port, keepalive=30)
        self._client.loop_start()
        self._started = True

    def stop(self) -> None:
        if not self._started:
            return
        self._started = False
        try:
            self._client.disconnect()
        finally:
            if self._connected:
                self._client.loop_stop()
            else:
                # Between connection attempts paho's thread sleeps in steps of a second before
                # it sees the stop: holding no connection, it is told and not waited for (a
                # command that found no broker ends at once, not a second later).
                threading.Thread(target=self._client.loop_stop, daemon=True).start()

    def __enter__(self) -> RetainedView:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ state

    @property
    def connected(self) -> bool:
        return self._connected

    @property
    def synced(self) -> bool:
        return self._synced.is_set()

    def wait_synced(self, timeout: float | None, *, or_refused: bool = False) -> bool:
        """True once the retained messages are known; with `or_refused`, False as soon as the
        broker refuses the connection or cannot be connected to (`refused`, `closed`): a
        one-shot command has nothing to wait for then."""
        if not or_refused:
            return self._synced.wait(timeout)
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._synced.is_set():
            left = None if deadline is None else deadline - time.monotonic()
            gone = self.refused is not None or self.closed is not None
            if gone or (left is not None and left <= 0):
                return False
            self._synced.wait(0.05 if left is None else min(0.05, left))
        return True

    def silence(self) -> str:
        """Why nothing is known yet, in words: the last error, or a listener that took the
        connection and never answered MQTT's CONNECT (not a broker, or a wedged one)."""
        if self.last_error:
            return self.last_error
        if self.reached:
            return (
                f"{self.connection.address.url} accepted a connection but never answered "
                "MQTT's CONNECT: is it an MQTT broker?"
            )
        return "no answer"

    def snapshot(self) -> dict[str, bytes]:
        with self._lock:
            return dict(self._topics)

    def get(self, topic: str) -> bytes | None:
        with self._lock:
            return self._topics.get(topic)

    def confirm_missing(self, topics: Sequence[str], timeout: float) -> int:
        """How many of `topics`, absent from the snapshot, the broker does hold: a few of them
        (CONFIRM_SAMPLE) read again over a connection of its own, whose handful of exact topics
        no queue limit cuts. Any found proves the snapshot lossy, and `lost` says so."""
        sample = [t for t in topics if self.get(t) is None][:CONFIRM_SAMPLE]
        if not sample:
            return 0
        found = take_snapshot(
            self.connection, sample, self._marker_base, f"{self.role}-check", timeout
        )
        if found and self.lost is None:
            self._found_lost(
                f"{len(found)} of {len(sample)} topic(s) missing from its read were there "
                "when read alone"
            )
        return len(found or {})

    def _found_lost(self, evidence: str) -> None:
        self.lost = evidence
        log.warning(
            "the broker dropped retained messages sent to %s (%s): raise its "
            "max_queued_messages (robotconf broker-config sets it for the fleet)",
            self.client_id,
            evidence,
        )

    # ------------------------------------------------------------------ publishing

    def publish_retained(
        self,
        items: Sequence[tuple[str, Payload]],
        timeout: float,
        kept: Sequence[bytes | None] | None = None,
    ) -> bool:
        """Publishes retained QoS 1 and waits for every PUBACK; an empty payload clears a topic.

        True when the broker acknowledged all of them in time. The local copy is updated on
        acknowledgement, so the next diff does not publish them again before their echo, unless
        a message arrived on the topic meanwhile (the echo, or a newer one: it is the truth).
        `kept`: what the copy keeps of each item, as `keep` would make it (the caller knows it
        without reading the payload back); None, or left out: `keep` of the payload. A payload
        may be what makes it (`Payload`): it is then made as it is sent.
        """
        if not self._synced.is_set():
            return False
        copies = [
            self._kept(topic, made(payload)) if copy is None else copy
            for (topic, payload), copy in zip(items, kept or [None] * len(items), strict=True)
        ]
        with self._lock:
            before = {topic: self._arrivals.get(topic, 0) for topic, _ in items}
        deadline = time.monotonic() + timeout
        infos = _Window(deadline).send(self._client, items, copies)
        ok = True
        for topic, copy, info in infos:
            try:
                info.wait_for_publish(max(0.0, deadline - time.monotonic()))
            except (RuntimeError, ValueError) as exc:
                self.last_error = str(exc)
                ok = False
                continue
            if not info.is_published():
                ok = False
                continue
            with self._lock:
                if self._arrivals.get(topic, 0) != before[topic]:
                    continue
                if copy:
                    self._topics[topic] = copy
                else:
                    self._topics.pop(topic, None)
        return ok

    def _kept(self, topic: str, payload: bytes | bytearray) -> bytes:
        if not payload:
            return b""
        return bytes(payload) if self._keep is None else self._keep(topic, bytes(payload))

    def publish(self, topic: str, payload: bytes, timeout: float) -> bool:
        """One message, not retained, QoS 1; True once the broker acknowledged it in time."""
        if not self._connected:
            return False
        info = self._client.publish(topic, payload, qos=1, retain=False)
        try:
            info.wait_for_publish(timeout)
        except (RuntimeError, ValueError) as exc:
            self.last_error = str(exc)
            return False
        return info.is_published()

    # ------------------------------------------------------------------ paho callbacks
    # They run on paho's network thread: update memory, set events, never block.

    @_guarded
    def _handle_connect(
        self, client: paho.Client, userdata: Any, flags: Any, reason: Any, properties: Any
    ) -> None:
        if getattr(reason, "is_failure", False):
            error = f"broker refused the connection: {reason}"
            if error != self.last_error:  # said once, not at every retry
                log.warning("%s", error)
            self.last_error, self.refused = error, str(reason)
            return
        with self._lock:
            self._generation += 1
            self._topics.clear()  # a broker that lost its retained messages must show as empty
            self._synced.clear()
            self._connected = True
            self.connections += 1
            self.lost = None
        self.last_error = self.refused = self.closed = None
        # QoS 0: a snapshot is taken anew at every connection, so redelivery buys nothing,
        # while a broker may drop queued QoS 1 messages beyond its per-client queue limit
        # (Mosquitto: max_queued_messages 1000) and a large fleet's snapshot would be lossy.
        if self.no_local:
            local = SubscribeOptions(qos=0, noLocal=True)
            # The marker must come back: it is how a snapshot is known complete.
            topics: list[tuple[str, Any]] = [(f, local) for f in self.filters]
            topics.append((self.marker_topic, SubscribeOptions(qos=0)))
        else:
            topics = [(f, 0) for f in self.filters] + [(self.marker_topic, 0)]
        _, mid = client.subscribe(topics)
        self._subscribe_mid = mid

    @_guarded
    def _handle_subscribe(
        self, client: paho.Client, userdata: Any, mid: int, reasons: Any, properties: Any
    ) -> None:
        if mid != self._subscribe_mid:
            return
        failed = [r for r in reasons if getattr(r, "is_failure", False)]
        if failed:
            self.last_error = f"broker refused a subscription: {failed[0]}"
            log.warning("%s", self.last_error)
        generation = self._generation
        client.publish(self.marker_topic, str(generation).encode(), qos=1)
        threading.Thread(target=self._watch_marker, args=(generation,), daemon=True).start()

    def _watch_marker(self, generation: int) -> None:
        """Mosquitto drops what is beyond its per-client queue limit, the marker too: once
        nothing has arrived for MARKER_QUIET seconds, the marker goes again, numbered. Order
        is kept per client, so the numbered one coming back without the first proves that
        the broker dropped messages (see `_handle_marker`)."""
        retries, seen = 0, -1
        while self._started and generation == self._generation and not self._synced.is_set():
            time.sleep(MARKER_QUIET)
            received = self._received
            if received == seen and generation == self._generation and self._connected:
                retries += 1
                payload = f"{generation}.{retries}".encode()
                self._client.publish(self.marker_topic, payload, qos=1)
            seen = received

    def _handle_marker(self, payload: bytes) -> None:
        generation = str(self._generation)
        text = payload.decode("ascii", "replace")
        if self._synced.is_set() or text.partition(".")[0] != generation:
            return  # a late copy, or one of an earlier connection
        if text != generation:
            self._found_lost(
                f"its sync marker was dropped after {self._received:,} retained message(s)"
            )
        self._synced.set()
        if self._on_synced is not None:
            self._on_synced()

    @_guarded
    def _handle_socket_open(self, client: paho.Client, userdata: Any, sock: Any) -> None:
        self.reached = True

    @_guarded
    def _handle_connect_fail(self, client: paho.Client, userdata: Any) -> None:
        # paho calls this from the `except OSError` of its connection attempt and does not
        # pass the error: it is the one being handled. Should that change, `closed` stays None
        # and a command waits out its timeout, as for a silent network.
        self.closed = connect_failure(sys.exc_info()[1])
        why = f": {self.closed}" if self.closed else ""
        self.last_error = f"cannot reach the broker at {self.connection.address.url}{why}"

    @_guarded
    def _handle_disconnect(
        self, client: paho.Client, userdata: Any, flags: Any, reason: Any, properties: Any
    ) -> None:
        with self._lock:
            answered, self._connected = self._connected, False
            self._synced.clear()
        if not self._started:
            return
        url = self.connection.address.url
        if not answered and self.refused is None and not _keepalive(reason):
            # Closed by the broker's side before it answered CONNECT (not our keepalive giving
            # up on a silent one): a listener that turns clients away.
            self.closed = "it closed the connection before answering MQTT's CONNECT"
            self.last_error = f"the broker at {url} {self.closed}"
        else:
            self.last_error = f"disconnected from {url}: {reason}"
        log.info("%s; reconnecting", self.last_error)

    @_guarded
    def _handle_message(
        self, client: paho.Client, userdata: Any, message: paho.MQTTMessage
    ) -> None:
        if message.topic == self.marker_topic:
            self._handle_marker(bytes(message.payload))
            return
        self._received += 1
        payload = message.payload
        if len(payload) > self.max_payload:
            # Dropped at once: a robot that publishes 100 MB must not make us hold it.
            self.oversized += 1
            self._dropped.note(
                "oversized",
                message.topic,
                oversized(len(payload)),
                f"{len(payload):,} bytes, over the limit of {self.max_payload:,}; dropped",
            )
            payload = oversized(len(payload))
        copy = self._kept(message.topic, payload)
        with self._lock:
            self._arrivals[message.topic] = self._arrivals.get(message.topic, 0) + 1
            if copy:
                # The echo of what was just published equals the copy kept at its PUBACK:
                # keeping that one object, not a second copy.
                current = self._topics.get(message.topic)
                self._topics[message.topic] = current if current == copy else copy
            else:
                self._topics.pop(message.topic, None)
        if self._on_topic is not None:
            self._on_topic(message.topic)
        if self._on_payload is not None:
            self._on_payload(message.topic, bytes(payload))
        if self._on_change is not None:
            self._on_change()


class Presence:
    """A connection that only holds a Last Will, which the broker publishes (retained, QoS 1)
    when this process dies or loses the broker.

    A will is fixed when a client connects, so a new will takes a new connection: it connects
    first, then the old one leaves cleanly (which discards its will), so one is always in place.
    """

    def __init__(self, connection: Connection, topic: str, role: str = "presence") -> None:
        self.connection = connection
        self.topic = topic
        self.role = role
        self._client: paho.Client | None = None
        self._will: bytes | None = None

    @property
    def will(self) -> bytes | None:
        return self._will

    def hold(self, will: bytes, timeout: float) -> bool:
        """Makes `will` what the broker publishes if this process dies; False when the broker
        did not accept a connection in time (the previous will stays in place)."""
        if will == self._will:
            return True
        connected = threading.Event()

        @_guarded
        def on_connect(
            client: paho.Client, userdata: Any, flags: Any, reason: Any, properties: Any
        ) -> None:
            if not getattr(reason, "is_failure", False):
                connected.set()

        client = make_client(self.connection, client_id(self.role))
        client.suppress_exceptions = True
        client.will_set(self.topic, will, qos=1, retain=True)
        client.on_connect = on_connect
        address = self.connection.address
        client.connect_async(address.host, address.port, keepalive=30)
        client.loop_start()
        if not connected.wait(timeout):
            _leave(client)
            return False
        old, self._client, self._will = self._client, client, will
        if old is not None:
            _leave(old)
        return True

    def release(self) -> None:
        """Leaves cleanly: the broker discards the will (publish the offline status first)."""
        client, self._client, self._will = self._client, None, None
        if client is not None:
            _leave(client)


def _keepalive(reason: Any) -> bool:
    """Whether a disconnection is paho's own keepalive giving up (reason code 0x8D)."""
    return getattr(reason, "value", None) == KEEPALIVE_TIMEOUT


def _leave(client: paho.Client) -> None:
    try:
        client.disconnect()
    finally:
        client.loop_stop()


def speaks_mqtt5(connection: Connection, timeout: float = 3.0) -> bool:
    """Whether the broker takes an MQTT 5 connection now (for No Local); False when it refuses,
    does not answer in time, or cannot be reached."""
    v5 = dataclasses.replace(connection, protocol=MQTTProtocolVersion.MQTTv5)
    client = make_client(v5, client_id("probe"))
    client.suppress_exceptions = True
    answered = threading.Event()
    accepted: list[bool] = []

    def on_connect(c: paho.Client, u: Any, flags: Any, reason: Any, properties: Any) -> None:
        accepted.append(not getattr(reason, "is_failure", True))
        answered.set()

    client.on_connect = on_connect
    address = connection.address
    try:
        client.connect(address.host, address.port, keepalive=10)
    except Exception:  # refused, unreachable, TLS: not known to speak MQTT 5
        return False
    client.loop_start()
    try:
        answered.wait(timeout)
        return accepted == [True]
    finally:
        with contextlib.suppress(Exception):
            client.disconnect()
        client.loop_stop()


def take_snapshot(
    connection: Connection, filters: Sequence[str], marker_topic: str, role: str, timeout: float
) -> dict[str, bytes] | None:
    """The retained messages under `filters` right now, over a connection of its own; None
    when the broker does not answer within `timeout` seconds."""
    return take_snapshot_said(connection, filters, marker_topic, role, timeout)[0]


def take_snapshot_said(
    connection: Connection, filters: Sequence[str], marker_topic: str, role: str, timeout: float
) -> tuple[dict[str, bytes] | None, str | None]:
    """`take_snapshot`, and how the snapshot is known to lack messages the broker dropped
    (`RetainedView.lost`), or None: for a caller that says so to its user."""
    view = RetainedView(connection, filters, marker_topic, role=role)
    view.start()
    try:
        if not view.wait_synced(timeout, or_refused=True):
            return None, None
        return view.snapshot(), view.lost
    finally:
        view.stop()
