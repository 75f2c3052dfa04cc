"""The brain state machine without a broker or a process: events in, effects and states out."""

from __future__ import annotations

from typing import Any

from agent.supervisor import Kill, Policy, Spawn, Supervisor, Terminate
from configurator.wire import AgentState
from tests.support.agents import make_request

A = make_request(variant=0)
B = make_request(variant=1)


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
