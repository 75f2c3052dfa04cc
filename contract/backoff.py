"""Exponential backoff: the delays between retries, doubling from a first delay up to a cap.

Pure; one definition for the agent's brain restarts, its broker reconnects and the reconciler.
"""

from __future__ import annotations

from dataclasses import dataclass

# 2.0 ** 1024 overflows a float; long before that every delay is at the cap anyway.
_MAX_DOUBLINGS = 1000


def exponential_delay(attempt: int, initial: float, maximum: float) -> float:
    """The delay before retry `attempt + 1` of a run of failures: `initial * 2**attempt`,
    at most `maximum`."""
    if attempt < 0:
        raise ValueError(f"attempt must be >= 0, got {attempt}")
    return float(min(maximum, initial * 2.0 ** min(attempt, _MAX_DOUBLINGS)))


@dataclass
class Backoff:
    """A run of failures: `next()` gives the delay before the next retry, `reset()` ends the
    run after a success."""

    initial: float
    maximum: float
    attempt: int = 0  # failures so far in this run

    def __post_init__(self) -> None:
        if not 0 < self.initial <= self.maximum:
            raise ValueError(
                f"backoff needs 0 < initial <= maximum, got {self.initial} and {self.maximum}"
            )

    def next(self) -> float:
        delay = exponential_delay(self.attempt, self.initial, self.maximum)
        self.attempt += 1
        return delay

    def reset(self) -> None:
        self.attempt = 0
