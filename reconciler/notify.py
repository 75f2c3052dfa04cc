"""Alert receivers: each URL gets events POSTed by a worker thread of its own.

A bounded queue (the oldest event dropped, and counted, when full), a short timeout and a few
retries with backoff: a receiver that fails or hangs never delays reconciling, nor the others.
"""

from __future__ import annotations

import collections
import json
import logging
import threading
import urllib.error
import urllib.request
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from urllib.parse import urlsplit

from configurator.backoff import Backoff
from reconciler.events import Event

log = logging.getLogger("robotconf.reconciler")

SLACK = "slack:"
QUEUE = 100  # events waiting per receiver; beyond, the oldest is dropped
TIMEOUT = 5.0  # seconds a receiver has to answer one POST
ATTEMPTS = 3  # POSTs of one event before it is given up
RETRY_INITIAL, RETRY_MAX = 1.0, 10.0
# Outcomes a receiver's metrics count: sent, failed (given up after retries), dropped (queue).
OUTCOMES = ("sent", "failed", "dropped")

Counter = Callable[[str, str], None]  # (receiver name, outcome)


@dataclass(frozen=True)
class Receiver:
    """A validated receiver URL. `name` is what logs and metrics show: its position and host,
    never its credentials nor its path (a Slack webhook's path is its secret)."""

    url: str
    slack: bool
    name: str

    def body(self, event: Event) -> bytes:
        if self.slack:
            return json.dumps({"text": event.text()}).encode()
        return json.dumps(event.as_json()).encode()


def parse_receiver(text: str, index: int = 1) -> Receiver:
    """`http(s)://…`, or `slack:https://…` for a Slack-compatible `{"text": …}` body.
    ValueError with a one-line reason, which never repeats the URL's credentials or path."""
    slack = text.startswith(SLACK)
    url = text[len(SLACK) :] if slack else text
    try:
        parts = urlsplit(url)
        host, port = parts.hostname, parts.port
    except ValueError:
        raise ValueError(f"--notify #{index} is not a valid URL") from None
    if parts.scheme not in ("http", "https"):
        raise ValueError(
            f"--notify #{index} must be an http:// or https:// URL (optionally prefixed slack:)"
        )
    if not host:
        raise ValueError(f"--notify #{index} has no host")
    shown = f"{parts.scheme}://{host}{f':{port}' if port else ''}"
    return Receiver(url, slack, f"#{index} {SLACK if slack else ''}{shown}")


class Sender:
    """One receiver's worker thread: POSTs the events queued for it, in order."""

    def __init__(
        self,
        receiver: Receiver,
        count: Counter | None = None,
        *,
        timeout: float = TIMEOUT,
        attempts: int = ATTEMPTS,
        retry: tuple[float, float] = (RETRY_INITIAL, RETRY_MAX),
    ) -> None:
        self.receiver = receiver
        self.timeout = timeout
        self.attempts = attempts
        self.retry = retry
        self._count = count
        self._queue: collections.deque[Event] = collections.deque(maxlen=QUEUE)
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._stop = threading.Event()
        self.dropped = 0
        # The environment's proxy settings apply: a receiver is reached as curl would.
        self._opener = urllib.request.build_opener()
        self._thread = threading.Thread(
            target=self._run, name=f"notify {receiver.name}", daemon=True
        )

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 1.0) -> None:
        """Events still queued are not sent: a stop does not wait for a slow receiver."""
        self._stop.set()
        self._ready.set()
        self._thread.join(timeout)

    def put(self, event: Event) -> None:
        """Never blocks: a full queue drops its oldest event."""
        with self._lock:
            if len(self._queue) == self._queue.maxlen:
                self.dropped += 1
                self._counted("dropped")
                log.warning("notify %s: queue full, oldest event dropped", self.receiver.name)
            self._queue.append(event)
        self._ready.set()

    def _take(self) -> Event | None:
        with self._lock:
            if not self._queue:
                self._ready.clear()
                return None
            return self._queue.popleft()

    def _run(self) -> None:
        while not self._stop.is_set():
            event = self._take()
            if event is None:
                self._ready.wait()
                continue
            try:
                self._deliver(event)
            except Exception:  # a bug here must not end the receiver's thread
                log.exception("notify %s: internal error; event dropped", self.receiver.name)

    def _deliver(self, event: Event) -> None:
        body = self.receiver.body(event)
        backoff = Backoff(*self.retry)
        for attempt in range(1, self.attempts + 1):
            error, final = self._post(body)
            if error is None:
                self._counted("sent")
                return
            if final or attempt == self.attempts:
                log.warning(
                    "notify %s: %s event not delivered after %d attempt(s): %s",
                    self.receiver.name,
                    event.kind.value,
                    attempt,
                    error,
                )
                self._counted("failed")
                return
            if self._stop.wait(backoff.next()):
                return

    def _post(self, body: bytes) -> tuple[str | None, bool]:
        """None, or why the POST failed and whether retrying is pointless (a 4xx refusal)."""
        request = urllib.request.Request(
            self.receiver.url,
            data=body,
            headers={"Content-Type": "application/json", "User-Agent": "robotconf"},
            method="POST",
        )
        try:
            with self._opener.open(request, timeout=self.timeout) as answer:
                answer.read(65536)
            return None, False
        except urllib.error.HTTPError as exc:
            final = 400 <= exc.code < 500 and exc.code not in (408, 429)
            return f"HTTP {exc.code}", final
        except (OSError, ValueError) as exc:
            # URLError wraps the cause, whose text may name the host but never the path.
            reason = getattr(exc, "reason", exc)
            return f"{type(exc).__name__}: {reason}", False

    def _counted(self, outcome: str) -> None:
        if self._count is not None:
            self._count(self.receiver.name, outcome)


class Notifier:
    """Tells every receiver every event; each on its own thread."""

    def __init__(
        self, receivers: Sequence[Receiver], count: Counter | None = None, timeout: float = TIMEOUT
    ) -> None:
        self.senders = [Sender(receiver, count, timeout=timeout) for receiver in receivers]

    def start(self) -> None:
        for sender in self.senders:
            sender.start()

    def stop(self) -> None:
        for sender in self.senders:
            sender.stop()

    def tell(self, events: Sequence[Event]) -> None:
        for event in events:
            log.info("event %s: %s", event.kind.value, event.message)
            for sender in self.senders:
                sender.put(event)
