"""The brain's log for the desk: tails, the followed stream, redaction, bounds and pace."""

from __future__ import annotations

import json
from pathlib import Path

from robotconf.agent.logs import (
    ASKS_PER_SECOND,
    BURST,
    MAX_LINE_BYTES,
    MAX_SESSIONS,
    QUANTUM,
    QUEUE_LIMIT,
    RATE,
    READ_LIMIT,
    REDACTED,
    SESSION_ASKS_PER_SECOND,
    LogStream,
    Redactor,
    fit_line,
    read_tail,
)
from robotconf.contract.wire import LOG_FOLLOW_TTL, MAX_LOG_MESSAGE_BYTES, LogsChunk, LogsRequest


def stream(
    path: Path, secrets: tuple[str, ...] = (), names: tuple[str, ...] = (), backups: int = 3
) -> LogStream:
    return LogStream(path, "tb3-01", Redactor(secrets, names), backups=backups)


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
    assert logs.ask(ask(lines=5), 0.0) is None
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


def test_asks_are_budgeted_per_session_and_for_all_desks(tmp_path: Path) -> None:
    logs = stream(tmp_path / "brain.log")
    own = int(SESSION_ASKS_PER_SECOND)
    served = [logs.ask(ask("busy", lines=1), 0.0) for _ in range(own + 3)]
    assert served[:own] == [None] * own
    assert all(r is not None and "session busy asks more than" in r for r in served[own:])
    # Others are served meanwhile, up to the ceiling of everyone together.
    others = [logs.ask(ask(f"s{n}", lines=1), 0.0) for n in range(int(ASKS_PER_SECOND))]
    assert others.count(None) == int(ASKS_PER_SECOND) - own
    refused = [r for r in others if r is not None]
    assert all("from all desks together" in r for r in refused)
    # A refused ask costs nothing: the session refused by the ceiling is served once it is not
    # reached; the busy one again once its own budget has refilled one ask, and only one.
    later = 1.0 / SESSION_ASKS_PER_SECOND
    assert logs.ask(ask("s19", lines=1), later) is None
    assert logs.ask(ask("busy", lines=1), later) is None
    assert logs.ask(ask("busy", lines=1), later) is not None
    assert logs.ask(ask("busy", lines=1), 1.5) is None


def test_session_budgets_are_bounded_and_forgotten_once_full(tmp_path: Path) -> None:
    logs = stream(tmp_path / "brain.log")
    for n in range(MAX_SESSIONS * 3):
        assert logs.ask(ask(f"s{n}", lines=0), n * 0.1) is None
    assert len(logs._budgets) <= MAX_SESSIONS
    assert len(logs._budgets) < 5  # idle ones are full again: nothing to remember


def sent_order(logs: LogStream, until: float, step: float = 0.01) -> list[tuple[str | None, str]]:
    """(session, line or '<end>') in the order they go out, taking every `step` seconds."""
    order: list[tuple[str | None, str]] = []
    t = 0.0
    while t <= until:
        for chunk in logs.take(t):
            order += [(chunk.session, line) for line in chunk.lines]
            if chunk.end:
                order.append((chunk.session, "<end>"))
        t += step
    return order


def test_a_short_tail_goes_out_within_a_turn_of_a_long_backlog(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, *[f"line {n}" for n in range(2000)])
    logs = stream(log)
    for _ in range(4):  # a dashboard asking for more than the robot sends
        assert logs.ask(ask("dash", lines=1000), 0.0) is None
    first = sent_order(logs, 0.0)  # the burst goes to the dashboard: nobody else asked yet
    assert logs.ask(ask("op", lines=5), 0.0) is None
    order = sent_order(logs, 60.0)
    ops = [n for n, (session, _) in enumerate(order) if session == "op"]
    assert [order[n][1] for n in ops] == [f"line {n}" for n in range(1995, 2000)] + ["<end>"]
    # Only the rest of the dashboard's current turn goes out before the operator's lines.
    assert ops[0] <= QUANTUM
    # The dashboard gets every one of its tails, whole or with the oldest lines said dropped.
    assert [line for _, line in first + order].count("<end>") == 4 + 1


