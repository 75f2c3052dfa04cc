"""The UI's operators, end to end: `robotconf ui` with an operator token, a real Mosquitto and
a real agent. A restart by Bearer or by login cookie and CSRF reaches the agent and starts its
brain again; a viewer, a stale form, a forged cookie and other attacks are refused, answered,
and leave no traceback; an operator follows the brain's log."""

from __future__ import annotations

import http.client
import re
import socket
import ssl
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

import pytest

from robotconf.contract.signing import generate_keys, load_private_key, sign
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import FAILS_ONCE, ROBOT, TIMEOUT, make_request, publish
from tests.support.lab import ROBOTCONF
from tests.support.mosquitto import Mosquitto
from tests.support.tlsutil import make_pki
from tests.support.watch import FleetWatch, wait_for

TOPICS = Topics()
TOKEN = "ui-operator-token-" + "k3" * 12
FORM = "application/x-www-form-urlencoded"
# A hostile line (a carriage return that would start a forged event), then a numbered tick
# five times a second.
TICKS = [
    sys.executable,
    "-u",
    "-c",
    "import time\n"
    "print('evil \\x1b[31m<b>\\rdata: forged\\r\\revent: x')\n"
    "n = 0\n"
    "while True:\n"
    "    print('tick', n)\n"
    "    n += 1\n"
    "    time.sleep(0.2)\n",
    "{launch_request}",
]


@dataclass
class Answer:
    code: int
    headers: dict[str, str]
    body: str


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class UiProc:
    """`robotconf ui` as a process on a free loopback port (over TLS with `tls`, the client's
    context trusting the UI's certificate)."""

    def __init__(
        self,
        tmp_path: Path,
        broker: Mosquitto,
        *extra: str,
        token: bool = True,
        tls: ssl.SSLContext | None = None,
    ):
        self.tls = tls
        self.port = free_port()
        self.stderr_path = tmp_path / "ui.stderr"
        args = [str(ROBOTCONF), "ui", "--broker", broker.url, "--repo", str(tmp_path)]
        args += ["--listen", f"127.0.0.1:{self.port}", *extra]
        if token:
            token_file = tmp_path / "operator-token"
            token_file.write_text(TOKEN + "\n", encoding="utf-8")
            token_file.chmod(0o600)
            args += ["--operator-token-file", str(token_file)]
        with self.stderr_path.open("ab") as err:
            self.proc = subprocess.Popen(
                args, stdin=subprocess.DEVNULL, stdout=err, stderr=err, start_new_session=True
            )
        wait_for(self._up, "the UI answering /healthz")

    def _up(self) -> bool:
        assert self.proc.poll() is None, self.stderr()
        try:
            return self.ask("GET", "/healthz").code == 200
        except OSError:
            return False

    def stderr(self) -> str:
        return self.stderr_path.read_text(encoding="utf-8", errors="replace")

    def connect(self) -> http.client.HTTPConnection:
        if self.tls is not None:
            return http.client.HTTPSConnection(
                "127.0.0.1", self.port, timeout=TIMEOUT, context=self.tls
            )
        return http.client.HTTPConnection("127.0.0.1", self.port, timeout=TIMEOUT)

    def ask(
        self, method: str, path: str, body: bytes | str | None = None, **headers: str
    ) -> Answer:
        connection = self.connect()
        try:
            data = body.encode() if isinstance(body, str) else body
            named = {name.replace("_", "-"): value for name, value in headers.items()}
            connection.request(method, path, body=data, headers=named)
            response = connection.getresponse()
            text = response.read().decode("utf-8", "replace")
            return Answer(response.status, dict(response.getheaders()), text)
        finally:
            connection.close()

    def login(self) -> str:
        """A session cookie (`robotconf_ui=...`) from the login form."""
        page = self.ask("GET", "/login")
        assert page.code == 200 and "data-login" in page.body
        answer = self.ask("POST", "/login", urlencode({"token": TOKEN}), Content_Type=FORM)
        assert answer.code == 303, answer.body
        return answer.headers["Set-Cookie"].split(";")[0]

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(TIMEOUT)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


