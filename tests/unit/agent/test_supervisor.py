"""The brain state machine without a broker or a process: events in, effects and states out."""

from __future__ import annotations

import signal
from typing import Any

import pytest

from robotconf.agent.supervisor import Kill, Policy, Reload, Spawn, Supervisor, Terminate
from robotconf.contract.launch import with_digest
from robotconf.contract.wire import AgentState
from tests.support.agents import make_request

A = make_request(variant=0)
B = make_request(variant=1)  # another setting: the same restart digest as A
LOGIC = make_request(logic="follow_by_spinning")  # another capability: a new restart digest
HUP = signal.SIGHUP


class Clock:
    def __init__(self) -> None:
        self.wall = 1_000.0

    def __call__(self) -> float:
        return self.wall


def supervisor(**policy: Any) -> Supervisor:
    settings: dict[str, Any] = {
        "startsecs": 1.0,
        "stop_timeout": 10.0,
        "backoff_initial": 1.0,
        "backoff_max": 4.0,
        "max_restarts": 3,
        "reset_after": 60.0,
    }
    settings.update(policy)
    return Supervisor("tb3-01", Policy(**settings), wall_clock=Clock())


def running(sup: Supervisor, pid: int = 100, now: float = 0.0) -> Supervisor:
    """Drive a fresh supervisor to `running` request A as `pid`."""
    assert sup.accept(A, [], now) == [Spawn(A)]
    sup.spawned(pid, now)
    sup.tick(now + sup.policy.startsecs)
    assert sup.state == AgentState.RUNNING
    return sup


def test_starts_idle_and_waits() -> None:
    sup = supervisor()
    assert sup.state == AgentState.IDLE
    assert sup.deadline is None
    assert sup.status().pid is None and sup.status().digest is None


def test_running_only_after_startsecs() -> None:
    sup = supervisor(startsecs=2.0)
    assert sup.accept(A, ["w"], 0.0) == [Spawn(A)]
    assert sup.state == AgentState.STARTING
    sup.spawned(42, 0.0)
    assert sup.tick(1.9) == []
    assert sup.state == AgentState.STARTING
    sup.tick(2.0)
    status = sup.status()
    assert (status.state, status.pid, status.digest, status.warnings) == (
        AgentState.RUNNING,
        42,
        A.digest,
        ["w"],
    )


def test_startsecs_zero_means_running_at_once() -> None:
    sup = supervisor(startsecs=0)
    sup.accept(A, [], 0.0)
    sup.spawned(1, 0.0)
    assert sup.state == AgentState.RUNNING


def test_same_digest_is_a_no_op_even_with_another_revision() -> None:
    sup = running(supervisor())
    same = make_request(variant=0, revision="other-commit")
    assert same.digest == A.digest
    assert sup.accept(same, [], 5.0) == []
    assert sup.state == AgentState.RUNNING and sup.pid == 100
    assert sup.status().revision == A.revision


def test_new_digest_stops_gracefully_then_starts() -> None:
    sup = running(supervisor())
    assert sup.accept(B, [], 5.0) == [Terminate(100)]
    assert sup.state == AgentState.STOPPING
    assert sup.status().digest == A.digest  # still what runs
    assert sup.exited(100, -15, 6.0) == [Spawn(B)]
    sup.spawned(101, 6.0)
    status = sup.status()
    assert status.digest == B.digest and status.state == AgentState.STARTING


def test_sigkill_after_stop_timeout_once() -> None:
    sup = running(supervisor(stop_timeout=3.0))
    sup.accept(B, [], 10.0)
    assert sup.tick(12.9) == []
    assert sup.tick(13.0) == [Kill(100)]
    assert sup.tick(20.0) == []
    assert sup.exited(100, -9, 20.5) == [Spawn(B)]


def test_newest_request_wins_while_stopping() -> None:
    sup = running(supervisor())
    C = make_request(variant=2)
    assert sup.accept(B, [], 1.0) == [Terminate(100)]
    assert sup.accept(C, [], 1.5) == []  # SIGTERM already sent
    assert sup.exited(100, 0, 2.0) == [Spawn(C)]


