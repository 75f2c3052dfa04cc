"""The one rule of what may become a file name (contract.models.file_name), and the one YAML
writer (contract.yamlio.document_text): no name leaves its folder or misleads a terminal, and
no comment or value breaks out of its place in a written file."""

from __future__ import annotations

import pytest
import yaml

from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.models import file_name, file_name_problem
from robotconf.contract.yamlio import document_text, parse_document

REFUSED = [
    "",
    ".",
    "..",
    "../../x",
    "a/b",
    "/etc/passwd",
    ".hidden",
    "-starts-with-a-dash",
    "tb3\n",
    "tb3\nplatform: evil",
    "tb3\r",
    "\x1b[2Jtb3",
    "tb3\u202ex",
    "tb3\u2028x",
    "with space",
    "x" * 65,
    "tb3\x00",
]


@pytest.mark.parametrize("name", ["tb3-01", "turtlebot3-burger", "ROS2", "a", "a.b_c-d", "x" * 64])
def test_names_of_letters_digits_and_marks_may_be_files(name: str) -> None:
    assert file_name_problem(name) is None
    assert file_name("--template", name) == name


@pytest.mark.parametrize("name", REFUSED)
def test_names_that_leave_their_folder_or_mislead_are_refused_in_one_safe_line(name: str) -> None:
    assert file_name_problem(name) is not None
    with pytest.raises(CliError) as refused:
        file_name("--robot", name)
    message = refused.value.message
    assert refused.value.code == ExitCode.TOOL
    assert message.startswith("--robot '") and "cannot name a file" in message
    assert message.isprintable() and len(message) < 250


def test_a_written_document_reads_back_whatever_its_comment_and_values_hold() -> None:
    body = {"platform": "yes", "name": "a: b # c", "list": ["1.0", "x\ny"], "empty": {}}
    text = document_text(["one\ntwo\rthree\u2028four\x85five", "\x1b[2J"], body)
    header = [line for line in text.splitlines() if line.startswith("#")]
    assert len(header) == 6 and all(line.isprintable() for line in header)
    assert text.isascii()
    assert yaml.safe_load(text) == body
    assert parse_document("configs/x.yaml", text.encode("utf-8")).data == body


def test_block_lists_are_indented_under_their_key_and_leaves_may_flow() -> None:
    body = {"actions": {"Follow": ["a", "b"]}}
    assert document_text([], body) == "actions:\n  Follow:\n    - a\n    - b\n"
    assert document_text([], body, flow_leaves=True) == "actions:\n  Follow: [a, b]\n"
