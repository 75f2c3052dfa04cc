"""`robotconf agent --config agent.yaml [--broker URL] [--check]`: runs one robot's agent.

Exit 0 after a signal-initiated stop, 2 when the configuration or the machine is unusable.
"""

from __future__ import annotations

import argparse
import logging
import ssl
import sys
from pathlib import Path

from agent.config import ConfigInvalid, load_config, with_broker
from agent.runtime import Agent
from agent.workdir import WorkdirLock
from configurator.signing import SigningKeyError

PROG = "robotconf agent"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Receive this robot's Launch Request over MQTT; supervise its brain service.",
    )
    parser.add_argument("--config", required=True, type=Path, metavar="PATH", help="agent.yaml")
    parser.add_argument(
        "--broker", metavar="URL", help="overrides the file's broker: mqtt[s]://host:port"
    )
    parser.add_argument("--check", action="store_true", help="validate the configuration and exit")
    parser.add_argument(
        "--log-level", default="info", choices=["debug", "info", "warning", "error"]
    )
    return parser


def main(argv: list[str]) -> int:
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:  # argparse has printed the usage problem already
        return exc.code if isinstance(exc.code, int) else 2
    try:
        config = load_config(args.config, prepare=not args.check)
        if args.broker:
            config = with_broker(config, args.broker)
    except ConfigInvalid as exc:
        for error in exc.errors:
            print(error, file=sys.stderr)
        return 2
    if args.check:
        print(f"{args.config}: ok (robot {config.robot_id})")
        return 0
    logging.basicConfig(
        level=args.log_level.upper(),
        format=f"%(asctime)s {config.robot_id} %(levelname)s %(message)s",
        stream=sys.stderr,
    )
    lock = WorkdirLock(config.workdir)
    problem = lock.acquire()
    if problem:
        print(f"{PROG}: {problem}", file=sys.stderr)
        return 2
    try:
        try:
            agent = Agent(config)
        except (OSError, ssl.SSLError, ValueError, SigningKeyError) as exc:
            # e.g. a TLS certificate or key that exists but cannot be loaded.
            print(f"{PROG}: cannot set up: {exc}", file=sys.stderr)
            return 2
        agent.install_signal_handlers()
        return agent.run()
    finally:
        lock.release()


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