def test_over_the_bound_the_longest_waiting_answer_loses_its_oldest_lines(
    tmp_path: Path,
) -> None:
    log = tmp_path / "brain.log"
    write(log, *[f"line {n}" for n in range(1000)])
    logs = stream(log)
    for n in range(4):  # new sessions each time: 4,000 lines asked, more than the queue holds
        assert logs.ask(ask(f"big{n}", lines=1000), 0.0) is None
    assert logs.ask(ask("small", lines=3), 0.0) is None
    chunks: list[LogsChunk] = []
    for t in range(60):
        chunks += logs.take(float(t))
    small = [c for c in chunks if c.session == "small"]
    assert lines_of(small, "small") == ["line 997", "line 998", "line 999"]
    assert sum(c.dropped for c in small) == 0 and small[-1].end
    for n in range(4):
        mine = [c for c in chunks if c.session == f"big{n}"]
        got, dropped = lines_of(mine, f"big{n}"), sum(c.dropped for c in mine)
        assert mine[-1].end and len(got) + dropped == 1000
        assert got == [f"line {k}" for k in range(dropped, 1000)]  # the newest kept, in order
    assert sum(c.dropped for c in chunks) == 4 * 1000 + 3 - QUEUE_LIMIT


def test_the_followed_stream_takes_its_turn_beside_tails(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, *[f"old {n}" for n in range(1000)])
    logs = stream(log)
    assert logs.ask(ask("f", lines=0, follow=True), 0.0) is None
    assert logs.ask(ask("t", lines=1000), 0.0) is None
    logs.take(0.0)
    write(log, "new 1", "new 2")
    logs.poll(0.5)
    order = sent_order(logs, 1.0)
    streamed = [n for n, (session, _) in enumerate(order) if session is None]
    assert [order[n][1] for n in streamed] == ["new 1", "new 2"]
    assert streamed[0] <= QUANTUM


def test_a_lost_connection_drops_what_waits(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, *[f"l{n}" for n in range(500)])
    logs = stream(log)
    logs.ask(ask(lines=500, follow=True), 0.0)
    logs.stop()
    assert logs.take(5.0) == [] and not logs.following


def test_a_bug_while_sending_the_log_stops_the_stream_not_the_agent(tmp_path: Path) -> None:
    from robotconf.agent.config import parse_config
    from robotconf.agent.runtime import Agent

    text = (
        "broker: mqtt://127.0.0.1:1\n"
        "description: {id: tb3-01}\n"
        "command: [brain, '{launch_request}']\n"
        f"workdir: {tmp_path / 'work'}\n"
    )
    agent = Agent(parse_config(text, "agent.yaml"))
    write(tmp_path / "work" / "brain.log", "a line")
    agent.logs.ask(ask(lines=1, follow=True), 0.0)
    agent.status.connected = True

    def broken(now: float) -> list[LogsChunk]:
        raise RuntimeError("injected")

    agent.logs.take = broken  # type: ignore[method-assign]
    agent.desk.send_logs(1.0)  # logged, not raised
    assert not agent.logs.following


# ---------------------------------------------------------------- keys, whatever the window

BODY = [
    f"MIIE{n:02d}" + "QIBADANBgkqhkiG9w0BAQEFAASCBKcwggSjAgEAAoIBAQDm" + "x" * 10 for n in range(25)
]
KEY = ["-----BEGIN RSA PRIVATE KEY-----", *BODY, "-----END RSA PRIVATE KEY-----"]


def leaked(text: str) -> list[str]:
    return [b for b in BODY if b[:12] in text]


def tail_text(log: Path, lines: int, secrets: tuple[str, ...] = (), backups: int = 3) -> str:
    logs = stream(log, secrets=secrets, backups=backups)
    assert logs.ask(ask(lines=lines), 0.0) is None
    return "\n".join(lines_of(logs.take(0.0)))


def test_a_tail_that_begins_inside_a_key_shows_none_of_it(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "before", *KEY, "after 1", "after 2")
    for count in range(1, len(KEY) + 4):
        text = tail_text(log, count)
        assert not leaked(text), count
        assert text.endswith("after 1\nafter 2" if count > 1 else "after 2")


