"""Strict YAML reading that remembers where every key and value came from.

Refuses what would hide a mistake or exhaust the process: duplicate keys, aliases, tabs in
indentation, several documents, non-UTF-8 bytes, odd line breaks, oversized or deep files.
"""

from __future__ import annotations

import codecs
import math
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from functools import lru_cache
from itertools import islice
from typing import Any

import yaml
from yaml.constructor import SafeConstructor
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from robotconf.contract.codes import require
from robotconf.contract.textsafe import printable

try:  # the C parser is several times faster; fall back where libyaml is missing
    from yaml import CSafeLoader as _Loader
except ImportError:  # pragma: no cover - depends on the PyYAML build
    from yaml import SafeLoader as _Loader  # type: ignore[assignment]
_LIBYAML = _Loader.__name__.startswith("C")

MAX_FILE_BYTES = 8 * 1024 * 1024
# Composed and built, a YAML node takes some hundreds of bytes and a few microseconds: at
# most about 150 MB and 1.5 s a file. A 10,000-robot fleet.yaml is some 70,000 events.
MAX_EVENTS = 200_000
# A file's problems past this many are not listed (a file of tabs, or of one duplicate key,
# would list every line).
MAX_PROBLEMS = 100
MAX_DEPTH = 64
_TOO_DEEP = f"nested deeper than {MAX_DEPTH} levels"
_DEPTH_STEP: dict[type[yaml.Event], int] = {
    yaml.MappingStartEvent: 1,
    yaml.SequenceStartEvent: 1,
    yaml.MappingEndEvent: -1,
    yaml.SequenceEndEvent: -1,
}
# libyaml's composer takes some 320 bytes of C stack a level (8 MiB overflow at ~25,000):
# a text with at most _SAFE_BRACKETS opening brackets and no run of indentation and block
# indicators as long as _LONG_LEAD nests under 1,000 levels, safe on any thread.
_SAFE_BRACKETS = 500
# JSON readers differ beyond 64-bit integers; longer digit strings are refused before any
# conversion (Python refuses over 4,300 digits, and base 60 is quadratic).
MAX_INT = 2**63 - 1
_MAX_NUMBER_CHARS = 100
_NON_FINITE = re.compile(r"[-+]?\.(?:inf|Inf|INF|nan|NaN|NAN)")
# What opens block collections at the start of a line: indentation and the indicators - ? :
# (a run of 247 nests at most 2 * 247 + 3 levels, with _SAFE_BRACKETS under 1,000).
_LONG_LEAD = re.compile(r"^[ ?:-]{248,}", re.MULTILINE)
_TAB_INDENT = re.compile(r"^ *\t", re.MULTILINE)
# YAML 1.1 breaks lines here too, editors and git do not: a reported line would be wrong.
# A byte order mark past the start (files joined together) is invisible, and YAML takes it
# for the start of a stream.
_ODD_CHARS = re.compile("\r(?!\n)|[\x85\u2028\u2029\ufeff]")
_BREAKS_LINES = (
    " breaks the line for YAML but not for editors or git; end lines with a line feed (\\n), "
    "or write the character as an escape in a double-quoted string"
)
_ODD_CHAR_MESSAGES = {
    "\r": "a carriage return not followed by a line feed (old Mac line end)" + _BREAKS_LINES,
    "\x85": "NEXT LINE (U+0085)" + _BREAKS_LINES,
    "\u2028": "LINE SEPARATOR (U+2028)" + _BREAKS_LINES,
    "\u2029": "PARAGRAPH SEPARATOR (U+2029)" + _BREAKS_LINES,
    "\ufeff": "byte order mark (U+FEFF) inside the file, an invisible character (files joined "
    "together?); remove it, or write \\ufeff in a double-quoted string",
}

_STANDARD = "tag:yaml.org,2002:"
_STR = "tag:yaml.org,2002:str"
_INT = "tag:yaml.org,2002:int"
_FLOAT = "tag:yaml.org,2002:float"
_BOOL = "tag:yaml.org,2002:bool"
_NULL = "tag:yaml.org,2002:null"
_TIMESTAMP = "tag:yaml.org,2002:timestamp"
_MERGE = "tag:yaml.org,2002:merge"
_MAP = "tag:yaml.org,2002:map"
_SEQ = "tag:yaml.org,2002:seq"
_KNOWN_TAGS = {_STR, _INT, _FLOAT, _BOOL, _NULL, _TIMESTAMP, _MAP, _SEQ}

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

    def __post_init__(self) -> None:
        require(self.code)


