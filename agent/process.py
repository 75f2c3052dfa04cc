"""The brain as an OS process: spawn in its own session, signal its group, pidfile, capped log.

Linux only (it reads /proc); no MQTT and no state machine here.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from robotconf.agent.workdir import write_atomic
from robotconf.contract.launch import LaunchRequest

log = logging.getLogger("robotconf.agent.process")

PLACEHOLDER = "{launch_request}"


def substitute(command: Sequence[str], request_path: Path) -> list[str]:
    """Each argument stays one argument: the path is never seen by a shell."""
    return [arg.replace(PLACEHOLDER, str(request_path)) for arg in command]


# ---------------------------------------------------------------- /proc


_boot_id_cache: list[str] = []


def _boot_id() -> str | None:
    # Constant while this process lives (a reboot ends it): read once, not at every spawn.
    if _boot_id_cache:
        return _boot_id_cache[0]
    try:
        boot = Path("/proc/sys/kernel/random/boot_id").read_text(encoding="ascii").strip()
    except OSError:
        return None
    _boot_id_cache.append(boot)
    return boot


def proc_stat(pid: int) -> tuple[str, int] | None:
    """(state letter, start time in clock ticks since boot) of a process, None if it is gone."""
    try:
        raw = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:
        return None
    # The command name may hold spaces and parentheses: split after its last ')'.
    fields = raw[raw.rindex(b")") + 2 :].split()
    return fields[0].decode("ascii"), int(fields[19])


def is_alive(pid: int) -> bool:
    """A zombie counts as dead: nobody may reap an orphan inside some containers."""
    stat = proc_stat(pid)
    return stat is not None and stat[0] not in ("Z", "X")


def signal_group(pgid: int, sig: signal.Signals) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.killpg(pgid, sig)


# ---------------------------------------------------------------- pidfile


@dataclass(frozen=True)
class PidRecord:
    """Enough to tell, after the agent died, whether a pid is still our brain or a reused number."""

    pid: int
    start_time: int
    boot_id: str | None
    digest: str | None = None

    def to_json(self) -> bytes:
        return json.dumps(self.__dict__, sort_keys=True).encode("utf-8")

    @classmethod
    def from_json(cls, raw: bytes) -> PidRecord | None:
        try:
            data = json.loads(raw)
            return cls(
                pid=int(data["pid"]),
                start_time=int(data["start_time"]),
                boot_id=data.get("boot_id"),
                digest=data.get("digest"),
            )
        except (ValueError, KeyError, TypeError):
            return None

    @classmethod
    def of(cls, pid: int, digest: str | None) -> PidRecord | None:
        stat = proc_stat(pid)
        if stat is None:
            return None
        return cls(pid=pid, start_time=stat[1], boot_id=_boot_id(), digest=digest)

    def is_running(self) -> bool:
        """The recorded process is alive and is the same process (not a recycled pid)."""
        stat = proc_stat(self.pid)
        if stat is None or stat[0] in ("Z", "X") or stat[1] != self.start_time:
            return False
        return self.boot_id is None or self.boot_id == _boot_id()


def read_pidfile(path: Path) -> PidRecord | None:
    try:
        return PidRecord.from_json(path.read_bytes())
    except OSError:
        return None


def stop_orphan(
    pidfile: Path, stop_timeout: float, sleep: Callable[[float], None] = time.sleep
) -> str | None:
    """Stop the brain a killed agent left behind; returns what was done, for the status."""
    record = read_pidfile(pidfile)
    if record is None:
        with contextlib.suppress(FileNotFoundError):
            pidfile.unlink()
        return None
    if not record.is_running():
        pidfile.unlink()
        return None
    log.warning("stopping brain pid %d left behind by a previous agent", record.pid)
    signal_group(record.pid, signal.SIGTERM)
    deadline = time.monotonic() + stop_timeout
    while record.is_running() and time.monotonic() < deadline:
        sleep(0.05)
    how = "stopped"
    if record.is_running():
        how = "killed"
        signal_group(record.pid, signal.SIGKILL)
        deadline = time.monotonic() + 5
        while record.is_running() and time.monotonic() < deadline:
            sleep(0.05)
    # What the brain started in its group goes with it, as when the agent watches it exit.
    signal_group(record.pid, signal.SIGKILL)
    pidfile.unlink()
    return f"{how} brain pid {record.pid} left behind by a previous agent"


# ---------------------------------------------------------------- the log


class BrainLog:
    """stdout+stderr of the brain, appended to one file that the agent caps by rotation.

    The brain writes to the file directly (O_APPEND), not through a pipe, so that it survives
    the agent's death; rotation is copy-then-truncate, checked periodically by the agent.
    """

    def __init__(self, path: Path, max_bytes: int, backups: int) -> None:
        self.path = path
        self.max_bytes = max_bytes
        self.backups = backups

    def open_for_child(self) -> int:
        return os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o640)

    def note(self, line: str) -> None:
        """A line of the agent's own, so that the log reads as a history of starts and exits."""
        stamp = time.strftime("%Y-%m-%d %H:%M:%S")
        with contextlib.suppress(OSError), open(self.path, "a", encoding="utf-8") as out:
            out.write(f"--- robotconf agent {stamp}: {line}\n")

    def rotate_if_needed(self) -> bool:
        try:
            size = self.path.stat().st_size
        except OSError:
            return False
        if size <= self.max_bytes:
            return False
        try:
            if self.backups > 0:
                for n in range(self.backups - 1, 0, -1):
                    older = self.path.with_name(f"{self.path.name}.{n}")
                    if older.exists():
                        os.replace(older, self.path.with_name(f"{self.path.name}.{n + 1}"))
                shutil.copyfile(self.path, self.path.with_name(f"{self.path.name}.1"))
            # Writers hold O_APPEND descriptors: after truncation they write at the new end.
            os.truncate(self.path, 0)
        except OSError as exc:
            log.warning("cannot rotate %s: %s", self.path, exc)
            return False
        return True


