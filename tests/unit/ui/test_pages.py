"""The UI's pages, pure: escaping, no inline script or style, the browser test's DOM contract."""

from __future__ import annotations

import re
from html.parser import HTMLParser

from robotconf.contract.wire import AgentState, RolloutStatus
from robotconf.readmodel.verdicts import Verdict
from robotconf.workstation.ui.auth import ANONYMOUS, Identity
from robotconf.workstation.ui.model import FleetQuery, HistoryEntry
from robotconf.workstation.ui.pages import error_page, fleet_page
from robotconf.workstation.ui.robot_page import robot_page
from robotconf.workstation.ui.text import MAX_TEXT, esc
from tests.unit.ui.fleets import fleet, reconciler, refused, row, snapshot

OPERATOR = Identity(operator=True, csrf="c" * 32, via="cookie")


class Tags(HTMLParser):
    """Every start tag with its attributes, and the text inside each `data-diagnostics` li."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict[str, str | None]]] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))


def tags(page: str) -> list[tuple[str, dict[str, str | None]]]:
    parser = Tags()
    parser.feed(page)
    return parser.tags


def assert_no_inline_code(page: str) -> None:
    for tag, attrs in tags(page):
        assert tag != "style", "an inline <style>"
        if tag == "script":
            assert attrs.get("src") == "/static/ui.js", attrs
        assert "style" not in attrs, (tag, attrs)
        assert not [name for name in attrs if name.startswith("on")], (tag, attrs)
        for name in ("href", "src", "action"):
            assert not (attrs.get(name) or "").lower().startswith("javascript:"), attrs
    assert not re.search(r"<script(?![^>]*src=\"/static/ui.js\")", page)


def test_a_robot_named_script_is_text() -> None:
    hostile = "<script>alert(1)</script>"
    rows = [
        row(hostile, Verdict.DEGRADED, reason='"><img src=x onerror=alert(1)>', labels={"a": "<b>"})
    ]
    page = fleet_page(snapshot(fleet(rows)), FleetQuery(), ANONYMOUS)
    assert "<script>alert" not in page and "<img" not in page and "<b>" not in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert_no_inline_code(page)
    found = [attrs for tag, attrs in tags(page) if tag == "tr" and "data-robot" in attrs]
    assert found[0]["data-robot"] == hostile  # an attribute value, as text


def test_every_row_has_its_id_and_verdict_and_says_the_verdict_as_text() -> None:
    rows = [row("r1"), row("r2", Verdict.PROGRESSING), row("r3", Verdict.OFFLINE, online=False)]
    page = fleet_page(snapshot(fleet(rows)), FleetQuery(), ANONYMOUS)
    found = [a for tag, a in tags(page) if tag == "tr" and "data-robot" in a]
    assert [(a["data-robot"], a["data-verdict"]) for a in found] == [
        ("r3", "Offline"),
        ("r2", "Progressing"),
        ("r1", "InSync"),
    ]
    for robot_id, verdict in (("r3", "Offline"), ("r2", "Progressing"), ("r1", "InSync")):
        line = re.search(rf'<tr data-robot="{robot_id}".*?</tr>', page)
        assert line is not None and f">{verdict}<" in line.group()
    assert_no_inline_code(page)


def test_the_page_has_the_filter_form_and_the_reconciler_box() -> None:
    page = fleet_page(snapshot(fleet([row("r1")])), FleetQuery(), ANONYMOUS)
    forms = [a for tag, a in tags(page) if tag == "form" and "data-filter" in a]
    assert forms and forms[0]["method"] == "get"
    names = {a.get("name") for tag, a in tags(page) if tag in ("input", "select")}
    assert {"selector", "verdict", "q"} <= names
    assert 'data-reconciler-state="Ready"' in page
    assert "data-diagnostics" not in page


def test_a_refused_commit_shows_each_diagnostic_as_file_line_col_code_message() -> None:
    page = fleet_page(snapshot(fleet([row("r1")], refused())), FleetQuery(), ANONYMOUS)
    assert 'data-reconciler-state="Stalled"' in page
    listed = re.search(r"<ul data-diagnostics>(.*?)</ul>", page)
    assert listed is not None
    items = [re.sub(r"<[^>]+>", "", li) for li in re.findall(r"<li>(.*?)</li>", listed.group(1))]
    assert items == [
        "configs/fleet.yaml:3:5 RC101 no such scenario",
        "SourceUnavailable &lt;b&gt;not bold&lt;/b&gt;",
    ]


def test_a_huge_text_is_cut_and_control_characters_escaped() -> None:
    assert len(esc("x" * 100_000)) <= MAX_TEXT + 1
    assert esc("a\x1b[31mb\u202ec") == "a\\x1b[31mb\\u202ec"


def test_a_missing_or_stale_reconciler_and_a_lost_broker_are_said() -> None:
    stale = reconciler(heartbeat=1_000.0)
    page = fleet_page(snapshot(fleet([row("r1")], stale), connected=False), FleetQuery(), ANONYMOUS)
    assert 'data-banner="broker"' in page and 'data-banner="reconciler"' in page
    assert "heartbeat stale" in page
    calm = fleet_page(snapshot(fleet([row("r1")])), FleetQuery(), ANONYMOUS)
    assert "data-banner=" not in calm


def test_the_first_rows_are_shown_and_the_rest_counted() -> None:
    rows = [row(f"r{n:05d}") for n in range(600)]
    page = fleet_page(snapshot(fleet(rows)), FleetQuery(), ANONYMOUS)
    assert page.count("<tr data-robot=") == 500
    assert "100 more, narrow the filter" in page


def test_a_robot_page_has_its_sections_and_operator_controls_only_for_operators() -> None:
    r = row("tb3-01", Verdict.DEGRADED, state=AgentState.FAILED.value)
    snap = snapshot(fleet([r]))
    entry = HistoryEntry.of(r, 1_790_000_000.0)
    snap = snap.__class__(**{**snap.__dict__, "history": {"tb3-01": (entry,)}})
    viewer = robot_page(snap, "tb3-01", ANONYMOUS, None, None)
    operator = robot_page(snap, "tb3-01", OPERATOR, None, None)
    assert 'data-robot-page="tb3-01"' in viewer
    assert "<pre data-log-tail" in viewer and "<pre data-log-tail" in operator
    assert 'data-action="restart"' not in viewer
    assert '<a data-action="restart" href="/robots/tb3-01/restart">Restart tb3-01</a>' in operator
    assert "<table data-history>" in viewer and ">failed<" in viewer
    assert_no_inline_code(viewer)
    assert_no_inline_code(operator)


def test_an_error_page_escapes_what_it_quotes() -> None:
    page = error_page(400, "bad <id>", ANONYMOUS)
    assert "bad &lt;id&gt;" in page
    assert_no_inline_code(page)


def test_the_rollout_box_lists_the_wave_by_how_its_robots_fare_and_a_rollback() -> None:
    rollout = RolloutStatus(
        revision="c" * 40,
        stable_revision="d" * 40,
        state="RolledBack",
        wave=1,
        waves=3,
        wave_name="half",
        healthy=["r1"],
        failed=["r2"],
        pending=["<r3>"],
        offline=["r4"],
        counts={"healthy": 1, "failed": 1, "pending": 1, "offline": 1},
        message="too many failed",
    )
    rows = [row("r1", wave="half"), row("r5", Verdict.PROGRESSING, wave="half", state="deferred")]
    page = fleet_page(snapshot(fleet(rows, reconciler(rollout=rollout))), FleetQuery(), ANONYMOUS)
    box = re.search(r'<section data-box="rollout".*?</section>', page)
    assert box is not None
    text = box.group()
    assert 'data-rollout-state="RolledBack"' in text and "2 of 3 (half)" in text
    for group, robot in (
        ("healthy", "r1"),
        ("failed", "r2"),
        ("deferred", "r5"),
        ("offline", "r4"),
    ):
        found = re.search(rf'data-group="{group}"><h3>\w+: 1</h3><ul>(.*?)</ul>', text)
        assert found is not None and f">{robot}<" in found.group(1), group
    assert "&lt;r3&gt;" in text and "<r3>" not in text
    assert "data-rolled-back" in text and "d" * 12 in text


def fold_of(page: str, box: str) -> str | None:
    """The `data-fold` of a box's details, with ` open` when the page opens it."""
    found = re.search(rf'data-box="{box}"[^>]*><details data-fold="(\w+)"( open)?>', page)
    return None if found is None else found.group(1) + (found.group(2) or "")


