"""The run's order for xdist's workers: each share starts with its long tests, nothing lost."""

from __future__ import annotations

from pathlib import Path

from tests.support.schedule import LONGEST, longest_first, shares


def test_shares_are_the_ones_worksteal_hands_out() -> None:
    assert shares(10, 4) == [2, 2, 3, 3] and shares(2344, 4) == [586] * 4
    assert shares(3, 4) == [0, 1, 1, 1]


def test_each_share_starts_with_its_long_tests_longest_first() -> None:
    ids = [f"t{i:02}::x" for i in range(20)]
    longest = ("t17::", "t03::", "t09::", "t18::", "t01::")  # by duration: t17 is the longest
    order = longest_first(ids, ids, 2, longest)
    assert sorted(order) == sorted(ids)
    first, second = order[:10], order[10:]
    assert first[:3] == ["t17::x", "t09::x", "t01::x"] and second[:2] == ["t03::x", "t18::x"]
    rest = [i for i in ids if not i.startswith(longest)]
    assert first[3:] + second[2:] == rest  # the others keep their order


def test_more_long_tests_than_a_share_loses_none() -> None:
    ids = [f"t{i}" for i in range(6)]
    order = longest_first(ids, ids, 4, ("t0", "t1", "t2", "t3", "t4"))
    assert sorted(order) == ids and order[0] == "t0"


def test_a_prefix_names_every_test_of_a_file_and_the_list_has_no_repeats() -> None:
    ids = ["a.py::x", "b.py::y[1]", "c.py::z", "b.py::y[2]"]
    # The tests of one entry stay together, on one worker: they may share a module's fixture.
    assert longest_first(ids, ids, 2, ("b.py::",)) == [
        "b.py::y[1]",
        "b.py::y[2]",
        "a.py::x",
        "c.py::z",
    ]
    assert len(set(LONGEST)) == len(LONGEST)


def test_every_long_test_named_still_exists() -> None:
    """A renamed test would only lose its place; still, the list should say what it means."""
    root = Path(__file__).resolve().parents[2]
    for prefix in LONGEST:
        path, _, name = prefix.partition("::")
        source = (root / path).read_text(encoding="utf-8")
        assert f"def {name}" in source or not name, prefix
