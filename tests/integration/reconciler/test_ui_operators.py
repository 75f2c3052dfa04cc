"""Named operators end to end: tokens made and hashed by `robotconf hash-token` (real
processes, the token on stdin), a real `robotconf ui --operators-file` over real HTTP, a real
reconciler keeping its ledger and real agents. Each operator restarts a robot with their own
token (a login form, a script's Bearer NAME:TOKEN): the robots' statuses and `robotconf events`
name them. Wrong tokens are throttled across loopback addresses as one client."""

from __future__ import annotations

import http.client
import json
import re
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

from robotconf.contract.wire import AgentStatus
from tests.integration.reconciler.conftest import Fleet
from tests.support.fleet import robotconf_argv
from tests.support.mosquitto import Mosquitto, free_port
from tests.support.ui import UiProc
from tests.support.watch import wait_for

FORM = "application/x-www-form-urlencoded"


def hash_token(*args: str, stdin: str = "") -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        robotconf_argv("hash-token", *args), input=stdin, capture_output=True, text=True, timeout=60
    )
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    return done


def operators_file(folder: Path) -> tuple[Path, dict[str, str]]:
    """alice's token made by `hash-token --new`, bob's own hashed from stdin: the file of both."""
    made = hash_token("--new", "alice")
    assert made.returncode == 0, made.stderr
    alice = made.stderr.rsplit(": ", 1)[1].strip()
    assert alice not in made.stdout and made.stdout.startswith("alice scrypt$")
    bob = "bobs-own-token-" + "b7" * 12
    hashed = hash_token("--name", "bob", stdin=bob + "\n")
    assert hashed.returncode == 0 and bob not in hashed.stdout
    assert hash_token(stdin=bob).stdout.startswith("scrypt$")  # the hash alone
    path = folder / "operators"
    path.write_text(f"# the lab's operators\n{made.stdout}{hashed.stdout}", encoding="utf-8")
    path.chmod(0o644)
    return path, {"alice": alice, "bob": bob}


def ask(
    ui: UiProc,
    method: str,
    path: str,
    body: str = "",
    source: str = "127.0.0.1",
    **headers: str,
) -> tuple[int, dict[str, str], str]:
    """One HTTP exchange from `source` (any loopback address), redirects not followed."""
    connection = http.client.HTTPConnection(
        "127.0.0.1", ui.port, timeout=30, source_address=(source, 0)
    )
    try:
        named = {name.replace("_", "-"): value for name, value in headers.items()}
        connection.request(method, path, body=body.encode() or None, headers=named)
        response = connection.getresponse()
        text = response.read().decode("utf-8", "replace")
        return response.status, dict(response.getheaders()), text
    finally:
        connection.close()


def log_in(ui: UiProc, name: str, token: str) -> str:
    form = urlencode({"username": name, "token": token})
    code, headers, body = ask(ui, "POST", "/login", form, Content_Type=FORM)
    assert code == 303, body
    return headers["Set-Cookie"].split(";")[0]


