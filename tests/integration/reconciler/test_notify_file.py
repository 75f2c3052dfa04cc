"""Receiver URLs off the command line: `reconcile --notify-file FILE` (one URL a line) and
`$ROBOTCONF_NOTIFY` (whitespace-separated), used together with --notify. A real reconciler is
told of a refused commit at every receiver so given, and no URL is in its command line (what
`ps` shows every user); a broken file is a one-line error naming FILE:LINE, never the URL."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from robotconf.reconciler.notify import MAX_NOTIFY_FILE_BYTES, NOTIFY_ENV
from tests.integration.reconciler.test_alerts import Receiver, break_fleet
from tests.support.fleet import GitLab, refused_reconcile, start_reconciler
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for


def test_receivers_from_a_file_and_the_environment_are_told_and_not_in_ps(
    lab: GitLab,
    mosquitto: Mosquitto,
    watch: FleetWatch,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from_file, slack, from_env, flagged = Receiver(), Receiver(), Receiver(), Receiver()
    listed = tmp_path / "receivers"
    listed.write_text(
        f"# the lab's alert receivers\n\n  {from_file.url}  \nslack:{slack.url}\n{flagged.url}\n"
    )
    listed.chmod(0o600)
    monkeypatch.setenv(NOTIFY_ENV, f"  {from_env.url}\n{from_file.url} ")  # one URL twice
    reconciler = start_reconciler(
        lab, mosquitto.url, tmp_path / "reconciler.log", "--interval", "1",
        "--notify-file", str(listed), "--notify", flagged.url,
    )  # fmt: skip
    everyone = (from_file, slack, from_env, flagged)
    try:
        good = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == good, "applied")
        argv = Path(f"/proc/{reconciler.pid}/cmdline").read_bytes().decode()
        assert not any(r.base in argv for r in (from_file, slack, from_env))
        bad = break_fleet(lab)
        for receiver in (from_file, from_env, flagged):
            wait_for(lambda r=receiver: r.events("commit_refused", revision=bad), "told")
        wait_for(lambda: slack.got(), "the Slack receiver told")
        assert slack.got()[0]["text"].startswith("robotconf commit refused")
        # Each URL is one receiver, however many times it is given: told once.
        assert len(from_file.events("commit_refused")) == 1
        assert len(flagged.events("commit_refused")) == 1
    finally:
        assert reconciler.stop() == 0, reconciler.output()[-3000:]
        for receiver in everyone:
            receiver.close()


def _file(tmp_path: Path, content: bytes) -> Path:
    path = tmp_path / "receivers"
    path.write_bytes(content)
    path.chmod(0o600)
    return path


@pytest.mark.parametrize(
    ("content", "said"),
    [
        (b"# ok\nhttp://ok.example/\n\nftp://user:hunter2@host/x\n", "receivers:4 must be an http"),
        (b"http://user:hunter2@ho st/\n", "receivers:1 must be ASCII without spaces"),
        (b"\xff\xfe", "is not UTF-8 text"),
        (b"#" * (MAX_NOTIFY_FILE_BYTES + 1), "over the limit"),
    ],
)
def test_a_broken_notify_file_is_a_one_line_error_naming_its_line(
    lab: GitLab, mosquitto: Mosquitto, tmp_path: Path, content: bytes, said: str
) -> None:
    path = _file(tmp_path, content)
    said_back = refused_reconcile(lab, mosquitto.url, ["--notify-file", str(path)])
    assert f"--notify-file {path}" in said_back
    assert said in said_back and "hunter2" not in said_back


def test_a_notify_file_others_may_read_is_refused_as_a_secret(
    lab: GitLab, mosquitto: Mosquitto, tmp_path: Path
) -> None:
    path = _file(tmp_path, b"https://hooks.slack.com/services/T/B/hunter2\n")
    path.chmod(0o640)  # a Slack webhook's path is its key: readable by the group, refused
    said_back = refused_reconcile(lab, mosquitto.url, ["--notify-file", str(path)])
    assert f"--notify-file {path}" in said_back and "chmod 600" in said_back
    assert "hunter2" not in said_back


def test_a_missing_notify_file_and_a_bad_environment_url_are_one_line_errors(
    lab: GitLab, mosquitto: Mosquitto, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    said: Any = refused_reconcile(lab, mosquitto.url, ["--notify-file", str(tmp_path / "none")])
    assert "--notify-file" in said and "No such file" in said
    monkeypatch.setenv(NOTIFY_ENV, "http://ok.example/ http://user:hunter2@/x")
    said = refused_reconcile(lab, mosquitto.url, [])
    assert f"${NOTIFY_ENV} #2 has no host" in said and "hunter2" not in said
