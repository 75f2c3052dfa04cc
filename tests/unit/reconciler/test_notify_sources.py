"""Where receiver URLs come from: --notify, a --notify-file's lines and $ROBOTCONF_NOTIFY,
used together, each URL once; every one named by where it was given (errors never quote it)."""

from __future__ import annotations

import pytest

from robotconf.reconciler.notify import given_urls, notify_file_urls, parse_receiver


def test_a_file_gives_one_url_a_line_skipping_comments_and_blank_lines() -> None:
    text = "# receivers\n\n  http://a.lab/hook  \n\t\nslack:https://hooks.example/T/B/X\n#http://off/\n"
    found = notify_file_urls(text, "urls")
    assert [(u.text, u.where) for u in found] == [
        ("http://a.lab/hook", "--notify-file urls:3"),
        ("slack:https://hooks.example/T/B/X", "--notify-file urls:5"),
    ]
    assert "hooks.example" not in repr(found)  # a URL is never shown by a repr


def test_flags_file_and_environment_are_a_union_each_url_once_in_that_order() -> None:
    from_file = notify_file_urls("http://b.lab/\nhttp://a.lab/\n", "f")
    given = given_urls(["http://a.lab/"], from_file, " http://c.lab/\n http://b.lab/ ")
    assert [(u.text, u.where) for u in given] == [
        ("http://a.lab/", "--notify #1"),
        ("http://b.lab/", "--notify-file f:1"),
        ("http://c.lab/", "$ROBOTCONF_NOTIFY #1"),
    ]
    assert given_urls([], [], None) == [] and given_urls([], [], "  \n") == []


def test_an_error_names_where_the_url_was_given_never_the_url() -> None:
    [url] = notify_file_urls("\n\nftp://user:hunter2@host/x\n", "/etc/robotconf/urls")
    with pytest.raises(ValueError) as refused:
        parse_receiver(url.text, 1, url.where)
    assert str(refused.value).startswith("--notify-file /etc/robotconf/urls:3 must be an http")
    assert "hunter2" not in str(refused.value)
