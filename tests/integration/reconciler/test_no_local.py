"""MQTT 5's No Local on the reconciler's view: no echo of what it publishes, the same truth."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from robotconf.contract.mqtt import Connection
from robotconf.readmodel import retained
from robotconf.readmodel.retained import RetainedView, speaks_mqtt5
from tests.support.agents import publish
from tests.support.mosquitto import Mosquitto, free_port
from tests.support.watch import wait_for

FILTER = "robotconf/robots/+/launch"


def view(broker: Mosquitto, *, no_local: bool) -> RetainedView:
    made = RetainedView(
        Connection(broker.url), [FILTER], "robotconf/sync", role="test", no_local=no_local
    )
    made.start()
    assert made.wait_synced(10)
    return made


def test_the_broker_is_asked_whether_it_speaks_mqtt5(mosquitto: Mosquitto) -> None:
    assert speaks_mqtt5(Connection(mosquitto.url))
    assert not speaks_mqtt5(Connection(f"mqtt://127.0.0.1:{free_port()}"), timeout=1.0)


def test_no_local_sends_no_echo_yet_reads_back_what_is_retained(mosquitto: Mosquitto) -> None:
    items = [(f"robotconf/robots/r{i}/launch", f"request {i}".encode()) for i in range(50)]
    quiet = view(mosquitto, no_local=True)
    try:
        assert quiet.publish_retained(items, 10)
        # Its copy is the truth at once (updated at each PUBACK), without a message back.
        assert quiet.snapshot() == dict(items)
        other = "robotconf/robots/r0/launch"
        publish(mosquitto.url, other, b"from someone else")  # another writer is still seen
        wait_for(lambda: quiet.get(other) == b"from someone else", "the other writer's request")
        assert sum(quiet._arrivals.values()) == 1  # that one, and no echo of its own 50
    finally:
        quiet.stop()
    # A new connection reads every retained request back, its own included.
    again = view(mosquitto, no_local=True)
    try:
        expected = dict(items)
        expected["robotconf/robots/r0/launch"] = b"from someone else"
        assert again.snapshot() == expected
    finally:
        again.stop()
    # Without No Local, every request published comes back (the MQTT 3.1.1 behaviour).
    echoing = view(mosquitto, no_local=False)
    try:
        before = sum(echoing._arrivals.values())
        assert echoing.publish_retained([(t, p + b"!") for t, p in items], 10)
        wait_for(lambda: sum(echoing._arrivals.values()) >= before + len(items), "the echoes")
    finally:
        echoing.stop()


def test_publishing_more_than_a_window_sends_every_message_and_keeps_what_it_is_told(
    mosquitto: Mosquitto, monkeypatch: pytest.MonkeyPatch
) -> None:
    """At most PUBLISH_WINDOW messages are in flight: the rest wait for earlier PUBACKs, and
    every one is still published, acknowledged and kept (as `kept` says, not the payload)."""
    monkeypatch.setattr(retained, "PUBLISH_WINDOW", 7)
    items = [(f"robotconf/robots/w{i}/launch", f"request {i}".encode()) for i in range(60)]
    kept = [f"kept {i}".encode() for i in range(60)]
    quiet = view(mosquitto, no_local=True)
    try:
        assert quiet.publish_retained(items, 10, kept)
        mine = {t: p for t, p in quiet.snapshot().items() if "/w" in t}
        assert mine == {t: k for (t, _), k in zip(items, kept, strict=True)}
    finally:
        quiet.stop()
    again = view(mosquitto, no_local=True)
    try:
        held = {t: p for t, p in again.snapshot().items() if "/w" in t}
        assert held == dict(items)  # the broker holds the payloads themselves
    finally:
        again.stop()


def test_what_the_caller_does_not_say_to_keep_is_kept_as_the_view_keeps_it(
    mosquitto: Mosquitto,
) -> None:
    """`kept` None: the view's own `keep` of the payload (here: its upper-cased bytes)."""
    made = RetainedView(
        Connection(mosquitto.url),
        [FILTER],
        "robotconf/sync",
        role="test",
        no_local=True,
        keep=lambda topic, payload: payload.upper(),
    )
    made.start()
    try:
        assert made.wait_synced(10)
        items = [(f"robotconf/robots/k{i}/launch", f"request {i}".encode()) for i in range(3)]
        assert made.publish_retained(items, 10, [b"told", None, b""])
        mine = {t: p for t, p in made.snapshot().items() if "/k" in t}
        assert mine == {items[0][0]: b"told", items[1][0]: b"REQUEST 1"}  # b"": nothing kept
    finally:
        made.stop()


def test_payloads_made_as_they_are_sent_within_a_window_of_bytes(
    mosquitto: Mosquitto, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A payload may be what makes it: each is made once, when it is sent; a window of bytes
    holds back the rest (here two payloads of 10 bytes at most), and one payload larger than
    the whole window still goes, alone."""
    monkeypatch.setattr(retained, "PUBLISH_WINDOW_BYTES", 25)
    made: list[int] = []

    def maker(i: int, size: int = 10) -> Callable[[], bytes]:
        def make() -> bytes:
            made.append(i)
            return f"request {i}".encode().ljust(size, b".")

        return make

    items: list[tuple[str, retained.Payload]] = [
        (f"robotconf/robots/m{i}/launch", maker(i, 40 if i == 5 else 10)) for i in range(30)
    ]
    quiet = view(mosquitto, no_local=True)
    try:
        assert quiet.publish_retained(items, 10, [b"kept"] * 30)
        assert made == list(range(30))
    finally:
        quiet.stop()
    again = view(mosquitto, no_local=True)
    try:
        held = {t: p for t, p in again.snapshot().items() if "/m" in t}
        assert len(held) == 30
        assert held["robotconf/robots/m5/launch"] == b"request 5".ljust(40, b".")
        assert held["robotconf/robots/m29/launch"] == b"request 29"
    finally:
        again.stop()
