"""The log tail's events, pure: whatever a brain prints, one line stays one `data:` field."""

from __future__ import annotations

from robotconf.contract.wire import LogsChunk
from robotconf.workstation.ui.logtail import MAX_LINE, chunk_event, event, note


def fields(sse: bytes) -> list[str]:
    text = sse.decode()
    assert text.endswith("\n\n")
    return text[:-2].split("\n")


def test_each_line_is_one_data_field_and_nothing_can_end_the_event() -> None:
    chunk = LogsChunk(
        robot_id="tb3-01",
        lines=[
            "plain",
            "\x1b[31mred\x1b[0m",
            "cr\rdata: forged",
            "lf\n\nevent: x",
            "nul\x00 and \u2028 sep",
        ],
    )
    assert fields(chunk_event(chunk)) == [
        "data: plain",
        "data: red",
        "data: cr\\rdata: forged",
        "data: lf\\n\\nevent: x",
        "data: nul\\x00 and \\u2028 sep",
    ]


def test_a_long_line_is_cut_and_left_out_lines_are_said() -> None:
    chunk = LogsChunk(robot_id="tb3-01", lines=["x" * (MAX_LINE + 50)], dropped=7)
    text = chunk_event(chunk).decode()
    assert text.startswith("data: [robotconf ui] 7 line(s) left out")
    assert ("x" * MAX_LINE + " [cut]\n") in text and "x" * (MAX_LINE + 1) not in text


def test_an_empty_chunk_sends_nothing() -> None:
    assert chunk_event(LogsChunk(robot_id="tb3-01")) == b""
    assert event([]) == b"data:\n\n"
    assert fields(note("gone")) == ["data: [robotconf ui] gone"]
