"""Arguments of the commands that talk to a broker; their work lives in reconciler/."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

Add = Callable[[str, Callable[[argparse.Namespace], int], str], argparse.ArgumentParser]


def _reconcile(args: argparse.Namespace) -> int:
    from reconciler.commands import cmd_reconcile

    return cmd_reconcile(args)


def _status(args: argparse.Namespace) -> int:
    from reconciler.commands import cmd_status

    return cmd_status(args)


def _up(args: argparse.Namespace) -> int:
    from reconciler.commands import cmd_up

    return cmd_up(args)


def add_commands(add: Add, repo_args: Callable[..., Any], broker_args: Callable[..., Any]) -> None:
    p = add("reconcile", _reconcile, "make the fleet match a git branch (runs until signalled)")
    repo_args(p, rev=False)
    broker_args(p)
    p.add_argument("--branch", required=True, help="the branch whose head commit is applied")
    p.add_argument("--remote", default=None, help="fetch this URL into a cache clone instead")
    p.add_argument(
        "--interval", type=float, default=30.0, help="resync (and fetch) period in seconds"
    )
    p.add_argument(
        "--signing-key",
        type=Path,
        default=None,
        help="Ed25519 private key (robotconf keys generate): sign every Launch Request",
    )
    p.add_argument(
        "--cache-dir",
        default=None,
        help="where --remote is cloned (default: ~/.cache/robotconf/remotes)",
    )

    p = add("status", _status, "show the fleet: desired vs reported, worst first")
    repo_args(p)
    broker_args(p)
    p.add_argument("--watch", action="store_true", help="keep showing until interrupted")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument(
        "--wait",
        type=float,
        default=5.0,
        help="give up when the broker's retained messages have not arrived after S seconds",
    )

    p = add("up", _up, "the whole loop on this machine: broker, reconciler, agents, status")
    repo_args(p, rev=False)
    broker_args(p)
    p.add_argument("--branch", default=None, help="branch to reconcile (default: the current)")
    p.add_argument("--workdir", default=None, help="where agents keep their files")
    p.add_argument(
        "--no-signing",
        action="store_true",
        help="do not sign requests (by default up signs them with a key kept in its workdir)",
    )
