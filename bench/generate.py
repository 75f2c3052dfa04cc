"""Generate a lab-sized, entirely valid Robot Configurator repository for benchmarks.

The default size is a large lab: 2 platforms with 3 mapping schemes each, 20 robot templates,
200 actions of 3 logics, 40 tasks, 10 environments (50 Location objects and 3 knowledge sets
each), 200 capability configurations, 1,000 scenarios and 10,000 robots in `fleet.yaml`.

Everything generated is valid by construction, so that a benchmark measures a clean
validation of the whole repository: every reference resolves, every selected logic's mappings
are in the capability's robot template and bound by its mapping scheme, every `requires` is
selected, every goal's task is achievable by the selected actions, goal locations are Location
objects of the scenario's environment, all settings are within their bounds, and every
robot has its own ROS 2 namespace (the schemes' names are relative), so no two robots of one
world share a topic.

`--shape namespaced` writes the lab the project recommends at scale: every robot in a namespace
of its own (nested under its site, `site_3/robot_00042`), robot templates that list every
mapping of their platform, logics that need more of them, and schemes that name them relative
(`ns0/sensor_007`) or under `{namespace}/`: each request binds about 40 mappings, each resolved
in its robot's namespace (about 6.6 KB a request, against about 3 KB in the default shape).

The output is deterministic for a given seed, shape and set of sizes. YAML is written as plain text
(no YAML library needed), each file with the editor modeline pointing at `schemas/`.

    python bench/generate.py [TARGET] [--robots N] [--scenarios N] ... [--seed S]
                             [--shape default|namespaced] [--git]

TARGET defaults to bench/out/lab. An existing TARGET is replaced only when it is empty or was
written by this generator (it holds `.bench-generator.json`).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

MARKER = ".bench-generator.json"
DEFAULT_TARGET = Path(__file__).resolve().parent / "out" / "lab"

BASE_MAPPINGS = ("cmd_vel", "odometry", "scan", "imu")
MAPPING_KINDS = ("topic", "topic", "topic", "service", "action_client")
ENV_TYPES = ("Gazebo", "2D", "Real")
SHAPES = ("default", "namespaced")


@dataclass(frozen=True)
class Sizes:
    """How much to generate; the defaults are the lab-sized benchmark."""

    robots: int = 10_000
    scenarios: int = 1_000
    capabilities: int = 200
    actions: int = 200
    logics: int = 3
    tasks: int = 40
    templates: int = 20
    environments: int = 10
    locations: int = 50
    platforms: int = 2
    schemes: int = 3
    mappings: int = 60
    seed: int = 1


# ---------------------------------------------------------------- YAML text helpers


def q(text: str) -> str:
    """A YAML double-quoted scalar (JSON strings are valid YAML)."""
    return json.dumps(text)


def num(value: float) -> str:
    """A float that YAML 1.1 resolvers (PyYAML) read back as a float: always with a dot."""
    text = f"{value:.4f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def scalar(value: bool | int | float | str) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return num(value)
    return q(value)


def flow(items: list[str]) -> str:
    return "[" + ", ".join(items) + "]"


def modeline(depth: int, kind: str) -> str:
    return f"# yaml-language-server: $schema={'../' * depth}schemas/{kind}.schema.json\n"


# ---------------------------------------------------------------- the catalogue in memory


@dataclass
class Setting:
    type: str
    default: bool | int | float | str
    minimum: float | None = None
    maximum: float | None = None
    choices: list[str] | None = None
    unit: str | None = None

    def yaml(self) -> str:
        parts = [f"type: {self.type}", f"default: {scalar(self.default)}"]
        if self.minimum is not None:
            parts.append(f"minimum: {scalar(self.minimum)}")
        if self.maximum is not None:
            parts.append(f"maximum: {scalar(self.maximum)}")
        if self.choices is not None:
            parts.append("choices: " + flow([q(c) for c in self.choices]))
        if self.unit is not None:
            parts.append(f"unit: {q(self.unit)}")
        return "{" + ", ".join(parts) + "}"

    def pick(self, rng: random.Random) -> bool | int | float | str:
        """A valid value, different from the default where possible."""
        if self.type == "number":
            assert self.minimum is not None and self.maximum is not None
            return round(rng.uniform(self.minimum, self.maximum), 3)
        if self.type == "integer":
            assert self.minimum is not None and self.maximum is not None
            return rng.randint(int(self.minimum), int(self.maximum))
        if self.type == "boolean":
            return not self.default
        if self.type == "enum":
            assert self.choices
            return rng.choice(self.choices)
        return f"value-{rng.randint(0, 999)}"


def random_setting(rng: random.Random) -> Setting:
    kind = rng.choice(("number", "number", "integer", "boolean", "enum", "string"))
    if kind == "number":
        low = round(rng.uniform(0.0, 1.0), 2)
        high = round(low + rng.uniform(0.1, 5.0), 2)
        return Setting("number", round((low + high) / 2, 3), low, high, unit="m")
    if kind == "integer":
        low = rng.randint(-10, 5)
        high = low + rng.randint(1, 100)
        return Setting("integer", rng.randint(low, high), float(low), float(high))
    if kind == "boolean":
        return Setting("boolean", rng.random() < 0.5)
    if kind == "enum":
        choices = rng.sample(["slow", "normal", "fast", "eco", "safe", "aggressive"], 3)
        return Setting("enum", choices[0], choices=choices)
    return Setting("string", f"default-{rng.randint(0, 99)}")


@dataclass
class Template:
    name: str
    platform: str
    mappings: list[str]
    settings: dict[str, Setting]


@dataclass
class Logic:
    name: str
    mappings: list[str]
    settings: dict[str, Setting]


@dataclass
class Action:
    name: str
    platforms: list[str]
    requires: list[str]
    logics: list[Logic]


@dataclass
class Environment:
    name: str
    type: str
    locations: list[tuple[str, str, float, float]]  # id, name, x, y
    knowledge_sets: list[str] = field(default_factory=list)


@dataclass
class Capability:
    name: str
    platform: str
    scheme: str
    template: Template | None
    logics: dict[str, Logic]  # action -> chosen logic
    tasks: list[str]  # tasks achievable with the selected actions


# ---------------------------------------------------------------- generation


class Generator:
    def __init__(self, sizes: Sizes, root: Path, shape: str = "default") -> None:
        self.s = sizes
        self.namespaced = shape == "namespaced"
        self.root = root
        self.rng = random.Random(sizes.seed)
        self.files = 0
        self.platforms = (
            ["ROS1", "ROS2"]
            if sizes.platforms == 2
            else [f"ROS{i + 1}" for i in range(sizes.platforms)]
        )
        extras = max(sizes.mappings - len(BASE_MAPPINGS), 0)
        self.extra_mappings = [f"sensor_{i:03d}" for i in range(extras)]
        self.schemes: dict[str, list[str]] = {}
        self.templates: dict[str, list[Template]] = {}
        self.actions: list[Action] = []
        self.tasks: dict[str, list[list[str]]] = {}
        self.environments: list[Environment] = []
        self.capabilities: list[Capability] = []
        self.scenarios: list[str] = []

    def write(self, rel: str, text: str) -> None:
        path = self.root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        self.files += 1

    def run(self) -> None:
        self.gen_platforms()
        self.gen_actions()
        self.gen_tasks()
        self.gen_environments()
        self.gen_capabilities()
        self.gen_scenarios()
        self.gen_fleet()

    # -------------------------------------------------------- platforms

    def gen_platforms(self) -> None:
        per_platform = max(1, self.s.templates // len(self.platforms))
        for p_index, platform in enumerate(self.platforms):
            ros2 = platform != "ROS1"
            base = f"models/platforms/{platform}"
            self.write(
                f"{base}/platform.yaml",
                modeline(3, "platform") + f"description: {q(f'Generated platform {platform}')}\n",
            )
            names = [f"{platform.lower()}-scheme-{j}" for j in range(self.s.schemes)]
            self.schemes[platform] = names
            for j, scheme in enumerate(names):
                lines = [
                    modeline(4, "mapping-scheme"),
                    f"description: {q(f'Generated mapping scheme {j} of {platform}')}\n",
                    "mappings:\n",
                ]
                for m_index, mapping in enumerate(BASE_MAPPINGS + tuple(self.extra_mappings)):
                    kind = MAPPING_KINDS[m_index % len(MAPPING_KINDS)]
                    if mapping in BASE_MAPPINGS:
                        kind = "topic"
                    iface = {"topic": "msg", "service": "srv", "action_client": "action"}[kind]
                    camel = "".join(part.capitalize() for part in mapping.split("_"))
                    type_ = f"lab_msgs/{iface}/{camel}" if ros2 else f"lab_msgs/{camel}"
                    name = f"ns{j}/{mapping}"
                    if self.namespaced and m_index % 2:
                        name = q(f"{{namespace}}/{mapping}")
                    lines.append(f"  {mapping}: {{kind: {kind}, name: {name}, type: {type_}}}\n")
                self.write(f"{base}/mapping-schemes/{scheme}.yaml", "".join(lines))
            count = per_platform
            if p_index == len(self.platforms) - 1:
                count = max(1, self.s.templates - per_platform * (len(self.platforms) - 1))
            self.templates[platform] = [self.gen_template(platform, i) for i in range(count)]

    def gen_template(self, platform: str, index: int) -> Template:
        rng = self.rng
        name = f"{platform.lower()}-robot-{index:02d}"
        extras = rng.sample(self.extra_mappings, len(self.extra_mappings) // 2)
        if self.namespaced:  # a template that lists all its platform's mappings: all logics fit
            extras = list(self.extra_mappings)
        mappings = list(BASE_MAPPINGS) + sorted(extras)
        linear = round(rng.uniform(0.2, 0.3), 2)
        angular = round(rng.uniform(1.5, 3.0), 2)
        settings = {
            "max_linear_speed": Setting("number", round(linear * 0.8, 3), 0.0, linear, unit="m/s"),
            "max_angular_speed": Setting(
                "number", round(angular * 0.8, 3), 0.0, angular, unit="rad/s"
            ),
        }
        for k in range(rng.randint(1, 4)):
            settings[f"option_{k}"] = random_setting(rng)
        template = Template(name, platform, mappings, settings)
        lines = [
            modeline(4, "robot-template"),
            f"description: {q(f'Generated robot {index} of {platform}')}\n",
            f"mappings: {flow(mappings)}\n",
            "settings:\n",
        ]
        lines += [f"  {key}: {value.yaml()}\n" for key, value in settings.items()]
        self.write(f"models/platforms/{platform}/robot-templates/{name}.yaml", "".join(lines))
        return template

    # -------------------------------------------------------- actions and tasks

    def gen_actions(self) -> None:
        rng = self.rng
        everywhere: list[str] = []  # actions on every platform: the only `requires` targets
        for i in range(self.s.actions):
            name = f"Action{i:03d}"
            platforms = list(self.platforms)
            if len(self.platforms) > 1 and i % 10 in (4, 9):
                platforms = [self.platforms[i % len(self.platforms)]]
            requires: list[str] = []
            if everywhere and i % 8 == 3:
                requires = [rng.choice(everywhere)]
            logics: list[Logic] = []
            for k in range(max(1, self.s.logics)):
                if self.namespaced:
                    mappings = self.namespaced_logic_mappings(k)
                elif k == 0:  # always fits every template: only base mappings
                    mappings = rng.sample(BASE_MAPPINGS, rng.randint(1, 2))
                elif k == 1:
                    mappings = rng.sample(BASE_MAPPINGS, 1) + rng.sample(
                        self.extra_mappings, min(len(self.extra_mappings), rng.randint(1, 2))
                    )
                else:
                    mappings = rng.sample(
                        self.extra_mappings, min(len(self.extra_mappings), rng.randint(2, 3))
                    )
                settings = {f"param_{n}": random_setting(rng) for n in range(rng.randint(0, 3))}
                logics.append(Logic(f"{name.lower()}_logic_{k}", mappings, settings))
            action = Action(name, platforms, requires, logics)
            self.actions.append(action)
            if len(platforms) == len(self.platforms):
                everywhere.append(name)
            lines = [
                modeline(2, "action"),
                f"description: {q(f'Generated action {i}')}\n",
                f"platforms: {flow(platforms)}\n",
                f"requires: {flow(requires)}\n",
                "logics:\n",
            ]
            for logic in logics:
                lines.append(f"  {logic.name}:\n")
                lines.append(f"    description: {q('Generated logic ' + logic.name)}\n")
                lines.append(f"    mappings: {flow(logic.mappings)}\n")
                if logic.settings:
                    lines.append("    settings:\n")
                    lines += [f"      {k}: {v.yaml()}\n" for k, v in logic.settings.items()]
            self.write(f"models/actions/{name}.yaml", "".join(lines))

    def namespaced_logic_mappings(self, k: int) -> list[str]:
        """A logic of the namespaced shape: a few base mappings and more sensors than the
        default shape's logics need (every template lists them all)."""
        rng, extras = self.rng, self.extra_mappings
        base = rng.sample(BASE_MAPPINGS, rng.randint(1, 3))
        return base + rng.sample(extras, min(len(extras), rng.randint(6, 8) + 2 * k))

    def gen_tasks(self) -> None:
        rng = self.rng
        everywhere = [a.name for a in self.actions if len(a.platforms) == len(self.platforms)]
        names = [a.name for a in self.actions]
        for i in range(self.s.tasks):
            name = f"Task{i:02d}"
            impls = [rng.sample(everywhere, min(len(everywhere), rng.randint(1, 4)))]
            for _ in range(rng.randint(0, 2)):
                impls.append(rng.sample(names, min(len(names), rng.randint(1, 4))))
            self.tasks[name] = impls
            lines = [
                modeline(2, "task"),
                f"description: {q(f'Generated task {i}')}\n",
                "implementations:\n",
            ]
            lines += [f"  - {flow(impl)}\n" for impl in impls]
            self.write(f"models/tasks/{name}.yaml", "".join(lines))

    # -------------------------------------------------------- environments

    def gen_environments(self) -> None:
        rng = self.rng
        for i in range(self.s.environments):
            name = f"Environment{i:02d}"
            env = Environment(name, ENV_TYPES[i % len(ENV_TYPES)], [])
            lines = [
                modeline(2, "environment"),
                f"description: {q(f'Generated environment {i}')}\n",
                f"type: {env.type}\n",
                "objects:\n" if self.s.locations else "objects: []\n",
            ]
            for k in range(self.s.locations):
                x, y = round(rng.uniform(-20, 20), 2), round(rng.uniform(-20, 20), 2)
                env.locations.append((str(k + 1), f"Room{k:03d}", x, y))
                lines.append(
                    f'  - {{id: "{k + 1}", name: Room{k:03d}, type: Location, '
                    f"x: {num(x)}, y: {num(y)}}}\n"
                )
            doors = self.s.locations // 10 if len(env.locations) > 1 else 0
            for d in range(doors):
                a, b = rng.sample(env.locations, 2)
                lines.append(
                    f'  - {{id: "D{d}", name: Door{d:02d}, type: Door, '
                    f'connects: ["{a[0]}", "{b[0]}"]}}\n'
                )
            lines.append("knowledge_sets:\n  Helper:\n    LOCATIONS:")
            lines.append("\n" if env.locations else " []\n")
            lines += [
                f'      - {{ID: "{loc[0]}", X: {num(loc[2])}, Y: {num(loc[3])}}}\n'
                for loc in env.locations
            ]
            target = env.locations[0][0] if env.locations else "0"
            lines.append(f'  Delivery:\n    TARGET: {{GOAL_ID: "{target}"}}\n')
            lines.append(
                f"  Layout:\n    FLOOR: {i}\n    DOORS: {doors}\n"
                f"    MAP: {q(f'maps/{name.lower()}.yaml')}\n"
            )
            env.knowledge_sets = ["Helper", "Delivery", "Layout"]
            self.environments.append(env)
            self.write(f"models/environments/{name}.yaml", "".join(lines))

    # -------------------------------------------------------- configurations

    def gen_capabilities(self) -> None:
        rng = self.rng
        by_name = {a.name: a for a in self.actions}
        task_names = list(self.tasks)
        for i in range(self.s.capabilities):
            name = f"capability-{i:03d}"
            platform = self.platforms[i % len(self.platforms)]
            scheme = rng.choice(self.schemes[platform])
            template = rng.choice(self.templates[platform]) if i % 10 != 7 else None
            selected: dict[str, None] = {}  # ordered set of action names
            for task in rng.sample(task_names, min(len(task_names), rng.randint(1, 4))):
                feasible = [
                    impl
                    for impl in self.tasks[task]
                    if all(platform in by_name[a].platforms for a in impl)
                ]
                for action in rng.choice(feasible):
                    selected[action] = None
            pending = list(selected)
            while pending:  # close over `requires` (targets are on every platform)
                for required in by_name[pending.pop()].requires:
                    if required not in selected:
                        selected[required] = None
                        pending.append(required)
            chosen: dict[str, Logic] = {}
            for action in selected:
                fits = [
                    logic
                    for logic in by_name[action].logics
                    if template is None or set(logic.mappings) <= set(template.mappings)
                ]
                chosen[action] = rng.choice(fits)
            achievable = [
                task
                for task, impls in self.tasks.items()
                if any(set(impl) <= set(selected) for impl in impls)
            ]
            self.capabilities.append(
                Capability(name, platform, scheme, template, chosen, achievable)
            )
            lines = [
                modeline(2, "capability"),
                f"description: {q(f'Generated capability {i}')}\n",
                f"platform: {platform}\n",
                f"mapping_scheme: {scheme}\n",
            ]
            if template is not None:
                lines.append(f"robot_template: {template.name}\n")
            lines.append("actions:\n")
            lines += [f"  {action}: {logic.name}\n" for action, logic in chosen.items()]
            self.write(f"configs/capabilities/{name}.yaml", "".join(lines))

    def gen_scenarios(self) -> None:
        rng = self.rng
        for i in range(self.s.scenarios):
            name = f"scenario-{i:04d}"
            cap = rng.choice(self.capabilities)
            env = rng.choice(self.environments) if i % 20 != 13 else None
            lines = [
                modeline(2, "scenario"),
                f"description: {q(f'Generated scenario {i}')}\n",
                f"capability: {cap.name}\n",
            ]
            if env is not None:
                lines.append(f"environment: {env.name}\n")
            if cap.template is not None:
                lines.append("robot_settings:\n")
                keys = rng.sample(list(cap.template.settings), rng.randint(1, 2))
                lines += [
                    f"  {key}: {scalar(cap.template.settings[key].pick(rng))}\n" for key in keys
                ]
            with_settings = [logic for logic in cap.logics.values() if logic.settings]
            if with_settings:
                lines.append("logic_settings:\n")
                for logic in rng.sample(with_settings, min(len(with_settings), 3)):
                    values = ", ".join(
                        f"{key}: {scalar(setting.pick(rng))}"
                        for key, setting in logic.settings.items()
                    )
                    lines.append(f"  {logic.name}: {{{values}}}\n")
            if env is not None:
                sets = rng.sample(env.knowledge_sets, rng.randint(1, 2))
                lines.append(f"knowledge_sets: {flow(sets)}\n")
            lines.append(
                f"knowledge:\n  SCENARIO: {{ID: {i}, LABEL: {q(name)}}}\n"
                f"  ROLE: {q(rng.choice(['delivery', 'guide', 'patrol']))}\n"
            )
            if cap.tasks:
                lines.append("goals:\n")
                for task in rng.sample(cap.tasks, min(len(cap.tasks), rng.randint(1, 3))):
                    if env is None or not env.locations:
                        lines.append(f"  - {{task: {task}}}\n")
                        continue
                    loc = rng.choice(env.locations)
                    where = loc[1] if rng.random() < 0.5 else f'"{loc[0]}"'
                    lines.append(f"  - {{task: {task}, location: {where}}}\n")
            self.scenarios.append(name)
            self.write(f"configs/scenarios/{name}.yaml", "".join(lines))

    def gen_fleet(self) -> None:
        rng = self.rng
        if self.s.robots == 0:
            empty = "robots: {}\nallow_empty: true\n"
            self.write("configs/fleet.yaml", modeline(1, "fleet") + empty)
            return
        lines = [modeline(1, "fleet"), "robots:\n"]
        for i in range(self.s.robots):
            scenario = rng.choice(self.scenarios)
            extra = ", suspended: true" if i % 50 == 49 else ""
            namespace = f"robot_{i:05d}"
            if self.namespaced:
                namespace = f"site_{i % 7}/{namespace}"
            lines.append(
                f'  robot-{i:05d}: {{scenario: {scenario}, name: "Robot {i}", '
                f"namespace: {namespace}{extra}}}\n"
            )
        self.write("configs/fleet.yaml", "".join(lines))


