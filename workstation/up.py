"""`robotconf up`: the whole loop on one machine — broker, reconciler, one agent per robot, status.

Agents run as `robotconf agent` subprocesses with a stand-in brain; the reconciler runs in this
process. Ctrl-C, SIGTERM or SIGHUP stop the agents (and their brains) first, then the reconciler,
then the broker; if `up` is killed, the kernel tells its agents (agent/parent_death.py).
What is shown, and how, is the caller's (workstation/cli/up.py): an UpScreen.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import json
import logging
import os
import shlex
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol
from urllib.parse import quote

import yaml

from robotconf.agent.parent_death import ENV as DIE_WITH_PARENT
from robotconf.agent.standin_ros2 import GRAPH_ENV
from robotconf.agent.standin_ros2 import install as install_ros2
from robotconf.agent.workdir import HOLD_FILE, LOCK_FILE, WorkdirLock
from robotconf.configurator.render import FleetRender
from robotconf.configurator.source import SourceError
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.files import read_regular, write_atomic
from robotconf.contract.lifecycle import log_to_file, on_stop_signals
from robotconf.contract.models import file_name
from robotconf.contract.mqtt import Connection
from robotconf.contract.pidlock import PidLock
from robotconf.contract.signing import PRIVATE_NAME, PUBLIC_NAME, KeyPair, generate_keys
from robotconf.contract.wire import (
    BROKER_ENV,
    ReconcilerReason,
    ReconcilerStatus,
    Topics,
    redact_url,
    short_rev,
)
from robotconf.readmodel.ledger import ledger_path
from robotconf.readmodel.retained import RetainedView
from robotconf.readmodel.verdicts import (
    FleetStatus,
    clean,
    desired_from_fleet,
    diagnostic_lines,
    rollout_line,
)
from robotconf.reconciler.controller import Controller
from robotconf.reconciler.desired import DesiredBuilder
from robotconf.reconciler.signer import make_signer, make_verifier
from robotconf.reconciler.source import LocalBranch, open_repo
from robotconf.reconciler.telemetry import Telemetry
from robotconf.workstation import desired_store
from robotconf.workstation.fleet_reader import FleetReader, open_reader
from robotconf.workstation.fleet_status import Desired, change_key
from robotconf.workstation.up_desk import UpDesk, write_desk

if TYPE_CHECKING:
    from robotconf.reconciler.ledger_feed import LedgerFeed
    from robotconf.workstation.ui.run import RunningUi, UiOptions

log = logging.getLogger("robotconf.up")

AGENT_STOP_TIMEOUT = 5.0  # the stand-in brain stops at once; this bounds a stubborn one
RESYNC_INTERVAL = 10.0
REFUSED = {ReconcilerReason.BUILD_FAILED.value, ReconcilerReason.EMPTY_FLEET_REFUSED.value}
REFUSED_DIAGNOSTICS = 3  # the first ones say what to fix; `robotconf validate` lists them all
GIVEN_BROKER_WAIT = 10.0  # a given broker that has not answered by then is an error, not a wait
DEFAULT_PORT = 1883
UI_TOKEN = "ui.token"  # `up --ui`'s operator token, in its folder (0600)
# Each robot's stand-in `ros2` (agent/standin_ros2.py) reads its graph from this file in the
# robot's folder: the robot's ROS interfaces, as a real robot's `ros2 ... list -t` would print.
GRAPH_FILE = "ros2-graph.json"
# Three short `ros2` runs per robot per reading: every 10 s keeps six robots' readings to a
# few percent of one core, and an edit of a graph is seen as drift within seconds.
INTERFACES_INTERVAL = 10.0


@dataclass
class UpSetup:
    """What `up` will run, decided before anything starts."""

    root: Path
    branch: str
    head: str
    fleet: FleetRender
    workdir: Path
    notes: list[str] = field(default_factory=list)
    # The build of `head` above, kept: the controller's first build of it reuses every file
    # and robot instead of building the commit a second time.
    builder: DesiredBuilder = field(default_factory=DesiredBuilder)
    port: int = DEFAULT_PORT  # the embedded broker's, when free
    broker_origin: str = "--broker"  # where a given broker came from, for messages
    ui: UiOptions | None = None  # `up --ui`: the fleet's web page, served beside
    # `up --ui`'s operator token, for the login link it prints (never in a repr or a log).
    ui_token: str | None = field(default=None, repr=False)
    ui_token_made: bool = False  # made by this `up` (else kept from an earlier one)

    @property
    def state_dir(self) -> Path:
        """The reconciler's state folder (its outcome ledger), where `history` looks first."""
        return self.workdir / "state"


