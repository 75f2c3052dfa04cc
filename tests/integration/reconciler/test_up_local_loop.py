"""The whole local loop of `robotconf up`, as a newcomer tries it: `up --ui` makes its operator
token once (0600) and prints a link that logs a browser in (robots' logs, restarts); up's
agents report interfaces through the stand-in `ros2`, so drift and `draft` work; a robot made
busy with its hold file says so, and a restart waits for it."""

from __future__ import annotations

import http.client
import json
import re
import signal
import stat
import subprocess
import time
from pathlib import Path
from typing import Any
from urllib.parse import urlencode, urlsplit

from robotconf.contract.mqtt import Connection
from robotconf.workstation.broker import free_port
from tests.integration.reconciler.test_up import TWO_ROBOTS, in_sync, start_up, up_folder
from tests.integration.reconciler.test_up_desk import desk
from tests.support.fleet import GitLab, robotconf_argv
from tests.support.watch import FleetWatch, wait_for

FORM = "application/x-www-form-urlencoded"
LINK = re.compile(r"ui: log in as its operator \(robots' logs, restarts\) with (http://\S+)")


def ask(port: int, method: str, path: str, body: str | None = None, **headers: str) -> Any:
    """(code, headers, body) of one request to the UI on loopback."""
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    try:
        named = {name.replace("_", "-"): value for name, value in headers.items()}
        connection.request(method, path, body=body, headers=named)
        response = connection.getresponse()
        text = response.read().decode("utf-8", "replace")
        return response.status, dict(response.getheaders()), text
    finally:
        connection.close()


def first_log_lines(port: int, robot: str, cookie: str, until: str) -> str:
    """The robot's log stream, read until `until` is in it (or 30 s pass)."""
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    try:
        connection.request("GET", f"/robots/{robot}/logs", headers={"Cookie": cookie})
        response = connection.getresponse()
        assert response.status == 200, response.read()[:500]
        assert response.getheader("Content-Type", "").startswith("text/event-stream")
        seen = ""
        deadline = time.monotonic() + 30
        while until not in seen and time.monotonic() < deadline:
            line = response.fp.readline()
            if not line:
                break
            seen += line.decode("utf-8", "replace")
        return seen
    finally:
        connection.close()


def status_rows(lab: GitLab) -> dict[str, dict[str, Any]] | None:
    """`robotconf status --json`'s robots, as the desk reads them from up's broker."""
    done = desk(lab, "status", "--json")
    if not done.stdout.strip():
        return None
    return {row["robot_id"]: row for row in json.loads(done.stdout)["robots"]}


@TWO_ROBOTS
def test_up_ui_logs_its_operator_in_with_the_link_it_prints(lab: GitLab, tmp_path: Path) -> None:
    port = free_port("127.0.0.1")
    up = start_up(lab, tmp_path, "--ui", f"127.0.0.1:{port}")
    token_file = Path(up_folder(lab)) / "ui.token"
    try:
        in_sync(up, lab)
        assert stat.S_IMODE(token_file.stat().st_mode) == 0o600
        token = token_file.read_text().strip()
        found = LINK.search(up.output())
        assert found, up.output()
        link = urlsplit(found.group(1))
        assert link.port == port and link.path == "/login" and link.query == f"token={token}"
        assert "(the token, made now, is in .robotconf/up/ui.token, mode 0600)" in up.output()

        # A viewer, a wrong token and a link followed from another site act on nothing.
        assert ask(port, "GET", "/robots/tb3-01/logs")[0] == 401
        assert ask(port, "POST", "/robots/tb3-01/restart", "", Content_Type=FORM)[0] == 401
        assert ask(port, "GET", "/login?token=not-the-token-0000000000")[0] == 401
        foreign = ask(port, "GET", f"/login?{link.query}", Sec_Fetch_Site="cross-site")
        assert foreign[0] == 403 and "Set-Cookie" not in foreign[1]

        code, headers, _ = ask(port, "GET", f"/login?{link.query}")
        assert code == 303 and headers["Location"] == "/", headers
        cookie = headers["Set-Cookie"].split(";")[0]
        page = ask(port, "GET", "/robots/tb3-02", Cookie=cookie)[2]
        assert 'href="/robots/tb3-02/restart"' in page, page[:2000]
        assert "stand-in brain for tb3-01" in first_log_lines(
            port, "tb3-01", cookie, "stand-in brain for tb3-01"
        )

        confirm = ask(port, "GET", "/robots/tb3-02/restart", Cookie=cookie)
        csrf = re.search(r'name="csrf" value="([^"]+)"', confirm[2])
        assert confirm[0] == 200 and csrf, confirm[2][:2000]
        form = urlencode({"csrf": csrf.group(1)})
        posted = ask(port, "POST", "/robots/tb3-02/restart", form, Content_Type=FORM, Cookie=cookie)
        assert posted[0] == 303, posted[2][:2000]

        def restarted_by_ui() -> bool:
            rows = status_rows(lab)
            restart = rows["tb3-02"]["restart"] if rows else None
            return restart is not None and restart["requested_by"] == "ui.cookie"

        wait_for(restarted_by_ui, "tb3-02 restarted by the browser's operator")
    finally:
        assert up.stop(signal.SIGINT, timeout=60) == 0, up.output()

    # The next `up --ui` keeps the token: the same link logs in again.
    again = start_up(lab, tmp_path, "--ui", f"127.0.0.1:{port}", log="again.out")
    try:
        wait_for(lambda: LINK.search(again.output()), "the second up's login link")
        assert "(the token, the same as before, is in" in again.output()
        assert token_file.read_text().strip() == token
        wait_for(
            lambda: ask(port, "GET", f"/login?{link.query}")[0] == 303, "the same link to log in"
        )
    finally:
        assert again.stop(signal.SIGINT, timeout=60) == 0, again.output()
    assert "Traceback" not in up.output() + again.output()


