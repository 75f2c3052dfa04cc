"""Incremental builds: a commit costs what it changes, with the verdicts of a full build.

A `BuildCache` keeps, from one build to the next:
- every file loaded (parsed, typed, checked on its own), by path and git blob id: a file whose
  bytes did not change is never read or parsed again;
- every rule unit's findings (configurator/rules: one rule on one subject) with what the unit
  read of the repository, and the reverse index from what was read to the units that read it:
  a build runs again only the units that read something that changed;
- the values units share (a scenario's ROS names) with what they read, worked out again when
  that changed, their dependents re-run only when the value itself differs (early cut-off);
- each scenario's rendered content and each robot's request: a robot is rendered again only
  when its assignment or its scenario's content changed (else it keeps its request, stamped
  with the new revision as it is read: FleetRequests); while fleet.yaml is unchanged, only the
  robots of the scenarios whose content changed are visited at all.

What a unit reads is recorded, not declared: the repository a unit gets records every lookup
(an entry by name, the names of a kind, whether a name exists), so a rule that starts reading
something else is tracked without anyone updating a list. Whatever is not known to be
unchanged is computed again. Memory is bounded by the newest build: what it no longer uses
is dropped, and the YAML node trees of cached files are released (parsed again from their
bytes when a position is asked for).

Pure: the I/O happens in the source given to `check` (git or the work tree).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

from robotconf.configurator.drift import logics_needing
from robotconf.configurator.gcpause import collector_paused
from robotconf.configurator.loader import LoadedFile, load_repository
from robotconf.configurator.render import (
    FleetRender,
    needed_by,
    render_fleet,
    request_for,
    scenario_requests,
)
from robotconf.configurator.rendered import FleetRequests, RenderedRequest, ScenarioRequests
from robotconf.configurator.repository import Entry, Platform, Repository
from robotconf.configurator.rules import DERIVED, Unit, rule_units
from robotconf.configurator.rules.report import Reporter
from robotconf.configurator.source import Source
from robotconf.configurator.types import Action, Fleet, RobotAssignment
from robotconf.configurator.workspace import Checked, judged
from robotconf.contract.diagnostics import Diagnostic
from robotconf.contract.launch import LaunchCapability, LaunchScenario, canonical_json

V = TypeVar("V")

# What a unit read: ("entry", container, name) an entry's content, ("has", container, name)
# only whether it exists, ("keys", container) the names in order, ("all", container) every
# entry, ("derived", name, argument) a shared value.
Dep = tuple[str, ...]
# A container's content at one build: name -> the blob id of its file (platforms: of their
# platform.yaml; broken: the names of that kind that cannot be read).
Snapshot = dict[str, dict[str, Hashable]]
_MISSING = object()


class _Recorder:
    """Notes what the computation under way reads; nested for a value worked out inside one."""

    def __init__(self) -> None:
        self.stack: list[set[Dep]] = []

    def note(self, dep: Dep) -> None:
        if self.stack:
            self.stack[-1].add(dep)

    def recording(self) -> _Recording:
        return _Recording(self)


class _Recording:
    def __init__(self, recorder: _Recorder) -> None:
        self.recorder = recorder
        self.deps: set[Dep] = set()

    def __enter__(self) -> set[Dep]:
        self.recorder.stack.append(self.deps)
        return self.deps

    def __exit__(self, *exc: object) -> None:
        self.recorder.stack.pop()


class _TrackedDict(dict[str, V]):
    """One container of the repository, noting what is read of it."""

    __slots__ = ("_container", "_recorder")

    def __init__(self, container: str, recorder: _Recorder, items: dict[str, V]) -> None:
        super().__init__(items)
        self._container = container
        self._recorder = recorder

    def _entry(self, key: object) -> None:
        self._recorder.note(("entry", self._container, str(key)))

    def _keys(self) -> None:
        self._recorder.note(("keys", self._container))

    def _all(self) -> None:
        self._recorder.note(("all", self._container))

    def get(self, key: str, default: Any = None) -> Any:
        self._entry(key)
        return super().get(key, default)

    def __getitem__(self, key: str) -> V:
        self._entry(key)
        return super().__getitem__(key)

    def __contains__(self, key: object) -> bool:
        self._recorder.note(("has", self._container, str(key)))
        return super().__contains__(key)

    def __iter__(self) -> Iterator[str]:
        self._keys()
        return super().__iter__()

    def __reversed__(self) -> Iterator[str]:
        self._keys()
        return super().__reversed__()

    def __len__(self) -> int:
        self._keys()
        return super().__len__()

    def keys(self) -> Any:
        self._keys()
        return super().keys()

    def values(self) -> Any:
        self._all()
        return super().values()

    def items(self) -> Any:
        self._all()
        return super().items()

    def copy(self) -> dict[str, V]:
        self._all()
        return dict(super().items())

    def __eq__(self, other: object) -> bool:
        self._all()
        return super().__eq__(other)

    __hash__ = None


class _TrackedRepository(Repository):
    """The repository as units see it: the fleet noted when read."""

    def __getattribute__(self, name: str) -> Any:
        if name == "fleet":
            object.__getattribute__(self, "_recorder").note(("entry", "fleet", ""))
        elif name == "revision":
            object.__getattribute__(self, "_recorder").note(("revision",))
        return object.__getattribute__(self, name)


_KIND_CONTAINERS = {
    "action": "actions",
    "task": "tasks",
    "environment": "environments",
    "capability": "capabilities",
    "scenario": "scenarios",
}


def _tracked(repo: Repository, recorder: _Recorder) -> _TrackedRepository:
    platforms = {}
    for name, found in repo.platforms.items():
        platform = Platform(name, found.info)
        platform.templates = _TrackedDict(f"robot-template@{name}", recorder, found.templates)
        platform.schemes = _TrackedDict(f"mapping-scheme@{name}", recorder, found.schemes)
        platforms[name] = platform
    tracked = _TrackedRepository(
        revision_of=repo.revision_of,
        platforms=_TrackedDict("platforms", recorder, platforms),
        **{
            attribute: _TrackedDict(kind, recorder, getattr(repo, attribute))
            for kind, attribute in _KIND_CONTAINERS.items()
        },
        fleet=repo.fleet,
        broken=_TrackedDict("broken", recorder, repo.broken),
        files_read=repo.files_read,
        rule_configuration=repo.rule_configuration,
        ignores=repo.ignores,
    )
    object.__setattr__(tracked, "_recorder", recorder)
    return tracked


def _snapshot(repo: Repository, blobs: dict[str, str]) -> Snapshot:
    def token(entry: Entry[Any] | None) -> Hashable:
        return "" if entry is None else blobs[entry.path]

    snapshot: Snapshot = {
        "platforms": {name: token(p.info) for name, p in dict.items(repo.platforms)},
        "broken": {kind: frozenset(names) for kind, names in dict.items(repo.broken)},
        "fleet": {} if repo.fleet is None else {"": token(repo.fleet)},
    }
    for name, p in dict.items(repo.platforms):
        snapshot[f"robot-template@{name}"] = {t: token(e) for t, e in dict.items(p.templates)}
        snapshot[f"mapping-scheme@{name}"] = {s: token(e) for s, e in dict.items(p.schemes)}
    for kind, attribute in _KIND_CONTAINERS.items():
        entries: dict[str, Entry[Any]] = getattr(repo, attribute)
        snapshot[kind] = {name: token(e) for name, e in dict.items(entries)}
    return snapshot


def changes(before: Snapshot, after: Snapshot) -> set[Dep]:
    """Everything a unit may have read that differs between two builds."""
    changed: set[Dep] = {("revision",)}  # a commit is a new revision: never assumed equal
    for container in before.keys() | after.keys():
        old, new = before.get(container, {}), after.get(container, {})
        if old == new:
            continue
        changed.add(("all", container))
        if list(old) != list(new):
            changed.add(("keys", container))
        for name in old.keys() | new.keys():
            was, now = old.get(name, _MISSING), new.get(name, _MISSING)
            if was != now:
                changed.add(("entry", container, name))
            if (was is _MISSING) != (now is _MISSING):
                changed.add(("has", container, name))
    return changed


def same_content(before: LaunchScenario, after: LaunchScenario) -> bool:
    """The same request content, byte for byte: `==` alone would take `1` for `1.0` (and
    `True` for `1`), which JSON, and so the robot and the digest, tell apart."""
    return before == after and canonical_json(before.model_dump(mode="json")) == canonical_json(
        after.model_dump(mode="json")
    )


@dataclass
class _Done:
    """A unit's findings and what it read to find them."""

    deps: frozenset[Dep]
    diagnostics: tuple[Diagnostic, ...]


