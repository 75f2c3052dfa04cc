"""Incremental builds give exactly the verdicts of full builds (issue 14, item 1).

Random sequences of edits (Hypothesis) on the example lab and on a small generated lab: after
every step, the incremental build's diagnostics and rendered requests are compared with a full
build's, byte for byte. Then what a change costs: only the files, units and robots it can
affect are parsed, checked and rendered again, and the cache holds what the newest build uses.
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys
import tempfile
from collections.abc import Iterator, Sequence
from functools import cache
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, rule

from robotconf.configurator.incremental import BuildCache
from robotconf.configurator.loader import blob_id
from robotconf.configurator.render import FleetRender, RenderError, render_fleet
from robotconf.configurator.workspace import Checked, check_source

ROOT = Path(__file__).resolve().parents[2]
FLEET = "configs/fleet.yaml"


class MemorySource:
    """A repository held in memory: as a commit (blob ids known before reading) or as a work
    tree (known only from the bytes)."""

    def __init__(self, files: dict[str, bytes], revision: str, *, commit: bool) -> None:
        self._files = dict(files)
        self._revision = revision
        self._commit = commit

    def files(self) -> list[str]:
        return sorted(self._files)

    def refused(self) -> dict[str, str]:
        return {}

    def read(self, path: str) -> bytes:
        return self._files[path]

    def read_each(self, paths: Sequence[str]) -> Iterator[tuple[str, bytes | OSError]]:
        for path in paths:
            yield path, self._files[path]

    def blob_id(self, path: str) -> str | None:
        return blob_id(self._files[path]) if self._commit else None

    @property
    def revision(self) -> str:
        return self._revision


def _read_tree(root: Path) -> dict[str, bytes]:
    return {
        p.relative_to(root).as_posix(): p.read_bytes()
        for top in ("configs", "models")
        for p in sorted((root / top).rglob("*"))
        if p.is_file()
    }


@cache
def example_lab() -> dict[str, bytes]:
    return _read_tree(ROOT)


@cache
def generated_lab() -> dict[str, bytes]:
    spec = importlib.util.spec_from_file_location("bench_generate", ROOT / "bench" / "generate.py")
    assert spec is not None and spec.loader is not None
    generate: Any = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = generate  # its dataclasses look their module up
    spec.loader.exec_module(generate)
    sizes = generate.Sizes(
        robots=40,
        scenarios=10,
        capabilities=6,
        actions=14,
        tasks=6,
        templates=4,
        environments=3,
        locations=5,
        schemes=2,
        mappings=10,
    )
    with tempfile.TemporaryDirectory() as folder:
        generate.generate(Path(folder) / "lab", sizes)
        return _read_tree(Path(folder) / "lab")


BASES = {"example": example_lab, "generated": generated_lab}


def render_or_error(build: Any) -> FleetRender | str:
    try:
        rendered: FleetRender = build()
    except RenderError as exc:
        return f"RenderError: {exc}"
    return rendered


def assert_same_fleet(got: FleetRender | str, expected: FleetRender | str) -> None:
    if isinstance(expected, str) or isinstance(got, str):
        assert got == expected
        return
    assert isinstance(got, FleetRender)
    assert got.revision == expected.revision
    assert list(got.requests) == list(expected.requests)
    for robot_id, request in expected.requests.items():
        mine = got.requests[robot_id]
        assert mine.payload() == request.payload(), robot_id
        assert (mine.digest, mine.restart_digest) == (request.digest, request.restart_digest)
        assert mine.model() == request.model()
    assert got.scenario_of == expected.scenario_of
    assert got.needed_by == expected.needed_by
    assert got.labels == expected.labels
    assert got.suspended == expected.suspended
    assert (got.allow_empty, got.rollout) == (expected.allow_empty, expected.rollout)


def full_build(files: dict[str, bytes], revision: str) -> tuple[Checked, FleetRender | str | None]:
    checked = check_source(MemorySource(files, revision, commit=True))
    if not checked.ok:
        return checked, None
    return checked, render_or_error(lambda: render_fleet(checked.repo))


def incremental_build(
    cache_: BuildCache, files: dict[str, bytes], revision: str, *, commit: bool = True
) -> tuple[Checked, FleetRender | str | None]:
    checked = cache_.check(MemorySource(files, revision, commit=commit))
    if not checked.ok:
        return checked, None
    return checked, render_or_error(lambda: cache_.render(checked))


# ---------------------------------------------------------------- random sequences of edits

_NUMBER = re.compile(rb"(?<![\w.\-/])-?\d+(?:\.\d+)?(?![\w.\-/])")
_WORD = re.compile(rb"[A-Za-z_][A-Za-z0-9_.\-]*")
_NUMBERS = [b"0", b"1", b"2", b"0.1", b"0.25", b"-5", b"1000", b"3.5", b"true", b"x", b"'7'"]
_RULE_CONFIGURATION = ".robotconf.yaml"
_TUNED = ["RC505", "RC608", "RC501", "RC302", "RC706", "RC803"]
_BOGUS = [b"nothing", b"Follow", b"ROS2", b"ROS1", b"scenario-0001", b"capability-000", b"x"]


def _payload_lines(text: bytes) -> list[tuple[int, int]]:
    """(start, end) of each line that is not the editor modeline."""
    spans, start = [], 0
    for line in text.split(b"\n"):
        if not line.startswith(b"# yaml-language-server"):
            spans.append((start, start + len(line)))
        start += len(line) + 1
    return spans


def _matches(pattern: re.Pattern[bytes], text: bytes) -> list[re.Match[bytes]]:
    spans = _payload_lines(text)
    return [m for m in pattern.finditer(text) if any(a <= m.start() < b for a, b in spans)]


class IncrementalMatchesFull(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.files: dict[str, bytes] = {}
        self.base: dict[str, bytes] = {}
        self.cache = BuildCache()
        self.commit = True
        self.step = 0

    @initialize(base=st.sampled_from(sorted(BASES)), commit=st.booleans())
    def start(self, base: str, commit: bool) -> None:
        self.base = BASES[base]()
        self.files = dict(self.base)
        self.commit = commit

    def _yaml(self, prefix: str = "") -> list[str]:
        return [p for p in sorted(self.files) if p.startswith(prefix) and p.endswith(".yaml")]

    def _vocabulary(self) -> list[bytes]:
        words = {Path(p).stem.encode() for p in self.files}
        return sorted(words) + _BOGUS

    @rule(data=st.data())
    def change_a_number(self, data: st.DataObject) -> None:
        paths = [p for p in self._yaml() if _matches(_NUMBER, self.files[p])]
        scenarios = [p for p in paths if p.startswith("configs/scenarios/")]
        path = data.draw(st.sampled_from(scenarios or paths)) if paths else None
        if path is None:
            return
        text = self.files[path]
        found = data.draw(st.sampled_from(_matches(_NUMBER, text)))
        new = data.draw(st.sampled_from(_NUMBERS))
        self.files[path] = text[: found.start()] + new + text[found.end() :]

    @rule(data=st.data())
    def change_a_word(self, data: st.DataObject) -> None:
        """A catalogue entry's field or a configuration's reference changed: a name becomes
        another (dependents may turn invalid, or valid again)."""
        paths = [p for p in self._yaml() if _matches(_WORD, self.files[p])]
        path = data.draw(st.sampled_from(paths)) if paths else None
        if path is None:
            return
        text = self.files[path]
        found = data.draw(st.sampled_from(_matches(_WORD, text)))
        new = data.draw(st.sampled_from(self._vocabulary()))
        self.files[path] = text[: found.start()] + new + text[found.end() :]

    @rule(data=st.data())
    def rename_a_file(self, data: st.DataObject) -> None:
        paths = self._yaml()
        if not paths:
            return
        path = data.draw(st.sampled_from(paths))
        stem = data.draw(st.sampled_from([*self._vocabulary(), b"renamed"])).decode()
        suffix = data.draw(st.sampled_from([".yaml", ".yaml", ".yml"]))
        target = f"{path.rsplit('/', 1)[0]}/{stem}{suffix}"
        self.files[target] = self.files.pop(path)

    @rule(data=st.data())
    def delete_a_file(self, data: st.DataObject) -> None:
        paths = self._yaml()
        if len(paths) > 3:
            del self.files[data.draw(st.sampled_from(paths))]

    @rule(data=st.data())
    def copy_a_file(self, data: st.DataObject) -> None:
        paths = self._yaml()
        if paths:
            path = data.draw(st.sampled_from(paths))
            self.files[path.removesuffix(".yaml") + "-copy.yaml"] = self.files[path]

    @rule(data=st.data())
    def break_yaml(self, data: st.DataObject) -> None:
        paths = self._yaml()
        if not paths:
            return
        path = data.draw(st.sampled_from(paths))
        how = data.draw(st.sampled_from([b"\nbroken: [\n", b"\n\t- tab\n", b"\n---\nx: 1\n", b""]))
        self.files[path] = self.files[path] + how if how else b"- a list\n"

    @rule(data=st.data())
    def restore_a_file(self, data: st.DataObject) -> None:
        """Back to the base version (a revert): content seen before, maybe at another path."""
        path = data.draw(st.sampled_from(sorted(self.base)))
        self.files[path] = self.base[path]

    @rule(data=st.data())
    def add_a_robot(self, data: st.DataObject) -> None:
        fleet = self.files.get(FLEET, b"")
        if b"robots:\n" not in fleet:
            return
        scenarios = [Path(p).stem for p in self._yaml("configs/scenarios/")] or ["none"]
        scenario = data.draw(st.sampled_from([*scenarios, "no-such-scenario"]))
        self.step += 1
        robot = f"  added-{self.step}: {{scenario: {scenario}, namespace: added_{self.step}}}\n"
        if data.draw(st.booleans()):  # without a namespace: its names may clash (RC505)
            robot = f"  added-{self.step}: {{scenario: {scenario}}}\n"
        self.files[FLEET] = fleet.replace(b"robots:\n", b"robots:\n" + robot.encode(), 1)

    @rule(data=st.data())
    def reassign_a_robot(self, data: st.DataObject) -> None:
        fleet = self.files.get(FLEET, b"")
        found = list(re.finditer(rb"scenario: ([\w.\-]+)", fleet))
        scenarios = [Path(p).stem.encode() for p in self._yaml("configs/scenarios/")]
        if not found or not scenarios:
            return
        which = data.draw(st.sampled_from(found))
        new = data.draw(st.sampled_from(scenarios))
        self.files[FLEET] = fleet[: which.start(1)] + new + fleet[which.end(1) :]

    @rule(data=st.data())
    def change_a_robot(self, data: st.DataObject) -> None:
        """A robot's name, namespace, labels or suspension: its scenario stays the same."""
        fleet = self.files.get(FLEET, b"")
        lines = [m for m in re.finditer(rb"^  [\w.\-]+: \{.*\}$", fleet, re.MULTILINE)]
        if not lines:
            return
        line = data.draw(st.sampled_from(lines))
        text = line.group()
        how = data.draw(st.sampled_from(["namespace", "no-namespace", "name", "suspend", "label"]))
        if how == "namespace":
            new = data.draw(st.sampled_from([b"shared", b"other_ns", b"bad ns", b"x" * 300]))
            changed = re.sub(rb"namespace: [^,}]+", b"namespace: " + new, text)
            if changed == text:
                changed = text[:-1] + b", namespace: " + new + b"}"
        elif how == "no-namespace":
            changed = re.sub(rb", namespace: [^,}]+", b"", text)
        elif how == "name":
            changed = text[:-1] + b", name: Renamed}" if b"name:" not in text else text
        elif how == "suspend":
            changed = text[:-1] + b", suspended: true}" if b"suspended" not in text else text
        else:
            changed = text[:-1] + b", labels: {ring: canary}}" if b"labels" not in text else text
        self.files[FLEET] = fleet[: line.start()] + changed + fleet[line.end() :]

    @rule(data=st.data())
    def change_a_mapping_name(self, data: st.DataObject) -> None:
        """A mapping scheme's name made absolute, relative, per robot or shared: which robots'
        names clash changes without the fleet changing."""
        schemes = self._yaml("models/platforms/")
        found = [
            (p, m)
            for p in schemes
            if "/mapping-schemes/" in p
            for m in re.finditer(rb"name: ([^,}\s]+)", self.files[p])
        ]
        if not found:
            return
        path, which = data.draw(st.sampled_from(found))
        name = which.group(1).strip(b"/").removeprefix(b"{namespace}/")
        new = data.draw(
            st.sampled_from([b"/" + name, name, b"{namespace}/" + name, b"/shared", b"~/x"])
        )
        text = self.files[path]
        self.files[path] = text[: which.start(1)] + new + text[which.end(1) :]

    @rule(data=st.data())
    def tune_a_rule(self, data: st.DataObject) -> None:
        """`.robotconf.yaml` written, changed or removed (issue 21, item 6): the verdicts change
        though no rule reads it."""
        codes = data.draw(st.lists(st.sampled_from(_TUNED), max_size=3, unique=True))
        if not codes:
            self.files.pop(_RULE_CONFIGURATION, None)
            return
        levels = [data.draw(st.sampled_from(["error", "warning", "off", "loud"])) for _ in codes]
        lines = "".join(f"  {code}: {level}\n" for code, level in zip(codes, levels, strict=True))
        self.files[_RULE_CONFIGURATION] = f"rules:\n{lines}".encode()

    @rule(data=st.data())
    def ignore_on_a_line(self, data: st.DataObject) -> None:
        """`# robotconf: ignore CODE` at the end of a line of the fleet or a scheme."""
        paths = [p for p in self._yaml() if p == FLEET or "/mapping-schemes/" in p]
        path = data.draw(st.sampled_from(paths)) if paths else None
        if path is None:
            return
        lines = self.files[path].split(b"\n")
        index = data.draw(st.integers(0, len(lines) - 1))
        code = data.draw(st.sampled_from(_TUNED))
        lines[index] += f"  # robotconf: ignore {code}".encode()
        self.files[path] = b"\n".join(lines)

    @invariant()
    def same_as_a_full_build(self) -> None:
        if not self.files:
            return
        self.step += 1
        revision = f"{self.step:040x}"
        expected, expected_fleet = full_build(self.files, revision)
        got, got_fleet = incremental_build(self.cache, self.files, revision, commit=self.commit)
        assert got.diagnostics == expected.diagnostics
        assert got.repo.files_read == expected.repo.files_read
        if expected_fleet is not None:
            assert got_fleet is not None
            assert_same_fleet(got_fleet, expected_fleet)