def _git_repo(root: Path) -> Any:
    try:
        return open_repo(root)
    except SourceError as exc:
        raise CliError(str(exc).replace("the reconciler", "robotconf up")) from None


def prepare(root: Path, branch: str | None, workdir: str | None) -> UpSetup:
    """Checks the repository and says what will be applied, and makes up's state folders
    ignore themselves in git before anything is kept there; raises CliError."""
    root = root.absolute()
    if not (root / "configs").is_dir():
        raise CliError(f"{root} has no configs/ folder; run robotconf up in a lab repository")
    repo = _git_repo(root)
    notes: list[str] = []
    try:
        if branch is None:
            if repo.head.is_detached:
                raise CliError("HEAD is detached; say which branch to apply: --branch BRANCH")
            branch = str(repo.active_branch.name)
        top = Path(repo.working_tree_dir or root)
        rel = [os.path.relpath(root / part, top) for part in ("configs", "models")]
        dirty = repo.git.status("--porcelain", "--", *rel).splitlines()
    finally:
        repo.close()
    if dirty:
        notes.append(
            f"{len(dirty)} uncommitted change(s) in configs/ or models/ are NOT applied: "
            f"robotconf up applies commits of '{branch}' only; commit them to roll them out"
        )
    try:
        head = LocalBranch(root, branch).head()
    except SourceError as exc:
        raise CliError(str(exc)) from None
    builder = DesiredBuilder()
    desired = builder(root, head)
    if desired.fleet is None:
        shown = "\n  ".join(str(p) for p in desired.problems[:20])
        raise CliError(
            f"the head commit {short_rev(head)} of '{branch}' cannot be applied:\n  {shown}\n"
            "fix it (robotconf validate), commit, and run robotconf up again"
        )
    folder = Path(workdir).absolute() if workdir else root / ".robotconf" / "up"
    # Before anything is written there: keys, passwords and tokens are never committed.
    ignore_itself(root / ".robotconf")  # desk.json's folder, whatever --workdir says
    if not folder.is_relative_to(root / ".robotconf"):
        ignore_itself(folder)
    return UpSetup(root, branch, head, desired.fleet, folder, notes, builder)


IGNORE_ALL = "*"  # a state folder's .gitignore: itself and all it holds, as a virtualenv's
MAX_GITIGNORE_BYTES = 64 * 1024


def ignore_itself(folder: Path) -> None:
    """Makes `folder` ignore itself in git wherever it is (a `.gitignore` of `*` inside it, as
    virtualenvs do), so that `git add -A` in a lab's own repository never commits up's signing
    key, broker passwords or token. A `.gitignore` already there is kept; one without a `*`
    line gets one added (its own lines kept). CliError when it cannot be written."""
    path = folder / ".gitignore"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        try:
            text = read_regular(path, MAX_GITIGNORE_BYTES).decode("utf-8", "replace")
        except FileNotFoundError:
            text = None
        if text is not None and IGNORE_ALL in (line.strip() for line in text.splitlines()):
            return
        before = "" if not text or text.endswith("\n") else "\n"
        added = (text or "") + before + IGNORE_ALL + "\n"
        write_atomic(path, added.encode("utf-8"), 0o644)
    except OSError as exc:
        raise CliError(
            f"cannot make {path} ignore up's files (keys, passwords): {exc.strerror or exc}"
        ) from None