def test_crash_backs_off_exponentially_then_fails() -> None:
    sup = running(supervisor(backoff_initial=1.0, backoff_max=3.0, max_restarts=3))
    now = 2.0
    delays = []
    for n in range(3):
        assert sup.exited(sup.pid or 0, 1, now) == []
        assert sup.state == AgentState.BACKOFF
        assert sup.restarts == n
        assert sup.deadline is not None
        delays.append(sup.deadline - now)
        assert sup.tick(sup.deadline - 0.01) == []
        now = sup.deadline
        assert sup.tick(now) == [Spawn(A)]
        assert sup.restarts == n + 1
        sup.spawned(200 + n, now)
        now += 0.5  # crashes again before startsecs
    assert delays == [1.0, 2.0, 3.0]  # doubling, capped at backoff_max
    sup.exited(sup.pid or 0, 1, now)
    status = sup.status()
    assert status.state == AgentState.FAILED
    assert status.restarts == 3 and status.exit_code == 1
    assert sup.deadline is None


def test_max_restarts_zero_fails_at_the_first_crash() -> None:
    sup = running(supervisor(max_restarts=0))
    sup.exited(100, 2, 5.0)
    assert sup.state == AgentState.FAILED


def test_a_long_healthy_run_resets_the_backoff() -> None:
    sup = running(supervisor(reset_after=30.0))
    sup.exited(100, 1, 1.0)
    assert sup.deadline == 2.0  # 1 s after the crash
    sup.tick(2.0)
    sup.spawned(101, 2.0)
    sup.exited(101, 1, 3.0)
    assert sup.deadline == 5.0  # 2 s: still the same run of failures
    sup.tick(5.0)
    sup.spawned(102, 5.0)
    sup.exited(102, 1, 40.0)  # it had run 35 s: healthy again
    assert sup.deadline == 41.0
    assert sup.restarts == 2  # the count shown keeps growing for this request


def test_clean_exit_under_on_failure_is_exited() -> None:
    sup = running(supervisor())
    assert sup.exited(100, 0, 5.0) == []
    assert sup.state == AgentState.EXITED and sup.status().exit_code == 0


def test_policy_always_restarts_a_clean_exit() -> None:
    sup = running(supervisor(restart="always"))
    sup.exited(100, 0, 5.0)
    assert sup.state == AgentState.BACKOFF


def test_policy_never_does_not_restart() -> None:
    sup = running(supervisor(restart="never"))
    sup.exited(100, 3, 5.0)
    assert sup.state == AgentState.FAILED and sup.deadline is None
    sup = running(supervisor(restart="never"))
    sup.exited(100, 0, 5.0)
    assert sup.state == AgentState.EXITED


def test_clear_stops_then_idles() -> None:
    sup = running(supervisor())
    assert sup.clear(5.0) == [Terminate(100)]
    assert sup.state == AgentState.STOPPING
    assert sup.exited(100, 0, 6.0) == []
    status = sup.status()
    assert (status.state, status.pid, status.digest) == (AgentState.IDLE, None, None)


def test_clear_during_backoff_cancels_the_restart() -> None:
    sup = running(supervisor())
    sup.exited(100, 1, 5.0)
    assert sup.state == AgentState.BACKOFF
    assert sup.clear(5.5) == []
    assert sup.status().state == AgentState.IDLE and sup.deadline is None
    assert sup.tick(100.0) == []


def test_new_request_during_backoff_starts_at_once() -> None:
    sup = running(supervisor())
    sup.exited(100, 1, 5.0)
    assert sup.accept(B, [], 5.1) == [Spawn(B)]
    assert sup.restarts == 0


def test_rejection_leaves_the_brain_and_clears_on_the_next_good_request() -> None:
    sup = running(supervisor())
    assert sup.reject("the request is for robot 'x'", 5.0) == []
    status = sup.status()
    assert status.state == AgentState.REJECTED
    assert status.pid == 100 and status.digest == A.digest
    assert "robot 'x'" in status.message and "still running" in status.message
    assert sup.accept(A, [], 6.0) == []
    assert sup.state == AgentState.RUNNING and sup.pid == 100


def test_a_crash_while_rejected_is_still_supervised() -> None:
    sup = running(supervisor())
    sup.reject("bad", 5.0)
    sup.exited(100, 1, 6.0)
    assert sup.phase == AgentState.BACKOFF
    assert sup.tick(7.0) == [Spawn(A)]


