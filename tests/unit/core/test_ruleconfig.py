"""Rules a lab tunes (issue 21, item 6): `.robotconf.yaml` severities and `# robotconf: ignore`
comments applied to findings by the one pure function every build ends in."""

from __future__ import annotations

from robotconf.configurator.repository import Entry
from robotconf.configurator.ruleconfig import IgnoreComment, IgnoredCode, ignore_comments, judge
from robotconf.configurator.types import RuleConfiguration
from robotconf.contract.codes import Severity
from robotconf.contract.diagnostics import Diagnostic
from robotconf.contract.yamlio import parse_document

FLEET = "configs/fleet.yaml"


def comments(text: str) -> tuple[IgnoreComment, ...]:
    return ignore_comments(parse_document(FLEET, text.encode()))


def configured(text: str) -> Entry[RuleConfiguration]:
    doc = parse_document(".robotconf.yaml", text.encode())
    return Entry("robotconf", RuleConfiguration.model_validate(doc.data), doc)


def finding(code: str, line: int, severity: Severity = Severity.ERROR) -> Diagnostic:
    return Diagnostic(FLEET, line, 3, severity, code, f"a {code} finding")


def shown(found: list[Diagnostic]) -> list[tuple[str, int, int, str, str]]:
    return [(d.path, d.line, d.col, d.severity.value, d.code) for d in found]


def test_an_ignore_comment_is_read_with_the_position_of_each_code() -> None:
    text = (
        "robots:\n"
        "  tb3-01: {scenario: s}  # robotconf: ignore RC505, RC608 robots on two domains\n"
        "  tb3-02: {scenario: s}  #robotconf:ignore RC505,RC607\n"
    )
    assert comments(text) == (
        IgnoreComment(
            2, 26, (IgnoredCode("RC505", 2, 46), IgnoredCode("RC608", 2, 53))
        ),  # free text after the codes is a reason, not a code
        IgnoreComment(3, 26, (IgnoredCode("RC505", 3, 44), IgnoredCode("RC607", 3, 50))),
    )


def test_a_hash_inside_a_value_is_no_comment() -> None:
    text = (
        'name: "x # robotconf: ignore RC505"\n'
        "plain: a#robotconf:ignore RC505\n"
        "block: |\n"
        "  # robotconf: ignore RC505\n"
        "flow: ['# robotconf: ignore RC505', b]  # robotconf: ignore RC608\n"
    )
    assert comments(text) == (IgnoreComment(5, 41, (IgnoredCode("RC608", 5, 61),)),)
    assert comments("a: 1\n") == () and comments("a: 1  # robotconf: see README\n") == ()


def test_a_comment_naming_no_code_is_kept_to_be_reported() -> None:
    assert comments("a: 1  # robotconf: ignore\n") == (IgnoreComment(1, 7, ()),)


def test_severities_are_set_turned_off_and_raised() -> None:
    config = configured("rules: {RC505: warning, RC607: off, RC608: error}\n")
    found = [finding("RC505", 2), finding("RC607", 3), finding("RC608", 4, Severity.WARNING)]
    assert shown(judge(found, config, {})) == [
        (FLEET, 2, 3, "warning", "RC505"),
        (FLEET, 4, 3, "error", "RC608"),
    ]
    assert judge(found, None, {}) == sorted(found)  # no file: every rule as declared


def test_a_bare_off_is_read_as_false_and_means_off() -> None:
    assert judge([finding("RC505", 2)], configured("rules:\n  RC505: off\n"), {}) == []


def test_bad_configuration_entries_are_located_and_the_good_ones_still_apply() -> None:
    config = configured(
        "rules:\n  RC5O5: warning\n  RC501: off\n  RC608: loud\n  RC706: on\n  RC505: warning\n"
    )
    found = judge([finding("RC505", 2), finding("RC501", 3)], config, {})
    problems = [(d.line, d.col, d.message) for d in found if d.code == "RC801"]
    assert problems == [
        (2, 3, "unknown rule code 'RC5O5'; did you mean 'RC505'?"),
        (
            3,
            3,
            "RC501 cannot be tuned: ids, labels and names become MQTT topic levels and ROS names",
        ),
        (4, 10, "RC608: 'loud' is not a severity; use error, warning or off"),
        (
            5,
            10,
            "RC706: a yes/no value (on, yes, true) is not a severity; use error, warning or off",
        ),
    ]
    assert all(d.path == ".robotconf.yaml" and d.is_error for d in found if d.code == "RC801")
    assert [(d.code, d.severity.value) for d in found if d.path == FLEET] == [
        ("RC505", "warning"),
        ("RC501", "error"),
    ]


def test_an_ignore_comment_silences_its_codes_on_its_line_only() -> None:
    ignores = {FLEET: comments("a: 1\nb: 2  # robotconf: ignore RC505\n")}
    found = [finding("RC505", 2), finding("RC505", 1), finding("RC608", 2, Severity.WARNING)]
    assert shown(judge(found, None, ignores)) == [
        (FLEET, 1, 3, "error", "RC505"),
        (FLEET, 2, 3, "warning", "RC608"),
    ]
    other = {"configs/scenarios/s.yaml": ignores[FLEET]}  # another file's line 2
    assert [d.code for d in judge([finding("RC505", 2)], None, other)] == ["RC505", "RC803"]


def test_unknown_and_untunable_codes_in_a_comment_are_reported_and_silence_nothing() -> None:
    ignores = {FLEET: comments("a: 1  # robotconf: ignore RC501, RC9, RC505\n")}
    found = judge([finding("RC501", 1), finding("RC505", 1)], None, ignores)
    assert [(d.col, d.severity.value, d.code) for d in found] == [
        (3, "error", "RC501"),  # kept: an id that is no topic level cannot be waved through
        (27, "warning", "RC802"),
        (34, "warning", "RC802"),
    ]
    assert "RC501 cannot be ignored" in found[1].message
    assert found[2].message.startswith("'RC9' is not a rule code")
    assert "did you mean" in found[2].message


def test_an_ignore_that_silences_nothing_is_reported_at_its_code() -> None:
    ignores = {FLEET: comments("a: 1  # robotconf: ignore RC505\nb: 2  # robotconf: ignore\n")}
    found = judge([], None, ignores)
    assert shown(found) == [
        (FLEET, 1, 27, "warning", "RC803"),
        (FLEET, 2, 7, "warning", "RC802"),
    ]
    assert found[0].message == (
        "`# robotconf: ignore RC505` silences nothing: no RC505 finding on line 1; remove it"
    )
    # A lab may turn these warnings off like any tunable rule.
    assert judge([], configured("rules: {RC803: off, RC802: off}\n"), ignores) == []


def test_an_ignored_finding_of_a_rule_turned_off_still_uses_its_comment() -> None:
    ignores = {FLEET: comments("a: 1  # robotconf: ignore RC505\n")}
    assert judge([finding("RC505", 1)], configured("rules: {RC505: off}\n"), ignores) == []


def test_a_long_unknown_code_is_cut_in_the_message() -> None:
    code = "RC" + "5" * 1000  # YAML keys end at 1,024 characters
    found = judge(
        [],
        configured(f"rules: {{{code}: off}}\n"),
        {FLEET: comments(f"a: 1  # robotconf: ignore {code}\n")},
    )
    assert [d.code for d in found] == ["RC801", "RC802"]
    assert all(f"'RC{'5' * 18}...'" in d.message and len(d.message) < 200 for d in found)