def agent_yaml(
    fleet: FleetRender,
    robot_id: str,
    workdir: Path,
    connection: Connection,
    prefix: str,
    public_key: Path | None = None,
) -> dict[str, Any]:
    """The agent.yaml of one robot: it recommends the template it is assigned (no warning)."""
    request = fleet.requests[robot_id]
    capability = request.scenario_requests.scenario.capability  # what every robot of it shares
    description: dict[str, Any] = {"id": robot_id, "name": request.robot_name}
    if capability.robot_template:
        description["recommended_template"] = capability.robot_template
    description["platform"] = capability.platform
    config: dict[str, Any] = {
        "broker": connection.url,
        "prefix": prefix,
        "description": description,
        "command": [sys.executable, "-m", "robotconf.agent.standin_brain", "{launch_request}"],
        "workdir": str(workdir / robot_id),
        "stop_timeout": AGENT_STOP_TIMEOUT,
        # The stand-in brain re-reads its request on SIGHUP: a settings-only commit reloads it.
        "reload": {"signal": "SIGHUP"},
    }
    if capability.platform == "ROS2":
        # Its interfaces, as a ROS 2 robot's tooling reports them: the stand-in `ros2` in up's
        # bin folder reads the robot's graph file (`standin_graph`), so drift and `draft` work.
        # A ROS 1 robot reports none (`unknown`), as a real one's agent does.
        config["interfaces"] = {"interval": INTERFACES_INTERVAL}
        config["env"] = {
            "PATH": os.pathsep.join([str(workdir / "bin"), os.environ.get("PATH", os.defpath)]),
            GRAPH_ENV: str(workdir / robot_id / GRAPH_FILE),
        }
    # A given broker may need the same credentials and TLS settings as `up` itself.
    if connection.username:
        config["username"] = connection.username
    if connection.password_file:
        config["password_file"] = str(connection.password_file.absolute())
    if connection.address.tls:
        tls: dict[str, Any] = {"insecure": connection.insecure}
        for key in ("ca_file", "cert_file", "key_file"):
            value = getattr(connection, key)
            if value is not None:
                tls[key] = str(Path(value).absolute())
        config["tls"] = tls
    if public_key is not None:
        config["public_key"] = str(public_key.absolute())
    return config


class UpLock(PidLock):
    """One `up` per work directory. A flock: the kernel releases it when `up` dies, so the lock
    of a crashed `up` is never stale."""

    def __init__(self, workdir: Path) -> None:
        super().__init__(workdir / "up.lock")

    def acquire(self) -> None:
        """Raises CliError when another `up` holds it."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        holder = self.take()
        if holder is not None:
            raise CliError(
                f"another robotconf up (pid {holder}) is running with {self.path.parent}; "
                "stop it first, or give this one its own --workdir"
            )


def recover_agents(workdir: Path, say: Callable[[str], None]) -> None:
    """Stops the agents a killed `up` left running (where the kernel could not be asked to
    stop them, or they are still stopping): each holds its work directory's lock."""
    if not workdir.is_dir():
        return
    held: dict[Path, int] = {}
    for folder in sorted(p for p in workdir.iterdir() if (p / LOCK_FILE).is_file()):
        pid = WorkdirLock(folder).holder()
        if pid is None:
            continue
        if pid > 0 and not _runs_config(pid, folder / "agent.yaml"):
            # Not an agent `up` started (say, a robot's own, given --workdir): not ours to stop.
            raise CliError(
                f"another agent (pid {pid}) is using {folder}; give robotconf up another --workdir"
            )
        held[folder] = pid
    for folder, pid in held.items():
        if pid > 0:
            say(f"stopping agent pid {pid} left running in {folder} by a previous robotconf up")
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGTERM)  # it stops its brain and says so
    deadline = time.monotonic() + AGENT_STOP_TIMEOUT + 5.0
    for folder, pid in held.items():
        lock = WorkdirLock(folder)
        while lock.holder() is not None and time.monotonic() < deadline:
            time.sleep(0.1)
        if lock.holder() is not None and pid > 0:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(pid, signal.SIGKILL)  # its brain is stopped by the next agent
        while lock.holder() is not None and time.monotonic() < deadline + 5.0:
            time.sleep(0.1)
        if lock.holder() is not None:
            raise CliError(f"an agent still holds {folder / LOCK_FILE}; stop it and start again")


def standin_graph(fleet: FleetRender, robot_id: str) -> dict[str, Any]:
    """The graph the robot's stand-in `ros2` prints: every interface its request needs, with
    the types it needs, and the ROS graph's own two topics, as a robot built for it reports."""
    from robotconf.configurator.drift import needs_of_rendered

    kinds = {"topic": "topics", "service": "services", "action_client": "actions"}
    graph: dict[str, Any] = {
        "topics": [
            {"name": "/parameter_events", "type": "rcl_interfaces/msg/ParameterEvent"},
            {"name": "/rosout", "type": "rcl_interfaces/msg/Log"},
        ],
        "services": [],
        "actions": [],
    }
    for need in needs_of_rendered(fleet.requests[robot_id]):
        if need.kind in kinds:
            graph[kinds[need.kind]].append({"name": need.name, "type": need.type})
    return graph