@pytest.fixture
def ui_factory(tmp_path: Path, mosquitto: Mosquitto) -> Iterator[Any]:
    made: list[UiProc] = []

    def factory(*extra: str, token: bool = True, tls: ssl.SSLContext | None = None) -> UiProc:
        ui = UiProc(tmp_path, mosquitto, *extra, token=token, tls=tls)
        made.append(ui)
        return ui

    try:
        yield factory
    finally:
        for ui in made:
            ui.close()
            assert "Traceback" not in ui.stderr(), ui.stderr()


def failed_robot(
    make_agent: AgentFactory, watch: FleetWatch, broker: Mosquitto, **settings: Any
) -> Any:
    agent = make_agent(
        command=FAILS_ONCE, restart={"policy": "on-failure", "max_restarts": 0}, **settings
    )
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    return agent


def launch(broker: Mosquitto, request: Any) -> None:
    publish(broker.url, TOPICS.launch(ROBOT), request.payload())


def csrf_of(page: str) -> str:
    found = re.search(r'name="csrf" value="([^"]+)"', page)
    assert found is not None, page
    return found.group(1)


def restarted(watch: FleetWatch, agent: Any, by: str) -> AgentStatus:
    status = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent)
    assert status.restart_requested_by == by
    return status


def outcome_of(ui: UiProc, cookie: str) -> str:
    page = ui.ask("GET", f"/robots/{ROBOT}", Cookie=cookie).body
    found = re.search(r"<[^>]*data-restart-outcome[^>]*>(.*?)</", page, re.S)
    return found.group(1) if found else ""


# ---------------------------------------------------------------- restart


def test_an_operator_restarts_a_failed_brain_by_login_cookie_and_csrf(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, ui_factory: Any
) -> None:
    agent = failed_robot(make_agent, watch, mosquitto)
    request = make_request()
    launch(mosquitto, request)
    watch.wait_state(ROBOT, AgentState.FAILED, agent=agent, digest=request.digest)
    ui = ui_factory()
    cookie = ui.login()
    robot_page = ui.ask("GET", f"/robots/{ROBOT}", Cookie=cookie).body
    assert 'data-action="restart"' in robot_page
    page = ui.ask("GET", f"/robots/{ROBOT}/restart", Cookie=cookie)
    assert page.code == 200 and "data-confirm-restart" in page.body
    assert f"Restart {ROBOT}" in page.body
    form = urlencode({"csrf": csrf_of(page.body)})
    done = ui.ask("POST", f"/robots/{ROBOT}/restart", form, Cookie=cookie, Content_Type=FORM)
    assert done.code == 303 and done.headers["Location"] == f"/robots/{ROBOT}"
    restarted(watch, agent, "ui.cookie")
    assert "restart requested by ui.cookie" in agent.brain_log()
    wait_for(lambda: "confirmed" in outcome_of(ui, cookie), "the outcome on the robot page")
    # No page an operator sees holds the token or the session id (the CSRF token is the
    # session's forms' own).
    session_id = cookie.split("=", 1)[1]
    for path in ["/", f"/robots/{ROBOT}", f"/robots/{ROBOT}/restart", "/login"]:
        shown = ui.ask("GET", path, Cookie=cookie)
        text = shown.body + repr(shown.headers)
        assert shown.code == 200 and TOKEN not in text and session_id not in text, path


def test_a_script_restarts_with_a_bearer_token_and_a_signed_request(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    make_agent: AgentFactory,
    ui_factory: Any,
    tmp_path: Path,
) -> None:
    keys = generate_keys(tmp_path / "keys")
    agent = failed_robot(make_agent, watch, mosquitto, public_key=str(keys.public))
    request = sign(make_request(), load_private_key(keys.private))
    launch(mosquitto, request)
    watch.wait_state(ROBOT, AgentState.FAILED, agent=agent, digest=request.digest)
    ui = ui_factory("--signing-key", str(keys.private))
    bearer = {"Authorization": f"Bearer {TOKEN}"}
    done = ui.ask("POST", f"/robots/{ROBOT}/restart", b"", **bearer)
    assert done.code == 303, done.body
    restarted(watch, agent, "ui.bearer")
    assert "restart refused" not in agent.log_tail(200)


