"""Loads a repository from a source: the folder decides each file's kind, the types check it.

One loader serves the work tree and any commit; what cannot be read becomes a diagnostic and the
file is remembered as broken so that references to it are not reported twice.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Protocol

from pydantic import BaseModel, ValidationError

from robotconf.configurator.repository import Entry, Platform, Repository
from robotconf.configurator.ruleconfig import IgnoreComment, ignore_comments
from robotconf.configurator.source import RULE_CONFIGURATION, FileTooLarge, Source
from robotconf.configurator.types import (
    Action,
    CapabilityConfiguration,
    Environment,
    Fleet,
    MappingScheme,
    PlatformInfo,
    RobotTemplate,
    RuleConfiguration,
    ScenarioConfiguration,
    Task,
)
from robotconf.contract.diagnostics import Diagnostic, Severity
from robotconf.contract.typing_errors import typing_diagnostics
from robotconf.contract.yamlio import YamlDocument, YamlReadError, parse_document


@dataclass(frozen=True)
class Kind:
    """One kind of file: where it lives and the type that checks it."""

    name: str
    pattern: re.Pattern[str]
    model: type[BaseModel]
    title: str


KINDS = (
    Kind("fleet", re.compile(r"^configs/(fleet)\.yaml$"), Fleet, "fleet"),
    Kind(
        "capability",
        re.compile(r"^configs/capabilities/([^/]+)\.yaml$"),
        CapabilityConfiguration,
        "capability configuration",
    ),
    Kind(
        "scenario",
        re.compile(r"^configs/scenarios/([^/]+)\.yaml$"),
        ScenarioConfiguration,
        "scenario configuration",
    ),
    Kind(
        "platform",
        re.compile(r"^models/platforms/([^/]+)/platform\.yaml$"),
        PlatformInfo,
        "platform",
    ),
    Kind(
        "robot-template",
        re.compile(r"^models/platforms/([^/]+)/robot-templates/([^/]+)\.yaml$"),
        RobotTemplate,
        "robot template",
    ),
    Kind(
        "mapping-scheme",
        re.compile(r"^models/platforms/([^/]+)/mapping-schemes/([^/]+)\.yaml$"),
        MappingScheme,
        "mapping scheme",
    ),
    Kind("action", re.compile(r"^models/actions/([^/]+)\.yaml$"), Action, "action"),
    Kind("task", re.compile(r"^models/tasks/([^/]+)\.yaml$"), Task, "task"),
    Kind(
        "environment",
        re.compile(r"^models/environments/([^/]+)\.yaml$"),
        Environment,
        "environment",
    ),
)
KIND_BY_NAME = {kind.name: kind for kind in KINDS}
# Read like every kind, from the same source, but not one of the lab's documents.
RULE_CONFIGURATION_KIND = Kind(
    "rule-configuration",
    re.compile(r"^\.(robotconf)\.yaml$"),
    RuleConfiguration,
    "rule configuration",
)

_PLACES = (
    "configs/fleet.yaml, configs/capabilities/<name>.yaml, configs/scenarios/<name>.yaml, "
    "models/actions/, models/tasks/, models/environments/, "
    "models/platforms/<platform>/{platform.yaml,robot-templates/,mapping-schemes/}"
)
_PLATFORM_DIR = re.compile(r"^models/platforms/([^/]+)/")
_YAML_SUFFIX = re.compile(r"\.ya?ml$", re.IGNORECASE)
FLEET_PATH = "configs/fleet.yaml"


def classify(path: str) -> tuple[Kind, tuple[str, ...]] | None:
    for kind in KINDS:
        match = kind.pattern.match(path)
        if match:
            return kind, match.groups()
    return None


def _error(path: str, code: str, message: str, line: int = 1, col: int = 1) -> Diagnostic:
    return Diagnostic(path, line, col, Severity.ERROR, code, message)


@dataclass(frozen=True)
class LoadedFile:
    """One file read, parsed and typed: its entry (None when unreadable, and its name is then
    remembered as broken) and what is wrong with it on its own. It depends on the file's path
    and bytes alone, so a cache may keep it by path and git blob id."""

    path: str
    kind: Kind
    groups: tuple[str, ...]
    entry: Entry[Any] | None
    diagnostics: tuple[Diagnostic, ...]
    ignores: tuple[IgnoreComment, ...] = ()  # of a typed file only


class FileCache(Protocol):
    """Files loaded before, by path and blob id (configurator/incremental.py)."""

    def get(self, path: str, blob: str) -> LoadedFile | None: ...

    def put(self, blob: str, loaded: LoadedFile) -> None: ...


def blob_id(data: bytes) -> str:
    """The id git gives these bytes as a blob: a file of the work tree and the same file in a
    commit share it."""
    import hashlib  # a build with a file cache only: plain validate starts without OpenSSL

    return hashlib.sha1(b"blob %d\0" % len(data) + data, usedforsecurity=False).hexdigest()


def load_repository(
    source: Source, files: FileCache | None = None
) -> tuple[Repository, list[Diagnostic]]:
    """Every file of the source, typed; diagnostics for everything that is not readable.
    With `files`, a file whose bytes were loaded before is taken from there, not parsed again."""
    repo = Repository(revision_of=lambda: source.revision)
    diagnostics: list[Diagnostic] = []
    for path, why in source.refused().items():
        diagnostics.append(_error(path, "RC008", f"not read: {path} {why}"))
        found = classify(path)
        if found is not None:
            repo.broken.setdefault(found[0].name, set()).add(_qualified(found[1]))
    placed: list[tuple[str, Kind, tuple[str, ...]]] = []
    for path in source.files():
        found = place(path, repo, diagnostics)
        if found is not None:
            placed.append((path, *found))
    loaded: dict[str, LoadedFile] = {}
    if files is not None:
        for path, _, _ in placed:
            blob = source.blob_id(path)
            hit = files.get(path, blob) if blob is not None else None
            if hit is not None:
                loaded[path] = hit
    # One pass over every other file: a commit is read by one git process, not one per file.
    unread = [(path, kind, groups) for path, kind, groups in placed if path not in loaded]
    contents = source.read_each([path for path, _, _ in unread])
    for (path, kind, groups), (_, raw) in zip(unread, contents, strict=True):
        blob = source.blob_id(path) or (blob_id(raw) if isinstance(raw, bytes) else None)
        hit = files.get(path, blob) if files is not None and blob is not None else None
        if hit is None:
            hit = load_file(path, raw, kind, groups)
            if files is not None and blob is not None:
                files.put(blob, hit)
        loaded[path] = hit
    for path, _, _ in placed:
        add_loaded(repo, loaded[path], diagnostics)
    if repo.fleet is None and "fleet" not in repo.broken:
        diagnostics.append(_missing_fleet(source))
    return repo, diagnostics


def place(
    path: str, repo: Repository, diagnostics: list[Diagnostic]
) -> tuple[Kind, tuple[str, ...]] | None:
    """The kind of file a path holds, or None when it is not read (a README, a YAML file in
    the wrong place: reported). A platform's folder makes the platform, whatever it holds."""
    if path == RULE_CONFIGURATION:
        return RULE_CONFIGURATION_KIND, ("robotconf",)
    platform_dir = _PLATFORM_DIR.match(path)
    if platform_dir:
        repo.platforms.setdefault(platform_dir.group(1), Platform(platform_dir.group(1)))
    suffix = _YAML_SUFFIX.search(path)
    if suffix is None:
        return None  # READMEs and the like may sit beside the YAML files
    if suffix.group() != ".yaml":
        diagnostics.append(
            _error(
                path,
                "RC105",
                f"YAML files here end in .yaml; rename this {suffix.group()} file (it is not read)",
            )
        )
        return None
    found = classify(path)
    if found is None:
        diagnostics.append(
            _error(path, "RC105", f"not a known place for a YAML file; expected {_PLACES}")
        )
    return found


