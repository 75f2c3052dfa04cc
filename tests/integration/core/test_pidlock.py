"""The one pid-file lock (contract/pidlock.py) as the agent's work directory and `up` hold it:
one holder per file, its pid written for whoever finds it held, gone when it lets go."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from robotconf.agent.workdir import LOCK_FILE, WorkdirLock
from robotconf.contract.errors import CliError
from robotconf.contract.pidlock import PidLock, lock_holder
from robotconf.workstation.up import UpLock


def test_a_held_lock_names_its_holder_until_released(tmp_path: Path) -> None:
    first, second = PidLock(tmp_path / "x.lock"), PidLock(tmp_path / "x.lock")
    assert first.holder() is None  # no file yet: nobody holds it
    assert first.take() is None
    assert (tmp_path / "x.lock").read_text(encoding="ascii") == f"{os.getpid()}\n"
    assert second.take() == str(os.getpid())
    assert second.holder() == lock_holder(tmp_path / "x.lock") == os.getpid()
    first.release()
    assert second.holder() is None
    assert second.take() is None
    second.release()


def test_the_agent_and_up_say_who_holds_their_lock(tmp_path: Path) -> None:
    agent = WorkdirLock(tmp_path)
    assert agent.path == tmp_path / LOCK_FILE
    assert agent.acquire() is None
    refusal = WorkdirLock(tmp_path).acquire()
    assert refusal == f"another agent (pid {os.getpid()}) is using {tmp_path}"
    agent.release()

    workdir = tmp_path / "up"  # made when it is missing
    up = UpLock(workdir)
    up.acquire()
    with pytest.raises(CliError) as refused:
        UpLock(workdir).acquire()
    assert refused.value.message == (
        f"another robotconf up (pid {os.getpid()}) is running with {workdir}; "
        "stop it first, or give this one its own --workdir"
    )
    up.release()
    again = UpLock(workdir)
    again.acquire()  # the lock of an `up` that stopped is free
    again.release()
