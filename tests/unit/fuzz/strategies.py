"""Strategies for hostile inputs: JSON values, YAML-looking text, byte mutations of good files."""

from __future__ import annotations

from typing import Any

from hypothesis import strategies as st

# Characters that matter to YAML and to terminals: indicators, breaks, controls, odd Unicode.
_ODD = "\x00\x1b\x85\u2028\u2029\ufeff\ud7ff\u00e9\u202e\x7f"
_YAML_ALPHABET = list(" \n-:?,[]{}#&*!|>'\"%@`\t\r\\0123456789abcxyzEe.+_~/=<" + _ODD)

yaml_tokens = st.sampled_from(
    [
        "- ",
        "  ",
        "key: ",
        "a: b\n",
        "[",
        "]",
        "{",
        "}",
        ", ",
        "? ",
        "!!int ",
        "!!float ",
        "!!bool ",
        "!!str ",
        "!!binary ",
        "!!set ",
        "!custom ",
        "&a ",
        "*a ",
        "<<: ",
        "---\n",
        "...\n",
        "%YAML 1.1\n",
        "'",
        '"',
        "\\u2028",
        "\\x00",
        "|\n",
        ">-\n",
        "#c\n",
        "1e999",
        "9" * 50,
        "0x1F",
        "0o17",
        "1:2:3",
        "~",
        "null",
        "yes",
        "2020-01-01",
        ".nan",
        "\n",
    ]
)

yaml_text = st.one_of(
    st.text(alphabet=st.sampled_from(_YAML_ALPHABET), max_size=300),
    st.lists(yaml_tokens, max_size=60).map("".join),
)

json_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(max_size=30),
)

json_values: st.SearchStrategy[Any] = st.recursive(
    json_scalars,
    lambda children: st.one_of(
        st.lists(children, max_size=5),
        st.dictionaries(st.text(max_size=10), children, max_size=5),
    ),
    max_leaves=30,
)


@st.composite
def mutated(draw: st.DrawFn, original: bytes) -> bytes:
    """`original` with a few bytes flipped, inserted, deleted or a slice repeated."""
    data = bytearray(original)
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        if not data:
            data.extend(draw(st.binary(min_size=1, max_size=8)))
            continue
        at = draw(st.integers(min_value=0, max_value=len(data) - 1))
        how = draw(st.sampled_from(["flip", "insert", "delete", "repeat"]))
        if how == "flip":
            data[at] = draw(st.integers(min_value=0, max_value=255))
        elif how == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=8))
        elif how == "delete":
            del data[at : at + draw(st.integers(min_value=1, max_value=16))]
        else:
            end = min(len(data), at + draw(st.integers(min_value=1, max_value=32)))
            data[at:at] = data[at:end] * draw(st.integers(min_value=1, max_value=50))
    return bytes(data)
