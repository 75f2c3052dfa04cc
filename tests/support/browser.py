"""Debian's Chromium, headless, driven by Playwright for the browser tests (`./dev test`
installs both); where a browser is missing, whether that fails or skips the tests.

Playwright's own browser download cannot work on our machines: it drives /usr/bin/chromium.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from playwright.sync_api import Browser

# `./dev test` installs the browser and sets this: there a missing browser is a failure, as a
# missing Mosquitto is. A developer's plain `pytest` without it skips the browser tests.
REQUIRED_ENV = "ROBOTCONF_BROWSER_REQUIRED"
# A folder for the screenshots of tests/integration/ui/test_browser.py besides the test's own
# tmp_path: `ROBOTCONF_SCREENSHOTS=docs/images` remakes the docs' pictures from a real run.
SCREENSHOTS_ENV = "ROBOTCONF_SCREENSHOTS"
CHROMIUM_ENV = "ROBOTCONF_CHROMIUM"  # another Chromium than Debian's

CANDIDATES = ("/usr/bin/chromium", "/usr/lib/chromium/chromium")
# Headless, as root in a container, on a machine whose network is closed: without the
# background-networking flags Chromium keeps dialling Google's hosts and is refused.
FLAGS = (
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)


def find_chromium() -> str | None:
    """Debian's Chromium, or the one $ROBOTCONF_CHROMIUM names (if it is there)."""
    named = os.environ.get(CHROMIUM_ENV)
    for candidate in [named] if named else [*CANDIDATES, shutil.which("chromium") or ""]:
        if candidate and os.access(candidate, os.X_OK):
            return candidate
    return None


def missing() -> str | None:
    """Why the browser tests cannot run here, or None when they can."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the Python package playwright is not installed (the `dev` extra)"
    if find_chromium() is None:
        return "Chromium is not installed (Debian's package chromium)"
    return None


def required() -> bool:
    return os.environ.get(REQUIRED_ENV, "") not in ("", "0")


@contextmanager
def chromium() -> Iterator[Browser]:
    """A headless Chromium, closed on the way out. Each launch gets a new empty profile of
    Playwright's in the temporary folder, removed at close (launch() refuses --user-data-dir);
    tests isolate themselves further with one browser context each."""
    from playwright.sync_api import sync_playwright

    executable = find_chromium()
    assert executable is not None
    with sync_playwright() as driver:
        browser = driver.chromium.launch(
            executable_path=executable, headless=True, args=list(FLAGS)
        )
        try:
            yield browser
        finally:
            browser.close()


def screenshot_folders(tmp_path: Path) -> list[Path]:
    """Where a test's screenshots go: always its tmp_path (so the code that takes them runs in
    every run), and $ROBOTCONF_SCREENSHOTS when set."""
    folders = [tmp_path / "screenshots"]
    extra = os.environ.get(SCREENSHOTS_ENV)
    if extra:
        folders.append(Path(extra).resolve())
    for folder in folders:
        folder.mkdir(parents=True, exist_ok=True)
    return folders