def load_file(path: str, raw: bytes | OSError, kind: Kind, groups: tuple[str, ...]) -> LoadedFile:
    """One file's bytes (or why they could not be read) parsed, typed and checked on its own."""
    diagnostics: list[Diagnostic] = []
    doc, model = _parse(path, raw, kind, diagnostics)
    if model is None or doc is None:
        return LoadedFile(path, kind, groups, None, tuple(diagnostics))
    name = groups[-1]
    declared = getattr(model, "name", None)
    if kind.name != "fleet" and declared is not None and declared != name:
        line, col = doc.locate(["name"])
        diagnostics.append(
            _error(
                path,
                "RC104",
                f"name '{declared}' differs from the file name '{name}'; "
                f"a {kind.title}'s name is its file name (rename one, or drop 'name:')",
                line,
                col,
            )
        )
    entry = Entry(name, model, doc)
    return LoadedFile(path, kind, groups, entry, tuple(diagnostics), ignore_comments(doc))


def add_loaded(repo: Repository, loaded: LoadedFile, diagnostics: list[Diagnostic]) -> None:
    """One file's result into the repository: an entry, or a name remembered as broken."""
    repo.files_read += 1
    diagnostics.extend(loaded.diagnostics)
    if loaded.ignores:
        repo.ignores[loaded.path] = loaded.ignores
    if loaded.entry is None:
        repo.broken.setdefault(loaded.kind.name, set()).add(_qualified(loaded.groups))
    else:
        _add(repo, loaded.kind.name, loaded.groups, loaded.entry)