def test_healthy_boxes_fold_to_one_line_and_trouble_opens_them() -> None:
    calm = fleet_page(snapshot(fleet([row("r1")])), FleetQuery(), ANONYMOUS)
    assert fold_of(calm, "reconciler") == "closed"
    summary = re.search(r'data-box="reconciler".*?<summary>(.*?)</summary>', calm)
    assert summary is not None and "Reconciler: Ready" in summary.group(1)
    assert 'class="rev"' in summary.group(1) and "data-short" in summary.group(1)
    stalled = fleet_page(snapshot(fleet([row("r1")], refused())), FleetQuery(), ANONYMOUS)
    assert fold_of(stalled, "reconciler") == "open open"
    stale = fleet_page(
        snapshot(fleet([row("r1")], reconciler(heartbeat=1_000.0))), FleetQuery(), ANONYMOUS
    )
    assert fold_of(stale, "reconciler") == "open open"

    def with_rollout(state: str, failed: int = 0) -> str:
        rollout = RolloutStatus(
            revision="c" * 40, state=state, waves=2, wave_name="all",  # type: ignore[arg-type]
            counts={"healthy": 3, "failed": failed},
        )  # fmt: skip
        status = reconciler(rollout=rollout)
        return fleet_page(snapshot(fleet([row("r1")], status)), FleetQuery(), ANONYMOUS)

    assert fold_of(with_rollout("Complete"), "rollout") == "closed"
    assert fold_of(with_rollout("Progressing"), "rollout") == "closed"
    assert "3 healthy, 0 failed" in with_rollout("Complete")
    for state in ("Paused", "Halted", "RolledBack"):
        assert fold_of(with_rollout(state), "rollout") == "open open", state
    assert fold_of(with_rollout("Progressing", failed=1), "rollout") == "open open"


