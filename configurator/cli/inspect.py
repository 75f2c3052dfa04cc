"""Read-only commands: validate, catalog, tree, render, plan."""

from __future__ import annotations

import argparse
import json
import sys

from configurator.catalog import catalogue_summary, format_catalogue
from configurator.diagnostics import (
    Diagnostic,
    did_you_mean,
    format_github,
    format_json,
    format_text,
    summary_line,
)
from configurator.plan import format_plan_markdown, format_plan_text, make_plan, plan_as_json
from configurator.render import FleetRender, RenderError, render_fleet, render_robot
from configurator.textsafe import json_printable
from configurator.tree import build_tree, format_tree
from configurator.workspace import Checked, check

EXIT_OK, EXIT_FINDINGS, EXIT_TOOL = 0, 1, 2


def _print_errors(checked: Checked) -> None:
    sys.stderr.write(format_text(checked.diagnostics))
    sys.stderr.write(summary_line(checked.diagnostics, checked.repo.files_read) + "\n")


def cmd_validate(args: argparse.Namespace) -> int:
    checked = check(args.repo, args.rev)
    diagnostics: list[Diagnostic] = checked.diagnostics
    if args.format == "json":
        sys.stdout.write(format_json(diagnostics))
    elif args.format == "github":
        sys.stdout.write(format_github(diagnostics))
        print(summary_line(diagnostics, checked.repo.files_read), file=sys.stderr)
    else:
        sys.stdout.write(format_text(diagnostics))
        print(summary_line(diagnostics, checked.repo.files_read), file=sys.stderr)
    return EXIT_FINDINGS if checked.errors else EXIT_OK


def cmd_catalog(args: argparse.Namespace) -> int:
    checked = check(args.repo, args.rev)
    summary = catalogue_summary(checked.repo)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        sys.stdout.write(format_catalogue(summary))
    if checked.errors:
        print(
            f"note: the repository has {len(checked.errors)} error(s); run robotconf validate",
            file=sys.stderr,
        )
    return EXIT_OK


def cmd_tree(args: argparse.Namespace) -> int:
    checked = check(args.repo, args.rev)
    repo = checked.repo
    if args.capability not in repo.capabilities:
        print(
            f"robotconf: no capability configuration '{args.capability}'"
            f"{did_you_mean(args.capability, repo.capabilities)}",
            file=sys.stderr,
        )
        return EXIT_FINDINGS
    sys.stdout.write(format_tree(build_tree(repo, args.capability)))
    path = repo.capabilities[args.capability].path
    own = [d for d in checked.errors if d.path == path]
    if own:
        sys.stderr.write(format_text(own))
        return EXIT_FINDINGS
    return EXIT_OK


def cmd_render(args: argparse.Namespace) -> int:
    checked = check(args.repo, args.rev)
    if not checked.ok:
        _print_errors(checked)
        print("robotconf: not rendering from an invalid repository", file=sys.stderr)
        return EXIT_FINDINGS
    try:
        request = render_robot(checked.repo, args.robot_id)
    except RenderError as exc:
        print(f"robotconf: {exc}", file=sys.stderr)
        return EXIT_FINDINGS
    print(json_printable(json.dumps(request.wire(), indent=2, sort_keys=True, ensure_ascii=False)))
    return EXIT_OK


def _fleet_at(args: argparse.Namespace, rev: str | None, label: str) -> FleetRender | None:
    checked = check(args.repo, rev)
    if not checked.ok:
        sys.stderr.write(format_text(checked.errors))
        print(f"robotconf: {label} revision {rev or '(work tree)'} is invalid", file=sys.stderr)
        return None
    try:
        return render_fleet(checked.repo)
    except RenderError as exc:
        print(f"robotconf: {label}: {exc}", file=sys.stderr)
        return None


def cmd_plan(args: argparse.Namespace) -> int:
    base = _fleet_at(args, args.base, "base")
    head = _fleet_at(args, args.head, "head")
    if base is None or head is None:
        return EXIT_TOOL
    plan = make_plan(base, head)
    if args.format == "markdown":
        sys.stdout.write(format_plan_markdown(plan))
    elif args.format == "json":
        print(json.dumps(plan_as_json(plan), indent=2))
    else:
        sys.stdout.write(format_plan_text(plan))
    return EXIT_FINDINGS if plan.changes else EXIT_OK
