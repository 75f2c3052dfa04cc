"""The brain's log for the desk: tails, the followed stream, redaction, bounds and pace."""

from __future__ import annotations

import json
from pathlib import Path

from agent.logs import (
    ASKS_PER_SECOND,
    BURST,
    MAX_LINE_BYTES,
    QUEUE_LIMIT,
    RATE,
    READ_LIMIT,
    REDACTED,
    LogStream,
    Redactor,
    fit_line,
    read_tail,
)
from configurator.wire import LOG_FOLLOW_TTL, MAX_LOG_MESSAGE_BYTES, LogsChunk, LogsRequest


def stream(path: Path, secrets: tuple[str, ...] = (), names: tuple[str, ...] = ()) -> LogStream:
    return LogStream(path, "tb3-01", Redactor(secrets, names))


def ask(session: str = "s1", lines: int = 50, follow: bool = False) -> LogsRequest:
    return LogsRequest(session=session, lines=lines, follow=follow)


def lines_of(chunks: list[LogsChunk], session: str | None = "s1") -> list[str]:
    return [line for c in chunks if c.session == session for line in c.lines]


def write(path: Path, *lines: str) -> None:
    with path.open("a", encoding="utf-8") as log:
        log.write("".join(line + "\n" for line in lines))


def test_a_tail_is_the_last_lines_and_ends_with_a_marked_chunk(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, *[f"line {n}" for n in range(100)])
    logs = stream(log)
    assert logs.ask(ask(lines=5), 0.0)
    chunks = logs.take(0.0)
    assert lines_of(chunks) == [f"line {n}" for n in range(95, 100)]
    assert chunks[-1].end and chunks[-1].session == "s1" and not chunks[-1].following
    assert logs.take(1.0) == [] and logs.due(1.0) is None  # asked nothing more: silent