def test_why_comes_after_the_verdict_and_digests_differ_from_revisions() -> None:
    r = row("r1", Verdict.DEGRADED, reason="brain exited with 1")
    page = fleet_page(snapshot(fleet([r])), FleetQuery(), ANONYMOUS)
    heads = re.findall(r'<th scope="col">(\w+)</th>', page)
    assert heads[:3] == ["Robot", "Verdict", "Why"]
    line = re.search(r'<tr data-robot="r1".*?</tr>', page)
    assert line is not None
    cells = re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", line.group())
    assert "Degraded" in cells[1] and cells[2] == "brain exited with 1"
    digest = f'<code class="digest" title="sha256:{"1" * 64}">sha256:{"1" * 8}</code>'
    assert digest in line.group()
    # A revision is a link, 12 hex digits, the commit in its title.
    assert f'<a class="rev" href="/revisions/{"a" * 40}" title="commit {"a" * 40}"><code>' in page
    snap = snapshot(fleet([r]))
    entry = HistoryEntry.of(r, 1_790_000_000.0)
    snap = snap.__class__(**{**snap.__dict__, "history": {"r1": (entry,)}})
    robot = robot_page(snap, "r1", ANONYMOUS, None, None)
    assert '<p class="why">brain exited with 1</p>' in robot
    assert re.search(r"<th[^>]*>When</th><th[^>]*>Verdict</th><th[^>]*>Why</th>", robot)
    assert '<td class="why">brain exited with 1</td>' in robot
    assert f'title="sha256:{"2" * 64}">sha256:{"2" * 8}</code>' in robot  # what it reported