def test_up_ui_refuses_a_token_file_others_may_read(lab: GitLab) -> None:
    token_file = Path(up_folder(lab)) / "ui.token"
    token_file.parent.mkdir(parents=True)
    token_file.write_text("an-operator-token-that-others-read\n")
    token_file.chmod(0o644)
    done = subprocess.run(
        robotconf_argv("up", "--repo", str(lab.root), "--ui"),
        capture_output=True,
        text=True,
        timeout=120,
        cwd=lab.root,
    )
    assert done.returncode == 2, done.stdout + done.stderr
    assert "up's operator token file" in done.stderr
    assert "may be read by others (mode 0644): chmod 600" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (Path(up_folder(lab)) / "tb3-01").exists()  # nothing started


def test_up_s_robots_report_interfaces_drift_and_busy(lab: GitLab, tmp_path: Path) -> None:
    up = start_up(lab, tmp_path)
    folder = Path(up_folder(lab))
    try:
        in_sync(up, lab)
        assert "`touch .robotconf/up/tb3-01/brain.hold` makes tb3-01 busy" in up.output()

        def reported() -> dict[str, dict[str, Any]] | None:
            rows = status_rows(lab)
            ros2 = [r for robot, r in (rows or {}).items() if robot != "tb3-05"]
            return rows if ros2 and all(r["interfaces"] == "reported" for r in ros2) else None

        rows = wait_for(reported, "every ROS 2 robot's interfaces reported")
        assert all(row["drift"] == [] for row in rows.values()), rows
        assert rows["tb3-05"]["interfaces"] == "unknown"  # ROS 1 (noetic): none reported

        # tb3-04 loses its Nav2 action: drift, as the docs show it.
        graph_file = folder / "tb3-04" / "ros2-graph.json"
        graph = json.loads(graph_file.read_text())
        graph["actions"] = []
        graph_file.write_text(json.dumps(graph))

        def drifted() -> list[dict[str, Any]] | None:
            rows = status_rows(lab)
            return rows["tb3-04"]["drift"] if rows and rows["tb3-04"]["drift"] else None

        drift = wait_for(drifted, "tb3-04 to drift")
        assert [(d["mapping"], d["found_type"]) for d in drift] == [("navigate_to_pose", None)]
        shown = desk(lab, "status").stdout
        assert "tb3-04 lacks /navigate_to_pose (nav2_msgs/action/NavigateToPose)" in shown, shown
        drafted = desk(
            lab, "draft", "tb3-04", "--platform", "ROS2", "--template", "tb3-04-measured"
        )
        assert drafted.returncode == 0, drafted.stdout + drafted.stderr
        assert "odometry" in drafted.stdout and "wrote models/platforms/ROS2" in drafted.stdout

        # tb3-02 made busy: its agent says so, and a restart waits for it.
        desk_file = json.loads((lab.root / ".robotconf" / "up" / "desk.json").read_text())
        login = Connection(
            desk_file["broker"], desk_file["username"], Path(desk_file["password_file"])
        )
        watch = FleetWatch(login)
        try:
            hold = folder / "tb3-02" / "brain.hold"
            hold.touch()
            watch.wait_for("tb3-02", lambda status: status.busy, "busy, as its hold file says")
            restart = desk(lab, "restart", "tb3-02")
            assert restart.returncode == 0 and "deferred" in restart.stdout, restart.stdout
            hold.unlink()
            watch.wait_for("tb3-02", lambda status: not status.busy, "no longer busy")
        finally:
            watch.close()
    finally:
        assert up.stop(signal.SIGINT, timeout=60) == 0, up.output()
    assert "Traceback" not in up.output()
