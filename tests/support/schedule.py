"""The order the run hands tests to pytest-xdist's workers: each worker's first share begins
with some of the longest tests, so that none is left to start when the others are done.

xdist's `worksteal` gives each of N idle workers a contiguous share of the collection at the
start (the first `len // N`, then `rest // (N - 1)`, ...), and an idle worker later takes
tests from the *end* of a busy one's queue. A long test at the front of a share runs first
on its own worker; one late in the collection is the last thing the run waits for. Which tests
are long is known from `--durations` (each run prints the slowest 15); a stale entry only loses
its place, it never leaves a test out.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import islice
from typing import TypeVar

T = TypeVar("T")

# The longest tests of a run on two cores, longest first (a prefix of their node ids).
LONGEST = (
    "tests/integration/reconciler/test_hold_skip_deaths.py::test_a_reconciler_killed_while_a_wave_skips",
    "tests/integration/agent/test_robot_install.py::",
    "tests/integration/agent/test_agent_desk.py::test_logs_follow_streams_until_nobody_asks",
    "tests/integration/reconciler/test_rollout_offline.py::test_a_skipped_robot_back_while",
    "tests/integration/agent/test_agent_desk.py::test_a_polling_dashboard_does_not_starve",
    "tests/unit/test_incremental.py::",
    "tests/integration/reconciler/test_rollout_verify.py::test_a_reconciler_killed_during_a_stages",
    "tests/integration/reconciler/test_rollout_verify.py::test_a_good_revision_is_verified",
    "tests/integration/reconciler/test_rollout_offline.py::test_a_robot_back_mid_rollout",
    "tests/integration/core/test_namespace.py::",
    "tests/integration/reconciler/test_rollout_deaths.py::test_a_reconciler_killed_during_healthy",
    "tests/unit/fuzz/test_payloads.py::",
    "tests/integration/reconciler/test_rollout_decision_deaths.py::test_a_reconciler_killed_as_it",
    "tests/integration/core/test_precommit.py::test_the_published_hooks_run_in_an_install",
    "tests/integration/reconciler/test_rollout_verify.py::test_too_few_goals_pause_it",
    "tests/unit/reconciler/test_rollout_memory.py::test_sets_survive_their_record",
    "tests/integration/reconciler/test_up_desk.py::test_a_quick_restart_keeps_the_broker_port",
    "tests/integration/reconciler/test_up.py::test_the_embedded_broker_takes_many_clients",
    "tests/integration/reconciler/test_alerts.py::test_robot_transitions_are_told_once",
    "tests/integration/reconciler/test_up_local_loop.py::test_up_s_robots_report_interfaces",
    "tests/integration/reconciler/test_up_desk.py::test_a_given_broker_that_never_answers",
    "tests/unit/fuzz/test_redaction.py::",
)


def shares(total: int, workers: int) -> list[int]:
    """The sizes of the contiguous shares worksteal hands `workers` idle workers at the start."""
    sizes = []
    for i in range(workers):
        size = total // (workers - i)
        sizes.append(size)
        total -= size
    return sizes


def longest_first(
    ids: Sequence[str], items: Sequence[T], workers: int, longest: Sequence[str] = LONGEST
) -> list[T]:
    """`items` (whose node ids are `ids`) reordered: the ones `longest` names are dealt round the
    workers' shares, longest first, each share starting with its own (the tests one entry names
    together); the rest keep their order. Nothing is added or left out."""
    rank: dict[int, int] = {}
    for i, node_id in enumerate(ids):
        found = next((n for n, prefix in enumerate(longest) if node_id.startswith(prefix)), None)
        if found is not None:
            rank[i] = found
    # The tests one entry names stay together: they may share a module's costly fixture.
    units: list[list[int]] = [[] for _ in longest]
    for i in sorted(rank):
        units[rank[i]].append(i)
    units = [unit for unit in units if unit]
    rest = iter(i for i in range(len(items)) if i not in rank)
    order: list[int] = []
    for worker, size in enumerate(shares(len(items), workers)):
        mine = [i for unit in units[worker::workers] for i in unit]
        order.extend(mine)
        order.extend(islice(rest, max(0, size - len(mine))))
    order.extend(rest)  # more long tests than a share holds: whatever is left
    return [items[i] for i in order]
