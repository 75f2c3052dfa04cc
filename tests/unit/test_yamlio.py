"""contract.yamlio on bytes: the data it yields and where every key and value came from."""

from __future__ import annotations

import pytest

from robotconf.contract import yamlio
from robotconf.contract.yamlio import (
    MAX_DEPTH,
    MAX_EVENTS,
    MAX_PROBLEMS,
    YamlDocument,
    YamlProblem,
    YamlReadError,
    parse_document,
)

SCENARIO = b"""\
# yaml-language-server: $schema=../../schemas/scenario.schema.json
capability: turtlebot3-camera
robot_settings: {max_linear_speed: 0.2}
logic_settings:
  follow_with_poses:
    move_speed: 0.1
goals:
  - {task: Delivery, location: BallContainer}
  - task: Patrol
    location: Dock
"""


def _doc(raw: bytes) -> YamlDocument:
    return parse_document("configs/scenarios/x.yaml", raw)


def _refused(raw: bytes) -> list[YamlProblem]:
    with pytest.raises(YamlReadError) as caught:
        parse_document("x.yaml", raw)
    return caught.value.problems


def _problems(raw: bytes) -> list[tuple[int, int, str]]:
    return [(p.line, p.col, p.code) for p in _refused(raw)]


# ------------------------------------------------------------------ data


def test_data_values() -> None:
    doc = _doc(SCENARIO)
    assert doc.path == "configs/scenarios/x.yaml"
    assert doc.data == {
        "capability": "turtlebot3-camera",
        "robot_settings": {"max_linear_speed": 0.2},
        "logic_settings": {"follow_with_poses": {"move_speed": 0.1}},
        "goals": [
            {"task": "Delivery", "location": "BallContainer"},
            {"task": "Patrol", "location": "Dock"},
        ],
    }


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("42", 42),
        ("-7", -7),
        ("0", 0),
        ("1_000", 1000),
        ("0.22", 0.22),
        ("-1.5", -1.5),
        ("2.0", 2.0),
        ("true", True),
        ("false", False),
        ("True", True),
        ("null", None),
        ("~", None),
        ("", None),
        ('"42"', "42"),
        ("'true'", "true"),
        ("/cmd_vel", "/cmd_vel"),
    ],
)
def test_scalars(text: str, value: object) -> None:
    got = _doc(f"v: {text}\n".encode()).data["v"]
    assert got == value
    assert type(got) is type(value)


@pytest.mark.parametrize(
    "text", ["2024-05-01", "2024-05-01T10:00:00Z", "2024-05-01 10:00:00.5 +02:00"]
)
def test_dates_stay_strings(text: str) -> None:
    assert _doc(f"when: {text}\n".encode()).data["when"] == text


@pytest.mark.parametrize(
    ("key", "read_as"),
    [
        ("yes", "a boolean"),
        ("on", "a boolean"),
        ("true", "a boolean"),
        ("1", "an integer"),
        ("0.5", "a number"),
        ("2024-05-01", "a date"),
        ("~", "null"),
        ("<<", "merge keys"),
    ],
)
def test_keys_that_are_not_text_are_refused(key: str, read_as: str) -> None:
    (problem,) = _refused(f"a: 1\n{key}: value\n".encode())
    assert (problem.line, problem.col, problem.code) == (2, 1, "RC009")
    assert read_as in problem.message


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        (b"!!binary aGk=: 1\n", "key 'aGk=' has the tag '!!binary'; keys must be text"),
        (b'!foo "a\\nb": 1\n', "key 'a\\nb' has the tag '!foo'"),
        (b"!!int 7: 1\n", "key '7' is read as an integer, and keys must be text; quote it: '7'"),
    ],
)
def test_a_key_message_is_one_line_and_says_what_to_do(raw: bytes, message: str) -> None:
    (problem,) = _refused(raw)
    assert (problem.line, problem.col, problem.code) == (1, 1, "RC009")
    assert message in problem.message and "\n" not in problem.message


