"""`robotconf validate`: the whole repository checked, findings in text, JSON or GitHub form.

Start-up matters here (pre-commit, editors): this module imports the checker and nothing else.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from robotconf.configurator.gcpause import collector_paused
from robotconf.configurator.workspace import Checked, check
from robotconf.contract.diagnostics import format_github, format_json, format_text, summary_line
from robotconf.contract.errors import ExitCode
from robotconf.workstation.cli.options import repo_option, rev_option


@click.command("validate")
@repo_option
@rev_option
@click.option("--format", "fmt", type=click.Choice(["text", "json", "github"]), default="text")
@click.argument("files", nargs=-1, type=click.UNPROCESSED)  # pre-commit may pass some
def validate(repo: Path, rev: str | None, fmt: str, files: tuple[str, ...]) -> ExitCode:
    """Validate the whole repository (file names given are ignored: one file can break another).

    \b
    A lab tunes rules in .robotconf.yaml at the repository root (read from the work tree, or
    from the commit with --rev), and silences one finding with a comment on its line:
      .robotconf.yaml     rules: {RC505: warning, RC608: off}   (error, warning or off)
      configs/fleet.yaml  tb3-04: {...}  # robotconf: ignore RC505, RC608
    Rules that could make a robot unsafe or undeliverable cannot be tuned (the docs'
    reference/rules.md says why for each).
    Exit 1 on errors; warnings alone exit 0."""
    # Paused until what the build made is freed (by reference counting, as `_report`
    # returns): a collection while it lives would walk it all for nothing.
    with collector_paused():
        return _report(check(repo, rev), fmt)


def _report(checked: Checked, fmt: str) -> ExitCode:
    diagnostics = checked.diagnostics
    if fmt == "json":
        sys.stdout.write(format_json(diagnostics))
    else:
        sys.stdout.write(
            format_github(diagnostics) if fmt == "github" else format_text(diagnostics)
        )
        print(summary_line(diagnostics, checked.repo.files_read), file=sys.stderr)
    return ExitCode.FINDINGS if checked.errors else ExitCode.OK
