"""Outbound alert POSTs against real local HTTP servers: the timeout bounds a whole POST, a
redirect is never followed nor counted sent, credentials travel as Basic authentication and
never as text (issue 20, item 3)."""

from __future__ import annotations

import base64
import logging
import ssl
from collections.abc import Iterator
from pathlib import Path

import pytest

from robotconf.readmodel.events import Event, Kind
from robotconf.reconciler.notify import Sender, parse_receiver
from tests.support.receivers import ANSWER, Dripper, Recorder
from tests.support.tlsutil import make_pki
from tests.support.watch import wait_for

EVENT = Event(Kind.COMMIT_REFUSED, "bbbbbbbbbbbb on main refused (BuildFailed): nope", 1.0, "main")


class Counted:
    def __init__(self) -> None:
        self.outcomes: list[tuple[str, str]] = []

    def __call__(self, receiver: str, outcome: str) -> None:
        self.outcomes.append((receiver, outcome))


@pytest.fixture
def recorders() -> Iterator[list[Recorder]]:
    made: list[Recorder] = []
    try:
        yield made
    finally:
        for recorder in made:
            recorder.close()


def test_a_receiver_answering_a_byte_at_a_time_is_given_up_at_the_deadline() -> None:
    """Each byte comes well within the timeout: a timeout per read would wait for all of
    them and count the event sent. The deadline gives the POST up mid-answer."""
    dripper = Dripper(every=0.4)
    counted = Counted()
    sender = Sender(parse_receiver(dripper.url), counted, timeout=1.0, attempts=1)
    sender.start()
    try:
        sender.put(EVENT)
        wait_for(lambda: counted.outcomes, "the POST's outcome")
        assert counted.outcomes == [(f"#1 {dripper.url.removesuffix('/hook')}", "failed")]
        given_up = wait_for(lambda: dripper.given_up, "the receiver seeing the client leave")
        assert given_up[0] < len(ANSWER) and dripper.answered == 0
    finally:
        sender.stop()
        dripper.close()


