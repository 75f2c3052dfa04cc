"""A launch request in the reconciler's canonical form is read by its opening bytes: the same
digest a full parse gives, and any other form (or a broken one) still parsed in full."""

from __future__ import annotations

import json

from robotconf.configurator.render import render_fleet
from robotconf.configurator.workspace import check
from robotconf.contract.wire import Topics
from robotconf.readmodel.observed import canonical_digest, parse_retained, summarise_launches
from tests.support.lab import ROOT

T = Topics()


def _requests() -> dict[str, bytes]:
    fleet = render_fleet(check(ROOT).repo)
    return {T.launch(robot): request.payload() for robot, request in fleet.requests.items()}


def test_a_canonical_request_is_read_by_its_header_as_in_full() -> None:
    messages = _requests()
    for payload in messages.values():
        assert canonical_digest(payload) == json.loads(payload)["digest"]
    by_header = parse_retained(messages, T, requests=False)
    in_full = parse_retained(messages, T, requests=True)
    assert by_header.launch_digests() == in_full.launch_digests()
    assert by_header.ignored == {}


def test_other_forms_are_parsed_in_full() -> None:
    topic, payload = next(iter(_requests().items()))
    digest = json.loads(payload)["digest"]
    spaced = json.dumps(json.loads(payload), indent=1).encode()  # valid, not canonical
    assert canonical_digest(spaced) is None
    assert parse_retained({topic: spaced}, T, requests=False).launch_digests() == {
        topic.split("/")[2]: digest
    }
    cut = payload[: len(payload) // 2]  # the header intact, the rest lost
    assert canonical_digest(cut) is None
    read = parse_retained({topic: cut}, T, requests=False)
    assert read.launch_digests() == {topic.split("/")[2]: None}  # retained, unreadable
    assert read.ignored == {"launch": 1}
    forged = payload.replace(b'"kind":"LaunchRequest"', b'"kind":"Stop"', 1)
    assert canonical_digest(forged) is None  # only a request's header is read so


def test_the_reconcilers_summary_of_a_canonical_request_is_its_header() -> None:
    keep = summarise_launches(T)
    for topic, payload in _requests().items():
        summary = json.loads(keep(topic, payload))
        assert summary == {"digest": json.loads(payload)["digest"], "kind": "LaunchRequest"}