@dataclass
class _Value:
    """A derived value (or a scenario's rendered content) and what it was worked out from."""

    deps: frozenset[Dep]
    value: Any


@dataclass(slots=True)
class _Rendered:
    assignment: RobotAssignment
    request: RenderedRequest  # of the assignment, from its scenario's ScenarioRequests


@dataclass
class BuildStats:
    """What the last build did, not reused: for tests and benchmarks."""

    files_parsed: int = 0
    units_run: list[tuple[str, ...]] = field(default_factory=list)
    derived: list[tuple[str, str]] = field(default_factory=list)
    scenarios_rendered: list[str] = field(default_factory=list)
    robots_rendered: int = 0


class _NeedsMemo:
    """`logics_needing` of each capability, kept from one build to the next while the
    capability and the actions it selects are the very objects they were (an unchanged file
    keeps its models): otherwise worked out again. Holding the objects keeps their ids from
    being reused; what a build did not ask for is dropped at the next."""

    Kept = tuple[LaunchCapability, tuple[Action | None, ...], dict[str, tuple[str, ...]]]

    def __init__(self) -> None:
        self._last: dict[int, _NeedsMemo.Kept] = {}
        self._now: dict[int, _NeedsMemo.Kept] = {}

    def next_build(self) -> None:
        self._last, self._now = self._now, {}

    def __call__(
        self, capability: LaunchCapability, actions: Mapping[str, Action]
    ) -> dict[str, tuple[str, ...]]:
        used = tuple(actions.get(name) for name in capability.logics)
        kept = self._now.get(id(capability)) or self._last.get(id(capability))
        if (
            kept is None
            or kept[0] is not capability
            or len(kept[1]) != len(used)
            or any(a is not b for a, b in zip(kept[1], used, strict=True))
        ):
            kept = (capability, used, logics_needing(capability, actions))
        self._now[id(capability)] = kept
        return kept[2]