def test_spawn_failure_is_failed_until_a_new_digest() -> None:
    sup = supervisor()
    assert sup.accept(A, [], 0.0) == [Spawn(A)]
    sup.spawn_failed("cannot start 'cbs': No such file or directory", 0.0)
    status = sup.status()
    assert status.state == AgentState.FAILED and "No such file" in status.message
    assert sup.accept(A, [], 1.0) == []
    assert sup.accept(B, [], 2.0) == [Spawn(B)]


def test_shutdown_stops_the_brain_and_a_second_signal_kills_it() -> None:
    sup = running(supervisor())
    assert sup.shutdown(5.0) == [Terminate(100)]
    assert not sup.finished
    assert sup.accept(B, [], 5.5) == []  # nothing new starts while shutting down
    assert sup.shutdown(6.0) == [Kill(100)]
    assert sup.exited(100, -9, 6.1) == []
    assert sup.finished


def test_shutdown_without_a_brain_is_immediate() -> None:
    sup = supervisor()
    assert sup.shutdown(0.0) == []
    assert sup.finished


def test_reports_about_other_processes_are_ignored() -> None:
    sup = running(supervisor())
    assert sup.exited(99, 1, 5.0) == []
    assert sup.state == AgentState.RUNNING and sup.pid == 100


def test_since_moves_only_when_the_state_changes() -> None:
    clock = Clock()
    sup = Supervisor("tb3-01", Policy(startsecs=1.0), wall_clock=clock)
    sup.accept(A, [], 0.0)
    clock.wall = 1_010.0
    sup.spawned(100, 0.0)  # starting -> starting: same state
    assert sup.status().since == 1_000.0
    clock.wall = 1_020.0
    sup.tick(1.0)
    assert sup.status().since == 1_020.0


# ---------------------------------------------------------------- reload without restart


def reloading(**policy: Any) -> Supervisor:
    """Running A as pid 100, with reloads by SIGHUP configured."""
    return running(supervisor(reload_signal=HUP, **policy))


def test_a_reloadable_change_signals_the_running_brain() -> None:
    assert A.restart_digest == B.restart_digest and A.digest != B.digest
    sup = reloading()
    since = sup.status().since
    assert sup.accept(B, ["w"], 5.0) == [Reload(100, HUP, B)]
    status = sup.status()
    assert (status.state, status.pid, status.digest, status.revision) == (
        AgentState.RUNNING,
        100,
        B.digest,
        B.revision,
    )
    assert status.reloads == 1 and status.restarts == 0 and status.warnings == ["w"]
    assert status.since == since  # the state did not change: the same brain runs on
    assert "reloaded" in status.message and "SIGHUP" in status.message
    assert sup.deadline is None  # nothing to wait for: no stop, no start
    C = make_request(variant=2)
    assert sup.accept(C, [], 6.0) == [Reload(100, HUP, C)]
    assert sup.status().reloads == 2
    assert sup.accept(C, [], 7.0) == []  # the same digest again is still nothing


def test_the_configured_signal_is_the_one_sent() -> None:
    sup = running(supervisor(reload_signal=signal.SIGUSR2))
    assert sup.accept(B, [], 5.0) == [Reload(100, signal.SIGUSR2, B)]


def test_without_reload_configured_a_reloadable_change_restarts() -> None:
    sup = running(supervisor())
    assert sup.accept(B, [], 5.0) == [Terminate(100)]
    assert sup.status().reloads == 0


def test_a_capability_change_restarts_and_resets_the_reloads() -> None:
    sup = reloading()
    sup.accept(B, [], 5.0)
    assert sup.accept(LOGIC, [], 6.0) == [Terminate(100)]
    assert sup.state == AgentState.STOPPING and sup.status().digest == B.digest
    assert sup.exited(100, -15, 7.0) == [Spawn(LOGIC)]
    sup.spawned(101, 7.0)
    status = sup.status()
    assert status.digest == LOGIC.digest and status.reloads == 0 and status.restarts == 0


@pytest.mark.parametrize(("before", "after"), [(None, 1), (1, 2), (1, None), (None, 0)])
def test_a_domain_change_restarts_never_reloads(before: int | None, after: int | None) -> None:
    """A process joins its DDS domain when it starts: no reload can move a brain to another."""
    first = with_digest(A.model_copy(update={"ros_domain_id": before}))
    moved = with_digest(B.model_copy(update={"ros_domain_id": after}))
    sup = supervisor(reload_signal=HUP)
    assert sup.accept(first, [], 0.0) == [Spawn(first)]
    sup.spawned(100, 0.0)
    sup.tick(sup.policy.startsecs)
    assert sup.state == AgentState.RUNNING
    assert sup.accept(moved, [], 5.0) == [Terminate(100)]
    assert sup.exited(100, -15, 6.0) == [Spawn(moved)]
    assert sup.status().reloads == 0


