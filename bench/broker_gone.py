"""Time to the error of desk commands whose broker is not there: `status` and `logs` against a
port nobody listens on (the connection is refused at once), at their default --wait (5 s and
10 s), beside `status --help` (start-up and the command's imports: the floor of any run).

    python bench/broker_gone.py [-n 5] [--before CHECKOUT] [--silent]

--before runs the same commands of an older checkout too (PYTHONPATH=CHECKOUT), in the same
rounds, so before and after meet the same machine (e.g. `git archive main | tar -x -C DIR`).
--silent adds `status --wait 2` against a listener that takes the connection and never answers:
it must still wait its 2 s (a silent network is waited out, never taken for a refusal).

Each round runs every case once, in turn, so a machine that speeds up or slows down during the
call moves them all alike; one warm-up round is not counted. Medians of wall seconds per whole
process, and of that minus the floor (the time to the error itself); the target is 1 s.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGET = 1.0  # seconds from start-up to the error, for a refused connection

Case = tuple[str, list[str], dict[str, str], int]  # label, argv, environment, exit code


def robotconf() -> str:
    """The installed entry point next to this Python, else the one on PATH."""
    beside = Path(sys.executable).parent / "robotconf"
    found = str(beside) if beside.exists() else shutil.which("robotconf")
    if found is None:
        raise SystemExit("robotconf is not installed: run ./dev setup first")
    return found


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def cases(before: Path | None, silent_url: str | None) -> list[Case]:
    entry, repo = robotconf(), str(ROOT)
    gone = f"mqtt://127.0.0.1:{free_port()}"  # nobody listens: refused at once
    versions: list[tuple[str, dict[str, str], list[str]]] = [("", {}, [entry])]
    if before is not None:
        sys.path.insert(0, str(ROOT))
        from bench.startup import older_entry

        versions.append(("before: ", {"PYTHONPATH": str(before)}, older_entry(before, entry)))
    table: list[Case] = []
    for prefix, env, command in versions:
        status = [*command, "status", "--repo", repo, "--broker", gone]
        logs = [*command, "logs", "tb3-01", "--repo", repo, "--broker", gone]
        floor = [*command, "status", "--help"]
        table += [
            (f"{prefix}status --help (floor)", floor, env, 0),
            (f"{prefix}status, refused", status, env, 2),
            (f"{prefix}logs, refused", logs, env, 2),
        ]
    if silent_url is not None:
        silent = [entry, "status", "--repo", repo, "--broker", silent_url, "--wait", "2"]
        table.append(("status --wait 2, silent listener", silent, {}, 2))
    return table


def run_once(argv: list[str], env: dict[str, str], code: int) -> float:
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=ROOT, capture_output=True, env=env, text=True)
    wall = time.perf_counter() - start
    if done.returncode != code or "Traceback" in done.stderr:
        raise SystemExit(f"{' '.join(argv)} exited {done.returncode}: {done.stderr}")
    return wall


def measure(table: list[Case], rounds: int) -> dict[str, list[float]]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    times: dict[str, list[float]] = {label: [] for label, _, _, _ in table}
    for round_number in range(rounds + 1):
        for label, argv, extra, code in table:
            wall = run_once(argv, {**env, **extra}, code)
            if round_number:  # round 0 warms up
                times[label].append(wall)
    return times


def report(times: dict[str, list[float]], rounds: int) -> bool:
    """Prints the table; True when our refused commands reach their error within TARGET."""
    print(f"{'case':<40} {'wall':>8} {'- floor':>8}")
    held = True
    floor = 0.0
    for label, runs in times.items():
        wall = statistics.median(runs)
        if label.endswith("(floor)"):
            floor = wall
        print(f"{label:<40} {wall:>7.3f}s {wall - floor:>7.3f}s")
        if "refused" in label and not label.startswith("before"):
            held = held and wall - floor <= TARGET
    print(f"medians of {rounds} alternating rounds (one warm-up round not counted)")
    verdict = "holds" if held else "does NOT hold"
    print(f"target: a refused connection said within {TARGET:g} s of start-up: {verdict}")
    return held


def main() -> None:
    parser = argparse.ArgumentParser(description="time to the error when the broker is gone")
    parser.add_argument("-n", "--runs", type=int, default=5, help="rounds (default 5)")
    parser.add_argument("--before", type=Path, help="an older checkout to compare with")
    parser.add_argument(
        "--silent", action="store_true", help="also a listener that never answers (waited out)"
    )
    args = parser.parse_args()
    before = args.before.resolve() if args.before else None
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(64)  # never accepted: the kernel takes the connection, nobody answers
        silent = f"mqtt://127.0.0.1:{listener.getsockname()[1]}" if args.silent else None
        held = report(measure(cases(before, silent), args.runs), args.runs)
    raise SystemExit(0 if held else 1)


if __name__ == "__main__":
    main()
