"""Strict YAML reading that remembers where every key and value came from.

Refuses what would hide a mistake or exhaust memory: duplicate keys, aliases (alias bombs),
tabs in indentation, several documents, non-UTF-8 bytes, oversized files.
"""

from __future__ import annotations

import codecs
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import yaml
from yaml.constructor import SafeConstructor
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

try:  # the C parser is several times faster; fall back where libyaml is missing
    from yaml import CSafeLoader as _Loader
except ImportError:  # pragma: no cover - depends on the PyYAML build
    from yaml import SafeLoader as _Loader  # type: ignore[assignment]

MAX_FILE_BYTES = 8 * 1024 * 1024
MAX_DEPTH = 64
# JSON readers differ beyond 64-bit integers; longer digit strings are refused before any
# conversion (Python refuses over 4,300 digits, and base 60 is quadratic).
MAX_INT = 2**63 - 1
_MAX_NUMBER_CHARS = 100
_NOT_BRACKET = re.compile(r"[^\[\]{}]+")
# What opens block collections at the start of a line: indentation and the indicators - ? :
_BLOCK_LEAD = re.compile(r"^[ ?:-]*", re.MULTILINE)
# YAML 1.1 breaks lines here too, editors and git do not: a reported line would be wrong.
_ODD_BREAKS = re.compile("\r(?!\n)|[\x85\u2028\u2029]")
_BREAK_NAMES = {
    "\r": "a carriage return not followed by a line feed (old Mac line end)",
    "\x85": "NEXT LINE (U+0085)",
    "\u2028": "LINE SEPARATOR (U+2028)",
    "\u2029": "PARAGRAPH SEPARATOR (U+2029)",
}

_STR = "tag:yaml.org,2002:str"
_INT = "tag:yaml.org,2002:int"
_FLOAT = "tag:yaml.org,2002:float"
_BOOL = "tag:yaml.org,2002:bool"
_NULL = "tag:yaml.org,2002:null"
_TIMESTAMP = "tag:yaml.org,2002:timestamp"
_MERGE = "tag:yaml.org,2002:merge"
_MAP = "tag:yaml.org,2002:map"
_SEQ = "tag:yaml.org,2002:seq"

_scalars = SafeConstructor()


def _implicit_patterns() -> dict[str, list[re.Pattern[str]]]:
    """The patterns by which YAML resolves a plain scalar to each tag: an explicitly tagged
    value must match its tag's, or constructing it would fail (`!!float abc`)."""
    found: dict[str, list[re.Pattern[str]]] = {}
    for resolvers in yaml.resolver.Resolver.yaml_implicit_resolvers.values():
        for tag, pattern in resolvers:
            if pattern not in found.setdefault(tag, []):
                found[tag].append(pattern)
    return found


_FITS = _implicit_patterns()
_UNFIT = object()  # a tagged value that is not of its tag
_TAG_NAMES = {_INT: "an integer", _FLOAT: "a number", _BOOL: "a boolean", _NULL: "null"}

Loc = Sequence[str | int]


@dataclass(frozen=True)
class YamlProblem:
    """A reason the file could not be read as data; 1-based position."""

    line: int
    col: int
    code: str
    message: str


class YamlReadError(Exception):
    def __init__(self, problems: list[YamlProblem]) -> None:
        super().__init__(problems[0].message)
        self.problems = problems


