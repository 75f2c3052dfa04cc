"""A request's published size, worked out once per content, is always its payload's length."""

from __future__ import annotations

from robotconf.configurator.render import FleetRender, render_fleet
from robotconf.configurator.workspace import check
from robotconf.reconciler.builds import RequestSizes
from tests.support.agents import make_request
from tests.support.lab import ROOT


def test_sizes_are_exact_across_revisions_and_contents() -> None:
    sizes = RequestSizes()
    cases = [
        make_request(revision="a" * 40),
        make_request(revision="b" * 40),  # same content: served from the first
        make_request(revision="c" * 64),  # a SHA-256 repository's longer ids
        make_request(variant=3, revision="d" * 40),
        make_request(revision='odd "rev" \u00e9'),  # not a commit id: measured as it is
        make_request(revision=""),
    ]
    for request in cases:
        assert sizes.size(request) == len(request.payload()), request.revision
    sizes.keep_only([cases[3]])
    assert sizes.size(cases[3]) == len(cases[3].payload())
    assert list(sizes._without_revision) == [cases[3].digest]


def test_a_request_kept_from_an_earlier_commit_is_measured_as_it_is_published() -> None:
    # A fleet keeps unchanged robots' requests of an earlier commit (FleetRequests): each is
    # measured with the revision it will be published with.
    sizes = RequestSizes()
    fleet = _example_fleet()
    for request in list(fleet.requests.values())[:3]:
        for revision in ("a" * 40, "c" * 64, 'odd "rev" \u00e9', ""):
            stamped = request.with_revision(revision)
            assert sizes.size(request, revision) == len(stamped.payload()), revision
            assert sizes.size(stamped, request.revision) == len(request.payload())


def _example_fleet() -> FleetRender:
    checked = check(ROOT)
    assert checked.ok, checked.errors
    return render_fleet(checked.repo)
