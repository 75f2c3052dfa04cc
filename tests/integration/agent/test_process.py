"""Brain processes, the pidfile's identity check, the capped log and the work directory files."""

from __future__ import annotations

import os
import select
import signal
import stat
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from robotconf.agent.process import (
    BrainLog,
    PidRecord,
    brain_environment,
    is_alive,
    read_pidfile,
    spawn,
    stop_orphan,
    substitute,
    write_pidfile,
)
from robotconf.agent.workdir import SeqStore, WorkdirLock, write_atomic
from tests.support.watch import wait_for

IGNORES_SIGTERM = (
    "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
    "print('ready', flush=True); time.sleep(60)"
)


@pytest.fixture
def victim() -> Iterator[subprocess.Popen[bytes]]:
    """A process in its own group, as a brain would be; reaped and killed at teardown."""
    proc = subprocess.Popen(["sleep", "60"], start_new_session=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def test_substitution_keeps_one_argument_per_argument(tmp_path: Path) -> None:
    path = tmp_path / "dir with space; rm -rf x" / "launch-request.json"
    argv = substitute(["cbs", "{launch_request}", "--config={launch_request}", "-v"], path)
    assert argv == ["cbs", str(path), f"--config={path}", "-v"]


def test_atomic_write_is_private_and_leaves_no_temp_files(tmp_path: Path) -> None:
    target = tmp_path / "launch-request.json"
    target.write_bytes(b"old")
    target.chmod(0o644)
    write_atomic(target, b'{"new": true}')
    assert target.read_bytes() == b'{"new": true}'
    assert stat.S_IMODE(target.stat().st_mode) == 0o600
    assert sorted(p.name for p in tmp_path.iterdir()) == ["launch-request.json"]


def test_pidfile_recognises_its_process(tmp_path: Path, victim: subprocess.Popen[bytes]) -> None:
    pidfile = tmp_path / "brain.pid"
    write_pidfile(pidfile, victim.pid, "sha256:x")
    record = read_pidfile(pidfile)
    assert record is not None and record.pid == victim.pid and record.digest == "sha256:x"
    assert record.is_running()


def test_a_reused_pid_is_not_taken_for_the_brain(
    tmp_path: Path, victim: subprocess.Popen[bytes]
) -> None:
    """Same pid, other start time: another process now; stop_orphan must leave it alone."""
    real = PidRecord.of(victim.pid, None)
    assert real is not None
    pidfile = tmp_path / "brain.pid"
    for stranger in (
        PidRecord(victim.pid, real.start_time + 1, real.boot_id),
        PidRecord(victim.pid, real.start_time, "another-boot"),
    ):
        assert not stranger.is_running()
        write_atomic(pidfile, stranger.to_json())
        assert stop_orphan(pidfile, stop_timeout=0.2) is None
        assert victim.poll() is None and is_alive(victim.pid)
        assert not pidfile.exists()


def test_orphan_is_stopped_with_sigterm(tmp_path: Path, victim: subprocess.Popen[bytes]) -> None:
    pidfile = tmp_path / "brain.pid"
    write_pidfile(pidfile, victim.pid, None)
    note = stop_orphan(pidfile, stop_timeout=10)
    assert note == f"stopped brain pid {victim.pid} left behind by a previous agent"
    assert victim.wait(5) == -signal.SIGTERM
    assert not pidfile.exists()


def test_orphan_ignoring_sigterm_is_killed(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", IGNORES_SIGTERM], stdout=subprocess.PIPE, start_new_session=True
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline() == b"ready\n"
        pidfile = tmp_path / "brain.pid"
        write_pidfile(pidfile, proc.pid, None)
        note = stop_orphan(pidfile, stop_timeout=0.3)
        assert note is not None and note.startswith("killed brain pid")
        assert proc.wait(5) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def test_no_or_garbage_pidfile_is_nothing_to_do(tmp_path: Path) -> None:
    pidfile = tmp_path / "brain.pid"
    assert stop_orphan(pidfile, 1) is None
    pidfile.write_text("{garbage", encoding="utf-8")
    assert stop_orphan(pidfile, 1) is None
    assert not pidfile.exists()


def test_spawn_reports_the_exit_and_kills_what_the_brain_left_in_its_group(tmp_path: Path) -> None:
    out = tmp_path / "out.log"
    fd = os.open(out, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    exits: list[tuple[int, int]] = []
    done = threading.Event()

    def on_exit(pid: int, code: int) -> None:
        exits.append((pid, code))
        done.set()

    try:
        brain = spawn(
            ["sh", "-c", "sleep 60 & echo $!; echo to-stderr >&2; exit 3"],
            cwd=tmp_path,
            log_fd=fd,
            env=brain_environment({"ROBOTCONF_TEST": "1"}),
            on_exit=on_exit,
        )
    finally:
        os.close(fd)
    if brain.exit_fd is not None:  # pidfd: the owner waits for it and reaps
        readable, _, _ = select.select([brain.exit_fd], [], [], 20)
        assert readable
        exits.append((brain.pid, brain.reap()))
        assert brain.exit_fd is None  # closed by reap
    else:
        assert done.wait(20)
    assert exits == [(brain.pid, 3)]
    lines = out.read_text(encoding="utf-8").splitlines()
    assert lines[1] == "to-stderr"
    straggler = int(lines[0])
    wait_for(lambda: not is_alive(straggler), "the leftover sleep to be killed")
    assert os.getpgid(os.getpid()) != brain.pid  # it had its own group; ours was never signalled


def test_spawn_of_a_missing_executable_raises_the_os_error(tmp_path: Path) -> None:
    fd = os.open(tmp_path / "log", os.O_WRONLY | os.O_CREAT)
    try:
        with pytest.raises(FileNotFoundError):
            spawn(
                ["/nonexistent/brain"], cwd=tmp_path, log_fd=fd, env={}, on_exit=lambda p, c: None
            )
    finally:
        os.close(fd)


def test_log_rotation_keeps_backups_and_appenders_continue(tmp_path: Path) -> None:
    log = BrainLog(tmp_path / "brain.log", max_bytes=4096, backups=2)
    fd = log.open_for_child()
    try:
        for generation in "abc":
            os.write(fd, generation.encode() * 5000)
            assert log.rotate_if_needed()
        assert not log.rotate_if_needed()  # empty now
        os.write(fd, b"after")
    finally:
        os.close(fd)
    assert log.path.read_bytes() == b"after"  # O_APPEND: no hole, no old bytes
    assert (tmp_path / "brain.log.1").read_bytes() == b"c" * 5000
    assert (tmp_path / "brain.log.2").read_bytes() == b"b" * 5000
    assert not (tmp_path / "brain.log.3").exists()


def test_log_rotation_without_backups_only_truncates(tmp_path: Path) -> None:
    log = BrainLog(tmp_path / "brain.log", max_bytes=4096, backups=0)
    log.path.write_bytes(b"x" * 5000)
    assert log.rotate_if_needed()
    assert log.path.stat().st_size == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["brain.log"]


def test_seq_survives_a_restart_and_passes_what_was_seen(tmp_path: Path) -> None:
    path = tmp_path / "agent.seq"
    first = SeqStore(path)
    assert (first.current, first.advance(), first.advance()) == (0, 1, 2)
    second = SeqStore(path)
    assert second.current == 2 and second.advance() == 3
    second.observe(10)
    assert second.current == 3 and second.advance() == 11


def test_one_agent_per_workdir(tmp_path: Path) -> None:
    first, second = WorkdirLock(tmp_path), WorkdirLock(tmp_path)
    assert first.acquire() is None
    refusal = second.acquire()
    assert refusal is not None and f"pid {os.getpid()}" in refusal
    first.release()
    assert second.acquire() is None
    second.release()