def _runs_config(pid: int, config: Path) -> bool:
    """True when process `pid` was started with `--config config`, as `up` starts agents."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return False
    wanted = os.fsencode(config)
    return any(a == b"--config" and b == wanted for a, b in itertools.pairwise(argv))


class Agents:
    """One `robotconf agent` subprocess per robot, each in its own session so that Ctrl-C
    reaches this process only and the agents are stopped in order. Each is asked to die with
    this process (and its brain with it), so that not even a SIGKILL of `up` leaves them."""

    def __init__(
        self,
        workdir: Path,
        connection: Callable[[str], Connection],
        prefix: str,
        public_key: Path | None = None,
    ) -> None:
        self.workdir = workdir
        self.connection = connection  # of each robot
        self.prefix = prefix
        self.public_key = public_key
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._ros2 = False  # the stand-in `ros2` installed in the bin folder

    def start(self, robot_ids: list[str], fleet: FleetRender) -> None:
        """Starts an agent for each robot that has none yet, its graph file written afresh:
        the robot reports what the commit it starts on needs (edit the file to take some
        away)."""
        for robot_id in robot_ids:
            if robot_id in self.procs or robot_id not in fleet.requests:
                continue
            if not self._ros2:
                install_ros2(self.workdir / "bin")  # once: an agent may be running it
                self._ros2 = True
            folder = self.workdir / file_name("robot id", robot_id)  # validated: RC501
            folder.mkdir(parents=True, exist_ok=True)
            config = folder / "agent.yaml"
            settings = agent_yaml(
                fleet,
                robot_id,
                self.workdir,
                self.connection(robot_id),
                self.prefix,
                self.public_key,
            )
            config.write_text(yaml.safe_dump(settings, sort_keys=False), encoding="utf-8")
            if "interfaces" in settings:
                graph = json.dumps(standin_graph(fleet, robot_id), indent=1) + "\n"
                (folder / GRAPH_FILE).write_text(graph, encoding="utf-8")
            with (folder / "agent.log").open("ab") as out:
                self.procs[robot_id] = subprocess.Popen(
                    [sys.executable, "-m", "robotconf.agent.cli", "--config", str(config)],
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=out,
                    start_new_session=True,
                    # Asked of the kernel by the agent itself (no preexec_fn in this threaded
                    # process); agents are started on the main thread, which lives as long as
                    # `up`: the parent-death signal follows the thread, not the process.
                    env={**os.environ, DIE_WITH_PARENT: str(os.getpid())},
                )

    def died(self) -> list[tuple[str, int]]:
        return [(r, p.returncode) for r, p in self.procs.items() if p.poll() is not None]

    def stop(self, timeout: float = AGENT_STOP_TIMEOUT + 5.0) -> None:
        """SIGTERM lets each agent stop its brain and say so; SIGKILL only what is left."""
        for proc in self.procs.values():
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + timeout
        for proc in self.procs.values():
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(max(0.1, deadline - time.monotonic()))
        for proc in self.procs.values():
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def _demo_keys(folder: Path) -> KeyPair:
    """The key pair of this up folder: made once, reused, so restarted agents still verify."""
    pair = KeyPair(folder / PRIVATE_NAME, folder / PUBLIC_NAME)
    if pair.private.is_file() and pair.public.is_file():
        return pair
    return generate_keys(folder, force=True)


class UpScreen(Protocol):
    """Where `up` reports: lines as they happen, and the fleet whenever it changes."""

    @property
    def live(self) -> bool:
        """True when the fleet is drawn on a screen (then changes are not said as lines)."""
        ...

    def say(self, line: str) -> None: ...

    def begin(self, header: list[str]) -> None:
        """The fleet is about to be shown, under these lines."""
        ...

    def show(self, fleet: FleetStatus) -> None: ...

    def end(self) -> None:
        """Nothing more will be shown (the stopping lines are said after)."""
        ...


def refusal_lines(status: ReconcilerStatus | None) -> list[str]:
    """A commit the reconciler refused, in words: which, why, what the robots keep, and its
    first diagnostics; [] when none is refused. Shown as prominently as the robots."""
    if status is None or status.reason not in REFUSED or not status.failed_revision:
        return []
    where = f" of '{clean(status.branch)}'" if status.branch else ""
    keep = (
        f"the robots keep {short_rev(status.last_applied_revision)}"
        if status.last_applied_revision
        else "nothing is applied"
    )
    lines = [
        f"REFUSED: commit {short_rev(status.failed_revision)}{where} is not applied "
        f"({clean(status.reason)}); {keep}. Fix it (robotconf validate) and commit again."
    ]
    return lines + diagnostic_lines(status, REFUSED_DIAGNOSTICS)


def run_up(
    setup: UpSetup,
    given_broker: str | None,
    connect: Callable[[str], Connection],
    prefix: str,
    signing: bool,
    screen: UpScreen,
) -> ExitCode:
    """Runs the loop until SIGINT, SIGTERM or SIGHUP; `connect` makes the connection to a broker
    URL (raising CliError); without `given_broker`, an embedded broker is started."""
    lock = UpLock(setup.workdir)
    lock.acquire()
    try:
        return _run_up(setup, given_broker, connect, prefix, signing, screen)
    finally:
        lock.release()


def _run_up(
    setup: UpSetup,
    given_broker: str | None,
    connect: Callable[[str], Connection],
    prefix: str,
    signing: bool,
    screen: UpScreen,
) -> ExitCode:
    log_to_file(setup.workdir / "up.log")
    say = screen.say
    recover_agents(setup.workdir, say)
    for note in setup.notes:
        say(f"note: {note}")
    broker, login, url = _start_broker(setup, given_broker, prefix, say)
    try:
        logins = Logins(connect(url), login)
        if broker is None:
            _given_answers(logins.operator, prefix, setup.broker_origin)
        return _serve(setup, logins, prefix, signing, screen)
    finally:
        if broker is not None:
            broker.stop()
        say("stopped")


class Logins:
    """Who connects how: the operator's commands (the desk), `up`'s reconciler and each robot.
    On the embedded broker each has a login of its own (`login`, the operator's, and others in
    its folder), held to its topics as the generated ACL holds it; a given broker's one login is
    everyone's."""

    def __init__(self, connection: Connection, login: Any) -> None:
        self._connection = connection
        self.folder: Path | None = None if login is None else login.password_file.parent
        self.operator = self._as(login)
        self.reconciler = self.of("reconciler")

    def of(self, user: str) -> Connection:
        """The connection of `user`: a robot (its id) or a service user of the embedded broker."""
        if self.folder is None:
            return self._connection
        from robotconf.workstation.broker_login import broker_login

        return self._as(broker_login(self.folder, user))

    def _as(self, login: Any) -> Connection:
        if login is None:
            return self._connection
        return dataclasses.replace(
            self._connection, username=login.username, password_file=login.password_file
        )


