"""A stand-in brain service for demos and tests:
`python -m robotconf.agent.standin_brain REQUEST.json`.

It loads nothing real: it prints what a brain would load, says it is ready, runs its scenario's
goal tasks as goals through `robotconf.brain` (each taking STANDIN_GOAL_SECONDS, succeeding at
the rate STANDIN_SUCCESS_RATE, both from the scenario's knowledge), runs until signalled and
reloads on SIGHUP; asked to, it holds its agent off with the hold file (`--hold`,
`--hold-while`).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from robotconf.contract.lifecycle import queued_signals

if TYPE_CHECKING:
    from robotconf.contract.launch import LaunchRequest


def describe(request: LaunchRequest, environ: Mapping[str, str]) -> list[str]:
    """What a brain would load, and the ROS domain its environment puts it in (`environ`)."""
    scenario = request.scenario
    capability = scenario.capability
    lines = [
        f"stand-in brain for {request.robot_id} ({request.robot_name}), "
        f"scenario {scenario.name}, {request.digest} at {request.revision}",
        f"platform module: {capability.platform} (mapping scheme {capability.mapping_scheme}, "
        f"robot template {capability.robot_template or '-'})",
        "logic modules:",
    ]
    # An action selects one logic (its name) or several (a list, in the capability's order).
    lines += [
        f"  {action}: {logic if isinstance(logic, str) else ', '.join(logic)}"
        for action, logic in sorted(capability.logics.items())
    ]
    lines.append("mappings:")
    lines += [
        f"  {name}: {b.kind} {b.name} ({b.type})" for name, b in sorted(capability.mappings.items())
    ]
    if scenario.goals:
        lines.append("goals: " + ", ".join(goal.task for goal in scenario.goals))
    # Where a ROS 2 brain's nodes would join; said so that the agent's choice can be seen.
    lines.append(f"ROS domain: {environ.get('ROS_DOMAIN_ID', 'unset (ROS default, 0)')}")
    return lines


CRASH_KEY = "STANDIN_CRASH"
# Knowledge keys of a scenario that shape the stand-in's goals, so that a commit can lower the
# success rate and `status`, `history` and the browser show it.
SUCCESS_RATE_KEY = "STANDIN_SUCCESS_RATE"  # 0..1, the share of goals that succeed (default 1)
GOAL_SECONDS_KEY = "STANDIN_GOAL_SECONDS"  # how long one goal takes (default 5 s)
FAILURE_CODE = "STANDIN_FAILED"
DEFAULT_GOAL_SECONDS = 5.0
PROGRESS_STEPS = 5  # progress reports per goal


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m robotconf.agent.standin_brain",
        description="Stand-in brain: prints the modules it would load, runs until signalled.",
    )
    parser.add_argument("request", type=Path, help="the launch request JSON file")
    # Misbehaviour on demand, so that demos and tests can show crashes and stubborn brains.
    parser.add_argument("--exit-after", type=float, metavar="S", help="exit by itself after S s")
    parser.add_argument("--exit-code", type=int, default=0, help="code for --exit-after")
    parser.add_argument("--ignore-sigterm", action="store_true", help="only SIGKILL stops it")
    # Busy on demand: the hold file ($ROBOTCONF_HOLD_FILE) defers the agent's stops and reloads.
    parser.add_argument(
        "--hold", type=float, metavar="S", help="hold the agent off for S s after starting"
    )
    parser.add_argument(
        "--hold-while",
        type=Path,
        metavar="MARKER",
        help="hold the agent off from starting while the file MARKER exists",
    )
    return parser


HOLD_VARIABLE = "ROBOTCONF_HOLD_FILE"
HOLD_LOOK_EVERY = 0.05  # seconds between looks at --hold-while's marker


def hold(path: Path, seconds: float | None, marker: Path | None, stop: threading.Event) -> None:
    """Creates the hold file, then removes it once `seconds` have passed or `marker` is
    gone (or the brain stops): what a real brain does around a task it must not leave."""
    path.touch()
    print(f"stand-in brain: busy, holding the agent off ({path})", flush=True)
    deadline = None if seconds is None else time.monotonic() + seconds
    while not stop.is_set():
        if deadline is not None and time.monotonic() >= deadline:
            break
        if marker is not None and not marker.exists():
            break
        stop.wait(HOLD_LOOK_EVERY)
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
    with contextlib.suppress(OSError):
        print("stand-in brain: done, hold released", flush=True)


def _read(path: Path) -> LaunchRequest:
    """The request in `path`; raises OSError or pydantic's ValidationError."""
    from robotconf.contract.launch import LaunchRequest

    return LaunchRequest.model_validate_json(path.read_bytes())