def test_viewers_stale_forms_and_wrong_tokens_restart_nothing(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, ui_factory: Any
) -> None:
    agent = failed_robot(make_agent, watch, mosquitto)
    request = make_request()
    launch(mosquitto, request)
    failed = watch.wait_state(ROBOT, AgentState.FAILED, agent=agent, digest=request.digest)
    ui = ui_factory()
    path = f"/robots/{ROBOT}/restart"
    viewer_page = ui.ask("GET", f"/robots/{ROBOT}").body
    assert 'data-action="restart"' not in viewer_page
    assert ui.ask("GET", path).code == 401
    assert ui.ask("POST", path, "csrf=x", Content_Type=FORM).code == 401
    cookie = ui.login()
    stale = urlencode({"csrf": "not-the-session-csrf-token-at-all"})
    assert ui.ask("POST", path, stale, Cookie=cookie, Content_Type=FORM).code == 403
    assert ui.ask("POST", path, "", Cookie=cookie, Content_Type=FORM).code == 403
    wrong = {"Authorization": "Bearer not-the-operator-token-0000"}
    assert ui.ask("POST", path, b"", **wrong).code == 403
    forged = "robotconf_ui=" + "A" * 43
    csrf = csrf_of(ui.ask("GET", path, Cookie=cookie).body)
    form = urlencode({"csrf": csrf})
    assert ui.ask("POST", path, form, Cookie=forged, Content_Type=FORM).code == 401
    time.sleep(1.0)  # had anything been sent, the agent would have acted by now
    latest = watch.latest(ROBOT)
    assert latest is not None and latest.state is AgentState.FAILED
    assert latest.restart_requested_by is None and latest.pid == failed.pid
    assert "restart requested" not in agent.brain_log() + agent.log_tail(200)


def test_attacks_on_the_write_side_are_refused_and_the_ui_stays_up(
    mosquitto: Mosquitto, ui_factory: Any
) -> None:
    ui = ui_factory()
    form = {"Content_Type": FORM}
    # A huge body, announced: refused before it is read.
    connection = ui.connect()
    connection.putrequest("POST", "/login")
    connection.putheader("Content-Type", FORM)
    connection.putheader("Content-Length", str(100 * 1024 * 1024))
    connection.endheaders()
    connection.send(b"token=" + b"x" * 65536)
    response = connection.getresponse()
    assert response.status == 413
    connection.close()
    # The wrong content type, a JSON body, a non-ASCII body.
    assert ui.ask("POST", "/login", "token=x", Content_Type="text/plain").code == 415
    assert ui.ask("POST", "/login", '{"token": 1}', Content_Type="application/json").code == 415
    assert ui.ask("POST", "/login", b"token=\xff\xfe", **form).code == 400
    # A `next` pointing off-site is dropped.
    for off_site in ["//evil.example/", "https://evil.example/", "/\\evil.example"]:
        body = urlencode({"token": TOKEN, "next": off_site})
        answer = ui.ask("POST", "/login", body, **form)
        assert answer.code == 303 and answer.headers["Location"] == "/", off_site
    # A form from another site.
    other = {"Origin": "https://evil.example", "Sec_Fetch_Site": "cross-site"}
    assert ui.ask("POST", "/login", urlencode({"token": TOKEN}), **form, **other).code == 403
    # Repeated guesses: refused, then throttled, even for the right token.
    codes = [
        ui.ask("POST", "/login", urlencode({"token": f"guess-{n:03d}-" + "g" * 16}), **form).code
        for n in range(6)
    ]
    assert codes[:5] == [401] * 5 and codes[5] == 429
    right = ui.ask("POST", "/login", urlencode({"token": TOKEN}), **form)
    assert right.code == 429 and "Set-Cookie" not in right.headers
    assert int(right.headers["Retry-After"]) > 0
    assert ui.ask("GET", "/healthz").code == 200
    assert TOKEN not in ui.stderr()