class YamlReadError(Exception):
    def __init__(self, problems: list[YamlProblem]) -> None:
        super().__init__(problems[0].message)
        self.problems = problems


class YamlDocument:
    """A parsed file: its data and the node tree that locates every key and value in it.

    A long-lived holder (the reconciler's build cache) may `release` the tree and the data once
    the file is typed: a tree takes some hundred times the file's size. Both come back from the
    file's bytes, parsed again the same way, when a position is asked for."""

    __slots__ = ("_data", "_index", "_root", "path", "raw")

    def __init__(self, path: str, data: dict[str, Any], root: MappingNode, raw: bytes) -> None:
        self.path = path
        self.raw = raw
        self._data: dict[str, Any] | None = data
        self._root: MappingNode | None = root
        self._index: dict[int, dict[str, tuple[Node, Node]]] = {}

    @property
    def data(self) -> dict[str, Any]:
        if self._data is None:
            self._restore()
        assert self._data is not None
        return self._data

    @property
    def root(self) -> MappingNode:
        if self._root is None:
            self._restore()
        assert self._root is not None
        return self._root

    def release(self) -> None:
        """Drops the node tree and the data until they are asked for again."""
        self._data = self._root = None
        self._index = {}

    def _restore(self) -> None:
        again = parse_document(self.path, self.raw)  # parsed once already: it parses again
        self._data, self._root = again._data, again._root

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


def _tab_indents(text: str) -> Iterator[YamlProblem]:
    line, counted = 1, 0
    for match in _TAB_INDENT.finditer(text):
        tab = match.end() - 1
        line += text.count("\n", counted, tab)
        counted = tab
        yield YamlProblem(
            line,
            tab - match.start() + 1,
            "RC002",
            "tab character in indentation; YAML indents with spaces only",
        )


def _refuse_odd_characters(text: str) -> None:
    """RC003 for line breaks only YAML sees (after one, YAML's line numbers and everyone
    else's would differ, so no position reported past it could be trusted) and for a byte
    order mark past the start."""
    problems = []
    for match in _ODD_CHARS.finditer(text):
        offset = match.start()
        line = text.count("\n", 0, offset) + 1
        col = offset - (text.rfind("\n", 0, offset) + 1) + 1
        problems.append(YamlProblem(line, col, "RC003", _ODD_CHAR_MESSAGES[match.group()]))
        if len(problems) == 10:
            break
    if problems:
        raise YamlReadError(problems)


def _reader_problem(text: str, exc: yaml.reader.ReaderError) -> YamlProblem:
    """A character YAML refuses (control characters): located, in one line."""
    raw = text.encode("utf-8")
    offset = exc.position
    if not _LIBYAML:  # libyaml counts bytes, pure Python characters
        offset = len(text[:offset].encode("utf-8"))
    line, col = _position_of_byte(raw, offset)
    char = exc.character if isinstance(exc.character, int) else ord(exc.character)
    return YamlProblem(
        line,
        col,
        "RC003",
        f"YAML syntax error: {exc.reason} (character #x{char:04x})",
    )


def _may_nest_deep(text: str) -> bool:
    """Whether the text could nest beyond some 1,000 levels, where libyaml's composer nears
    the end of a small thread's stack.

    Flow nesting is at most the count of opening brackets, quoted or not (closing ones cannot
    lower it: one in a quoted string or a comment closes nothing). A block collection starts
    at or before the end of its line's run of indentation and indicators, and each column
    holds at most a mapping and a sequence: a run of n characters nests 2n + 3 levels."""
    if text.count("[") + text.count("{") > _SAFE_BRACKETS:
        return True
    return _LONG_LEAD.search(text) is not None