@pytest.fixture
def tls(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> ssl.SSLContext:
    """A server context whose certificate the client trusts (its default context, which
    reads SSL_CERT_FILE): HTTPS receivers are checked as in production."""
    pki = make_pki(tmp_path / "pki")
    monkeypatch.setenv("SSL_CERT_FILE", str(pki.ca_cert))
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    context.load_cert_chain(pki.server_cert, pki.server_key)
    return context


@pytest.mark.parametrize("handshake", [False, True], ids=["answer", "handshake"])
def test_an_https_receiver_dripping_its_answer_or_its_handshake_is_given_up(
    tls: ssl.SSLContext, handshake: bool
) -> None:
    good = Dripper(every=0.0, tls=tls)
    dripper = Dripper(every=0.4, tls=tls, handshake=handshake)
    counted = Counted()
    senders = [
        Sender(parse_receiver(good.url, 1), counted, timeout=5.0, attempts=1),
        Sender(parse_receiver(dripper.url, 2), counted, timeout=1.0, attempts=1),
    ]
    for sender in senders:
        sender.start()
    try:
        for sender in senders:
            sender.put(EVENT)
        wait_for(lambda: len(counted.outcomes) == 2, "both outcomes")
        assert sorted(o for _, o in counted.outcomes) == ["failed", "sent"]
        assert (f"#1 {good.url.removesuffix('/hook')}", "sent") in counted.outcomes
        assert good.answered == 1
        given_up = wait_for(lambda: dripper.given_up, "the receiver seeing the client leave")
        assert dripper.answered == 0 and given_up[0] > 0  # given up mid-way
    finally:
        for sender in senders:
            sender.stop()
        good.close()
        dripper.close()


def test_each_attempt_has_its_own_deadline_and_a_failure_is_logged_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    dripper = Dripper(every=0.4)
    counted = Counted()
    sender = Sender(parse_receiver(dripper.url), counted, timeout=1.0, retry=(0.1, 0.1))
    sender.start()
    try:
        with caplog.at_level(logging.WARNING, logger="robotconf.reconciler"):
            sender.put(EVENT)
            wait_for(lambda: counted.outcomes, "the event's outcome")
            wait_for(lambda: len(dripper.given_up) == 3, "three POSTs given up")
        assert [o for _, o in counted.outcomes] == ["failed"]
        said = [r.getMessage() for r in caplog.records if "not delivered" in r.getMessage()]
        assert len(said) == 1 and "after 3 attempt(s): no answer within 1 s" in said[0]
    finally:
        sender.stop()
        dripper.close()


def test_a_stop_gives_up_the_post_under_way_without_counting_it() -> None:
    dripper = Dripper(every=30.0)
    counted = Counted()
    sender = Sender(parse_receiver(dripper.url), counted, timeout=600.0)
    sender.start()
    try:
        sender.put(EVENT)
        wait_for(lambda: dripper.received, "the POST under way")
        sender.stop()
        wait_for(lambda: dripper.given_up, "the receiver seeing the client leave")
        assert counted.outcomes == []
    finally:
        dripper.close()


@pytest.mark.parametrize("code", [301, 302, 303, 307, 308])
def test_a_redirect_is_a_failure_said_once_by_host_never_followed(
    code: int, recorders: list[Recorder], caplog: pytest.LogCaptureFixture
) -> None:
    target = Recorder()
    recorders.append(target)
    location = f"http://localhost:{target.port}/services/T0/B0/redirect-secret?token=t0k3n"
    redirecting = Recorder(code, location)
    recorders.append(redirecting)
    counted = Counted()
    receiver = parse_receiver(f"slack:{redirecting.base}/hook")
    sender = Sender(receiver, counted, retry=(0.1, 0.1))
    sender.start()
    try:
        with caplog.at_level(logging.WARNING, logger="robotconf.reconciler"):
            sender.put(EVENT)
            wait_for(lambda: counted.outcomes, "the event's outcome")
        assert counted.outcomes == [(f"#1 slack:{redirecting.base}", "failed")]
        posted = redirecting.requests()
        assert [r.method for r in posted] == ["POST"]  # a 3xx is not retried
        assert posted[0].body == {"text": EVENT.text()}
        assert target.requests() == []  # neither a GET without the body nor a POST
        said = [r.getMessage() for r in caplog.records]
        assert len(said) == 1
        assert f"#1 slack:{redirecting.base}" in said[0]
        assert f"HTTP {code}, a redirect to localhost: not followed" in said[0]
        for secret in ("redirect-secret", "t0k3n", str(target.port), "/hook"):
            assert secret not in said[0]
    finally:
        sender.stop()


def test_credentials_in_the_url_are_sent_as_basic_authentication_and_never_shown(
    recorders: list[Recorder], caplog: pytest.LogCaptureFixture
) -> None:
    ok = Recorder()
    refusing = Recorder(403)
    recorders += [ok, refusing]
    # The password holds @ : / (percent-encoded, as a URL must).
    good = parse_receiver(f"http://alert%40lab:pa%40ss%3Aw%2Frd@127.0.0.1:{ok.port}/hook", 1)
    bad = parse_receiver(f"http://alert:pa%40ss%3Aw%2Frd@127.0.0.1:{refusing.port}/hook", 2)
    counted = Counted()
    senders = [Sender(receiver, counted, retry=(0.1, 0.1)) for receiver in (good, bad)]
    for sender in senders:
        sender.start()
    try:
        with caplog.at_level(logging.DEBUG):
            for sender in senders:
                sender.put(EVENT)
            wait_for(lambda: len(counted.outcomes) == 2, "both outcomes")
        assert sorted(counted.outcomes) == [
            (f"#1 {ok.base}", "sent"),
            (f"#2 {refusing.base}", "failed"),
        ]
        (posted,) = ok.requests()
        expected = base64.b64encode(b"alert@lab:pa@ss:w/rd").decode()
        assert posted.headers["authorization"] == f"Basic {expected}"
        assert posted.headers["host"] == f"127.0.0.1:{ok.port}" and posted.path == "/hook"
        shown = caplog.text + repr(good) + repr(bad) + good.name + bad.name
        for secret in ("pa%40ss", "pa@ss", "w/rd", "w%2Frd", expected):
            assert secret not in shown
    finally:
        for sender in senders:
            sender.stop()