@dataclass
class YamlDocument:
    """A parsed file: its data and the node tree that locates every key and value in it."""

    path: str
    data: dict[str, Any]
    root: MappingNode
    _index: dict[int, dict[str, tuple[Node, Node]]] = field(default_factory=dict, repr=False)

    def _pairs(self, node: MappingNode) -> dict[str, tuple[Node, Node]]:
        pairs = self._index.get(id(node))
        if pairs is None:
            pairs = {str(k.value): (k, v) for k, v in node.value if isinstance(k, ScalarNode)}
            self._index[id(node)] = pairs
        return pairs

    def locate(self, loc: Loc, *, key: bool = False) -> tuple[int, int]:
        """Line and column (1-based) of the value at `loc`, or of its key with `key=True`.

        A path that leaves the document stops at the deepest node that exists, so a missing
        field is reported where its parent mapping is.
        """
        node: Node = self.root
        key_node: Node | None = None
        for part in loc:
            if isinstance(node, MappingNode):
                found = self._pairs(node).get(str(part))
                if found is None:
                    break
                key_node, node = found
            elif isinstance(node, SequenceNode) and isinstance(part, int):
                if not 0 <= part < len(node.value):
                    break
                key_node, node = None, node.value[part]
            else:
                break
        target = key_node if key and key_node is not None else node
        mark = target.start_mark
        return mark.line + 1, mark.column + 1


def _problem(mark: Any, code: str, message: str) -> YamlProblem:
    if mark is None:
        return YamlProblem(1, 1, code, message)
    return YamlProblem(mark.line + 1, mark.column + 1, code, message)


def _within(problem: YamlProblem, text: str) -> YamlProblem:
    """libyaml places an error at the end of an unterminated last line on the line after it,
    which does not exist: report it at the end of the last line instead."""
    last = text.count("\n") + 1
    if problem.line <= last:
        return problem
    tail = len(text) - (text.rfind("\n") + 1)
    return YamlProblem(last, tail + 1, problem.code, problem.message)


def _position_of_byte(raw: bytes, offset: int) -> tuple[int, int]:
    """Line and column (1-based) of a byte offset into UTF-8; columns count characters, as
    YAML marks do (a leading BOM is not one)."""
    line = raw.count(b"\n", 0, offset) + 1
    start = raw.rfind(b"\n", 0, offset) + 1
    if start == 0 and raw.startswith(codecs.BOM_UTF8):
        start = len(codecs.BOM_UTF8)
    col = len(raw[start:offset].decode("utf-8", errors="replace")) + 1
    return line, col


# Longest first: UTF-32's little-endian mark begins with UTF-16's.
_OTHER_BOMS = (
    (codecs.BOM_UTF32_LE, "UTF-32"),
    (codecs.BOM_UTF32_BE, "UTF-32"),
    (codecs.BOM_UTF16_LE, "UTF-16"),
    (codecs.BOM_UTF16_BE, "UTF-16"),
)


def decode(raw: bytes) -> str:
    """UTF-8 text or a located RC001; a leading BOM is accepted and dropped."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        for bom, encoding in _OTHER_BOMS:
            if raw.startswith(bom):
                raise YamlReadError(
                    [YamlProblem(1, 1, "RC001", f"file is {encoding}; save it as UTF-8")]
                ) from None
        line, col = _position_of_byte(raw, exc.start)
        raise YamlReadError(
            [
                YamlProblem(
                    line,
                    col,
                    "RC001",
                    f"file is not valid UTF-8 (byte 0x{raw[exc.start]:02x}); save it as UTF-8",
                )
            ]
        ) from None
    return text[1:] if text.startswith("\ufeff") else text


def _tab_indents(text: str) -> list[YamlProblem]:
    problems = []
    for number, line in enumerate(text.split("\n"), start=1):
        body = line.lstrip(" ")
        if body.startswith("\t"):
            problems.append(
                YamlProblem(
                    number,
                    len(line) - len(body) + 1,
                    "RC002",
                    "tab character in indentation; YAML indents with spaces only",
                )
            )
    return problems


def _refuse_odd_line_breaks(text: str) -> None:
    """RC003 for line breaks only YAML sees: after one, YAML's line numbers and everyone
    else's would differ, so no position reported past it could be trusted."""
    problems = []
    for match in _ODD_BREAKS.finditer(text):
        offset = match.start()
        line = text.count("\n", 0, offset) + 1
        col = offset - (text.rfind("\n", 0, offset) + 1) + 1
        problems.append(
            YamlProblem(
                line,
                col,
                "RC003",
                f"{_BREAK_NAMES[match.group()]} breaks the line for YAML but not for editors "
                "or git; end lines with a line feed (\\n), or write the character as an "
                "escape in a double-quoted string",
            )
        )
        if len(problems) == 10:
            break
    if problems:
        raise YamlReadError(problems)


