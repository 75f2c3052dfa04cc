"""`robotconf draft ROBOT`: a robot template and a mapping scheme from a robot's interfaces."""

from __future__ import annotations

import contextlib
import datetime
import sys
from collections import Counter
from pathlib import Path

import click

from robotconf.configurator.draft import (
    Draft,
    ReportError,
    catalogue,
    draft,
    report_from,
    scheme_yaml,
    template_yaml,
)
from robotconf.configurator.repository import Repository
from robotconf.configurator.rosnames import namespace_problem
from robotconf.configurator.schemas import modeline_ref
from robotconf.configurator.types import SettingDefinition, is_robot_id
from robotconf.configurator.workspace import check, check_with
from robotconf.contract.diagnostics import Diagnostic, did_you_mean, format_text
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.files import read_regular, write_atomic
from robotconf.contract.interfaces import MAX_INTERFACES_BYTES, RobotInterfaces
from robotconf.contract.models import file_name
from robotconf.contract.safejson import PayloadError, parse_object
from robotconf.contract.textsafe import printable
from robotconf.contract.topics import Role, subscriptions
from robotconf.contract.wire import Topics
from robotconf.contract.yamlio import MAX_FILE_BYTES
from robotconf.readmodel.retained import RetainedView, read_object
from robotconf.workstation.cli.broker_options import BrokerOptions, desk_broker_options
from robotconf.workstation.cli.options import repo_option
from robotconf.workstation.desk.broker import wait_for_broker

SHOWN = 20  # interfaces left out for a reason, listed one by one (a hostile report has 4,096)


def from_file(path: Path) -> RobotInterfaces:
    """`--from FILE`: the retained message's JSON, bounded as the broker's copy is."""
    try:
        raw = read_regular(path, MAX_INTERFACES_BYTES)
        return report_from(parse_object(raw, max_bytes=MAX_INTERFACES_BYTES))
    except OSError as exc:
        raise CliError(f"cannot read --from {path}: {exc.strerror or exc}") from None
    except (PayloadError, ReportError) as exc:
        raise CliError(
            f"--from {path} is not an interfaces message: {printable(str(exc))}", ExitCode.FINDINGS
        ) from None


def from_broker(mqtt: BrokerOptions, robot_id: str, wait: float) -> RobotInterfaces:
    """The robot's retained interfaces message; a CliError when there is none or it is
    unreadable, or when the robot's source failed (an error proves nothing to draft from)."""
    connection = mqtt.connection()
    [topic] = subscriptions(Role.VIEWER, mqtt.prefix, "interfaces", robot_id=robot_id)
    view = RetainedView(
        connection,
        [topic],
        Topics(mqtt.prefix).sync,
        role="draft",
        max_payload=MAX_INTERFACES_BYTES,
    )
    with view:
        wait_for_broker(view, wait)
        payload = view.get(topic)
    if payload is None:
        raise CliError(
            f"{robot_id} has reported no interfaces ({topic} holds nothing): turn reporting "
            "on in its agent.yaml (interfaces: {interval: 30}), or draft offline with --from FILE",
            ExitCode.FINDINGS,
        )
    try:
        found = report_from(read_object(payload, MAX_INTERFACES_BYTES))
    except (PayloadError, ReportError) as exc:
        raise CliError(
            f"{topic} is not an interfaces message: {printable(str(exc))}", ExitCode.FINDINGS
        ) from None
    return found


def usable(found: RobotInterfaces, robot_id: str) -> RobotInterfaces:
    """A report whose source failed proves nothing about the robot: no draft from it."""
    if found.error is not None:
        raise CliError(
            f"{robot_id}'s interfaces source failed ({printable(found.error)}): nothing to draft "
            "from; see its agent's log (robotconf logs ROBOT)",
            ExitCode.FINDINGS,
        )
    return found


def robot_namespace(repo: Repository, robot_id: str, given: str | None) -> tuple[str | None, str]:
    """The namespace names are written relative to, and where it comes from."""
    fleet = repo.fleet.model.robots if repo.fleet is not None else {}
    assigned = fleet[robot_id].namespace if robot_id in fleet else None
    if given is not None:
        problem = namespace_problem(given)
        if problem is not None:
            raise CliError(f"--namespace {given!r} {problem}", ExitCode.FINDINGS)
        return given, "--namespace"
    if assigned is not None:
        problem = namespace_problem(assigned)
        if problem is not None:
            raise CliError(
                f"configs/fleet.yaml gives {robot_id} namespace {assigned!r}, which {problem}; "
                "fix it there, or pass --namespace",
                ExitCode.FINDINGS,
            )
        return assigned, "configs/fleet.yaml"
    if robot_id in fleet:
        return None, "configs/fleet.yaml gives it none"
    return None, f"{robot_id} is not in configs/fleet.yaml; --namespace sets one"


