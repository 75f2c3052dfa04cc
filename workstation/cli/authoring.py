"""Commands that write files: autofill (a capability configuration) and schemas."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from robotconf.configurator.autofill import AutofillResult, to_yaml
from robotconf.configurator.autofill import autofill as fill_capability
from robotconf.configurator.fitting import interfaces_fit
from robotconf.configurator.repository import Repository
from robotconf.configurator.schemas import dump, generate, modeline_ref
from robotconf.configurator.workspace import check
from robotconf.contract.diagnostics import did_you_mean, format_text
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.models import file_name, file_name_problem
from robotconf.workstation.cli.broker_options import BrokerOptions, desk_broker_options
from robotconf.workstation.cli.draft import from_broker, from_file, robot_namespace, usable
from robotconf.workstation.cli.options import repo_option


@click.command("autofill")
@repo_option
@click.option("--platform", "platform_name", required=True)
@click.option("--scheme", required=True, help="mapping scheme")
@click.option("--template", default=None, help="robot template (required unless --robot is given)")
@click.option("--name", default=None, help="configuration name (default: TEMPLATE-SCHEME)")
@click.option("--force", is_flag=True, help="overwrite an existing file")
@click.option(
    "--all",
    "every",
    is_flag=True,
    help="select every logic the template and scheme serve (an action then lists several)",
)
@click.option(
    "--robot",
    "robot_id",
    default=None,
    help="select only logics this live robot can run: each mapping they need, bound by the "
    "scheme and resolved in the robot's namespace, is among its reported interfaces",
)
@click.option(
    "--from",
    "from_path",
    type=click.Path(path_type=Path),
    default=None,
    help="with --robot: read its interfaces from this file (the topic's JSON), not the broker",
)
@click.option(
    "--namespace", default=None, help="with --robot: its namespace (default: configs/fleet.yaml)"
)
@click.option(
    "--wait",
    type=click.FloatRange(min=0.1, max=3600),
    default=5.0,
    show_default=True,
    help="with --robot: seconds to wait for the broker",
)
@desk_broker_options
def autofill(
    repo: Path,
    platform_name: str,
    scheme: str,
    template: str | None,
    name: str | None,
    force: bool,
    every: bool,
    robot_id: str | None,
    from_path: Path | None,
    namespace: str | None,
    wait: float,
    mqtt: BrokerOptions,
) -> ExitCode:
    """Write a capability configuration that fits a template, or a live robot (--robot, its
    reported interfaces), or both: per action, the first logic they serve, or with --all
    every such logic (the action then lists them: `Follow: [follow_with_poses,
    follow_with_bluetooth]`); the file validates. Every name given may become a file name
    (letters, digits, '_', '.', '-'; 1 to 64, starting with a letter or digit), else nothing
    is read or written."""
    if template is None and robot_id is None:
        raise CliError("give --template, --robot, or both", ExitCode.TOOL)
    if robot_id is None and from_path is not None:
        raise CliError("--from reads a robot's interfaces: give --robot too", ExitCode.TOOL)
    name = _file_name(platform_name, scheme, template, robot_id, name)
    found = check(repo).repo
    problems = _unknown_names(found, platform_name, scheme, template)
    if problems:
        raise CliError("\nrobotconf: ".join(problems), ExitCode.FINDINGS)
    robot_fit = None
    if robot_id is not None:
        reported = usable(
            from_file(from_path) if from_path is not None else from_broker(mqtt, robot_id, wait),
            robot_id,
        )
        robot_ns, _ = robot_namespace(found, robot_id, namespace)
        bound = found.platforms[platform_name].schemes[scheme].model
        robot_fit = interfaces_fit(bound, robot_ns, reported)
    target = repo / "configs" / "capabilities" / f"{name}.yaml"
    if target.exists() and not force:
        raise CliError(f"{target} exists; choose another --name or pass --force", ExitCode.FINDINGS)
    result = fill_capability(
        found, platform_name, scheme, template, every=every, robot_fit=robot_fit
    )
    fitted = " and ".join(
        part for part in (template, robot_id and f"robot {robot_id}'s interfaces") if part
    )
    if not result.config.actions:
        raise CliError(
            f"no action of {platform_name} has a logic that {fitted} can run under scheme {scheme}",
            ExitCode.FINDINGS,
        )
    text = to_yaml(
        result.config,
        modeline_ref("capability"),
        f"written by robotconf autofill for {fitted} ({platform_name}, {scheme})",
    )
    return _write_and_prove(repo, target, text, result)


def _file_name(
    platform_name: str, scheme: str, template: str | None, robot_id: str | None, name: str | None
) -> str:
    """The configuration's name, every name it may be made of checked first: each may become a
    file name (contract.models.file_name), the one chosen too."""
    given = {
        "--platform": platform_name,
        "--scheme": scheme,
        "--template": template,
        "--robot": robot_id,
        "--name": name,
    }
    for what, value in given.items():
        if value is not None:
            file_name(what, value)
    if name is not None:
        return name
    made = f"{template or robot_id}-{scheme}"
    if file_name_problem(made) is not None:
        raise CliError(f"the configuration's name {made} is too long (64 at most): give --name")
    return made


def _unknown_names(
    found: Repository, platform_name: str, scheme: str, template: str | None
) -> list[str]:
    """What of the platform, scheme and template autofill is given does not exist."""
    platform = found.platforms.get(platform_name)
    if platform is None:
        return [f"unknown platform '{platform_name}'{did_you_mean(platform_name, found.platforms)}"]
    problems = []
    if scheme not in platform.schemes:
        problems.append(
            f"platform {platform_name} has no mapping scheme '{scheme}'"
            f"{did_you_mean(scheme, platform.schemes)}"
        )
    if template is not None and template not in platform.templates:
        problems.append(
            f"platform {platform_name} has no robot template '{template}'"
            f"{did_you_mean(template, platform.templates)}"
        )
    return problems


def _write_and_prove(repo: Path, target: Path, text: str, result: AutofillResult) -> ExitCode:
    """Write the capability configuration, say what it selected and skipped, and check it."""
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(text, encoding="utf-8")
    print(f"wrote {target}")
    for action in result.config.actions:
        print(f"  {action}: {', '.join(result.config.logics_of(action))}")
    for action, reasons in sorted(result.skipped.items()):
        print(f"  skipped {action}: {'; '.join(reasons)}")
    # The promise of autofill is a file that validates: prove it.
    errors = [d for d in check(repo).errors if d.path.endswith(f"capabilities/{target.name}")]
    if errors:
        sys.stderr.write(format_text(errors))
        return ExitCode.FINDINGS
    return ExitCode.OK


@click.command("schemas")
@repo_option
@click.option("--check", "check_only", is_flag=True, help="fail when schemas/ is stale")
def schemas(repo: Path, check_only: bool) -> ExitCode:
    """Write the JSON Schemas under schemas/ (editors use them); --check fails when stale."""
    wanted = {name: dump(schema) for name, schema in generate(check(repo).repo).items()}
    folder = repo / "schemas"
    if check_only:
        stale = [
            name
            for name, text in wanted.items()
            if not (folder / name).is_file() or (folder / name).read_text(encoding="utf-8") != text
        ]
        if stale:
            raise CliError(
                f"schemas/ is stale ({', '.join(stale)}); run: robotconf schemas",
                ExitCode.FINDINGS,
            )
        print(f"schemas/ is current ({len(wanted)} schemas)")
        return ExitCode.OK
    folder.mkdir(parents=True, exist_ok=True)
    written = 0
    for schema_name, text in wanted.items():
        path = folder / schema_name
        if not path.is_file() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
            written += 1
    print(f"schemas/: {written} written, {len(wanted) - written} unchanged")
    return ExitCode.OK
