"""The editor schemas as an editor uses them: the real yaml-language-server (installed by
./dev setup) flags a setting out of range, a wrong choice and an unknown logic setting for the
capability a scenario names, and finds nothing in a good scenario."""

from __future__ import annotations

import json
import os
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from robotconf.configurator.schemas import dump, generate
from tests.support.lab import ROOT, Lab

SERVER = ROOT / os.environ.get("ROBOTCONF_VENV", ".venv") / "yaml-language-server"
BINARY = SERVER / "node_modules" / ".bin" / "yaml-language-server"
TIMEOUT = 60.0
SCENARIO = "configs/scenarios/delivery-gazebo.yaml"


Diagnostics = list[dict[str, Any]]


def clean(found: Diagnostics) -> bool:
    return found == []


def flagged(found: Diagnostics) -> bool:
    return found != []


def saying(*words: str) -> Callable[[Diagnostics], bool]:
    """Diagnostics of which one's message has every word (in any case)."""
    return lambda found: any(all(w in d["message"].lower() for w in words) for d in found)


class LanguageServer:
    """A language server over stdio: requests with ids, notifications kept per method."""

    def __init__(self, root: Path) -> None:
        self.proc = subprocess.Popen(
            [str(BINARY), "--stdio"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
        )
        self.lock = threading.Condition()
        self.responses: dict[int, Any] = {}
        self.diagnostics: dict[str, list[dict[str, Any]]] = {}
        self._ident = 1  # request ids: 1 is initialize's
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        self.request(
            1,
            "initialize",
            {"processId": os.getpid(), "rootUri": root.as_uri(), "capabilities": {}},
        )
        self.wait(lambda: 1 in self.responses, "the initialize answer")
        self.notify("initialized", {})
        self.notify(
            "workspace/didChangeConfiguration",
            {"settings": {"yaml": {"validate": True, "hover": True, "schemas": {}}}},
        )

    def _send(self, message: dict[str, Any]) -> None:
        body = json.dumps(message).encode()
        assert self.proc.stdin is not None
        self.proc.stdin.write(b"Content-Length: %d\r\n\r\n" % len(body) + body)
        self.proc.stdin.flush()

    def request(self, ident: int, method: str, params: dict[str, Any]) -> None:
        self._send({"jsonrpc": "2.0", "id": ident, "method": method, "params": params})

    def notify(self, method: str, params: dict[str, Any]) -> None:
        self._send({"jsonrpc": "2.0", "method": method, "params": params})

    def _read(self) -> None:
        stream = self.proc.stdout
        assert stream is not None
        while True:
            length = 0
            while (line := stream.readline()) not in (b"\r\n", b""):
                if line.lower().startswith(b"content-length:"):
                    length = int(line.split(b":")[1])
            if not line:
                return
            message = json.loads(stream.read(length))
            if "method" in message and "id" in message:  # the server asks us something
                settings = {"validate": True, "hover": True, "schemas": {}}
                items = message.get("params", {}).get("items", [])
                answer: Any = [settings for _ in items] if items else None
                self._send({"jsonrpc": "2.0", "id": message["id"], "result": answer})
                continue
            with self.lock:
                if "id" in message:
                    self.responses[message["id"]] = message.get("result")
                elif message.get("method") == "textDocument/publishDiagnostics":
                    params = message["params"]
                    self.diagnostics[params["uri"]] = params["diagnostics"]
                self.lock.notify_all()

    def wait(self, done: Any, what: str) -> None:
        deadline = time.monotonic() + TIMEOUT
        with self.lock:
            while not done():
                left = deadline - time.monotonic()
                if left <= 0 or self.proc.poll() is not None:
                    raise AssertionError(f"yaml-language-server: no {what}")
                self.lock.wait(min(left, 0.5))

    def check(
        self, path: Path, text: str, version: int, until: Callable[[Diagnostics], bool]
    ) -> Diagnostics:
        """Diagnostics for `text` as the contents of `path`, opened (or changed) in the editor:
        the first the server publishes that are `until`'s. The server names no version in what
        it publishes, and may publish an earlier version's again late (it validates again when
        a schema has loaded): a wait for any publication could take that one."""
        uri = path.as_uri()
        with self.lock:
            self.diagnostics.pop(uri, None)
        if version == 1:
            document = {"uri": uri, "languageId": "yaml", "version": 1, "text": text}
            self.notify("textDocument/didOpen", {"textDocument": document})
        else:
            self.notify(
                "textDocument/didChange",
                {
                    "textDocument": {"uri": uri, "version": version},
                    "contentChanges": [{"text": text}],
                },
            )
        try:
            self.wait(lambda: uri in self.diagnostics and until(self.diagnostics[uri]), "")
        except AssertionError:
            raise AssertionError(
                f"yaml-language-server: no diagnostics as expected for {path.name} v{version}; "
                f"the last: {self.diagnostics.get(uri)}"
            ) from None
        return self.diagnostics[uri]

    def hover(self, path: Path, line: int, character: int) -> str:
        """The hover's Markdown at a position of an open document ("" when there is none)."""
        self._ident += 1
        ident = self._ident
        position = {"line": line, "character": character}
        self.request(
            ident,
            "textDocument/hover",
            {"textDocument": {"uri": path.as_uri()}, "position": position},
        )
        self.wait(lambda: ident in self.responses, "hover answer")
        answer = self.responses.pop(ident)
        return str(answer["contents"]["value"]) if answer else ""

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()


@pytest.fixture
def server(lab: Lab) -> Iterator[LanguageServer]:
    if not BINARY.exists():
        pytest.skip(f"yaml-language-server is not installed in {SERVER}: ./dev setup installs it")
    checked = lab.check()
    assert checked.ok, checked.errors
    (lab.root / "schemas").mkdir()
    for name, schema in generate(checked.repo).items():
        (lab.root / "schemas" / name).write_text(dump(schema), encoding="utf-8")
    started = LanguageServer(lab.root)
    try:
        yield started
    finally:
        started.close()


def test_the_editor_flags_bad_setting_values_for_the_scenario_s_capability(
    lab: Lab, server: LanguageServer
) -> None:
    path = lab.path(SCENARIO)
    good = lab.read(SCENARIO)
    assert good.startswith("# yaml-language-server: $schema=../../schemas/scenario.schema.json")
    assert server.check(path, good, 1, clean) == []
    too_fast = good.replace("max_linear_speed: 0.2", "max_linear_speed: 99")
    found = server.check(path, too_fast, 2, saying("maximum", "0.26"))
    speed_line = next(n for n, line in enumerate(too_fast.splitlines()) if "99" in line)
    assert {d["range"]["start"]["line"] for d in found} == {speed_line}
    unknown = good.replace("move_speed: 0.1", "move_sped: 0.1")
    server.check(path, unknown, 3, saying("move_sped"))  # or it fails, with the last ones


def test_the_editor_takes_one_logic_or_a_list_of_distinct_ones(
    lab: Lab, server: LanguageServer
) -> None:
    path = lab.path("configs/capabilities/turtlebot3-follow-either.yaml")
    good = lab.read("configs/capabilities/turtlebot3-follow-either.yaml")
    both = "Follow: [follow_with_poses, follow_with_bluetooth]"
    assert both in good
    assert server.check(path, good, 1, clean) == []
    one = good.replace(both, "Follow: follow_with_bluetooth")
    assert server.check(path, one, 2, clean) == []
    twice = good.replace(both, "Follow: [follow_with_poses, follow_with_poses]")
    server.check(path, twice, 3, saying("duplicate"))
    unknown = good.replace(both, "Follow: [follow_with_poses, follow_by_smell]")
    found = server.check(path, unknown, 4, flagged)
    line = next(n for n, text in enumerate(unknown.splitlines()) if "follow_by_smell" in text)
    assert found and {d["range"]["start"]["line"] for d in found} == {line}, found
    empty = good.replace(both, "Follow: []")
    assert server.check(path, empty, 5, flagged) != []


def test_the_editor_offers_only_rules_a_lab_may_tune(lab: Lab, server: LanguageServer) -> None:
    path = lab.root / ".robotconf.yaml"
    good = (ROOT / ".robotconf.yaml").read_text(encoding="utf-8")
    assert good.startswith("# yaml-language-server: $schema=schemas/rule-configuration.schema")
    assert server.check(path, good, 1, clean) == []
    fixed = good.replace("RC608: off", "RC501: off")  # ids are topic levels: never tuned
    found = server.check(path, fixed, 2, flagged)
    line = next(n for n, text in enumerate(fixed.splitlines()) if "RC501" in text)
    assert found and {d["range"]["start"]["line"] for d in found} == {line}, found
    loud = good.replace("RC608: off", "RC608: loud")
    assert server.check(path, loud, 3, flagged) != []


def test_hovering_a_setting_shows_its_unit_range_default_and_choices(
    lab: Lab, server: LanguageServer
) -> None:
    """A robot setting and a logic setting of the scenario's capability, hovered at their keys:
    their own name, unit, range, choices and default, not the title of the object they are in."""
    path = lab.path(SCENARIO)
    text = lab.read(SCENARIO).replace(
        "robot_settings: {max_linear_speed: 0.2,",
        "robot_settings: {max_linear_speed: 0.2, camera_resolution: 640x480,",
    )
    assert server.check(path, text, 1, clean) == []
    lines = text.splitlines()

    def hover(key: str) -> str:
        line = next(n for n, words in enumerate(lines) if f"{key}:" in words)
        return server.hover(path, line, lines[line].index(key) + 1)

    speed = hover("max_linear_speed")
    assert speed.startswith("#### max\\_linear\\_speed (m/s)"), speed
    for fact in ("Waffle Pi's published limit", "unit: `m/s`", "range: `0 to 0.26`"):
        assert fact in speed, speed
    assert "default: `0.22`" in speed and "turtlebot3-waffle-pi" in speed
    assert "Robot Settings" not in speed
    camera = hover("camera_resolution")
    assert '`"320x240", "640x480", "1280x720"`' in camera and 'default: `"640x480"`' in camera
    move = hover("move_speed")
    assert move.startswith("#### move\\_speed (m/s)") and "default: `0.15`" in move, move
    assert "logic follow_with_poses (action Follow)" in move and "Logic Settings" not in move
