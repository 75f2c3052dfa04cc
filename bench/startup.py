"""Start-up time of whole `robotconf` processes: `--help`, `validate` on the example lab, and
`python -c pass` as the floor. N runs each (default 10); median and min, as a table.

    python bench/startup.py [-n 10]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def robotconf() -> list[str]:
    """The installed entry point next to this Python, else the one on PATH."""
    beside = Path(sys.executable).parent / "robotconf"
    found = str(beside) if beside.exists() else shutil.which("robotconf")
    if found is None:
        raise SystemExit("robotconf is not installed: run ./dev setup first")
    return [found]


def timed(argv: list[str], runs: int) -> list[float]:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        done = subprocess.run(argv, cwd=ROOT, capture_output=True)
        times.append(time.perf_counter() - start)
        if done.returncode not in (0, 1):
            raise SystemExit(f"{' '.join(argv)} exited {done.returncode}: {done.stderr.decode()}")
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", "--runs", type=int, default=10, help="runs per command (default 10)")
    runs = parser.parse_args().runs
    cases = [
        ("python -c pass", [sys.executable, "-c", "pass"]),
        ("robotconf --help", [*robotconf(), "--help"]),
        ("robotconf validate", [*robotconf(), "validate", "--repo", str(ROOT)]),
    ]
    print(f"{'command':<22} {'median':>8} {'min':>8}   ({runs} runs each)")
    for label, argv in cases:
        times = timed(argv, runs)
        print(f"{label:<22} {statistics.median(times):>7.3f}s {min(times):>7.3f}s")


if __name__ == "__main__":
    main()
