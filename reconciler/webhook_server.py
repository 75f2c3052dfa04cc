"""`reconcile --webhook HOST:PORT`: the HTTP edge that turns a git server's push into a fetch now.

Served by the bounded edge (`readmodel/http_edge.py`); every request is judged by
`reconciler.webhook.judge`, answered, and logged.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from robotconf.contract.files import NotRegularFile
from robotconf.contract.textsafe import printable
from robotconf.contract.trust import Trust, read_trusted
from robotconf.readmodel.http_edge import EdgeListener, Limits, Request, Response
from robotconf.reconciler.webhook import MAX_BODY, Answer, Outcome, judge, refused, server_of

log = logging.getLogger("robotconf.reconciler")

MAX_SECRET = 4096
# A git server sends one push at a time, from one or two addresses: 8 connections per address
# and 64 in all are far above what it needs, and an idle one costs only a file descriptor.
LIMITS = Limits(
    connections=64,
    per_client=8,
    head=5.0,  # the whole request head, however busy the client: a trickled head is cut
    silence=5.0,
    deadline=10.0,  # the whole request, body included: a slow body is answered 408
    max_body=MAX_BODY,
    body_methods=frozenset({"POST"}),
)


def read_secret(path: Path) -> bytes:
    """The secret in `path` without surrounding white space; ValueError with a one-line reason
    (which never quotes the file's content)."""
    try:
        data = read_trusted(path, Trust.SECRET, MAX_SECRET)
    except NotRegularFile as exc:
        raise ValueError(f"--webhook-secret-file {path} {exc}") from None
    except OSError as exc:
        raise ValueError(
            f"cannot read --webhook-secret-file {path}: {exc.strerror or exc}"
        ) from None
    secret = data.strip()
    if not secret:
        raise ValueError(
            f"--webhook-secret-file {path} is empty: write a long random secret into it "
            "(openssl rand -hex 32) and give the git server's webhook the same"
        )
    return secret


class WebhookServer(EdgeListener):
    """Listens once `serve`d; a push of `branch` calls `on_push` (it must return at once), and
    every answer's server and outcome are told to `on_answer` (metrics) when given."""

    def __init__(
        self,
        secret: bytes,
        branch: str,
        on_push: Callable[[], None],
        on_answer: Callable[[str, str], None] | None = None,
        *,
        limits: Limits = LIMITS,
    ) -> None:
        self.secret = secret
        self.branch = branch
        self.limits = limits
        self._on_push = on_push
        self._on_answer = on_answer

    def serve(self, host: str, port: int) -> None:
        """Listens now (OSError when it cannot) and answers on a thread of its own."""
        self._listen("webhook", self, self.limits, host, port)

    # ------------------------------------------------------------------ the edge's Service

    def answer(self, request: Request) -> Response:
        if request.method != "POST":
            method = printable(request.method[:20])
            return self.refused(request, 405, f"{method} is not POST")
        judged = judge(list(request.headers.items()), request.body, self.secret, self.branch)
        self.told(judged, request.client)
        return Response.text(judged.code, judged.message)

    def refused(self, request: Request, code: int, message: str) -> Response:
        """A refusal decided before the body is judged: told like the others, answered."""
        self.told(refused(code, server_of(request.headers.items()), message), request.client)
        allow = ("Allow", "POST")
        return Response.text(code, message, allow) if code == 405 else Response.text(code, message)

    def told(self, answer: Answer, client: str) -> Answer:
        """Logs the answer, counts it, and wakes the reconciler for a push of its branch."""
        if answer.outcome is Outcome.REFUSED:
            log.warning(
                "webhook request from %s refused (%d): %s", client, answer.code, answer.message
            )
        else:
            log.info("%s", answer.message)
        if answer.fetch:
            self._on_push()
        if self._on_answer is not None:
            try:
                self._on_answer(answer.server, answer.outcome.value)
            except Exception as exc:  # metrics must not cost an answer
                log.warning("webhook: counting an answer failed: %s", exc)
        return answer