# ---------------------------------------------------------------- driver


def prepare_target(target: Path) -> None:
    """Empty TARGET, refusing to touch a folder this generator did not write."""
    if target.exists():
        if not target.is_dir():
            raise SystemExit(f"generate: {target} exists and is not a folder")
        if any(target.iterdir()) and not (target / MARKER).exists():
            raise SystemExit(
                f"generate: {target} is not empty and was not written by bench/generate.py;"
                " refusing to replace it"
            )
        shutil.rmtree(target)
    target.mkdir(parents=True)


def git_commit(target: Path, message: str) -> None:
    env = dict(os.environ)
    env.update(
        GIT_AUTHOR_NAME="robotconf bench",
        GIT_AUTHOR_EMAIL="bench@robotconf.invalid",
        GIT_COMMITTER_NAME="robotconf bench",
        GIT_COMMITTER_EMAIL="bench@robotconf.invalid",
        GIT_AUTHOR_DATE="2024-01-01T00:00:00Z",
        GIT_COMMITTER_DATE="2024-01-01T00:00:00Z",
    )

    def git(*args: str) -> None:
        subprocess.run(["git", *args], cwd=target, env=env, check=True, stdout=subprocess.DEVNULL)

    git("init", "-q", "-b", "main")
    git("add", "--all", ".")
    git("-c", "commit.gpgsign=false", "commit", "-q", "-m", message)


