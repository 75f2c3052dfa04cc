"""Property: any bytes give data or located RC diagnostics from the YAML reader — never a crash."""

from __future__ import annotations

import json
import re
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from robotconf.contract.yamlio import YamlReadError, parse_document
from tests.unit.fuzz.strategies import mutated, yaml_text

ROOT = Path(__file__).resolve().parents[3]
EXAMPLES = sorted(p for top in ("configs", "models") for p in (ROOT / top).rglob("*.yaml"))
CODE = re.compile(r"RC\d{3}")


def read_totally(raw: bytes) -> None:
    """The reader's contract, asserted for one input."""
    try:
        doc = parse_document("fuzz.yaml", raw)
    except YamlReadError as exc:
        assert exc.problems
        last_line = raw.count(b"\n") + 1
        for problem in exc.problems:
            assert CODE.fullmatch(problem.code), problem
            # The real line: counted in newlines, whatever YAML calls a line break.
            assert 1 <= problem.line <= last_line, (problem, last_line)
            assert problem.col >= 1, problem
            assert problem.message and len(problem.message) <= 500, problem
            assert not any(c in problem.message for c in "\n\r\x85\u2028\u2029"), problem
        return
    assert isinstance(doc.data, dict)
    assert all(isinstance(key, str) for key in doc.data)
    # What was read can go into a launch request: strict JSON, encodable as UTF-8.
    json.dumps(doc.data, allow_nan=False, ensure_ascii=False).encode("utf-8")
    for key in doc.data:
        line, col = doc.locate([key], key=True)
        assert line >= 1 and col >= 1


@given(st.binary(max_size=512))
def test_any_bytes(raw: bytes) -> None:
    read_totally(raw)


@given(yaml_text)
def test_yaml_looking_text(text: str) -> None:
    read_totally(text.encode("utf-8", "surrogatepass"))


@given(st.sampled_from(EXAMPLES).flatmap(lambda path: mutated(path.read_bytes())))
def test_mutated_example_files(raw: bytes) -> None:
    read_totally(raw)


@given(
    st.integers(min_value=1, max_value=4000),
    st.sampled_from(["- ", "-\n{pad}  ", "a:\n{pad}  ", "[", "{a: ", "- [", "? "]),
)
def test_nesting_of_every_kind(depth: int, step: str) -> None:
    parts = []
    for level in range(depth):
        parts.append(step.replace("{pad}", "  " * level))
    read_totally(
        ("x: " if step.startswith(("[", "{")) else "x:\n").encode()
        + "".join(parts).encode()
        + b"1\n"
    )