def test_a_tail_reaches_into_the_rotated_file(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(tmp_path / "brain.log.1", "old 1", "old 2")
    write(log, "new 1")
    assert read_tail(log, 3) == ["old 1", "old 2", "new 1"]
    assert read_tail(log, 0) == [] and read_tail(tmp_path / "missing.log", 5) == []


def test_a_tail_of_a_missing_log_still_ends(tmp_path: Path) -> None:
    logs = stream(tmp_path / "brain.log")
    logs.ask(ask(), 0.0)
    chunks = logs.take(0.0)
    assert [(c.lines, c.end) for c in chunks] == [([], True)]


def test_env_values_passwords_and_keys_never_leave(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(
        log,
        "token is s3cr3t-token here",
        "ROS_DOMAIN_ID=7 and ROS_DOMAIN_ID: 7",
        "broker mqtts://tb3:hunter22@broker.lab:8883 up",
        "key follows -----BEGIN PRIVATE KEY-----",
        "MIIEvQIBADANBgkqhkiG9w0BAQEFAASCBKcwggSjAgEAAoIBAQ",
        "-----END PRIVATE KEY-----",
        "-----BEGIN EC PRIVATE KEY----- abc -----END EC PRIVATE KEY-----",
        "after the key",
        "the number 7 alone is no secret",
    )
    logs = stream(log, secrets=("s3cr3t-token", "7", "hunter22"), names=("ROS_DOMAIN_ID",))
    logs.ask(ask(), 0.0)
    text = "\n".join(lines_of(logs.take(0.0)))
    for secret in ("s3cr3t-token", "hunter22", "MIIEvQ", "abc", "=7", ": 7"):
        assert secret not in text, secret
    assert f"token is {REDACTED} here" in text
    assert f"ROS_DOMAIN_ID={REDACTED}" in text
    assert f"mqtts://tb3:{REDACTED}@broker.lab" in text
    assert "after the key" in text and "the number 7 alone" in text


def test_a_long_line_is_cut_with_a_marker_and_every_message_fits(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "x" * 200_000, "\x01" * 100_000, "é" * 70_000, "short")
    logs = stream(log)
    logs.ask(ask(lines=10), 0.0)
    chunks = logs.take(0.0)
    got = lines_of(chunks)
    assert len(got) == 4 and got[-1] == "short"
    assert all("[robotconf: line cut" in line for line in got[:3])
    assert got[0].startswith("x" * 1000)
    for chunk in chunks:
        assert len(chunk.model_dump_json().encode()) <= MAX_LOG_MESSAGE_BYTES


def test_fit_line_keeps_what_fits() -> None:
    assert fit_line("hello") == "hello"
    cut = fit_line("\x00" * MAX_LINE_BYTES)
    assert len(json.dumps(cut, ensure_ascii=False).encode()) <= MAX_LINE_BYTES


def test_lines_go_out_at_about_the_rate(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, *[f"l{n}" for n in range(1000)])
    logs = stream(log)
    logs.ask(ask(lines=1000), 0.0)
    sent = len(lines_of(logs.take(0.0)))
    assert sent == BURST
    due = logs.due(0.0)
    assert due is not None and 0 < due <= 1 / RATE + 1e-9
    sent += len(lines_of(logs.take(1.0)))
    assert sent == BURST + RATE
    for t in range(2, 20):
        sent += len(lines_of(logs.take(float(t))))
    assert sent == 1000


def test_following_streams_new_lines_until_the_asks_stop(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "before")
    logs = stream(log)
    logs.ask(ask(lines=1, follow=True), 0.0)
    assert lines_of(logs.take(0.0)) == ["before"]
    write(log, "during 1", "during 2")
    logs.poll(0.5)
    chunks = logs.take(0.5)
    assert lines_of(chunks, None) == ["during 1", "during 2"] and chunks[0].following
    # A partial line waits for its end.
    with log.open("a") as f:
        f.write("half")
    logs.poll(1.0)
    assert logs.take(1.0) == []
    write(log, " done")
    logs.poll(1.5)
    assert lines_of(logs.take(1.5), None) == ["half done"]
    # Asked again: the stream goes on LOG_FOLLOW_TTL after the newest ask, then stops.
    logs.ask(ask("s2", lines=0, follow=True), 20.0)
    write(log, "late")
    logs.poll(20.0 + LOG_FOLLOW_TTL - 1)
    assert lines_of(logs.take(20.0 + LOG_FOLLOW_TTL - 1), None) == ["late"]
    write(log, "unasked")
    logs.poll(20.0 + LOG_FOLLOW_TTL)
    assert not logs.following and logs.due(20.0 + LOG_FOLLOW_TTL) is None
    logs.poll(100.0)
    assert lines_of(logs.take(100.0), None) == []


def test_following_survives_rotation_by_truncation(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "a" * 50, "b" * 50)
    logs = stream(log)
    logs.ask(ask(lines=0, follow=True), 0.0)
    logs.take(0.0)
    log.write_text("")  # copy-then-truncate, as BrainLog rotates
    write(log, "after rotation")
    logs.poll(0.5)
    assert lines_of(logs.take(0.5), None) == ["after rotation"]


def test_a_flood_is_skipped_and_said(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "start")
    logs = stream(log)
    logs.ask(ask(lines=0, follow=True), 0.0)
    logs.take(0.0)
    write(log, *["y" * 99 for _ in range(2 * READ_LIMIT // 100)])
    logs.poll(0.5)
    got = lines_of(logs.take(0.5), None)
    assert got[0].startswith("[robotconf: skipped ") and "bytes" in got[0]
    # More lines than the queue holds: the rest are dropped and counted, never kept.
    for n in range(10):
        write(log, *["z" for _ in range(QUEUE_LIMIT // 4)])
        logs.poll(1.0 + n)
    total_dropped = 0
    for t in range(2, 200):
        chunks = logs.take(float(t))
        total_dropped += sum(c.dropped for c in chunks)
    assert total_dropped > 0


def test_asks_beyond_a_few_a_second_are_ignored(tmp_path: Path) -> None:
    logs = stream(tmp_path / "brain.log")
    served = [logs.ask(ask(f"s{n}", lines=1), 0.0) for n in range(ASKS_PER_SECOND + 3)]
    assert served.count(True) == ASKS_PER_SECOND
    assert logs.ask(ask("later", lines=1), 1.5)


def test_a_lost_connection_drops_what_waits(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, *[f"l{n}" for n in range(500)])
    logs = stream(log)
    logs.ask(ask(lines=500, follow=True), 0.0)
    logs.stop()
    assert logs.take(5.0) == [] and not logs.following


def test_a_bug_while_sending_the_log_stops_the_stream_not_the_agent(tmp_path: Path) -> None:
    from agent.config import parse_config
    from agent.runtime import Agent

    text = (
        "broker: mqtt://127.0.0.1:1\n"
        "description: {id: tb3-01}\n"
        "command: [brain, '{launch_request}']\n"
        f"workdir: {tmp_path / 'work'}\n"
    )
    agent = Agent(parse_config(text, "agent.yaml"))
    write(tmp_path / "work" / "brain.log", "a line")
    agent.logs.ask(ask(lines=1, follow=True), 0.0)
    agent.connected = True

    def broken(now: float) -> list[LogsChunk]:
        raise RuntimeError("injected")

    agent.logs.take = broken  # type: ignore[method-assign]
    agent._send_logs(1.0)  # logged, not raised
    assert not agent.logs.following
