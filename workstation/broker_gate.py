"""The embedded broker's gate: amqtt, made to check a client's login before it acts on its CONNECT,
within a deadline, to hold a bounded number of connections, and to let each client use only the
topics the generated Mosquitto ACL gives it (contract/topics.py). Imports amqtt: only
`workstation/broker.py` imports this, once amqtt is known to be installed.
"""

from __future__ import annotations

import asyncio
import functools
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from amqtt.adapters import ReaderAdapter
from amqtt.broker import Broker
from amqtt.contexts import Action
from amqtt.errors import AMQTTError, NoDataError
from amqtt.mqtt.connack import (
    BAD_USERNAME_PASSWORD,
    IDENTIFIER_REJECTED,
    NOT_AUTHORIZED,
    ConnackPacket,
)
from amqtt.mqtt.connect import ConnectPacket
from amqtt.plugins.base import BaseAuthPlugin, BaseTopicPlugin

from robotconf.configurator.brokerconf import ServiceUsers
from robotconf.contract.throttle import Throttle
from robotconf.contract.topics import Grants, grants
from robotconf.contract.wire import DEFAULT_PREFIX, agent_client_id
from robotconf.workstation.broker_login import BrokerLogin, accepts

log = logging.getLogger("robotconf.broker")
GRANTS_CACHED = 1024  # clients (user name and client id) whose compiled rules are kept


class LoginPlugin(BaseAuthPlugin):  # type: ignore[misc]
    """amqtt's own authentication, given the same logins: a client amqtt would let in without
    the gate (were amqtt to change where a CONNECT is read) is still checked."""

    @dataclass
    class Config:
        folder: str = ""

    async def authenticate(self, *, session: Any) -> bool:
        return accepts(Path(self.context.config.folder), session.username, session.password)