def marker(sizes: Sizes, shape: str = "default") -> dict[str, int | str]:
    """What MARKER holds: the sizes and, but for the default shape, the shape."""
    written: dict[str, int | str] = dict(asdict(sizes))
    if shape != "default":
        written["shape"] = shape
    return written


def add_shape_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--shape",
        choices=SHAPES,
        default="default",
        help="default: ~3 KB requests; namespaced: the recommended lab, every robot in a "
        "namespace of its own and ~40 mappings resolved in it (~6.6 KB requests)",
    )


def generate(target: Path, sizes: Sizes, use_git: bool = False, shape: str = "default") -> int:
    """Write the repository into TARGET; return the number of YAML files written."""
    if shape not in SHAPES:
        raise ValueError(f"unknown shape {shape!r}: one of {', '.join(SHAPES)}")
    prepare_target(target)
    gen = Generator(sizes, target, shape)
    gen.run()
    (target / MARKER).write_text(json.dumps(marker(sizes, shape), sort_keys=True) + "\n")
    if use_git:
        git_commit(target, f"Generated benchmark lab (seed {sizes.seed})")
    return gen.files


def parse_args(argv: list[str] | None) -> tuple[Path, Sizes, bool, str]:
    defaults = Sizes()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "target",
        nargs="?",
        type=Path,
        default=DEFAULT_TARGET,
        help=f"folder to write (default: {DEFAULT_TARGET})",
    )
    for key, value in asdict(defaults).items():
        parser.add_argument(
            f"--{key}", type=int, default=value, metavar="N", help=f"default: {value}"
        )
    add_shape_option(parser)
    parser.add_argument("--git", action="store_true", help="git init and commit the result")
    args = parser.parse_args(argv)
    values = {key: getattr(args, key) for key in asdict(defaults)}
    for key, value in values.items():
        low = 0 if key in ("robots", "locations") else 1
        if key != "seed" and value < low:
            parser.error(f"--{key} must be at least {low}")
    if values["templates"] < values["platforms"]:
        parser.error("--templates must be at least --platforms")
    return args.target, Sizes(**values), args.git, args.shape


def main(argv: list[str] | None = None) -> int:
    target, sizes, use_git, shape = parse_args(argv)
    start = time.perf_counter()
    files = generate(target, sizes, use_git, shape)
    print(
        f"generate: {files} YAML files in {target} ({time.perf_counter() - start:.2f} s)",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
