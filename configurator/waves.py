"""Which wave of a rollout each robot falls in: pure, deterministic, the same for `plan`, the
reconciler and `status`."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence

from robotconf.configurator.types import Wave

_SHARE = re.compile(r"^([0-9]{1,3})%$")  # not \d, which takes any script's digits


def matches(labels: Mapping[str, str], selector: Mapping[str, str]) -> bool:
    """A robot matches a selector when it has every label of it (an empty selector: all)."""
    return all(labels.get(key) == value for key, value in selector.items())


def assign_waves(robots: Mapping[str, Mapping[str, str]], waves: Sequence[Wave]) -> dict[str, int]:
    """robot id -> index of the first wave that takes it; robots no wave takes are absent.

    In wave order, robots in robot id order: a wave with a selector and no percent takes every
    matching robot not taken yet; with a percent, it takes matching robots until that share
    (rounded up) of all matching robots is taken, counting those earlier waves took; a wave
    with neither takes every robot left."""
    order = sorted(robots)
    placed: dict[str, int] = {}
    for index, wave in enumerate(waves):
        candidates = [r for r in order if matches(robots[r], wave.selector)]
        if wave.percent is None:
            for robot in candidates:
                placed.setdefault(robot, index)
            continue
        quota = math.ceil(len(candidates) * min(max(wave.percent, 0), 100) / 100)
        taken = sum(1 for robot in candidates if robot in placed)
        for robot in candidates:
            if taken >= quota:
                break
            if robot not in placed:
                placed[robot] = index
                taken += 1
    return placed


def failure_budget(max_failures: int | str, robots: int) -> int | None:
    """How many of a wave's `robots` may fail before the rollout stops: a count, or a share
    ('10%', rounded down); None when `max_failures` is neither (a validation error)."""
    if isinstance(max_failures, int) and not isinstance(max_failures, bool):
        return max_failures if max_failures >= 0 else None
    if isinstance(max_failures, str):
        share = _SHARE.fullmatch(max_failures.strip())
        if share is not None and int(share.group(1)) <= 100:
            return robots * int(share.group(1)) // 100
    return None
