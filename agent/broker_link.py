"""The agent's MQTT edge: one paho client driven by the agent's loop; a Last Will per connection.

No network thread: the agent's loop waits on the client's socket and calls `service()`, so that
a message, its handling and the status it causes take no thread hand-off. Only the blocking
TCP/TLS connect runs on a short-lived thread. Callbacks decide nothing: they queue events.
"""

from __future__ import annotations

import logging
import select
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import MQTTErrorCode
from paho.mqtt.reasoncodes import ReasonCode

from robotconf.agent.admission import MAX_COMMAND_BYTES, MAX_REQUEST_BYTES
from robotconf.agent.events import (
    Connected,
    ConnectFailed,
    Disconnected,
    Inbox,
    LaunchMessage,
    LogsMessage,
    RestartMessage,
    StatusMessage,
)
from robotconf.agent.workdir import SeqStore
from robotconf.contract.backoff import Backoff
from robotconf.contract.mqtt import (
    RECONNECT_MAX_DELAY,
    RECONNECT_MIN_DELAY,
    Connection,
    make_client,
)
from robotconf.contract.topics import Role, subscriptions
from robotconf.contract.wire import (
    AgentState,
    AgentStatus,
    RobotDescription,
    Topics,
    agent_client_id,
)

log = logging.getLogger("robotconf.agent.broker_link")

QOS = 1
MAX_STATUS_BYTES = 64 * 1024  # an agent status is a few hundred bytes
ECHOES = 8  # own status payloads remembered: a restart publishes three in quick succession
MISC_INTERVAL = 1.0  # keepalive bookkeeping (pings, a silent broker) at least this often
MAX_READS = 32  # packets read in one pass before the agent handles what they brought


def will_payload(robot_id: str, seq: int) -> bytes:
    status = AgentStatus(
        robot_id=robot_id,
        state=AgentState.OFFLINE,
        seq=seq,
        message="connection to the agent lost (Last Will)",
    )
    return status.model_dump_json().encode("utf-8")