def _settings(repo: Repository, platform: str, source: str | None) -> dict[str, SettingDefinition]:
    if source is None:
        return {}
    templates = repo.platforms[platform].templates
    if source not in templates:
        raise CliError(
            f"--settings-from: platform {platform} has no robot template '{source}'"
            f"{did_you_mean(source, templates)}",
            ExitCode.FINDINGS,
        )
    return dict(templates[source].model.settings)


def _when(found: RobotInterfaces) -> str:
    try:
        moment = datetime.datetime.fromtimestamp(found.at or 0.0, datetime.timezone.utc)
    except (OverflowError, ValueError, OSError):  # a robot's clock past what dates hold
        return "at an unknown time"
    return moment.strftime("on %Y-%m-%d at %H:%M UTC") if found.at else "at an unknown time"


def _targets(
    repo: Path, known: Repository, platform: str, names: tuple[str, str], force: bool
) -> list[Path]:
    """The two files to write: named safely, on a platform that exists, not overwritten
    without `force`."""
    template, scheme = file_name("--template", names[0]), file_name("--scheme", names[1])
    if file_name("--platform", platform) not in known.platforms:
        raise CliError(
            f"unknown platform '{platform}'{did_you_mean(platform, known.platforms)}",
            ExitCode.FINDINGS,
        )
    base = repo / "models" / "platforms" / platform
    paths = [
        base / "robot-templates" / f"{template}.yaml",
        base / "mapping-schemes" / f"{scheme}.yaml",
    ]
    for path in paths:
        if path.exists() and not force:
            raise CliError(
                f"{path} exists; choose another name or pass --force to overwrite it",
                ExitCode.FINDINGS,
            )
    return paths


def new_findings(before: list[Diagnostic], after: list[Diagnostic]) -> list[Diagnostic]:
    """What the drafted files add to what the repository already reports."""
    known = Counter((d.path, d.code, d.message) for d in before)
    added = []
    for found in after:
        key = (found.path, found.code, found.message)
        if known[key]:
            known[key] -= 1
        else:
            added.append(found)
    return added


def write_validated(
    repo: Path, texts: dict[Path, str], before: list[Diagnostic]
) -> list[Diagnostic]:
    """Writes the files when the repository with them has no new error; returns the new
    findings (the errors when nothing was written)."""
    overlay = {
        path.relative_to(repo).as_posix(): text.encode("utf-8") for path, text in texts.items()
    }
    added = new_findings(before, check_with(repo, overlay).diagnostics)
    if any(d.is_error for d in added):
        return [d for d in added if d.is_error]
    _write_all(texts)
    return added


def _write_all(texts: dict[Path, str]) -> None:
    """Each file atomically; when one cannot be written, the ones before it are put back: a
    template without its scheme is no draft."""
    done: list[tuple[Path, bytes | None]] = []
    for path, text in texts.items():
        try:
            before = read_regular(path, MAX_FILE_BYTES) if path.is_file() else None
            path.parent.mkdir(parents=True, exist_ok=True)
            write_atomic(path, text.encode("utf-8"), mode=0o644)
        except OSError as exc:
            for written, old in reversed(done):
                with contextlib.suppress(OSError):
                    if old is None:
                        written.unlink()
                    else:
                        write_atomic(written, old, mode=0o644)
            raise CliError(f"cannot write {path}: {exc.strerror or exc}; nothing written") from None
        done.append((path, before))


def _report(result: Draft, origin: str, found: RobotInterfaces) -> None:
    width = max((len(m.mapping) for m in result.mappings), default=0)
    print(f"{len(result.mappings)} mapping(s) {origin}:")
    for m in result.mappings:
        what = (
            f"catalogue name (bound alike in {', '.join(m.fits)})"
            if m.fits
            else f"new name{m.hint}"
        )
        print(printable(f"  {m.mapping:<{width}}  {m.kind} {m.reported} ({m.type}): {what}"))
    if result.infrastructure:
        print(
            f"left out {result.infrastructure} interface(s) of the ROS graph itself (/rosout, "
            "/parameter_events, parameter and lifecycle services, hidden names)"
        )
    for out in result.left_out[:SHOWN]:
        print(printable(f"left out {out.kind} {out.name!r} ({out.type}): {out.reason}"))
    if len(result.left_out) > SHOWN:
        print(f"left out {len(result.left_out) - SHOWN} more interface(s) the same way")
    if found.truncated:
        print(f"the report left out {found.truncated} interface(s) by its bounds: add them by hand")