def test_a_duplicate_key_is_quoted_and_cut_in_its_message() -> None:
    long_key = "k" * 100_000
    raw = f'"a\\nb": 1\n"a\\nb": 2\n? {long_key}\n: 1\n? {long_key}\n: 2\n'.encode()
    first, second = _refused(raw)
    assert (first.line, first.code) == (2, "RC004")
    assert "duplicate key 'a\\nb' (first at line 1)" in first.message
    assert (second.line, second.code) == (5, "RC004")
    assert "'kkkk" in second.message and len(second.message) < 200


def test_an_anchor_defined_twice_says_so() -> None:
    (problem,) = _refused(b"a: &x 1\nb: &x 2\n")
    assert (problem.line, problem.col, problem.code) == (2, 4, "RC005")
    assert "anchor (&name) defined twice (first at line 1)" in problem.message


@pytest.mark.parametrize("key", ["'yes'", '"1"', "'2024-05-01'", '"quoted"', "plain"])
def test_quoted_keys_are_text(key: str) -> None:
    data = _doc(f"{key}: value\n".encode()).data
    assert data == {key.strip("'\""): "value"}


def test_utf8_bom_is_dropped_and_positions_ignore_it() -> None:
    doc = _doc(b"\xef\xbb\xbfplatform: ROS2\nactions: {}\n")
    assert doc.data == {"platform": "ROS2", "actions": {}}
    assert doc.locate(["platform"]) == (1, 11)


def test_crlf_line_ends() -> None:
    doc = _doc(b"a: 1\r\nb:\r\n  c: two\r\n")
    assert doc.data == {"a": 1, "b": {"c": "two"}}
    assert doc.locate(["b", "c"]) == (3, 6)


def test_tabs_inside_values_are_text() -> None:
    assert _doc(b'd: "a\tb"\ne: x\ty\n').data == {"d": "a\tb", "e": "x\ty"}


# ------------------------------------------------------------------ locate


def test_locate_values_and_keys() -> None:
    doc = _doc(SCENARIO)
    assert doc.locate(["capability"]) == (2, 13)
    assert doc.locate(["capability"], key=True) == (2, 1)
    assert doc.locate(["robot_settings", "max_linear_speed"]) == (3, 36)
    assert doc.locate(["robot_settings", "max_linear_speed"], key=True) == (3, 18)


def test_locate_nested_paths_through_lists() -> None:
    doc = _doc(SCENARIO)
    assert doc.locate(["logic_settings", "follow_with_poses", "move_speed"]) == (6, 17)
    assert doc.locate(["goals", 0]) == (8, 5)
    assert doc.locate(["goals", 0, "location"]) == (8, 32)
    assert doc.locate(["goals", 1, "location"], key=True) == (10, 5)
    assert doc.locate(["goals", 1]) == (9, 5)
    # a list item has no key: key=True points at the item itself
    assert doc.locate(["goals", 1], key=True) == (9, 5)


def test_locate_missing_path_falls_back_to_the_parent() -> None:
    doc = _doc(SCENARIO)
    assert doc.locate(["logic_settings", "follow_with_poses", "nope"]) == (6, 5)
    assert doc.locate(["logic_settings", "nope", "deeper"]) == (5, 3)
    assert doc.locate(["goals", 5, "task"]) == (8, 3)  # index out of range: the list
    assert doc.locate(["capability", "inside a scalar"]) == (2, 13)
    assert doc.locate(["nope"]) == (2, 1)  # the top mapping starts after the comment
    assert doc.locate([]) == (2, 1)


def test_locate_quoted_keys_that_look_like_other_types() -> None:
    doc = _doc(b"settings:\n  '1': one\n  'yes': two\n")
    assert doc.locate(["settings", "1"]) == (2, 8)
    assert doc.locate(["settings", "yes"], key=True) == (3, 3)


# ------------------------------------------------------------------ refusals


def test_every_duplicate_key_is_reported_at_once() -> None:
    raw = b"a: 1\nb:\n  c: 1\n  c: 2\na: 3\n"
    assert _problems(raw) == [(4, 3, "RC004"), (5, 1, "RC004")]


def test_every_tab_indented_line_is_reported() -> None:
    assert _problems(b"a:\n\tb: 1\n  \tc: 2\n") == [(2, 1, "RC002"), (3, 3, "RC002")]


