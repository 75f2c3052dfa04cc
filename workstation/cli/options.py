"""Options of the commands that read a repository: which folder, which revision."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

F = TypeVar("F", bound=Callable[..., Any])


def repo_option(command: F) -> F:
    return click.option(
        "--repo",
        type=click.Path(path_type=Path),
        default=Path("."),
        help="repository folder (default: current)",
    )(command)


def rev_option(command: F) -> F:
    return click.option(
        "--rev", default=None, help="read this git revision instead of the work tree"
    )(command)


# Where the desk reads the reconciler's outcome ledger (`history`, `ui`): one option, one rule
# (readmodel.ledger.find_ledger).
ledger_dir_option = click.option(
    "--state-dir",
    type=click.Path(path_type=Path, file_okay=False),
    default=None,
    metavar="DIR",
    help="the reconciler's --state-dir whose outcome ledger is read (default: robotconf up's in "
    "this repository when it has one, else the reconciler's default for --prefix)",
)