def _start_broker(
    setup: UpSetup, given_broker: str | None, prefix: str, say: Callable[[str], None]
) -> tuple[Any, Any, str]:
    """The embedded broker and the operator's login (None, None with a given broker), and the
    URL; the other logins are made beside the operator's (`Logins`)."""
    if given_broker:
        say(f"broker: {redact_url(given_broker)} (given by {setup.broker_origin})")
        return None, None, given_broker
    from robotconf.workstation.broker import BrokerStartError, EmbeddedBroker
    from robotconf.workstation.broker_login import RECONCILER, USERNAME, broker_login, prune_logins

    folder = setup.workdir / "broker"
    login = broker_login(folder)
    gone = prune_logins(folder, {USERNAME, RECONCILER, *setup.fleet.requests})
    if gone:
        say(f"broker: logins removed of robots no longer in the fleet: {', '.join(gone)}")
    broker = EmbeddedBroker(login, preferred=setup.port, prefix=prefix)
    try:
        broker.start()
    except BrokerStartError as exc:
        raise CliError(f"{exc}; or pass --broker mqtt://HOST:PORT") from None
    taken = "" if broker.port == setup.port else f" (port {setup.port} is taken)"
    say(
        f"broker: embedded amqtt at {broker.url}{taken}, for up's logins only, each held to its "
        f"topics as the ACL of broker-config holds it; user {login.username}'s password is in "
        f"{login.password_file} (0600), readable by you alone"
    )
    return broker, login, broker.url


