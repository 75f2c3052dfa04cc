"""Restarts from the desk: which restart-topic payloads an agent carries out, without a broker."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from robotconf.agent.admission import (
    MAX_COMMAND_BYTES,
    MAX_RESTARTS_AHEAD,
    RESTART_MAX_AGE,
    Reject,
    Restart,
    RestartMemory,
    Verifier,
    interpret_restart,
)
from robotconf.agent.workdir import RESTART_ISSUED_FILE, RESTARTS_AHEAD_FILE, RestartLedger
from robotconf.contract.launch import RestartRequest
from robotconf.contract.signing import (
    generate_keys,
    load_private_key,
    load_public_key,
    sign,
    verify_object,
)

NOW = 1_800_000_000.0


def restart(robot_id: str = "tb3-01", at: float = NOW, by: str = "alice") -> RestartRequest:
    return RestartRequest(robot_id=robot_id, requested_by=by, issued_at=at)


def outcome(
    payload: bytes,
    verify: Verifier | None = None,
    newest: float | None = None,
    memory: RestartMemory | None = None,
    now: float = NOW,
) -> Restart | Reject:
    return interpret_restart(payload, "tb3-01", verify, memory or RestartMemory(newest), now)


def reason(
    payload: bytes,
    verify: Verifier | None = None,
    newest: float | None = None,
    memory: RestartMemory | None = None,
    now: float = NOW,
) -> str:
    found = outcome(payload, verify, newest, memory, now)
    assert isinstance(found, Reject), found
    return found.reason


@pytest.fixture
def keyed(tmp_path: Path) -> tuple[Any, Verifier]:
    pair = generate_keys(tmp_path)
    public = load_public_key(pair.public)
    return load_private_key(pair.private), lambda data: verify_object(data, public)


def test_an_unsigned_restart_is_carried_out_by_an_agent_without_a_key() -> None:
    assert outcome(restart().payload()) == Restart("alice", NOW)


def test_a_restart_for_another_robot_is_refused() -> None:
    assert "for robot 'tb3-02'" in reason(restart("tb3-02").payload())


@pytest.mark.parametrize(
    "payload, expected",
    [
        (b"", "malformed restart request"),
        (b"{", "malformed restart request"),
        (b"[]", "expected a JSON object"),
        (b"x" * (MAX_COMMAND_BYTES + 1), "malformed restart request"),
        (b'{"apiVersion": "robotconf/v1", "kind": "LaunchRequest"}', "not a restart request"),
        (b"[" * 100_000, "malformed restart request"),
    ],
)
def test_garbage_is_refused_with_a_reason(payload: bytes, expected: str) -> None:
    assert expected in reason(payload)


def test_fields_are_validated_after_the_address() -> None:
    data = json.loads(restart().payload())
    data["requested_by"] = "alice; rm -rf /"
    assert "requested_by" in reason(json.dumps(data).encode())
    data = json.loads(restart().payload())
    data["extra"] = 1
    assert "extra" in reason(json.dumps(data).encode())


@pytest.mark.parametrize("offset", [RESTART_MAX_AGE + 1, -(RESTART_MAX_AGE + 1), 1e300, -1e300])
def test_a_restart_far_from_now_is_refused(offset: float) -> None:
    assert "apart" in reason(restart(at=NOW + offset).payload())


def test_each_restart_is_carried_out_once() -> None:
    payload = restart(at=NOW - 10).payload()
    assert isinstance(outcome(payload), Restart)
    assert "not newer than the last one" in reason(payload, newest=NOW - 10)
    assert "not newer than the last one" in reason(payload, newest=NOW - 5)
    assert isinstance(outcome(restart(at=NOW - 4).payload(), newest=NOW - 5), Restart)


def test_a_restart_dated_ahead_locks_out_no_restart_from_a_correct_clock() -> None:
    ahead = restart(at=NOW + 240, by="fastdesk").payload()
    fast = Restart("fastdesk", NOW + 240)
    assert outcome(ahead) == fast
    memory = RestartMemory().carried_out(fast, NOW)
    # The watermark stops at the robot's clock; the one dated ahead is remembered as itself.
    assert memory == RestartMemory(NOW, frozenset({fast}))
    genuine = restart(at=NOW + 1, by="ops").payload()
    assert outcome(genuine, memory=memory, now=NOW + 1.5) == Restart("ops", NOW + 1)
    assert "carried out already" in reason(ahead, memory=memory, now=NOW + 2)
    after = memory.carried_out(Restart("ops", NOW + 1), NOW + 1.5)
    assert after == RestartMemory(NOW + 1, frozenset({fast}))
    assert "carried out already" in reason(ahead, memory=after, now=NOW + 2)
    assert "not newer than the last one" in reason(genuine, memory=after, now=NOW + 2)
    # Another desk, dated the same instant ahead, is another restart; and so is a later one.
    other = restart(at=NOW + 240, by="ops").payload()
    assert outcome(other, memory=after, now=NOW + 3) == Restart("ops", NOW + 240)
    assert isinstance(outcome(restart(at=NOW + 250).payload(), memory=after, now=NOW + 3), Restart)
    # Once its time has come, the watermark covers it, and it is forgotten by itself.
    late = after.carried_out(Restart("ops", NOW + 241), NOW + 241)
    assert late == RestartMemory(NOW + 241, frozenset())


def test_restarts_dated_ahead_are_remembered_up_to_a_bound() -> None:
    memory = RestartMemory()
    for n in range(MAX_RESTARTS_AHEAD):
        found = outcome(restart(at=NOW + 10 + n).payload(), memory=memory)
        assert isinstance(found, Restart)
        memory = memory.carried_out(found, NOW)
    assert "a desk's clock is wrong" in reason(restart(at=NOW + 100).payload(), memory=memory)
    # A correct clock is never refused for it; and the age limit forgets the ones ahead.
    assert isinstance(outcome(restart(at=NOW + 0.5).payload(), memory=memory, now=NOW + 1), Restart)
    later = NOW + 10 + MAX_RESTARTS_AHEAD + RESTART_MAX_AGE
    assert memory.pruned(later).ahead == frozenset()
    assert isinstance(outcome(restart(at=later + 100).payload(), memory=memory, now=later), Restart)


def test_the_restart_ledger_survives_an_agent_restart(tmp_path: Path) -> None:
    ledger = RestartLedger(tmp_path)
    assert (ledger.watermark, ledger.ahead) == (None, frozenset())
    ahead = frozenset({(NOW + 240, "fastdesk"), (NOW + 250, "alice@lab")})
    ledger.record(NOW, ahead)
    again = RestartLedger(tmp_path)
    assert (again.watermark, again.ahead) == (NOW, ahead)
    memory = RestartMemory.of(again.watermark, again.ahead)
    assert memory.ahead == frozenset(
        {Restart("fastdesk", NOW + 240), Restart("alice@lab", NOW + 250)}
    )
    assert memory.ahead_entries() == ahead
    again.record(NOW + 245, frozenset({(NOW + 250, "alice@lab")}))
    assert RestartLedger(tmp_path).ahead == frozenset({(NOW + 250, "alice@lab")})
    for path in tmp_path.iterdir():
        assert path.stat().st_mode & 0o777 == 0o600
    # An older agent's watermark (one number) is read as such; a damaged file as nothing.
    (tmp_path / RESTART_ISSUED_FILE).write_text("1800000000.25\n")
    assert RestartLedger(tmp_path).watermark == 1800000000.25
    (tmp_path / RESTART_ISSUED_FILE).write_text("nan\n")
    assert RestartLedger(tmp_path).watermark is None
    (tmp_path / RESTARTS_AHEAD_FILE).write_bytes(b"\xff garbage\n")
    assert RestartLedger(tmp_path).ahead == frozenset()


def test_with_a_key_only_a_signed_restart_is_carried_out(keyed: tuple[Any, Verifier]) -> None:
    private, check = keyed
    assert "not signed" in reason(restart().payload(), check)
    signed = sign(restart(), private, NOW)
    assert outcome(signed.payload(), check) == Restart("alice", NOW)
    # Who asked is covered by the signature: changing it is a forgery.
    forged = json.loads(signed.payload())
    forged["requested_by"] = "mallory"
    forged_bytes = json.dumps(forged, sort_keys=True, separators=(",", ":")).encode()
    assert "does not verify" in reason(forged_bytes, check)
    # Exactly the signed bytes: white space riding along is refused.
    assert "canonical" in reason(json.dumps(json.loads(signed.payload())).encode(), check)
    # A signed restart replayed: refused once one as new was carried out.
    assert "not newer" in reason(signed.payload(), check, newest=NOW)


def test_a_signed_launch_request_is_not_a_restart(keyed: tuple[Any, Verifier]) -> None:
    from tests.support.agents import make_request

    private, check = keyed
    launch = sign(make_request(), private, NOW)
    assert "not a restart request" in reason(launch.payload(), check)


def test_log_requests_are_bounded_and_strict() -> None:
    from robotconf.agent.admission import interpret_logs_request
    from robotconf.contract.wire import LogsRequest

    good = LogsRequest(session="s1", lines=5, follow=True)
    assert interpret_logs_request(good.model_dump_json().encode()) == good
    for payload, said in [
        (b"[" * 100_000, "malformed logs request"),
        (b"x" * (MAX_COMMAND_BYTES + 1), "malformed logs request"),
        (b'{"session": "s", "lines": 100000000}', "lines"),
        (b'{"session": "../#"}', "session"),
        (b'{"session": "s", "extra": 1}', "extra"),
    ]:
        found = interpret_logs_request(payload)
        assert isinstance(found, Reject) and said in found.reason, (payload[:20], found)
