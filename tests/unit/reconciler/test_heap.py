"""heap.release gives the pages a large step freed back to the system (glibc), and is
harmless where there is nothing to give back or no glibc."""

from __future__ import annotations

from pathlib import Path

import pytest

from robotconf.reconciler import heap


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    pytest.skip("no /proc/self/status")


@pytest.mark.skipif(heap._malloc_trim() is None, reason="not glibc: release is a no-op")
def test_release_returns_what_a_large_step_freed_between_live_objects() -> None:
    # 60 MB in 3 KB chunks (over pymalloc's limit: the C heap's), one in ten kept alive, as
    # a publish leaves the requests it keeps between the payloads it dropped.
    chunks = [bytes(3000) + i.to_bytes(4, "big") for i in range(20_000)]
    kept = chunks[::10]
    del chunks
    heap.release()  # whatever the allocation left behind
    before = _rss_mb()
    spread = [bytes(3000) + i.to_bytes(4, "big") for i in range(20_000)]
    kept += spread[::10]
    del spread
    held = _rss_mb()
    heap.release()
    after = _rss_mb()
    assert held - after > 20, (before, held, after)
    assert len(kept) == 4000


def test_release_twice_and_without_glibc_does_nothing_wrong(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    heap.release()
    heap.release()
    monkeypatch.setattr(heap, "_malloc_trim", lambda: None)
    heap.release()
