"""Push, not poll: a real reconciler following a bare repository once an hour is woken by signed
push events posted over HTTP, and refuses forged, misdirected and malformed ones."""

from __future__ import annotations

import hashlib
import hmac
import json
import signal
import socket
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from robotconf.reconciler.webhook import MAX_BODY
from tests.integration.reconciler.test_alerts import scrape, value
from tests.support.fleet import GitLab, Proc, refused_reconcile, start_reconciler
from tests.support.mosquitto import Mosquitto, free_port
from tests.support.private import write_private
from tests.support.watch import FleetWatch, wait_for

SECRET = "d1c6f0a7e9b34c2b8f5e0a1d3c7b9e24"
FLEET = "configs/fleet.yaml"


def post(port: int, body: bytes, headers: dict[str, str]) -> tuple[int, str]:
    """POSTs as a git server does; the HTTP status and the answer's text."""
    request = urllib.request.Request(
        f"http://127.0.0.1:{port}/", data=body, headers=headers, method="POST"
    )
    try:
        with urllib.request.urlopen(request, timeout=30) as answer:
            return answer.status, answer.read().decode()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read().decode()


def push_body(ref: str, after: str) -> bytes:
    return json.dumps({"ref": ref, "before": "0" * 40, "after": after, "commits": []}).encode()


def signature(body: bytes, secret: str = SECRET) -> str:
    return hmac.new(secret.encode(), body, hashlib.sha256).hexdigest()


def github(body: bytes, event: str = "push", signed: str | None = SECRET) -> dict[str, str]:
    headers = {"Content-Type": "application/json", "X-GitHub-Event": event}
    if signed is not None:
        headers["X-Hub-Signature-256"] = "sha256=" + signature(body, signed)
    return headers


def rename(lab: GitLab, old: str, new: str) -> str:
    """A commit that changes tb3-02's request (its name)."""
    lab.replace(FLEET, f"name: {old},", f"name: {new},")
    return lab.commit(f"tb3-02 is {new}")


@pytest.fixture
def bare(lab: GitLab, tmp_path: Path) -> Path:
    """The lab's git server: a bare repository it pushes to."""
    path = tmp_path / "lab.git"
    lab.git("clone", "-q", "--bare", str(lab.root), str(path))
    return path


def start(lab: GitLab, bare: Path, mosquitto: Mosquitto, tmp_path: Path) -> tuple[Proc, int, int]:
    """`reconcile --remote` polling once an hour, with a webhook and metrics."""
    secret = tmp_path / "webhook.secret"
    write_private(secret, SECRET + "\n")
    port, metrics = free_port(), free_port()
    proc = start_reconciler(
        lab, mosquitto.url, tmp_path / "reconciler.log",
        "--remote", str(bare), "--cache-dir", str(tmp_path / "cache"), "--interval", "3600",
        "--webhook", f"127.0.0.1:{port}", "--webhook-secret-file", str(secret),
        "--metrics", f"127.0.0.1:{metrics}",
    )  # fmt: skip
    wait_for(lambda: "webhook: listening at" in proc.output() or not proc.alive(), "listening")
    assert proc.alive(), proc.output()
    return proc, port, metrics


def refuse_every_wrong_post(port: int, reconciler: Proc, pushed: str) -> None:
    """Forged, unsigned, misdirected, malformed, oversized posts, a ping and a GET: each has
    its answer, and the reconciler lives on."""
    body = push_body("refs/heads/main", pushed)
    refusals = [
        ("forged signature", body, github(body, signed="not the secret"), 403),
        ("no signature", body, github(body, signed=None), 401),
        ("another branch", push_body("refs/heads/dev", pushed), None, 202),
        ("not JSON", b'{"ref": "refs/heads/main",', None, 400),
        ("too large", b" " * (MAX_BODY + 1), None, 413),
        ("a ping", b'{"zen": "Design for failure."}', "ping", 204),
    ]
    for what, payload, headers, code in refusals:
        if headers is None or isinstance(headers, str):
            headers = github(payload, event=headers or "push")
        answer = post(port, payload, headers)
        assert answer[0] == code, (what, answer)
        assert reconciler.alive(), reconciler.output()
    with pytest.raises(urllib.error.HTTPError) as got:
        urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=30)
    assert got.value.code == 405 and got.value.headers["Allow"] == "POST"


