"""The agent's MQTT edge: one paho client, a Last Will per connection, callbacks that only enqueue.

Nothing here decides anything: every callback hands an event to the agent's thread.
"""

from __future__ import annotations

import logging
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.reasoncodes import ReasonCode

from agent.events import (
    Connected,
    ConnectFailed,
    Disconnected,
    Inbox,
    LaunchMessage,
    StatusMessage,
)
from agent.workdir import SeqStore
from configurator.mqtt import Connection, make_client
from configurator.wire import AgentState, AgentStatus, RobotDescription, Topics

log = logging.getLogger(__name__)

QOS = 1


def will_payload(robot_id: str, seq: int) -> bytes:
    status = AgentStatus(
        robot_id=robot_id,
        state=AgentState.OFFLINE,
        seq=seq,
        message="connection to the agent lost (Last Will)",
    )
    return status.model_dump_json().encode("utf-8")


class BrokerLink:
    """Connects, reconnects with paho's backoff, and forwards what arrives to the inbox."""

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
        self._connection = connection
        self._keepalive = keepalive
        self._inbox = inbox
        self._seq = seq
        self._conn_seq = 0
        self.client = make_client(connection, client_id=f"robotconf-agent-{robot_id}")
        self.client.on_pre_connect = self._on_pre_connect
        self.client.on_connect = self._on_connect
        self.client.on_connect_fail = self._on_connect_fail
        self.client.on_disconnect = self._on_disconnect
        self.client.on_message = self._on_message

    # ------------------------------------------------------------ network thread

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
            self._inbox.put(ConnectFailed(f"broker refused the connection: {reason_code}"))
            return
        # Subscribing here, not once at start-up, restores the subscriptions after a reconnect.
        client.subscribe([(self.launch_topic, QOS), (self.status_topic, QOS)])
        self._inbox.put(Connected(self._conn_seq))

    def _on_connect_fail(self, client: paho.Client, userdata: Any) -> None:
        # paho does not say why; name the usual suspects.
        address = self._connection.address
        why = "broker down or unreachable"
        if address.tls:
            why += ", or the TLS handshake failed"
        self._inbox.put(ConnectFailed(f"cannot connect to {address.url} ({why})"))

    def _on_disconnect(
        self,
        client: paho.Client,
        userdata: Any,
        flags: paho.DisconnectFlags,
        reason_code: ReasonCode,
        properties: Any,
    ) -> None:
        self._inbox.put(Disconnected(str(reason_code)))

    def _on_message(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        if message.topic == self.launch_topic:
            self._inbox.put(LaunchMessage(bytes(message.payload)))
        elif message.topic == self.status_topic:
            self._inbox.put(StatusMessage(bytes(message.payload)))

    # ------------------------------------------------------------ agent thread

    def start(self) -> None:
        address = self._connection.address
        self.client.connect_async(address.host, address.port, keepalive=self._keepalive)
        self.client.loop_start()

    def publish_status(self, status: AgentStatus) -> paho.MQTTMessageInfo:
        return self.client.publish(
            self.status_topic, status.model_dump_json().encode("utf-8"), qos=QOS, retain=True
        )

    def publish_description(self, description: RobotDescription) -> None:
        payload = description.model_dump_json(exclude_none=True).encode("utf-8")
        self.client.publish(self.description_topic, payload, qos=QOS, retain=True)

    def close(self, final: AgentStatus | None, timeout: float = 5.0) -> None:
        """Publish the final status if connected, then disconnect cleanly (no Last Will)."""
        if final is not None and self.client.is_connected():
            info = self.publish_status(final)
            try:
                info.wait_for_publish(timeout)
            except (RuntimeError, ValueError) as exc:
                log.warning("could not publish the final status: %s", exc)
        self.client.disconnect()
        self.client.loop_stop()
