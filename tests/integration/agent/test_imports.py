"""The robot side installs only paho-mqtt, pydantic and PyYAML: the agent must not need more."""

from __future__ import annotations

import json
import subprocess
import sys

SERVER_ONLY = ["git", "watchfiles", "amqtt", "readmodel", "reconciler"]
# Loaded only when agent.yaml names a public key: an agent without one stays small.
ON_DEMAND = ["cryptography"]


def test_agent_imports_nothing_from_the_server_side() -> None:
    code = (
        "import json, sys\n"
        "import robotconf.agent.cli, robotconf.agent.runtime, robotconf.agent.standin_brain\n"
        "import robotconf.brain\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    loaded = set(json.loads(result.stdout))
    assert "robotconf.agent.runtime" in loaded and "paho.mqtt.client" in loaded  # the probe works
    for name in SERVER_ONLY + ON_DEMAND:
        assert name not in loaded, f"the agent imports {name}"
        assert not any(m.startswith(name + ".") for m in loaded), f"the agent imports {name}.*"