def _reader_problem(text: str, exc: yaml.reader.ReaderError) -> YamlProblem:
    """A character YAML refuses (control characters): located, in one line."""
    raw = text.encode("utf-8")
    offset = exc.position
    if not _Loader.__name__.startswith("C"):  # libyaml counts bytes, pure Python characters
        offset = len(text[:offset].encode("utf-8"))
    line, col = _position_of_byte(raw, offset)
    char = exc.character if isinstance(exc.character, int) else ord(exc.character)
    return YamlProblem(
        line,
        col,
        "RC003",
        f"YAML syntax error: {exc.reason} (character #x{char:04x})",
    )


def _flow_depth_bound(text: str) -> int:
    """An upper bound of flow ([...], {...}) nesting: brackets inside quotes count too.

    Block nesting needs indentation, so within MAX_FILE_BYTES it stays far below what the C
    composer survives; only flow nesting can run away."""
    depth = peak = 0
    for bracket in "".join(_NOT_BRACKET.split(text)):
        if bracket in "[{":
            depth += 1
            peak = max(peak, depth)
        elif depth:
            depth -= 1
    return peak


def _block_depth_bound(text: str) -> int:
    """An upper bound of block nesting: a block collection starts at or before the end of its
    line's run of indentation and indicators, and each column holds at most a mapping and a
    sequence (`key:` then `- item` at the same indentation)."""
    lead = max((len(m) for m in _BLOCK_LEAD.findall(text)), default=0)
    return 2 * (lead + 1) + 1


def _refuse_runaway_nesting(text: str) -> None:
    """RC009 before composing: libyaml's composer recurses once per level in C, so some tens of
    thousands of nested levels (brackets, or `- - - ...` in a few hundred kB) overflow the
    stack and crash.

    Only a text that could nest deep is scanned, event by event (libyaml's parser keeps no C
    stack per level), which is cheap next to composing; syntax errors are left to the
    composer, which locates them."""
    if _flow_depth_bound(text) + _block_depth_bound(text) <= MAX_DEPTH:
        return
    loader = _Loader(text)
    depth = 0
    try:
        while loader.check_event():
            event = loader.get_event()
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                if depth > MAX_DEPTH:
                    raise YamlReadError(
                        [
                            _problem(
                                event.start_mark, "RC009", f"nested deeper than {MAX_DEPTH} levels"
                            )
                        ]
                    )
                depth += 1
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                depth -= 1
    except yaml.YAMLError:
        return
    finally:
        loader.dispose()


def _compose(text: str) -> Node | None:
    try:
        loader = _Loader(text)  # the pure-Python reader checks every character here
    except yaml.reader.ReaderError as exc:  # pragma: no cover - only without libyaml
        raise YamlReadError([_reader_problem(text, exc)]) from None
    try:
        return loader.get_single_node()
    except yaml.reader.ReaderError as exc:
        raise YamlReadError([_reader_problem(text, exc)]) from None
    except yaml.composer.ComposerError as exc:
        if "single document" in f"{exc.context} {exc.problem}":
            raise YamlReadError(
                [
                    _problem(
                        exc.problem_mark,
                        "RC006",
                        "a second YAML document starts here; one file holds one document "
                        "(remove the '---' line or split the file)",
                    )
                ]
            ) from None
        if "undefined alias" in f"{exc.problem}":
            raise YamlReadError(
                [
                    _problem(
                        exc.problem_mark,
                        "RC005",
                        "YAML aliases (*name) are not supported, and this one names no anchor; "
                        "write the value out in full",
                    )
                ]
            ) from None
        raise YamlReadError([_problem(exc.problem_mark, "RC003", _yaml_message(exc))]) from None
    except yaml.MarkedYAMLError as exc:
        raise YamlReadError([_problem(exc.problem_mark, "RC003", _yaml_message(exc))]) from None
    except yaml.YAMLError as exc:
        raise YamlReadError([YamlProblem(1, 1, "RC003", f"YAML syntax error: {exc}")]) from None
    finally:
        loader.dispose()


