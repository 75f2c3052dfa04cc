"""The embedded broker's gate: amqtt, made to check a client's login before it acts on its CONNECT,
within a deadline, and to hold a bounded number of connections. Imports amqtt: only
`workstation/broker.py` imports this, once amqtt is known to be installed.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from amqtt.adapters import ReaderAdapter
from amqtt.broker import Broker
from amqtt.errors import AMQTTError, NoDataError
from amqtt.mqtt.connack import BAD_USERNAME_PASSWORD, ConnackPacket
from amqtt.mqtt.connect import ConnectPacket
from amqtt.plugins.base import BaseAuthPlugin

from contract.throttle import Throttle
from workstation.broker_login import BrokerLogin

log = logging.getLogger("robotconf.broker")


class LoginPlugin(BaseAuthPlugin):  # type: ignore[misc]
    """amqtt's own authentication, given the same login: a client amqtt would let in without
    the gate (were amqtt to change where a CONNECT is read) is still checked."""

    @dataclass
    class Config:
        username: str = ""
        password_file: str = ""

    async def authenticate(self, *, session: Any) -> bool:
        config = self.context.config
        login = BrokerLogin(config.username, Path(config.password_file))
        return login.accepts(session.username, session.password)


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
    ) -> None:
        super().__init__(config, loop=loop)
        self._login = login
        self._connect_timeout = connect_timeout
        self._max_clients = max_clients
        self._clients = 0
        self._said = Throttle(60.0, limit=3)

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
        if not self._login.accepts(username, password):
            self._say(
                f"embedded broker: a client from {remote_address} refused: not the login of "
                "robotconf up"
            )
            try:
                await ConnackPacket.build(0, BAD_USERNAME_PASSWORD).to_stream(writer)
            finally:
                await writer.close()
            raise AMQTTError(f"{remote_address}: not the login of robotconf up")
        replay = _Replay(reader, bytes(recording.data))
        return await super()._initialize_client_session(replay, writer, remote_address, remote_port)


def gated() -> bool:
    """True when this amqtt reads a CONNECT where the gate expects to (the versions pinned)."""
    return all(
        callable(getattr(Broker, name, None))
        for name in ("_client_connected", "_initialize_client_session")
    )
