"""What must never leave the robot in a log line: secrets in their common encodings, `NAME=value`,
passwords in URLs and private-key PEM blocks (a block spans lines: the redactor keeps state).
"""

from __future__ import annotations

import base64
import copy
import json
import re
from collections.abc import Iterable
from enum import Enum
from typing import Any
from urllib.parse import quote, quote_plus

MIN_SECRET_CHARS = 3  # shorter values (ROS_DOMAIN_ID: 7) are redacted only as NAME=value
REDACTED = "[redacted]"
# Base64 of a value inside a longer base64 text (an HTTP Basic header: base64 of user:password)
# is redacted from this many characters on: shorter runs occur by chance in any base64 text.
BASE64_INNER_MIN = 8

# Terminal escape sequences: CSI (colours, cursor moves; ESC [ or the 8-bit CSI), OSC (titles,
# links; ended by BEL or ST, or by the line's end) and the other two-character ESC sequences.
# Stripped before anything else: a colour code inside a secret must not hide it.
_ESCAPES = re.compile(
    r"(?:\x1b\[|\x9b)[0-?]*[ -/]*[@-~]"
    r"|(?:\x1b\]|\x9d)[^\x07\x1b\x9c]*(?:\x07|\x1b\\|\x9c)?"
    r"|\x1b[@-Z\\-_]"
)
_PEM = re.compile(r"-----(BEGIN|END) [A-Z0-9 ]*PRIVATE KEY[A-Z0-9 ]*-----")
# A line of a PEM body: base64 only (the last line may be short, and padded).
_PEM_BODY = re.compile(r"[A-Za-z0-9+/=]+")
# What a BEGIN line may have left when a rotation lost its beginning (`ATE KEY-----`, or
# `[31mIN PRIVATE KEY-----` when the loss cut a colour code before it): ending in a dash.
_PEM_REMAINDER = re.compile(r".*-")
_URL_PASSWORD = re.compile(r"(?i)\b([a-z][a-z0-9+.-]*://[^\s/:@]*):[^\s/@]+@")
_PERCENT = re.compile(r"%[0-9A-F]{2}")


class Pem(Enum):
    """Where a line stands with respect to private-key PEM blocks."""

    OUTSIDE = "outside"
    INSIDE = "inside"  # after a BEGIN line and before its END: every line is key material
    # Cannot tell (a log file that begins where a rotation may have lost lines): lines that
    # look like a PEM body (or the end of a BEGIN line) are redacted until one does not.
    UNKNOWN = "unknown"


def strip_escapes(text: str) -> str:
    """`text` without terminal escape sequences (colours included)."""
    return _ESCAPES.sub("", text) if "\x1b" in text or "\x9b" in text or "\x9d" in text else text


def pem_state_after(text: str) -> Pem | None:
    """INSIDE or OUTSIDE after the last PEM marker of `text`; None when it has none."""
    markers = _PEM.findall(strip_escapes(text))
    if not markers:
        return None
    return Pem.INSIDE if markers[-1] == "BEGIN" else Pem.OUTSIDE


def key_fragment(text: str) -> bool:
    """Whether a line, without any PEM marker, may be part of a key: base64 alone, or what a
    BEGIN line leaves when its start is lost."""
    body = text.strip()
    if not body or _PEM.search(text):
        return False
    return bool(_PEM_BODY.fullmatch(body) or _PEM_REMAINDER.fullmatch(body))


