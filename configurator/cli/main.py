"""Placeholder entry point, replaced below."""

import sys


def main(argv: list[str] | None = None) -> int:
    print("robotconf: not yet", file=sys.stderr)
    return 2
