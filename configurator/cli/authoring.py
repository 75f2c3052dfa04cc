"""Commands that write files: autofill (a capability configuration) and schemas."""

from __future__ import annotations

import argparse
import sys

from configurator.autofill import autofill, to_yaml
from configurator.diagnostics import did_you_mean, format_text
from configurator.schemas import dump, generate, modeline_ref
from configurator.workspace import check

EXIT_OK, EXIT_FINDINGS = 0, 1


def cmd_autofill(args: argparse.Namespace) -> int:
    repo = check(args.repo).repo
    platform = repo.platforms.get(args.platform)
    problems = []
    if platform is None:
        problems.append(
            f"unknown platform '{args.platform}'{did_you_mean(args.platform, repo.platforms)}"
        )
    else:
        if args.scheme not in platform.schemes:
            problems.append(
                f"platform {args.platform} has no mapping scheme '{args.scheme}'"
                f"{did_you_mean(args.scheme, platform.schemes)}"
            )
        if args.template not in platform.templates:
            problems.append(
                f"platform {args.platform} has no robot template '{args.template}'"
                f"{did_you_mean(args.template, platform.templates)}"
            )
    if problems:
        for p in problems:
            print(f"robotconf: {p}", file=sys.stderr)
        return EXIT_FINDINGS
    name = args.name or f"{args.template}-{args.scheme}"
    target = args.repo / "configs" / "capabilities" / f"{name}.yaml"
    if target.exists() and not args.force:
        print(f"robotconf: {target} exists; choose another --name or pass --force", file=sys.stderr)
        return EXIT_FINDINGS
    result = autofill(repo, args.platform, args.scheme, args.template)
    if not result.config.actions:
        print(
            f"robotconf: no action of {args.platform} has a logic that {args.template} "
            f"can run under scheme {args.scheme}",
            file=sys.stderr,
        )
        return EXIT_FINDINGS
    text = to_yaml(
        result.config,
        modeline_ref("capability"),
        f"written by robotconf autofill for {args.template} ({args.platform}, {args.scheme})",
    )
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(text, encoding="utf-8")
    print(f"wrote {target}")
    for action, logic in result.config.actions.items():
        print(f"  {action}: {logic}")
    for action, reasons in sorted(result.skipped.items()):
        print(f"  skipped {action}: {'; '.join(reasons)}")
    # The promise of autofill is a file that validates: prove it.
    errors = [d for d in check(args.repo).errors if d.path.endswith(f"capabilities/{name}.yaml")]
    if errors:
        sys.stderr.write(format_text(errors))
        return EXIT_FINDINGS
    return EXIT_OK


def cmd_schemas(args: argparse.Namespace) -> int:
    repo = check(args.repo).repo
    wanted = {name: dump(schema) for name, schema in generate(repo).items()}
    folder = args.repo / "schemas"
    if args.check:
        stale = [
            name
            for name, text in wanted.items()
            if not (folder / name).is_file() or (folder / name).read_text(encoding="utf-8") != text
        ]
        if stale:
            print(
                f"robotconf: schemas/ is stale ({', '.join(stale)}); run: robotconf schemas",
                file=sys.stderr,
            )
            return EXIT_FINDINGS
        print(f"schemas/ is current ({len(wanted)} schemas)")
        return EXIT_OK
    folder.mkdir(parents=True, exist_ok=True)
    written = 0
    for name, text in wanted.items():
        path = folder / name
        if not path.is_file() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
            written += 1
    print(f"schemas/: {written} written, {len(wanted) - written} unchanged")
    return EXIT_OK
