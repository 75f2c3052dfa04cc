"""The bounded JSON reader for MQTT payloads: bounds before parsing, strict after."""

from __future__ import annotations

import pytest

from robotconf.contract.safejson import PayloadError, parse_json, parse_object


@pytest.mark.parametrize(
    ("payload", "why"),
    [
        (b"[" * 100_000 + b"]" * 100_000, "nested 100000 levels"),
        (b'{"a": 1, "a": 2}', "duplicate key 'a'"),
        (b'{"a": NaN}', "NaN is not a JSON number"),
        (b"[Infinity]", "Infinity is not a JSON number"),
        (b"1" * 5000, "malformed JSON"),
        (b"\xff\xfe", "not UTF-8"),
        (b"x" * 2_000_000, "over the limit of"),
        (b"[1]]", "malformed JSON"),
    ],
)
def test_refused(payload: bytes, why: str) -> None:
    with pytest.raises(PayloadError, match=why):
        parse_json(payload)


def test_brackets_inside_strings_are_not_nesting() -> None:
    text = b'{"a": "' + b"[" * 1000 + b'", "b": "\\\\", "c": ["]\\"]"]}'
    assert parse_json(text) == {"a": "[" * 1000, "b": "\\", "c": [']"]']}


def test_depth_limit_is_inclusive() -> None:
    assert parse_json(b"[" * 64 + b"]" * 64, max_depth=64) is not None
    with pytest.raises(PayloadError):
        parse_json(b"[" * 65 + b"]" * 65, max_depth=64)


def test_object_required() -> None:
    assert parse_object(b'{"k": [1, 2.5, true, null]}') == {"k": [1, 2.5, True, None]}
    with pytest.raises(PayloadError, match="expected a JSON object, got an array"):
        parse_object(b"[]")


@pytest.mark.parametrize(
    ("payload", "why"),
    [
        (b'{"issued_at": 1e999}', "too large to be represented"),
        (b'["\\ud800"]', "lone UTF-16 surrogate"),
        (b'{"\\udfff": 1}', "lone UTF-16 surrogate"),
    ],
)
def test_values_that_cannot_be_written_back_are_refused(payload: bytes, why: str) -> None:
    with pytest.raises(PayloadError, match=why):
        parse_json(payload)


def test_paired_surrogate_escapes_are_one_character() -> None:
    assert parse_json(b'["\\ud83d\\ude00", "\\\\ud800"]') == ["\U0001f600", "\\ud800"]