def test_a_request_without_restart_digest_always_restarts() -> None:
    older = B.model_copy(update={"restart_digest": None})  # from an older reconciler
    sup = reloading()
    assert sup.accept(older, [], 5.0) == [Terminate(100)]
    # Nor can a brain that runs such a request be reloaded: nothing says what it runs.
    sup = running(supervisor(reload_signal=HUP))
    assert sup.accept(make_request(variant=3).model_copy(update={"restart_digest": None}), [], 5.0)
    sup.exited(100, -15, 6.0)
    sup.spawned(101, 6.0)
    sup.tick(7.0)
    assert sup.state == AgentState.RUNNING
    assert sup.accept(B, [], 8.0) == [Terminate(101)]


def test_a_starting_brain_is_restarted_not_signalled() -> None:
    # It may not handle the signal yet, and SIGHUP's default action ends a process.
    sup = supervisor(reload_signal=HUP)
    sup.accept(A, [], 0.0)
    sup.spawned(100, 0.0)
    assert sup.state == AgentState.STARTING
    assert sup.accept(B, [], 0.5) == [Terminate(100)]
    assert sup.exited(100, -15, 0.6) == [Spawn(B)]
    assert sup.status().reloads == 0


def test_in_backoff_the_new_request_starts_at_once() -> None:
    sup = reloading()
    sup.exited(100, 1, 5.0)
    assert sup.state == AgentState.BACKOFF
    assert sup.accept(B, [], 5.1) == [Spawn(B)]  # no brain runs to reload
    assert sup.status().reloads == 0


def test_while_stopping_the_newest_request_starts() -> None:
    sup = reloading()
    assert sup.accept(LOGIC, [], 1.0) == [Terminate(100)]
    # Back to A's capability while A's brain stops: it is stopping, so it is started anew.
    assert sup.accept(B, [], 1.5) == []
    assert sup.exited(100, -15, 2.0) == [Spawn(B)]


def test_a_reload_while_rejected_clears_the_rejection() -> None:
    sup = reloading()
    sup.reject("malformed launch request", 5.0)
    assert sup.state == AgentState.REJECTED
    assert sup.accept(B, [], 6.0) == [Reload(100, HUP, B)]
    assert sup.state == AgentState.RUNNING and sup.status().digest == B.digest


def test_a_reload_that_cannot_be_written_leaves_the_brain_on_its_request() -> None:
    sup = reloading()
    sup.accept(B, [], 5.0)
    sup.reload_failed(B, "cannot write the new request: ENOSPC", 5.0)
    status = sup.status()
    assert (status.state, status.pid, status.digest, status.reloads) == (
        AgentState.REJECTED,
        100,
        A.digest,
        0,
    )
    assert "ENOSPC" in status.message and f"still running {A.digest}" in status.message
    # The same request again is tried again (it was never applied).
    assert sup.accept(B, [], 6.0) == [Reload(100, HUP, B)]
    assert sup.state == AgentState.RUNNING and sup.status().reloads == 1


def test_a_crash_after_a_reload_restarts_the_reloaded_request() -> None:
    sup = reloading()
    sup.accept(B, [], 5.0)
    assert sup.exited(100, 1, 6.0) == []
    assert sup.tick(6.0 + sup.policy.backoff_initial) == [Spawn(B)]
    sup.spawned(101, 8.0)
    # Like restarts, reloads count for the request's lineage until a new capability restarts.
    assert sup.status().digest == B.digest and sup.status().restarts == 1


def test_clear_after_reloads_resets_them() -> None:
    sup = reloading()
    sup.accept(B, [], 5.0)
    sup.clear(6.0)
    sup.exited(100, -15, 6.5)
    status = sup.status()
    assert status.state == AgentState.IDLE and status.reloads == 0


