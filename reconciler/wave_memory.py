"""What the reconciler saw of a rollout's current wave, kept on a retained topic of its own so
that a restarted reconciler resumes from it: pure (the model, and sets <-> bitmaps).

Sets of robots are bitmaps over the wave's changed robots in id order (10,000 robots: 1.7 KB
each), bound to that list by its digest: a record of another list is not trusted, never
misread.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

from pydantic import BaseModel, ConfigDict, Field


class WaveRecord(BaseModel):
    """`<prefix>/reconciler/rollout` (retained): the current wave's observations.

    Apart from the reconciler's status on purpose: that status is also the reconciler's Last
    Will, fixed when it was set, and would take back at a crash what the wave established since.
    """

    model_config = ConfigDict(extra="ignore", frozen=True)

    revision: str
    wave: int
    wave_started_at: float
    members: str = Field(description="digest of the wave's changed robots, in id order")
    watching_since: float = Field(
        description="when the reconciler last (re)learned the robots' statuses"
    )
    seen: str = Field("", description="seen online while its new request was held")
    healthy: str = Field("", description="seen running the new request for healthy_after")
    failed: str = Field("", description="failed the wave: stays failed")
    rejecting: str = Field("", description="rejected a request already as the wave began")
    doubted: str = Field("", description="seen, then dark when the statuses were learned anew")
    deferring: str = Field("", description="seen deferring (its brain's hold file) at last look")
    held_since: float | None = Field(
        None, description="when a group of the wave was first held for a busy robot of it"
    )
    deferred_at: float | None = Field(
        None, description="when a robot was last seen deferring, or done deferring"
    )


@dataclass
class WaveMemory:
    """A wave's observations as sets, for the robots in `members` (sorted)."""

    revision: str
    wave: int
    wave_started_at: float
    members: Sequence[str]
    watching_since: float
    seen: set[str] = field(default_factory=set)
    healthy: set[str] = field(default_factory=set)
    failed: set[str] = field(default_factory=set)
    rejecting: set[str] = field(default_factory=set)
    doubted: set[str] = field(default_factory=set)
    deferring: set[str] = field(default_factory=set)
    deferred_at: float | None = None
    held_since: float | None = None

    def record(self) -> WaveRecord:
        members = self.members
        return WaveRecord(
            revision=self.revision,
            wave=self.wave,
            wave_started_at=self.wave_started_at,
            members=members_digest(members),
            watching_since=self.watching_since,
            seen=_bits(members, self.seen),
            healthy=_bits(members, self.healthy),
            failed=_bits(members, self.failed),
            rejecting=_bits(members, self.rejecting),
            doubted=_bits(members, self.doubted),
            deferring=_bits(members, self.deferring),
            deferred_at=self.deferred_at,
            held_since=self.held_since,
        )


def members_digest(members: Iterable[str]) -> str:
    return hashlib.sha256("\n".join(members).encode()).hexdigest()[:32]


def memory_of(
    record: WaveRecord | None,
    revision: str,
    wave: int,
    wave_started_at: float,
    members: Sequence[str],
) -> WaveMemory | None:
    """The record's sets when it is about this very wave (revision, wave, start, robots);
    None for any other record, or one whose bitmaps are unreadable."""
    if (
        record is None
        or record.revision != revision
        or record.wave != wave
        or record.wave_started_at != wave_started_at
        or record.members != members_digest(members)
    ):
        return None
    try:
        return WaveMemory(
            revision,
            wave,
            wave_started_at,
            members,
            record.watching_since,
            seen=_members(members, record.seen),
            healthy=_members(members, record.healthy),
            failed=_members(members, record.failed),
            rejecting=_members(members, record.rejecting),
            doubted=_members(members, record.doubted),
            deferring=_members(members, record.deferring),
            deferred_at=record.deferred_at,
            held_since=record.held_since,
        )
    except ValueError:
        return None


def _bits(members: Sequence[str], chosen: set[str]) -> str:
    if not chosen:
        return ""
    bits = bytearray((len(members) + 7) // 8)
    for index, robot in enumerate(members):
        if robot in chosen:
            bits[index >> 3] |= 1 << (index & 7)
    return base64.b64encode(bytes(bits)).decode("ascii")


def _members(members: Sequence[str], text: str) -> set[str]:
    if not text:
        return set()
    try:
        bits = base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError):
        raise ValueError("not base64") from None
    if len(bits) != (len(members) + 7) // 8:
        raise ValueError("a bitmap of another length")
    return {robot for index, robot in enumerate(members) if bits[index >> 3] >> (index & 7) & 1}
