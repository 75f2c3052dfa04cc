"""Rules a lab tunes: severities set in `.robotconf.yaml` and `# robotconf: ignore CODE` comments,
applied to a build's findings in one place (`workspace.judged`); the rules never see either."""

from __future__ import annotations

import bisect
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Protocol

from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from robotconf.configurator.types import RuleConfiguration
from robotconf.contract.codes import RULES, Severity
from robotconf.contract.diagnostics import Diagnostic, did_you_mean
from robotconf.contract.yamlio import YamlDocument, decode


class Configured(Protocol):
    """`.robotconf.yaml` as the loader gives it (a repository's Entry)."""

    @property
    def path(self) -> str: ...

    @property
    def model(self) -> RuleConfiguration: ...

    @property
    def doc(self) -> YamlDocument: ...


LEVELS = ("error", "warning", "off")
_MARKER = b"robotconf:"  # a file without it has no ignore comment: most files cost one search
_COMMENT = re.compile(r"#[ \t]*robotconf:[ \t]*ignore\b[ \t]*")
_CODE_LIST = re.compile(r"[A-Za-z]+[0-9]+(?:[ \t]*,[ \t]*[A-Za-z]+[0-9]+)*")  # then free text
_CODE = re.compile(r"[A-Za-z]+[0-9]+")
_EXAMPLE = "`# robotconf: ignore RC505` (codes separated by commas)"


@dataclass(frozen=True)
class IgnoredCode:
    """One code of an ignore comment, where it is written (1-based)."""

    code: str
    line: int
    col: int


@dataclass(frozen=True)
class IgnoreComment:
    """`# robotconf: ignore RC505, RC608` on a line: the codes it silences on that line."""

    line: int
    col: int  # of the `#`
    codes: tuple[IgnoredCode, ...]  # none when it names no code (reported)


def ignore_comments(doc: YamlDocument) -> tuple[IgnoreComment, ...]:
    """The ignore comments of a parsed file. Read from the text the reader accepted; a `#` is a
    comment only after a space or at a line's start and outside every scalar (a quoted value or
    a block scalar may hold `# robotconf: ignore` as text), which the node tree tells."""
    if _MARKER not in doc.raw:
        return ()
    text = decode(doc.raw)
    candidates: list[tuple[tuple[int, int], re.Match[str]]] = []
    line, counted = 0, 0
    for match in _COMMENT.finditer(text):
        start = match.start()
        if start > 0 and text[start - 1] not in " \t\n":
            continue
        line += text.count("\n", counted, start)
        counted = start
        candidates.append(((line, start - (text.rfind("\n", 0, start) + 1)), match))
    if not candidates:
        return ()
    inside = _inside_scalars(doc.root, [position for position, _ in candidates])
    return tuple(
        _comment(position, match)
        for index, (position, match) in enumerate(candidates)
        if index not in inside
    )


def _inside_scalars(root: Node, positions: list[tuple[int, int]]) -> set[int]:
    """Indices of the (sorted, 0-based) positions that lie within a scalar of the tree."""
    inside: set[int] = set()
    pending: list[Node] = [root]
    while pending:  # a stack, not recursion: nesting is bounded, but need not be shallow
        node = pending.pop()
        if isinstance(node, ScalarNode):
            start = (node.start_mark.line, node.start_mark.column)
            end = (node.end_mark.line, node.end_mark.column)
            index = bisect.bisect_left(positions, start)
            while index < len(positions) and positions[index] < end:
                inside.add(index)
                index += 1
        elif isinstance(node, MappingNode):
            pending.extend(part for pair in node.value for part in pair)
        elif isinstance(node, SequenceNode):
            pending.extend(node.value)
    return inside


def _comment(position: tuple[int, int], match: re.Match[str]) -> IgnoreComment:
    line, col = position[0] + 1, position[1] + 1
    listed = _CODE_LIST.match(match.string, match.end())
    codes: tuple[IgnoredCode, ...] = ()
    if listed is not None:
        offset = col + listed.start() - match.start()
        codes = tuple(
            IgnoredCode(code.group(), line, offset + code.start())
            for code in _CODE.finditer(listed.group())
        )
    return IgnoreComment(line, col, codes)