def _reload(path: Path, running: LaunchRequest) -> LaunchRequest:
    """What a brain that supports reloading does on SIGHUP: read the request again and apply
    what changed in place. One that cannot read it keeps what it runs."""
    from pydantic import ValidationError

    try:
        request = _read(path)
    except (OSError, ValidationError) as exc:
        print(
            f"stand-in brain: cannot reload {path} ({type(exc).__name__}); keeping {running.digest}"
        )
        return running
    print(f"stand-in brain: SIGHUP received, reloaded {request.digest} at {request.revision}")
    if request.scenario.capability != running.scenario.capability:
        # A real brain would have to restart for this; the agent restarts it then, not reloads.
        print("stand-in brain: the capability changed too; only a restart applies it")
    if request.scenario.goals:
        print("goals: " + ", ".join(goal.task for goal in request.scenario.goals))
    return request


def _load(path: Path) -> LaunchRequest | int:
    """The request in `path`, or the exit code after saying on stderr why it cannot be read."""
    from pydantic import ValidationError

    try:
        return _read(path)
    except OSError as exc:
        print(f"stand-in brain: cannot read {path}: {exc.strerror}", file=sys.stderr)
        return 2
    except ValidationError as exc:
        print(f"stand-in brain: malformed launch request {path}:", file=sys.stderr)
        for error in exc.errors():
            where = ".".join(str(p) for p in error["loc"]) or "(top level)"
            print(f"  {where}: {error['msg']}", file=sys.stderr)
        return 1


def _crash_code(request: LaunchRequest) -> int | None:
    """The code a request asks this brain to crash with, so that a bad commit can be rehearsed
    end to end (a rollout stopping at its canaries): knowledge {STANDIN_CRASH: CODE}."""
    crash = request.scenario.environment_knowledge.get(CRASH_KEY)
    if crash in (None, False, 0):
        return None
    return crash if isinstance(crash, int) and not isinstance(crash, bool) else 1


def _number(
    knowledge: Mapping[str, object], key: str, default: float, low: float, high: float
) -> float:
    value = knowledge.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return default
    return min(high, max(low, float(value)))


def goal_plan(request: LaunchRequest) -> tuple[list[str], float, float]:
    """(goal tasks, success rate, seconds a goal) the stand-in runs for `request`."""
    knowledge = request.scenario.environment_knowledge
    rate = _number(knowledge, SUCCESS_RATE_KEY, 1.0, 0.0, 1.0)
    seconds = _number(knowledge, GOAL_SECONDS_KEY, DEFAULT_GOAL_SECONDS, 0.05, 3600.0)
    return [goal.task for goal in request.scenario.goals], rate, seconds


def run_goals(current: list[LaunchRequest], stop: threading.Event) -> None:
    """The scenario's goal tasks, one after another, round and round: each reports progress
    and ends succeeded or failed as the (current, reloaded) request's knowledge asks."""
    import random

    from robotconf import brain

    chance = random.Random()
    battery = 1.0
    while not stop.is_set():
        tasks, rate, seconds = goal_plan(current[0])
        if not tasks:
            stop.wait(1.0)
            continue
        for task in tasks:
            goal = brain.goal(task)
            for step in range(1, PROGRESS_STEPS + 1):
                if stop.wait(seconds / PROGRESS_STEPS):
                    goal.canceled()
                    return
                left = seconds * (PROGRESS_STEPS - step) / PROGRESS_STEPS
                goal.progress(step / PROGRESS_STEPS, eta=left)
            if chance.random() < rate:
                goal.succeeded()
            else:
                goal.failed(FAILURE_CODE, f"failed as {SUCCESS_RATE_KEY} {rate:g} asks")
            battery = max(0.05, battery - 0.01)
            brain.vitals({"battery": round(battery, 2)})
            tasks, rate, seconds = goal_plan(current[0])  # a reload applies from the next goal


