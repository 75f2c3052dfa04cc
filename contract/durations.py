"""Durations as people write them in flags and fleet.yaml: `90s`, `15m`, `2h`, `7d`, `1w`."""

from __future__ import annotations

import re

_DURATION = re.compile(r"^\s*([0-9]+(?:\.[0-9]+)?)\s*(s|m|h|d|w)?\s*$")  # not \d: any script's
_UNITS = {"s": 1, "m": 60, "h": 3600, "d": 86400, "w": 7 * 86400, None: 1}


def parse_duration(text: str) -> float:
    """`90s`, `15m`, `2h`, `7d`, `1w` (a bare number: seconds) in seconds; ValueError."""
    found = _DURATION.match(text)
    if found is None:
        raise ValueError(
            f"{text!r} is not a duration: a number with s, m, h, d or w (e.g. 30m, 2h, 7d)"
        )
    seconds = float(found.group(1)) * _UNITS[found.group(2)]
    if seconds <= 0:
        raise ValueError(f"{text!r} is not a positive duration")
    return seconds