_EXAMPLES = {"deep": 1_000, "quick": 10}.get(os.environ.get("HYPOTHESIS_PROFILE", ""), 60)

TestIncrementalMatchesFull = IncrementalMatchesFull.TestCase
TestIncrementalMatchesFull.settings = settings(
    max_examples=_EXAMPLES,
    stateful_step_count=12,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


# ---------------------------------------------------------------- what a change costs


def _edit(files: dict[str, bytes], path: str, old: bytes, new: bytes) -> dict[str, bytes]:
    assert old in files[path], (path, old)
    return {**files, path: files[path].replace(old, new, 1)}


def _robots_of(rendered: FleetRender, scenario: str) -> int:
    return sum(1 for s in rendered.scenario_of.values() if s == scenario)


@pytest.fixture
def built() -> tuple[BuildCache, dict[str, bytes], FleetRender]:
    files = generated_lab()
    cache_ = BuildCache()
    checked, rendered = incremental_build(cache_, files, "1" * 40)
    assert checked.ok and isinstance(rendered, FleetRender)
    assert cache_.stats.files_parsed == len(files)
    return cache_, files, rendered


def test_a_new_commit_with_the_same_files_reuses_everything(built: Any) -> None:
    cache_, files, first = built
    _, rendered = incremental_build(cache_, files, "2" * 40)
    stats = cache_.stats
    assert (stats.files_parsed, stats.units_run, stats.derived) == (0, [], [])
    assert (stats.scenarios_rendered, stats.robots_rendered) == ([], 0)
    assert isinstance(rendered, FleetRender) and rendered.revision == "2" * 40
    assert all(r.revision == "2" * 40 for r in rendered.requests.values())
    assert {r: q.digest for r, q in rendered.requests.items()} == {
        r: q.digest for r, q in first.requests.items()
    }


def test_one_number_in_one_scenario_rechecks_that_scenario_and_renders_its_robots(
    built: Any,
) -> None:
    cache_, files, first = built
    path = "configs/scenarios/scenario-0003.yaml"
    changed = _edit(files, path, b"ROLE:", b"EXTRA: 1\n  ROLE:")
    checked, rendered = incremental_build(cache_, changed, "2" * 40)
    stats = cache_.stats
    assert checked.ok and isinstance(rendered, FleetRender)
    assert stats.files_parsed == 1
    assert stats.units_run == [("scenario", "scenario-0003")]
    assert stats.derived == [("scenario-names", "scenario-0003")]  # unchanged: cut off
    assert stats.scenarios_rendered == ["scenario-0003"]
    assert stats.robots_rendered == _robots_of(first, "scenario-0003") > 0
    assert_same_fleet(rendered, full_build(changed, "2" * 40)[1])


def test_a_catalogue_change_rechecks_its_dependents_only(built: Any) -> None:
    cache_, files, _ = built
    text = files["configs/capabilities/capability-000.yaml"].decode()
    action, logic = re.findall(r"^  (Action\d+): (\S+)$", text, re.MULTILINE)[0]
    path = f"models/actions/{action}.yaml"
    changed = _edit(files, path, f"  {logic}:".encode(), f"  {logic}-renamed:".encode())
    checked, _ = incremental_build(cache_, changed, "2" * 40)
    run = set(cache_.stats.units_run)
    users = {
        Path(p).stem
        for p, data in changed.items()
        if p.startswith("configs/capabilities/")
        and re.search(rf"^  {action}: ", data.decode(), re.M)
    }
    assert ("action", action) in run and ("capability", "capability-000") in run
    assert {key[1] for key in run if key[0] == "capability"} == users
    assert not {key for key in run if key[0] in ("robot-template", "mapping-scheme", "task")}
    assert any(d.code == "RC205" for d in checked.errors)  # the logic it selected is gone
    assert checked.diagnostics == full_build(changed, "2" * 40)[0].diagnostics


def test_adding_a_robot_rechecks_the_fleet_and_renders_that_robot(built: Any) -> None:
    cache_, files, _ = built
    changed = _edit(
        files,
        FLEET,
        b"robots:\n",
        b"robots:\n  new-robot: {scenario: scenario-0001, namespace: n}\n",
    )
    checked, rendered = incremental_build(cache_, changed, "2" * 40)
    assert checked.ok and isinstance(rendered, FleetRender)
    assert set(cache_.stats.units_run) == {("fleet",), ("namespaces",)}
    assert cache_.stats.robots_rendered == 1
    assert_same_fleet(rendered, full_build(changed, "2" * 40)[1])


def test_the_cache_holds_what_the_newest_build_uses(built: Any) -> None:
    cache_, files, _ = built
    changed = dict(files)
    for path in [p for p in files if p.startswith("configs/scenarios/")][:4]:
        del changed[path]
    changed = _edit(changed, FLEET, b"robots:\n", b"robots:\n  x: {scenario: nowhere}\n")
    incremental_build(cache_, changed, "2" * 40)
    incremental_build(cache_, files, "3" * 40)  # and back
    fresh = BuildCache()
    incremental_build(fresh, files, "3" * 40)
    assert cache_.sizes() == fresh.sizes()


def test_a_failure_during_a_build_leaves_no_half_updated_cache(built: Any) -> None:
    cache_, files, _ = built

    class Failing(MemorySource):
        def read_each(self, paths: Sequence[str]) -> Iterator[tuple[str, bytes | OSError]]:
            raise RuntimeError("the source broke")
            yield  # pragma: no cover

    changed = _edit(files, "configs/scenarios/scenario-0003.yaml", b"ROLE:", b"X: 1\n  ROLE:")
    with pytest.raises(RuntimeError):
        cache_.check(Failing(changed, "2" * 40, commit=True))
    assert cache_.sizes() == BuildCache().sizes()  # forgotten: the next build is a full one
    _, rendered = incremental_build(cache_, changed, "2" * 40)
    assert cache_.stats.files_parsed == len(changed)
    expected = full_build(changed, "2" * 40)[1]
    assert isinstance(rendered, FleetRender) and isinstance(expected, FleetRender)
    assert_same_fleet(rendered, expected)


def test_the_work_tree_and_a_commit_share_what_they_parsed(built: Any) -> None:
    """`robotconf plan --base REV` with the work tree as head: unchanged files are not parsed
    again, whichever way they were read."""
    cache_, files, _ = built
    changed = _edit(files, "configs/scenarios/scenario-0002.yaml", b"ROLE:", b"X: 1\n  ROLE:")
    checked, _ = incremental_build(cache_, changed, "worktree", commit=False)
    assert cache_.stats.files_parsed == 1
    assert checked.diagnostics == full_build(changed, "worktree")[0].diagnostics


def test_a_domain_changed_in_a_commit_is_judged_and_rendered_again() -> None:
    """tb3-04 (on RoboticsLab's domain) and tb3-07 (its own) patrol on the same names: a
    commit that puts them on one domain is refused, one that parts them again is not, whether
    the robot's domain or its environment's changed; their requests follow."""
    files, lab = example_lab(), "models/environments/RoboticsLab.yaml"
    cache_ = BuildCache()
    checked, rendered = incremental_build(cache_, files, "1" * 40)
    assert checked.ok and isinstance(rendered, FleetRender)
    assert rendered.requests["tb3-04"].ros_domain_id == 1
    one = _edit(files, FLEET, b"ros_domain_id: 2}", b"ros_domain_id: 1}")
    parted = _edit(one, lab, b"ros_domain_id: 1", b"ros_domain_id: 3")
    for revision, changed, clash in (("2", one, True), ("3", parted, False), ("4", files, False)):
        checked, rendered = incremental_build(cache_, changed, revision * 40)
        full, expected = full_build(changed, revision * 40)
        assert checked.diagnostics == full.diagnostics
        assert [d.code for d in checked.diagnostics] == (["RC505"] if clash else [])
        if not clash:
            assert isinstance(rendered, FleetRender)
            assert_same_fleet(rendered, expected)
    assert isinstance(rendered, FleetRender)
    assert rendered.requests["tb3-04"].ros_domain_id == 1
    checked, rendered = incremental_build(cache_, parted, "5" * 40)
    assert isinstance(rendered, FleetRender)
    assert {r: rendered.requests[r].ros_domain_id for r in ("tb3-04", "tb3-07")} == {
        "tb3-04": 3,
        "tb3-07": 1,
    }
    assert cache_.stats.robots_rendered == 2  # the environment's robots, no other
    assert_same_fleet(rendered, full_build(parted, "5" * 40)[1])


def test_a_number_written_another_way_renders_the_bytes_a_full_build_does(built: Any) -> None:
    """`1` and `1.0` are equal in Python but not in JSON: the request carries what the file
    says, so a scenario whose content compares equal but serialises differently is new."""
    cache_, files, _ = built
    path = "configs/scenarios/scenario-0003.yaml"
    one_point_o = _edit(files, path, b"ROLE:", b"EXTRA: 1.0\n  ROLE:")
    incremental_build(cache_, one_point_o, "2" * 40)
    one = _edit(files, path, b"ROLE:", b"EXTRA: 1\n  ROLE:")
    checked, rendered = incremental_build(cache_, one, "3" * 40)
    assert checked.ok and isinstance(rendered, FleetRender)
    assert_same_fleet(rendered, full_build(one, "3" * 40)[1])


def test_which_logics_need_a_mapping_follows_an_action_changed_under_a_kept_capability(
    built: Any,
) -> None:
    """The build keeps `logics_needing` of a capability while its models are the same objects:
    an action whose logic needs one mapping less must be worked out again, even where the
    capability's requests (and so its objects) stay as they were."""
    cache_, files, first = built
    text = files["configs/capabilities/capability-000.yaml"].decode()
    action, logic = re.findall(r"^  (Action\d+): (\S+)$", text, re.MULTILINE)[0]
    path = f"models/actions/{action}.yaml"
    found = re.search(rf"  {logic}:\n.*\n    mappings: \[(\w+), ", files[path].decode())
    assert found is not None, files[path].decode()
    dropped = found.group(1)
    changed = _edit(files, path, f"mappings: [{dropped}, ".encode(), b"mappings: [")
    checked, rendered = incremental_build(cache_, changed, "2" * 40)
    assert checked.ok and isinstance(rendered, FleetRender), checked.errors[:3]
    assert logic in first.needed_by["capability-000"][dropped]
    assert logic not in rendered.needed_by["capability-000"].get(dropped, ())
    assert_same_fleet(rendered, full_build(changed, "2" * 40)[1])