def judge(
    diagnostics: Iterable[Diagnostic],
    configuration: Configured | None,
    ignores: Mapping[str, tuple[IgnoreComment, ...]],
) -> list[Diagnostic]:
    """A build's findings as the lab tuned them, sorted: those its ignore comments silence
    dropped, the severities of `.robotconf.yaml` applied (off drops), and what is wrong with
    either reported. A rule a lab cannot tune is kept as declared, whatever either says."""
    levels, found = _levels(configuration)
    wanted, problems = _wanted(ignores)
    used: set[tuple[str, int, str]] = set()
    for diagnostic in diagnostics:
        key = (diagnostic.path, diagnostic.line, diagnostic.code)
        if key in wanted:  # only tunable codes are wanted
            used.add(key)
        else:
            found.append(diagnostic)
    for key, ignored in wanted.items():
        if key not in used:
            found.append(_unused(key[0], ignored))
    found.extend(problems)
    return sorted(_leveled(found, levels))


def _leveled(found: Iterable[Diagnostic], levels: Mapping[str, str]) -> Iterable[Diagnostic]:
    for diagnostic in found:
        level = levels.get(diagnostic.code)
        if level is None:
            yield diagnostic
        elif level != "off":
            yield replace(diagnostic, severity=Severity(level))


def _levels(
    configuration: Configured | None,
) -> tuple[dict[str, str], list[Diagnostic]]:
    """Code -> level for each rule `.robotconf.yaml` tunes, and RC801 for each it cannot."""
    levels: dict[str, str] = {}
    problems: list[Diagnostic] = []
    if configuration is None:
        return levels, problems
    doc, path = configuration.doc, configuration.path

    def refuse(code: str, message: str, *, key: bool) -> None:
        line, col = doc.locate(["rules", code], key=key)
        problems.append(Diagnostic(path, line, col, Severity.ERROR, "RC801", message))

    for code, value in configuration.model.rules.items():
        rule = RULES.get(code)
        level = "off" if value is False else value
        if rule is None:
            message = f"unknown rule code '{_cut(code)}'{did_you_mean(code, RULES)}"
            refuse(code, message, key=True)
        elif not rule.tunable:
            refuse(code, f"{code} cannot be tuned: {rule.fixed}", key=True)
        elif level not in LEVELS:
            shown = "a yes/no value (on, yes, true)" if value is True else repr(value)
            refuse(code, f"{code}: {shown} is not a severity; use error, warning or off", key=False)
        else:
            levels[code] = str(level)
    return levels, problems


def _wanted(
    ignores: Mapping[str, tuple[IgnoreComment, ...]],
) -> tuple[dict[tuple[str, int, str], IgnoredCode], list[Diagnostic]]:
    """(path, line, code) -> where each tunable code of an ignore comment is written, and
    RC802 for each comment or code that silences nothing by its very writing."""
    wanted: dict[tuple[str, int, str], IgnoredCode] = {}
    problems: list[Diagnostic] = []
    for path, comments in ignores.items():
        for comment in comments:
            if not comment.codes:
                message = f"this ignore comment names no rule code; write {_EXAMPLE}"
                problems.append(_rc802(path, comment.line, comment.col, message))
            for ignored in comment.codes:
                rule = RULES.get(ignored.code)
                if rule is None:
                    message = (
                        f"'{_cut(ignored.code)}' is not a rule code, so it silences nothing"
                        f"{did_you_mean(ignored.code, RULES)}"
                    )
                elif not rule.tunable:
                    message = (
                        f"{ignored.code} cannot be ignored ({rule.fixed}); fix what it reports"
                    )
                else:
                    wanted[(path, comment.line, ignored.code)] = ignored
                    continue
                problems.append(_rc802(path, ignored.line, ignored.col, message))
    return wanted, problems


def _cut(text: str, limit: int = 20) -> str:
    """A code as written, cut in a message: a file may write anything there."""
    return text if len(text) <= limit else text[:limit] + "..."


def _rc802(path: str, line: int, col: int, message: str) -> Diagnostic:
    return Diagnostic(path, line, col, Severity.WARNING, "RC802", message)


def _unused(path: str, ignored: IgnoredCode) -> Diagnostic:
    return Diagnostic(
        path,
        ignored.line,
        ignored.col,
        Severity.WARNING,
        "RC803",
        f"`# robotconf: ignore {ignored.code}` silences nothing: no {ignored.code} finding on "
        f"line {ignored.line}; remove it",
    )
