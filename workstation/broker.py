"""The embedded broker of `robotconf up`: amqtt (pure Python, MQTT 3.1.1) on its own thread,
taking no client without a password `up` generates, each client held to its topics as the
generated Mosquitto ACL holds it (a robot to its own).

Imported only by `up` when no `--broker` is given, so nothing else needs amqtt.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import socket
import threading
from collections.abc import Iterator
from importlib import metadata
from typing import Any

from robotconf.contract.wire import DEFAULT_PREFIX
from robotconf.workstation.broker_login import BrokerLogin

DEFAULT_PORT = 1883
START_TIMEOUT = 15.0
CONNECT_TIMEOUT = 10.0  # seconds a client has, once connected, to send its whole CONNECT
MAX_CLIENTS = 256  # connections at once; more are closed at once (an fd each, below ulimit -n)


class BrokerStartError(Exception):
    """The embedded broker could not be started; the message says what to do."""


def port_is_free(host: str, port: int) -> bool:
    """True when a server may listen on `port`: bound as amqtt binds it (SO_REUSEADDR), so that
    the TIME-WAIT connections a broker just stopped leaves behind do not count as taken."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError:
            return False
    return True


def free_port(host: str) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        port: int = sock.getsockname()[1]
        return port


class _SnapshotDict(dict[str, Any]):
    """A dict whose iteration walks a copy of its keys.

    amqtt (0.11 and 0.12) loops over its subscriptions with an `await` inside the loop when a
    client connects; another client subscribing meanwhile changes the dict, the loop raises
    "RuntimeError: dictionary changed size during iteration", asyncio logs it and the
    connecting client is dropped (it reconnects). `up` connects five agents at once: that
    happened at most starts. Iterating a copy is what amqtt's loop means to do."""

    def __iter__(self) -> Iterator[str]:
        return iter(list(super().__iter__()))

    def items(self) -> Any:
        return list(super().items())


def _harden(broker: Any) -> None:
    subscriptions = getattr(broker, "_subscriptions", None)
    if type(subscriptions) is dict:
        broker._subscriptions = _SnapshotDict(subscriptions)
    else:  # an amqtt outside the pinned range: it may or may not have the bug
        logging.getLogger("robotconf.broker").warning(
            "amqtt %s: subscriptions not hardened (see workstation/broker.py)", _version()
        )


def _version() -> str:
    try:
        return metadata.version("amqtt")
    except metadata.PackageNotFoundError:
        return "?"


class EmbeddedBroker:
    """An amqtt broker on 127.0.0.1 that takes only clients giving a login of the folder of
    `login` (the operator's; up's reconciler and each robot have theirs beside it), with the rules
    of the ACL for topics under `prefix`; the port is `port` when given, else `preferred` (1883)
    when free, else any free one."""

    def __init__(
        self,
        login: BrokerLogin,
        host: str = "127.0.0.1",
        port: int | None = None,
        *,
        preferred: int = DEFAULT_PORT,
        connect_timeout: float = CONNECT_TIMEOUT,
        max_clients: int = MAX_CLIENTS,
        prefix: str = DEFAULT_PREFIX,
    ) -> None:
        self.login = login
        self.prefix = prefix
        self.host = host
        self.port = port or 0
        self.preferred = preferred
        self.connect_timeout = connect_timeout
        self.max_clients = max_clients
        self._loop: asyncio.AbstractEventLoop | None = None
        self._broker: Any = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    @property
    def url(self) -> str:
        return f"mqtt://{self.host}:{self.port}"

    def start(self) -> None:
        try:
            import amqtt.broker  # noqa: F401 - imported here: only `up` needs it
        except ImportError as exc:
            raise BrokerStartError(
                "the embedded broker needs amqtt: pip install 'robotconf[server]' "
                "(or pass --broker mqtt://HOST:PORT to use a running broker)"
            ) from exc
        from robotconf.workstation.broker_gate import gated

        if not gated():  # amqtt outside the pinned range: its CONNECT is read elsewhere
            logging.getLogger("robotconf.broker").warning(
                "amqtt %s: logins are checked only by amqtt itself "
                "(see workstation/broker_gate.py)",
                _version(),
            )
        # amqtt logs every connection and any client that vanishes; keep that out of the screen.
        logging.getLogger("amqtt").setLevel(logging.ERROR)
        logging.getLogger("transitions").setLevel(logging.ERROR)
        candidates = [self.port] if self.port else []
        if not candidates:
            if port_is_free(self.host, self.preferred):
                candidates.append(self.preferred)
            candidates += [free_port(self.host), free_port(self.host)]
        last: BaseException | None = None
        for port in candidates:
            try:
                self._start_on(port)
                return
            except BrokerStartError as exc:
                last = exc
        raise BrokerStartError(f"the embedded broker could not start: {last}")

    def _start_on(self, port: int) -> None:
        self.port = port
        self._ready.clear()
        self._error = None
        self._thread = threading.Thread(target=self._run, name="robotconf-broker", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT):
            raise BrokerStartError(f"no answer on port {port} after {START_TIMEOUT:g} s")
        if self._error is not None:
            self._thread.join(5)
            raise BrokerStartError(f"port {port}: {_reason(self._error)}")

    def _run(self) -> None:
        from robotconf.workstation.broker_gate import GatedBroker, LoginPlugin, TopicRulesPlugin

        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)

        def path(plugin: type) -> str:
            return f"{plugin.__module__}.{plugin.__name__}"

        config = {
            "listeners": {"default": {"type": "tcp", "bind": f"{self.host}:{self.port}"}},
            # No logging or $SYS plugins: a quiet broker for one machine. Every local user can
            # reach 127.0.0.1: only clients with up's logins are let in, each to its topics.
            "plugins": {
                path(LoginPlugin): {"folder": str(self.login.password_file.parent)},
                path(TopicRulesPlugin): {"prefix": self.prefix},
            },
        }

        async def main() -> None:
            self._broker = GatedBroker(
                config,
                self.login,
                connect_timeout=self.connect_timeout,
                max_clients=self.max_clients,
                loop=loop,
                prefix=self.prefix,
            )
            _harden(self._broker)
            await self._broker.start()

        try:
            loop.run_until_complete(main())
        except BaseException as exc:
            self._error = exc
            self._ready.set()
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            with contextlib.suppress(Exception):
                loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()

    def stop(self, timeout: float = 10.0) -> None:
        loop, broker, thread = self._loop, self._broker, self._thread
        if loop is None or thread is None or not thread.is_alive():
            return
        if broker is not None:
            future = asyncio.run_coroutine_threadsafe(broker.shutdown(), loop)
            with contextlib.suppress(Exception):
                future.result(timeout)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout)


def _reason(exc: BaseException) -> str:
    cause: BaseException | None = exc
    while cause is not None:
        if isinstance(cause, OSError) and cause.errno == errno.EADDRINUSE:
            return "address already in use"
        cause = cause.__cause__
    return f"{type(exc).__name__}: {exc}"
