"""The rollout box with `rollout.verify`: the wave's evidence against what it must show, its
verdict as text, a dry run said, who decided by hand, and the commands when it is paused on
inconclusive evidence; escaped, no inline style."""

from __future__ import annotations

import re

from robotconf.contract.wire import RolloutStatus, WaveVerification
from robotconf.workstation.ui.auth import ANONYMOUS
from robotconf.workstation.ui.model import FleetQuery
from robotconf.workstation.ui.pages import evidence_html, fleet_page, rollout_box
from robotconf.workstation.ui.text import when
from tests.unit.ui.fleets import NOW, fleet, reconciler, snapshot
from tests.unit.ui.test_pages import assert_no_inline_code

EVIDENCE = WaveVerification(
    goals=14,
    min_goals=20,
    succeeded=13,
    failed=1,
    canceled=2,
    robots=3,
    rate=13 / 14,
    success_rate=0.9,
    deadline=NOW + 600,
    message="14 of 20 goals, 93% ≥ 90%",
)


def rollout(
    found: WaveVerification | None, state: str = "Progressing", message: str = ""
) -> RolloutStatus:
    return RolloutStatus.model_validate(
        {
            "revision": "c" * 40,
            "stable_revision": "d" * 40,
            "state": state,
            "wave": 1,
            "waves": 3,
            "wave_name": "half",
            "healthy": ["r1"],
            "counts": {"healthy": 1},
            "verification": found,
            "message": message,
        }
    )


def box(status: RolloutStatus) -> str:
    return rollout_box(snapshot(fleet([], reconciler(rollout=status))))


def facts(html: str) -> dict[str, str]:
    """The evidence's <dt>/<dd> pairs, their text without tags."""
    found = re.search(r"<div class=\"evidence\".*?</div>", html)
    assert found is not None
    pairs = re.findall(r"<dt>(.*?)</dt><dd>(.*?)</dd>", found.group())
    return {name: re.sub(r"<[^>]+>", "", value) for name, value in pairs}


def test_gathering_evidence_shows_goals_and_rate_against_what_is_asked() -> None:
    html = box(rollout(EVIDENCE, message="wave 'half' verifying: 14 of 20 goals, 93% ≥ 90%"))
    assert '<div class="evidence" data-evidence="Gathering">' in html
    assert "<h3>Evidence: Gathering</h3>" in html
    assert facts(html) == {
        "Verdict": "Gathering",
        "Goals": "14 of at least 20 (13 succeeded, 1 failed, 2 canceled) from 3 robots",
        "Success rate": "93% (at least 90%)",
        "Judged by": when(NOW + 600),  # the deadline: by then too few goals is Inconclusive
    }
    # Before the robot groups: what the wave must show is read with where it stands.
    assert html.index("data-evidence") < html.index('class="groups"')
    assert "data-verify-commands" not in html and "Dry run" not in html
    assert_no_inline_code(html)


def test_without_verify_the_box_has_no_evidence() -> None:
    assert "evidence" not in box(rollout(None)).lower()


def test_a_comparison_with_stable_and_critical_codes_are_shown() -> None:
    found = EVIDENCE.model_copy(
        update={
            "verdict": "Failed",
            "stable_rate": 0.97,
            "stable_goals": 40,
            "max_drop": 0.1,
            "critical": ["COLLISION"],
        }
    )
    shown = facts(evidence_html(found, paused=False))
    assert shown["Verdict"] == "Failed"
    assert shown["Stable revision"] == "97% over 40 goals (at most 10% below it)"
    assert shown["Critical codes"] == "COLLISION"
    assert "Judged by" not in shown  # judged already
    no_rate_yet = EVIDENCE.model_copy(update={"max_drop": 0.1})
    assert facts(evidence_html(no_rate_yet, paused=False))["Stable revision"] == (
        "no rate to compare with yet (at most 10% below it)"
    )


def test_a_rate_without_a_threshold_is_the_rate_alone() -> None:
    found = EVIDENCE.model_copy(update={"success_rate": None, "rate": 0.5, "robots": 1})
    shown = facts(evidence_html(found, paused=False))
    assert shown["Success rate"] == "50%" and shown["Goals"].endswith("from 1 robot")


def test_paused_on_inconclusive_evidence_names_the_commands() -> None:
    found = EVIDENCE.model_copy(update={"verdict": "Inconclusive"})
    html = box(rollout(found, "Paused", message="wave 'half' inconclusive"))
    assert 'data-rollout-state="Paused"' in html and 'data-evidence="Inconclusive"' in html
    commands = re.search(r"<p data-verify-commands>(.*?)</p>", html)
    assert commands is not None
    assert "<code>robotconf rollout resume</code> passes the wave" in commands.group(1)
    assert "<code>robotconf rollout abort</code> fails it" in commands.group(1)
    assert_no_inline_code(html)
    # Paused by rollout.paused, or a wave an operator already resumed: nothing to run.
    for other in (
        rollout(EVIDENCE.model_copy(update={"verdict": "Successful"}), "Paused"),
        rollout(found.model_copy(update={"decided_by": "ada"}), "Paused"),
        rollout(found, "Progressing"),
    ):
        assert "data-verify-commands" not in box(other)


def test_a_dry_run_and_who_decided_by_hand_are_said() -> None:
    shadow = EVIDENCE.model_copy(update={"verdict": "Failed", "dry_run": True})
    html = box(rollout(shadow))
    assert '<div class="evidence" data-evidence="Failed" data-dry-run>' in html
    assert "Dry run: judged and shown, not gating" in html
    resumed = EVIDENCE.model_copy(update={"verdict": "Inconclusive", "decided_by": "ada"})
    assert facts(evidence_html(resumed, paused=False))["Resumed by"] == "ada"
    aborted = EVIDENCE.model_copy(update={"verdict": "Failed", "decided_by": "bo"})
    assert facts(evidence_html(aborted, paused=False))["Aborted by"] == "bo"


def test_evidence_from_the_broker_is_escaped_on_the_fleet_page() -> None:
    found = EVIDENCE.model_copy(
        update={"verdict": "Failed", "decided_by": "<script>x</script>", "critical": ["<b>"]}
    )
    status = rollout(found, "RolledBack")
    page = fleet_page(snapshot(fleet([], reconciler(rollout=status))), FleetQuery(), ANONYMOUS)
    assert "&lt;script&gt;x&lt;/script&gt;" in page and "<script>x" not in page
    assert "&lt;b&gt;" in page and "<b>" not in page
    assert_no_inline_code(page)
