"""Properties: text from robots is data. A log record is one line whatever its message holds, a
traceback keeps only its own lines, a chat message pings nobody, and a receiver URL's
password shows nowhere (issue 20, items 3 and 4)."""

from __future__ import annotations

import base64
import logging
import re
import sys
from urllib.parse import quote, unquote

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from robotconf.contract.logsafe import SafeFormatter, format_exception
from robotconf.contract.textsafe import chat_text, printable
from robotconf.reconciler.notify import parse_receiver

FORMAT = "%(levelname)s %(message)s"
FORGED = "\nERROR forged line\r\x1b[2J<!channel>"
# Every character some terminal, log viewer or str.splitlines takes for a line break.
BREAKS = "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
# Text robots send: anything, with what forges lines and drives terminals well represented.
HOSTILE = st.text(
    alphabet=st.one_of(
        st.characters(),
        st.sampled_from([*BREAKS, "\x1b", "\x9b", "\u202e", "\u2066", "<", ">", "&", "@", "|"]),
    ),
    max_size=60,
)


def record(message: str, *args: object, exc: BaseException | None = None) -> logging.LogRecord:
    info = (type(exc), exc, exc.__traceback__) if exc is not None else None
    return logging.LogRecord("robotconf.test", logging.INFO, __file__, 1, message, args, info)


def raised(message: str) -> ValueError:
    try:
        try:
            raise KeyError(message)
        except KeyError as inner:
            raise ValueError(message) from inner
    except ValueError as exc:
        return exc


def is_one_safe_line(text: str) -> bool:
    return len(text.splitlines()) <= 1 and printable(text) == text


@given(HOSTILE)
def test_a_record_is_one_printable_line_whatever_its_message(said: str) -> None:
    formatted = SafeFormatter(FORMAT).format(record("robot says %s", said))
    assert is_one_safe_line(formatted)
    assert formatted == "INFO robot says " + printable(said)


@given(HOSTILE)
def test_a_traceback_has_the_same_lines_whatever_the_exception_says(said: str) -> None:
    formatter = SafeFormatter(FORMAT)
    shape = formatter.format(record("failed", exc=raised("x"))).split("\n")
    lines = formatter.format(record("failed", exc=raised(said))).split("\n")
    assert len(lines) == len(shape)
    assert all(is_one_safe_line(line) for line in lines)
    assert lines[-1] == (printable(f"ValueError: {said}") if said else "ValueError")
    # The frames and the chain's headers are Python's own.
    assert lines[1] == "Traceback (most recent call last):"
    assert "The above exception was the direct cause of the following exception:" in lines


def test_a_forged_line_stays_inside_its_record() -> None:
    formatted = SafeFormatter(FORMAT).format(
        record("tb3-01 is failed: %s", FORGED, exc=raised(FORGED))
    )
    assert not any(line.startswith("ERROR forged") for line in formatted.splitlines())
    assert "\x1b" not in formatted and "\r" not in formatted
    assert (
        formatted.splitlines()[0]
        == "INFO tb3-01 is failed: \\nERROR forged line\\r\\x1b[2J<!channel>"
    )


def test_another_handler_reuses_the_escaped_traceback() -> None:
    """The escaped text is cached on the record: a plain formatter after it shows that."""
    escaped = record("failed", exc=raised(FORGED))
    SafeFormatter(FORMAT).format(escaped)
    plain = logging.Formatter(FORMAT).format(escaped)
    assert not any(line.startswith("ERROR forged") for line in plain.splitlines())


@pytest.mark.skipif(sys.version_info < (3, 11), reason="exception groups and notes: 3.11+")
def test_exception_groups_and_notes_are_escaped_too() -> None:
    inner = raised(FORGED)
    inner.add_note(FORGED)
    group = ExceptionGroup(FORGED, [inner])  # noqa: F821
    text = format_exception(group)
    assert not any(line.startswith("ERROR forged") for line in text.splitlines())
    assert "[exception 1 of 1 in the group]" in text and "\x1b" not in text


def test_a_broken_str_does_not_lose_the_line() -> None:
    class Broken(Exception):
        def __str__(self) -> str:
            raise RuntimeError("no")

    assert format_exception(Broken()).endswith("Broken: <exception str() failed>")


MENTION = re.compile(r"(?<!\w)@\w")


@given(HOSTILE)
def test_chat_text_pings_nobody_and_loses_nothing(said: str) -> None:
    assume("\u2060" not in said)
    shown = chat_text(said)
    assert is_one_safe_line(shown)
    assert "<" not in shown and ">" not in shown
    assert re.search(r"&(?!amp;|lt;|gt;)", shown) is None
    assert MENTION.search(shown) is None
    back = shown.replace("@\u2060", "@").replace("&lt;", "<").replace("&gt;", ">")
    assert back.replace("&amp;", "&") == printable(said)


def test_chat_text_of_slack_commands() -> None:
    assert chat_text("<!channel> <@U123> <http://x|y> a&b @here mail@lab") == (
        "&lt;!channel&gt; &lt;@\u2060U123&gt; &lt;http://x|y&gt; a&amp;b @\u2060here mail@lab"
    )


NAME = "#1 https://alerts.example:8443"
REFUSALS = {
    "--notify #1 must be ASCII without spaces or control characters (percent-encode them; an "
    "international host name in its xn-- form)",
    "--notify #1 is not a valid URL: scheme://[user:password@]host[:port]/path, with any "
    "@ : / ? # in the user name or password percent-encoded",
    "--notify #1 has an @ after its host: percent-encode any / ? # in its password "
    "(%2F %3F %23) and any @ in its path (%40)",
    "--notify #1 has no host",
}


@given(st.text(min_size=1, max_size=40))
def test_a_percent_encoded_password_is_sent_never_shown(password: str) -> None:
    receiver = parse_receiver(f"https://robot:{quote(password, safe='')}@alerts.example:8443/T/B")
    assert repr(receiver) == f"Receiver(slack=False, name='{NAME}')"
    assert receiver.url == "https://alerts.example:8443/T/B"
    assert receiver.authorization is not None
    sent = base64.b64decode(receiver.authorization.removeprefix("Basic ")).decode()
    assert sent == f"robot:{password}"


@given(st.text(min_size=1, max_size=40))
def test_a_password_as_typed_is_sent_or_refused_in_words_of_our_own(password: str) -> None:
    """Typed raw, a password may break the URL anywhere: where its host or port should be,
    or into its path. The URL is then refused in fixed words, or it names the host only."""
    try:
        receiver = parse_receiver(f"https://robot:{password}@alerts.example:8443/T/B")
    except ValueError as exc:
        assert str(exc) in REFUSALS
        return
    assert receiver.name == NAME
    assert receiver.authorization is not None
    sent = base64.b64decode(receiver.authorization.removeprefix("Basic ")).decode()
    assert sent == f"robot:{unquote(password)}"
