"""What the reconciler keeps of each retained launch payload (a summary of its kind and digest)
reads as the payload itself does, whatever the payload: the diff and the status are the same."""

from __future__ import annotations

import json
from dataclasses import asdict

from hypothesis import given, settings
from hypothesis import strategies as st

from robotconf.contract.launch import StopRequest
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from robotconf.readmodel.observed import (
    LaunchDigests,
    launch_summary,
    parse_retained,
    summarise_launches,
)
from robotconf.readmodel.retained import oversized
from tests.support.agents import make_request

T = Topics()
KEEP = summarise_launches(T)


def _reads_alike(topic: str, payload: bytes) -> None:
    whole = parse_retained({topic: payload}, T, requests=False)
    kept = parse_retained({topic: KEEP(topic, payload)}, T, requests=False)
    assert {r: asdict(s) for r, s in kept.robots.items()} == {
        r: asdict(s) for r, s in whole.robots.items()
    }
    assert (kept.ignored, kept.reconciler) == (whole.ignored, whole.reconciler)


REQUEST = make_request("tb3-01").payload()
CASES = {
    "request": REQUEST,
    "another robot's stop": StopRequest(robot_id="tb3-02", revision="r").payload(),
    "its stop": StopRequest(robot_id="tb3-01", revision="r").payload(),
    "not json": b"{not json",
    "an array": b"[1, 2]",
    "a number digest": json.dumps({**json.loads(REQUEST), "digest": 7}).encode(),
    "no digest": json.dumps({"kind": "LaunchRequest"}).encode(),
    "a stop of another shape": b'{"kind": "Stop", "robot_id": 3}',
    "deep": b"[" * 5000 + b"]" * 5000,
    "oversized": oversized(10_000_000),
    "invalid request, digest kept": REQUEST.replace(b'"robot_name"', b'"robot_nom"'),
}


def test_each_kind_of_launch_payload_reads_alike_kept_or_whole() -> None:
    for payload in CASES.values():
        _reads_alike(T.launch("tb3-01"), payload)


def test_a_request_is_kept_as_its_kind_and_digest_and_the_rest_whole() -> None:
    request = make_request("tb3-01")
    kept = KEEP(T.launch("tb3-01"), request.payload())
    assert kept == launch_summary("LaunchRequest", request.digest) and len(kept) < 120
    stop = CASES["its stop"]
    assert KEEP(T.launch("tb3-01"), stop) is stop
    status = AgentStatus(robot_id="tb3-01", state=AgentState.RUNNING).model_dump_json().encode()
    assert KEEP(T.status("tb3-01"), status) is status  # only launch topics are summarised
    assert KEEP(T.reconciler_status, b"{}") == b"{}"


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300) | st.sampled_from(list(CASES.values())).map(lambda b: b[:-3]))
def test_any_bytes_read_alike_kept_or_whole(payload: bytes) -> None:
    if payload:
        _reads_alike(T.launch("tb3-01"), payload)


def _signed() -> bytes:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    from robotconf.contract.signing import sign

    return sign(make_request("tb3-01"), Ed25519PrivateKey.generate()).payload()


def test_whether_a_request_is_signed_is_kept_and_read_alike() -> None:
    signed = _signed()
    spaced = json.dumps(json.loads(signed), indent=1).encode()  # not canonical: read in full
    # A knowledge value named "signature" is not the request's signature.
    lookalike = make_request("tb3-01", knowledge={"signature": "A" * 88}).payload()
    topic = T.launch("tb3-01")
    cases = ((signed, True), (spaced, True), (lookalike, False), (REQUEST, False))
    for payload, is_signed in cases:
        _reads_alike(topic, payload)
        kept = parse_retained({topic: KEEP(topic, payload)}, T, requests=False)
        assert kept.robots["tb3-01"].launch_signed is is_signed, payload[-120:]


def test_the_reconciler_s_step_knows_which_robots_hold_an_unsigned_request() -> None:
    digests = LaunchDigests(T)
    one, two = T.launch("tb3-01"), T.launch("tb3-02")
    unsigned = make_request("tb3-02").payload()
    digests.update({one: KEEP(one, _signed()), two: KEEP(two, unsigned)})
    assert digests.unsigned == {"tb3-02"}
    digests.update({one: KEEP(one, _signed()), two: KEEP(two, _signed())})
    assert digests.unsigned == frozenset()
    digests.update({one: KEEP(one, REQUEST)})  # tb3-02 cleared: no longer anyone's
    assert digests.unsigned == {"tb3-01"}
