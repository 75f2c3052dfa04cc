"""`robotconf`: the argument parser and dispatch; each command lives in its own module."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from pathlib import Path

from configurator import __version__
from configurator.source import SourceError
from configurator.wire import BROKER_ENV, DEFAULT_BROKER, DEFAULT_PREFIX

EXIT_OK, EXIT_FINDINGS, EXIT_TOOL = 0, 1, 2

Handler = Callable[[argparse.Namespace], int]


def _repo_args(parser: argparse.ArgumentParser, *, rev: bool = True) -> None:
    parser.add_argument(
        "--repo", type=Path, default=Path("."), help="repository folder (default: current)"
    )
    if rev:
        parser.add_argument(
            "--rev", default=None, help="read this git revision instead of the work tree"
        )


def _broker_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--broker",
        default=os.environ.get(BROKER_ENV),
        help=f"mqtt://host:port or mqtts://host:port (default: ${BROKER_ENV}, "
        f"else {DEFAULT_BROKER})",
    )
    parser.add_argument(
        "--prefix", default=DEFAULT_PREFIX, help="topic prefix (default: %(default)s)"
    )
    parser.add_argument("--username", default=None, help="broker user name")
    parser.add_argument(
        "--password-file", type=Path, default=None, help="file holding the password"
    )
    parser.add_argument("--ca-file", type=Path, default=None, help="CA certificate for mqtts://")
    parser.add_argument(
        "--cert-file", type=Path, default=None, help="client certificate (mqtts://)"
    )
    parser.add_argument("--key-file", type=Path, default=None, help="client key (mqtts://)")
    parser.add_argument(
        "--insecure",
        action="store_true",
        help="accept a TLS server whose certificate cannot be verified (test benches only)",
    )


def build_parser() -> argparse.ArgumentParser:
    from configurator.cli import authoring, inspect, security, server

    parser = argparse.ArgumentParser(
        prog="robotconf",
        description="GitOps for a mixed robot fleet: validate, render and deliver Launch Requests.",
    )
    parser.add_argument("--version", action="version", version=f"robotconf {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    def add(name: str, handler: Handler, help_text: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(handler=handler)
        return p

    p = add("validate", inspect.cmd_validate, "validate the whole repository")
    _repo_args(p)
    p.add_argument("--format", choices=["text", "json", "github"], default="text")
    p.add_argument("files", nargs="*", help=argparse.SUPPRESS)  # pre-commit may pass some

    p = add("catalog", inspect.cmd_catalog, "list what exists in the catalogue")
    _repo_args(p)
    p.add_argument("--json", action="store_true", help="machine-readable output")

    p = add("tree", inspect.cmd_tree, "show a capability's tasks > actions > logics")
    _repo_args(p)
    p.add_argument("capability", help="capability configuration name")

    p = add("render", inspect.cmd_render, "print a robot's Launch Request as JSON")
    _repo_args(p)
    p.add_argument("robot_id")

    p = add("plan", inspect.cmd_plan, "what would change per robot between two revisions")
    _repo_args(p, rev=False)
    p.add_argument("--base", required=True, help="the revision robots run now")
    p.add_argument("--head", default=None, help="the new revision (default: the work tree)")
    p.add_argument("--format", choices=["text", "markdown", "json"], default="text")

    p = add(
        "autofill", authoring.cmd_autofill, "write a capability configuration that fits a template"
    )
    _repo_args(p, rev=False)
    p.add_argument("--platform", required=True)
    p.add_argument("--scheme", required=True, help="mapping scheme")
    p.add_argument("--template", required=True, help="robot template")
    p.add_argument("--name", default=None, help="configuration name (default: TEMPLATE-SCHEME)")
    p.add_argument("--force", action="store_true", help="overwrite an existing file")

    p = add("schemas", authoring.cmd_schemas, "write the JSON Schemas under schemas/")
    _repo_args(p, rev=False)
    p.add_argument("--check", action="store_true", help="fail when schemas/ is stale")

    p = add("keys", security.cmd_keys, "make the Ed25519 key pair that signs Launch Requests")
    p.add_argument("action", choices=["generate"], help="generate a new key pair")
    p.add_argument("--out", type=Path, default=Path("keys"), help="folder (default: keys/)")
    p.add_argument("--force", action="store_true", help="replace an existing pair")

    p = add(
        "broker-config",
        security.cmd_broker_config,
        "write Mosquitto ACL, password file and TLS listener from configs/fleet.yaml",
    )
    _repo_args(p)
    p.add_argument("--prefix", default=DEFAULT_PREFIX, help="topic prefix (default: %(default)s)")
    p.add_argument("--out", type=Path, default=Path("broker"), help="folder (default: broker/)")
    p.add_argument(
        "--install-dir",
        type=Path,
        default=None,
        help="where the broker host keeps acl and passwd (default: OUT)",
    )
    p.add_argument(
        "--secrets", type=Path, default=None, help="password files (default: OUT/secrets)"
    )
    p.add_argument(
        "--port", type=int, default=8883, help="robots' listener port (default: %(default)s)"
    )
    p.add_argument(
        "--service-port",
        type=int,
        default=None,
        help="listener port of the reconciler and viewers (default: --port + 1)",
    )
    p.add_argument("--bind", default=None, help="listener address (default: all)")
    p.add_argument("--certfile", type=Path, default=None, help="server certificate (TLS)")
    p.add_argument("--keyfile", type=Path, default=None, help="server key (TLS)")
    p.add_argument("--cafile", type=Path, default=None, help="CA for client certificates")
    p.add_argument("--require-certificate", action="store_true", help="clients must present one")
    p.add_argument("--reconciler-user", default="reconciler")
    p.add_argument("--viewer-user", default="viewer")
    p.add_argument("--check", action="store_true", help="fail when the files are stale")

    server.add_commands(add, _repo_args, _broker_args)
    return parser


def main(argv: list[str] | None = None) -> int:
    args_list = list(sys.argv[1:] if argv is None else argv)
    if args_list and args_list[0] == "agent":
        # The robot side parses its own arguments and imports nothing server-side.
        from agent.cli import main as agent_main

        return agent_main(args_list[1:])
    parser = build_parser()
    args = parser.parse_args(args_list)
    handler: Handler = args.handler
    try:
        return handler(args)
    except SourceError as exc:
        print(f"robotconf: {exc}", file=sys.stderr)
        return EXIT_TOOL
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return EXIT_OK
    except Exception as exc:  # a tool failure is exit 2 with one line, never a traceback
        if os.environ.get("ROBOTCONF_DEBUG"):
            raise
        print(
            f"robotconf: internal error: {type(exc).__name__}: {exc} "
            "(set ROBOTCONF_DEBUG=1 for the traceback)",
            file=sys.stderr,
        )
        return EXIT_TOOL
