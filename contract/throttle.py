"""Log lines about what anyone may send in a loop, rate-limited: a few per interval, the next
one admitted saying how many were not. Agent-safe: the standard library only."""

from __future__ import annotations

from collections import deque


class Throttle:
    """At most `limit` lines per `every` seconds; the next one admitted says how many were
    not. With a limit above one, a few in a row are all said (an operator's second try is not
    hidden). Not thread-safe: its owner serialises calls."""

    def __init__(self, every: float, limit: int = 1) -> None:
        self.every = every
        self.limit = limit
        self._said: deque[float] = deque()
        self._quiet = 0

    def admit(self, line: str, now: float) -> str | None:
        while self._said and now - self._said[0] >= self.every:
            self._said.popleft()
        if len(self._said) >= self.limit:
            self._quiet += 1
            return None
        self._said.append(now)
        quiet, self._quiet = self._quiet, 0
        return line + (f" (and {quiet} more not logged)" if quiet else "")
