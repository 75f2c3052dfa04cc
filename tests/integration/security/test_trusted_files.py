"""Files read as configuration or credentials are checked before they are trusted, with real
files, modes, links and owners (contract/trust.py; the rule itself: tests/unit/core/test_trust.py).
Owners other than the user can only be made by root: those tests run as root, as git's own
safe.directory tests do, and are skipped otherwise."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from robotconf.agent.config import ConfigInvalid, load_config
from robotconf.agent.workdir import hold_exists
from robotconf.contract.signing import (
    SigningKeyError,
    generate_keys,
    load_private_key,
    load_public_key,
)
from robotconf.contract.trust import Trust, UntrustedFile, read_trusted
from robotconf.workstation.up_desk import DESK_FILE, UpDesk, find_desk, write_desk
from tests.support.fleet import robotconf_argv
from tests.support.private import write_private

NOBODY = 65534
as_root = pytest.mark.skipif(os.geteuid() != 0, reason="only root can give a file another owner")


def desk(tmp_path: Path) -> UpDesk:
    return UpDesk(
        broker="mqtt://127.0.0.1:41414",
        prefix="planted",
        pid=os.getpid(),
        username="operator",
        password_file=tmp_path / "their.password",
    )


def robotconf(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {name: value for name, value in os.environ.items() if name != "ROBOTCONF_BROKER"}
    return subprocess.run(
        robotconf_argv(*args), capture_output=True, text=True, timeout=60, cwd=cwd, env=env
    )


def test_a_world_writable_config_and_a_readable_secret_are_refused(tmp_path: Path) -> None:
    config = tmp_path / "agent.yaml"
    config.write_text("broker: mqtt://x\n")
    config.chmod(0o666)
    with pytest.raises(UntrustedFile, match=rf"mode 0666\): chmod go-w {config}$"):
        read_trusted(config, Trust.CONFIG, 1024)
    config.chmod(0o644)
    assert read_trusted(config, Trust.CONFIG, 1024) == b"broker: mqtt://x\n"
    with pytest.raises(UntrustedFile, match=rf"may be read by others .*chmod 600 {config}"):
        read_trusted(config, Trust.SECRET, 1024)


def test_a_password_file_others_may_read_is_one_line_naming_it(tmp_path: Path) -> None:
    password = tmp_path / "pw"
    password.write_text("s3cret\n")
    password.chmod(0o644)
    argv = ["status", "--broker", "mqtt://127.0.0.1:1", "--username", "op"]
    done = robotconf(*argv, "--password-file", str(password), cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr == (
        f"robotconf: cannot read --password-file {password}: may be read by others "
        f"(mode 0644): chmod 600 {password}, as ssh asks of a key\n"
    )


def test_signing_keys_are_checked_before_they_are_trusted(tmp_path: Path) -> None:
    pair = generate_keys(tmp_path / "keys", force=False)
    load_private_key(pair.private)
    load_public_key(pair.public)  # 0644: anyone may read a public key...
    pair.private.chmod(0o640)
    with pytest.raises(SigningKeyError, match="may be read by others"):
        load_private_key(pair.private)
    pair.public.chmod(0o664)  # ...but whoever may change it decides what an agent obeys
    with pytest.raises(SigningKeyError, match="may be changed by others"):
        load_public_key(pair.public)


def test_a_symbolic_link_is_refused_where_the_tool_names_the_path(tmp_path: Path) -> None:
    real = write_private(tmp_path / "real.password", "s3cret\n")
    link = tmp_path / "link.password"
    link.symlink_to(real)
    # A path the user gives may be a link: its target is judged.
    assert read_trusted(link, Trust.SECRET, 1024) == b"s3cret\n"
    with pytest.raises(UntrustedFile, match="is a symbolic link"):
        read_trusted(link, Trust.SECRET, 1024, follow=False)
    # The desk file is a path the tool names itself: a link there is someone else's doing.
    lease = write_desk(tmp_path / "theirs", desk(tmp_path))
    (tmp_path / "lab" / DESK_FILE).parent.mkdir(parents=True)
    (tmp_path / "lab" / DESK_FILE).symlink_to(lease.path)
    try:
        found, note = find_desk(tmp_path / "lab")
        assert found is None and note is not None and "is a symbolic link" in note
    finally:
        lease.release()


def test_agent_yaml_that_others_may_change_is_refused(tmp_path: Path) -> None:
    config = tmp_path / "agent.yaml"
    config.write_text("broker: mqtt://127.0.0.1:1883\n")
    config.chmod(0o646)
    with pytest.raises(ConfigInvalid, match=r"may be changed by others \(mode 0646\)"):
        load_config(config, prepare=False)


@as_root
def test_a_desk_file_planted_above_the_lab_is_never_read(tmp_path: Path) -> None:
    """Another user's folder above the lab holds a live, well-formed desk file: the walk up
    stops at that folder, and the command never goes to the planted broker."""
    shared = tmp_path / "shared"
    lease = write_desk(shared, desk(tmp_path))
    for path in (shared, shared / ".robotconf", shared / DESK_FILE.parent, lease.path):
        os.chown(path, NOBODY, NOBODY)
    lab = shared / "lab"
    lab.mkdir()
    try:
        found, note = find_desk(lab)
        assert found is None and note is not None
        assert f"belongs to user id {NOBODY}" in note and "safe.directory" in note
        done = robotconf("status", "--wait", "0", cwd=lab)
        assert "41414" not in done.stdout + done.stderr, done.stderr
        assert f"belongs to user id {NOBODY}" in done.stderr
        assert "Traceback" not in done.stderr
    finally:
        lease.release()


@as_root
def test_a_desk_file_of_another_user_in_the_user_s_folder_is_refused(tmp_path: Path) -> None:
    lease = write_desk(tmp_path, desk(tmp_path))
    os.chown(lease.path, NOBODY, NOBODY)
    try:
        found, note = find_desk(tmp_path)
        assert found is None and note is not None
        assert note.startswith(f"{lease.path} belongs to user id {NOBODY}, not to you")
    finally:
        lease.release()


@as_root
def test_a_secret_of_another_user_is_refused(tmp_path: Path) -> None:
    password = write_private(tmp_path / "pw", "s3cret\n")
    os.chown(password, NOBODY, NOBODY)
    with pytest.raises(UntrustedFile, match=f"belongs to user id {NOBODY}"):
        read_trusted(password, Trust.SECRET, 1024)


@as_root
def test_a_hold_file_of_another_user_defers_nothing(tmp_path: Path) -> None:
    hold = tmp_path / "brain.hold"
    hold.touch()
    assert hold_exists(hold)
    os.chown(hold, NOBODY, NOBODY)
    assert not hold_exists(hold)
