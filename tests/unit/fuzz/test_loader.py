"""Property: a repository with any one file mangled loads and validates into located diagnostics,
and what validates renders into requests that read back intact."""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robotconf.configurator.render import render_fleet
from robotconf.configurator.workspace import check
from robotconf.contract.launch import LaunchRequest
from robotconf.contract.safejson import parse_object
from tests.unit.fuzz.strategies import mutated, yaml_text

ROOT = Path(__file__).resolve().parents[3]
FILES = sorted(
    [
        p.relative_to(ROOT).as_posix()
        for top in ("configs", "models")
        for p in (ROOT / top).rglob("*.yaml")
    ]
    + [".robotconf.yaml"]  # the rule configuration (issue 21, item 6)
)


@pytest.fixture(scope="module")
def lab() -> Iterator[Path]:
    folder = Path(tempfile.mkdtemp(prefix="robotconf-fuzz-"))
    for part in ("configs", "models"):
        shutil.copytree(ROOT / part, folder / part)
    shutil.copy(ROOT / ".robotconf.yaml", folder / ".robotconf.yaml")
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def validate_with(lab: Path, rel: str, content: bytes) -> None:
    target = lab / rel
    original = target.read_bytes()
    target.write_bytes(content)
    try:
        checked = check(lab)
        for d in checked.diagnostics:
            assert (lab / d.path).is_file(), d
            lines = (lab / d.path).read_bytes().count(b"\n") + 1
            assert 1 <= d.line <= lines, d
            assert d.col >= 1, d
            assert "\n" not in str(d), d
        if checked.ok:
            rendered = render_fleet(checked.repo)
            for request in rendered.requests.values():
                again = LaunchRequest.model_validate(parse_object(request.payload()))
                assert again.digest_matches()
    finally:
        target.write_bytes(original)


edits = st.sampled_from(FILES).flatmap(
    lambda rel: st.tuples(
        st.just(rel),
        st.one_of(
            mutated((ROOT / rel).read_bytes()),
            yaml_text.map(lambda t: t.encode("utf-8", "surrogatepass")),
        ),
    )
)


@given(edits)
def test_one_mangled_file(lab: Path, edit: tuple[str, bytes]) -> None:
    validate_with(lab, *edit)


_FLEET = (ROOT / "configs/fleet.yaml").read_bytes()
_IGNORES = st.text(alphabet="RC05816, #\"'|:-\n", max_size=30).map(
    lambda tail: b" # robotconf: ignore " + tail.encode()
)


@given(st.lists(st.tuples(st.integers(0, len(_FLEET)), _IGNORES), max_size=4))
def test_ignore_comments_anywhere(lab: Path, inserts: list[tuple[int, bytes]]) -> None:
    """Ignore comments (and look-alikes in values) at any place of the fleet: located
    diagnostics, never a crash."""
    content = _FLEET
    for at, text in sorted(inserts, reverse=True):
        content = content[:at] + text + content[at:]
    validate_with(lab, "configs/fleet.yaml", content)
