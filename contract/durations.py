"""Durations as people write them in flags and fleet.yaml: `90s`, `15m`, `2h`, `7d`, `1w`."""

from __future__ import annotations

import re

_DURATION = re.compile(r"^\s*([0-9]+(?:\.[0-9]+)?)\s*(s|m|h|d|w)?\s*$")  # not \d: any script's
_UNITS = {"s": 1, "m": 60, "h": 3600, "d": 86400, "w": 7 * 86400, None: 1}
# The longest duration anyone means (a ledger kept, a window looked back on, a wave's wait):
# 10 years. Longer is a typo, and far longer overflows what times and dates can hold.
MAX_SECONDS = 3650 * 86400


def parse_duration(text: str, clamp: bool = False) -> float:
    """`90s`, `15m`, `2h`, `7d`, `1w` (a bare number: seconds) in seconds; ValueError. Over
    MAX_SECONDS is refused, or with `clamp` taken as MAX_SECONDS (a window to look back on:
    longer than anything kept is everything)."""
    found = _DURATION.match(text)
    if found is None:
        raise ValueError(
            f"{text!r} is not a duration: a number with s, m, h, d or w (e.g. 30m, 2h, 7d)"
        )
    seconds = float(found.group(1)) * _UNITS[found.group(2)]
    if seconds > MAX_SECONDS and clamp:
        return MAX_SECONDS
    return checked_seconds(seconds, repr(text))


def checked_seconds(seconds: float, said: str) -> float:
    """`seconds` when it is a duration one means: over 0, at most MAX_SECONDS; ValueError
    naming the value as `said` otherwise. The one rule for durations written as text or as a
    number of seconds."""
    if seconds <= 0:
        raise ValueError(f"{said} is not a positive duration")
    if seconds > MAX_SECONDS:
        raise ValueError(f"{said} is too long a duration: at most 3650d (10 years)")
    return seconds
