"""Commands that show the repository: catalog, tree, render and plan (read-only)."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import click
from rich.console import Group
from rich.tree import Tree

from robotconf.configurator.catalog import Section, catalogue_sections, catalogue_summary
from robotconf.configurator.incremental import BuildCache
from robotconf.configurator.plan import (
    FleetRead,
    Plan,
    PlanBase,
    Reported,
    choose_base,
    format_plan_markdown,
    format_plan_text,
    make_plan,
    plan_as_json,
    with_drift,
)
from robotconf.configurator.render import FleetRender, RenderError, render_robot
from robotconf.configurator.source import SourceError
from robotconf.configurator.tree import (
    CapabilityTree,
    action_label,
    alternative_label,
    build_tree,
    heading,
    logic_label,
    task_label,
)
from robotconf.configurator.types import RolloutPolicy
from robotconf.configurator.workspace import Checked, check
from robotconf.contract.diagnostics import did_you_mean, format_text, summary_line
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.textsafe import json_printable, markdown_text, printable
from robotconf.contract.topics import Role, subscriptions
from robotconf.contract.wire import Topics
from robotconf.workstation.cli.broker_options import BrokerOptions, desk_broker_options
from robotconf.workstation.cli.options import repo_option, rev_option
from robotconf.workstation.cli.terminal import safe, show


def catalogue_view(sections: list[Section]) -> Group:
    trees = []
    for title, entries in sections:
        section = Tree(safe(title, "bold"))
        for line, details in entries:
            entry = section.add(safe(line))
            for detail in details:
                entry.add(safe(detail))
        trees.append(section)
    return Group(*trees)


@click.command("catalog")
@repo_option
@rev_option
@click.option("--json", "as_json", is_flag=True, help="machine-readable output")
def catalog(repo: Path, rev: str | None, as_json: bool) -> ExitCode:
    """List what exists in the catalogue."""
    checked = check(repo, rev)
    summary = catalogue_summary(checked.repo)
    if as_json:
        print(json.dumps(summary, indent=2))
    else:
        show(catalogue_view(catalogue_sections(summary)))
    if checked.errors:
        print(
            f"note: the repository has {len(checked.errors)} error(s); run robotconf validate",
            file=sys.stderr,
        )
    return ExitCode.OK


def capability_view(tree: CapabilityTree) -> Tree:
    top = Tree(safe(heading(tree), "bold"))
    groups = [
        (
            task_label(task),
            [(None, task.implementations[0])]
            if len(task.implementations) == 1
            else [
                (alternative_label(i, impl), impl) for i, impl in enumerate(task.implementations)
            ],
        )
        for task in tree.tasks
    ]
    if tree.other_actions:
        groups.append(("actions in no task", [(None, tree.other_actions)]))
    for label, alternatives in groups:
        group = top.add(safe(label))
        for title, actions in alternatives:
            parent = group if title is None else group.add(safe(title))
            for node in actions:
                branch = parent.add(safe(action_label(node)))
                for logic in node.logics:
                    branch.add(safe(logic_label(logic)))
    return top


@click.command("tree")
@repo_option
@rev_option
@click.argument("capability")
def tree(repo: Path, rev: str | None, capability: str) -> ExitCode:
    """Show a capability's tasks > actions > logics: chosen, available, and why not."""
    checked = check(repo, rev)
    found = checked.repo
    if capability not in found.capabilities:
        raise CliError(
            f"no capability configuration '{capability}'"
            f"{did_you_mean(capability, found.capabilities)}",
            ExitCode.FINDINGS,
        )
    show(capability_view(build_tree(found, capability)))
    path = found.capabilities[capability].path
    own = [d for d in checked.errors if d.path == path]
    if own:
        sys.stderr.write(format_text(own))
        return ExitCode.FINDINGS
    return ExitCode.OK


@click.command("render")
@repo_option
@rev_option
@click.argument("robot_id")
def render(repo: Path, rev: str | None, robot_id: str) -> ExitCode:
    """Print a robot's Launch Request as JSON."""
    checked = check(repo, rev)
    if not checked.ok:
        sys.stderr.write(format_text(checked.diagnostics))
        sys.stderr.write(summary_line(checked.diagnostics, checked.repo.files_read) + "\n")
        raise CliError("not rendering from an invalid repository", ExitCode.FINDINGS)
    try:
        request = render_robot(checked.repo, robot_id)
    except RenderError as exc:
        raise CliError(str(exc), ExitCode.FINDINGS) from None
    print(json_printable(json.dumps(request.wire(), indent=2, sort_keys=True, ensure_ascii=False)))
    return ExitCode.OK


