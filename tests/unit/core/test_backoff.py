"""The one exponential backoff: doubling from the first delay, capped, restarted by reset()."""

from __future__ import annotations

import pytest

from robotconf.agent.supervisor import Policy
from robotconf.contract.backoff import Backoff, exponential_delay


def test_delays_double_up_to_the_cap() -> None:
    assert [exponential_delay(n, 1.0, 30.0) for n in range(7)] == [1, 2, 4, 8, 16, 30, 30]
    assert [exponential_delay(n, 0.25, 1.0) for n in range(4)] == [0.25, 0.5, 1.0, 1.0]


def test_a_very_long_run_stays_at_the_cap() -> None:
    # max_restarts has no upper bound: 2 ** 5000 must not overflow.
    assert exponential_delay(5000, 1.0, 60.0) == 60.0
    assert exponential_delay(10**9, 1e300, 1e308) == 1e308


def test_negative_attempts_are_a_bug() -> None:
    with pytest.raises(ValueError):
        exponential_delay(-1, 1.0, 2.0)


def test_backoff_counts_a_run_and_reset_starts_a_new_one() -> None:
    backoff = Backoff(1.0, 5.0)
    assert [backoff.next() for _ in range(5)] == [1.0, 2.0, 4.0, 5.0, 5.0]
    backoff.reset()
    assert backoff.next() == 1.0


@pytest.mark.parametrize(("initial", "maximum"), [(0.0, 1.0), (-1.0, 1.0), (2.0, 1.0)])
def test_backoff_refuses_bounds_that_never_wait_or_never_grow(
    initial: float, maximum: float
) -> None:
    with pytest.raises(ValueError):
        Backoff(initial, maximum)


def test_the_supervisor_restarts_on_the_same_schedule() -> None:
    policy = Policy(backoff_initial=0.5, backoff_max=3.0)
    assert [policy.backoff(n) for n in range(5)] == [0.5, 1.0, 2.0, 3.0, 3.0]
    assert policy.backoff(10_000) == 3.0