def restarts_kept(state: Path) -> dict[str, Any]:
    done = subprocess.run(
        robotconf_argv("events", "--state-dir", str(state), "--kind", "robot_restarted", "--json"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "Traceback" not in done.stderr, done.stderr
    if done.returncode != 0:
        return {}
    return {event["robot"]: event for event in json.loads(done.stdout)}


def asked_by(by: str) -> Callable[[AgentStatus], bool]:
    return lambda status: status.restart_requested_by == by


def test_each_operator_restarts_with_their_own_token_and_is_named(
    fleet: Fleet, tmp_path: Path
) -> None:
    state = tmp_path / "state"
    assert fleet.reconciler is not None
    fleet.reconciler.stop()
    fleet.start_reconciler("--interval", "5", "--state-dir", str(state))
    path, tokens = operators_file(tmp_path)
    ui = UiProc(
        fleet.lab.root, fleet.broker.url, tmp_path / "ui.log",
        "--operators-file", str(path), "--state-dir", str(state),
    )  # fmt: skip
    try:
        # alice logs in with her name and token, and restarts tb3-01 from its page.
        cookie = log_in(ui, "alice", tokens["alice"])
        code, _, page = ask(ui, "GET", "/robots/tb3-01/restart", Cookie=cookie)
        assert code == 200 and "operator alice" in page
        found = re.search(r'name="csrf" value="([^"]+)"', page)
        assert found is not None
        form = urlencode({"csrf": found.group(1)})
        done = ask(ui, "POST", "/robots/tb3-01/restart", form, Cookie=cookie, Content_Type=FORM)
        assert done[0] == 303, done[2]
        # bob's script restarts tb3-02 with his own token; alice's name with bob's is refused.
        bearer = {"Authorization": f"Bearer bob:{tokens['bob']}"}
        assert ask(ui, "POST", "/robots/tb3-02/restart", **bearer)[0] == 303
        posing = {"Authorization": f"Bearer alice:{tokens['bob']}"}
        assert ask(ui, "POST", "/robots/tb3-03/restart", **posing)[0] == 403

        for robot_id, by in [("tb3-01", "ui.alice"), ("tb3-02", "ui.bob")]:
            fleet.watch.wait_for(robot_id, asked_by(by), f"restarted by {by}")

        def both() -> dict[str, Any] | None:
            found = restarts_kept(state)
            return found if {"tb3-01", "tb3-02"} <= set(found) else None

        kept = wait_for(both, "both restarts in the timeline")
        assert kept["tb3-01"]["by"] == "ui.alice" and kept["tb3-02"]["by"] == "ui.bob"
        assert "tb3-03" not in kept
        assert "restarted from the desk by ui.alice" in kept["tb3-01"]["message"]

        # Four wrong guesses more (the posing Bearer was one) from 127.0.0.1: 127.0.0.2 is
        # the same client, held even with the right token.
        for n in range(4):
            guess = urlencode({"username": "alice", "token": f"guess-{n:02d}-" + "g" * 20})
            assert ask(ui, "POST", "/login", guess, Content_Type=FORM)[0] == 401
        right = urlencode({"username": "bob", "token": tokens["bob"]})
        held = ask(ui, "POST", "/login", right, source="127.0.0.2", Content_Type=FORM)
        assert held[0] == 429 and "Set-Cookie" not in held[1]
        assert ask(ui, "GET", "/healthz", source="127.0.0.3")[0] == 200
    finally:
        output = ui.stop()
    assert "ui: alice logged in from loopback" in output
    assert "ui: restart of tb3-01 asked by ui.alice from loopback" in output
    assert "ui: restart of tb3-02 asked by ui.bob from loopback" in output
    assert tokens["alice"] not in output and tokens["bob"] not in output


def test_hash_token_refuses_a_bad_token_or_name(tmp_path: Path) -> None:
    short = hash_token(stdin="short\n")
    assert short.returncode == 2 and "shorter than 16" in short.stderr
    two = hash_token(stdin="a-long-enough-token-1\nanother-line-here\n")
    assert two.returncode == 2 and "one line" in two.stderr
    bad = hash_token("--new", "al ice")
    assert bad.returncode == 2 and "not an operator name" in bad.stderr
    reserved = hash_token("--name", "cookie", stdin="a-long-enough-token-1\n")
    assert reserved.returncode == 2 and "reserved" in reserved.stderr


def test_a_ui_refuses_a_bad_operators_file_before_it_serves(
    mosquitto: Mosquitto, tmp_path: Path
) -> None:
    def run_ui(*args: str) -> subprocess.CompletedProcess[str]:
        done = subprocess.run(
            robotconf_argv(
                "ui", "--broker", mosquitto.url, "--repo", str(tmp_path),
                "--listen", f"127.0.0.1:{free_port()}", *args,
            ),
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
        return done

    path = tmp_path / "operators"
    path.write_text("alice scrypt$16384$8$1$AAAAAAAAAAA$AAAA\n", encoding="utf-8")
    assert f"{path}:1: the salt is at least 8 bytes" in run_ui("--operators-file", str(path)).stderr
    path.write_text("# nobody\n", encoding="utf-8")
    path.chmod(0o666)
    assert "chmod go-w" in run_ui("--operators-file", str(path)).stderr
    token = tmp_path / "token"
    token.write_text("the-one-token-" + "t" * 20 + "\n", encoding="utf-8")
    token.chmod(0o600)
    both = run_ui("--operators-file", str(path), "--operator-token-file", str(token))
    assert "do not go together" in both.stderr
    proxy = run_ui("--trusted-proxy", "proxy.lab")
    assert "--trusted-proxy 'proxy.lab' is not an IP address" in proxy.stderr