def test_a_key_split_by_a_rotation_stays_hidden_on_both_sides(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(tmp_path / "brain.log.1", "old line", *KEY[:10])
    write(log, *KEY[10:], "after")
    for count in range(1, len(KEY) + 4):
        text = tail_text(log, count)
        assert not leaked(text), count
        assert text.endswith("after") and ("old line" in text) == (count >= len(KEY) + 2)


def test_a_key_whose_beginning_a_rotation_lost_stays_hidden(tmp_path: Path) -> None:
    # Written between the copy and the truncation: in neither file. What follows looks like
    # a key's body and ends like one: the desk sees neither.
    log = tmp_path / "brain.log"
    write(tmp_path / "brain.log.1", "old 1", "old 2")
    write(log, *KEY[12:], "after", "ZZZZ")
    for count in range(1, len(KEY) + 3):
        text = tail_text(log, count)
        assert not leaked(text), count
        # After a line that is not base64, lines are shown.
        assert text.endswith("after\nZZZZ" if count > 1 else "ZZZZ")
    assert tail_text(log, 100).startswith("old 1\nold 2\n")
    # Lost in the middle of the BEGIN line: what is left of it says as much.
    write(tmp_path / "cut.log", "RSA PRIVATE KEY-----", *KEY[1:], "after")
    assert not leaked(tail_text(tmp_path / "cut.log", 100, backups=0))
    assert tail_text(tmp_path / "cut.log", 100, backups=0).endswith("after")


def test_the_start_of_a_log_that_is_only_truncated_is_treated_as_unknown(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, *KEY[5:], "after")
    assert not leaked(tail_text(log, 100, backups=0))
    # With copies kept and none there, the file's start is the log's own start.
    write(tmp_path / "young.log", "Starting", "after")
    assert tail_text(tmp_path / "young.log", 5) == "Starting\nafter"
    # The oldest copy kept begins where a deleted one ended: unknown too; a younger one not.
    (tmp_path / "old").mkdir()
    write(tmp_path / "old" / "brain.log.1", *KEY[5:], "after")
    write(tmp_path / "old" / "brain.log", "now")
    assert not leaked(tail_text(tmp_path / "old" / "brain.log", 100, backups=1))
    assert leaked(tail_text(tmp_path / "old" / "brain.log", 100, backups=2))


def test_following_from_inside_a_key_shows_none_of_it(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "before", *KEY[:5])  # the brain is printing a key, slowly
    logs = stream(log)
    assert logs.ask(ask(lines=0, follow=True), 0.0) is None
    logs.take(0.0)
    write(log, *KEY[5:], "after")
    logs.poll(0.5)
    text = "\n".join(lines_of(sent(logs, 0.5, 5.0), None))
    assert not leaked(text) and text.endswith("after")


def sent(logs: LogStream, start: float, until: float) -> list[LogsChunk]:
    chunks: list[LogsChunk] = []
    t = start
    while t <= until:
        chunks += logs.take(t)
        t += 0.1
    return chunks


def test_a_skip_inside_a_key_keeps_it_hidden(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "start")
    logs = stream(log)
    logs.ask(ask(lines=0, follow=True), 0.0)
    logs.take(0.0)
    body = [BODY[n % len(BODY)] for n in range(40 * 1024 // 64)]
    write(log, "-----BEGIN PRIVATE KEY-----", *body, "-----END PRIVATE KEY-----")
    # More than a look reads: the look starts in the middle of the key's body.
    flood = (READ_LIMIT - len(body) * 65 // 2) // 1000
    write(log, *["y" * 999 for _ in range(flood)], "end of flood")
    logs.poll(0.5)
    text = "\n".join(lines_of(sent(logs, 0.5, 60.0), None))
    assert text.startswith("[robotconf: skipped ") and text.endswith("end of flood")
    assert not leaked(text)


def test_a_streamed_line_cut_for_length_shows_nothing_of_its_rest(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "start")
    logs = stream(log, secrets=("s3cr3t-token",))
    logs.ask(ask(lines=0, follow=True), 0.0)
    logs.take(0.0)
    with log.open("a") as f:
        f.write("x" * (MAX_LINE_BYTES + 100) + " s3cr")
    logs.poll(0.5)
    with log.open("a") as f:
        f.write("3t-token, then the rest of that long line\nnext line\n")
    logs.poll(1.0)
    got = lines_of(sent(logs, 0.5, 5.0), None)
    assert len(got) == 2 and "[robotconf: line cut" in got[0] and got[1] == "next line"
    assert "3t-token" not in "\n".join(got)


def test_the_stream_starts_where_the_tail_ends(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "one", "two")
    logs = stream(log)
    logs.ask(ask(lines=5, follow=True), 0.0)
    write(log, "three")
    logs.poll(0.5)
    chunks = sent(logs, 0.5, 2.0)
    assert lines_of(chunks) == ["one", "two"] and lines_of(chunks, None) == ["three"]


def test_colours_cannot_split_a_secret_and_never_leave(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "token \x1b[1;31ms3cr\x1b[0m3t-\x1b]8;;http://x\x07token\x1b[m ok")
    text = tail_text(log, 1, secrets=("s3cr3t-token",))
    assert text == f"token {REDACTED} ok"


def rotate(log: Path) -> None:
    """As BrainLog rotates: copy, then truncate (the brain's descriptor stays open)."""
    (log.parent / (log.name + ".1")).write_bytes(log.read_bytes())
    with log.open("r+b") as f:
        f.truncate(0)


def test_a_line_a_rotation_cut_in_two_is_whole_again_in_a_tail(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    with log.open("a") as f:
        f.write("a line before\ntoken s3cr")
    rotate(log)
    with log.open("a") as f:
        f.write("3t-token end\n")
    logs_of = {n: tail_text(log, n, secrets=("s3cr3t-token",)) for n in (1, 2, 5)}
    assert logs_of[1] == f"token {REDACTED} end"
    assert logs_of[2] == logs_of[5] == f"a line before\ntoken {REDACTED} end"
    write(log, "next")
    assert tail_text(log, 1) == "next"
    assert tail_text(log, 3, secrets=("s3cr3t-token",)).endswith(f"token {REDACTED} end\nnext")
    assert read_tail(log, 2) == ["token s3cr3t-token end", "next"]


def test_a_line_a_rotation_cut_where_bytes_were_lost_hides_what_may_be_a_key(
    tmp_path: Path,
) -> None:
    # The copy ends in the middle of a line; a BEGIN line and the start of a body line were
    # written between the copy and the truncation: the rest of that body line is all there is.
    log = tmp_path / "brain.log"
    with log.open("a") as f:
        f.write("a line before\n0 0 ")
    rotate(log)
    write(log, BODY[0][10:], *BODY[1:], KEY[-1], "after")
    for count in range(1, len(BODY) + 4):
        text = tail_text(log, count)
        assert not leaked(text) and BODY[0][10:] not in text, count
        assert text.endswith("after")
    logs = stream(log)
    logs.ask(ask(lines=0, follow=True), 0.0)
    with log.open("a") as f:
        f.write("0 0 ")
    logs.poll(0.5)
    rotate(log)
    logs.rotated()
    write(log, BODY[0][10:], *BODY[1:], KEY[-1], "after")
    logs.poll(1.0)
    streamed = lines_of(sent(logs, 0.0, 3.0), None)
    assert streamed[-1] == "after" and not leaked("\n".join(streamed))
    assert BODY[0][10:] not in "\n".join(streamed)


def test_following_across_a_rotation_misses_nothing_and_joins_a_cut_line(tmp_path: Path) -> None:
    log = tmp_path / "brain.log"
    write(log, "start")
    logs = stream(log, secrets=("s3cr3t-token",))
    logs.ask(ask(lines=0, follow=True), 0.0)
    write(log, "a")
    logs.poll(0.5)
    with log.open("a") as f:
        f.write("b\nhalf s3c")
    rotate(log)  # before the stream looked again
    logs.rotated()  # as the agent says once it has rotated the log
    with log.open("a") as f:
        f.write("r3t-token\nc\n")  # more than the stream had read: its size says nothing
    logs.poll(1.0)
    assert lines_of(sent(logs, 0.0, 3.0), None) == ["a", "b", f"half {REDACTED}", "c"]
