"""What a commit costs the reconciler's build step on a lab-sized repository (issue 14).

The repository comes from bench/generate.py (10,000 robots by default), written into a
temporary git repository (the bench commits to it). Each measurement runs in a process of its
own; wall times are medians, memory is the process's peak resident set (os.wait4):

  validate      `robotconf validate --repo DIR`: the work tree, the floor to compare with
  check --rev   `robotconf validate --repo DIR --rev HEAD`: the same files read from the commit
  full build    one process building the commit as a fresh reconciler does (read, validate,
                render every robot's Launch Request: `reconciler.desired.load_desired`)
  rebuild       one process holding the reconciler's build cache (`DesiredBuilder`): a first
                build, then N commits that each change one number in one scenario, each
                built after its `git commit`; p50 of those builds, and the process's resident
                memory after them (the cache and the last 4 builds; the controller keeps 2)

Run against an older checkout (PYTHONPATH=that checkout), the rebuild is a full build each
time: the same script measures before and after.

Targets: full build within 1.3x validate; check --rev within 1.3x validate. The last rebuild
is compared with a fresh full build of the same commit (same diagnostics, same requests).

    python bench/incremental.py [--repeat 3] [--edits 7] [--robots N] ...
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from dataclasses import asdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import generate  # bench/generate.py, next to this file
from validate_speed import Run, run_process, tail

BUILD_TARGET = 1.3  # a full build of a commit may take at most this many times validate

FULL_BUILD = """\
import sys, time
from pathlib import Path
from robotconf.reconciler.desired import load_desired
desired = load_desired(Path(sys.argv[1]), "HEAD")
assert desired.ok, desired.problems[:3]
print(len(desired.fleet.requests), "requests")
"""

REBUILD = """\
import json, resource, statistics, subprocess, sys, time
from pathlib import Path
from robotconf.configurator.render import render_fleet
from robotconf.configurator.workspace import check

try:
    from robotconf.reconciler.desired import DesiredBuilder
except ImportError:  # before incremental builds (measuring an older checkout): full builds
    from robotconf.reconciler.desired import load_desired as build
    rendered_again = lambda: -1
else:
    build = DesiredBuilder()
    rendered_again = lambda: build.cache.stats.robots_rendered

root, edits = Path(sys.argv[1]), int(sys.argv[2])

def git(*args):
    return subprocess.run(
        ["git", *args], cwd=root, check=True, capture_output=True, text=True
    ).stdout.strip()

def rss_mb():
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * resource.getpagesize() / 2**20

kept = []  # the controller keeps the last 4 builds
start = time.perf_counter()
kept.append(build(root, git("rev-parse", "HEAD")))
first = time.perf_counter() - start
first_mb = rss_mb()
assert kept[-1].ok, kept[-1].problems[:3]
builds, commits, rendered = [], [], []
scenarios = sorted((root / "configs" / "scenarios").glob("*.yaml"))
for i in range(edits):
    path = scenarios[(i * 37) % len(scenarios)]
    text = path.read_text()
    path.write_text(text.replace("ROLE:", f"EDIT: {i}\\n  ROLE:", 1))
    start = time.perf_counter()
    git("commit", "-qam", f"edit {i}")
    revision = git("rev-parse", "HEAD")
    committed = time.perf_counter()
    kept.append(build(root, revision))
    builds.append(time.perf_counter() - committed)
    commits.append(committed - start)
    kept = kept[-4:]
    rendered.append(rendered_again())
    assert kept[-1].ok, kept[-1].problems[:3]
