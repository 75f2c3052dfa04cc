"""Start-up of whole `robotconf` processes against the floor, `python -c "import yaml, pydantic"`:
starting Python and importing PyYAML and pydantic, what every run of a hook pays anyway.

    python bench/startup.py [-n 15] [--repo PATH] [--before CHECKOUT] [--decompose]

--before runs `--help` and `validate` of an older checkout too (PYTHONPATH=CHECKOUT), in the
same rounds, so before and after meet the same machine.

--decompose adds, in the same rounds, the steps from the floor to `validate`: importing
pydantic's models (`pydantic.main`), then click, then everything `validate` imports (the
collector paused, as robotconf imports a command); and, in a process of its own at each
round, how much of that last import is building pydantic models (the time in pydantic's model
class constructor) and how much is the rest (our modules, and what they import).

Each round runs every command once, in turn (A B C D, A B C D, ...), so a machine that speeds
up or slows down during the call moves them all alike; one warm-up round is not counted (it
also writes the bytecode an installed package would have: PYTHONDONTWRITEBYTECODE is dropped
for the children). Medians of wall and CPU (user + system) seconds, each as a ratio to the
floor; the target is 1.6x of the floor's wall median for `--help` and `validate`.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGET = 1.6
FLOOR = "import yaml, pydantic"
# Not a target: what any process that validates with pydantic pays at least (BaseModel's
# import, one model built, pydantic's plugin look-up), to show how much of a ratio is ours.
PYDANTIC_LEAST = (
    "import yaml\nfrom pydantic import BaseModel\nclass A(BaseModel):\n    x: int\nA(x=1)"
)


def robotconf() -> str:
    """The installed entry point next to this Python, else the one on PATH."""
    beside = Path(sys.executable).parent / "robotconf"
    found = str(beside) if beside.exists() else shutil.which("robotconf")
    if found is None:
        raise SystemExit("robotconf is not installed: run ./dev setup first")
    return found


Case = tuple[str, list[str], dict[str, str]]  # label, argv, environment variables set
# What `robotconf validate` imports, as it imports it (the collector paused).
VALIDATE_IMPORTS = (
    "import gc\ngc.disable()\nimport yaml, pydantic.main, click\n"
    "import robotconf.workstation.cli.main, robotconf.workstation.cli.validate"
)
# The same import in one process, timed inside: milliseconds in pydantic's model class
# constructor (the outermost call: building every model) and in the whole import.
MODEL_PROBE = """\
import gc, time
gc.disable()
import yaml, pydantic.main, click
from pydantic._internal import _model_construction as construction

built, depth, new = [0.0], [0], construction.ModelMetaclass.__new__

def timed(mcs, *args, **kwargs):
    depth[0] += 1
    start = time.perf_counter()
    try:
        return new(mcs, *args, **kwargs)
    finally:
        depth[0] -= 1
        if not depth[0]:
            built[0] += time.perf_counter() - start