def test_non_utf8_column_counts_characters() -> None:
    # 'ü' is two bytes: the bad byte is the 7th character of its line, and its 8th byte
    assert _problems("a: x\nb: Mü ".encode() + b"\xe9\n") == [(2, 7, "RC001")]
    assert _problems(b"\xef\xbb\xbfa: \xe9\n") == [(1, 4, "RC001")]


def test_control_character_is_located_in_one_line() -> None:
    with pytest.raises(YamlReadError) as caught:
        parse_document("x.yaml", "a: x\nb: Mü\x07\n".encode())
    (problem,) = caught.value.problems
    assert (problem.line, problem.col, problem.code) == (2, 6, "RC003")
    assert "\n" not in problem.message and "#x0007" in problem.message


@pytest.mark.parametrize(
    ("raw", "where"),
    [
        (b"a: &a [1, 2]\nb: [x, *a]\n", (2, 8)),  # in a list: the alias itself
        (b"a: &a 1\nb:\n  - x\n  - *a\n", (4, 5)),
        (b"a: &a {k: 1}\nb: *a\n", (2, 1)),  # a mapping value: its key
        (b"a: &a {k: 1}\n<<: *a\n", (2, 1)),  # a merge key is an alias too
        (b"a: &a [*a]\n", (1, 8)),  # recursive
    ],
)
def test_aliases_are_refused_where_they_are(raw: bytes, where: tuple[int, int]) -> None:
    assert _problems(raw) == [(*where, "RC005")]


def test_nesting_limit_is_exact() -> None:
    # the top mapping is level 0; `k`'s list is level 1
    ok = b"k: " + b"[" * MAX_DEPTH + b"]" * MAX_DEPTH + b"\n"
    value, levels = _doc(ok).data["k"], 1
    while value:
        value, levels = value[0], levels + 1
    assert levels == MAX_DEPTH
    deeper = b"k: " + b"[" * (MAX_DEPTH + 1) + b"]" * (MAX_DEPTH + 1) + b"\n"
    assert _problems(deeper) == [(1, 4 + MAX_DEPTH, "RC009")]


def test_runaway_nesting_is_refused_before_composing(monkeypatch: pytest.MonkeyPatch) -> None:
    """libyaml's composer recurses in C (tens of thousands of levels crash the process) and
    takes time quadratic in flow nesting, so a text that could nest deep is refused from its
    events, located as the builder would."""

    def must_not_compose(text: str) -> None:
        raise AssertionError("composed a runaway nesting")

    monkeypatch.setattr(yamlio, "_compose", must_not_compose)
    depth = 60_000
    raw = b"k: " + b"{a: " * depth + b"1" + b"}" * depth + b"\n"
    assert _problems(raw) == [(1, 4 + 4 * MAX_DEPTH, "RC009")]


@pytest.mark.parametrize("text", [".nan", ".NaN", ".inf", "-.inf", "+.Inf"])
def test_non_finite_numbers_are_refused(text: str) -> None:
    assert _problems(f"v: {text}\n".encode()) == [(1, 4, "RC009")]


@pytest.mark.parametrize(
    "raw",
    [
        b"~: 1\n",
        b"null: 1\n",
        b"[a, b]: 1\n",
        b"{a: 1}: 2\n",
    ],
)
def test_keys_must_be_plain_names(raw: bytes) -> None:
    assert _problems(raw) == [(1, 1, "RC009")]


@pytest.mark.parametrize(
    "raw",
    [
        b"v: !!python/object/apply:os.system [echo]\n",
        b"v: !!python/name:os.system\n",
        b"v: !foo bar\n",
        b"v: !!binary aGVsbG8=\n",
        b"v: !!set {a, b}\n",
        b"v: !!omap [a: 1]\n",
    ],
)
def test_tags_are_refused(raw: bytes) -> None:
    assert _problems(raw) == [(1, 4, "RC009")]


# ------------------------------------------------------------------ totality (issue 10, item 4)