def _given_answers(connection: Connection, prefix: str, origin: str) -> None:
    """Raises CliError when a given broker does not answer within GIVEN_BROKER_WAIT: a stale
    $ROBOTCONF_BROKER must not leave `up` waiting for ever with nothing started."""
    probe = RetainedView(connection, [], Topics(prefix).sync, role="up-probe")
    with probe:
        if probe.wait_synced(GIVEN_BROKER_WAIT, or_refused=True):
            return
    unset = f"; unset {BROKER_ENV} to run up's own broker" if origin == f"${BROKER_ENV}" else ""
    silence = f"did not answer within {GIVEN_BROKER_WAIT:g} s ({probe.silence()})"
    said = silence if probe.closed is None else f"cannot be connected to ({probe.closed})"
    raise CliError(
        f"the broker {connection.address.url} (given by {origin}) {said}: start it or give "
        f"another{unset}"
    )


def _serve(
    setup: UpSetup, logins: Logins, prefix: str, signing: bool, screen: UpScreen
) -> ExitCode:
    say = screen.say
    connection = logins.operator
    signer, public_key, private_key = _signing(setup, signing, say)

    stop = threading.Event()
    changed = threading.Event()
    # The timeline's events (robotconf events, /timeline), kept in the ledger as reconcile's.
    telemetry = Telemetry(logins.reconciler, prefix)
    telemetry.keep_desired = partial(desired_store.write, setup.root)
    controller = _controller(setup, logins, prefix, changed, signer, private_key, telemetry)
    agents = Agents(setup.workdir, logins.of, prefix, public_key)
    serving = ServingDesired(controller)
    view, reader = open_reader(logins.reconciler, prefix, serving, changed.set)
    ledger = _start_ledger(setup, logins.reconciler, prefix, say)
    if ledger is not None:
        telemetry.keep = ledger.keep

    def at_once() -> None:  # a second Ctrl-C: do not wait (the brains get SIGTERM as orphans)
        for proc in agents.procs.values():
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
        os._exit(ExitCode.INTERRUPTED)

    on_stop_signals(stop, changed.set, again=at_once)

    say(
        f"reconciling {setup.root} branch '{setup.branch}' (head {short_rev(setup.head)}), "
        f"{len(setup.fleet.requests)} robot(s); agent files and logs in {setup.workdir}"
    )
    say(robots_line(setup))
    lease = write_desk(setup.root, up_desk(setup, connection, prefix, private_key))
    header = banner(setup, connection, lease.path)
    for line in header[1:3]:
        say(line.strip())
    thread = threading.Thread(target=controller.run, name="robotconf-reconciler", daemon=True)
    telemetry.start()
    thread.start()
    view.start()
    agents.start(sorted(setup.fleet.requests), setup.fleet)
    ui = _start_ui(setup, connection, prefix, say, private_key)
    screen.begin(header)
    try:
        _loop(controller, agents, view, reader, stop, changed, screen)
    finally:
        screen.end()
        if ui is not None:
            ui.close()
        say("stopping: agents and their brains ...")
        lease.remove()
        agents.stop()
        view.stop()
        controller.stop()
        thread.join(10)
        telemetry.stop()
        if ledger is not None:
            ledger.stop()
    return ExitCode.OK


def _controller(
    setup: UpSetup,
    logins: Logins,
    prefix: str,
    changed: threading.Event,
    signer: Any,
    private_key: Path | None,
    telemetry: Telemetry,
) -> Controller:
    """up's reconciler: its branch, its login, signing when asked; rollout.verify counts its
    ledger's outcomes, and operators' rollout actions are checked against the signing key."""
    return Controller(
        LocalBranch(setup.root, setup.branch),
        logins.reconciler,
        prefix,
        RESYNC_INTERVAL,
        on_reconciled=lambda status: changed.set(),
        signer=signer,
        builder=setup.builder,
        ledger=ledger_path(setup.state_dir),
        verifier=make_verifier(private_key),
        on_step=telemetry.on_step,
    )


def _signing(
    setup: UpSetup, signing: bool, say: Callable[[str], None]
) -> tuple[Any, Path | None, Path | None]:
    """The signer, public and private key of `up --sign` (demo keys in its folder), or Nones."""
    if not signing:
        return None, None, None
    keys = _demo_keys(setup.workdir / "keys")
    say(f"signing: every request is signed; agents verify with {keys.public}")
    return make_signer(keys.private), keys.public, keys.private


