"""The parent-death SIGHUP (agent/parent_death.py), in a process of its own: however many the
kernel sends (one per thread of a killed `up`), the agent's stop runs once."""

from __future__ import annotations

import subprocess
import sys
import textwrap

# The second SIGHUP is sent at the first C call inside the first one's handler (a profile
# hook sends it): Python runs the handler again right after that call, nested, before the
# first one goes on. That is where a flag tested and then set let two stops through.
NESTED = textwrap.dedent(
    """
    import os, signal, sys
    from robotconf.agent.parent_death import die_with_parent

    calls = []
    signal.signal(signal.SIGTERM, lambda signum, frame: calls.append(signum))
    assert die_with_parent(os.getppid())
    sent = []

    def profile(frame, event, arg):
        if event == "c_call" and frame.f_code.co_name == "once" and not sent:
            sent.append(True)
            os.kill(os.getpid(), signal.SIGHUP)

    sys.setprofile(profile)
    os.kill(os.getpid(), signal.SIGHUP)
    for _ in range(1_000):
        pass
    sys.setprofile(None)
    sys.exit(0 if sent and calls == [signal.SIGHUP] else 3)
    """
)


def test_a_hangup_landing_inside_the_first_one_s_handler_stops_the_agent_once() -> None:
    done = subprocess.run(
        [sys.executable, "-c", NESTED], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
