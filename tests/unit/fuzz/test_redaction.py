"""Property: no secret leaves the robot in a log answer, whatever the secret, its encoding, where
it sits in the log, and which window is asked for (a tail, a followed stream, across rotations)."""

from __future__ import annotations

import base64
import json
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote, quote_plus

from hypothesis import given, settings
from hypothesis import strategies as st

from robotconf.agent.logs import LogStream
from robotconf.agent.redact import MIN_SECRET_CHARS, REDACTED, Redactor, encodings, secret_forms
from robotconf.contract.wire import LogsChunk, LogsRequest

# What a secret may hold: any printable character (a log line cannot carry a control
# character as it was written), with the ones that encodings change made likely.
_SPECIAL = list(" %+/=\\\"'&?#:;@~!*()[]{}<>-_.,é€ß\u2028😀")
_secret_char = st.one_of(
    st.characters(blacklist_categories=("Cc", "Cs")), st.sampled_from(_SPECIAL)
)
one_line_secrets = st.text(_secret_char, min_size=MIN_SECRET_CHARS, max_size=30).filter(
    lambda s: len(s.strip()) >= MIN_SECRET_CHARS
)
_B64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/"
_body_lines = st.lists(st.text(_B64, min_size=16, max_size=64), min_size=1, max_size=8)
_KINDS = ["PRIVATE KEY", "RSA PRIVATE KEY", "EC PRIVATE KEY", "OPENSSH PRIVATE KEY"]
pem_secrets = st.builds(
    lambda kind, body: "\n".join([f"-----BEGIN {kind}-----", *body, f"-----END {kind}-----"]),
    st.sampled_from(_KINDS),
    _body_lines,
)
multi_line_secrets = st.lists(one_line_secrets, min_size=2, max_size=4).map("\n".join)
secrets = st.one_of(one_line_secrets, pem_secrets, multi_line_secrets)