@pytest.mark.parametrize(
    "text",
    [
        "x:\n" + "- " * 50_000 + "1\n",  # block sequences on one line: segfaulted libyaml
        "x:\n" + "".join("  " * i + "-\n" for i in range(200)) + "  " * 200 + "1\n",
        "x:\n" + "".join("  " * i + "-\n" for i in range(600)) + "  " * 600 + "1\n",
        "".join(" " * i + "k:\n" for i in range(2_000)) + "x: 1\n",
        "x: " + "[" * 50_000,
        "x:\n" + "- " * 40 + "[" * 40 + "1" + "]" * 40 + "\n",  # block and flow together
    ],
)
def test_nesting_of_every_kind_is_refused_before_composing(text: str) -> None:
    problems = _refused(text.encode())
    assert [p.code for p in problems] == ["RC009"]
    assert problems[0].line >= 1


@pytest.mark.parametrize(
    "step",
    [
        "[" * 20 + " #" + "]" * 20 + "\n",  # closing brackets in comments close nothing
        "[" * 20 + '"' + "]" * 20 + '", ',  # nor in quoted strings
        "[" * 20 + "'" + "]" * 20 + "', ",
    ],
)
def test_closing_brackets_that_close_nothing_cannot_hide_nesting(
    monkeypatch: pytest.MonkeyPatch, step: str
) -> None:
    """The brackets balance out, the real nesting runs away: 60,000 levels crashed libyaml's
    composer. Refused from events, never composed."""

    def must_not_compose(text: str) -> None:
        raise AssertionError("composed a runaway nesting")

    monkeypatch.setattr(yamlio, "_compose", must_not_compose)
    problems = _refused(("x: " + step * 3_000 + "\n").encode())
    assert [(p.line, p.code) for p in problems] == [(1 + step.count("\n") * 3, "RC009")]


