"""Fixtures of the browser tests: one headless Chromium for the session, and a page in a
browser context of its own (its own cookies) per test, closed afterwards."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest

from tests.support import browser as support

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page


@pytest.fixture(scope="session")
def browser() -> Iterator[Browser]:
    why = support.missing()
    if why is not None:
        if support.required():
            pytest.fail(f"{why}: ./dev test installs it (the browser tests never run without)")
        pytest.skip(f"{why}; `./dev test` installs it")
    with support.chromium() as started:
        yield started


@pytest.fixture
def page(browser: Browser) -> Iterator[Page]:
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    try:
        yield context.new_page()
    finally:
        context.close()