class BrokerRules:
    """Each client's grants, as the generated ACL gives them (contract/topics.py), compiled once
    per user name and client id: a check on a publish or a delivery is one regex match."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix
        self.services = ServiceUsers().roles()
        self.grants = functools.lru_cache(maxsize=GRANTS_CACHED)(self._grants)

    def _grants(self, username: str | None, client_id: str) -> Grants:
        return grants(self.prefix, username, client_id, self.services)

    def allowed(self, username: str | None, client_id: str, topic: str, action: Any) -> bool:
        rules = self.grants(username, client_id)
        if action == Action.PUBLISH:
            return rules.may_write(topic)
        if action == Action.SUBSCRIBE:  # a filter no read rule covers whole is refused
            return rules.may_subscribe(topic)
        return rules.may_read(topic)  # Action.RECEIVE: each message, before it is sent

    def refusal(
        self, username: str | None, client_id: str, will_topic: str | None
    ) -> tuple[int, str] | None:
        """The CONNACK code and why, when a CONNECT is refused after its login is accepted: a
        robot under another's client id would take over that robot's session (Mosquitto forces
        a robot's client id to its user name), and amqtt sends a Last Will unchecked."""
        own = (username, agent_client_id(username or ""))
        if username not in self.services and client_id not in own:
            return IDENTIFIER_REJECTED, f"robot {username} may not use client id {client_id!r}"
        if will_topic is not None and not self.grants(username, client_id).may_write(will_topic):
            return NOT_AUTHORIZED, f"{username} may not write its Last Will's topic {will_topic!r}"
        return None


class TopicRulesPlugin(BaseTopicPlugin):  # type: ignore[misc]
    """amqtt's topic check, by the same rules as the generated Mosquitto ACL: a refused publish
    is dropped, a refused subscription gets a failure and no message."""

    @dataclass
    class Config:
        prefix: str = DEFAULT_PREFIX

    def __init__(self, context: Any) -> None:
        super().__init__(context)
        self.rules = BrokerRules(self.context.config.prefix)

    async def topic_filtering(
        self, *, session: Any = None, topic: str | None = None, action: Any = None
    ) -> bool:
        if session is None or not topic:
            return False
        return self.rules.allowed(session.username, session.client_id, topic, action)


class _Recording(ReaderAdapter):  # type: ignore[misc]
    """Reads through, and keeps what it read: the CONNECT, for amqtt to read again."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.data = bytearray()

    async def read(self, n: int = -1) -> bytes:
        if n < 0:  # a CONNECT is read field by field, each 64 KiB at most
            raise NoDataError("an unbounded read of a CONNECT")
        chunk: bytes = await self.inner.read(n)
        self.data += chunk
        return chunk

    def feed_eof(self) -> None:
        self.inner.feed_eof()


class _Replay(ReaderAdapter):  # type: ignore[misc]
    """What was read first, then the connection itself."""

    def __init__(self, inner: Any, first: bytes) -> None:
        self.inner = inner
        self.first = first

    async def read(self, n: int = -1) -> bytes:
        if not self.first:
            data: bytes = await self.inner.read(n)
            return data
        if n < 0:
            head, self.first = self.first, b""
            return head + await self.inner.read(n)  # type: ignore[no-any-return]
        head, self.first = self.first[:n], self.first[n:]
        if len(head) < n:
            head += await self.inner.read(n - len(head))
        return head

    def feed_eof(self) -> None:
        self.inner.feed_eof()


class GatedBroker(Broker):  # type: ignore[misc]
    """amqtt's broker, but a client is let in only with `login`, checked before amqtt looks its
    client id up: amqtt authenticates after it has already deleted the subscriptions of the
    session of that id (a clean start) or taken over its connection, so that anyone able to
    connect could knock an agent off its subscriptions without any password. A client has
    `connect_timeout` seconds to send its CONNECT; beyond `max_clients` connections at once, a
    new one is closed at once."""

    def __init__(
        self,
        config: dict[str, Any],
        login: BrokerLogin,
        *,
        connect_timeout: float,
        max_clients: int,
        loop: asyncio.AbstractEventLoop,
        prefix: str = DEFAULT_PREFIX,
    ) -> None:
        super().__init__(config, loop=loop)
        self._login = login
        self._rules = BrokerRules(prefix)
        self._connect_timeout = connect_timeout
        self._max_clients = max_clients
        self._clients = 0
        self._said = Throttle(60.0, limit=3)

    async def _refuse(self, writer: Any, code: int, why: str) -> None:
        self._say(f"embedded broker: a client refused: {why}")
        try:
            await ConnackPacket.build(0, code).to_stream(writer)
        finally:
            await writer.close()

    def _say(self, line: str) -> None:
        said = self._said.admit(line, asyncio.get_running_loop().time())
        if said is not None:
            log.warning("%s", said)

    async def _client_connected(self, listener_name: str, reader: Any, writer: Any) -> None:
        if self._clients >= self._max_clients:
            self._say(f"embedded broker: a connection closed at once: {self._clients} already")
            await writer.close()
            return
        self._clients += 1
        try:
            await super()._client_connected(listener_name, reader, writer)
        finally:
            self._clients -= 1

    async def _publish_retained_messages_for_subscription(
        self, subscription: tuple[str, int], session: Any
    ) -> None:
        """amqtt 0.12 calls this at every CONNECT for every filter anyone holds, and sends the
        retained messages unchecked: a new client got every robot's launch, status and
        description before it subscribed to anything. Only a filter the client holds itself is
        served, and only with the messages it may read."""
        topic_filter, qos = subscription
        held = self._subscriptions.get(topic_filter, ())
        handler = self._get_handler(session)
        if handler is None or all(s.client_id != session.client_id for s, _ in held):
            return
        rules = self._rules.grants(session.username, session.client_id)
        sends = [
            asyncio.ensure_future(
                handler.mqtt_publish(m.topic, m.data, min(qos, m.qos or qos), retain=True)
            )
            for topic, m in list(self._retained_messages.items())
            if self._matches(topic, topic_filter) and rules.may_read(topic)
        ]
        if sends:
            await asyncio.wait(sends)

    async def _initialize_client_session(
        self, reader: Any, writer: Any, remote_address: str, remote_port: int
    ) -> Any:
        recording = _Recording(reader)
        try:
            connect = await asyncio.wait_for(
                ConnectPacket.from_stream(recording), self._connect_timeout
            )
            username, password = connect.username, connect.password
        except Exception as exc:  # silent, slow, or not a CONNECT: nothing to answer
            await writer.close()
            reason = "no CONNECT in time" if isinstance(exc, asyncio.TimeoutError) else "no CONNECT"
            raise AMQTTError(f"{remote_address}: {reason}") from None
        if not accepts(self._login.password_file.parent, username, password):
            why = "not a login of robotconf up"
            await self._refuse(writer, BAD_USERNAME_PASSWORD, f"from {remote_address}: {why}")
            raise AMQTTError(f"{remote_address}: {why}")
        will = connect.payload.will_topic if connect.will_flag else None
        refusal = self._rules.refusal(username, connect.client_id or "", will)
        if refusal is not None:
            code, why = refusal
            await self._refuse(writer, code, f"from {remote_address}: {why}")
            raise AMQTTError(f"{remote_address}: {why}")
        replay = _Replay(reader, bytes(recording.data))
        return await super()._initialize_client_session(replay, writer, remote_address, remote_port)


def gated() -> bool:
    """True when this amqtt reads a CONNECT where the gate expects to (the versions pinned)."""
    return all(
        callable(getattr(Broker, name, None))
        for name in ("_client_connected", "_initialize_client_session")
    )