def _yaml_message(exc: yaml.MarkedYAMLError) -> str:
    parts = [p for p in (exc.context, exc.problem) if p]
    text = "; ".join(parts) or "invalid YAML"
    return f"YAML syntax error: {text}"


class _Builder:
    """Turns a node tree into plain data, refusing aliases and duplicate keys."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.seen: set[int] = set()
        self.problems: list[YamlProblem] = []

    def build(self, node: Node, depth: int = 0, where: Any = None) -> Any:
        if id(node) in self.seen:
            # A node met twice is an alias: refuse before anything could be expanded.
            raise YamlReadError(
                [
                    _problem(
                        where or _first_alias_mark(self.text) or node.start_mark,
                        "RC005",
                        "YAML aliases (*name, <<: *name) are not supported; "
                        "write the value out in full",
                    )
                ]
            )
        self.seen.add(id(node))
        if depth > MAX_DEPTH:
            raise YamlReadError(
                [_problem(node.start_mark, "RC009", f"nested deeper than {MAX_DEPTH} levels")]
            )
        if isinstance(node, ScalarNode):
            return self.scalar(node)
        if isinstance(node, MappingNode):
            if node.tag != _MAP:
                self.problems.append(_problem(node.start_mark, "RC009", _tag_message(node)))
            result: dict[str, Any] = {}
            first_line: dict[str, int] = {}
            for key_node, value_node in node.value:
                if not isinstance(key_node, ScalarNode) or key_node.tag != _STR:
                    if key_node.tag == _MERGE:
                        # `<<: *name` is first of all an alias: refused as one, where it is.
                        self.build(value_node, depth + 1, key_node.start_mark)
                    self.problems.append(
                        _problem(key_node.start_mark, "RC009", _key_message(key_node))
                    )
                    continue
                key = str(key_node.value)
                if key in result:
                    self.problems.append(
                        _problem(
                            key_node.start_mark,
                            "RC004",
                            f"duplicate key '{key}' (first at line {first_line[key]}); "
                            "each key may appear once",
                        )
                    )
                    continue
                first_line[key] = key_node.start_mark.line + 1
                result[key] = self.build(value_node, depth + 1, key_node.start_mark)
            return result
        if isinstance(node, SequenceNode):
            if node.tag != _SEQ:
                self.problems.append(_problem(node.start_mark, "RC009", _tag_message(node)))
            return [self.build(item, depth + 1) for item in node.value]
        raise YamlReadError([_problem(node.start_mark, "RC009", "unsupported YAML node")])

    def scalar(self, node: ScalarNode) -> Any:
        tag = node.tag
        if tag == _STR:
            return node.value
        if tag not in _TAG_NAMES and tag != _TIMESTAMP:
            return self.refuse(node, _tag_message(node))
        if tag == _INT and len(node.value) > _MAX_NUMBER_CHARS:
            return self.refuse(node, _too_large(node))
        # An untagged value fits its tag by construction; one tagged explicitly (`!!float abc`)
        # may not, and then constructing it fails in one of these ways.
        try:
            value = self.construct(node)
        except (ValueError, KeyError, IndexError, TypeError, OverflowError):
            value = _UNFIT
        if value is _UNFIT:
            return self.refuse(
                node,
                f"{_snippet(node.value)} is not {_TAG_NAMES.get(tag, 'a date')}, as its tag "
                f"'{_short_tag(tag)}' says; drop the tag, or write a value of that type",
            )
        if tag == _INT and abs(value) > MAX_INT:
            return self.refuse(node, _too_large(node))
        if tag == _FLOAT and (math.isnan(value) or math.isinf(value)):
            return self.refuse(
                node, f"{_snippet(node.value)} cannot be represented in JSON; use a finite number"
            )
        return value

    @staticmethod
    def construct(node: ScalarNode) -> Any:
        if node.tag == _INT:
            return _scalars.construct_yaml_int(node)
        if node.tag == _FLOAT:
            return _scalars.construct_yaml_float(node)
        if node.tag == _BOOL:
            return _scalars.construct_yaml_bool(node)
        if not any(p.fullmatch(node.value) for p in _FITS[node.tag]):
            return _UNFIT
        # Dates stay text: launch requests are JSON.
        return None if node.tag == _NULL else node.value

    def refuse(self, node: Node, message: str) -> None:
        self.problems.append(_problem(node.start_mark, "RC009", message))


def _key_message(node: Node) -> str:
    if not isinstance(node, ScalarNode):
        return "a key must be a plain name, not a list or mapping"
    if node.tag == _MERGE:
        return "merge keys (<<) are not supported; write the keys out in full"
    read_as = _TAG_NAMES.get(node.tag, "a date" if node.tag == _TIMESTAMP else "not text")
    return (
        f"key {_snippet(node.value)} is read as {read_as}, and keys must be text; "
        f"quote it: '{node.value[:40]}': ..."
    )


def _too_large(node: ScalarNode) -> str:
    return (
        f"{_snippet(node.value)} is beyond the 64-bit integer range JSON readers share; "
        "quote it if it is text"
    )


def _snippet(value: str, limit: int = 40) -> str:
    """A value as it may appear in a message: quoted, and cut when long."""
    shown = value if len(value) <= limit else value[:limit] + "..."
    return repr(shown)


def _short_tag(tag: str) -> str:
    return "!!" + tag[len("tag:yaml.org,2002:") :] if tag.startswith("tag:yaml.org,2002:") else tag


def _first_alias_mark(text: str) -> Any:
    """Where the first alias (*name) is: composed, it is only its anchor's node met again.

    Read token by token, so even an alias bomb costs no more than its own text."""
    loader = _Loader(text)
    try:
        while loader.check_token():
            token = loader.get_token()
            if isinstance(token, yaml.AliasToken):
                return token.start_mark
    except yaml.YAMLError:
        pass
    finally:
        loader.dispose()
    return None


def _tag_message(node: Node) -> str:
    return (
        f"YAML tag '{_short_tag(node.tag)}' is not supported; "
        "use plain strings, numbers, lists, mappings"
    )


def parse_document(path: str, raw: bytes) -> YamlDocument:
    """Read one file's bytes as a top-level mapping, or raise YamlReadError with every problem."""
    if len(raw) > MAX_FILE_BYTES:
        raise YamlReadError(
            [
                YamlProblem(
                    1,
                    1,
                    "RC008",
                    f"file is {len(raw):,} bytes, over the limit of {MAX_FILE_BYTES:,}; "
                    "split it into smaller files",
                )
            ]
        )
    text = decode(raw)
    _refuse_odd_line_breaks(text)
    if "\t" in text:
        tabs = _tab_indents(text)
        if tabs:
            raise YamlReadError(tabs)
    try:
        _refuse_runaway_nesting(text)
        root = _compose(text)
    except YamlReadError as exc:
        raise YamlReadError([_within(p, text) for p in exc.problems]) from None
    if root is None or (
        isinstance(root, ScalarNode) and root.tag == _NULL and not root.value.strip()
    ):
        raise YamlReadError(
            [YamlProblem(1, 1, "RC007", "file is empty; expected a mapping of fields (key: value)")]
        )
    if not isinstance(root, MappingNode):
        found = "a list" if isinstance(root, SequenceNode) else "a single value"
        raise YamlReadError(
            [
                _problem(
                    root.start_mark,
                    "RC007",
                    f"expected a mapping of fields (key: value) at the top of the file, "
                    f"found {found}",
                )
            ]
        )
    builder = _Builder(text)
    data = builder.build(root)
    if builder.problems:
        raise YamlReadError(builder.problems)
    return YamlDocument(path=path, data=data, root=root)