@click.command("draft")
@click.argument("robot_id", metavar="ROBOT")
@repo_option
@desk_broker_options
@click.option(
    "--platform", "platform_name", required=True, help="the robot's platform (models/platforms/P)"
)
@click.option("--template", required=True, help="robot template to write")
@click.option(
    "--scheme", default=None, help="mapping scheme to write (default: the template's name)"
)
@click.option(
    "--from",
    "from_path",
    type=click.Path(path_type=Path, dir_okay=False),
    default=None,
    help="read the interfaces from this JSON file (the topic's format), not from the broker",
)
@click.option(
    "--namespace", default=None, help="the robot's namespace (default: configs/fleet.yaml's)"
)
@click.option(
    "--settings-from", default=None, metavar="TEMPLATE", help="copy the settings of this template"
)
@click.option("--force", is_flag=True, help="overwrite existing files")
@click.option(
    "--wait",
    type=click.FloatRange(min=0.1),
    default=5.0,
    show_default=True,
    help="give up when the broker has not answered after S seconds",
)
def draft_command(
    robot_id: str,
    repo: Path,
    mqtt: BrokerOptions,
    platform_name: str,
    template: str,
    scheme: str | None,
    from_path: Path | None,
    namespace: str | None,
    settings_from: str | None,
    force: bool,
    wait: float,
) -> ExitCode:
    """Draft a robot template and a mapping scheme from the interfaces ROBOT reports.

    Reads the robot's retained <prefix>/robots/ROBOT/interfaces message (or --from FILE) and
    writes models/platforms/P/robot-templates/TEMPLATE.yaml and
    models/platforms/P/mapping-schemes/SCHEME.yaml. Each interface takes the catalogue's
    mapping name whose kind, type and name (resolved in the robot's namespace) fit it, else a
    name derived from its own, with the catalogue's closest names as a did-you-mean. Names are
    written relative under the robot's namespace; the ROS graph's own interfaces are left
    out. The files are validated with the repository before anything is written, and nothing
    is overwritten without --force. Exit 0 written, 1 refused, 2 broker or tool failure.
    """
    if not is_robot_id(robot_id):
        raise CliError(f"{robot_id!r} is not a robot id", ExitCode.FINDINGS)
    scheme = scheme or template
    checked = check(repo)
    known = checked.repo
    paths = _targets(repo, known, platform_name, (template, scheme), force)
    settings = _settings(known, platform_name, settings_from)
    ns, ns_origin = robot_namespace(known, robot_id, namespace)
    found = usable(
        from_file(from_path) if from_path is not None else from_broker(mqtt, robot_id, wait),
        robot_id,
    )
    description = f"Drafted from the interfaces {robot_id} reported {_when(found)}."
    bounds = catalogue(known, platform_name)
    result = draft(found, bounds, ns, description=description, settings=settings)
    origin = f"for {robot_id} " + (f"in namespace {ns}" if ns else "without a namespace")
    origin += f" ({ns_origin})"
    if not result.mappings:
        _report(result, origin, found)
        raise CliError(f"{robot_id} reports no interface a draft could bind", ExitCode.FINDINGS)
    comment = f"drafted by robotconf draft from {robot_id}'s interfaces ({platform_name})"
    texts = {
        paths[0]: template_yaml(result.template, modeline_ref("robot-template"), comment),
        paths[1]: scheme_yaml(result.scheme, modeline_ref("mapping-scheme"), comment),
    }
    added = write_validated(repo, texts, checked.diagnostics)
    _report(result, origin, found)
    if any(d.is_error for d in added):
        sys.stderr.write(format_text(added))
        raise CliError("the draft does not validate; nothing written", ExitCode.FINDINGS)
    _tell_written(repo, paths, added, platform_name, template, scheme)
    return ExitCode.OK


def _tell_written(
    repo: Path,
    paths: list[Path],
    added: list[Diagnostic],
    platform_name: str,
    template: str,
    scheme: str,
) -> None:
    """What the draft wrote, what the repository says of it now, and what to do next."""
    for path in paths:
        print(f"wrote {path.relative_to(repo).as_posix()}")
    sys.stdout.write(format_text(added))
    if any(d.code == "RC608" for d in added):
        print(
            "RC608 warns where schemes of one platform bind different mappings: a new robot's "
            "scheme lacks what it lacks, other schemes its new names (bind them there, or rename)"
        )
    learn = " and ".join(dict.fromkeys([template, scheme]))
    print(
        f"next: robotconf schemas (editors learn {learn}), then e.g. "
        f"robotconf autofill --platform {platform_name} --scheme {scheme} --template {template}"
    )
