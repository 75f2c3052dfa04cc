"""Text from files and peers made safe to print: no control character, line break or bidi
override can forge a line of a report or drive the terminal.

Agent-safe: the standard library only.
"""

from __future__ import annotations

import re

# C0 and C1 controls (tab, newline and escape among them), DEL, the Unicode line and paragraph
# separators, bidi embeddings, overrides and isolates, and lone surrogates (undecodable bytes).
_UNSAFE = re.compile(
    "[\x00-\x1f\x7f-\x9f\u2028\u2029\u200e\u200f\u202a-\u202e\u2066-\u2069\ud800-\udfff]"
)
# What JSON leaves raw inside strings (ensure_ascii=False) that a terminal would still act on.
_UNSAFE_IN_JSON = re.compile("[\x7f-\x9f\u2028\u2029\u200e\u200f\u202a-\u202e\u2066-\u2069]")


_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _escape(match: re.Match[str]) -> str:
    char = match.group()
    if char in _NAMED:
        return _NAMED[char]
    code = ord(char)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def printable(text: str) -> str:
    """`text` with every unsafe character written as an escape (`\\n`, `\\x1b`, `\\u202e`)."""
    if _UNSAFE.search(text) is None:
        return text
    return _UNSAFE.sub(_escape, text)


def shorten(text: str, limit: int) -> str:
    """`text` of at most `limit` characters: cut, with `…` as its last, when longer."""
    return text if len(text) <= limit else text[: limit - 1] + "…"


def printable_lines(lines: list[str]) -> str:
    """Lines of a report, each made printable, each ending in a newline."""
    return "".join(printable(line) + "\n" for line in lines)


_MARKDOWN = re.compile(r"([\\`*_{}\[\]<>()#+!|~])")


def markdown_text(text: str) -> str:
    """Text for a Markdown table cell: printable, with Markdown's punctuation escaped."""
    return _MARKDOWN.sub(r"\\\1", printable(text))


def markdown_code(text: str) -> str:
    """Text as a Markdown code span in a table cell: printable, `|` escaped (GFM tables), and
    fenced with more backticks than it holds."""
    shown = printable(text).replace("|", "\\|")
    runs = [len(run) for run in re.findall("`+", shown)]
    fence = "`" * (max(runs, default=0) + 1)
    pad = " " if runs else ""
    return f"{fence}{pad}{shown}{pad}{fence}"


# An @ that starts a word: where Mattermost, Rocket.Chat and Discord read a mention
# (`@channel`, `@here`, `@all`, `@everyone`), even in a Slack-compatible webhook's text.
_MENTION = re.compile(r"(?<!\w)@(?=\w)")
_WORD_JOINER = "\u2060"  # invisible; it keeps the @ from starting a mention


def chat_text(text: str) -> str:
    """Text for a Slack-compatible chat message, inert: one printable line, with `&`, `<` and
    `>` escaped as Slack's message formatting requires (so `<!channel>`, `<@U123>` and
    `<http://x|y>` show as written instead of pinging or linking), and a word joiner after an
    @ that starts a word (so a plain `@channel` pings nobody where the chat reads those)."""
    shown = printable(text).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return _MENTION.sub("@" + _WORD_JOINER, shown)


def json_printable(text: str) -> str:
    """JSON text (ensure_ascii=False) with the characters JSON leaves raw escaped as \\uXXXX:
    the same document, safe on a terminal."""
    return _UNSAFE_IN_JSON.sub(lambda m: f"\\u{ord(m.group()):04x}", text)