def gitea_and_gitlab_pushes_fetch(lab: GitLab, bare: Path, port: int, watch: FleetWatch) -> None:
    """Gitea's signed push fetches; GitLab's fetches with its token, and not with a wrong one."""
    gitea = rename(lab, "Guide bot on the push", "Guide bot pushed to Gitea")
    lab.git("push", "-q", str(bare), "main")
    body = push_body("refs/heads/main", gitea)
    headers = {
        "Content-Type": "application/json",
        "X-Gitea-Event": "push",
        "X-GitHub-Event": "push",
        "X-Gitea-Signature": signature(body),
    }
    assert post(port, body, headers)[0] == 200
    watch.wait_reconciler(lambda s: s.last_applied_revision == gitea, "Gitea's push applied")
    gitlab = rename(lab, "Guide bot pushed to Gitea", "Guide bot pushed to GitLab")
    lab.git("push", "-q", str(bare), "main")
    body = push_body("refs/heads/main", gitlab)
    json_ = {"Content-Type": "application/json", "X-Gitlab-Event": "Push Hook"}
    assert post(port, body, {**json_, "X-Gitlab-Token": SECRET[:-1]})[0] == 403
    assert post(port, body, {**json_, "X-Gitlab-Token": SECRET})[0] == 200
    watch.wait_reconciler(lambda s: s.last_applied_revision == gitlab, "GitLab's push applied")


def assert_webhooks_counted(metrics: int) -> None:
    """Every post above, counted by server and outcome."""
    seen = scrape(metrics)
    name = "robotconf_webhooks_total"
    assert value(seen, name, server="github", outcome="fetch") == 1.0
    assert value(seen, name, server="github", outcome="refused") == 4.0
    assert value(seen, name, server="github", outcome="ignored") == 2.0
    assert value(seen, name, server="gitea", outcome="fetch") == 1.0
    assert value(seen, name, server="gitlab", outcome="refused") == 1.0
    assert value(seen, name, server="gitlab", outcome="fetch") == 1.0
    assert value(seen, name, server="unknown", outcome="refused") == 2.0  # GET, slow body


def assert_logged_quietly(output: str) -> None:
    """No traceback, no secret, each refusal one warning, the slow client one line."""
    assert "Traceback" not in output
    assert SECRET not in output and SECRET[:-1] not in output
    refused = [line for line in output.splitlines() if "refused" in line]
    assert len([line for line in refused if " WARNING " in line]) == len(refused) >= 7
    assert "timed out" in output  # the slow client, said in one line


