"""What rule configuration costs a build (issue 21, item 6) on a lab-sized repository.

The repository comes from bench/generate.py (10,000 robots by default). In one process,
medians of --repeat runs:

  scan, no marker     finding the ignore comments of fleet.yaml, which has none (one search)
  scan, every line    the same with `# robotconf: ignore RC505` on every robot's line
  parse               parsing that fleet.yaml (what the scan is compared with)
  judge               applying the comments (all unused: one RC803 each) to the findings
  validate            the whole repository checked (`workspace.check`), without and with them

    python bench/ignore_comments.py [--repeat 5] [--robots N]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import generate  # bench/generate.py, next to this file

from robotconf.configurator.ruleconfig import ignore_comments, judge
from robotconf.configurator.workspace import check
from robotconf.contract.yamlio import parse_document

FLEET = "configs/fleet.yaml"
COMMENT = b"  # robotconf: ignore RC505"


def median(repeat: int, work: Callable[[], Any]) -> tuple[float, Any]:
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = work()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--robots", type=int, default=generate.Sizes().robots)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        lab = Path(folder) / "lab"
        generate.generate(lab, generate.Sizes(robots=args.robots), False)
        plain = (lab / FLEET).read_bytes()
        marked = b"\n".join(
            line + COMMENT if line.startswith(b"  ") and b"scenario:" in line else line
            for line in plain.split(b"\n")
        )
        rows: list[tuple[str, float]] = []
        doc = parse_document(FLEET, plain)
        rows.append(("scan, no marker", median(args.repeat, lambda: ignore_comments(doc))[0]))
        parse, marked_doc = median(args.repeat, lambda: parse_document(FLEET, marked))
        scan, found = median(args.repeat, lambda: ignore_comments(marked_doc))
        rows += [(f"scan, every line ({len(found):,} comments)", scan), ("parse", parse)]
        took, checked = median(args.repeat, lambda: check(lab))
        ignores = {FLEET: found}
        rows.append(
            ("judge", median(args.repeat, lambda: judge(checked.diagnostics, None, ignores))[0])
        )
        rows.append(("validate, no comment", took))
        (lab / FLEET).write_bytes(marked)
        rows.append(("validate, a comment a robot", median(args.repeat, lambda: check(lab))[0]))
    for name, seconds in rows:
        print(f"{name:40} {seconds * 1000:10.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