resident = rss_mb()
full = check(root, kept[-1].revision)
expected = render_fleet(full.repo)
got = kept[-1].fleet
same = list(got.requests) == list(expected.requests) and all(
    got.requests[r].payload() == q.payload() for r, q in expected.requests.items()
)
print(json.dumps({
    "first": first, "builds": builds, "commits": commits, "rendered": rendered,
    "first_mb": first_mb, "resident_mb": resident, "same_as_full": same,
}))
"""


def median(runs: list[Run]) -> float:
    return statistics.median(run.seconds for run in runs)


def peak(runs: list[Run]) -> float:
    return max(run.peak_kib for run in runs) / 1024


def repeat(argv: list[str], cwd: Path, times: int, what: str) -> list[Run]:
    runs = []
    for _ in range(times):
        run = run_process(argv, cwd)
        if run.exit_code != 0:
            raise SystemExit(f"{what} exited {run.exit_code}:\n{tail(run.output)}")
        runs.append(run)
    return runs


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    bindir = Path(sys.executable).parent
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per measurement (default 3)")
    parser.add_argument("--edits", type=int, default=7, help="one-scenario commits (default 7)")
    parser.add_argument(
        "--robotconf",
        type=Path,
        default=bindir / "robotconf",
        help="the robotconf console script (default: next to this Python)",
    )
    for key, value in asdict(generate.Sizes()).items():
        parser.add_argument(
            f"--{key}", type=int, default=value, metavar="N", help=f"generator size ({value})"
        )
    args = parser.parse_args(argv)
    if args.repeat < 1 or args.edits < 1:
        parser.error("--repeat and --edits must be at least 1")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    sizes = generate.Sizes(**{key: getattr(args, key) for key in asdict(generate.Sizes())})
    python = sys.executable
    with tempfile.TemporaryDirectory(prefix="robotconf-incremental-") as folder:
        repo = Path(folder) / "lab"
        files = generate.generate(repo, sizes, use_git=True)
        print(f"{files} files, {sizes.robots} robots in {repo}", file=sys.stderr)
        validate = repeat(
            [str(args.robotconf), "validate", "--repo", str(repo)], repo, args.repeat, "validate"
        )
        from_commit = repeat(
            [str(args.robotconf), "validate", "--repo", str(repo), "--rev", "HEAD"],
            repo,
            args.repeat,
            "validate --rev HEAD",
        )
        full = repeat([python, "-c", FULL_BUILD, str(repo)], repo, args.repeat, "full build")
        rebuild = run_process([python, "-c", REBUILD, str(repo), str(args.edits)], repo)
        if rebuild.exit_code != 0:
            raise SystemExit(f"rebuild exited {rebuild.exit_code}:\n{tail(rebuild.output)}")
    found = json.loads(rebuild.output.strip().splitlines()[-1])
    floor = median(validate)
    print(f"{'measurement':<34} {'median s':>9} {'peak MB':>8} {'x validate':>10}")
    for name, runs in (
        ("validate (work tree)", validate),
        ("validate --rev HEAD (commit)", from_commit),
        ("full build of the commit", full),
    ):
        ratio = median(runs) / floor
        print(f"{name:<34} {median(runs):>9.3f} {peak(runs):>8.1f} {ratio:>10.2f}")
    builds, commits = found["builds"], found["commits"]
    again = ", ".join("all" if n < 0 else str(n) for n in found["rendered"])
    print(
        f"\nrebuild after a one-scenario commit: p50 {statistics.median(builds):.3f} s "
        f"(min {min(builds):.3f}, max {max(builds):.3f}; {len(builds)} commits; robots "
        f"rendered again: {again}); `git commit` itself "
        f"p50 {statistics.median(commits):.3f} s"
    )
    print(
        f"first build with the cache {found['first']:.3f} s, resident then "
        f"{found['first_mb']:.1f} MB; after the rebuilds (4 builds kept) "
        f"{found['resident_mb']:.1f} MB; last rebuild same as a full build: "
        f"{found['same_as_full']} (that check's full build makes the process's peak, "
        f"{rebuild.peak_kib / 1024:.1f} MB)"
    )
    verdicts = [
        ("full build", median(full) / floor),
        ("validate --rev HEAD", median(from_commit) / floor),
    ]
    print()
    for name, ratio in verdicts:
        met = "met" if ratio <= BUILD_TARGET else "MISSED"
        print(f"target {name} <= {BUILD_TARGET:g}x validate ({ratio:.2f}x): {met}")
    if not found["same_as_full"]:
        print("the last rebuild differs from a full build", file=sys.stderr)
        return 2
    return 0 if all(ratio <= BUILD_TARGET for _, ratio in verdicts) else 1


if __name__ == "__main__":
    sys.exit(main())