def test_a_file_of_too_many_nodes_is_refused_before_composing(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """8 MiB of `[],` took 27 s and 1.4 GB to compose: the nodes are counted first."""

    def must_not_compose(text: str) -> None:
        raise AssertionError("composed too many nodes")

    monkeypatch.setattr(yamlio, "_compose", must_not_compose)
    (problem,) = _refused(b"x: [" + b"[]," * (MAX_EVENTS // 2) + b"]\n")
    assert (problem.line, problem.col, problem.code) == (1, 1, "RC008")
    assert f"over {MAX_EVENTS:,} YAML nodes" in problem.message


def test_a_file_of_many_nodes_within_the_limit_is_read() -> None:
    items = MAX_EVENTS // 2 - 10  # each item one event, the mappings and the stream a few
    assert len(_doc(b"x: [" + b"a," * items + b"]\n").data["x"]) == items


@pytest.mark.parametrize(
    ("raw", "code"),
    [
        (b"a:\n" + b"\tb: 1\n" * 50_000, "RC002"),
        (b"k: 1\n" * 50_000, "RC004"),
        (b"".join(b"%d: 1\n" % i for i in range(50_000)), "RC009"),
    ],
)
def test_a_file_lists_at_most_so_many_problems(raw: bytes, code: str) -> None:
    problems = _refused(raw)
    assert len(problems) == MAX_PROBLEMS
    assert {p.code for p in problems} == {code}
    assert problems[-1].message.endswith("(further problems in this file are not listed)")
    assert problems[-2].line < problems[-1].line


def test_moderate_indentation_is_still_read() -> None:
    text = "a:\n" + "".join("  " * i + f"k{i}:\n" for i in range(1, 40)) + "  " * 40 + "v: 1\n"
    assert _doc(text.encode()).data["a"]["k1"]["k2"]


@pytest.mark.parametrize(
    ("value", "says"),
    [
        ("!!float abc", "'abc' is not a number"),
        ("!!float", "'' is not a number"),
        ("!!int x", "'x' is not an integer"),
        ("!<tag:yaml.org,2002:int> x", "'x' is not an integer"),
        ("!!bool maybe", "'maybe' is not a boolean"),
        ("!!null x", "'x' is not null"),
        ("!!timestamp nope", "'nope' is not a date"),
        ("!!binary aGk=", "'!!binary' is not supported"),
        ("!!set {a}", "'!!set' is not supported"),
        ("!custom x", "'!custom' is not supported"),
        ("9" * 5_000, "beyond the 64-bit integer range"),
        ("0x" + "f" * 5_000, "beyond the 64-bit integer range"),
        ("1:" * 3_000 + "1", "beyond the 64-bit integer range"),
        ("9223372036854775808", "beyond the 64-bit integer range"),
        ("1.0e+999", "beyond the range of a number"),
        ("1" * 500 + ".5", "beyond the range of a number"),
        ("59:" * 3_000 + "1.5", "beyond the range of a number"),  # base 60, untagged
        ("!!float '1e999'", "beyond the range of a number"),
        ("!!str {c: 1}", "'!!str' does not fit a mapping; drop the tag"),
        ("!!int [1]", "'!!int' does not fit a list; drop the tag"),
        ("!!map x", "'!!map' does not fit one value; drop the tag"),
        ("!foo%0Abar x", "YAML tag '!foo\\nbar' is not supported"),  # a line break in a tag
        ("!<tag:x," + "y" * 100_000 + "> 1", "YAML tag 'tag:x,yyyyy"),  # cut, not echoed
    ],
)
def test_every_tag_and_number_is_data_or_rc009(value: str, says: str) -> None:
    (problem,) = _refused(f"a: 1\nb: {value}\n".encode())
    assert (problem.line, problem.col, problem.code) == (2, 4, "RC009")
    assert says in problem.message
    assert len(problem.message) < 300 and "\n" not in problem.message


@pytest.mark.parametrize(
    ("value", "data"),
    [
        ("!!int '3'", 3),
        ("!!str 1", "1"),
        ("!!float 1", 1.0),
        ("!!bool 'true'", True),
        ("-9223372036854775807", -(2**63) + 1),
        ("1" * 300 + ".5", float("1" * 300 + ".5")),
    ],
)
def test_tagged_values_that_fit_are_read(value: str, data: object) -> None:
    assert _doc(f"b: {value}\n".encode()).data == {"b": data}


@pytest.mark.parametrize(
    ("br", "name"),
    [
        ("\u2028", "LINE SEPARATOR"),
        ("\u2029", "PARAGRAPH SEPARATOR"),
        ("\x85", "NEXT LINE"),
        ("\r", "carriage return"),
    ],
)
def test_line_breaks_only_yaml_sees_are_refused_on_the_real_line(br: str, name: str) -> None:
    (problem,) = _refused(f"a: 1\nb: x{br}c: [\nd: 2\n".encode())
    assert (problem.line, problem.col, problem.code) == (2, 5, "RC003")
    assert name in problem.message


@pytest.mark.parametrize(
    ("raw", "where"),
    [
        (b"a: 1\n\xef\xbb\xbfb: 2\n", (2, 1)),  # files joined together
        (b"a: x\xef\xbb\xbfy\n", (1, 5)),
        (b'a: 1\nb: "x\xef\xbb\xbf"\n', (2, 6)),
        (b"\xef\xbb\xbf\xef\xbb\xbfa: 1\n", (1, 1)),  # only the first one is a BOM
    ],
)
def test_a_byte_order_mark_inside_the_file_is_refused_where_it_is(
    raw: bytes, where: tuple[int, int]
) -> None:
    (problem,) = _refused(raw)
    assert (problem.line, problem.col, problem.code) == (*where, "RC003")
    assert "byte order mark (U+FEFF) inside the file" in problem.message


def test_an_escaped_byte_order_mark_or_line_separator_is_text() -> None:
    assert _doc(b'a: "x\\ufeffy\\u2028z"\n').data == {"a": "x\ufeffy\u2028z"}


def test_an_error_at_the_end_of_an_unterminated_last_line_is_on_that_line() -> None:
    assert _problems(b"a: 1\nb: [") == [(2, 5, "RC003")]


@pytest.mark.parametrize("encoding", ["utf-16", "utf-32"])
def test_a_file_in_another_unicode_encoding_says_which(encoding: str) -> None:
    (problem,) = _refused("a: 1\n".encode(encoding))
    assert (problem.line, problem.col, problem.code) == (1, 1, "RC001")
    assert problem.message == f"file is {encoding.upper()}; save it as UTF-8"