def test_a_restart_from_the_desk_starts_a_failed_brain_again() -> None:
    sup = supervisor(max_restarts=0)
    sup.accept(A, [], 0.0)
    sup.spawned(1, 0.0)
    sup.exited(1, 3, 0.5)
    assert sup.state == AgentState.FAILED
    effects, problem = sup.restart("alice", 1234.5, 1.0)
    assert problem is None and effects == [Spawn(A)]
    assert sup.state == AgentState.STARTING
    status = sup.status()
    assert (status.restart_requested_by, status.restart_requested_at) == ("alice", 1234.5)
    assert status.restarts == 0
    sup.spawned(2, 1.0)
    sup.tick(2.0)
    assert sup.state == AgentState.RUNNING and sup.status().pid == 2


def test_a_restart_stops_a_running_brain_first_then_starts_it() -> None:
    sup = running(supervisor(), pid=100)
    effects, problem = sup.restart("bob", 1.0, 5.0)
    assert problem is None and effects == [Terminate(100)]
    assert sup.state == AgentState.STOPPING
    assert "restart requested by bob" in sup.status().message
    # A wedged brain that ignores SIGTERM is killed after the stop timeout, as for any stop.
    assert sup.tick(5.0 + sup.policy.stop_timeout) == [Kill(100)]
    assert sup.exited(100, -9, 16.0) == [Spawn(A)]


def test_a_restart_in_backoff_starts_at_once() -> None:
    sup = running(supervisor(), pid=100)
    sup.exited(100, 1, 2.0)
    assert sup.state == AgentState.BACKOFF and sup.deadline is not None
    effects, problem = sup.restart("alice", 1.0, 2.1)
    assert problem is None and effects == [Spawn(A)] and sup.streak == 0


def test_a_restart_with_nothing_assigned_or_while_shutting_down_does_nothing() -> None:
    sup = supervisor()
    effects, problem = sup.restart("alice", 1.0, 0.0)
    assert effects == [] and problem is not None and "no launch request" in problem
    assert sup.status().restart_requested_by is None
    sup = running(supervisor(), pid=7)
    sup.shutdown(1.0)
    effects, problem = sup.restart("alice", 1.0, 1.5)
    assert effects == [] and problem == "the agent is shutting down"


# ---------------------------------------------------------------- busy robots: the hold file


class Hold:
    """The brain's hold file, as the supervisor asks about it."""

    def __init__(self) -> None:
        self.there = False

    def __call__(self) -> bool:
        return self.there


def holding(pid: int = 100, **policy: Any) -> tuple[Supervisor, Hold]:
    """Running A as `pid` with max_defer 30 s, its brain holding."""
    hold = Hold()
    settings: dict[str, Any] = {"startsecs": 1.0, "stop_timeout": 10.0, "max_defer": 30.0}
    settings.update(policy)
    sup = Supervisor("tb3-01", Policy(**settings), wall_clock=Clock(), held=hold)
    running(sup, pid)
    hold.there = True
    return sup, hold


def test_a_new_request_waits_while_the_brain_holds_then_goes_ahead_once_released() -> None:
    sup, hold = holding()
    assert sup.accept(LOGIC, [], 5.0) == []
    status = sup.status()
    assert status.state == AgentState.DEFERRED and status.pid == 100
    assert status.digest == A.digest  # the brain still runs the old request
    assert status.deferred_since == status.since and status.max_defer == 30.0
    assert f"restart for request {LOGIC.digest} deferred by the brain's hold file" in (
        status.message
    )
    assert sup.tick(5.0 + sup.policy.hold_poll) == []  # still held: looked at again later
    assert sup.state == AgentState.DEFERRED
    hold.there = False
    assert sup.tick(sup.deadline or 0.0) == [Terminate(100)]
    assert sup.state == AgentState.STOPPING and "removed its hold file" in sup.message
    assert sup.status().deferred_since is None
    assert sup.exited(100, -15, 7.0) == [Spawn(LOGIC)]


def test_max_defer_passed_goes_ahead_and_says_so() -> None:
    sup, _ = holding(max_defer=20.0)
    sup.accept(LOGIC, [], 5.0)
    now = 5.0
    while sup.state == AgentState.DEFERRED:
        assert sup.deadline is not None and sup.deadline <= 25.0
        now = sup.deadline
        effects = sup.tick(now)
    assert now == 25.0 and effects == [Terminate(100)]
    assert "deferral ran out after 20 s (max_defer)" in sup.status().message