def _compose_within_bounds(text: str) -> Node | None:
    """Compose only what cannot crash the process or take it over.

    libyaml's composer recurses in C once per level (tens of thousands of levels, brackets or
    `- - - ...` in a few hundred kB, overflowed the stack) and takes time quadratic in flow
    nesting, so a text that may nest deep is composed only once its events show nesting
    within MAX_DEPTH (the builder refuses what is deeper). Every node costs some hundreds of
    bytes and microseconds (8 MiB of `[],` took 1.4 GB and 27 s), so a text that may hold
    more than MAX_EVENTS is composed only once they are counted."""
    if not _LIBYAML or _may_nest_deep(text):
        _scan_events(text)
    elif len(text) > MAX_EVENTS:  # each event takes at least a character
        _count_events(text)
    return _compose(text)


def _scan_events(text: str, loader_class: Any = _Loader) -> None:
    """RC009 for nesting deeper than MAX_DEPTH, located as the builder would, and RC008 for
    more than MAX_EVENTS, from libyaml's events (its parser keeps no C stack per level).
    Syntax errors are left to the composer, which locates them."""
    loader = loader_class(text)
    depth = events = 0
    try:
        while (event := loader.get_event()) is not None:
            events += 1
            if events > MAX_EVENTS:
                raise YamlReadError([_too_many_events()])
            step = _DEPTH_STEP.get(type(event), 0)
            if step > 0 and depth > MAX_DEPTH:
                raise YamlReadError([_problem(event.start_mark, "RC009", _TOO_DEEP)])
            depth += step
    except yaml.MarkedYAMLError as exc:
        if loader_class is _Loader and _LIBYAML and "maximum nesting depth" in str(exc.problem):
            # libyaml 0.2.6 refuses 1,000 levels of flow nesting while scanning ahead, before
            # the events that reach MAX_DEPTH: the pure-Python parser (no such limit, no
            # recursion) finds where they do, in the text up to libyaml's refusal.
            end = exc.problem_mark.line if exc.problem_mark is not None else 0
            _scan_events("\n".join(text.split("\n", end + 1)[: end + 1]), yaml.SafeLoader)
        return
    except yaml.YAMLError:
        return
    finally:
        loader.dispose()


def _count_events(text: str) -> None:
    """RC008 for more than MAX_EVENTS, counted in C; syntax errors are left to the composer."""
    loader = _Loader(text)
    try:
        events = loader.raw_parse()
    except yaml.YAMLError:
        return
    finally:
        loader.dispose()
    if events > MAX_EVENTS:
        raise YamlReadError([_too_many_events()])


def _too_many_events() -> YamlProblem:
    return YamlProblem(
        1,
        1,
        "RC008",
        f"file holds too much to read: over {MAX_EVENTS:,} YAML nodes (a key or a value "
        "counts one, a list or a mapping two); split it into smaller files",
    )


_RESOLVER = yaml.resolver.Resolver()


@lru_cache(maxsize=4096)
def _resolve_plain(value: str) -> str:
    return str(_RESOLVER.resolve(ScalarNode, value, (True, False)))  # type: ignore[no-untyped-call]


class _ComposingLoader(_Loader):
    """The safe loader, resolving each distinct short plain scalar once, and skipping the
    bookkeeping of path resolvers (none is registered): resolving was a fifth of the time to
    validate a repository."""

    def descend_resolver(self, current_node: Any, current_index: Any) -> None:
        return None

    def ascend_resolver(self) -> None:
        return None

    def resolve(self, kind: type[Node], value: Any, implicit: tuple[bool, bool]) -> str:
        if kind is ScalarNode and implicit[0] and len(value) <= 64:
            return _resolve_plain(value)
        return str(super().resolve(kind, value, implicit))  # type: ignore[no-untyped-call]