construction.ModelMetaclass.__new__ = timed
start = time.perf_counter()
import robotconf.workstation.cli.main, robotconf.workstation.cli.validate
print(built[0], time.perf_counter() - start)
"""


def cases(repo: Path, before: Path | None, decompose: bool = False) -> list[Case]:
    python, entry = sys.executable, robotconf()
    table: list[Case] = [
        ("python -c pass", [python, "-c", "pass"], {}),
        ("floor: import yaml, pydantic", [python, "-c", FLOOR], {}),
        ("(pydantic's least)", [python, "-c", PYDANTIC_LEAST], {}),
        ("robotconf --help", [entry, "--help"], {}),
        ("robotconf validate", [entry, "validate", "--repo", str(repo)], {}),
    ]
    if decompose:
        table[2:2] = [
            ("+ pydantic.main", [python, "-c", "import yaml, pydantic.main"], {}),
            ("+ click", [python, "-c", "import yaml, pydantic.main, click"], {}),
            ("+ validate's imports", [python, "-c", VALIDATE_IMPORTS], {}),
        ]
    if before is not None:
        older = {"PYTHONPATH": str(before)}
        old = older_entry(before, entry)
        table.append(("  before: --help", [*old, "--help"], older))
        table.append(("  before: validate", [*old, "validate", "--repo", str(repo)], older))
    return table


def older_entry(checkout: Path, entry: str) -> list[str]:
    """The command that starts `checkout`'s robotconf: the installed entry point imports
    robotconf.workstation.cli, which a checkout from before the one namespace (issue 33) lacks;
    there its own top-level `workstation.cli` is started as the entry point would (the
    checkout first on sys.path: `-c` puts the working folder, this checkout, before
    PYTHONPATH)."""
    if (checkout / "robotconf" / "workstation").exists():
        return [entry]
    shim = f"import sys\nsys.path.insert(0, {str(checkout)!r})\nsys.argv[0] = 'robotconf'\n"
    return [sys.executable, "-c", shim + "from workstation.cli import main\nsys.exit(main())"]


def run_once(argv: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall and CPU seconds of one whole process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=ROOT, capture_output=True, env=env)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(argv)} exited {done.returncode}: {done.stderr.decode()}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def measure(table: list[Case], rounds: int) -> dict[str, list[tuple[float, float]]]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    times: dict[str, list[tuple[float, float]]] = {label: [] for label, _, _ in table}
    for round_number in range(rounds + 1):
        for label, argv, extra in table:
            timing = run_once(argv, {**env, **extra})
            if round_number:  # round 0 warms up
                times[label].append(timing)
    return times


def probe_models(rounds: int) -> None:
    """How much of validate's imports is building pydantic models: medians of `rounds`
    processes (after the other rounds, on the same machine)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    found = []
    for _ in range(rounds + 1):
        done = subprocess.run(
            [sys.executable, "-c", MODEL_PROBE], cwd=ROOT, capture_output=True, env=env, text=True
        )
        if done.returncode != 0:
            raise SystemExit(f"the model probe failed: {done.stderr}")
        found.append(tuple(map(float, done.stdout.split())))
    models = statistics.median(m for m, _ in found[1:])
    whole = statistics.median(w for _, w in found[1:])
    print(
        f"validate's imports, inside one process: {whole * 1000:.1f} ms, of which building "
        f"pydantic models {models * 1000:.1f} ms and the rest {(whole - models) * 1000:.1f} ms "
        f"(medians of {rounds})"
    )


def report(times: dict[str, list[tuple[float, float]]], rounds: int) -> bool:
    """Prints the table; True when `--help` and `validate` are within TARGET of the floor."""
    floor = times["floor: import yaml, pydantic"]
    floor_wall = statistics.median(w for w, _ in floor)
    floor_cpu = statistics.median(c for _, c in floor)
    print(f"{'command':<30} {'wall':>7} {'x floor':>8} {'cpu':>7} {'x floor':>8}")
    held = True
    for label, runs in times.items():
        wall = statistics.median(w for w, _ in runs)
        cpu = statistics.median(c for _, c in runs)
        print(
            f"{label:<30} {wall:>6.3f}s {wall / floor_wall:>7.2f}x "
            f"{cpu:>6.3f}s {cpu / floor_cpu:>7.2f}x"
        )
        if label.startswith("robotconf"):  # ours, not the older checkout's
            held = held and wall / floor_wall <= TARGET
    print(f"medians of {rounds} alternating rounds (one warm-up round not counted)")
    verdict = "holds" if held else "does NOT hold"
    print(f"target: --help and validate within {TARGET}x of the floor's wall median: {verdict}")
    return held


def main() -> None:
    parser = argparse.ArgumentParser(description="start-up of robotconf against the floor")
    parser.add_argument("-n", "--runs", type=int, default=15, help="rounds (default 15)")
    parser.add_argument(
        "--repo", type=Path, default=ROOT, help="repository to validate (default: the example)"
    )
    parser.add_argument("--before", type=Path, help="an older checkout to compare with")
    parser.add_argument(
        "--decompose", action="store_true", help="also time the steps from the floor to validate"
    )
    args = parser.parse_args()
    before = args.before.resolve() if args.before else None
    table = cases(args.repo.resolve(), before, args.decompose)
    report(measure(table, args.runs), args.runs)
    if args.decompose:
        probe_models(args.runs)


if __name__ == "__main__":
    main()