class BrokerLink:
    """Connects, reconnects with backoff, and turns what arrives into inbox events."""

    def __init__(
        self,
        connection: Connection,
        prefix: str,
        robot_id: str,
        keepalive: int,
        inbox: Inbox,
        seq: SeqStore,
    ) -> None:
        self.topics = Topics(prefix)
        self.robot_id = robot_id
        self.launch_topic = self.topics.launch(robot_id)
        self.status_topic = self.topics.status(robot_id)
        self.description_topic = self.topics.description(robot_id)
        self.restart_topic = self.topics.restart(robot_id)
        self.logs_request_topic = self.topics.logs_request(robot_id)
        self.logs_topic = self.topics.logs(robot_id)
        self.interfaces_topic = self.topics.interfaces(robot_id)
        self.goals_topic = self.topics.goals(robot_id)
        self.goal_outcomes_topic = self.topics.goal_outcomes(robot_id)
        # Every topic a robot may read (contract/topics.py): its launch, status, restart and
        # log request topics.
        self.reads = subscriptions(Role.ROBOT, prefix, robot_id=robot_id)
        self._connection = connection
        self._keepalive = keepalive
        self._inbox = inbox
        self._seq = seq
        self._conn_seq = 0
        # What this link published on its status topic, so that their echoes are dropped here
        # instead of reaching the agent: only someone else's status (a late Last Will) matters.
        self._echoes: deque[bytes] = deque(maxlen=ECHOES)
        self._started = False
        self._attempt: threading.Thread | None = None
        self._attempt_error: str | None = None
        self._attempt_over = threading.Event()  # set by the attempt right before it wakes us
        self._socket_open = False
        self._generation = 0
        self._poller: select.poll | None = None  # readiness of the current socket, no waiting
        self._retry_at = 0.0
        self._backoff = Backoff(RECONNECT_MIN_DELAY, RECONNECT_MAX_DELAY)
        self._next_misc = 0.0
        self.client = make_client(connection, client_id=agent_client_id(robot_id))
        # A callback that raises must not end the loop: paho logs it and goes on.
        self.client.suppress_exceptions = True
        self.client.on_pre_connect = self._on_pre_connect
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect
        self.client.on_message = self._on_message

    # ------------------------------------------------------------ paho callbacks
    # They run inside `service()` or `publish_*()`, on the agent's thread (on_pre_connect on
    # the connect thread): queue an event, nothing more.

    def _on_pre_connect(self, client: paho.Client, userdata: Any) -> None:
        # A new connection gets a new seq, and its Last Will carries that seq: a will that
        # arrives late from this connection is then recognisable as older than the next one.
        self._conn_seq = self._seq.advance()
        client.will_set(
            self.status_topic, will_payload(self.robot_id, self._conn_seq), qos=QOS, retain=True
        )

    def _on_connect(
        self,
        client: paho.Client,
        userdata: Any,
        flags: paho.ConnectFlags,
        reason_code: ReasonCode,
        properties: Any,
    ) -> None:
        if reason_code.is_failure:
            self._inbox.put_local(ConnectFailed(f"broker refused the connection: {reason_code}"))
            return
        self._backoff.reset()
        # Subscribing here, not once at start-up, restores the subscriptions after a reconnect.
        # The own status topic is watched for a late Last Will; QoS 0 is enough, since every
        # reconnection delivers the retained status anew, and spares a PUBACK per echo.
        # Restarts and log requests from the desk come on topics of their own (the ACL lets
        # operators write them, and robots only read their own).
        client.subscribe(
            [(topic, 0 if topic == self.status_topic else QOS) for topic in self.reads]
        )
        self._inbox.put_local(Connected(self._conn_seq))

    def _on_disconnect(
        self,
        client: paho.Client,
        userdata: Any,
        flags: paho.DisconnectFlags,
        reason_code: ReasonCode,
        properties: Any,
    ) -> None:
        self._inbox.put_local(Disconnected(str(reason_code)))

    def _on_message(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        # Cut to one byte over each limit: the outcome (too large) is the same, the rest of a
        # huge payload is not kept while it waits in the inbox.
        if message.topic == self.launch_topic:
            self._inbox.put_local(LaunchMessage(bytes(message.payload[: MAX_REQUEST_BYTES + 1])))
        elif message.topic == self.status_topic:
            payload = bytes(message.payload[: MAX_STATUS_BYTES + 1])
            if payload not in self._echoes:
                self._inbox.put_local(StatusMessage(payload))
        elif message.topic == self.restart_topic:
            payload = bytes(message.payload[: MAX_COMMAND_BYTES + 1])
            self._inbox.put_local(RestartMessage(payload, bool(message.retain)))
        elif message.topic == self.logs_request_topic and not message.retain:
            # A retained log request is stale by nature: nobody waits for its answer.
            self._inbox.put_local(LogsMessage(bytes(message.payload[: MAX_COMMAND_BYTES + 1])))

    # ------------------------------------------------------------ the agent's loop

    def start(self) -> None:
        address = self._connection.address
        self.client.connect_async(address.host, address.port, keepalive=self._keepalive)
        self._started = True
        self._retry_at = 0.0

    def watch(self) -> tuple[int, int, bool] | None:
        """What to wait on: (socket generation, fd, wants to write); None without a socket.

        The generation tells a new socket from a closed one that had the same number."""
        if not self._socket_open:
            return None
        sock = self.client.socket()
        if sock is None:
            return None
        return self._generation, sock.fileno(), self.client.want_write()

    def wait_limit(self, now: float) -> float | None:
        """Seconds until `service()` has work without any readiness; None: nothing planned."""
        if not self._started or self._attempt is not None:
            return None
        if not self._socket_open:
            return max(0.0, self._retry_at - now)
        if self._tls_pending():
            return 0.0
        return max(0.0, self._next_misc - now)

    def service(self, readable: bool, writable: bool, now: float) -> None:
        """Reads, writes, keeps alive; notices a closed socket; starts a connection attempt."""
        if self._attempt is not None and self._attempt_over.is_set():
            self._finish_attempt(now)
        if self._socket_open:
            client = self.client
            if readable or self._tls_pending():
                self._read(client)
            if writable and client.socket() is not None:
                client.loop_write()
            if now >= self._next_misc and client.socket() is not None:
                self._next_misc = now + MISC_INTERVAL
                client.loop_misc()
            if client.socket() is None:  # closed: by the broker, an error, or a keepalive miss
                self._socket_open = False
                self._schedule_retry(now)
        idle = self._started and not self._socket_open and self._attempt is None
        if idle and now >= self._retry_at:
            self._begin_attempt()

    def _read(self, client: paho.Client) -> None:
        # paho reads about one packet per call; a PUBACK and an echo often arrive together,
        # and each packet left would cost the agent one more pass through its loop.
        for _ in range(MAX_READS):
            client.loop_read()
            if client.socket() is None or self._poller is None:
                return
            if not self._poller.poll(0) and not self._tls_pending():
                return

    def _tls_pending(self) -> bool:
        """TLS holds decrypted bytes that no readiness of the socket announces."""
        sock = self.client.socket()
        return sock is not None and getattr(sock, "pending", lambda: 0)() > 0

    def _begin_attempt(self) -> None:
        # TCP connect and TLS handshake block (up to paho's connect timeout): a thread of their
        # own keeps the agent answering its brain and its signals meanwhile.
        self._attempt_error = None
        self._attempt_over.clear()
        self._attempt = threading.Thread(target=self._connect, name="mqtt-connect", daemon=True)
        self._attempt.start()

    def _connect(self) -> None:
        try:
            rc = self.client.reconnect()
            if rc != MQTTErrorCode.MQTT_ERR_SUCCESS:
                self._attempt_error = self._why(rc.name)
        except Exception as exc:  # socket, TLS and name errors alike become a retry
            self._attempt_error = self._why(
                getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
            )
        finally:
            self._attempt_over.set()
            self._inbox.wake()

    def _why(self, detail: str) -> str:
        # The address, never the configured URL: that may carry a password.
        return f"cannot connect to {self._connection.address.url}: {detail}"

    def _finish_attempt(self, now: float) -> None:
        self._attempt = None
        sock = self.client.socket()
        if self._attempt_error is None and sock is not None:
            self._socket_open = True
            self._generation += 1
            self._poller = select.poll()
            self._poller.register(sock.fileno(), select.POLLIN)
            self._next_misc = now + MISC_INTERVAL
            return
        self._inbox.put_local(ConnectFailed(self._attempt_error or "connection closed"))
        self._schedule_retry(now)

    def _schedule_retry(self, now: float) -> None:
        self._retry_at = now + self._backoff.next()

    # ------------------------------------------------------------ publishing

    def publish_status(self, status: AgentStatus) -> paho.MQTTMessageInfo:
        payload = status.model_dump_json().encode("utf-8")
        self._echoes.append(payload)
        return self.client.publish(self.status_topic, payload, qos=QOS, retain=True)

    def publish_description(self, description: RobotDescription) -> None:
        payload = description.model_dump_json(exclude_none=True).encode("utf-8")
        self.client.publish(self.description_topic, payload, qos=QOS, retain=True)

    def publish_interfaces(self, payload: bytes) -> None:
        # Retained: a reader that comes later (the reconciler, `status`) needs the last report.
        self.client.publish(self.interfaces_topic, payload, qos=QOS, retain=True)

    def publish_goals(self, payload: bytes) -> None:
        # Retained: `status` and the browser read the robot's last summary whenever they come.
        self.client.publish(self.goals_topic, payload, qos=QOS, retain=True)

    def publish_outcome(self, payload: bytes) -> None:
        # Not retained, QoS 1: the reconciler's ledger keeps every record, once each.
        self.client.publish(self.goal_outcomes_topic, payload, qos=QOS, retain=False)

    def publish_logs(self, payload: bytes) -> None:
        # Not retained: an answer is for who asks now. Paced by LogStream, so QoS 1 costs
        # a few PUBACKs a second, and a tail's end marker is not lost.
        self.client.publish(self.logs_topic, payload, qos=QOS, retain=False)

    def close(self, final: AgentStatus | None, timeout: float = 5.0) -> None:
        """Publish the final status if connected, then disconnect cleanly (no Last Will)."""
        self._started = False
        deadline = time.monotonic() + timeout
        if final is not None and self._socket_open and self.client.is_connected():
            info = self.publish_status(final)
            self._pump(lambda: info.is_published(), deadline)
            if not info.is_published():
                log.warning("could not publish the final status")
        if self._socket_open:
            self.client.disconnect()
            self._pump(lambda: self.client.socket() is None, deadline)
            self._socket_open = False
        elif self._attempt is not None:
            self.client.disconnect()  # an attempt still under way: its socket is not ours

    def _pump(self, done: Callable[[], bool], deadline: float) -> None:
        """The loop's work, until `done()` or the deadline: for the last messages at shutdown."""
        while not done():
            sock = self.client.socket()
            left = deadline - time.monotonic()
            if sock is None or left <= 0:
                return
            poller = select.poll()
            writing = select.POLLOUT if self.client.want_write() else 0
            poller.register(sock.fileno(), select.POLLIN | writing)
            for _, mask in poller.poll(min(left, 0.1) * 1000):
                if mask & (select.POLLIN | select.POLLHUP | select.POLLERR):
                    self.client.loop_read()
                if mask & select.POLLOUT and self.client.socket() is not None:
                    self.client.loop_write()
