"""A request's published size, worked out once per content, is always its payload's length."""

from __future__ import annotations

from reconciler.controller import RequestSizes
from tests.support.agents import make_request


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