# ---------------------------------------------------------------- spawning

# Run in each brain's child before exec; set when `robotconf up` runs this agent, so that a
# brain gets SIGTERM if its agent dies (agent/parent_death.py). None on a robot: there a brain
# outlives its agent's crash, and the restarted agent adopts or stops it (stop_orphan).
brain_preexec: Callable[[], None] | None = None


class Brain:
    """One started brain process, and how its exit is noticed.

    With pidfds (Linux >= 5.3) `exit_fd` becomes readable when the brain exits: the owner
    waits on it beside its other descriptors and calls `reap()`, with no thread at all.
    Without, a waiter thread of the brain's own reaps it and calls `on_exit(pid, code)`.
    """

    def __init__(self, popen: subprocess.Popen[bytes], on_exit: Callable[[int, int], None]) -> None:
        self.popen = popen
        self.pid = popen.pid
        self._on_exit = on_exit
        self.exit_fd: int | None = None
        try:
            self.exit_fd = os.pidfd_open(self.pid)
        except (AttributeError, OSError):
            thread = threading.Thread(target=self._wait, name=f"brain-{self.pid}", daemon=True)
            thread.start()

    def _wait(self) -> None:
        with contextlib.suppress(ChildProcessError):
            os.waitid(os.P_PID, self.pid, os.WEXITED | os.WNOWAIT)
        self._on_exit(self.pid, self.reap())

    def reap(self) -> int:
        """The exit code, once the brain has exited (blocks until then)."""
        # The leader has exited but is not reaped yet: while it is a zombie its pid (= the
        # group id) cannot be reused, so killing leftover group members cannot hit a stranger.
        signal_group(self.pid, signal.SIGKILL)
        code = self.popen.wait()
        if self.exit_fd is not None:
            with contextlib.suppress(OSError):
                os.close(self.exit_fd)
            self.exit_fd = None
        return code


def brain_environment(extra: Mapping[str, str]) -> dict[bytes, bytes]:
    """This process's environment plus `extra`, encoded once: what a brain's environment is
    made of (`request_environment` adds the request's part).

    Bytes, so that Popen need not encode some forty variables again at every start."""
    return {**os.environb, **{os.fsencode(k): os.fsencode(v) for k, v in extra.items()}}


ROS_DOMAIN_VARIABLE = "ROS_DOMAIN_ID"
DIGEST_VARIABLE = "ROBOTCONF_DIGEST"


def request_environment(
    base: Mapping[bytes, bytes], local: Mapping[str, str], request: LaunchRequest
) -> tuple[dict[bytes, bytes], list[str]]:
    """The brain's complete environment for `request`, and the warnings it gives: the one
    definition, for starting the brain and for anything that must see its ROS graph.

    `base`: `brain_environment` of agent.yaml's `env:` (`local`) and the agent's own ROBOTCONF_*
    variables. Lowest first: the agent's environment, the request's ROS domain, agent.yaml's
    `env:` (a robot-local override, so a conflict with the request is warned about, never
    resolved silently), the agent's ROBOTCONF_* variables."""
    env = dict(base)
    warnings: list[str] = []
    domain = request.ros_domain_id
    if domain is not None:
        override = local.get(ROS_DOMAIN_VARIABLE)
        if override is None:
            env[ROS_DOMAIN_VARIABLE.encode()] = str(domain).encode()
        elif int(override) != domain:  # agent.yaml's is checked to be a domain id on reading
            warnings.append(
                f"agent.yaml's env sets {ROS_DOMAIN_VARIABLE} to {int(override)}, the launch "
                f"request's ros_domain_id is {domain}: the brain runs in domain {int(override)} "
                "(agent.yaml wins on the robot); make the two agree, or remove "
                f"{ROS_DOMAIN_VARIABLE} from agent.yaml's env"
            )
    env[DIGEST_VARIABLE.encode()] = request.digest.encode("ascii")
    return env, warnings


def spawn(
    argv: Sequence[str],
    cwd: Path,
    log_fd: int,
    env: Mapping[bytes, bytes],
    on_exit: Callable[[int, int], None],
) -> Brain:
    """Start the brain as the leader of a new session, with exactly the environment `env`
    (see `brain_environment`); raises OSError (e.g. no such file).

    `on_exit` is called from a waiter thread, and only when the brain has no `exit_fd`."""
    popen = subprocess.Popen(
        list(argv),
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        stdout=log_fd,
        stderr=log_fd,
        env=env,
        start_new_session=True,
        close_fds=True,
        preexec_fn=brain_preexec,
    )
    return Brain(popen, on_exit)


def write_pidfile(path: Path, pid: int, digest: str | None) -> None:
    record = PidRecord.of(pid, digest)
    if record is not None:
        # Not durable: after a power cut the boot id tells that the recorded pid is stale.
        write_atomic(path, record.to_json(), mode=0o644, durable=False)
