"""The MQTT edge: a live copy of retained topics (complete once a marker returns) and publishing.

Shared by the reconciler (launch topics) and `robotconf status` (every robot topic).
"""

from __future__ import annotations

import itertools
import logging
import os
import socket
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import paho.mqtt.client as paho

from configurator.mqtt import Connection, make_client

log = logging.getLogger("robotconf.mqtt")

_ids = itertools.count(1)


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
        max_inflight: int = 0,
    ) -> None:
        self.connection = connection
        self.filters = list(filters)
        self.client_id = client_id(role)
        self.marker_topic = f"{marker_topic}/{self.client_id}"
        self._on_change = on_change
        self._on_synced = on_synced
        self._lock = threading.Lock()
        self._topics: dict[str, bytes] = {}
        self._generation = 0
        self._subscribe_mid: int | None = None
        self._synced = threading.Event()
        self._connected = False
        self.last_error: str | None = None
        self.connections = 0
        self._client = make_client(connection, self.client_id)
        # Many retained QoS 1 publishes in flight at once: waiting for each PUBACK in turn
        # would make a 1,000-robot rollout as slow as 1,000 round trips. 0 is unlimited, and
        # also spares paho its scan of every message in flight at each PUBACK (a limit makes
        # a rollout quadratic in the number of robots).
        self._client.max_inflight_messages_set(max_inflight)
        self._client.on_connect = self._handle_connect
        self._client.on_disconnect = self._handle_disconnect
        self._client.on_subscribe = self._handle_subscribe
        self._client.on_message = self._handle_message
        self._client.on_connect_fail = self._handle_connect_fail
        self._started = False

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
            self._client.loop_stop()

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

    def wait_synced(self, timeout: float | None) -> bool:
        return self._synced.wait(timeout)

    def snapshot(self) -> dict[str, bytes]:
        with self._lock:
            return dict(self._topics)

    # ------------------------------------------------------------------ publishing

    def publish_retained(self, items: Sequence[tuple[str, bytes]], timeout: float) -> bool:
        """Publishes retained QoS 1 and waits for every PUBACK; an empty payload clears a topic.

        True when the broker acknowledged all of them in time. The local copy is updated on
        acknowledgement, so the next diff does not publish them again before their echo.
        """
        if not self._synced.is_set():
            return False
        infos = [
            (topic, payload, self._client.publish(topic, payload, qos=1, retain=True))
            for topic, payload in items
        ]
        deadline = time.monotonic() + timeout
        ok = True
        for topic, payload, info in infos:
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
                if payload:
                    self._topics[topic] = payload
                else:
                    self._topics.pop(topic, None)
        return ok

    # ------------------------------------------------------------------ paho callbacks
    # They run on paho's network thread: update memory, set events, never block.

    def _handle_connect(
        self, client: paho.Client, userdata: Any, flags: Any, reason: Any, properties: Any
    ) -> None:
        if getattr(reason, "is_failure", False):
            self.last_error = f"broker refused the connection: {reason}"
            log.warning("%s", self.last_error)
            return
        with self._lock:
            self._generation += 1
            self._topics.clear()  # a broker that lost its retained messages must show as empty
            self._synced.clear()
            self._connected = True
            self.connections += 1
        self.last_error = None
        # QoS 0: a snapshot is taken anew at every connection, so redelivery buys nothing,
        # while a broker may drop queued QoS 1 messages beyond its per-client queue limit
        # (Mosquitto: max_queued_messages 1000) and a large fleet's snapshot would be lossy.
        topics = [(f, 0) for f in self.filters] + [(self.marker_topic, 0)]
        _, mid = client.subscribe(topics)
        self._subscribe_mid = mid

    def _handle_subscribe(
        self, client: paho.Client, userdata: Any, mid: int, reasons: Any, properties: Any
    ) -> None:
        if mid != self._subscribe_mid:
            return
        failed = [r for r in reasons if getattr(r, "is_failure", False)]
        if failed:
            self.last_error = f"broker refused a subscription: {failed[0]}"
            log.warning("%s", self.last_error)
        client.publish(self.marker_topic, str(self._generation).encode(), qos=1)

    def _handle_connect_fail(self, client: paho.Client, userdata: Any) -> None:
        self.last_error = f"cannot reach the broker at {self.connection.address.url}"

    def _handle_disconnect(
        self, client: paho.Client, userdata: Any, flags: Any, reason: Any, properties: Any
    ) -> None:
        with self._lock:
            self._connected = False
            self._synced.clear()
        if self._started:
            self.last_error = f"disconnected from {self.connection.address.url}: {reason}"
            log.info("%s; reconnecting", self.last_error)

    def _handle_message(
        self, client: paho.Client, userdata: Any, message: paho.MQTTMessage
    ) -> None:
        if message.topic == self.marker_topic:
            if message.payload == str(self._generation).encode():
                self._synced.set()
                if self._on_synced is not None:
                    self._on_synced()
            return
        with self._lock:
            if message.payload:
                self._topics[message.topic] = bytes(message.payload)
            else:
                self._topics.pop(message.topic, None)
        if self._on_change is not None:
            self._on_change()


def take_snapshot(
    connection: Connection, filters: Sequence[str], marker_topic: str, role: str, timeout: float
) -> dict[str, bytes] | None:
    """The retained messages under `filters` right now, over a connection of its own; None
    when the broker does not answer within `timeout` seconds."""
    view = RetainedView(connection, filters, marker_topic, role=role)
    view.start()
    try:
        if not view.wait_synced(timeout):
            return None
        return view.snapshot()
    finally:
        view.stop()
