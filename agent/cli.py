"""`robotconf agent --config agent.yaml [--config ...] [--broker URL] [--check]`: runs one
robot's agent, or several robots' agents in one process (a simulation host).

Exit 0 after a signal-initiated stop, 2 when a configuration or the machine is unusable.
"""

from __future__ import annotations

import argparse
import logging
import ssl
import sys
from collections.abc import Sequence
from pathlib import Path

from robotconf.agent import parent_death, process
from robotconf.agent.config import AgentConfig, ConfigInvalid, load_config, with_broker
from robotconf.agent.runtime import Agent, RobotIdFilter, install_signal_handlers, run_agents
from robotconf.agent.workdir import WorkdirLock
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.logsafe import SafeFormatter
from robotconf.contract.signing import SigningKeyError

PROG = "robotconf agent"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Receive this robot's Launch Request over MQTT; supervise its brain service.",
        epilog="With `interfaces: {interval: SECONDS}` in agent.yaml the agent also reports the "
        "robot's ROS topics, services and actions (`ros2 ... list -t`, or `interfaces.command`) "
        "on <prefix>/robots/<id>/interfaces; off unless configured. A busy brain defers a "
        "stop, restart or reload by creating the file named in its $ROBOTCONF_HOLD_FILE: the "
        "state is `deferred` until it removes it, or for agent.yaml's `max_defer` seconds at "
        "most (default 300; 0 ignores the file); a crash restart and this agent's own stop "
        "are never deferred.",
    )
    parser.add_argument(
        "--config",
        required=True,
        type=Path,
        action="append",
        metavar="PATH",
        help="agent.yaml; repeat it to run several robots' agents in this one process",
    )
    parser.add_argument(
        "--broker", metavar="URL", help="overrides every file's broker: mqtt[s]://host:port"
    )
    parser.add_argument("--check", action="store_true", help="validate the configuration and exit")
    parser.add_argument(
        "--log-level", default="info", choices=["debug", "info", "warning", "error"]
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Exit code as `robotconf` gives them: a CliError is one line on stderr. Also the
    `robotconf-agent` entry point of a robot-only install (argv from the command line)."""
    try:
        return _run(sys.argv[1:] if argv is None else argv)
    except CliError as exc:
        print(f"{PROG}: {exc.message}", file=sys.stderr)
        return exc.code


def _run(argv: list[str]) -> int:
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:  # argparse has printed the usage problem already
        return exc.code if isinstance(exc.code, int) else ExitCode.TOOL
    paths: list[Path] = args.config
    configs: list[AgentConfig] = []
    invalid = False
    for path in paths:  # every file is checked, so that one run lists every problem
        try:
            config = load_config(path, prepare=not args.check)
            if args.broker:
                config = with_broker(config, args.broker)
        except ConfigInvalid as exc:
            for error in exc.errors:
                print(error, file=sys.stderr)
            invalid = True
            continue
        configs.append(config)
    if invalid:
        return ExitCode.TOOL  # each problem has been printed as its own file:line line
    clash = _clash(paths, configs)
    if clash:
        raise CliError(clash)
    if args.check:
        for path, config in zip(paths, configs, strict=True):
            print(f"{path}: ok (robot {config.robot_id})")
        return ExitCode.OK
    _log_to_stderr(args.log_level, configs)
    parent = parent_death.take_request()  # before the agents copy the environment
    locks: list[WorkdirLock] = []
    try:
        for config in configs:
            lock = WorkdirLock(config.workdir)
            problem = lock.acquire()
            if problem:
                raise CliError(problem)
            locks.append(lock)
        try:
            agents = [Agent(config) for config in configs]
        except (OSError, ssl.SSLError, ValueError, SigningKeyError) as exc:
            # e.g. a TLS certificate or key that exists but cannot be loaded.
            raise CliError(f"cannot set up: {exc}") from None
        install_signal_handlers(agents)
        if parent is not None:  # `robotconf up` runs this agent: die with it, brains with us
            if not parent_death.die_with_parent(parent):
                raise CliError(f"robotconf up (pid {parent}) ended before this agent started")
            process.brain_preexec = parent_death.child_setup()
        run_agents(agents)
        return ExitCode.OK
    finally:
        for lock in locks:
            lock.release()


def _clash(paths: Sequence[Path], configs: Sequence[AgentConfig]) -> str | None:
    """Two files for one robot, or for one work directory: each agent needs its own of both
    (one robot id is one set of topics; one work directory holds one brain)."""
    robots: dict[str, Path] = {}
    workdirs: dict[Path, Path] = {}
    for path, config in zip(paths, configs, strict=True):
        robot, workdir = config.robot_id, config.workdir.resolve()
        if robot in robots:
            return f"{robots[robot]} and {path} both configure robot {robot!r}; one agent per robot"
        if workdir in workdirs:
            return f"{workdirs[workdir]} and {path} share workdir {workdir}; give each its own"
        robots[robot], workdirs[workdir] = path, path
    return None


def _log_to_stderr(level: str, configs: Sequence[AgentConfig]) -> None:
    handler = logging.StreamHandler(sys.stderr)
    # Statuses, requests and refusals quote what peers sent: one line each, escaped.
    handler.setFormatter(SafeFormatter("%(asctime)s %(robot_id)s %(levelname)s %(message)s"))
    # Lines logged outside any one agent's turn name the process's robot, or all of them.
    handler.addFilter(RobotIdFilter(",".join(config.robot_id for config in configs)))
    logging.basicConfig(level=level.upper(), handlers=[handler])


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
