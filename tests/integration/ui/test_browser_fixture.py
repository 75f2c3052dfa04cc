"""The browser fixture itself: headless Chromium opens a page of a real local HTTP server, runs
its script from 'self' under a strict CSP and takes a screenshot; a missing browser fails the
tests under `./dev test` and skips them, saying why, in a developer's plain pytest."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from tests.support import browser as support
from tests.support.lab import ROOT

if TYPE_CHECKING:
    from playwright.sync_api import Page

PAGE = b"""<!doctype html><html><head><title>probe</title><script src="/probe.js" defer></script>
</head><body><h1 id="title">served</h1><button id="go">go</button></body></html>"""
SCRIPT = b"""document.getElementById("go").addEventListener("click", () => {
  document.getElementById("title").textContent = "clicked";
});"""
CSP = "default-src 'none'; script-src 'self'"


class Tiny(BaseHTTPRequestHandler):
    def do_GET(self) -> None:
        body, kind = {"/": (PAGE, "text/html"), "/probe.js": (SCRIPT, "text/javascript")}.get(
            self.path, (b"not found", "text/plain")
        )
        self.send_response(200 if body != b"not found" else 404)
        self.send_header("Content-Type", f"{kind}; charset=utf-8")
        self.send_header("Content-Security-Policy", CSP)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture
def tiny_server() -> Iterator[str]:
    server = ThreadingHTTPServer(("127.0.0.1", 0), Tiny)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(10)


def test_the_browser_opens_a_page_of_a_local_server(
    page: Page, tiny_server: str, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    page.goto(tiny_server + "/")
    expect(page.locator("#title")).to_have_text("served")
    page.click("#go")  # the script ran: it came from 'self', which the CSP allows
    expect(page.locator("#title")).to_have_text("clicked")
    shot = tmp_path / "probe.png"
    page.screenshot(path=str(shot))
    assert shot.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")


@pytest.mark.parametrize(("required", "outcome"), [("1", "1 error"), ("", "1 skipped")])
def test_a_missing_browser_fails_under_dev_test_and_skips_elsewhere(
    required: str, outcome: str, tmp_path: Path
) -> None:
    env = dict(os.environ)
    env[support.CHROMIUM_ENV] = str(tmp_path / "no-chromium")
    env[support.REQUIRED_ENV] = required
    done = subprocess.run(
        [
            sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-rsE", "-q",
            f"{Path(__file__).relative_to(ROOT)}::test_the_browser_opens_a_page_of_a_local_server",
        ],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert outcome in done.stdout, done.stdout + done.stderr
    assert "Chromium is not installed (Debian's package chromium)" in done.stdout
    assert "./dev test installs it" in done.stdout or "`./dev test` installs it" in done.stdout