def _compose(text: str) -> Node | None:
    try:
        loader = _ComposingLoader(text)  # the pure-Python reader checks every character here
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
        if "duplicate anchor" in f"{exc.context}":
            first = exc.context_mark.line + 1 if exc.context_mark else "?"
            raise YamlReadError(
                [
                    _problem(
                        exc.problem_mark,
                        "RC005",
                        f"anchor (&name) defined twice (first at line {first}); anchors serve "
                        "only aliases, which are not supported: remove it",
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
            raise YamlReadError([_problem(node.start_mark, "RC009", _TOO_DEEP)])
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
                            f"duplicate key {_snippet(key)} (first at line {first_line[key]}); "
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
        except OverflowError:  # a base-60 float past float's range
            return self.refuse(node, _too_large(node))
        except (ValueError, KeyError, IndexError, TypeError):
            value = _UNFIT
        if value is _UNFIT:
            return self.refuse(
                node,
                f"{_snippet(node.value)} is not {_TAG_NAMES.get(tag, 'a date')}, as its tag "
                f"{_tag_name(tag)} says; drop the tag, or write a value of that type",
            )
        if tag == _INT and abs(value) > MAX_INT:
            return self.refuse(node, _too_large(node))
        if tag == _FLOAT and not math.isfinite(value):
            if not _NON_FINITE.fullmatch(node.value):  # digits past float's range
                return self.refuse(node, _too_large(node))
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
    key = _snippet(node.value)
    if node.tag not in _TAG_NAMES and node.tag != _TIMESTAMP:
        return f"key {key} has the tag {_tag_name(node.tag)}; keys must be text: drop the tag"
    read_as = _TAG_NAMES.get(node.tag, "a date")
    return f"key {key} is read as {read_as}, and keys must be text; quote it: {key}: ..."


def _too_large(node: ScalarNode) -> str:
    if node.tag == _FLOAT:
        return f"{_snippet(node.value)} is beyond the range of a number (about 1.8e308)"
    return (
        f"{_snippet(node.value)} is beyond the 64-bit integer range JSON readers share; "
        "quote it if it is text"
    )


def _snippet(value: str, limit: int = 40) -> str:
    """A value as it may appear in a message: quoted, and cut when long."""
    shown = value if len(value) <= limit else value[:limit] + "..."
    return repr(shown)


def _tag_name(tag: str) -> str:
    """A tag as written (`!!int` for a standard one), quoted and cut like any snippet."""
    short = "!!" + tag[len(_STANDARD) :] if tag.startswith(_STANDARD) else tag
    return _snippet(short)


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
    if node.tag in _KNOWN_TAGS:  # a standard tag on the wrong kind of node (`!!str {a: 1}`)
        kinds: dict[type[Node], str] = {MappingNode: "a mapping", SequenceNode: "a list"}
        kind = kinds.get(type(node), "one value")
        return f"YAML tag {_tag_name(node.tag)} does not fit {kind}; drop the tag"
    return (
        f"YAML tag {_tag_name(node.tag)} is not supported; "
        "use plain strings, numbers, lists, mappings"
    )


def _capped(problems: Iterable[YamlProblem]) -> list[YamlProblem]:
    """The first MAX_PROBLEMS, the last of them saying that there are more."""
    found = iter(problems)
    listed = list(islice(found, MAX_PROBLEMS))
    if next(found, None) is not None:
        last = listed[-1]
        note = f"{last.message} (further problems in this file are not listed)"
        listed[-1] = YamlProblem(last.line, last.col, last.code, note)
    return listed


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
    _refuse_odd_characters(text)
    if "\t" in text:
        tabs = _capped(_tab_indents(text))
        if tabs:
            raise YamlReadError(tabs)
    try:
        root = _compose_within_bounds(text)
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
        raise YamlReadError(_capped(builder.problems))
    return YamlDocument(path, data, root, raw)


# ------------------------------------------------------------------ writing


class _IndentedDumper(yaml.SafeDumper):
    """PyYAML's safe dumper, with a block list indented under its key, as people write it."""

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        super().increase_indent(flow, False)


def document_text(header: Iterable[str], body: dict[str, Any], *, flow_leaves: bool = False) -> str:
    """A YAML file written by the emitter, never by formatting strings: `header` as comment
    lines (each line of it escaped: no line break or escape sequence leaves its comment), then
    `body`. The emitter quotes what must be quoted (`yes`, `1.0`, `a: b`) and escapes what is
    not ASCII, so every value reads back as the same text; `flow_leaves` writes a list or map
    of scalars on one line (`[a, b]`)."""
    lines = [f"# {printable(line)}" for text in header for line in text.splitlines() or [""]]
    dumped = yaml.dump(
        body,
        Dumper=_IndentedDumper,
        sort_keys=False,
        default_flow_style=None if flow_leaves else False,
        allow_unicode=False,
        width=100,
    )
    return "".join(line + "\n" for line in lines) + dumped