# Log text around them: words and spaces, nothing any rule redacts by itself.
_word = st.text("abcdefghijklmnopqrstuvwxyz0123456789.,;!()_", min_size=1, max_size=8)
filler = st.lists(_word, min_size=2, max_size=6).map(" ".join)
# Each example writes and reads log files: half the profile's examples (`deep` explores more).
FILE_EXAMPLES = max(50, settings().max_examples // 2)
_SGR = ["\x1b[31m", "\x1b[0m", "\x1b[1;32m", "\x1b[m", "\x1b[38;5;208m"]


def forms_to_check(secret: str) -> set[str]:
    """What must never appear, worked out here independently of the redactor: the value and
    its URL, JSON and base64 forms (one line each), and each line of a multi-line value."""
    raw = secret.encode("utf-8")
    forms = {
        quote(secret, safe=""),
        quote(secret),
        quote_plus(secret),
        json.dumps(secret)[1:-1],
        json.dumps(secret, ensure_ascii=False)[1:-1],
    }
    for encoded in (base64.b64encode(raw), base64.urlsafe_b64encode(raw)):
        forms |= {encoded.decode(), encoded.decode().rstrip("=")}
    if "\n" in secret:
        forms |= {p.strip() for p in secret.split("\n") if len(p.strip()) >= MIN_SECRET_CHARS}
    else:
        forms.add(secret)
    return {f for f in forms if "\n" not in f}


@st.composite
def embedded(draw: st.DrawFn, secret: str) -> list[str]:
    """The log lines that carry `secret` in one of its forms, with text around it."""
    how = draw(st.sampled_from(["raw", "coloured", "url", "url+", "json", "b64", "b64url"]))
    raw = secret.encode("utf-8")
    if how == "coloured":
        cuts = sorted(draw(st.lists(st.integers(0, len(secret)), min_size=1, max_size=4)))
        pieces, start = [], 0
        for cut in cuts:
            pieces += [secret[start:cut], draw(st.sampled_from(_SGR))]
            start = cut
        text = "".join(pieces) + secret[start:]
    else:
        text = {
            "raw": secret,
            "url": quote(secret, safe=""),
            "url+": quote_plus(secret),
            "json": json.dumps(secret, ensure_ascii=draw(st.booleans()))[1:-1],
            "b64": base64.b64encode(raw).decode(),
            "b64url": base64.urlsafe_b64encode(raw).decode().rstrip("="),
        }[how]
    before, after = draw(filler), draw(filler)
    return (before + draw(st.sampled_from([" ", "=", ":", "'", ""])) + text + " " + after).split(
        "\n"
    )


@dataclass
class Log:
    lines: list[str]
    secrets: list[str]
    keys: list[str] = field(default_factory=list)  # body lines of PEM blocks
    plain: set[int] = field(default_factory=set)  # indexes of filler lines outside any block

    def hidden(self) -> set[str]:
        return {f for s in self.secrets for f in forms_to_check(s)} | set(self.keys)


@st.composite
def logs(draw: st.DrawFn) -> Log:
    found = Log([], draw(st.lists(secrets, min_size=1, max_size=3)))
    for _ in range(draw(st.integers(1, 25))):
        what = draw(st.sampled_from(["filler", "filler", "secret", "key"]))
        if what == "filler":
            found.plain.add(len(found.lines))
            found.lines.append(draw(filler))
        elif what == "secret":
            found.lines += draw(embedded(draw(st.sampled_from(found.secrets))))
        else:
            kind, body = draw(st.sampled_from(_KINDS)), draw(_body_lines)
            begin, end = f"-----BEGIN {kind}-----", f"-----END {kind}-----"
            if draw(st.booleans()):  # a colour inside the marker hides nothing
                begin = begin[:8] + draw(st.sampled_from(_SGR)) + begin[8:]
            found.lines += [draw(filler) + " " + begin, *body, end + " " + draw(filler)]
            found.keys += body
    return found


def redactor_for(log: Log) -> Redactor:
    return Redactor(log.secrets, ["API_TOKEN"])


def assert_nothing_leaks(lines: list[str], log: Log) -> None:
    hidden = log.hidden()
    for line in lines:
        for segment in line.split(REDACTED):
            for secret in hidden:
                assert secret not in segment, (secret, line)


def shown_plainly(log: Log) -> set[str]:
    """Filler lines no rule touches: they must reach the desk as written."""
    forms = secret_forms(log.secrets)
    return {
        log.lines[n] for n in log.plain if not any(f in log.lines[n] for f in forms | log.hidden())
    }


def write(path: Path, lines: list[str]) -> None:
    with path.open("a", encoding="utf-8") as out:
        out.write("".join(line + "\n" for line in lines))


def tail(folder: Path, log: Log, count: int) -> list[str]:
    stream = LogStream(folder / "brain.log", "tb3-01", redactor_for(log))
    assert stream.ask(LogsRequest(session="s", lines=count), 0.0) is None
    got: list[str] = []
    for t in range(40):
        got += [line for chunk in stream.take(float(t)) for line in chunk.lines]
    return got


@settings(max_examples=FILE_EXAMPLES)
@given(
    log=logs(),
    counts=st.lists(st.integers(1, 80), min_size=1, max_size=4),
    rotation=st.one_of(st.none(), st.tuples(st.floats(0, 1), st.integers(0, 40))),
)
def test_no_tail_shows_a_secret_or_a_key(
    log: Log, counts: list[int], rotation: tuple[float, int] | None
) -> None:
    """Any window of the log, rotated (copy, then truncate) at any byte or not, with bytes lost
    between the copy and the truncation or not."""
    folder = Path(tempfile.mkdtemp(prefix="robotconf-fuzz-redact-"))
    try:
        written = "".join(line + "\n" for line in log.lines).encode("utf-8")
        plain = shown_plainly(log)
        if rotation is None:
            (folder / "brain.log").write_bytes(written)
            lost = 0
        else:
            at, lost = int(rotation[0] * len(written)), rotation[1]
            (folder / "brain.log.1").write_bytes(written[:at])
            (folder / "brain.log").write_bytes(written[at + lost :])
            # A line the rotation cut may be hidden whole: what follows the cut may have lost
            # a key's beginning (the redactor cannot tell that nothing was lost).
            cut = written[:at].count(b"\n")
            if at and written[at - 1 : at] != b"\n":
                plain.discard(log.lines[cut])
        for count in counts:
            got = tail(folder, log, count)
            assert_nothing_leaks(got, log)
            if lost == 0:
                # Nothing lost: the window's lines, a line cut by the rotation whole again,
                # and every plain one as it was written.
                assert len(got) == min(count, len(log.lines))
                for line, shown in zip(log.lines[-count:], got, strict=True):
                    if line in plain:
                        assert shown == line
    finally:
        shutil.rmtree(folder)


@settings(max_examples=FILE_EXAMPLES)
@given(
    log=logs(),
    start=st.floats(0, 1),
    tail_lines=st.integers(0, 5),
    cuts=st.lists(st.integers(1, 200), max_size=12),
    rotate_after=st.one_of(st.none(), st.integers(0, 12)),
    told=st.booleans(),
)
def test_no_followed_chunk_shows_a_secret_or_a_key(
    log: Log,
    start: float,
    tail_lines: int,
    cuts: list[int],
    rotate_after: int | None,
    told: bool,
) -> None:
    """Following from any line, the brain's writes cut at any byte (mid-line, mid-character),
    the log rotated (copy, then truncate) between any two of them or not, the stream told so
    (as the agent that rotates tells it) or left to notice."""
    folder = Path(tempfile.mkdtemp(prefix="robotconf-fuzz-redact-"))
    path = folder / "brain.log"
    try:
        first = int(start * len(log.lines))
        write(path, log.lines[:first])
        path.touch()
        stream = LogStream(path, "tb3-01", redactor_for(log))
        now = 0.0
        assert stream.ask(LogsRequest(session="s", lines=tail_lines, follow=True), now) is None
        rest = "".join(line + "\n" for line in log.lines[first:]).encode("utf-8")
        chunks: list[LogsChunk] = []
        offset = 0
        plain = shown_plainly(log)
        for n, cut in enumerate([*cuts, len(rest)]):
            piece, offset = rest[offset : offset + cut], offset + cut
            with path.open("ab") as out:
                out.write(piece)
            if n == rotate_after:
                if offset < len(rest) and rest[offset - 1 : offset] != b"\n":
                    # A line the rotation cut may be hidden whole (see the tail's test).
                    plain.discard(log.lines[first + rest[:offset].count(b"\n")])
                shutil.copyfile(path, folder / "brain.log.1")
                with path.open("r+b") as log_file:
                    log_file.truncate(0)
                if told:
                    stream.rotated()
            now += 0.3
            stream.poll(now)
            chunks += stream.take(now)
            if offset >= len(rest):
                break
        for _ in range(30):
            now += 1.0
            chunks += stream.take(now)
        streamed = [line for chunk in chunks if chunk.session is None for line in chunk.lines]
        tailed = [line for chunk in chunks if chunk.session == "s" for line in chunk.lines]
        assert_nothing_leaks(streamed + tailed, log)
        if rotate_after is None or told:
            # Nothing lost: every plain line written after the ask is streamed, in order.
            expected = [line for line in log.lines[first:] if line in plain]
            assert [line for line in streamed if line in plain] == expected
    finally:
        shutil.rmtree(folder)


@given(one_line_secrets)
def test_every_common_encoding_of_a_value_is_redacted(secret: str) -> None:
    assert forms_to_check(secret) <= encodings(secret)
    redactor = Redactor([secret], [])
    for form in forms_to_check(secret):
        shown = redactor.line(f"a {form} b")
        assert REDACTED in shown and all(form not in s for s in shown.split(REDACTED)), form
