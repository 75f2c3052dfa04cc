"""The agent's inbox: events in order, a wake-up from other threads, none after close."""

from __future__ import annotations

import os
import select
import threading

from robotconf.agent.events import BrainExited, Inbox, Shutdown


def readable(inbox: Inbox, timeout: float) -> bool:
    ready, _, _ = select.select([inbox.fileno()], [], [], timeout)
    return bool(ready)


def test_a_put_from_another_thread_wakes_the_loop() -> None:
    inbox = Inbox()
    try:
        assert not readable(inbox, 0)
        threading.Thread(target=inbox.put, args=(Shutdown("SIGTERM"),)).start()
        assert readable(inbox, 10)
        inbox.clear_wakeups()
        assert not readable(inbox, 0)
        assert inbox.pop() == Shutdown("SIGTERM")
        assert inbox.pop() is None and not inbox
    finally:
        inbox.close()


def test_events_of_the_loop_itself_need_no_wake_up_and_keep_their_order() -> None:
    inbox = Inbox()
    try:
        inbox.put_local(BrainExited(10, 0))
        inbox.put(Shutdown("SIGINT"))
        inbox.put_local(BrainExited(11, 1))
        assert inbox
        assert [inbox.pop(), inbox.pop(), inbox.pop()] == [
            BrainExited(10, 0),
            Shutdown("SIGINT"),
            BrainExited(11, 1),
        ]
        inbox.clear_wakeups()
        inbox.put_local(BrainExited(12, 0))
        assert not readable(inbox, 0)
    finally:
        inbox.close()


def test_after_close_a_late_wake_up_writes_nothing() -> None:
    inbox = Inbox()
    write_fd = inbox._write_fd
    inbox.close()
    inbox.close()  # twice is harmless
    # The lowest free numbers come back at once: the new pipe's write end is the old one's.
    r, w = os.pipe()
    try:
        assert w == write_fd
        inbox.wake()
        inbox.put(Shutdown("SIGTERM"))
        ready, _, _ = select.select([r], [], [], 0)
        assert not ready  # nothing was written into a pipe that is not the inbox's
    finally:
        os.close(r)
        os.close(w)