def _start_ledger(
    setup: UpSetup, connection: Connection, prefix: str, say: Callable[[str], None]
) -> LedgerFeed | None:
    """The outcome ledger under up's folder (`robotconf history` finds it there); a state
    folder that cannot be written is said, and `up` runs without a ledger."""
    from robotconf.readmodel.ledger import LedgerError
    from robotconf.reconciler.ledger_feed import LedgerFeed, LedgerSettings

    feed = LedgerFeed(connection, prefix, LedgerSettings(setup.state_dir))
    try:
        feed.start()
    except LedgerError as exc:
        say(f"ledger: {exc}; goal outcomes are not kept")
        return None
    return feed


def _start_ui(
    setup: UpSetup,
    connection: Connection,
    prefix: str,
    say: Callable[[str], None],
    private_key: Path | None,
) -> RunningUi | None:
    """`up --ui`: the fleet's web page, read with the operator's login, its restarts signed
    with up's key (its agents verify it); its address and login link said."""
    if setup.ui is None:
        return None
    from robotconf.contract.signing import load_private_key
    from robotconf.readmodel.ledger import ledger_path
    from robotconf.workstation.ui.revisions import LedgerHistory
    from robotconf.workstation.ui.run import RunningUi

    history = LedgerHistory(ledger_path(setup.state_dir))
    key = load_private_key(private_key) if private_key is not None else None
    options = dataclasses.replace(setup.ui, key=key)
    ui = RunningUi(connection, prefix, setup.root, options, history=history)
    say(f"ui: the fleet's web page is at {ui.url}")
    if setup.ui_token is not None:
        kept = "made now" if setup.ui_token_made else "the same as before"
        say(
            f"ui: log in as its operator (robots' logs, restarts) with "
            f"{ui.url}login?token={quote(setup.ui_token, safe='')} (the token, {kept}, is in "
            f"{_shown_path(setup.workdir / UI_TOKEN)}, mode 0600)"
        )
    return ui


def with_operator(setup: UpSetup) -> UpSetup:
    """`up --ui`: its UI with an operator, whoever reads the token in up's folder (made once,
    mode 0600; a wider mode is refused, CliError), who logs in with the link `up` prints."""
    if setup.ui is None:
        return setup
    from robotconf.workstation.ui.auth import OperatorAuth, own_token

    token, made = own_token(setup.workdir / UI_TOKEN, "up's operator token file")
    ui = dataclasses.replace(setup.ui, auth=OperatorAuth(token), link_login=True)
    return dataclasses.replace(setup, ui=ui, ui_token=token, ui_token_made=made)


def up_desk(
    setup: UpSetup, connection: Connection, prefix: str, private_key: Path | None
) -> UpDesk:
    """What the desk commands need to reach this `up`: the URL without credentials, and the
    paths of the password file and signing key (the secrets stay in their 0600 files)."""

    def absolute(path: Path | None) -> Path | None:
        return None if path is None else path.absolute()

    return UpDesk(
        broker=connection.address.url,
        prefix=prefix,
        pid=os.getpid(),
        username=connection.username or connection.address.username,
        password_file=absolute(connection.password_file),
        signing_key=absolute(private_key),
        ca_file=absolute(connection.ca_file),
        cert_file=absolute(connection.cert_file),
        key_file=absolute(connection.key_file),
        insecure=connection.insecure,
    )


def desk_commands(root: Path) -> list[str]:
    """What to type in another terminal: no options from within the repository; from
    elsewhere, --repo naming it (that is where the desk file is looked for)."""
    here = Path.cwd().absolute()
    inside = here == root or root in here.parents
    where = "" if inside else f" --repo {_shown_path(root)}"
    return [
        f"robotconf status{where}",
        f"robotconf logs ROBOT{where}",
        f"robotconf restart ROBOT{where}",
    ]


def banner(setup: UpSetup, connection: Connection, desk: Path) -> list[str]:
    """The lines above the live fleet: where the broker is, and what to type elsewhere."""
    commands = "    ".join(desk_commands(setup.root))
    return [
        f"robotconf up: broker {redact_url(connection.url)}, branch '{setup.branch}' of "
        f"{setup.root}",
        f"  another terminal: {commands}    (Ctrl-C stops everything)",
        f"  they find this up's broker, login and signing key in {_shown_path(desk)} "
        "while it runs; no options needed",
        *[f"  note: {n}" for n in setup.notes],
        "",
    ]