def _fleet_at(
    repo: Path, rev: str | None, label: str, cache: BuildCache
) -> tuple[FleetRender, RolloutPolicy | None]:
    """The revision's rendered fleet and its rollout policy."""
    try:
        checked = check(repo, rev, cache.check)
    except SourceError as exc:
        raise CliError(f"{label} revision does not exist: {exc}") from None
    if not checked.ok:
        raise CliError(_does_not_validate(checked, rev, label))
    try:
        rendered = cache.render(checked)
    except RenderError as exc:
        raise CliError(f"{label}: {exc}") from None
    fleet = checked.repo.fleet
    return rendered, fleet.model.rollout if fleet is not None else None


def _does_not_validate(checked: Checked, rev: str | None, label: str) -> str:
    """Its errors on stderr, under a heading that says the revision exists; the reason there
    is no plan: an invalid commit renders no fleet, and the base is what robots run, which the
    reconciler never takes from a commit that does not validate."""
    name = "(work tree)" if rev is None else f"{rev} ({checked.repo.revision[:12]})"
    errors = len(checked.errors)
    count = f"{errors} error{'s' if errors != 1 else ''}"
    sys.stderr.write(f"robotconf: {label} revision {name} exists but does not validate:\n")
    sys.stderr.write(format_text(checked.errors))
    why = (
        "no robot runs it (the reconciler applies only revisions that validate): give as --base "
        "the revision `robotconf status` shows as applied"
        if label == "base"
        else "fix them, then plan again"
    )
    return f"{label} revision {name} is invalid ({count} above), so there is no plan; {why}"


def _reported_interfaces(mqtt: BrokerOptions, wait: float) -> Reported | None:
    """Each robot's retained interfaces report (or why it cannot be read); None, said on
    stderr, when the broker does not answer: the plan stands without drift."""
    from robotconf.readmodel.observed import parse_retained
    from robotconf.readmodel.retained import take_snapshot_said

    connection = mqtt.connection()
    topics = Topics(mqtt.prefix)
    messages, lost = take_snapshot_said(
        connection, subscriptions(Role.VIEWER, mqtt.prefix, "interfaces"), topics.sync, "plan", wait
    )
    if messages is None:
        sys.stderr.write(
            f"robotconf: note: no answer from {connection.address.url} within {wait:g} s: "
            "drift is not judged (--wait S)\n"
        )
        return None
    if lost is not None:
        sys.stderr.write(
            f"robotconf: note: the broker dropped retained messages ({printable(lost)}): "
            "drift is judged only for the robots whose interfaces arrived; raise its "
            "max_queued_messages (robotconf broker-config sets it for the fleet)\n"
        )
    seen = parse_retained(messages, topics)
    return {r: (robot.interfaces, robot.interfaces_error) for r, robot in seen.robots.items()}


def _fleet_runs(mqtt: BrokerOptions, wait: float) -> FleetRead:
    """The revision the fleet's reconciler has applied (its retained status), read from the
    broker within `wait` seconds; a broker that refuses or is not there is known at once."""
    from pydantic import ValidationError

    from robotconf.contract.safejson import PayloadError
    from robotconf.contract.wire import ReconcilerStatus
    from robotconf.readmodel.retained import RetainedView, read_object

    connection = mqtt.connection()
    url = connection.address.url
    topics = Topics(mqtt.prefix)
    filters = subscriptions(Role.VIEWER, mqtt.prefix, "reconciler_status")
    with RetainedView(connection, filters, topics.sync, role="plan-base") as view:
        if not view.wait_synced(wait, or_refused=True):
            if view.refused is not None:
                return FleetRead(url, f"the broker at {url} refused the login: {view.refused}")
            return FleetRead(url, f"no broker reachable at {url}")
        payload = view.get(topics.reconciler_status)
    try:
        status = ReconcilerStatus.model_validate(read_object(payload)) if payload else None
    except (PayloadError, ValidationError):
        status = None  # not a reconciler's status: it names no applied revision
    return FleetRead(url, applied=status.last_applied_revision if status is not None else None)