def encodings(value: str) -> set[str]:
    """The forms a program may print `value` in: as is, URL-encoded (Python's and JavaScript's
    safe sets, either case of hex), JSON- or Python-escaped, base64 (standard or URL-safe, with
    or without padding, and inside longer base64), hex. One line each: a form with a line break
    cannot appear in one log line."""
    raw = value.encode("utf-8", "surrogatepass")
    forms = {value}
    for safe in ("", "/", "!'()*", "-_.!~*'()"):
        for quoted in (quote(raw, safe=safe), quote_plus(raw, safe=safe)):
            forms.add(quoted)
            forms.add(_PERCENT.sub(lambda m: m.group(0).lower(), quoted))
    escaped = json.dumps(value)[1:-1]
    forms.update(
        {
            escaped,
            escaped.replace("/", "\\/"),
            json.dumps(value, ensure_ascii=False)[1:-1],
            repr(value)[1:-1],
            ascii(value)[1:-1],
        }
    )
    for encode in (base64.b64encode, base64.urlsafe_b64encode):
        whole = encode(raw).decode("ascii")
        forms.update({whole, whole.rstrip("=")})
        # Inside longer base64, `value` starts at one of three alignments; the characters
        # that depend on its bytes alone are the same whatever surrounds it.
        for shift in (0, 1, 2):
            inner = encode(bytes(shift) + raw).decode("ascii")
            core = inner[-(-8 * shift // 6) : 8 * (shift + len(raw)) // 6]
            if shift == 0 or len(core) >= BASE64_INNER_MIN:
                forms.add(core)
    forms.update({raw.hex(), raw.hex().upper()})
    return {f for f in forms if "\n" not in f and len(f) >= MIN_SECRET_CHARS}


def secret_forms(secrets: Iterable[str]) -> set[str]:
    """Every literal to redact for these secrets: each one's encodings, and each line of a
    multi-line one (a PEM key in `env:`) as it appears in a line of the log."""
    forms: set[str] = set()
    for secret in secrets:
        if len(secret) < MIN_SECRET_CHARS:
            continue
        forms |= encodings(secret)
        if "\n" in secret:
            for piece in secret.split("\n"):
                if len(piece.strip()) >= MIN_SECRET_CHARS:  # not a blank or a short line
                    forms |= {piece.rstrip("\r"), piece.strip()}
    return {f for f in forms if len(f) >= MIN_SECRET_CHARS}


class Redactor:
    """Takes secrets out of log lines: the values of agent.yaml's `env:` and the broker
    password (each at least MIN_SECRET_CHARS long) in the forms of `encodings`, `NAME=value`
    for every `env:` name whatever its value, passwords in URLs, and private-key PEM blocks.
    Terminal escape sequences go first, so that none can split a secret.

    Stateful: a PEM block spans lines, so one Redactor reads one stream in order, starting in
    the `state` its reader found by looking back before the first line (`fresh`)."""

    def __init__(
        self, secrets: Iterable[str], names: Iterable[str], state: Pem = Pem.OUTSIDE
    ) -> None:
        forms = secret_forms(secrets)
        self._values = re.compile(_union(forms)) if forms else None
        named = set(names)
        self._assignments = (
            re.compile(r"\b(" + _union(named) + r")(['\"]?\s*[=:]\s*)(\S+)") if named else None
        )
        # The same names without the word boundary, which keeps the engine from skipping
        # ahead to where a name begins: a quick look first, most lines name none.
        self._names = re.compile(_union(named)) if named else None
        self.state = state

    def fresh(self, state: Pem = Pem.OUTSIDE) -> Redactor:
        """The same rules for another read of the log, starting in `state`."""
        other = copy.copy(self)
        other.state = state
        return other

    @property
    def inside(self) -> bool:
        """Inside a PEM block, as far as the lines read so far say."""
        return self.state is Pem.INSIDE

    def line(self, text: str) -> str:
        """`text` as it may leave the robot; advances the PEM state."""
        return self._advance(text, emit=True)

    def track(self, text: str) -> None:
        """Advances the PEM state over a line that is read but not sent."""
        self._advance(text, emit=False)

    def _advance(self, text: str, emit: bool) -> str:
        text = strip_escapes(text)
        if self.state is Pem.UNKNOWN:
            body = text.strip()
            if not body:
                return text
            if key_fragment(text):
                return REDACTED
            first = _PEM.search(text)
            # An END before any BEGIN: what precedes it on this line is the key's end.
            inside = first is not None and first.group(1) == "END"
        else:
            inside = self.state is Pem.INSIDE
        pieces: list[str] = [REDACTED] if inside else []
        start = 0
        for marker in _PEM.finditer(text):
            if inside:
                if marker.group(1) == "END":
                    inside, start = False, marker.end()
            elif marker.group(1) == "BEGIN":
                if emit:
                    pieces += [self._scrub(text[start : marker.start()]), REDACTED]
                inside, start = True, marker.end()
        if not inside and emit:
            pieces.append(self._scrub(text[start:]))
        self.state = Pem.INSIDE if inside else Pem.OUTSIDE
        return "".join(pieces)

    def _scrub(self, text: str) -> str:
        if not text:
            return text
        if self._values is not None:
            text = self._values.sub(REDACTED, text)
        if self._assignments is not None and self._names is not None and self._names.search(text):
            text = self._assignments.sub(lambda m: m.group(1) + m.group(2) + REDACTED, text)
        if "://" not in text:
            return text
        return _URL_PASSWORD.sub(lambda m: m.group(1) + ":" + REDACTED + "@", text)


def _union(words: Iterable[str]) -> str:
    """A pattern matching any of `words`, the longest where several match at one place (of two
    secrets where one contains the other, the whole one goes): their trie, which the regex
    engine walks once per position instead of trying each word."""
    root: dict[str, Any] = {}
    for word in words:
        node = root
        for char in word:
            node = node.setdefault(char, {})
        node[""] = {}
    try:
        return _branches(root)
    except RecursionError:  # thousands of nested prefixes: plain alternation, longest first
        ordered = sorted(set(words), key=lambda w: (-len(w), w))
        return "(?:" + "|".join(re.escape(w) for w in ordered) + ")"


def _branches(node: dict[str, Any]) -> str:
    alternatives = []
    for char in sorted(k for k in node if k):
        child, run = node[char], char
        while len(child) == 1 and "" not in child:  # a chain without branches: one literal
            ((char, child),) = child.items()
            run += char
        alternatives.append(re.escape(run) + _branches(child))
    if not alternatives:
        return ""
    body = "(?:" + "|".join(alternatives) + ")"
    # A word ends here: the longer ones are tried first (greedy), then this one.
    return "(?:" + body + ")?" if "" in node else body