class BuildCache:
    """What earlier builds proved, reused by the next: see the module's docstring. One cache
    serves one repository; `check` a source, then `render` its result if it is valid."""

    def __init__(self) -> None:
        self._reset()

    def clear(self) -> None:
        """Forgets everything: the next build is a full one."""
        self._reset()

    def _reset(self) -> None:
        self._files: dict[tuple[str, str], LoadedFile] = {}
        self._blobs: dict[str, str] = {}  # path -> blob id, in the build under way
        self._snapshot: Snapshot = {}
        self._units: dict[tuple[str, ...], _Done] = {}
        self._derived: dict[tuple[str, str], _Value] = {}
        self._dependents: dict[Dep, set[tuple[str, ...]]] = {}
        self._checked: _TrackedRepository | None = None
        self._rendered_snapshot: Snapshot = {}
        self._scenarios: dict[str, _Value] = {}
        self._robots: dict[str, _Rendered] = {}
        self._last: _LastRender | None = None
        self._needs = _NeedsMemo()
        self._recorder = _Recorder()
        self.stats = BuildStats()

    def sizes(self) -> dict[str, int]:
        """How much is kept, part by part: what the newest build uses, no more."""
        return {
            "files": len(self._files),
            "units": len(self._units),
            "derived": len(self._derived),
            "index": sum(len(users) for users in self._dependents.values()),
            "scenarios": len(self._scenarios),
            "robots": len(self._robots),
        }

    # ------------------------------------------------------------ the file cache (loader)

    def get(self, path: str, blob: str) -> LoadedFile | None:
        found = self._files.get((path, blob))
        if found is not None:
            self._blobs[path] = blob
        return found

    def put(self, blob: str, loaded: LoadedFile) -> None:
        if loaded.entry is not None:
            # Typed and checked on its own: its node tree is not kept through the build (all
            # trees at once were the build's peak), a rule reporting here parses it again.
            loaded.entry.doc.release()
        self._files[(loaded.path, blob)] = loaded
        self._blobs[loaded.path] = blob
        self.stats.files_parsed += 1

    # ------------------------------------------------------------ check

    def check(self, source: Source) -> Checked:
        """The source validated as `workspace.check_source` would, reusing what is unchanged."""
        try:
            with collector_paused():
                return self._check(source)
        except BaseException:
            self.clear()  # half an update is never trusted
            raise

    def _check(self, source: Source) -> Checked:
        self.stats = BuildStats()
        self._blobs = {}
        loaded, diagnostics = load_repository(source, files=self)
        self._files = {
            key: f for key, f in self._files.items() if self._blobs.get(key[0]) == key[1]
        }
        repo = _tracked(loaded, self._recorder)
        snapshot = _snapshot(repo, self._blobs)
        changed = changes(self._snapshot, snapshot)
        self._snapshot = snapshot
        self._refresh_derived(repo, changed)
        dirty = {unit for dep in changed for unit in self._dependents.get(dep, ())}
        units = rule_units(repo)
        live = {unit.key for unit in units}
        for key in [key for key in self._units if key not in live]:
            self._forget_unit(key)
        for unit in units:
            done = self._units.get(unit.key)
            if done is None or unit.key in dirty:
                done = self._run(repo, unit)
            diagnostics.extend(done.diagnostics)
        used = {
            dep[1:] for done in self._units.values() for dep in done.deps if dep[0] == "derived"
        }
        self._derived = {key: v for key, v in self._derived.items() if key in used}
        for found in self._files.values():
            if found.entry is not None:
                found.entry.doc.release()
        self._checked = repo
        return judged(repo, diagnostics)

    def _refresh_derived(self, repo: _TrackedRepository, changed: set[Dep]) -> None:
        """Works out again each derived value that read something changed; one whose value
        differs is a change itself (its dependents run again), one that came out equal is not."""
        for key, old in list(self._derived.items()):
            if old.deps.isdisjoint(changed):
                continue
            value = self._derive(repo, key)
            if value != old.value:
                changed.add(("derived", *key))

    def _derive(self, repo: _TrackedRepository, key: tuple[str, str]) -> Any:
        with self._recorder.recording() as deps:
            value = DERIVED[key[0]](repo, key[1])
        self._derived[key] = _Value(frozenset(deps), value)
        self.stats.derived.append(key)
        return value

    def _run(self, repo: _TrackedRepository, unit: Unit) -> _Done:
        self._forget_unit(unit.key)
        report = Reporter()

        def derive(name: str, argument: str) -> Any:
            key = (name, argument)
            self._recorder.note(("derived", name, argument))
            found = self._derived.get(key)
            if found is not None:
                return found.value
            return self._derive(repo, key)

        with self._recorder.recording() as deps:
            unit.run(repo, report, derive)
        done = _Done(frozenset(deps), tuple(report.found))
        self._units[unit.key] = done
        for dep in done.deps:
            self._dependents.setdefault(dep, set()).add(unit.key)
        self.stats.units_run.append(unit.key)
        return done

    def _forget_unit(self, key: tuple[str, ...]) -> None:
        done = self._units.pop(key, None)
        if done is None:
            return
        for dep in done.deps:
            users = self._dependents.get(dep)
            if users is not None:
                users.discard(key)
                if not users:
                    del self._dependents[dep]

    # ------------------------------------------------------------ render

    def render(self, checked: Checked) -> FleetRender:
        """The fleet of the build just checked (which must be valid), as `render_fleet` would
        render it; raises RenderError as it would."""
        if checked.repo is not self._checked:
            raise ValueError("render the build this cache checked last")
        try:
            with collector_paused():
                return self._render(self._checked)
        except BaseException:
            self.clear()
            raise

    def _render(self, repo: _TrackedRepository) -> FleetRender:
        changed = changes(self._rendered_snapshot, self._snapshot)
        self._rendered_snapshot = self._snapshot
        self._needs.next_build()
        scenarios: dict[str, _Value] = {}
        scenario_of = self._scenario_of(repo, changed, scenarios)
        fleet_model = None if repo.fleet is None else repo.fleet.model
        last = self._last
        if last is not None and fleet_model is not None and last.model is fleet_model:
            fleet = self._render_changed(repo, last, scenario_of)
        else:
            fleet = self._render_all(repo, scenario_of)
        self._scenarios = scenarios
        return fleet

    def _scenario_of(
        self, repo: _TrackedRepository, changed: set[Dep], scenarios: dict[str, _Value]
    ) -> Callable[[str], ScenarioRequests]:
        """Each scenario's ScenarioRequests for this build (into `scenarios`): the one of the
        build before while what it read is unchanged, or while its content comes out the
        same (its robots then need nothing new)."""

        def scenario_of(name: str) -> ScenarioRequests:
            found = scenarios.get(name)
            if found is None:
                found = self._scenarios.get(name)
                if found is None or not found.deps.isdisjoint(changed):
                    with self._recorder.recording() as deps:
                        made = scenario_requests(repo, name)
                    before: ScenarioRequests | None = None if found is None else found.value
                    if (
                        before is not None
                        and same_content(before.scenario, made.scenario)
                        and before.ros_domain_id == made.ros_domain_id
                    ):
                        made = before  # the same content: its robots need nothing new
                    found = _Value(frozenset(deps), made)
                    self.stats.scenarios_rendered.append(name)
                scenarios[name] = found
            rendered: ScenarioRequests = found.value
            return rendered

        return scenario_of

    def _render_all(
        self, repo: _TrackedRepository, scenario_of: Callable[[str], ScenarioRequests]
    ) -> FleetRender:
        """Every robot through `render_fleet`: a robot is rendered again only when its
        assignment or its scenario's content changed (else it keeps its request)."""
        robots: dict[str, _Rendered] = {}

        def request_of(
            robot_id: str, assignment: RobotAssignment, scenario: ScenarioRequests
        ) -> RenderedRequest:
            before = self._robots.get(robot_id)
            if (
                before is None
                or before.request.scenario_requests is not scenario
                # `is` first: an unchanged fleet.yaml keeps its models, and comparing 10,000
                # pydantic models field by field costs a tenth of a commit's build.
                or (before.assignment is not assignment and before.assignment != assignment)
            ):
                request = request_for(repo, robot_id, assignment, scenario)
                self.stats.robots_rendered += 1
            else:
                request = before.request  # stamped with this build's revision when read
            robots[robot_id] = _Rendered(assignment, request)
            return request

        fleet = render_fleet(repo, scenario_of, request_of, self._needs)
        self._robots = robots
        assert repo.fleet is not None
        self._last = _LastRender(repo.fleet.model, fleet, _by_scenario(repo.fleet.model))
        return fleet

    def _render_changed(
        self,
        repo: _TrackedRepository,
        last: _LastRender,
        scenario_of: Callable[[str], ScenarioRequests],
    ) -> FleetRender:
        """The same fleet.yaml as the build before (its very models): the robots of the
        scenarios whose content changed are rendered again, every other robot keeps its
        request, and the rest of the fleet is the last one's. What `_render_all` would give,
        without a step per robot."""
        before, model = last.fleet, last.model
        fleet = FleetRender(
            revision=repo.revision,
            requests=FleetRequests(repo.revision, dict(before.requests.as_kept())),
            suspended=set(before.suspended),
            scenario_of=dict(before.scenario_of),
            labels=dict(before.labels),
            allow_empty=before.allow_empty,
            rollout=before.rollout,
            stages=before.stages,
            groups=before.groups,
            drift=before.drift,
        )
        used: dict[int, ScenarioRequests] = {}
        again: list[str] = []  # robots of a scenario whose content changed
        for name, robot_ids in last.robots_of.items():
            scenario = scenario_of(name)
            used.setdefault(id(scenario), scenario)
            if self._robots[robot_ids[0]].request.scenario_requests is not scenario:
                again.extend(robot_ids)
        # In the fleet's order: the first robot that cannot be rendered is the one
        # render_fleet names.
        for robot_id in sorted(again, key=last.position.__getitem__):
            assignment = model.robots[robot_id]
            request = request_for(repo, robot_id, assignment, scenario_of(assignment.scenario))
            self.stats.robots_rendered += 1
            self._robots[robot_id] = _Rendered(assignment, request)
            fleet.requests[robot_id] = request
        fleet.needed_by = needed_by(repo, used.values(), self._needs)
        self._last = _LastRender(model, fleet, last.robots_of, last.position)
        return fleet


@dataclass
class _LastRender:
    """The fleet the last render made, the fleet.yaml model it made it from, and that
    model's robots by scenario (in the fleet's order) with each robot's place in it."""

    model: Fleet
    fleet: FleetRender
    robots_of: dict[str, list[str]]
    position: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.position:
            self.position = {robot_id: i for i, robot_id in enumerate(self.model.robots)}


def _by_scenario(model: Fleet) -> dict[str, list[str]]:
    """The robots of each scenario, in the fleet's order (scenarios by their first robot)."""
    found: dict[str, list[str]] = {}
    for robot_id, assignment in model.robots.items():
        found.setdefault(assignment.scenario, []).append(robot_id)
    return found