class ServingDesired:
    """The desired robots of the revision up's reconciler serves, made once per revision: what
    up's screen compares the fleet with."""

    def __init__(self, controller: Controller) -> None:
        self.controller = controller
        self._made: tuple[str | None, Desired] = (None, ({}, "", []))

    def get(self, reconciler: ReconcilerStatus | None) -> Desired:
        serving = self.controller.serving
        if serving is None or serving.fleet is None:
            return self._made[1]
        if serving.revision != self._made[0]:
            where = f"{short_rev(serving.revision)} ({self.controller.source.branch})"
            self._made = (serving.revision, (desired_from_fleet(serving.fleet), where, []))
        return self._made[1]


def _loop(
    controller: Controller,
    agents: Agents,
    view: RetainedView,
    reader: FleetReader,
    stop: threading.Event,
    changed: threading.Event,
    screen: UpScreen,
) -> None:
    """Shows the fleet while it changes; starts agents for robots that later commits add."""
    say = screen.say
    shown = ""
    refusal: list[str] = []
    in_sync_at: str | None = None
    reported_dead: set[str] = set()
    started = time.monotonic()
    waiting_said = False
    fleet: FleetStatus | None = None
    while not stop.is_set():
        changed.clear()
        serving = controller.serving
        if serving is not None and serving.fleet is not None:
            agents.start(sorted(serving.fleet.requests), serving.fleet)
        for robot_id, code in agents.died():
            if robot_id not in reported_dead:
                reported_dead.add(robot_id)
                log_file = agents.workdir / robot_id / "agent.log"
                say(f"agent {robot_id} exited ({code}); see {log_file}")
        if not view.synced and not waiting_said and time.monotonic() - started > 5:
            waiting_said = True
            say(f"waiting for the broker at {view.connection.address.url} ({view.silence()})")
        if view.synced and serving is not None and serving.fleet is not None:
            fleet, _ = reader.read(fleet, whole=fleet is None)
            key = change_key(fleet)
            if key != shown:
                shown = key
                screen.show(fleet)
                refused = refusal_lines(fleet.reconciler)
                if refused != refusal:  # said once per refused commit, even on a live screen
                    refusal = refused
                    for line in refused:
                        say(line)
                if fleet.in_sync and in_sync_at != serving.revision:
                    in_sync_at = serving.revision
                    say(
                        f"all robots InSync with {short_rev(serving.revision)}; "
                        f"watching '{controller.source.branch}' (Ctrl-C to stop)"
                    )
                elif not screen.live:
                    say(summary(fleet))
        changed.wait(5.0)
        time.sleep(0.2)  # coalesce a burst of status messages into one redraw


def _shown_path(path: Path) -> str:
    """`path` relative to the current folder when it is under it (shorter), quoted for a shell."""
    with contextlib.suppress(ValueError):
        path = path.relative_to(Path.cwd())
    return shlex.quote(str(path))


def robots_line(setup: UpSetup) -> str:
    """How to make one of up's robots busy or drift, on the files of the first robot (the
    first on ROS 2, whose interfaces are reported)."""
    requests = setup.fleet.requests
    ros2 = [r for r in requests if _platform(setup.fleet, r) == "ROS2"]
    robot = min(ros2 or requests, default="ROBOT")
    folder = _shown_path(setup.workdir / robot)
    line = f"robots: `touch {folder}/{HOLD_FILE}` makes {robot} busy (its brain's hold file; rm it"
    if not ros2:
        return line + " to release)"
    return (
        f"{line} to release), and {folder}/{GRAPH_FILE} is what its stand-in ros2 reports "
        f"every {INTERFACES_INTERVAL:g} s (take an interface out: {robot} drifts)"
    )


def _platform(fleet: FleetRender, robot_id: str) -> str:
    return fleet.requests[robot_id].scenario_requests.scenario.capability.platform


def summary(fleet: FleetStatus) -> str:
    """One line for the line output: the robots per verdict, and a rollout under way."""
    counts = ", ".join(f"{n} {v}" for v, n in fleet.counts().items()) or "no robots"
    line = f"{len(fleet.rows)} robots: {counts}"
    rollout = fleet.reconciler.rollout if fleet.reconciler is not None else None
    if rollout is not None and rollout.state != "Complete":
        line += f"; {rollout_line(rollout, fleet.reconciler)}"
    return line
