"""JSON from untrusted peers (MQTT payloads): size and depth bounded before parsing, strict after.

Any robot may publish anything on its own topics, so a payload is checked cheaply first (its
length, then its nesting with strings skipped) and only then handed to `json.loads`; duplicate
keys and NaN/Infinity are refused so that what was parsed is exactly what the bytes say.
Agent-safe: the standard library only.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

# Statuses and descriptions are a few hundred bytes, launch requests a few kB: generous bounds.
MAX_PAYLOAD_BYTES = 1024 * 1024
MAX_JSON_DEPTH = 64

# A JSON string: what is inside it never counts as nesting.
_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
_NOT_BRACKET = re.compile(rb"[^\[\]{}]+")
# A \u escape of a UTF-16 surrogate: paired it is one character, alone it is no text at all.
_SURROGATE_ESCAPE = re.compile(rb"\\u[dD][89a-fA-F]")


class PayloadError(ValueError):
    """The payload is not acceptable JSON; the message says why, in one line."""


def _depth(raw: bytes) -> int:
    brackets = _NOT_BRACKET.sub(b"", _STRING.sub(b"", raw))
    depth = peak = 0
    for byte in brackets:
        if byte in b"[{":
            depth += 1
            if depth > peak:
                peak = depth
        else:
            depth -= 1
    return peak


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    result: dict[str, Any] = {}
    for key, value in pairs:
        if key in result:
            raise PayloadError(f"duplicate key {key!r}")
        result[key] = value
    return result


def _no_constant(name: str) -> Any:
    raise PayloadError(f"{name} is not a JSON number")


def _finite(text: str) -> float:
    value = float(text)
    if math.isinf(value):
        raise PayloadError(f"number {text[:20]!r} is too large to be represented")
    return value


def _check_text(value: Any) -> None:
    """Refuses a lone surrogate anywhere in the value: it cannot be written out as UTF-8."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            try:
                item.encode("utf-8")
            except UnicodeEncodeError:
                raise PayloadError("a string holds a lone UTF-16 surrogate escape") from None
        elif isinstance(item, dict):
            stack.extend(item.keys())
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)


def parse_json(
    payload: bytes, *, max_bytes: int = MAX_PAYLOAD_BYTES, max_depth: int = MAX_JSON_DEPTH
) -> Any:
    """The parsed value, or PayloadError: too large, nested too deep, not UTF-8, not strict JSON
    (duplicate keys, NaN, numbers beyond float range, lone surrogates)."""
    if len(payload) > max_bytes:
        raise PayloadError(f"payload is {len(payload):,} bytes, over the limit of {max_bytes:,}")
    # Nesting needs an opening bracket per level: a payload with few brackets (in strings or
    # not) is within bounds without the scan, at a C count's cost.
    few = payload.count(b"{") + payload.count(b"[") <= max_depth
    depth = 0 if few else _depth(payload)
    if depth > max_depth:
        raise PayloadError(f"payload is nested {depth} levels deep, over the limit of {max_depth}")
    try:
        text = payload.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PayloadError(f"payload is not UTF-8 (byte {exc.start})") from None
    try:
        value = json.loads(
            text,
            object_pairs_hook=_no_duplicates,
            parse_constant=_no_constant,
            parse_float=_finite,
        )
    except PayloadError:
        raise
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, over-long integers
        raise PayloadError(f"malformed JSON: {exc}") from None
    if _SURROGATE_ESCAPE.search(payload):
        _check_text(value)
    return value


def parse_object(
    payload: bytes, *, max_bytes: int = MAX_PAYLOAD_BYTES, max_depth: int = MAX_JSON_DEPTH
) -> dict[str, Any]:
    """Like `parse_json`, for payloads that must be a JSON object."""
    value = parse_json(payload, max_bytes=max_bytes, max_depth=max_depth)
    if not isinstance(value, dict):
        raise PayloadError(f"expected a JSON object, got {_json_type(value)}")
    return value


def _json_type(value: Any) -> str:
    if isinstance(value, list):
        return "an array"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, bool):
        return "a boolean"
    if value is None:
        return "null"
    return "a number"