def _fleets(
    repo: Path, base: str, head: str | None, chosen: PlanBase | None
) -> tuple[FleetRender, tuple[FleetRender, RolloutPolicy | None]]:
    """The base's and the head's rendered fleets (the head's rollout policy too); both are
    checked before either is reported: each names its own problems."""
    found: dict[str, tuple[FleetRender, RolloutPolicy | None]] = {}
    problems: list[str] = []
    cache = BuildCache()  # the head is built from what the base proved: it costs its changes
    for label, rev in (("base", base), ("head", head)):
        try:
            found[label] = _fleet_at(repo, rev, label, cache)
        except CliError as exc:
            lacking = label == "base" and chosen is not None and chosen.from_fleet
            problems.append(
                f"the fleet runs {base[:12]}, which this clone cannot build ({exc.message}): "
                "git fetch, or give --base"
                if lacking
                else exc.message
            )
    if problems:
        raise CliError("\nrobotconf: ".join(problems))
    return found["base"][0], found["head"]


def _subjects(repo: Path, result: Plan) -> dict[str, str]:
    """The commit subjects of the plan's revisions (the work tree's side has none)."""
    from robotconf.readmodel.commits import CommitBook

    revisions = (result.base, result.head)  # the work tree's is no commit: left out
    return {line.revision: line.subject for line in CommitBook(repo).lines(revisions)}


def _show_plan(result: Plan, fmt: str, chosen: PlanBase | None) -> None:
    """The plan in `fmt`; when the base was chosen (no --base), which one and why: the first
    line of text and markdown, `against` in JSON."""
    lead = None if chosen is None else printable(chosen.line(result.base))
    if fmt == "markdown":
        sys.stdout.write("" if lead is None else f"{markdown_text(lead)}\n\n")
        sys.stdout.write(format_plan_markdown(result))
    elif fmt == "json":
        found = plan_as_json(result)
        if chosen is not None:
            source = "fleet" if chosen.from_fleet else "HEAD"
            found["against"] = {"source": source, "why": printable(chosen.why)}
        print(json.dumps(found, indent=2))
    else:
        sys.stdout.write("" if lead is None else lead + "\n")
        sys.stdout.write(format_plan_text(result))


@click.command("plan")
@repo_option
@click.option(
    "--base",
    default=None,
    help="the revision robots run now (default: what the fleet's reconciler has applied, read "
    "from the broker; HEAD when no broker answers)",
)
@click.option(
    "--head", "--rev", "head", default=None, help="the new revision (default: the work tree)"
)
@click.option("--format", "fmt", type=click.Choice(["text", "markdown", "json"]), default="text")
@desk_broker_options
@click.option(
    "--wait",
    type=float,
    default=3.0,
    help="seconds to wait for the broker: the fleet's revision (without --base), the robots' "
    "interfaces (with a broker given)",
)
def plan(
    repo: Path, base: str | None, head: str | None, fmt: str, mqtt: BrokerOptions, wait: float
) -> ExitCode:
    """What would change per robot between two revisions (exit 1 when something would).

    Without --base, the base is what the fleet runs: the revision the reconciler has applied,
    read from its retained status on the broker (--broker, $ROBOTCONF_BROKER, a running
    `robotconf up`'s broker, else the default one); when no broker answers, HEAD. The first
    line says which. With a broker given (or robotconf up's), also the drift of each robot
    that would change: what its new request needs that the interfaces it reports lack."""
    chosen = None if base is not None else choose_base(_fleet_runs(mqtt, wait))
    base_rev = chosen.revision if chosen is not None else base or "HEAD"
    base_fleet, (head_fleet, rollout) = _fleets(repo, base_rev, head, chosen)
    # The head's policy decides the waves: it is the one the reconciler will roll out by.
    result = make_plan(base_fleet, head_fleet, rollout)
    result = replace(result, subjects=_subjects(repo, result))
    if mqtt.broker is not None:
        reported = _reported_interfaces(mqtt, wait)
        if reported is not None:
            result = with_drift(result, head_fleet, reported)
    _show_plan(result, fmt, chosen)
    return ExitCode.FINDINGS if result.changes else ExitCode.OK
