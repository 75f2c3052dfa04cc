"""Every revision is a commit, in a real browser: headless Chromium on `robotconf ui` of a real
git lab. A revision's page shows its commit (subject as text, author, time, the files changed)
and what it changes on the fleet (`plan` against the revision before); a commit that does not
validate shows why the reconciler refuses it.

DOM contract: `[data-commit]` with `[data-subject]`, `ul[data-files]`, `pre[data-plan]`, and
for a refused commit `ul[data-diagnostics]`."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from tests.integration.ui.test_browser import (  # noqa: F401 (pages_without_errors: autouse)
    expect_ms,
    open_page,
    pages_without_errors,
)
from tests.support.fleet import GitLab
from tests.support.mosquitto import Mosquitto
from tests.support.ui import UiProc

if TYPE_CHECKING:
    from playwright.sync_api import Browser

HOSTILE = 'Rename <img src=x onerror="window.pwned=1"> the patrol'


@pytest.fixture
def lab(tmp_path: Path) -> GitLab:
    lab = GitLab(tmp_path / "lab")
    lab.commit("the lab")
    return lab


@pytest.fixture
def ui(lab: GitLab, tmp_path: Path, mosquitto: Mosquitto) -> Iterator[UiProc]:
    proc = UiProc(lab.root, mosquitto.url, tmp_path / "ui.log", "--prefix", "robotconf")
    try:
        yield proc
    finally:
        proc.stop()


def test_a_revision_page_shows_its_commit_and_what_it_changes(
    lab: GitLab, ui: UiProc, browser: Browser
) -> None:
    from playwright.sync_api import expect

    lab.replace("configs/fleet.yaml", "name: Lab patrol", "name: Lab patrol v2")
    good = lab.commit(HOSTILE)
    page = open_page(browser)
    page.goto(f"http://127.0.0.1:{ui.port}/revisions/{good}")
    commit = page.locator(f'[data-commit="{good}"]')
    expect(commit.locator("[data-subject]")).to_have_text(HOSTILE, **expect_ms())
    assert page.evaluate("window.pwned") is None  # commit text is text
    expect(commit).to_contain_text("by Lab")
    expect(commit.locator("ul[data-files]")).to_contain_text("configs/fleet.yaml")
    expect(commit.locator("pre[data-plan]")).to_contain_text("tb3-04")
    lab.write("configs/fleet.yaml", "robots: [\n")
    bad = lab.commit("Break fleet.yaml")
    page.goto(f"http://127.0.0.1:{ui.port}/revisions/{bad[:12]}")
    refused = page.locator("[data-commit] ul[data-diagnostics]")
    expect(refused).to_contain_text("configs/fleet.yaml", **expect_ms())
    page.goto(f"http://127.0.0.1:{ui.port}/revisions/{'0' * 40}")
    expect(page.locator('[data-commit="unknown"]')).to_contain_text("no such commit")