def test_a_newer_request_replaces_the_one_that_waits_and_keeps_the_deadline() -> None:
    sup, _ = holding()
    sup.accept(LOGIC, [], 5.0)
    other = make_request(logic="follow_by_spinning", variant=3)
    assert sup.accept(other, [], 10.0) == []
    assert other.digest in sup.message and LOGIC.digest not in sup.message
    while sup.state == AgentState.DEFERRED:  # max_defer counts from the first deferral
        effects = sup.tick(sup.deadline or 0.0)
    assert effects == [Terminate(100)]
    assert sup.exited(100, -15, 36.0) == [Spawn(other)]


def test_back_to_the_running_request_ends_the_deferral_with_nothing_done() -> None:
    sup, _ = holding()
    sup.accept(LOGIC, [], 5.0)
    assert sup.accept(A, [], 6.0) == []
    assert sup.state == AgentState.RUNNING and sup.deadline is None
    assert sup.status().deferred_since is None


def test_a_stop_for_a_robot_leaving_the_fleet_is_deferred() -> None:
    sup, hold = holding()
    assert sup.clear(5.0) == []
    assert sup.state == AgentState.DEFERRED
    assert sup.message.startswith("stop (no launch request for this robot) deferred")
    hold.there = False
    assert sup.tick(sup.deadline or 0.0) == [Terminate(100)]
    sup.exited(100, -15, 6.0)
    assert sup.state == AgentState.IDLE


def test_a_restart_from_the_desk_is_deferred_then_carried_out() -> None:
    sup, hold = holding()
    effects, problem = sup.restart("alice", 1234.5, 5.0)
    assert (effects, problem) == ([], None)
    assert sup.state == AgentState.DEFERRED
    assert "restart requested by alice deferred" in sup.message
    assert sup.status().restart_requested_by == "alice"  # taken: the desk sees it deferred
    hold.there = False
    assert sup.tick(sup.deadline or 0.0) == [Terminate(100)]
    assert sup.status().restart_requested_by == "alice"
    assert sup.exited(100, -15, 6.0) == [Spawn(A)]


def test_a_reload_is_deferred_then_signals() -> None:
    sup, hold = holding(reload_signal=HUP)
    assert sup.accept(B, [], 5.0) == []
    assert sup.state == AgentState.DEFERRED
    assert f"reload to request {B.digest} deferred" in sup.message
    hold.there = False
    assert sup.tick(sup.deadline or 0.0) == [Reload(100, HUP, B)]
    status = sup.status()
    assert status.state == AgentState.RUNNING and status.digest == B.digest
    assert status.reloads == 1


def test_a_crash_while_deferred_is_not_deferred() -> None:
    sup, _ = holding()
    sup.accept(LOGIC, [], 5.0)
    assert sup.exited(100, 1, 6.0) == [Spawn(LOGIC)]  # the hold file is still there
    assert sup.status().deferred_since is None


def test_a_crash_restart_is_never_deferred() -> None:
    sup, _ = holding(backoff_initial=1.0)
    sup.exited(100, 1, 6.0)
    assert sup.state == AgentState.BACKOFF
    assert sup.tick(7.0) == [Spawn(A)]


def test_the_agents_own_shutdown_is_not_deferred() -> None:
    sup, _ = holding()
    sup.accept(LOGIC, [], 5.0)
    assert sup.shutdown(6.0) == [Terminate(100)]
    assert sup.state == AgentState.STOPPING


def test_max_defer_zero_ignores_the_hold_file() -> None:
    sup, _ = holding(max_defer=0.0)
    assert sup.accept(LOGIC, [], 5.0) == [Terminate(100)]


def test_a_desk_restart_is_shown_until_a_new_request_restarts_the_brain() -> None:
    """`restart: ROBOT by WHO at WHEN` tells the brain's latest restart, not an old one."""
    sup = running(supervisor(), pid=100)
    sup.restart("alice", 1234.5, 5.0)
    sup.exited(100, -15, 5.5)
    sup.spawned(101, 6.0)
    sup.exited(101, 1, 7.0)  # a crash restart after it: RESTARTS counts it, the line stays
    sup.tick(7.0 + sup.policy.backoff_initial)
    assert sup.status().restart_requested_by == "alice" and sup.status().restarts == 1
    sup.accept(LOGIC, [], 20.0)  # a later commit restarts the brain
    status = sup.status()
    assert (status.restart_requested_by, status.restart_requested_at) == (None, None)


