"""Time `robotconf validate` on a lab-sized repository against two baselines.

The repository comes from bench/generate.py (generated once, then reused while its sizes are
unchanged). Each contender runs as its own process, a few times; the table shows the median
wall time, the peak resident memory (from the child's own rusage via os.wait4) and the
ratio to baseline (a):

  validate   `robotconf validate --repo DIR`: the whole-repository validation
  (a) yaml   one Python process parsing every YAML file once with PyYAML's C loader
             (`yaml.load(text, Loader=yaml.CSafeLoader)`): the floor for reading the files
  (b) check-jsonschema
             `check-jsonschema --schemafile schemas/<kind>.schema.json FILES...`, once per
             kind, on the schemas written by `robotconf schemas --repo DIR` (structure only:
             no cross-file references)

Targets: validate within 2x of (a), and faster than (b). Exit 0 when every contender ran and
the targets are met, 1 when a target is missed, 2 when a contender failed or is missing.

    python bench/validate_speed.py [--repo DIR] [--repeat N] [--regenerate] [--robots N] ...
                                   [--shape namespaced]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import generate  # bench/generate.py, next to this file

VALIDATE_TARGET = 2.0  # validate may take at most this many times baseline (a)

# The file kinds of a repository, as (kind, glob relative to the repository root).
KINDS: tuple[tuple[str, str], ...] = (
    ("platform", "models/platforms/*/platform.yaml"),
    ("robot-template", "models/platforms/*/robot-templates/*.yaml"),
    ("mapping-scheme", "models/platforms/*/mapping-schemes/*.yaml"),
    ("action", "models/actions/*.yaml"),
    ("task", "models/tasks/*.yaml"),
    ("environment", "models/environments/*.yaml"),
    ("capability", "configs/capabilities/*.yaml"),
    ("scenario", "configs/scenarios/*.yaml"),
    ("fleet", "configs/fleet.yaml"),
)

# Baseline (a): one process, one C-loader parse of every file named on stdin.
YAML_BASELINE = """\
import sys
import yaml
count = 0
for path in sys.stdin.read().splitlines():
    with open(path, encoding="utf-8") as handle:
        yaml.load(handle.read(), Loader=yaml.CSafeLoader)
    count += 1
