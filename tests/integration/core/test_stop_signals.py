"""Stop signals of the long-running commands (contract/lifecycle.py), in a process of their own:
a SIGTERM landing wherever the main thread is must still stop it."""

from __future__ import annotations

import subprocess
import sys
import textwrap

# The main thread holds the lock of the very Event the stop sets, as it does for a few
# bytecodes of every `stop.wait()`, when SIGTERM arrives: the handler runs right there, on it.
HELD_WHEN_SIGNALLED = textwrap.dedent(
    """
    import os, signal, sys, threading
    from robotconf.contract.lifecycle import on_stop_signals

    stop = threading.Event()
    called = threading.Event()
    on_stop_signals(stop, called.set)
    with stop._cond:
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(100_000):  # bytecodes: the Python-level handler runs among them
            pass
    sys.exit(0 if stop.wait(20) and called.wait(20) else 3)
    """
)


def test_a_stop_signal_while_the_main_thread_holds_the_stop_event_s_lock_stops_it() -> None:
    # A handler that set the Event itself waited for the lock its own thread held: forever.
    done = subprocess.run(
        [sys.executable, "-c", HELD_WHEN_SIGNALLED], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr


def test_a_second_stop_signal_calls_again_and_a_second_hangup_does_not() -> None:
    script = textwrap.dedent(
        """
        import os, signal, sys, threading, time
        from robotconf.contract.lifecycle import on_stop_signals

        stop, again = threading.Event(), threading.Event()
        on_stop_signals(stop, again=again.set)
        os.kill(os.getpid(), signal.SIGHUP)
        assert stop.wait(20)
        os.kill(os.getpid(), signal.SIGHUP)  # a closed terminal's second SIGHUP: no hurry
        time.sleep(0.5)
        assert not again.is_set()
        os.kill(os.getpid(), signal.SIGINT)  # a second Ctrl-C: at once
        sys.exit(0 if again.wait(20) else 3)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
