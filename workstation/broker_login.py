"""The logins of `robotconf up`'s embedded broker: a password generated once per user (`operator`,
`reconciler`, each robot by its id) into a file only its owner can read. No amqtt here."""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
from dataclasses import dataclass
from pathlib import Path

from robotconf.contract.models import file_name_problem, is_robot_id
from robotconf.contract.trust import read_secret_text

USERNAME = "operator"  # the operator's commands (the desk); up's reconciler and robots have theirs
RECONCILER = "reconciler"
PASSWORD_NAME = "operator.password"


@dataclass(frozen=True)
class BrokerLogin:
    """The user name and password every client of the embedded broker must give."""

    username: str
    password_file: Path

    def password(self) -> str:
        return read_secret_text(self.password_file)

    def accepts(self, username: str | None, password: str | bytes | None) -> bool:
        """Compared in constant time, so that not even the password's length shows."""
        given = password.encode() if isinstance(password, str) else (password or b"")
        try:
            wanted = self.password().encode()
        except OSError:  # the file is gone: nobody gets in
            return False
        same = hmac.compare_digest(hashlib.sha256(given).digest(), hashlib.sha256(wanted).digest())
        return same and username == self.username


def broker_login(folder: Path, username: str = USERNAME) -> BrokerLogin:
    """The login of `username` on the broker whose files are in `folder` (0700): its password
    file (`<user>.password`, 0600) is made once with a random password, and kept, so that agents
    and the operator's commands keep working across `up`s."""
    if file_name_problem(username) is not None:  # a file name too: never a path
        raise ValueError(f"{username!r} is not a user name of the embedded broker")
    folder.mkdir(parents=True, exist_ok=True)
    os.chmod(folder, 0o700)
    path = folder / f"{username}.password"
    if not path.is_file() or not path.read_text(encoding="utf-8").strip():
        path.unlink(missing_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as out:
            out.write(secrets.token_urlsafe(32) + "\n")
    os.chmod(path, 0o600)
    return BrokerLogin(username, path)


def prune_logins(folder: Path, keep: set[str]) -> list[str]:
    """Removes the password files of users not in `keep` (robots that left the fleet since an
    earlier `up`), so that a robot no longer in fleet.yaml cannot log in; the removed users."""
    gone = []
    for path in sorted(folder.glob("*.password")):
        user = path.name.removesuffix(".password")
        if user not in keep and is_robot_id(user):
            path.unlink(missing_ok=True)
            gone.append(user)
    return gone


def accepts(folder: Path, username: str | None, password: str | bytes | None) -> bool:
    """True when `username` has a login in `folder` and `password` is its password."""
    if username is None or not is_robot_id(username):
        return False
    return BrokerLogin(username, folder / f"{username}.password").accepts(username, password)