print(count, "files parsed")
"""


@dataclass
class Run:
    """One process run: its wall time, peak RSS and outcome."""

    seconds: float
    peak_kib: int
    exit_code: int
    output: str


@dataclass
class Result:
    """All repetitions of one contender."""

    name: str
    runs: list[Run] = field(default_factory=list)
    error: str | None = None

    @property
    def median(self) -> float:
        return statistics.median(run.seconds for run in self.runs)

    @property
    def peak_mb(self) -> float:
        return max(run.peak_kib for run in self.runs) / 1024


def run_process(argv: Sequence[str], cwd: Path, stdin: str | None = None) -> Run:
    """Run one process to completion; read its own peak RSS from os.wait4."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as inp:
        if stdin is not None:
            inp.write(stdin.encode())
            inp.seek(0)
        start = time.perf_counter()
        proc = subprocess.Popen(
            list(argv),
            cwd=cwd,
            stdin=inp if stdin is not None else subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - start
        proc.returncode = os.waitstatus_to_exitcode(status)  # Popen must not wait again
        out.seek(0)
        output = out.read().decode(errors="replace")
    # ru_maxrss is in KiB on Linux (bytes on macOS).
    peak_kib = usage.ru_maxrss // 1024 if sys.platform == "darwin" else usage.ru_maxrss
    return Run(seconds, peak_kib, proc.returncode, output)


def combine(runs: list[Run]) -> Run:
    """Several processes run one after another as one measurement (check-jsonschema per kind)."""
    return Run(
        seconds=sum(run.seconds for run in runs),
        peak_kib=max((run.peak_kib for run in runs), default=0),
        exit_code=next((run.exit_code for run in runs if run.exit_code != 0), 0),
        output="".join(run.output for run in runs),
    )


def files_by_kind(repo: Path) -> dict[str, list[Path]]:
    return {kind: sorted(repo.glob(pattern)) for kind, pattern in KINDS}


def tail(text: str, lines: int = 15) -> str:
    return "\n".join(text.rstrip().splitlines()[-lines:])


# ---------------------------------------------------------------- preparing the repository


def ensure_repo(repo: Path, sizes: generate.Sizes, regenerate: bool, shape: str) -> None:
    marker = repo / generate.MARKER
    wanted = generate.marker(sizes, shape)
    if not regenerate and marker.exists():
        try:
            if json.loads(marker.read_text()) == wanted:
                print(f"reusing {repo}", file=sys.stderr)
                return
        except ValueError:
            pass
    print(f"generating {repo} ...", file=sys.stderr)
    start = time.perf_counter()
    files = generate.generate(repo, sizes, use_git=True, shape=shape)
    print(f"  {files} files in {time.perf_counter() - start:.1f} s", file=sys.stderr)


def ensure_schemas(repo: Path, robotconf: Path) -> str | None:
    """Write the repository's schemas/ with `robotconf schemas`; return an error or None."""
    if not robotconf.exists():
        return f"{robotconf} not found"
    run = run_process([str(robotconf), "schemas", "--repo", str(repo)], cwd=repo)
    if run.exit_code != 0:
        return f"`robotconf schemas` exited {run.exit_code}:\n{tail(run.output)}"
    missing = [k for k, _ in KINDS if not (repo / "schemas" / f"{k}.schema.json").exists()]
    if missing:
        return "`robotconf schemas` wrote no schema for: " + ", ".join(missing)
    return None


# ---------------------------------------------------------------- the contenders


def bench_validate(repo: Path, robotconf: Path, repeat: int) -> Result:
    result = Result("robotconf validate")
    if not robotconf.exists():
        result.error = f"{robotconf} not found"
        return result
    for _ in range(repeat):
        run = run_process([str(robotconf), "validate", "--repo", str(repo)], cwd=repo)
        if run.exit_code != 0:
            result.error = f"exited {run.exit_code} (the repository should be clean):\n" + tail(
                run.output
            )
            return result
        result.runs.append(run)
    return result


def bench_yaml(repo: Path, python: str, repeat: int) -> Result:
    result = Result("(a) PyYAML CSafeLoader")
    paths = "\n".join(str(p) for files in files_by_kind(repo).values() for p in files)
    for _ in range(repeat):
        run = run_process([python, "-c", YAML_BASELINE], cwd=repo, stdin=paths)
        if run.exit_code != 0:
            result.error = f"exited {run.exit_code}:\n{tail(run.output)}"
            return result
        result.runs.append(run)
    return result


def bench_check_jsonschema(
    repo: Path, check_jsonschema: Path, schema_error: str | None, repeat: int
) -> Result:
    result = Result("(b) check-jsonschema")
    if not check_jsonschema.exists():
        result.error = f"{check_jsonschema} not found (pip install -e '.[bench]')"
        return result
    if schema_error is not None:
        result.error = "no schemas: " + schema_error
        return result
    groups = [(kind, files) for kind, files in files_by_kind(repo).items() if files]
    for _ in range(repeat):
        runs = []
        for kind, files in groups:
            schema = repo / "schemas" / f"{kind}.schema.json"
            argv = [str(check_jsonschema), "--schemafile", str(schema), *map(str, files)]
            runs.append(run_process(argv, cwd=repo))
        run = combine(runs)
        if run.exit_code != 0:
            result.error = f"exited {run.exit_code}:\n{tail(run.output)}"
            return result
        result.runs.append(run)
    return result


# ---------------------------------------------------------------- report


def report(results: list[Result], baseline: Result) -> int:
    print(f"{'name':<26} {'median s':>9} {'peak MB':>8} {'x (a)':>7}  runs")
    for res in results:
        if res.error is not None or not res.runs:
            print(f"{res.name:<26} {'-':>9} {'-':>8} {'-':>7}  FAILED")
            continue
        ratio = "-"
        if baseline.runs and baseline.error is None:
            ratio = f"{res.median / baseline.median:.2f}"
        times = " ".join(f"{run.seconds:.2f}" for run in res.runs)
        print(f"{res.name:<26} {res.median:>9.3f} {res.peak_mb:>8.1f} {ratio:>7}  {times}")
    failed = [res for res in results if res.error is not None]
    for res in failed:
        print(f"\n{res.name}: {res.error}", file=sys.stderr)
    validate, _, jsonschema = results
    verdicts: list[bool] = []
    print()
    if validate.runs and baseline.runs:
        limit = VALIDATE_TARGET * baseline.median
        ok = validate.median <= limit
        verdicts.append(ok)
        print(
            f"target validate <= {VALIDATE_TARGET:g}x (a) ({limit:.3f} s): "
            f"{'met' if ok else 'MISSED'}"
        )
    if validate.runs and jsonschema.runs:
        ok = validate.median < jsonschema.median
        verdicts.append(ok)
        print(
            f"target validate faster than (b) ({jsonschema.median:.3f} s): "
            f"{'met' if ok else 'MISSED'}"
        )
    if failed:
        return 2
    return 0 if all(verdicts) else 1


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    bindir = Path(sys.executable).parent
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--repo",
        type=Path,
        default=generate.DEFAULT_TARGET,
        help=f"the generated repository (default: {generate.DEFAULT_TARGET})",
    )
    parser.add_argument("--repeat", type=int, default=3, help="runs per contender (default: 3)")
    parser.add_argument(
        "--regenerate",
        action="store_true",
        help="generate the repository even when it can be reused",
    )
    parser.add_argument(
        "--robotconf",
        type=Path,
        default=bindir / "robotconf",
        help="the robotconf console script (default: next to this Python)",
    )
    parser.add_argument(
        "--check-jsonschema",
        type=Path,
        default=bindir / "check-jsonschema",
        help="the check-jsonschema script (default: next to this Python)",
    )
    parser.add_argument(
        "--python", default=sys.executable, help="Python with PyYAML's C loader for baseline (a)"
    )
    for key, value in asdict(generate.Sizes()).items():
        parser.add_argument(
            f"--{key}",
            type=int,
            default=value,
            metavar="N",
            help=f"generator size (default: {value})",
        )
    generate.add_shape_option(parser)
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    repo: Path = args.repo.resolve()
    sizes = generate.Sizes(**{key: getattr(args, key) for key in asdict(generate.Sizes())})
    ensure_repo(repo, sizes, args.regenerate, args.shape)
    counts = {kind: len(files) for kind, files in files_by_kind(repo).items()}
    print(
        f"{sum(counts.values())} files: " + ", ".join(f"{n} {kind}" for kind, n in counts.items()),
        file=sys.stderr,
    )
    schema_error = ensure_schemas(repo, args.robotconf)
    validate = bench_validate(repo, args.robotconf, args.repeat)
    baseline = bench_yaml(repo, args.python, args.repeat)
    jsonschema = bench_check_jsonschema(repo, args.check_jsonschema, schema_error, args.repeat)
    return report([validate, baseline, jsonschema], baseline)


if __name__ == "__main__":
    sys.exit(main())
