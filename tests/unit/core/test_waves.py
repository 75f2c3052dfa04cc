"""Wave assignment and failure budgets: pure, deterministic, shared by plan and the reconciler."""

from __future__ import annotations

from robotconf.configurator.types import Wave
from robotconf.configurator.waves import assign_waves, failure_budget

ROBOTS = {
    "a": {"ring": "canary"},
    "b": {},
    "c": {"site": "hall-a"},
    "d": {"ring": "canary", "site": "hall-a"},
    "e": {},
}


def test_selector_then_percent_then_all() -> None:
    waves = [
        Wave(name="canary", selector={"ring": "canary"}),
        Wave(name="half", percent=50),
        Wave(name="all"),
    ]
    # canary takes a and d; half of 5 is 3 (rounded up): one more, the first left by id (b).
    assert assign_waves(ROBOTS, waves) == {"a": 0, "d": 0, "b": 1, "c": 2, "e": 2}


def test_a_robot_goes_in_the_first_wave_that_takes_it_and_none_may_take_it() -> None:
    waves = [
        Wave(name="hall", selector={"site": "hall-a"}),
        Wave(name="canary", selector={"ring": "canary"}),
    ]
    assert assign_waves(ROBOTS, waves) == {"c": 0, "d": 0, "a": 1}


def test_a_percent_of_a_selector_counts_only_its_robots() -> None:
    waves = [Wave(name="some-canaries", selector={"ring": "canary"}, percent=50), Wave(name="all")]
    assert assign_waves(ROBOTS, waves) == {"a": 0, "b": 1, "c": 1, "d": 1, "e": 1}


def test_assignment_is_independent_of_input_order() -> None:
    waves = [Wave(name="first", percent=40), Wave(name="rest")]
    backwards = dict(reversed(list(ROBOTS.items())))
    assert (
        assign_waves(ROBOTS, waves)
        == assign_waves(backwards, waves)
        == {"a": 0, "b": 0, "c": 1, "d": 1, "e": 1}
    )


def test_failure_budgets() -> None:
    assert failure_budget(1, 10) == 1
    assert failure_budget("10%", 25) == 2
    assert failure_budget("0%", 25) == 0
    assert failure_budget("100%", 3) == 3
    assert failure_budget("ten", 10) is None
    assert failure_budget("101%", 10) is None
    assert failure_budget(-1, 10) is None
