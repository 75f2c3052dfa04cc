"""A test brain that writes raw JSON lines to its agent's socket, without the brain library.

`python raw_brain.py PLAN.json {launch_request}`: connects to $ROBOTCONF_BRAIN_SOCKET and
follows the plan, a list of steps, then sleeps until it is stopped:

- `{"send": TEXT}`: TEXT and a newline, as UTF-8 (`{"send_hex": HEX}` for any bytes);
- `{"flood": TEXT, "count": N}`: TEXT and a newline, N times, as fast as the socket takes them
  (a full socket buffer drops the rest, as the library does);
- `{"sleep": SECONDS}`; `{"print": TEXT}` (to its log);
- `{"connect": N}`: N more connections, held open;
- `{"exit": CODE}`.

Placeholders in TEXT: `{digest}` (ROBOTCONF_DIGEST), `{pid}`.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time


def main() -> int:
    with open(sys.argv[1], encoding="utf-8") as file:
        plan = json.load(file)
    path = os.environ["ROBOTCONF_BRAIN_SOCKET"]
    fill = {"digest": os.environ.get("ROBOTCONF_DIGEST", ""), "pid": str(os.getpid())}
    main_sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    main_sock.connect(path)
    held = [main_sock]
    print("raw brain up", os.getpid(), flush=True)
    for step in plan:
        if "send" in step or "send_hex" in step:
            if "send" in step:
                data = step["send"]
                for name, value in fill.items():
                    data = data.replace("{" + name + "}", value)
                raw = data.encode("utf-8") + b"\n"
            else:
                raw = bytes.fromhex(step["send_hex"]) + b"\n"
            main_sock.sendall(raw)
        elif "flood" in step:
            raw = step["flood"].encode("utf-8") + b"\n"
            main_sock.setblocking(False)
            sent = 0
            for _ in range(step["count"]):
                try:
                    main_sock.send(raw)
                    sent += 1
                except BlockingIOError:
                    pass
            main_sock.setblocking(True)
            print("flooded", sent, flush=True)
        elif "print" in step:
            print(step["print"], flush=True)
        elif "sleep" in step:
            time.sleep(step["sleep"])
        elif "connect" in step:
            for _ in range(step["connect"]):
                extra = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                extra.connect(path)
                held.append(extra)
        elif "exit" in step:
            return int(step["exit"])
    while True:
        time.sleep(3600)


if __name__ == "__main__":
    sys.exit(main())
