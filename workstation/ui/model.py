"""What the fleet pages show, pure: one state of the fleet as the UI holds it (`Snapshot`), a
page's query (label selector, verdict, id search) read from a request, and the rows it selects."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple
from urllib.parse import parse_qsl

from robotconf.configurator.waves import matches
from robotconf.contract.models import is_robot_id
from robotconf.readmodel.verdicts import WORST_FIRST, FleetStatus, RobotRow, Verdict

MAX_QUERY = 2048  # characters of a query string: a longer one is refused (414)
MAX_FIELDS = 32  # query fields
MAX_SELECTOR = 16  # KEY=VALUE pairs in one selector
MAX_SEARCH = 64  # characters of the id search
ROWS_SHOWN = 500  # rows of the fleet page: the worst first, the rest counted
HISTORY = 20  # status changes kept per robot


class QueryError(ValueError):
    """A query the pages cannot answer; its words are the error page's, `code` its status."""

    def __init__(self, message: str, code: int = 400) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class FleetQuery:
    """Which robots a fleet page (and its event stream) shows."""

    selector: tuple[tuple[str, str], ...] = ()  # every KEY=VALUE, as `status -l`
    verdict: Verdict | None = None
    search: str = ""  # a part of the robot id

    def wants(self, row: RobotRow) -> bool:
        """The verdict filter aside: counts per verdict are of the rows this keeps."""
        if self.search and self.search not in row.robot_id:
            return False
        return not self.selector or matches(row.labels, dict(self.selector))

    def as_query(self) -> list[tuple[str, str]]:
        """The query string's fields, as the filter form sends them."""
        fields = [("selector", ",".join(f"{k}={v}" for k, v in self.selector))]
        fields += [("verdict", self.verdict.value if self.verdict else ""), ("q", self.search)]
        return [(name, value) for name, value in fields if value]


def parse_query(query: str) -> tuple[FleetQuery, dict[str, str]]:
    """The fleet query of a URL's query string, and its other single fields (`robot`, `v`);
    QueryError when it is too long or a field is malformed."""
    if len(query) > MAX_QUERY:
        raise QueryError(
            f"the query is {len(query):,} characters, over the limit of {MAX_QUERY:,}", 414
        )
    try:
        fields = parse_qsl(query, keep_blank_values=True, max_num_fields=MAX_FIELDS)
    except ValueError:
        raise QueryError(f"the query has more than {MAX_FIELDS} fields") from None
    selector: dict[str, str] = {}
    verdict: Verdict | None = None
    search = ""
    other: dict[str, str] = {}
    for name, value in fields:
        if name == "selector":
            selector.update(parse_selector(value))
        elif name == "verdict":
            verdict = parse_verdict(value)
        elif name == "q":
            search = parse_search(value)
        else:
            other[name] = value
    if len(selector) > MAX_SELECTOR:
        raise QueryError(f"a selector has at most {MAX_SELECTOR} labels")
    return FleetQuery(tuple(sorted(selector.items())), verdict, search), other


def parse_selector(text: str) -> dict[str, str]:
    """`key=value` pairs, comma-separated (one form field) or one per field; blank: none."""
    found: dict[str, str] = {}
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        key, equals, value = part.partition("=")
        key, value = key.strip(), value.strip()
        if not equals or not is_robot_id(key) or not is_robot_id(value):
            raise QueryError(
                "a selector is KEY=VALUE (several: comma-separated), with a label key and "
                "value written like robot ids, e.g. ring=canary"
            )
        found[key] = value
    return found


def parse_verdict(text: str) -> Verdict | None:
    if not text:
        return None
    try:
        return Verdict(text)
    except ValueError:
        names = ", ".join(v.value for v in Verdict)
        raise QueryError(f"a verdict is one of {names}") from None


def parse_search(text: str) -> str:
    text = text.strip()
    if len(text) > MAX_SEARCH:
        raise QueryError(f"the id search is at most {MAX_SEARCH} characters")
    if (text and not all(c.isalnum() or c in "_.-" for c in text)) or not text.isascii():
        raise QueryError("the id search is a part of a robot id: letters, digits, _ . -")
    return text


def rank(row: RobotRow) -> str:
    """The row's place worst first, as text that sorts the same in a browser: its verdict,
    drifted first among its verdict's, then its id (verdicts.build_rows' order)."""
    return f"{WORST_FIRST.index(row.verdict)}{0 if row.drift.drifted else 1}{row.robot_id}"


@dataclass(frozen=True)
class Visible:
    """A fleet page's rows: the first `ROWS_SHOWN` of those its query selects, and counts."""

    rows: list[RobotRow]
    selected: int  # rows the query selects, all of them
    counts: dict[str, int]  # per verdict, of the rows the query selects but for its verdict
    total: int  # robots in the fleet


def visible(fleet: FleetStatus, query: FleetQuery, limit: int = ROWS_SHOWN) -> Visible:
    """`fleet.rows` are worst first already: the page's rows are the first that match."""
    rows: list[RobotRow] = []
    counts = {v.value: 0 for v in Verdict}
    selected = 0
    for row in fleet.rows:
        if not query.wants(row):
            continue
        counts[row.verdict.value] += 1
        if query.verdict is not None and row.verdict is not query.verdict:
            continue
        selected += 1
        if len(rows) < limit:
            rows.append(row)
    return Visible(rows, selected, {k: n for k, n in counts.items() if n}, len(fleet.rows))


class HistoryEntry(NamedTuple):
    """One change of a robot's status, as the UI saw it arrive (a tuple: 10,000 of them are
    made at the first read, several times faster than frozen dataclasses)."""

    at: float
    verdict: str
    state: str
    reported: str | None  # the digest it reported
    restarts: int
    reloads: int
    reason: str

    @classmethod
    def of(cls, row: RobotRow, at: float) -> HistoryEntry:
        return cls(
            at, row.verdict.value, row.state, row.reported, row.restarts, row.reloads, row.reason
        )

    def same(self, other: HistoryEntry) -> bool:
        """The same status (arrived at another time)."""
        return (self.verdict, self.state, self.reported, self.restarts, self.reloads) == (
            other.verdict,
            other.state,
            other.reported,
            other.restarts,
            other.reloads,
        )


@dataclass(frozen=True)
class Snapshot:
    """One state of the fleet as the pages show it. `fleet` None: not read yet."""

    version: int
    fleet: FleetStatus | None
    broker: str  # the broker's URL, as people read it (no password)
    connected: bool  # the broker's retained topics are read and up to date
    broker_error: str | None = None  # why not, when it is not
    at: float = 0.0  # when this state was made (unix time): ages are counted from it
    history: Mapping[str, tuple[HistoryEntry, ...]] = field(default_factory=dict)
    by_id: Mapping[str, RobotRow] = field(default_factory=dict)

    def row(self, robot_id: str) -> RobotRow | None:
        return self.by_id.get(robot_id)
