"""The wall-clock time as every message carries it: seconds since the epoch, to the millisecond.

A module of its own so that a brain (through contract/goals.py) stamps its reports without
importing the fleet's whole wire (contract/wire.py): a brain starts on every launch and reload.
"""

from __future__ import annotations

import time


def now() -> float:
    return round(time.time(), 3)
