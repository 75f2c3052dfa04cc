"""Reading retained payloads with a memo: the same verdicts as without, read once per payload."""

from __future__ import annotations

from robotconf.contract.launch import StopRequest
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from robotconf.readmodel.observed import LaunchDigests, ReadMemo, parse_retained
from robotconf.readmodel.retained import Ignored
from tests.support.agents import make_request

T = Topics()


def status(robot: str, state: AgentState) -> bytes:
    return AgentStatus(robot_id=robot, state=state).model_dump_json().encode()


def test_a_memo_reads_each_payload_once_and_gives_what_a_fresh_read_gives() -> None:
    messages = {
        T.launch("tb3-01"): make_request("tb3-01").payload(),
        T.launch("tb3-02"): b"{not json",
        T.status("tb3-01"): status("tb3-01", AgentState.RUNNING),
    }
    memo = ReadMemo()
    first = parse_retained(messages, T, requests=False, memo=memo)
    again = parse_retained(dict(messages), T, requests=False, memo=memo)
    fresh = parse_retained(messages, T, requests=False)
    for seen in (first, again):
        assert seen.launch_digests() == fresh.launch_digests()
        assert seen.ignored == fresh.ignored == {"launch": 1}
        assert seen.robots["tb3-02"].launch_retained
    # Read once: the second call reuses the model the first one built.
    assert again.robots["tb3-01"].status is first.robots["tb3-01"].status
    # A changed payload is read again; a topic gone is forgotten.
    messages[T.status("tb3-01")] = status("tb3-01", AgentState.FAILED)
    del messages[T.launch("tb3-02")]
    third = parse_retained(messages, T, requests=False, memo=memo)
    status_seen = third.robots["tb3-01"].status
    assert status_seen is not None and status_seen.state is AgentState.FAILED
    assert "tb3-02" not in third.robots and third.ignored == {}
    assert len(memo._readings) == 2


def test_an_invalid_request_with_a_digest_keeps_its_digest_in_a_full_read() -> None:
    payload = make_request("tb3-01").payload().replace(b'"robot_name"', b'"robot_nom"')
    seen = parse_retained({T.launch("tb3-01"): payload}, T, memo=ReadMemo())
    robot = seen.robots["tb3-01"]
    assert robot.launch is None and robot.launch_digest is not None and robot.launch_retained
    assert seen.ignored == {"launch": 1}


def test_launch_digests_follow_the_snapshots_as_a_fresh_read_does() -> None:
    # Kept from one snapshot to the next, updated by what changed: at every step the digests
    # and the unreadable payloads noted are those of reading the whole snapshot again.
    garbage = b"{not json"
    stop_for_another = StopRequest(robot_id="tb3-09", revision="r").model_dump_json().encode()
    snapshots: list[dict[str, bytes]] = [
        {
            T.launch("tb3-01"): make_request("tb3-01").payload(),
            T.launch("tb3-02"): garbage,
            T.launch("tb3-03"): StopRequest(robot_id="tb3-03", revision="r")
            .model_dump_json()
            .encode(),
            T.reconciler_status: b"[]",
            f"{T.prefix}/elsewhere": b"x",
        },
        {},  # all gone
    ]
    again = dict(snapshots[0])
    again[T.launch("tb3-01")] = make_request("tb3-01", variant=2).payload()
    again[T.launch("tb3-02")] = make_request("tb3-02").payload()  # readable now
    again[T.launch("tb3-03")] = b""  # cleared
    again[T.launch("tb3-04")] = stop_for_another
    again.pop(T.reconciler_status)
    snapshots[1:1] = [dict(snapshots[0]), again, dict(again)]
    kept, noted = LaunchDigests(T), Ignored()
    for step, messages in enumerate(snapshots):
        fresh, fresh_noted = parse_retained(messages, T, requests=False), Ignored()
        parse_retained(messages, T, requests=False, ignored=fresh_noted)
        assert kept.update(messages, noted) == fresh.launch_digests(), step
        assert noted._seen == fresh_noted._seen, step
        noted = Ignored()
    assert kept.update({}) == {} and not kept._errors and not kept._robot_of