def test_a_signed_push_fetches_at_once_and_nothing_else_does(
    lab: GitLab, bare: Path, mosquitto: Mosquitto, watch: FleetWatch, tmp_path: Path
) -> None:
    reconciler, port, metrics = start(lab, bare, mosquitto, tmp_path)
    # Clients that connect and never finish their request: they must hold nothing up.
    slow = socket.create_connection(("127.0.0.1", port))
    slow.sendall(b"POST / HTTP/1.1\r\nHost: x\r\nContent-Le")
    slow_body = socket.create_connection(("127.0.0.1", port))
    slow_body.sendall(b"POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n{")
    try:
        first = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == first, "applied")
        before = watch.digest("tb3-02")
        assert before == lab.requests(first)["tb3-02"].digest

        pushed = rename(lab, "Guide bot", "Guide bot on the push")
        lab.git("push", "-q", str(bare), "main")
        wanted = lab.requests(pushed)["tb3-02"].digest
        assert wanted != before
        refuse_every_wrong_post(port, reconciler, pushed)
        # None of them fetched: the pushed commit is on the server, unseen.
        assert "fetching" not in reconciler.output()
        status = watch.reconciler()
        assert status is not None and status.last_attempted_revision == first
        assert watch.digest("tb3-02") == before

        body = push_body("refs/heads/main", pushed)
        code, text = post(port, body, github(body))
        assert (code, text) == (
            200,
            f"push from github for main: fetching (commit {pushed[:12]})\n",
        )
        watch.wait(lambda: watch.digest("tb3-02") == wanted, "the pushed request retained")
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == pushed, "applied")
        assert "push from github for main: fetching" in reconciler.output()

        # Still serving, and Gitea's and GitLab's pushes fetch too.
        gitea_and_gitlab_pushes_fetch(lab, bare, port, watch)

        # The slow clients were cut off, one without an answer (it never sent a whole request).
        slow.settimeout(60)
        assert slow.recv(1024) == b""
        slow_body.settimeout(60)
        assert slow_body.makefile("rb").readline().startswith(b"HTTP/1.1 408 ")

        assert_webhooks_counted(metrics)
    finally:
        slow.close()
        slow_body.close()
        assert reconciler.stop() == 0, reconciler.output()[-3000:]
    assert_logged_quietly(reconciler.output())


@pytest.mark.parametrize(
    ("options", "secret", "said"),
    [
        (["--webhook", "127.0.0.1:9292"], None, "--webhook needs --webhook-secret-file FILE"),
        (["--webhook", "9292"], "s3cret", "--webhook '9292' must be HOST:PORT"),
        (["--webhook", ":9292"], "", "is empty: write a long random secret into it"),
        (["--webhook", ":9292"], "missing", "cannot read --webhook-secret-file"),
        ([], "s3cret", "--webhook-secret-file is given without --webhook"),
        (["--webhook", "256.256.256.256:9292"], "s3cret", "cannot listen"),
    ],
)
def test_bad_webhook_options_are_one_line_errors(
    lab: GitLab, mosquitto: Mosquitto, tmp_path: Path, options: list[str], secret: str | None,
    said: str,
) -> None:  # fmt: skip
    if secret is not None:
        path = tmp_path / "secret"
        if secret != "missing":
            write_private(path, secret + "\n")
        options = [*options, "--webhook-secret-file", str(path)]
    said_back = refused_reconcile(lab, mosquitto.url, options)
    assert said in said_back and "s3cret" not in said_back


def test_a_webhook_port_in_use_is_a_one_line_error(
    lab: GitLab, mosquitto: Mosquitto, tmp_path: Path
) -> None:
    secret = tmp_path / "secret"
    write_private(secret, SECRET)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        said = refused_reconcile(
            lab,
            mosquitto.url,
            ["--webhook", f"127.0.0.1:{port}", "--webhook-secret-file", str(secret)],
        )
    assert "cannot listen" in said


def test_a_local_branch_with_a_webhook_stops_cleanly(
    lab: GitLab, mosquitto: Mosquitto, tmp_path: Path
) -> None:
    """Without --remote a push re-reads the local branch; SIGTERM ends the receiver too."""
    secret = tmp_path / "secret"
    write_private(secret, SECRET)
    port = free_port()
    proc = start_reconciler(
        lab, mosquitto.url, tmp_path / "reconciler.log", "--webhook", f"127.0.0.1:{port}",
        "--webhook-secret-file", str(secret),
    )  # fmt: skip
    try:
        wait_for(lambda: "in sync with" in proc.output(), "in sync")
        body = push_body("refs/heads/main", lab.head())
        assert post(port, body, github(body))[0] == 200
        wait_for(lambda: "push from github for main: fetching" in proc.output(), "the push")
    finally:
        assert proc.stop(signal.SIGTERM) == 0, proc.output()[-3000:]
    assert "Traceback" not in proc.output()