def _missing_fleet(source: Source) -> Diagnostic:
    """The reconciler cannot apply a commit without a fleet: neither may validate pass one."""
    hint = ""
    if not any(path.startswith(("configs/", "models/")) for path in source.files()):
        hint = " (this folder holds no configs/ or models/ files: is it the repository root?)"
    return _error(
        FLEET_PATH,
        "RC106",
        f"{FLEET_PATH} is missing: it says which robot runs which scenario; create it "
        f"(`robots: {{}}` and `allow_empty: true` for a fleet of none){hint}",
    )


def _qualified(groups: tuple[str, ...]) -> str:
    return "/".join(groups)


def _parse(
    path: str, raw: bytes | OSError, kind: Kind, diagnostics: list[Diagnostic]
) -> tuple[YamlDocument | None, Any]:
    """The document and its model; the document alone when it is not of its kind, neither
    when unreadable."""
    if isinstance(raw, FileTooLarge):
        diagnostics.append(_error(path, "RC008", str(raw)))
        return None, None
    if isinstance(raw, OSError):
        diagnostics.append(_error(path, "RC008", f"cannot read the file: {raw.strerror or raw}"))
        return None, None
    try:
        doc = parse_document(path, raw)
    except YamlReadError as exc:
        for p in exc.problems:
            diagnostics.append(_error(path, p.code, p.message, p.line, p.col))
        return None, None
    try:
        return doc, kind.model.model_validate(doc.data)
    except ValidationError as exc:
        diagnostics.extend(typing_diagnostics(doc, kind.model, exc, _article(kind.title)))
        return doc, None


def _article(title: str) -> str:
    return f"{'an' if title[0] in 'aeiou' else 'a'} {title}"


def _add(repo: Repository, kind: str, groups: tuple[str, ...], entry: Entry[Any]) -> None:
    if kind == "fleet":
        repo.fleet = entry
    elif kind == "capability":
        repo.capabilities[entry.name] = entry
    elif kind == "scenario":
        repo.scenarios[entry.name] = entry
    elif kind == "platform":
        repo.platforms[groups[0]].info = entry
    elif kind == "robot-template":
        repo.platforms[groups[0]].templates[entry.name] = entry
    elif kind == "mapping-scheme":
        repo.platforms[groups[0]].schemes[entry.name] = entry
    elif kind == "action":
        repo.actions[entry.name] = entry
    elif kind == "task":
        repo.tasks[entry.name] = entry
    elif kind == "environment":
        repo.environments[entry.name] = entry
    elif kind == "rule-configuration":
        repo.rule_configuration = entry
