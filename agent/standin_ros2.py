"""A stand-in `ros2` for demos and tests: `ros2 topic|service|action list [-t]` as ros2cli prints
them, from a JSON graph file named by $STANDIN_ROS2_GRAPH; it can hang, fail or print garbage.
"""

# The graph: {"topics": [{"name": "/scan", "type": "sensor_msgs/msg/LaserScan"}, ...],
# "services": [...], "actions": [...], "mode": "ok"}. A name listed twice with two types is
# printed once with both (`/x [a/msg/A, b/msg/B]`). `$VAR` in a name is the variable of the
# environment it runs with (e.g. `/domain_$ROS_DOMAIN_ID`). `mode` is `ok`, `fail` (exit 1, a
# line on stderr), `hang` (sleep until killed), `garbage` (lines that are no list), or a
# mapping verb -> mode (`{"action": "fail"}`). With $STANDIN_ROS2_LOG set, each run appends
# `PID VERB MODE` to that file. Standard library only: it starts fast.

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

GRAPH_ENV = "STANDIN_ROS2_GRAPH"
LOG_ENV = "STANDIN_ROS2_LOG"
KIND_OF_VERB = {"topic": "topics", "service": "services", "action": "actions"}
USAGE = "usage: ros2 {topic,service,action} list [-t]"


def lines_of(graph: dict[str, object], verb: str, show_types: bool) -> list[str]:
    """What ros2cli's `list` verb prints: `name [type, type]` per name (sorted by name, as
    rclpy returns them), or the bare name without -t."""
    entries = graph.get(KIND_OF_VERB[verb], [])
    assert isinstance(entries, list)
    types: dict[str, list[str]] = {}
    for entry in entries:
        name = os.path.expandvars(str(entry["name"]))
        types.setdefault(name, []).append(str(entry["type"]))
    out = []
    for name in sorted(types):
        # ros2topic/verb/list.py: msg += ' [{topic_types_formatted}]', types joined by ', '.
        out.append(f"{name} [{', '.join(types[name])}]" if show_types else name)
    return out


def _mode(graph: dict[str, object], verb: str) -> str:
    mode = graph.get("mode", "ok")
    if isinstance(mode, dict):
        mode = mode.get(verb, "ok")
    return str(mode)


def main(argv: list[str]) -> int:
    if len(argv) < 2 or argv[0] not in KIND_OF_VERB or argv[1] != "list":
        print(USAGE, file=sys.stderr)
        return 2
    verb, show_types = argv[0], "-t" in argv[2:] or "--show-types" in argv[2:]
    path = os.environ.get(GRAPH_ENV)
    if not path:
        print(f"stand-in ros2: set {GRAPH_ENV} to a graph JSON file", file=sys.stderr)
        return 2
    graph = json.loads(Path(path).read_text(encoding="utf-8"))
    mode = _mode(graph, verb)
    calls = os.environ.get(LOG_ENV)
    if calls:
        with open(calls, "a", encoding="utf-8") as out:
            out.write(f"{os.getpid()} {verb} {mode}\n")
    if mode == "fail":
        print("!rclpy.ok(): the stand-in was told to fail", file=sys.stderr)
        return 1
    if mode == "hang":
        while True:
            time.sleep(3600)
    if mode == "garbage":
        sys.stdout.write("Traceback? \x1b[31mnot a list\x1b[0m\n/odom geometry_msgs/msg/Twist\n")
        return 0
    sys.stdout.write("".join(line + "\n" for line in lines_of(graph, verb, show_types)))
    return 0


def install(bin_dir: Path, python: str = sys.executable) -> Path:
    """Writes an executable `ros2` into `bin_dir` that runs this module with `python`."""
    root = Path(__file__).resolve().parents[1]
    bin_dir.mkdir(parents=True, exist_ok=True)
    shim = bin_dir / "ros2"
    shim.write_text(
        "#!/bin/sh\n"
        f'PYTHONPATH="{root}${{PYTHONPATH:+:$PYTHONPATH}}" '
        f'exec "{python}" -m robotconf.agent.standin_ros2 "$@"\n',
        encoding="utf-8",
    )
    shim.chmod(0o755)
    return shim


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