def test_over_tls_the_session_cookie_is_sent_over_tls_only(
    mosquitto: Mosquitto, ui_factory: Any, tmp_path: Path
) -> None:
    pki = make_pki(tmp_path / "pki")
    trust = ssl.create_default_context(cafile=str(pki.ca_cert))
    ui = ui_factory("--tls-cert", str(pki.server_cert), "--tls-key", str(pki.server_key), tls=trust)
    answer = ui.ask("POST", "/login", urlencode({"token": TOKEN}), Content_Type=FORM)
    assert answer.code == 303
    flags = [flag.strip() for flag in answer.headers["Set-Cookie"].split(";")]
    assert {"Secure", "HttpOnly", "SameSite=Strict", "Path=/"} <= set(flags)


def run_ui(tmp_path: Path, broker: Mosquitto, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(ROBOTCONF), "ui", "--broker", broker.url, "--repo", str(tmp_path), *args],
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_a_ui_refuses_a_readable_token_file_and_an_unprotected_address(
    mosquitto: Mosquitto, tmp_path: Path
) -> None:
    token_file = tmp_path / "token"
    token_file.write_text(TOKEN + "\n", encoding="utf-8")
    token_file.chmod(0o644)
    loopback = f"127.0.0.1:{free_port()}"
    readable = run_ui(
        tmp_path, mosquitto, "--listen", loopback, "--operator-token-file", str(token_file)
    )
    assert readable.returncode == 2 and "chmod 600" in readable.stderr
    assert TOKEN not in readable.stderr + readable.stdout
    token_file.chmod(0o600)
    anywhere = f"0.0.0.0:{free_port()}"
    no_token = run_ui(tmp_path, mosquitto, "--listen", anywhere)
    assert no_token.returncode == 2 and "--operator-token-file" in no_token.stderr
    no_tls = run_ui(
        tmp_path, mosquitto, "--listen", anywhere, "--operator-token-file", str(token_file)
    )
    assert no_tls.returncode == 2 and "--behind-tls-proxy" in no_tls.stderr
    for done in (readable, no_token, no_tls):
        assert "Traceback" not in done.stderr


# ---------------------------------------------------------------- logs


def read_events(ui: UiProc, cookie: str, until: str) -> str:
    """The log stream's text until `until` is in it (or the time runs out)."""
    connection = ui.connect()
    try:
        connection.request("GET", f"/robots/{ROBOT}/logs", headers={"Cookie": cookie})
        response = connection.getresponse()
        assert response.status == 200
        assert response.getheader("Content-Type", "").startswith("text/event-stream")
        seen = ""
        deadline = time.monotonic() + TIMEOUT
        while until not in seen and time.monotonic() < deadline:
            line = response.fp.readline()
            if not line:
                break
            seen += line.decode("utf-8", "replace")
        return seen
    finally:
        connection.close()


def test_an_operator_follows_the_brains_log_and_a_viewer_cannot(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, ui_factory: Any
) -> None:
    agent = make_agent(command=TICKS).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = make_request()
    launch(mosquitto, request)
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    agent.note_brain(running.pid)
    ui = ui_factory()
    assert ui.ask("GET", f"/robots/{ROBOT}/logs").code == 401
    wrong = {"Authorization": "Bearer not-the-operator-token-0000"}
    assert ui.ask("GET", f"/robots/{ROBOT}/logs", **wrong).code == 403
    cookie = ui.login()
    seen = read_events(ui, cookie, "data: tick 30")
    assert "data: tick 30" in seen
    # The hostile line is one line of data, its carriage returns written as escapes.
    assert "data: evil <b>\\rdata: forged\\r\\revent: x\n" in seen
    assert "\r" not in seen and "\ndata: forged" not in seen and "\nevent:" not in seen
    # Streams end when their page goes: more streams, one after the other, than the UI
    # serves at once all open.
    for _ in range(9):
        assert "data: tick" in read_events(ui, cookie, "data: tick")
