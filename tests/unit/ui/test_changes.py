"""What one open page is sent, pure: only the rows that changed for it (with their rank), the
ids that left it, and the boxes whose HTML changed; a reset when it cannot be brought up to date."""

from __future__ import annotations

import json
from dataclasses import replace

from robotconf.readmodel.verdicts import Verdict
from robotconf.workstation.ui.changes import Shown, Views, change, changed_rows, first
from robotconf.workstation.ui.model import FleetQuery
from tests.unit.ui.fleets import fleet, refused, row, snapshot


def message(event: bytes | None) -> dict[str, object]:
    assert event is not None
    lines = event.decode().split("\n")
    assert lines[1] == "event: fleet" and event.endswith(b"\n\n")
    data = [line for line in lines if line.startswith("data: ")]
    assert len(data) == 1  # one line of JSON: a robot's text cannot end the event early
    parsed: dict[str, object] = json.loads(data[0][6:])
    return parsed


def test_a_page_made_from_the_current_state_gets_no_first_event_and_an_older_one_a_reset() -> None:
    snap = snapshot(fleet([row("r1"), row("r2")]), version=7)
    assert first(snap, Shown(FleetQuery()), 7) is None
    reset = message(first(snap, Shown(FleetQuery()), 6))
    assert reset["reset"] is True and reset["v"] == 7
    assert [r[0] for r in reset["rows"]] == ["r1", "r2"]  # type: ignore[attr-defined]
    assert set(reset["boxes"]) == {"banner", "reconciler", "rollout", "summary", "rates"}  # type: ignore[arg-type]


def test_one_robot_changing_sends_its_row_alone_with_its_new_rank() -> None:
    before = snapshot(fleet([row(f"r{n}") for n in range(100)]), version=1)
    shown = Shown(FleetQuery())
    first(before, shown, 1)
    rows = [row(f"r{n}", Verdict.PROGRESSING if n == 42 else Verdict.IN_SYNC) for n in range(100)]
    after = snapshot(fleet(rows), version=2)
    sent = message(change(after, shown, changed_rows(before, after)))
    assert sent["reset"] is False and sent["removed"] == []
    assert [(r[0], r[1]) for r in sent["rows"]] == [("r42", "31r42")]  # type: ignore[attr-defined]
    assert 'data-verdict="Progressing"' in sent["rows"][0][2]  # type: ignore[index]
    assert set(sent["boxes"]) == {"summary"}  # type: ignore[arg-type]  # its counts changed
    assert change(after, shown, set()) is None  # nothing new since


def test_a_robot_leaving_a_filtered_page_is_removed_and_one_entering_sent() -> None:
    query = FleetQuery(verdict=Verdict.PROGRESSING)
    before = snapshot(fleet([row("r1", Verdict.PROGRESSING), row("r2")]), version=1)
    shown = Shown(query)
    first(before, shown, 1)
    after = snapshot(fleet([row("r1"), row("r2", Verdict.PROGRESSING)]), version=2)
    sent = message(change(after, shown, changed_rows(before, after)))
    assert sent["removed"] == ["r1"]
    assert [r[0] for r in sent["rows"]] == ["r2"]  # type: ignore[attr-defined]


def test_a_change_off_the_page_sends_nothing_and_a_refused_commit_sends_the_reconciler() -> None:
    query = FleetQuery(search="a")
    before = snapshot(fleet([row("a1"), row("b1")]), version=1)
    shown = Shown(query)
    first(before, shown, 1)
    after = snapshot(fleet([row("a1"), row("b1", Verdict.DEGRADED)]), version=2)
    assert change(after, shown, changed_rows(before, after)) is None
    refusing = snapshot(fleet([row("a1"), row("b1", Verdict.DEGRADED)], refused()), version=3)
    sent = message(change(refusing, shown, set()))
    assert sent["rows"] == [] and "data-diagnostics" in sent["boxes"]["reconciler"]  # type: ignore[index]


def test_a_robot_page_is_sent_its_box_when_it_changes() -> None:
    before = snapshot(fleet([row("r1"), row("r2")]), version=1)
    shown = Shown(FleetQuery(), robot="r1")
    first(before, shown, 1)
    other = snapshot(fleet([row("r1"), row("r2", Verdict.DEGRADED)]), version=2)
    assert change(other, shown, {"r2"}) is None
    mine = snapshot(fleet([row("r1", restarts=3), row("r2", Verdict.DEGRADED)]), version=3)
    sent = message(change(mine, shown, {"r1"}))
    assert set(sent["boxes"]) == {"robot"} and sent["rows"] == []  # type: ignore[arg-type]


def test_changed_rows_are_those_that_differ_or_left() -> None:
    before = snapshot(fleet([row("r1"), row("r2"), row("r3")]))
    after = snapshot(fleet([row("r1"), replace(row("r2"), restarts=1)]))
    assert changed_rows(before, after) == {"r2", "r3"}
    assert changed_rows(None, after) == {"r1", "r2"}


def test_pages_of_one_query_share_one_scan_and_get_the_same_event() -> None:
    before = snapshot(fleet([row(f"r{n}") for n in range(50)]), version=1)
    pages = [Shown(FleetQuery()) for _ in range(3)] + [Shown(FleetQuery(search="r1"))]
    for shown in pages:
        first(before, shown, 1)
    after = snapshot(fleet([row(f"r{n}", restarts=int(n == 10)) for n in range(50)]), version=2)
    views = Views(after)
    sent = [change(after, shown, {"r10"}, views) for shown in pages]
    assert sent[0] == sent[1] == sent[2] == sent[3]  # r10 is on every page
    assert views.seen(pages[0]) is views.seen(pages[1]) is not views.seen(pages[3])
