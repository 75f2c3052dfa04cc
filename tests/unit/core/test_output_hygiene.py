"""No name or value from a file can reach the terminal raw, nor be taken as markup (pure part)."""

from __future__ import annotations

from robotconf.contract.textsafe import markdown_code, printable


def test_markdown_code_spans_hold_any_text() -> None:
    assert markdown_code("a|b") == "`a\\|b`"
    assert markdown_code("x`y") == "`` x`y ``"
    assert printable("tab\there\r\n\x7f\u2029") == "tab\\there\\r\\n\\x7f\\u2029"


def test_tree_and_catalog_text_is_never_rich_markup() -> None:
    from robotconf.configurator.tree import ActionNode, CapabilityTree, LogicNode, TaskNode
    from robotconf.workstation.cli.terminal import plain_text
    from robotconf.workstation.cli.views import capability_view, catalogue_view

    action = ActionNode("[bold]Act", True, [], [LogicNode("[red]logic", True, [])])
    tree = CapabilityTree(
        "[blink]cap", "ROS2", "gazebo", None, [TaskNode("T", ["x"], [[action]])], []
    )
    text = plain_text(capability_view(tree))
    assert text.startswith("[blink]cap  (platform ROS2")
    assert "✔ action [bold]Act (selected)" in text and "● [red]logic (chosen)" in text
    catalogue = plain_text(catalogue_view([("Tasks", [("[b]T: [x]", ["[i]\x1b[2J"])])]))
    assert "[b]T: [x]" in catalogue and "[i]\\x1b[2J" in catalogue and "\x1b" not in catalogue
