"""What the reconciler keeps of each retained launch payload (a summary of its kind and digest)
reads as the payload itself does, whatever the payload: the diff and the status are the same."""

from __future__ import annotations

import json
from dataclasses import asdict

from hypothesis import given, settings
from hypothesis import strategies as st

from robotconf.contract.launch import StopRequest
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from robotconf.readmodel.observed import launch_summary, parse_retained, summarise_launches
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