def _start_work(
    args: argparse.Namespace, request: LaunchRequest, stop: threading.Event
) -> list[LaunchRequest]:
    """Ready, then the goals (and the hold, when asked) on threads of their own; returns the
    request they follow, which a reload replaces in place."""
    from robotconf import brain

    brain.ready()  # nothing to set up: ready at once (a real brain says it once it can work)
    current = [request]
    threading.Thread(target=run_goals, args=(current, stop), daemon=True).start()
    held = os.environ.get(HOLD_VARIABLE)
    if held and (args.hold is not None or args.hold_while is not None):
        threading.Thread(
            target=hold, args=(Path(held), args.hold, args.hold_while, stop), daemon=True
        ).start()
    return current


class Signals:
    """The signals received, taken by the main loop from the queue their handler puts them on
    (`queued_signals`): an Event set in the handler could wait forever for its own lock."""

    def __init__(self) -> None:
        # Before the slow imports: a brain stopped while it starts should still stop cleanly,
        # and one told to reload while it starts should not die of SIGHUP's default action.
        self.queue = queued_signals((signal.SIGINT, signal.SIGTERM, signal.SIGHUP))
        self.stop = threading.Event()
        self.received: list[str] = []  # the stop signals' names
        self.reloads = 0  # SIGHUPs not acted on yet

    def take(self, timeout: float | None = 0.0) -> None:
        """Takes in what was received, waiting up to `timeout` for the first one."""
        try:
            first = self.queue.get(timeout=timeout) if timeout else self.queue.get_nowait()
        except queue.Empty:
            return
        pending = [first]
        with contextlib.suppress(queue.Empty):
            while True:
                pending.append(self.queue.get_nowait())
        for signum in pending:
            if signum == signal.SIGHUP:
                self.reloads += 1
            else:
                self.received.append(signal.Signals(signum).name)
                self.stop.set()


def main(argv: list[str]) -> int:
    signals = Signals()
    stop = signals.stop
    args = _parser().parse_args(argv)
    if args.ignore_sigterm:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    loaded = _load(args.request)
    if isinstance(loaded, int):
        return loaded
    request = loaded
    for line in describe(request, os.environ):
        print(line)
    sys.stdout.flush()
    crash = _crash_code(request)
    if crash is not None:
        print(f"stand-in brain: crashing with code {crash}, as {CRASH_KEY} asks", flush=True)
        return crash

    signals.take()  # a stop asked while it started: no goal begins
    current = _start_work(args, request, stop)
    deadline = None if args.exit_after is None else time.monotonic() + args.exit_after
    while not stop.is_set():
        if signals.reloads:
            signals.reloads = 0  # several signals before it looked: one reading is enough
            with contextlib.suppress(OSError):  # the log may be gone
                request = current[0] = _reload(args.request, request)
                sys.stdout.flush()
            crash = _crash_code(request)
            if crash is not None:  # a settings-only change reloads: the rehearsal still crashes
                print(
                    f"stand-in brain: crashing with code {crash}, as {CRASH_KEY} asks", flush=True
                )
                return crash
            continue
        remaining = None if deadline is None else deadline - time.monotonic()
        if remaining is not None and remaining <= 0:
            print(f"stand-in brain: exiting with code {args.exit_code} as asked", flush=True)
            return int(args.exit_code)
        signals.take(timeout=remaining if remaining is not None else 3600)
    # The log may be gone; stopping matters more than saying so.
    with contextlib.suppress(OSError):
        print(f"stand-in brain: {signals.received[0]} received, stopping", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