def test_a_reload_keeps_the_desk_restart_and_a_cleared_request_forgets_it() -> None:
    sup = reloading()
    sup.restart("alice", 1234.5, 1.0)
    sup.exited(100, -15, 1.5)
    sup.spawned(101, 2.0)
    sup.tick(2.0 + sup.policy.startsecs)
    sup.accept(B, [], 5.0)  # reloaded: the same process runs on
    assert sup.status().reloads == 1 and sup.status().restart_requested_by == "alice"
    sup.clear(6.0)
    assert sup.status().restart_requested_by is None


# ---------------------------------------------------------------- readiness (issue 30)


def test_a_brain_that_said_hello_is_starting_until_ready() -> None:
    sup = supervisor(startsecs=1.0, ready_timeout=30.0)
    sup.accept(A, [], 0.0)
    sup.spawned(100, 0.0)
    sup.hello(0.2)
    assert sup.state == AgentState.STARTING and "said hello" in sup.message
    assert sup.deadline == 30.2  # the ready_timeout, from the hello; startsecs no longer
    assert sup.tick(1.0) == [] and sup.state == AgentState.STARTING
    sup.ready(5.0)
    assert sup.state == AgentState.RUNNING and sup.deadline is None
    assert "ready" in sup.message


def test_a_hello_after_startsecs_is_starting_again_until_ready() -> None:
    sup = running(supervisor(ready_timeout=30.0))
    sup.hello(3.0)
    assert sup.state == AgentState.STARTING and sup.deadline == 33.0
    sup.ready(4.0)
    assert sup.state == AgentState.RUNNING
    sup.hello(5.0)  # a reconnection: readiness was said already
    assert sup.state == AgentState.RUNNING


def test_no_ready_within_ready_timeout_is_a_failed_start() -> None:
    sup = supervisor(ready_timeout=10.0, max_restarts=1, reset_after=5.0)
    sup.accept(A, [], 0.0)
    sup.spawned(100, 0.0)
    sup.hello(0.1)
    assert sup.tick(10.1) == [Terminate(100)]
    assert sup.state == AgentState.STOPPING and "not ready within 10 s" in sup.message
    sup.exited(100, -15, 10.2)
    # A failure although it ran past reset_after: it was never healthy.
    assert sup.state == AgentState.BACKOFF
    assert "not ready within 10 s (ready_timeout)" in sup.message
    assert sup.tick(sup.deadline or 0) == [Spawn(A)]
    sup.spawned(101, 12.0)
    sup.hello(12.0)
    assert sup.tick(22.0) == [Terminate(101)]
    sup.exited(101, 0, 22.1)  # even a clean exit after the stop
    assert sup.state == AgentState.FAILED and "gave up after 1 restarts" in sup.message


def test_no_ready_under_policy_never_is_failed() -> None:
    sup = supervisor(ready_timeout=1.0, restart="never")
    sup.accept(A, [], 0.0)
    sup.spawned(100, 0.0)
    sup.hello(0.0)
    sup.tick(1.0)
    sup.exited(100, -15, 1.1)
    assert sup.state == AgentState.FAILED


def test_a_new_request_during_an_unready_stop_starts_at_once() -> None:
    sup = supervisor(ready_timeout=1.0)
    sup.accept(A, [], 0.0)
    sup.spawned(100, 0.0)
    sup.hello(0.0)
    sup.tick(1.0)
    assert sup.accept(B, [], 1.1) == []
    assert sup.exited(100, -15, 1.2) == [Spawn(B)]


def test_ready_timeout_zero_waits_for_ready_as_long_as_it_takes() -> None:
    sup = supervisor(ready_timeout=0.0)
    sup.accept(A, [], 0.0)
    sup.spawned(100, 0.0)
    sup.hello(0.0)
    assert sup.deadline is None and sup.tick(1e6) == []
    assert sup.state == AgentState.STARTING


def test_ready_without_hello_and_a_brain_without_either() -> None:
    sup = supervisor()
    sup.accept(A, [], 0.0)
    sup.spawned(100, 0.0)
    sup.ready(0.1)
    assert sup.state == AgentState.RUNNING
    plain = running(supervisor())  # no hello: startsecs, as ever
    assert plain.state == AgentState.RUNNING


def test_hello_and_ready_without_a_brain_change_nothing() -> None:
    sup = supervisor()
    assert sup.hello(0.0) == [] and sup.ready(0.0) == []
    assert sup.state == AgentState.IDLE
