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
