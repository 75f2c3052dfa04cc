"""Retry or terminal is data per reason (reconciler.decide.HANDLING), as Flux's reasons are."""

from __future__ import annotations

import pytest

from robotconf.reconciler.decide import HANDLING, Reason, Retry, retry_of, state_of


def test_every_reason_is_handled_and_says_something() -> None:
    assert set(HANDLING) == set(Reason)
    assert all(h.says.strip() for h in HANDLING.values())


@pytest.mark.parametrize(
    ("reason", "retry"),
    [
        (Reason.APPLIED, Retry.NONE),
        (Reason.PROGRESSING, Retry.NONE),
        (Reason.OFFLINE, Retry.NONE),
        (Reason.BROKER_UNAVAILABLE, Retry.BACKOFF),
        (Reason.SOURCE_UNAVAILABLE, Retry.RESYNC),
        (Reason.INTERNAL_ERROR, Retry.RESYNC),
        (Reason.BUILD_FAILED, Retry.TERMINAL),
        (Reason.EMPTY_FLEET_REFUSED, Retry.TERMINAL),
        (Reason.ROLLOUT_PAUSED, Retry.TERMINAL),
        (Reason.ROLLOUT_HALTED, Retry.TERMINAL),
        (Reason.ROLLED_BACK, Retry.TERMINAL),
    ],
)
def test_each_reason_is_retried_or_terminal_as_the_table_says(reason: Reason, retry: Retry) -> None:
    assert retry_of(reason) is retry


def test_a_stalled_reason_is_never_treated_as_nothing_failed() -> None:
    """A step that stalls is retried one way or another, or waits for a commit or an
    operator: never `none`, which is for steps that did what they were asked."""
    for reason in Reason:
        if state_of(reason) == "Stalled":
            assert retry_of(reason) is not Retry.NONE, reason


def test_only_what_may_pass_by_itself_backs_off() -> None:
    """Backoff is for faults outside the commit that a sooner look may find gone: the broker.
    A source or a build is mended by a fetch, a moved branch, or a new commit."""
    assert [r for r in Reason if retry_of(r) is Retry.BACKOFF] == [Reason.BROKER_UNAVAILABLE]
