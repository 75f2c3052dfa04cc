"""A fleet page's query, pure: label selector, verdict and id search read and bounded; the rows
they select, worst first, the first few shown and all counted."""

from __future__ import annotations

import pytest

from robotconf.readmodel.verdicts import Verdict
from robotconf.workstation.ui.model import MAX_QUERY, FleetQuery, QueryError, parse_query, visible
from tests.unit.ui.fleets import fleet, row


def test_a_query_is_read_as_status_reads_its_selector() -> None:
    query, other = parse_query("selector=ring%3Dcanary%2Csite%3Dsim&verdict=InSync&q=tb3&robot=x")
    assert query == FleetQuery((("ring", "canary"), ("site", "sim")), Verdict.IN_SYNC, "tb3")
    assert other == {"robot": "x"}
    repeated, _ = parse_query("selector=ring=canary&selector=site=sim&verdict=&q=")
    assert repeated == FleetQuery((("ring", "canary"), ("site", "sim")))
    assert parse_query("") == (FleetQuery(), {})


@pytest.mark.parametrize(
    "text",
    [
        "selector=ring",
        "selector=ring%3D%3Cscript%3E",
        "selector==x",
        "verdict=Fine",
        "q=%3Cscript%3E",
        "q=" + "a" * 65,
        "x=1&" * 40,
        "q=" + "a" * MAX_QUERY,
    ],
)
def test_a_malformed_or_oversized_query_is_refused_in_words(text: str) -> None:
    with pytest.raises(QueryError) as found:
        parse_query(text)
    assert str(found.value)


def test_the_query_round_trips_through_its_form_fields() -> None:
    query = FleetQuery((("ring", "canary"),), Verdict.DEGRADED, "tb")
    from urllib.parse import urlencode

    assert parse_query(urlencode(query.as_query()))[0] == query


def test_rows_are_selected_by_labels_verdict_and_id_and_counted_per_verdict() -> None:
    rows = [
        row("a-1", labels={"ring": "canary"}),
        row("a-2", Verdict.DEGRADED, labels={"ring": "canary"}),
        row("b-1", labels={"ring": "main"}),
        row("b-2", Verdict.OFFLINE),
    ]
    status = fleet(rows)
    canary = visible(status, FleetQuery((("ring", "canary"),)))
    assert [r.robot_id for r in canary.rows] == ["a-2", "a-1"]
    assert canary.counts == {"Degraded": 1, "InSync": 1} and canary.total == 4
    synced = visible(status, FleetQuery((("ring", "canary"),), Verdict.IN_SYNC))
    assert [r.robot_id for r in synced.rows] == ["a-1"]
    assert synced.counts == {"Degraded": 1, "InSync": 1}  # the verdict links stay
    search = visible(status, FleetQuery(search="b-"))
    assert [r.robot_id for r in search.rows] == ["b-2", "b-1"]


def test_only_the_first_rows_are_kept_and_all_are_counted() -> None:
    status = fleet([row(f"r{n:03d}") for n in range(50)])
    shown = visible(status, FleetQuery(), limit=10)
    assert len(shown.rows) == 10 and shown.selected == 50
